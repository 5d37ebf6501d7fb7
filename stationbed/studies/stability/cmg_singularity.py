"""Case ``cmg_singularity``: an SGCMG pyramid driven into its internal singularity
(``scenarios/sgcmg_singularity.toml``) under every steering law the scene offers: which laws
stall there and which pass through?"""

from __future__ import annotations

import math
import typing

import numpy as np

from ...scene import Cmg, load_scene
from ..common import scenario, try_simulate
from .base import Case, Context, stability_case

__all__ = ["STALL_FRACTION", "CMG_WINDOW_S", "cmg_singularity"]

#: a steering law stalls when the cluster delivers less than this fraction of the commanded
#: x torque over the last CMG_WINDOW_S of the run
STALL_FRACTION = 0.5
CMG_WINDOW_S = 3.0


@stability_case("cmg_singularity")
def cmg_singularity(ctx: Context) -> Case:
    """Each steering law: the torque about x the cluster delivers over the last
    ``CMG_WINDOW_S`` (from the change of its momentum h_x) against the commanded one."""
    scene = load_scene(scenario("sgcmg_singularity.toml"))
    duration = scene.simulation.duration  # 30 s: SR and o-DSR need ~10 s to leave the singularity
    window = CMG_WINDOW_S
    c = scene.cmg
    h_sing = 2 * math.cos(c.skew) * c.h_rotor  # the internal singular momentum along x [N m s]
    tau_cmd = float(scene.controller.params["torque_B"][0])  # N m
    case = Case(ctx.name, "SGCMG pyramid driven into its internal singularity: steering laws",
                f"torque delivered about x over the last {window:g} s (-Δh_x/Δt) vs the {tau_cmd:g} N m "
                f"commanded; stalls below {STALL_FRACTION:.0%}")
    plt = ctx.plt
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(15, 5.5), constrained_layout=True)
    rows = []
    for law in typing.get_args(Cmg.model_fields["steering"].annotation):
        sc = scene.replace(**{"cmg.steering": law})
        ctx.note(f"steering {law}")
        tr, status = try_simulate(sc, None, None, duration=duration)
        if tr is None or status != "ok":
            case.add(law, math.nan, "N m", status)
            continue
        hx = tr["hx"]
        i0 = int(np.searchsorted(tr.t, tr.t[-1] - window - 1e-9))
        delivered = -(hx[-1] - hx[i0]) / (tr.t[-1] - tr.t[i0])
        frac = delivered / tau_cmd
        sing = tr["cmg_singularity"]
        s = tr.meta.get("summary", {})
        above = np.nonzero(hx > 1.01 * h_sing)[0]
        escape = f" (h_x past the singular value at {tr.t[above[0]]:.3g} s)" if above.size else ""
        verdict = ("stalls at the singularity" if frac < STALL_FRACTION else "passes through" + escape) + (
            f": delivers {delivered:.3g} N m, final |h| {np.linalg.norm(tr.cols('hx', 'hy', 'hz')[-1]):.4g} N m s, "
            f"min measure {sing.min():.2g} at {tr.t[int(np.argmin(sing))]:.3g} s, "
            f"{s.get('rate_limited_ticks', 0)} rate-limited ticks")
        case.add(law, delivered, "N m", verdict)
        rows += [[law, t, a, b] for t, a, b in zip(tr.t, hx, sing)]
        ax0.plot(tr.t, hx, label=f"{law}: {'stalls' if frac < STALL_FRACTION else 'passes'} ({delivered:.3g} N m at the end)")
        ax1.semilogy(tr.t, np.maximum(sing, 1e-16), label=law)
    ax0.axhline(h_sing, color="red", linestyle="--", label=f"internal singularity 2 cos β h0 = {h_sing:g} N m s")
    ax0.set_xlabel("time [s]")
    ax0.set_ylabel("CMG momentum h_x [N m s]")
    ax0.set_title(f"sgcmg_singularity: {tau_cmd:g} N m about x commanded")
    ax0.legend(fontsize=8)
    ax0.grid(True, alpha=0.3)
    ax1.set_xlabel("time [s]")
    ax1.set_ylabel("singularity measure sqrt(det(Â Âᵀ)) [-]")
    ax1.set_title("distance from the singular configuration")
    ax1.legend(fontsize=8)
    ax1.grid(True, which="both", alpha=0.3)
    ctx.save(case, fig, rows, ["steering", "t_s", "hx_Nms", "singularity_measure"])
    return case
