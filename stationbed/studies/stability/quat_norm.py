"""Case ``quat_norm``: how far the integrator's own quaternion leaves unit norm over a long
torque-free tumble, with and without projection after every fixed step."""

from __future__ import annotations

import math

import numpy as np

from ..common import one_line, registered_integrators
from ..plotting import colours
from ..probes import ROUNDOFF_REL, growth, growth_verdict, raw_states
from .base import Case, Context, stability_case
from .long_horizon import LONG_STEP_S, long_label, long_setting
from .scenes import orbital_rate, tumble_scene

__all__ = ["NORM_ORBITS", "QUICK_NORM_ORBITS", "quat_norm"]

NORM_ORBITS = 20
QUICK_NORM_ORBITS = 1


@stability_case("quat_norm")
def quat_norm(ctx: Context) -> Case:
    """Every integrator at its long-run setting (fixed-step ones also projected every step):
    the largest ``||q| - 1|`` of the raw state and the log-log slope of its growth."""
    n = orbital_rate()
    T_orb = 2 * math.pi / n
    n_orb = QUICK_NORM_ORBITS if ctx.quick else NORM_ORBITS
    scene = tumble_scene(n_orb * T_orb, T_orb / 10)
    ts = np.linspace(0.0, n_orb * T_orb, 10 * n_orb + 1)
    case = Case(ctx.name, f"quaternion norm drift, torque-free tumble ({n_orb} orbits), with and without projection",
                "max ||q| - 1| of the integrator's own state, and the log-log slope of its growth")
    plt = ctx.plt
    fig, ax = plt.subplots(figsize=(13, 5.5), constrained_layout=True)
    integs = registered_integrators()
    icol = colours(plt, list(integs))
    rows = []
    for name, cls in integs.items():
        variants = [(False, long_label(name, cls))]
        if not cls.adaptive:
            variants.append((True, f"{name} + projection every step (h {LONG_STEP_S:g} s)"))
        for project, label in variants:
            ctx.note(label)
            try:
                xs = raw_states(scene, "momentum", name, ts, project=project, **long_setting(cls))
            except (ValueError, NotImplementedError) as e:
                case.add(label, math.nan, "", f"skipped: {one_line(e)}")
                break
            except Exception as e:  # noqa: BLE001 - a method that breaks down is a result here
                case.add(label, math.nan, "", f"failed: {type(e).__name__}: {one_line(e)}")
                continue
            e = np.abs(np.linalg.norm(xs[:, :4], axis=1) - 1.0)
            slope, final = growth(ts, e)
            worst = float(e.max())
            verdict = "unit norm to round-off" if worst < ROUNDOFF_REL else growth_verdict(slope, worst)
            if project and worst >= ROUNDOFF_REL:
                verdict = f"bounded by one step's error (slope {slope:.2f})"
            case.add(label, worst, "|q|-1", verdict)
            rows += [[label, t / T_orb, v] for t, v in zip(ts, e)]
            ax.semilogy(ts[1:] / T_orb, np.maximum(e[1:], 1e-16), color=icol[name],
                        linestyle="--" if project else "-", label=f"{label}: {worst:.1e}")
    ax.axhline(ROUNDOFF_REL, color="0.5", linestyle=":", label="round-off level")
    ax.set_xlabel("time [orbits of 92.6 min]")
    ax.set_ylabel("| |q_BN| - 1 |  [-]  (zero drawn at 1e-16)")
    ax.set_title(case.title)
    fig.legend(loc="outside right upper", fontsize=8, title="method: max | |q| - 1 |")
    ax.grid(True, alpha=0.3)
    ctx.save(case, fig, rows, ["method", "t_orbits", "abs_norm_error"])
    return case
