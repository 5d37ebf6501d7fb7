"""Case ``dzhanibekov``: a rigid body spun about its intermediate axis flips periodically; up to
which fixed step does each fixed-step integrator keep the flip timing?"""

from __future__ import annotations

import math

import numpy as np

from ...run.simulation import simulate
from ...scene import scene_from_dict
from ..common import registered_integrators, try_simulate
from ..plotting import colours
from ..probes import flip_times
from .base import Case, Context, stability_case

__all__ = ["FLIP_SCENE", "FLIP_STEPS_S", "QUICK_FLIP_STEPS_S", "FLIP_TOL_FRACTION", "dzhanibekov"]

#: a rigid body spun about its intermediate axis (0.1 rad/s) with 1e-3 rad/s off-axis: it
#: flips every ~290 s (first at 177 s)
FLIP_SCENE = {
    "name": "study_dzhanibekov",
    "simulation": {"duration": 2000.0, "output_dt": 0.5},
    "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [1e-3, 0.1, 1e-3]},
    "body": {"mass": 100.0, "inertia": [[100.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.0, 0.0, 250.0]], "cm": [0, 0, 0]},
}
FLIP_STEPS_S = [0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
QUICK_FLIP_STEPS_S = [1.0, 4.0, 16.0]
#: a method keeps the flip timing while every flip is within this fraction of the mean
#: interval between flips of the reference
FLIP_TOL_FRACTION = 0.01


@stability_case("dzhanibekov")
def dzhanibekov(ctx: Context) -> Case:
    """Every fixed-step integrator over ``FLIP_STEPS_S``: the largest error of the flip times
    against DOP853 at rtol 1e-12 (a missing flip loses the timing)."""
    d = dict(FLIP_SCENE, simulation=dict(FLIP_SCENE["simulation"]))
    if ctx.quick:
        d["simulation"]["duration"] = 500.0
    scene = scene_from_dict(d, source="study Dzhanibekov scene")
    ctx.note("reference dop853 rtol 1e-12")
    ref = simulate(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    t_ref = flip_times(ref)
    gap = float(np.mean(np.diff(t_ref))) if t_ref.size > 1 else scene.simulation.duration
    tol = FLIP_TOL_FRACTION * gap
    case = Case(ctx.name, "intermediate-axis flips: flip timing vs step size",
                f"max |t_flip - t_flip,ref| over the {t_ref.size} reference flips; lost above {tol:.3g} s "
                f"({FLIP_TOL_FRACTION:.0%} of the {gap:.3g} s between flips) or when a flip is missing")
    plt = ctx.plt
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(15, 5.5), constrained_layout=True)
    ax0.plot(ref.t, ref["wy"], color="k", linewidth=2, label="reference (DOP853 rtol 1e-12)")
    fixed = {n: c for n, c in registered_integrators().items() if not c.adaptive}
    icol = colours(plt, list(fixed))
    rows = []
    steps = QUICK_FLIP_STEPS_S if ctx.quick else FLIP_STEPS_S
    for name in fixed:
        errs, lose, shown, skipped = [], None, False, None
        for h in steps:
            ctx.note(f"{name} h {h:g} s")
            tr, status = try_simulate(scene, "momentum", name, step=h, output_dt=h)
            if status.startswith("skipped"):
                skipped = status
                break
            if tr is None or status != "ok":
                err = math.inf
            else:
                tf = flip_times(tr)
                err = float(np.max(np.abs(tf - t_ref))) if tf.size == t_ref.size else math.inf
            errs.append(err)
            rows.append([name, h, err, status])
            if err > tol and lose is None:
                lose = h
                if tr is not None and not shown:
                    ax0.plot(tr.t, tr["wy"], color=icol[name], linewidth=1, label=f"{name}, h = {h:g} s (timing lost)")
                    shown = True
        if skipped:
            case.add(name, math.nan, "s", skipped)
            continue
        fin = [(h, e) for h, e in zip(steps, errs) if math.isfinite(e)]
        if fin:
            ax1.loglog([h for h, _ in fin], [max(e, 1e-6) for _, e in fin], marker="o", color=icol[name], label=name)
        lost = [h for h, e in zip(steps, errs) if not math.isfinite(e)]
        if lost:
            ax1.plot(lost, [gap] * len(lost), "x", color=icol[name], markersize=9)
        ok_steps = [h for h, e in zip(steps, errs) if e <= tol and (lose is None or h < lose)]
        h_keep = max(ok_steps) if ok_steps else math.nan
        verdict = (f"keeps timing up to h = {h_keep:g} s" if lose is None else
                   f"loses flip timing at h = {lose:g} s" + (f" (keeps it at {h_keep:g} s)" if ok_steps else ""))
        case.add(name, h_keep, "s", verdict)
    ax0.set_xlabel("time [s]")
    ax0.set_ylabel("ω_y, intermediate axis [rad/s]")
    ax0.set_title("Dzhanibekov flips: ω_y changes sign at each flip")
    ax0.legend(fontsize=8)
    ax0.grid(True, alpha=0.3)
    ax1.axhline(tol, color="red", linestyle="--", label=f"lost above {tol:.3g} s")
    ax1.set_xlabel("fixed step h [s]")
    ax1.set_ylabel("max flip-time error [s] (x: a flip missing)")
    ax1.set_title("flip timing error vs step size")
    ax1.legend(fontsize=8)
    ax1.grid(True, which="both", alpha=0.3)
    ctx.save(case, fig, rows, ["integrator", "step_s", "max_flip_time_err_s", "status"])
    return case
