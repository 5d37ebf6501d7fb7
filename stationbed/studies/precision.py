"""Work-precision study (``stationbed study precision SCENE``).

Every formulation x integrator x setting on one scene against a reference solution (the
tightest DOP853 run, cross-checked with a second method and formulation): adaptive
integrators swept over tolerances, fixed-step ones over step sizes. Writes a CSV, two charts
(attitude and rate error against wall time and RHS evaluations) and a table of the cheapest
method reaching 1e-3, 1e-6 and 1e-9 rad. An integrator that refuses the scene (``ValueError``,
e.g. a rigid-body-only method on an articulated scene) is listed as *skipped* with its reason;
one that fails part-way as *failed*.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from ..core import progress
from ..formulations import FORMULATIONS
from ..run.simulation import simulate
from ..scene import Scene, load_scene
from .common import registered_formulations, registered_integrators, sweep_setting, try_simulate, write_csv
from .plotting import MARKERS, STYLES, colours, pyplot
from .probes import max_errors

__all__ = ["PrecisionResult", "precision_study"]

#: adaptive sweep: rtol from 1e-3 to 1e-12 by decades (atol = rtol, dimensionless)
ADAPTIVE_RTOLS = [10.0**-k for k in range(3, 13)]
QUICK_RTOLS = [1e-4, 1e-7]
#: fixed-step sweep: h = output_dt / m, m = 1, 2, 4, ... (every step lands on the outputs)
FIXED_DIVISIONS = [2**k for k in range(0, 12)]
QUICK_DIVISIONS = [2, 8]
#: output rows over the run (the errors are sampled there; attitude errors grow smoothly)
N_OUTPUT = 50
QUICK_N_OUTPUT = 10
#: reference: DOP853 at this rtol (atol a hundredth of it); cross-checked with CROSS_INTEGRATOR
REF_RTOL = 1e-13
QUICK_REF_RTOL = 1e-11
CROSS_INTEGRATOR = "scipy_dop853"
#: wall-time repeats per point (median reported); runs shorter than a few ms are repeated
#: until they add up to MIN_TIMED_S (at most MAX_REPEATS): sub-ms timings on a shared machine
#: are noisy
REPEATS = 3
MIN_TIMED_S = 0.05
MAX_REPEATS = 15
#: stop refining a method once one run takes longer than this [s] (keeps the study to minutes)
WALL_BUDGET_S = 2.0
QUICK_WALL_BUDGET_S = 0.5
#: accuracy targets of the cheapest-method table [rad]
TARGETS_RAD = (1e-3, 1e-6, 1e-9)
#: the CSV's columns
COLUMNS = ["formulation", "integrator", "kind", "rtol", "step_s", "status", "att_err_rad",
           "rate_err_rad_s", "wall_s", "n_rhs", "n_steps"]


@dataclass
class PrecisionResult:
    """What :func:`precision_study` measured and wrote.

    Attributes
    ----------
    scene : str
        The scene's name.
    duration : float
        Length of every run [s].
    rows : list of dict
        One per formulation x integrator x setting, keyed by ``COLUMNS`` (errors in rad and
        rad/s, ``inf`` when the run did not finish; wall time [s], NaN then).
    reference : dict
        ``method``, ``cross_method``, and the cross-check's errors ``cross_att_rad`` [rad] and
        ``cross_rate_rad_s`` [rad/s] (the reference's own accuracy).
    cheapest : list of dict
        Per target in ``TARGETS_RAD``: the method with the least wall time reaching it
        (``integrator`` None: none did).
    files : list of Path
        The CSV, the two charts and the Markdown table.
    """

    scene: str
    duration: float
    rows: list[dict]
    reference: dict
    cheapest: list[dict]
    files: list[Path] = field(default_factory=list)

    def table(self) -> str:
        """The cheapest-method table as Markdown."""
        lines = [
            f"cheapest method (median wall time) reaching each attitude accuracy on {self.scene}, "
            f"{self.duration:g} s (reference {self.reference['method']}, cross-check "
            f"{self.reference['cross_method']}: {self.reference['cross_att_rad']:.2g} rad):",
            "",
            "| target [rad] | formulation | integrator | setting | att. error [rad] | wall [s] | RHS evals |",
            "|---:|---|---|---|---:|---:|---:|",
        ]
        for c in self.cheapest:
            if c["integrator"] is None:
                lines.append(f"| {c['target_rad']:.0e} | — | none reached it | | | | |")
                continue
            note = " (below the reference's cross-check)" if c["target_rad"] < 10 * self.reference["cross_att_rad"] else ""
            lines.append(
                f"| {c['target_rad']:.0e} | {c['formulation']} | {c['integrator']} | {c['setting']} | "
                f"{c['att_err_rad']:.2g}{note} | {c['wall_s']:.3g} | {c['n_rhs']} |"
            )
        return "\n".join(lines)


def _setting(adaptive: bool, value: float) -> str:
    """A sweep point in words: ``rtol 1e-06`` or ``step 0.5 s``."""
    return f"rtol {value:.0e}" if adaptive else f"step {value:.4g} s"


def _setting_label(row) -> str:
    adaptive = row["kind"] == "adaptive"
    return _setting(adaptive, row["rtol"] if adaptive else row["step_s"])


def precision_study(
    scene: Scene | str | Path,
    *,
    out: Path | str,
    duration: float | None = None,
    formulations=None,
    integrators=None,
    quick: bool = False,
    repeats: int | None = None,
    log=progress.echo,
) -> PrecisionResult:
    """Work-precision diagram of one scene (of the closed loop's own choices when the scene has a
    ``[controller]``: :func:`~.precision_loop.loop_precision`, a ``LoopPrecisionResult``).

    For each formulation x integrator x setting: the largest attitude error [rad] and rate error
    [rad/s] against the reference over ``N_OUTPUT`` rows, the median wall time [s] of ``repeats``
    runs (compilation excluded) and the RHS evaluations. A method's sweep stops when it is
    below the reference's own accuracy or when one run exceeds the wall-time budget.

    Parameters
    ----------
    scene : Scene or path
    out : path
        Folder for ``precision.csv``, ``precision.png``, ``precision_rate.png`` and
        ``precision_cheapest.md`` (created if missing).
    duration : float, optional
        Length of every run [s]; default the scene's.
    formulations, integrators : list of str, optional
        Default: every registered one.
    quick : bool
        A small sweep (``QUICK_RTOLS``, ``QUICK_DIVISIONS``), one repeat, a looser reference.
    repeats : int, optional
        Timed runs per point (default ``REPEATS``, quick 1).
    log : callable
        Receives one result line per run (default: stdout, above any progress bar). Progress
        itself (per method and setting) goes to :mod:`stationbed.core.progress`.

    Returns
    -------
    PrecisionResult

    Raises
    ------
    StudyError
        matplotlib is missing.
    ValueError
        An unknown formulation or integrator name.
    """
    plt = pyplot()
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    duration = float(duration or scene.simulation.duration)
    if scene.controller is not None:  # the closed loop's own choices (issue 25): precision_loop.py
        from .precision_loop import loop_precision

        if integrators is not None:
            raise ValueError(f"--integrators: {scene.name} has a [controller]: its study sweeps RK4 sub-steps per tick "
                             "and the environment's rate against DOP853 (no integrator to choose)")

        return loop_precision(scene, out, duration, formulations=formulations, quick=quick, repeats=repeats,
                              log=log, plt=plt)
    forms = registered_formulations(formulations)
    integs = registered_integrators(integrators)
    with progress.task("study precision", total=len(integs) * len(forms), unit="methods") as bar:
        return _precision(scene, out, duration, forms, integs, quick, repeats, log, plt, bar)


def _precision(scene, out, duration, forms, integs, quick, repeats, log, plt, bar) -> PrecisionResult:
    """:func:`precision_study` once its arguments are checked; ``bar`` is its progress task."""
    n_out = QUICK_N_OUTPUT if quick else N_OUTPUT
    output_dt = duration / n_out
    repeats = repeats or (1 if quick else REPEATS)
    budget = QUICK_WALL_BUDGET_S if quick else WALL_BUDGET_S
    common = {"duration": duration, "output_dt": output_dt}

    # reference, and its cross-check by a second method (another formulation when there is one)
    ref_rtol = QUICK_REF_RTOL if quick else REF_RTOL
    ref_form = "momentum" if "momentum" in FORMULATIONS else forms[0]
    bar.update(0, f"reference dop853/{ref_form} rtol {ref_rtol:.0e}")
    ref = simulate(scene, formulation=ref_form, integrator="dop853", rtol=ref_rtol, atol=ref_rtol / 100, **common)
    cross_form = next((f for f in FORMULATIONS if f != ref_form), ref_form)
    bar.update(0, f"cross-check {CROSS_INTEGRATOR}/{cross_form} rtol {ref_rtol:.0e}")
    cross = simulate(scene, formulation=cross_form, integrator=CROSS_INTEGRATOR, rtol=ref_rtol, atol=ref_rtol / 100, **common)
    cross_att, cross_rate = max_errors(cross, ref)
    reference = {
        "method": f"dop853/{ref_form} rtol {ref_rtol:.0e}",
        "cross_method": f"{CROSS_INTEGRATOR}/{cross_form} rtol {ref_rtol:.0e}",
        "cross_att_rad": cross_att,
        "cross_rate_rad_s": cross_rate,
    }
    log(f"reference {reference['method']}; cross-check {reference['cross_method']}: "
        f"{cross_att:.3g} rad, {cross_rate:.3g} rad/s")
    floor = max(cross_att, 1e-14)

    rows: list[dict] = []
    n_methods, k = len(integs) * len(forms), 0
    for integ, cls in integs.items():
        kind = "adaptive" if cls.adaptive else "fixed"
        values = (QUICK_RTOLS if quick else ADAPTIVE_RTOLS) if cls.adaptive else [
            output_dt / m for m in (QUICK_DIVISIONS if quick else FIXED_DIVISIONS)
        ]
        for form in forms:
            k += 1
            for v in values:
                kw = sweep_setting(cls, v)
                bar.update(k - 1, f"method {k}/{n_methods} {integ}/{form} {_setting(cls.adaptive, v)}")
                walls, tr, status = [], None, "ok"
                # at least `repeats` runs; short runs repeat until they add up to MIN_TIMED_S
                while len(walls) < repeats or (not quick and sum(walls) < MIN_TIMED_S and len(walls) < MAX_REPEATS):
                    tr, status = try_simulate(scene, form, integ, **kw, **common)
                    if status != "ok":
                        break
                    walls.append(tr.meta["wall_s"])
                row = {
                    "formulation": form, "integrator": integ, "kind": kind,
                    "rtol": v if cls.adaptive else math.nan, "step_s": math.nan if cls.adaptive else v,
                    "status": status, "att_err_rad": math.inf, "rate_err_rad_s": math.inf,
                    "wall_s": math.nan, "n_rhs": -1, "n_steps": -1,
                }
                if status == "ok":
                    att, rate = max_errors(tr, ref)
                    row.update(att_err_rad=att, rate_err_rad_s=rate, wall_s=statistics.median(walls),
                               n_rhs=int(tr.meta.get("n_rhs", -1)), n_steps=int(tr.meta.get("n_steps", -1)))
                rows.append(row)
                log(f"  {form:<11} {integ:<13} {_setting_label(row):<16} {status[:60]:<10} "
                    f"att {row['att_err_rad']:.3g} rad  wall {row['wall_s']:.3g} s  rhs {row['n_rhs']}")
                if status.startswith("skipped"):
                    break  # the method refuses this scene: no point sweeping further
                if status == "ok" and (row["att_err_rad"] < floor or row["wall_s"] > budget):
                    break
    bar.update(n_methods, "charts")

    csv_path = out / "precision.csv"
    write_csv(csv_path, COLUMNS, [[r[c] for c in COLUMNS] for r in rows])

    cheapest = []
    ok = [r for r in rows if r["status"] == "ok" and math.isfinite(r["att_err_rad"])]
    for target in TARGETS_RAD:
        cand = [r for r in ok if r["att_err_rad"] <= target]
        if not cand:
            cheapest.append({"target_rad": target, "formulation": None, "integrator": None})
            continue
        b = min(cand, key=lambda r: r["wall_s"])
        cheapest.append({"target_rad": target, "formulation": b["formulation"], "integrator": b["integrator"],
                         "setting": _setting_label(b), "att_err_rad": b["att_err_rad"],
                         "wall_s": b["wall_s"], "n_rhs": b["n_rhs"]})
    res = PrecisionResult(scene.name, duration, rows, reference, cheapest)
    md = out / "precision_cheapest.md"
    md.write_text(res.table() + "\n")
    png = out / "precision.png"
    _plot_precision(plt, res, "att_err_rad", "max attitude error [rad]", png, forms, list(integs))
    png_rate = out / "precision_rate.png"
    _plot_precision(plt, res, "rate_err_rad_s", "max rate error [rad/s]", png_rate, forms, list(integs))
    res.files = [csv_path, png, png_rate, md]
    return res


def _plot_precision(plt, res: PrecisionResult, ycol: str, ylabel: str, path: Path, forms, integs) -> None:
    """Error ``ycol`` against wall time (left) and RHS evaluations (right): colour per
    integrator, marker and line style per formulation."""
    from matplotlib.lines import Line2D

    icol = colours(plt, integs)
    fig, axes = plt.subplots(1, 2, figsize=(14, 6), constrained_layout=True)
    for ax, xcol, xlabel in ((axes[0], "wall_s", "wall time per run (median) [s]"),
                             (axes[1], "n_rhs", "right-hand-side evaluations")):
        for integ in integs:
            for j, form in enumerate(forms):
                pts = [r for r in res.rows if r["integrator"] == integ and r["formulation"] == form
                       and r["status"] == "ok" and math.isfinite(r[ycol]) and r[xcol] > 0]
                if not pts:
                    continue
                x = [r[xcol] for r in pts]
                y = [max(r[ycol], 1e-16) for r in pts]
                ax.plot(x, y, color=icol[integ], marker=MARKERS[j % len(MARKERS)],
                        linestyle=STYLES[j % len(STYLES)], markersize=5, linewidth=1.2)
        if ycol == "att_err_rad":
            for tgt in TARGETS_RAD:
                ax.axhline(tgt, color="0.6", linestyle=":", linewidth=0.8)
            ax.axhline(res.reference["cross_att_rad"], color="red", linestyle="--", linewidth=0.9)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_title(f"{res.scene}, {res.duration:g} s: error vs wall time")
    axes[1].set_title("error vs cost in RHS evaluations")
    shown = {r["integrator"] for r in res.rows if r["status"] == "ok"}
    handles = [Line2D([], [], color=icol[i], linewidth=2, label=i if i in shown else f"{i} (skipped/failed)")
               for i in integs]
    handles += [Line2D([], [], color="k", marker=MARKERS[j % len(MARKERS)], linestyle=STYLES[j % len(STYLES)],
                       label=f) for j, f in enumerate(forms)]
    if ycol == "att_err_rad":
        handles.append(Line2D([], [], color="red", linestyle="--", label="reference cross-check"))
        handles.append(Line2D([], [], color="0.6", linestyle=":", label="targets 1e-3/1e-6/1e-9"))
    fig.legend(handles=handles, loc="outside right upper", fontsize=9, title="integrator / formulation")
    fig.savefig(path, dpi=110)
    plt.close(fig)
