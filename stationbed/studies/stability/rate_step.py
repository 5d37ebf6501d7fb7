"""Case ``rate_step``: an array rate step (an impulse) in free drift, where H_O_N must stay
constant. The momentum form (H is its state) keeps it; an ω-state form keeps it only when the
jump at the step is applied (``simulation.impulse_jump``), else it loses the impulse."""

from __future__ import annotations

import math

import numpy as np

from ...formulations import FORMULATIONS
from ...scene import load_scene
from ..common import scenario, try_simulate
from ..plotting import STYLES
from .base import Case, Context, stability_case

__all__ = ["H_JUMP_REL", "rate_step"]

#: an H_O_N change across a rate step above this (relative) is a lost impulse: 10⁴ x the
#: scene's rtol (1e-10), and 3e4 x below the impulse itself (3 % of |H|)
H_JUMP_REL = 1e-6


@stability_case("rate_step")
def rate_step(ctx: Context) -> Case:
    """``scenarios/array_rate_step.toml`` in every formulation (ω-state forms with and without
    the jump): the relative change of H_O_N across each rate step."""
    case = Case(ctx.name, "array rate step (impulse): H_O_N across the step",
                "|H_O_N(after) - H_O_N(before)| / |H_O_N| at each rate step")
    scene = load_scene(scenario("array_rate_step.toml"))
    duration = 1200.0 if ctx.quick else scene.simulation.duration
    t_steps = sorted({st.t for a in scene.appendage for j in (a.alpha, a.beta) for st in j.rate_step if st.t < duration})
    variants = []
    for f, cls in FORMULATIONS.items():
        variants += [(f, False), (f, True)] if cls.omega_is_state else [(f, None)]
    plt = ctx.plt
    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    rows = []
    for f, jump in variants:
        sc = scene if jump is None else scene.replace(**{"simulation.impulse_jump": jump})
        label = f if jump is None else f"{f} ({'jump applied' if jump else 'no jump handling'})"
        ctx.note(label)
        tr, status = try_simulate(sc, f, None, duration=duration)
        if tr is None or status != "ok":
            case.add(label, math.nan, "", status)
            continue
        H = tr.H_O_N
        H0 = float(np.linalg.norm(H[0]))
        dH = np.linalg.norm(H - H[0], axis=1) / H0
        jumps = []
        for ts in t_steps:
            i_before = int(np.searchsorted(tr.t, ts)) - 1
            jumps.append(float(np.linalg.norm(H[i_before + 1] - H[i_before]) / H0))
        worst = max(jumps)
        case.add(label, worst, "relative", "H jumps (impulse lost)" if worst > H_JUMP_REL else "H continuous")
        rows += [[label, t, d] for t, d in zip(tr.t, dH)]
        style = STYLES[list(FORMULATIONS).index(f) % len(STYLES)]  # equal curves of two forms stay visible
        ax.semilogy(tr.t, np.maximum(dH, 1e-17), linestyle=style, linewidth=1.8 if style == "-" else 1.4,
                    label=f"{label}: max jump {worst:.1e}")
    for ts in t_steps:
        ax.axvline(ts, color="0.5", linestyle=":", linewidth=1)
    ax.axhline(H_JUMP_REL, color="red", linestyle="--", linewidth=0.9, label=f"detector threshold {H_JUMP_REL:g}")
    ax.set_xlabel("time [s] (dotted: array rate steps)")
    ax.set_ylabel("|H_O_N(t) - H_O_N(0)| / |H_O_N(0)|  [-]")
    ax.set_title("array_rate_step: total angular momentum must stay constant (free drift)")
    ax.legend(fontsize=8, loc="center right")
    ax.grid(True, alpha=0.3)
    ctx.save(case, fig, rows, ["variant", "t_s", "dH_rel"])
    return case
