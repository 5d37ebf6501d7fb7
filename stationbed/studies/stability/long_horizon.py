"""Case ``long_horizon``: energy and momentum of a torque-free tumble and the Jacobi integral of
a gravity-gradient libration over many orbits, with every integrator: does the invariant's
error drift secularly or stay bounded?"""

from __future__ import annotations

import math

import numpy as np

from ..common import registered_integrators, sweep_setting, try_simulate
from ..plotting import colours
from ..probes import growth, growth_verdict, jacobi_integral
from .base import Case, Context, stability_case
from .scenes import gravity_gradient_scene, orbital_rate, tumble_scene

__all__ = ["LONG_ORBITS", "QUICK_LONG_ORBITS", "LONG_RTOL", "LONG_STEP_S", "long_setting", "long_label", "long_horizon"]

LONG_ORBITS = 100
QUICK_LONG_ORBITS = 3
#: adaptive methods run at this rtol, fixed-step ones at this step [s] (n h = 0.07, |ω| h = 0.08)
LONG_RTOL = 1e-8
LONG_STEP_S = 60.0

#: the invariants: panel key -> name in the verdicts and the CSV
_INV = {"T": "energy", "H": "momentum", "J": "Jacobi integral"}


def long_setting(cls) -> dict:
    """The simulate() keywords of an integrator class on the long runs (``LONG_RTOL`` or
    ``LONG_STEP_S``)."""
    return sweep_setting(cls, LONG_RTOL if cls.adaptive else LONG_STEP_S)


def long_label(name: str, cls) -> str:
    """``"<name> (rtol 1e-08)"`` or ``"<name> (h 60 s)"``: a method with its long-run setting."""
    return f"{name} (rtol {LONG_RTOL:g})" if cls.adaptive else f"{name} (h {LONG_STEP_S:g} s)"


@stability_case("long_horizon")
def long_horizon(ctx: Context) -> Case:
    """Every integrator on the tumble (T, |ΔH_O_N|) and the libration (Jacobi integral): the
    log-log slope of each invariant's running maximum error."""
    n_orb = QUICK_LONG_ORBITS if ctx.quick else LONG_ORBITS
    n = orbital_rate()
    T_orb = 2 * math.pi / n
    duration, output_dt = n_orb * T_orb, T_orb / 10
    case = Case(ctx.name, f"long horizon ({n_orb} orbits): energy and momentum error growth",
                "log-log slope of the running max of the invariant's error (1: drift, 0: bounded)")
    tumble, gg = tumble_scene(duration, output_dt), gravity_gradient_scene(duration, output_dt)
    plt = ctx.plt
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.5), constrained_layout=True)
    integs = registered_integrators()
    icol = colours(plt, list(integs))
    rows, walls = [], {}
    for name, cls in integs.items():
        label = long_label(name, cls)
        for sc, panels in ((tumble, ("T", "H")), (gg, ("J",))):
            ctx.note(f"{label} on {sc.name}")
            tr, status = try_simulate(sc, "momentum", name, **long_setting(cls))
            if tr is None or status != "ok":
                for pn in panels:
                    case.add(f"{label} [{_INV[pn]}]", math.nan, "", status)
                continue
            wall = tr.meta["wall_s"]
            for pn in panels:
                if pn == "T":
                    e = np.abs(tr["T"] - tr["T"][0]) / tr["T"][0]
                elif pn == "H":
                    e = np.linalg.norm(tr.H_O_N - tr.H_O_N[0], axis=1) / np.linalg.norm(tr.H_O_N[0])
                else:
                    J = jacobi_integral(sc, tr)
                    e = np.abs(J - J[0]) / (n**2 * np.trace(np.array(sc.body.inertia)))
                t_orb = tr.t / T_orb
                slope, final = growth(tr.t, e)
                case.add(f"{label} [{_INV[pn]}]", final, "relative", growth_verdict(slope, final))
                rows += [[name, _INV[pn], t, v] for t, v in zip(t_orb, e)]
                ax = axes["THJ".index(pn)]
                ax.semilogy(t_orb[1:], np.maximum(e[1:], 1e-17), color=icol[name], linewidth=1)
                walls[name] = walls.get(name, 0.0) + wall
    titles = {"T": "torque-free tumble: kinetic energy", "H": "torque-free tumble: |ΔH_O_N|",
              "J": "gravity gradient in orbit: Jacobi integral"}
    for pn, ax in zip("THJ", axes):
        ax.set_title(titles[pn])
        ax.set_xlabel("time [orbits of 92.6 min]")
        ax.set_ylabel("relative error of the invariant [-]")
        ax.grid(True, alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=icol[nm], linewidth=2,
                      label=f"{long_label(nm, c)}, {walls[nm]:.2g} s" if nm in walls else f"{nm} (failed)")
               for nm, c in integs.items()]
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title="integrator, wall time of both runs")
    ctx.save(case, fig, rows, ["integrator", "invariant", "t_orbits", "rel_error"])
    return case
