"""Case ``max_step``: the largest stable fixed step of every fixed-step integrator (and
formulation) on ``scenarios/articulated_stress.toml``."""

from __future__ import annotations

import math

import numpy as np

from ...formulations import FORMULATIONS
from ...run.simulation import simulate
from ...scene import load_scene
from ..common import registered_integrators, scenario, try_simulate
from ..plotting import MARKERS, STYLES, colours
from ..probes import max_errors
from .base import Case, Context, stability_case

__all__ = ["STABLE_ATT_RAD", "STABLE_H_REL", "max_step"]

#: a run fails when it blows up, is more than this far from the reference attitude [rad] ...
STABLE_ATT_RAD = 0.1
#: ... or when |H_O_N| (constant: deep space, torque free) drifts by more than this (relative)
STABLE_H_REL = 1e-2
SCAN_START_S = 0.25
QUICK_SCAN_START_S = 2.0
#: output rows (where the error is measured) about this far apart [s]
MAX_STEP_OUTPUT_DT_S = 5.0
BISECTIONS = 6
QUICK_BISECTIONS = 2


@stability_case("max_step")
def max_step(ctx: Context) -> Case:
    """A doubling scan of the step from ``SCAN_START_S`` until a run fails, then geometric
    bisection between the last good and the first failing step."""
    scene = load_scene(scenario("articulated_stress.toml"))
    duration = 200.0 if ctx.quick else scene.simulation.duration
    case = Case(ctx.name, f"largest stable fixed step on articulated_stress ({duration:g} s)",
                f"run fails on blow-up, attitude error > {STABLE_ATT_RAD} rad vs DOP853 rtol 1e-11, "
                f"or |ΔH_O_N|/|H| > {STABLE_H_REL:g}; doubling scan, then geometric bisection")
    fixed = {n: c for n, c in registered_integrators().items() if not c.adaptive}
    plt = ctx.plt
    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    icol = colours(plt, list(fixed))
    rows = []

    def run(form, name, h):
        dt = h * max(1, round(MAX_STEP_OUTPUT_DT_S / h))  # rows every ~5 s, a whole number of steps
        ctx.note(f"{name}/{form} h {h:.3g} s")
        tr, status = try_simulate(scene, form, name, step=h, output_dt=dt, duration=duration)
        if status.startswith("skipped"):
            return None, math.nan, status
        if tr is None or status != "ok" or len(tr) < 2:
            return False, math.inf, status
        ctx.note(f"{name}/{form} h {h:.3g} s: reference dop853")
        ref = simulate(scene, formulation=form, integrator="dop853", rtol=1e-11, atol=1e-13, output_dt=dt, duration=duration)
        att, _ = max_errors(tr, ref)
        H = tr.H_O_N
        dH = float(np.max(np.linalg.norm(H - H[0], axis=1)) / np.linalg.norm(H[0]))
        ok = att <= STABLE_ATT_RAD and dH <= STABLE_H_REL
        why = "ok" if ok else ("attitude error" if att > STABLE_ATT_RAD else "momentum drift")
        return ok, att, why

    forms = ["momentum"] if ctx.quick else list(FORMULATIONS)  # quick: one build per integrator
    for j, form in enumerate(forms):
        for name in fixed:
            method = f"{name}/{form}"
            h0 = QUICK_SCAN_START_S if ctx.quick else SCAN_START_S
            pts, h, h_pass, h_fail, skipped = [], h0, None, None, None
            while h <= duration / 4:
                ok, att, why = run(form, name, h)
                if ok is None:
                    skipped = why
                    break
                pts.append((h, att, ok, why))
                if ok:
                    h_pass, h = h, 2 * h
                else:
                    h_fail = h
                    break
            if skipped:
                case.add(method, math.nan, "s", skipped)
                continue
            if h_pass is not None and h_fail is not None:
                for _ in range(QUICK_BISECTIONS if ctx.quick else BISECTIONS):
                    hm = math.sqrt(h_pass * h_fail)
                    ok, att, why = run(form, name, hm)
                    pts.append((hm, att, ok, why))
                    h_pass, h_fail = (hm, h_fail) if ok else (h_pass, hm)
            rows += [[form, name, h, a, int(bool(o)), w] for h, a, o, w in sorted(pts)]
            pts.sort()
            ax.loglog([p[0] for p in pts], [min(max(p[1], 1e-12), 10.0) for p in pts], color=icol[name],
                      linestyle=STYLES[j % len(STYLES)], marker=MARKERS[j % len(MARKERS)], markersize=4,
                      label=f"{method}: h_max {h_pass:.3g} s" if h_pass else f"{method}: fails at {h0:g} s")
            bad = [p for p in pts if not p[2]]
            ax.plot([p[0] for p in bad], [min(max(p[1], 1e-12), 10.0) for p in bad], "x", color="k", markersize=7)
            if h_pass is None:
                case.add(method, math.nan, "s", f"fails already at h = {h0:g} s")
            elif h_fail is None:
                case.add(method, h_pass, "s", f"stable up to the largest step tried ({h_pass:g} s)")
            else:
                fail_why = next(p[3] for p in pts if p[0] == h_fail)
                case.add(method, h_pass, "s", f"largest good step {h_pass:.3g} s (fails at {h_fail:.3g} s: {fail_why})")
    ax.axhline(STABLE_ATT_RAD, color="red", linestyle="--", label=f"failure threshold {STABLE_ATT_RAD} rad")
    ax.set_xlabel("fixed step h [s]")
    ax.set_ylabel("max attitude error vs reference [rad] (10: run failed; x: step failed)")
    ax.set_title(case.title)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    ctx.save(case, fig, rows, ["formulation", "integrator", "step_s", "att_err_rad", "passed", "why"])
    return case
