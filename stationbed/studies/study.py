"""Work-precision and stability studies (``stationbed study precision|stability``).

Both studies run over whatever is registered in :data:`stationbed.integrators.INTEGRATORS` when
they start (adaptive integrators swept over tolerances, fixed-step ones over step sizes), so a
newly registered integrator appears in every chart without a change here. An integrator that
refuses a scene (``ValueError``, e.g. a rigid-body-only method on an articulated scene) is
listed as *skipped* with its reason; one that fails part-way is listed as *failed*.

``precision_study``
    Every formulation x integrator x setting on one scene against a reference solution (the
    tightest DOP853 run, cross-checked with a second method and formulation); CSV + PNG + a
    table of the cheapest method reaching 1e-3, 1e-6 and 1e-9 rad.
``stability_study``
    Seven cases where methods fail, each with a detector, a verdict per method, a CSV and a PNG.

Tolerances are dimensionless as in scene files (``atol`` in units of the scene's characteristic
rate or momentum, docs/design.md): the sweeps use ``atol = rtol``. matplotlib (extra ``plot``)
is imported only when a chart is drawn, with the Agg backend.
"""

from __future__ import annotations

import csv
import math
import statistics
import time
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.environment import C_ON
from ..formulations import FORMULATIONS
from ..model import Structure
from ..integrators import INTEGRATORS
from ..core.rotation import dcm, rotation_angle
from ..scene import Cmg, Scene, load_scene, scene_from_dict
from ..run.initial import characteristic_scales, initial_state, initial_x
from ..run.simulation import SimulationError, simulate
from ..run.system import build_system
from ..core.beam import beam_mode
from ..core.compile import FastCall
from ..run.trajectory import Trajectory

__all__ = ["StudyError", "precision_study", "stability_study", "STABILITY_CASES", "PrecisionResult", "Case"]

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

# ---------------------------------------------------------------------------------------
# precision study settings
# ---------------------------------------------------------------------------------------

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
#: colours per integrator, markers per formulation
_MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]
_STYLES = ["-", "--", ":", "-."]


class StudyError(RuntimeError):
    """A study could not run (missing optional dependency, missing scenario file)."""


def _pyplot():
    """matplotlib's pyplot on the Agg backend (files only), or a clear error if missing."""
    try:
        import matplotlib
    except ImportError:
        raise StudyError(
            "the studies draw their charts with matplotlib, which is not installed: "
            "pip install 'stationbed[plot]' (or pip install matplotlib)"
        ) from None
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _integrators(names=None) -> dict:
    """The registered integrators (now, not at import), or the named subset in that order."""
    if names is None:
        return dict(INTEGRATORS)
    unknown = [n for n in names if n not in INTEGRATORS]
    if unknown:
        raise ValueError(f"unknown integrator {unknown[0]!r}; valid: {', '.join(sorted(INTEGRATORS))}")
    return {n: INTEGRATORS[n] for n in names}


def _formulations(names=None) -> list[str]:
    if names is None:
        return list(FORMULATIONS)
    unknown = [n for n in names if n not in FORMULATIONS]
    if unknown:
        raise ValueError(f"unknown formulation {unknown[0]!r}; valid: {', '.join(sorted(FORMULATIONS))}")
    return list(names)


def _setting(cls, value) -> dict:
    """simulate() keywords of one sweep point: rtol (adaptive) or step [s] (fixed)."""
    return {"rtol": value, "atol": value} if cls.adaptive else {"step": value}


def _try(scene, form, integ, **kw) -> tuple[Trajectory | None, str]:
    """``(trajectory, status)``: status ``ok``, ``skipped: why`` (refused) or ``failed: why``."""
    try:
        tr = simulate(scene, formulation=form, integrator=integ, **kw)
    except (ValueError, NotImplementedError) as e:
        return None, f"skipped: {_one_line(e)}"
    except SimulationError as e:
        return e.trajectory, f"failed: {_one_line(e)}"
    except (ArithmeticError, RuntimeError, np.linalg.LinAlgError) as e:  # a method that breaks down
        return None, f"failed: {type(e).__name__}: {_one_line(e)}"
    if not np.all(np.isfinite(tr.data[:, :12])):  # t, q, ω, H_O_N, T (att_err_deg may be NaN)
        return tr, "failed: non-finite output"
    return tr, "ok"


def _one_line(e) -> str:
    s = " ".join(str(e).split())
    return s[:200]


def _write_csv(path: Path, header: list[str], rows: list) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([_fmt(v) for v in r])


def _fmt(v):
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return v


def _errors(tr: Trajectory, ref: Trajectory) -> tuple[float, float]:
    """Max attitude error [rad] and max rate error [rad/s] over the common rows."""
    n = min(len(tr), len(ref))
    if n == 0 or len(tr) != len(ref) or not np.allclose(tr.t[:n], ref.t[:n], rtol=0, atol=1e-9 * max(1.0, ref.t[-1])):
        return math.inf, math.inf
    att = rotation_angle(tr.q_BN, ref.q_BN)
    rate = np.linalg.norm(tr.omega_BN_B - ref.omega_BN_B, axis=1)
    return float(att.max()), float(rate.max())


# ---------------------------------------------------------------------------------------
# work-precision
# ---------------------------------------------------------------------------------------


@dataclass
class PrecisionResult:
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


def _setting_label(row) -> str:
    return f"rtol {row['rtol']:.0e}" if row["kind"] == "adaptive" else f"step {row['step_s']:.4g} s"


def precision_study(
    scene: Scene | str | Path,
    *,
    out: Path | str,
    duration: float | None = None,
    formulations=None,
    integrators=None,
    quick: bool = False,
    repeats: int | None = None,
    log=print,
) -> PrecisionResult:
    """Work-precision diagram of one scene; writes ``precision.csv``, ``precision.png``,
    ``precision_rate.png`` and ``precision_cheapest.md`` into ``out``.

    For each formulation x integrator x setting: the largest attitude error [rad] and rate error
    [rad/s] against the reference over ``N_OUTPUT`` rows, the median wall time [s] of ``repeats``
    runs (compilation excluded) and the RHS evaluations. A method's sweep stops when it is
    below the reference's own accuracy or when one run exceeds the wall-time budget.
    """
    plt = _pyplot()
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    duration = float(duration or scene.simulation.duration)
    forms = _formulations(formulations)
    integs = _integrators(integrators)
    n_out = QUICK_N_OUTPUT if quick else N_OUTPUT
    output_dt = duration / n_out
    repeats = repeats or (1 if quick else REPEATS)
    budget = QUICK_WALL_BUDGET_S if quick else WALL_BUDGET_S
    common = {"duration": duration, "output_dt": output_dt}

    # reference, and its cross-check by a second method (another formulation when there is one)
    ref_rtol = QUICK_REF_RTOL if quick else REF_RTOL
    ref_form = "momentum" if "momentum" in FORMULATIONS else forms[0]
    ref = simulate(scene, formulation=ref_form, integrator="dop853", rtol=ref_rtol, atol=ref_rtol / 100, **common)
    cross_form = next((f for f in FORMULATIONS if f != ref_form), ref_form)
    cross = simulate(scene, formulation=cross_form, integrator=CROSS_INTEGRATOR, rtol=ref_rtol, atol=ref_rtol / 100, **common)
    cross_att, cross_rate = _errors(cross, ref)
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
    for integ, cls in integs.items():
        kind = "adaptive" if cls.adaptive else "fixed"
        values = (QUICK_RTOLS if quick else ADAPTIVE_RTOLS) if cls.adaptive else [
            output_dt / m for m in (QUICK_DIVISIONS if quick else FIXED_DIVISIONS)
        ]
        for form in forms:
            for v in values:
                kw = _setting(cls, v)
                walls, tr, status = [], None, "ok"
                # at least `repeats` runs; short runs repeat until they add up to MIN_TIMED_S
                while len(walls) < repeats or (not quick and sum(walls) < MIN_TIMED_S and len(walls) < MAX_REPEATS):
                    tr, status = _try(scene, form, integ, **kw, **common)
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
                    att, rate = _errors(tr, ref)
                    row.update(att_err_rad=att, rate_err_rad_s=rate, wall_s=statistics.median(walls),
                               n_rhs=int(tr.meta.get("n_rhs", -1)), n_steps=int(tr.meta.get("n_steps", -1)))
                rows.append(row)
                log(f"  {form:<11} {integ:<13} {_setting_label(row):<16} {status[:60]:<10} "
                    f"att {row['att_err_rad']:.3g} rad  wall {row['wall_s']:.3g} s  rhs {row['n_rhs']}")
                if status.startswith("skipped"):
                    break  # the method refuses this scene: no point sweeping further
                if status == "ok" and (row["att_err_rad"] < floor or row["wall_s"] > budget):
                    break

    cols = ["formulation", "integrator", "kind", "rtol", "step_s", "status", "att_err_rad",
            "rate_err_rad_s", "wall_s", "n_rhs", "n_steps"]
    csv_path = out / "precision.csv"
    _write_csv(csv_path, cols, [[r[c] for c in cols] for r in rows])

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


def _colours(plt, names):
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    return {n: cmap(i % cmap.N) for i, n in enumerate(names)}


def _plot_precision(plt, res: PrecisionResult, ycol: str, ylabel: str, path: Path, forms, integs) -> None:
    from matplotlib.lines import Line2D

    colours = _colours(plt, integs)
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
                ax.plot(x, y, color=colours[integ], marker=_MARKERS[j % len(_MARKERS)],
                        linestyle=_STYLES[j % len(_STYLES)], markersize=5, linewidth=1.2)
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
    handles = [Line2D([], [], color=colours[i], linewidth=2, label=i if i in shown else f"{i} (skipped/failed)")
               for i in integs]
    handles += [Line2D([], [], color="k", marker=_MARKERS[j % len(_MARKERS)], linestyle=_STYLES[j % len(_STYLES)],
                       label=f) for j, f in enumerate(forms)]
    if ycol == "att_err_rad":
        handles.append(Line2D([], [], color="red", linestyle="--", label="reference cross-check"))
        handles.append(Line2D([], [], color="0.6", linestyle=":", label="targets 1e-3/1e-6/1e-9"))
    fig.legend(handles=handles, loc="outside right upper", fontsize=9, title="integrator / formulation")
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------
# stability study
# ---------------------------------------------------------------------------------------


@dataclass
class Case:
    """One stability case: what it detects, a verdict per method, and its files."""

    name: str
    title: str
    detector: str
    verdicts: list[dict] = field(default_factory=list)  # method, value, unit, verdict
    files: list[Path] = field(default_factory=list)

    def add(self, method: str, value: float, unit: str, verdict: str) -> None:
        self.verdicts.append({"method": method, "value": value, "unit": unit, "verdict": verdict})


@dataclass
class _Ctx:
    out: Path
    quick: bool
    plt: object
    log: object


#: ISS inertia (JEOD, with its products of inertia) [kg m²]: the rigid scenes of the study
_ISS_INERTIA = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]
_ORBIT = {"radius": 6778137.0, "inclination": 0.9006, "u0": 0.0, "gravity_gradient": True}  # 400 km, 51.6 deg


def _tumble_scene(duration: float, output_dt: float) -> Scene:
    """A rigid ISS tumbling torque-free in deep space (|ω| = 1.4 mrad/s): T and H_N constant."""
    return scene_from_dict({
        "name": "study_tumble",
        "simulation": {"duration": duration, "output_dt": output_dt},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [1.0e-3, -0.6e-3, 0.8e-3]},
        "body": {"mass": 4.0e5, "inertia": _ISS_INERTIA, "cm": [0.0, 0.0, 0.0]},
    }, source="study tumble scene")


def _gg_scene(duration: float, output_dt: float) -> Scene:
    """A rigid ISS in a circular orbit with gravity gradient, 0.1 rad off LVLH: the Jacobi
    integral is constant (see :func:`jacobi_integral`)."""
    return scene_from_dict({
        "name": "study_gravity_gradient",
        "simulation": {"duration": duration, "output_dt": output_dt},
        "initial": {"frame": "lvlh", "q_BN": [math.cos(0.05), math.sin(0.05), 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 4.0e5, "inertia": _ISS_INERTIA, "cm": [0.0, 0.0, 0.0]},
        "orbit": dict(_ORBIT),
    }, source="study gravity-gradient scene")


def jacobi_integral(scene: Scene, tr: Trajectory) -> np.ndarray:
    """The Jacobi integral of a rigid body in a circular orbit with gravity gradient [J].

    In LVLH (rotating at ω_ON = -n y_O) the energy of the relative motion is conserved:
    ``J = ½ ω_BOᵀ I ω_BO - ½ n² y_Bᵀ I y_B + (3/2) n² z_Bᵀ I z_B`` (kinetic energy of the motion
    relative to LVLH, the centrifugal term about the orbit normal y_O, the gravity-gradient
    potential along the radial z_O; y_B, z_B the LVLH axes in B). Rigid body only.
    """
    o = scene.orbit
    n = o.mean_motion
    I = np.array(scene.body.inertia)
    J = np.empty(len(tr))
    for k, (t, q, w) in enumerate(zip(tr.t, tr.q_BN, tr.omega_BN_B)):
        C_BO = dcm(q) @ C_ON(o.u0 + n * t, o.inclination).T
        w_BO = w - C_BO @ np.array([0.0, -n, 0.0])
        y_B, z_B = C_BO[:, 1], C_BO[:, 2]
        J[k] = 0.5 * w_BO @ I @ w_BO - 0.5 * n**2 * y_B @ I @ y_B + 1.5 * n**2 * z_B @ I @ z_B
    return J


#: log-log slope of the error's running maximum above which an error grows secularly (linear
#: drift gives 1, a bounded oscillating error ~0, round-off's random walk ~0.5)
DRIFT_SLOPE = 0.7
#: relative errors below this are float64 round-off over ~10⁵ steps (eps sqrt(N) x a few)
ROUNDOFF_REL = 1e-12


def growth(t: np.ndarray, err: np.ndarray) -> tuple[float, float]:
    """``(slope, final)``: log-log slope of the running max of ``err`` over the last 90 % of
    the run (detector of secular growth) and its final value."""
    env = np.maximum.accumulate(np.maximum(np.abs(err), 1e-300))
    sel = t >= 0.1 * t[-1]
    sel &= env > 0
    if sel.sum() < 3:
        return 0.0, float(env[-1])
    p = np.polyfit(np.log(t[sel]), np.log(np.maximum(env[sel], 1e-30)), 1)[0]
    return float(p), float(env[-1])


def growth_verdict(slope: float, final: float) -> str:
    if final < ROUNDOFF_REL:
        return "at round-off"
    return f"drifts (slope {slope:.2f})" if slope > DRIFT_SLOPE else f"bounded (slope {slope:.2f})"


# -- 1. array rate step ----------------------------------------------------------------

#: an H_O_N change across a rate step above this (relative) is a lost impulse: 10⁴ x the
#: scene's rtol (1e-10), and 3e4 x below the impulse itself (3 % of |H|)
H_JUMP_REL = 1e-6


def _case_rate_step(ctx: _Ctx) -> Case:
    case = Case("rate_step", "array rate step (impulse): H_O_N across the step",
                "|H_O_N(after) - H_O_N(before)| / |H_O_N| at each rate step")
    scene = load_scene(_scenario("array_rate_step.toml"))
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
        tr, status = _try(sc, f, None, duration=duration)
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
        style = _STYLES[list(FORMULATIONS).index(f) % len(_STYLES)]  # equal curves of two forms stay visible
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
    _save(ctx, case, fig, rows, ["variant", "t_s", "dH_rel"])
    return case


def _scenario(name: str) -> Path:
    p = SCENARIOS / name
    if not p.is_file():
        raise StudyError(f"the stability study needs {p} (run it from a stationbed checkout)")
    return p


def _save(ctx: _Ctx, case: Case, fig, rows, header) -> None:
    png = ctx.out / f"stability_{case.name}.png"
    fig.savefig(png, dpi=110)
    ctx.plt.close(fig)
    csv_path = ctx.out / f"stability_{case.name}.csv"
    _write_csv(csv_path, header, rows)
    case.files += [csv_path, png]


# -- 2. long horizon ---------------------------------------------------------------------

LONG_ORBITS = 100
QUICK_LONG_ORBITS = 3
#: adaptive methods run at this rtol, fixed-step ones at this step [s] (n h = 0.07, |ω| h = 0.08)
LONG_RTOL = 1e-8
LONG_STEP_S = 60.0


def _long_setting(cls) -> dict:
    return _setting(cls, LONG_RTOL if cls.adaptive else LONG_STEP_S)


def _long_label(name, cls) -> str:
    return f"{name} (rtol {LONG_RTOL:g})" if cls.adaptive else f"{name} (h {LONG_STEP_S:g} s)"


def _case_long_horizon(ctx: _Ctx) -> Case:
    n_orb = QUICK_LONG_ORBITS if ctx.quick else LONG_ORBITS
    n = math.sqrt(3.986004418e14 / _ORBIT["radius"] ** 3)
    T_orb = 2 * math.pi / n
    duration, output_dt = n_orb * T_orb, T_orb / 10
    case = Case("long_horizon", f"long horizon ({n_orb} orbits): energy and momentum error growth",
                "log-log slope of the running max of the invariant's error (1: drift, 0: bounded)")
    tumble, gg = _tumble_scene(duration, output_dt), _gg_scene(duration, output_dt)
    plt = ctx.plt
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.5), constrained_layout=True)
    integs = _integrators()
    colours = _colours(plt, list(integs))
    rows, walls = [], {}
    for name, cls in integs.items():
        label = _long_label(name, cls)
        for sc, panels in ((tumble, ("T", "H")), (gg, ("J",))):
            tr, status = _try(sc, "momentum", name, **_long_setting(cls))
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
                ax.semilogy(t_orb[1:], np.maximum(e[1:], 1e-17), color=colours[name], linewidth=1)
                walls[name] = walls.get(name, 0.0) + wall
    titles = {"T": "torque-free tumble: kinetic energy", "H": "torque-free tumble: |ΔH_O_N|",
              "J": "gravity gradient in orbit: Jacobi integral"}
    for pn, ax in zip("THJ", axes):
        ax.set_title(titles[pn])
        ax.set_xlabel("time [orbits of 92.6 min]")
        ax.set_ylabel("relative error of the invariant [-]")
        ax.grid(True, alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colours[nm], linewidth=2,
                      label=f"{_long_label(nm, c)}, {walls[nm]:.2g} s" if nm in walls else f"{nm} (failed)")
               for nm, c in integs.items()]
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title="integrator, wall time of both runs")
    _save(ctx, case, fig, rows, ["integrator", "invariant", "t_orbits", "rel_error"])
    return case


_INV = {"T": "energy", "H": "momentum", "J": "Jacobi integral"}


# -- 3. Dzhanibekov flips ------------------------------------------------------------------

#: a rigid body spun about its intermediate axis (0.1 rad/s) with 1e-3 rad/s off-axis: it
#: flips every ~290 s (first at 177 s)
_FLIP_SCENE = {
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


def flip_times(tr: Trajectory) -> np.ndarray:
    """Times [s] at which the intermediate-axis rate ω_y changes sign (one per flip)."""
    from scipy.interpolate import CubicSpline

    roots = CubicSpline(tr.t, tr["wy"]).roots(extrapolate=False)
    return np.unique(np.round(roots[np.isfinite(roots)], 9))


def _case_dzhanibekov(ctx: _Ctx) -> Case:
    d = dict(_FLIP_SCENE, simulation=dict(_FLIP_SCENE["simulation"]))
    if ctx.quick:
        d["simulation"]["duration"] = 500.0
    scene = scene_from_dict(d, source="study Dzhanibekov scene")
    ref = simulate(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    t_ref = flip_times(ref)
    gap = float(np.mean(np.diff(t_ref))) if t_ref.size > 1 else scene.simulation.duration
    tol = FLIP_TOL_FRACTION * gap
    case = Case("dzhanibekov", "intermediate-axis flips: flip timing vs step size",
                f"max |t_flip - t_flip,ref| over the {t_ref.size} reference flips; lost above {tol:.3g} s "
                f"({FLIP_TOL_FRACTION:.0%} of the {gap:.3g} s between flips) or when a flip is missing")
    plt = ctx.plt
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(15, 5.5), constrained_layout=True)
    ax0.plot(ref.t, ref["wy"], color="k", linewidth=2, label="reference (DOP853 rtol 1e-12)")
    fixed = {n: c for n, c in _integrators().items() if not c.adaptive}
    colours = _colours(plt, list(fixed))
    rows = []
    steps = QUICK_FLIP_STEPS_S if ctx.quick else FLIP_STEPS_S
    for name in fixed:
        errs, lose, shown, skipped = [], None, False, None
        for h in steps:
            tr, status = _try(scene, "momentum", name, step=h, output_dt=h)
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
                    ax0.plot(tr.t, tr["wy"], color=colours[name], linewidth=1, label=f"{name}, h = {h:g} s (timing lost)")
                    shown = True
        if skipped:
            case.add(name, math.nan, "s", skipped)
            continue
        fin = [(h, e) for h, e in zip(steps, errs) if math.isfinite(e)]
        if fin:
            ax1.loglog([h for h, _ in fin], [max(e, 1e-6) for _, e in fin], marker="o", color=colours[name], label=name)
        lost = [h for h, e in zip(steps, errs) if not math.isfinite(e)]
        if lost:
            ax1.plot(lost, [gap] * len(lost), "x", color=colours[name], markersize=9)
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
    _save(ctx, case, fig, rows, ["integrator", "step_s", "max_flip_time_err_s", "status"])
    return case


# -- 4. largest stable fixed step on articulated_stress -------------------------------------

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


def _case_max_step(ctx: _Ctx) -> Case:
    scene = load_scene(_scenario("articulated_stress.toml"))
    duration = 200.0 if ctx.quick else scene.simulation.duration
    case = Case("max_step", f"largest stable fixed step on articulated_stress ({duration:g} s)",
                f"run fails on blow-up, attitude error > {STABLE_ATT_RAD} rad vs DOP853 rtol 1e-11, "
                f"or |ΔH_O_N|/|H| > {STABLE_H_REL:g}; doubling scan, then geometric bisection")
    fixed = {n: c for n, c in _integrators().items() if not c.adaptive}
    plt = ctx.plt
    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    colours = _colours(plt, list(fixed))
    rows = []

    def run(form, name, h):
        dt = h * max(1, round(MAX_STEP_OUTPUT_DT_S / h))  # rows every ~5 s, a whole number of steps
        tr, status = _try(scene, form, name, step=h, output_dt=dt, duration=duration)
        if status.startswith("skipped"):
            return None, math.nan, status
        if tr is None or status != "ok" or len(tr) < 2:
            return False, math.inf, status
        ref = simulate(scene, formulation=form, integrator="dop853", rtol=1e-11, atol=1e-13, output_dt=dt, duration=duration)
        att, _ = _errors(tr, ref)
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
            ax.loglog([p[0] for p in pts], [min(max(p[1], 1e-12), 10.0) for p in pts], color=colours[name],
                      linestyle=_STYLES[j % len(_STYLES)], marker=_MARKERS[j % len(_MARKERS)], markersize=4,
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
    _save(ctx, case, fig, rows, ["formulation", "integrator", "step_s", "att_err_rad", "passed", "why"])
    return case


# -- 5. quaternion norm ------------------------------------------------------------------------

NORM_ORBITS = 20
QUICK_NORM_ORBITS = 1


def raw_states(scene: Scene, formulation: str, integrator: str, ts: np.ndarray, project: bool = False, **kw) -> np.ndarray:
    """The integrator's own states at ``ts`` (the trajectory normalises q; this does not).

    Smooth scenes only (no controller, no discontinuity): the same set-up as ``simulate``.
    With ``project=True`` the run advances one step at a time (fixed-step integrators) and
    normalises q after every step; the rows then hold q *before* that projection.
    """
    system = build_system(Structure.of(scene), formulation, integrator)
    form, funcs = system.formulation, system.funcs
    model = form.model
    p = model.params(scene)
    q0, w0 = initial_state(scene)
    xe0 = model.initial_extra(scene, q0, p)
    atol = form.atol_vector(kw.get("atol", scene.simulation.atol), *characteristic_scales(scene, w0, model, p))
    integ = system.integrator_cls(funcs, p, form.nx, rtol=kw.get("rtol", scene.simulation.rtol), atol=atol,
                                  step=kw.get("step"), max_step=None)
    init = FastCall.of(funcs["init"])
    init.args[0][0] = 0.0
    for a, v in zip(init.args[1:], (q0, w0, xe0, p)):
        a[:] = v
    init()
    x = init.res[0].copy()
    u = np.zeros(model.nu)
    if not project:
        return integ.integrate(ts, x, u)
    out = np.empty((ts.size, x.size))
    out[0] = x
    for i in range(1, ts.size):
        n = max(1, math.ceil((ts[i] - ts[i - 1]) / kw["step"] - 1e-9))
        for k in range(n):
            t0 = ts[i - 1] + (ts[i] - ts[i - 1]) * k / n
            t1 = ts[i - 1] + (ts[i] - ts[i - 1]) * (k + 1) / n
            x = integ.advance(t0, t1, x, u)
            q_before = x[:4].copy()
            x[:4] /= np.linalg.norm(x[:4])
        out[i] = x
        out[i, :4] = q_before
    return out


def _case_quat_norm(ctx: _Ctx) -> Case:
    n = math.sqrt(3.986004418e14 / _ORBIT["radius"] ** 3)
    T_orb = 2 * math.pi / n
    n_orb = QUICK_NORM_ORBITS if ctx.quick else NORM_ORBITS
    scene = _tumble_scene(n_orb * T_orb, T_orb / 10)
    ts = np.linspace(0.0, n_orb * T_orb, 10 * n_orb + 1)
    case = Case("quat_norm", f"quaternion norm drift, torque-free tumble ({n_orb} orbits), with and without projection",
                "max ||q| - 1| of the integrator's own state, and the log-log slope of its growth")
    plt = ctx.plt
    fig, ax = plt.subplots(figsize=(13, 5.5), constrained_layout=True)
    integs = _integrators()
    colours = _colours(plt, list(integs))
    rows = []
    for name, cls in integs.items():
        variants = [(False, _long_label(name, cls))]
        if not cls.adaptive:
            variants.append((True, f"{name} + projection every step (h {LONG_STEP_S:g} s)"))
        for project, label in variants:
            try:
                xs = raw_states(scene, "momentum", name, ts, project=project, **_long_setting(cls))
            except (ValueError, NotImplementedError) as e:
                case.add(label, math.nan, "", f"skipped: {_one_line(e)}")
                break
            except Exception as e:  # noqa: BLE001 - a method that breaks down is a result here
                case.add(label, math.nan, "", f"failed: {type(e).__name__}: {_one_line(e)}")
                continue
            e = np.abs(np.linalg.norm(xs[:, :4], axis=1) - 1.0)
            slope, final = growth(ts, e)
            worst = float(e.max())
            verdict = "unit norm to round-off" if worst < ROUNDOFF_REL else growth_verdict(slope, worst)
            if project and worst >= ROUNDOFF_REL:
                verdict = f"bounded by one step's error (slope {slope:.2f})"
            case.add(label, worst, "|q|-1", verdict)
            rows += [[label, t / T_orb, v] for t, v in zip(ts, e)]
            ax.semilogy(ts[1:] / T_orb, np.maximum(e[1:], 1e-16), color=colours[name],
                        linestyle="--" if project else "-", label=f"{label}: {worst:.1e}")
    ax.axhline(ROUNDOFF_REL, color="0.5", linestyle=":", label="round-off level")
    ax.set_xlabel("time [orbits of 92.6 min]")
    ax.set_ylabel("| |q_BN| - 1 |  [-]  (zero drawn at 1e-16)")
    ax.set_title(case.title)
    fig.legend(loc="outside right upper", fontsize=8, title="method: max | |q| - 1 |")
    ax.grid(True, alpha=0.3)
    _save(ctx, case, fig, rows, ["method", "t_orbits", "abs_norm_error"])
    return case


# -- 6. CMG singular configuration ------------------------------------------------------------

#: a steering law stalls when the cluster delivers less than this fraction of the commanded
#: x torque over the last CMG_WINDOW_S of the run
STALL_FRACTION = 0.5
CMG_WINDOW_S = 3.0


def _case_cmg(ctx: _Ctx) -> Case:
    scene = load_scene(_scenario("sgcmg_singularity.toml"))
    duration = scene.simulation.duration  # 30 s: SR and o-DSR need ~10 s to leave the singularity
    window = CMG_WINDOW_S
    c = scene.cmg
    h_sing = 2 * math.cos(c.skew) * c.h_rotor  # the internal singular momentum along x [N m s]
    tau_cmd = float(scene.controller.params["torque_B"][0])  # N m
    case = Case("cmg_singularity", "SGCMG pyramid driven into its internal singularity: steering laws",
                f"torque delivered about x over the last {window:g} s (-Δh_x/Δt) vs the {tau_cmd:g} N m "
                f"commanded; stalls below {STALL_FRACTION:.0%}")
    plt = ctx.plt
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(15, 5.5), constrained_layout=True)
    rows = []
    for law in typing.get_args(Cmg.model_fields["steering"].annotation):
        sc = scene.replace(**{"cmg.steering": law})
        tr, status = _try(sc, None, None, duration=duration)
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
    _save(ctx, case, fig, rows, ["steering", "t_s", "hx_Nms", "singularity_measure"])
    return case


# -- 7. stiff array modes: explicit against implicit -----------------------------------------

#: a 100 t station core with one 37 m, 1100 kg wing (a 12 m x 37 m plate: span y, normal z in P)
#: bending in two modes: the first at 0.1 Hz, released from a 0.1 m tip deflection, and a stiff
#: one (the second cantilever shape, its frequency set to ``f_hi``) that only the coupling excites
_STIFF_BEAM = {"length": 37.0, "root": [0.0, -18.5, 0.0], "span": "y", "deflection": "z"}
_STIFF_SCENE = {
    "name": "study_stiff_modes",
    "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
    "body": {"mass": 1.0e5, "inertia": [[1.0e7, 0.0, 0.0], [0.0, 0.8e7, 0.0], [0.0, 0.0, 1.5e7]], "cm": [0.0, 0.0, 0.0]},
    "appendage": [{
        "name": "wing", "mass": 1100.0, "cm": [0.0, 30.0, 0.0],
        "inertia": [[1.255e5, 0.0, 0.0], [0.0, 1.32e4, 0.0], [0.0, 0.0, 1.387e5]],
    }],
}
STIFF_LOW_HZ = 0.1
STIFF_ETA0_M = 0.1
STIFF_DAMPING = 0.005
#: the adaptive sweep is repeated at the highest frequency with the stiff mode this damped: its
#: eigenvalues then lie 17° off the imaginary axis (BDF of order 3-5 is stable only in a sector
#: around the negative real axis: A(86°), A(73°), A(52°))
STIFF_DAMPED = 0.3
STIFF_FREQS_HZ = [1.0, 2.0, 5.0, 10.0, 20.0]
QUICK_STIFF_FREQS_HZ = [1.0, 20.0]
#: six (quick: two) periods of the 0.1 Hz mode
STIFF_DURATION_S = 60.0
QUICK_STIFF_DURATION_S = 20.0
#: output rows about this far apart [s] (energy and attitude error are read there)
STIFF_OUTPUT_DT_S = 0.5
#: fixed-step scan: doubling from this step [s] up to a quarter of the run, then bisections
STIFF_SCAN_START_S = 0.005
QUICK_STIFF_SCAN_START_S = 0.01
STIFF_BISECTIONS = 6
#: a fixed-step run is unstable when it stops (non-finite state, Newton not converged) or when a
#: mode's energy η̇² + ω²η² peaks above this many times the reference's peak: an unstable mode
#: grows exponentially (>= 6e4x in the full run), a stable step at most loses less of it than the
#: physical damping (<= 1.6x, rk4 right at its limit, where |R(hλ)| -> 1)
STIFF_MODE_GROWTH = 10.0
#: adaptive sweep: rtol (= atol) by half decades until the attitude error is below the target
#: [rad] (the 0.1 Hz mode rocks the station by 2.9e-4 rad: the target is 3.4e-5 of that)
STIFF_RTOLS = [10.0 ** (-k / 2) for k in range(6, 21)]
STIFF_TARGET_RAD = 1e-8
STIFF_REF = {"integrator": "dop853", "rtol": 1e-11, "atol": 1e-13}
#: log-log slope of cost against f_hi above which a method's cost is set by the stiff mode
STIFF_SLOPE = 0.5
#: the Newton-defect panel: one step from NEWTON_STATES states along each run; the rigid
#: tumble of the other cases over this long a run [s] for contrast
NEWTON_STATES = 12
NEWTON_TUMBLE_S = 2000.0

_RK4_TABLEAU = ([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
                [1 / 6, 1 / 3, 1 / 3, 1 / 6])


def _stability_tableaus() -> dict:
    """Butcher tables ``(A, b)`` of the explicit methods whose stability boundary the stiff-modes
    case predicts (RKMK4 is classical RK4 on the non-attitude states)."""
    from scipy.integrate import DOP853 as _D

    return {"rk4": _RK4_TABLEAU, "lie_rk4": _RK4_TABLEAU, "dop853": (_D.A[: _D.n_stages, : _D.n_stages], _D.B)}


def stability_function(A, b):
    """``R(z) = 1 + z bᵀ (E - z A)⁻¹ 1``, the Runge-Kutta method's growth factor per step on
    ``ẋ = λ x`` (z = hλ; Hairer & Wanner IV.3)."""
    A = np.asarray(A, dtype=complex)
    b = np.asarray(b, dtype=complex)
    E, one = np.eye(b.size), np.ones(b.size)
    return lambda z: complex(1.0 + z * (b @ np.linalg.solve(E - z * A, one)))


def stability_boundary(R, lam: complex, s_max: float = 20.0) -> float:
    """The largest ``h |λ|`` with ``|R(h λ)| <= 1`` for every smaller step (``inf`` up to ``s_max``).

    For classical RK4 and λ on the imaginary axis this is 2√2."""
    u = lam / abs(lam)
    ds = 0.01
    hi = next((k * ds for k in range(1, int(s_max / ds) + 1) if abs(R(k * ds * u)) > 1.0 + 1e-12), None)
    if hi is None:
        return math.inf
    lo = hi - ds
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if abs(R(mid * u)) > 1.0 + 1e-12 else (mid, hi)
    return lo


def _stiff_scene(f_hi: float, duration: float, damping_hi: float = STIFF_DAMPING) -> Scene:
    d = dict(_STIFF_SCENE, simulation={"duration": duration, "output_dt": STIFF_OUTPUT_DT_S})
    wing = dict(_STIFF_SCENE["appendage"][0])
    shapes = []
    for n in (1, 2):  # the beam's integrals given directly: a beam = {..} key recomputes them at every run
        phi_bar, H_hat, M = beam_mode(n, mass=wing["mass"], **_STIFF_BEAM)
        shapes.append({"translation": phi_bar.tolist(), "rotation": H_hat.tolist(), "modal_mass": M})
    wing["mode"] = [
        {"frequency_hz": STIFF_LOW_HZ, "damping": STIFF_DAMPING, "eta0": STIFF_ETA0_M, **shapes[0]},
        {"frequency_hz": f_hi, "damping": damping_hi, **shapes[1]},
    ]
    d["appendage"] = [wing]
    return scene_from_dict(d, source="study stiff-modes scene")


def rhs_eigenvalues(scene: Scene, formulation: str = "momentum") -> np.ndarray:
    """Eigenvalues [1/s] of the right-hand side's Jacobian at t = 0 (central differences on the
    compiled RHS). An elastic mode appears as ``-ζω ± iω√(1-ζ²)``, ω its frequency in the coupled
    system (above the clamped one: the station moves with the array)."""
    system = build_system(Structure.of(scene), formulation, "dop853")
    p = system.formulation.model.params(scene)
    q0, w0 = initial_state(scene)
    x0 = initial_x(system, scene, q0, w0, p)
    f = FastCall.of(system.funcs["rhs"])
    f.args[0][0] = 0.0
    f.args[2][:] = 0.0
    f.args[3][:] = p

    def rhs(x):
        f.args[1][:] = x
        f()
        return f.res[0].copy()

    J = np.empty((x0.size, x0.size))
    for j in range(x0.size):
        e = np.zeros(x0.size)
        e[j] = 1e-6 * max(1.0, abs(x0[j]))
        J[:, j] = (rhs(x0 + e) - rhs(x0 - e)) / (2 * e[j])
    return np.linalg.eigvals(J)


def _predicted_step(R, lams: np.ndarray) -> float:
    """The largest stable fixed step [s] of a method with stability function R on these
    eigenvalues (the slow ones, |λ| below 1e-3 of the fastest, never bind here)."""
    lam_max = float(np.max(np.abs(lams)))
    return min(stability_boundary(R, lam) / abs(lam) for lam in lams if abs(lam) > 1e-3 * lam_max)


def newton_defects(scene: Scene, integrator: str, hs, *, formulation: str = "momentum", n_states: int = NEWTON_STATES):
    """Largest defect of one step of a fixed-step implicit integrator (in its ``DEFECT_TOL``
    units: above it the run stops) at each step ``hs`` [s], from ``n_states`` states along the
    run (DOP853 at rtol 1e-10) with the scene's tolerances and u = 0: the compiled single step
    ``<name>_one`` of the :class:`~stationbed.integrators.FixedStep` driver, called directly.
    Smooth scenes only (no controller, no torque)."""
    system = build_system(Structure.of(scene), formulation, integrator)
    form = system.formulation
    model = form.model
    p = model.params(scene)
    _, w0 = initial_state(scene)
    atol = form.atol_vector(scene.simulation.atol, *characteristic_scales(scene, w0, model, p))
    tol = np.concatenate([[scene.simulation.rtol], atol])
    ts = np.linspace(0.0, scene.simulation.duration, n_states + 1)
    xs = raw_states(scene, formulation, "dop853", ts, rtol=1e-10, atol=1e-12)
    one = FastCall.of(system.funcs[f"{integrator}_one"])
    txd, hup = one.args
    hup[:] = 0.0
    hup[hup.size - p.size - tol.size : hup.size - tol.size] = p
    hup[hup.size - tol.size :] = tol
    out = []
    for h in hs:
        hup[0] = h
        worst = 0.0
        for t, x in zip(ts[:-1], xs[:-1]):
            txd[0] = t
            txd[1:-1] = x
            txd[-1] = 0.0
            one()
            d = float(one.res[0][-1])
            worst = max(worst, d) if math.isfinite(d) else math.inf
        out.append(worst)
    return out


def modal_energy(scene: Scene, tr: Trajectory) -> np.ndarray:
    """``η̇² + ω_k² η²`` [m²/s²] of every elastic mode at every row (columns in the scene's order):
    twice the mode's energy per unit modal mass, constant for a free undamped mode."""
    cols = []
    for a in scene.appendage:
        for k, m in enumerate(a.mode, start=1):
            eta, eta_dot = tr[f"eta_{a.name}_{k}"], tr[f"etadot_{a.name}_{k}"]
            cols.append(eta_dot**2 + (m.omega * eta) ** 2)
    return np.column_stack(cols)


def _why(status: str) -> str:
    if "not finite" in status:
        return "blows up"
    if "did not converge" in status:
        return "Newton does not converge"
    return status


def _case_stiff_modes(ctx: _Ctx) -> Case:
    freqs = QUICK_STIFF_FREQS_HZ if ctx.quick else STIFF_FREQS_HZ
    duration = QUICK_STIFF_DURATION_S if ctx.quick else STIFF_DURATION_S
    h0 = QUICK_STIFF_SCAN_START_S if ctx.quick else STIFF_SCAN_START_S
    case = Case(
        "stiff_modes",
        f"stiff array modes: {STIFF_LOW_HZ:g} Hz mode + a stiff mode at {', '.join(f'{f:g}' for f in freqs)} Hz "
        f"({duration:g} s, momentum form)",
        f"fixed step: unstable when the run stops or a mode's energy η̇² + ω²η² peaks above {STIFF_MODE_GROWTH:g}x "
        f"the reference's; doubling scan from {h0:g} s, then {STIFF_BISECTIONS} geometric bisections. "
        f"Adaptive: RHS evaluations of the loosest rtol (= atol, by half decades) with attitude error "
        f"<= {STIFF_TARGET_RAD:g} rad vs DOP853 rtol {STIFF_REF['rtol']:g}",
    )
    integs = _integrators()
    fixed = {n: c for n, c in integs.items() if not c.adaptive}
    adaptive = {n: c for n, c in integs.items() if c.adaptive}
    tableaus = _stability_tableaus()
    R4 = stability_function(*_RK4_TABLEAU)
    scenes = {f: _stiff_scene(f, duration) for f in freqs}
    lams = {f: rhs_eigenvalues(sc) for f, sc in scenes.items()}
    w_max = {f: float(np.max(np.abs(lam))) for f, lam in lams.items()}
    rk4_pred = {f: _predicted_step(R4, lam) for f, lam in lams.items()}
    refs: dict = {}

    def ref(f, dt):
        if (f, dt) not in refs:
            refs[(f, dt)] = simulate(scenes[f], formulation="momentum", output_dt=dt, duration=duration, **STIFF_REF)
        return refs[(f, dt)]

    rows = []
    header = ["part", "f_hi_hz", "omega_max_rad_s", "rk4_step_limit_s", "integrator", "step_s", "rtol", "status", "passed",
              "att_err_rad", "mode_energy_ratio", "n_rhs", "n_steps", "wall_s", "newton_defect"]

    def row(part, f, name, **kw):
        r = dict.fromkeys(header, math.nan)
        r.update(part=part, f_hi_hz=f, omega_max_rad_s=w_max.get(f, math.nan), rk4_step_limit_s=rk4_pred.get(f, math.nan),
                 integrator=name, status="", passed="")
        r.update(kw)
        rows.append(r)
        return r

    # (a) fixed step: largest stable step
    def run_fixed(f, name, h):
        dt = h * max(1, round(STIFF_OUTPUT_DT_S / h))  # rows every ~0.5 s, a whole number of steps
        with np.errstate(all="ignore"):
            tr, status = _try(scenes[f], "momentum", name, step=h, output_dt=dt, duration=duration)
        if status.startswith("skipped"):
            return None, status
        r = row("fixed", f, name, step_s=h, status=status)
        if tr is None or status != "ok" or len(tr) < 2:
            r.update(passed=0, why=_why(status))
            return r, status
        rf = ref(f, dt)
        growth = float(np.max(modal_energy(scenes[f], tr).max(axis=0) / modal_energy(scenes[f], rf).max(axis=0)))
        att, _ = _errors(tr, rf)
        ok = growth <= STIFF_MODE_GROWTH
        r.update(att_err_rad=att, mode_energy_ratio=growth, n_rhs=int(tr.meta["n_rhs"]), n_steps=int(tr.meta["n_steps"]),
                 wall_s=tr.meta["wall_s"], passed=int(ok), why="ok" if ok else "a mode's energy grows")
        return r, status

    fixed_res: dict = {}  # name -> {f: (h_pass, h_fail, why, [rows])}
    skipped: dict = {}
    for name in fixed:
        for f in freqs:
            pts, h, h_pass, h_fail = [], h0, None, None
            while h <= duration / 4:
                r, status = run_fixed(f, name, h)
                if r is None:
                    skipped[name] = status
                    break
                pts.append(r)
                if r["passed"]:
                    h_pass, h = h, 2 * h
                else:
                    h_fail = h
                    break
            if name in skipped:
                break
            if h_pass is not None and h_fail is not None:
                for _ in range(STIFF_BISECTIONS):
                    hm = math.sqrt(h_pass * h_fail)
                    r, _ = run_fixed(f, name, hm)
                    pts.append(r)
                    h_pass, h_fail = (hm, h_fail) if r["passed"] else (h_pass, hm)
            pts.sort(key=lambda r: r["step_s"])
            why = next((r["why"] for r in pts if r["step_s"] == h_fail), "")
            fixed_res.setdefault(name, {})[f] = (h_pass, h_fail, why, pts)

    # radau's Newton iteration: the stiff linear modes against the nonlinear rigid tumble
    implicit = [n for n in fixed_res if math.isfinite(fixed[n].DEFECT_TOL)]
    tumble = _tumble_scene(NEWTON_TUMBLE_S, NEWTON_TUMBLE_S / 10)
    w_tumble = float(np.linalg.norm(tumble.initial.omega_BN_B))  # rad/s
    newton: dict = {}
    for name in implicit:
        for f in freqs:
            hs = [r["step_s"] for r in fixed_res[name][f][3]]
            newton[(name, f)] = (hs, newton_defects(scenes[f], name, hs))
        hs = [2.0**k for k in range(0, 11)]  # 1 ... 1024 s
        newton[(name, "tumble")] = (hs, newton_defects(tumble, name, hs))
    for (name, f), (hs, ds) in newton.items():
        for h, dd in zip(hs, ds):
            if f == "tumble":
                rows.append(dict(dict.fromkeys(header, math.nan), part="newton_rigid_tumble", integrator=name, step_s=h,
                                 status="", passed="", newton_defect=dd))
            else:
                row("newton", f, name, step_s=h, newton_defect=dd)

    # (b) adaptive: cost of a fixed accuracy; at the highest frequency also with the stiff mode
    # well damped (its eigenvalues leave the imaginary axis)
    f_hi = freqs[-1]
    scenes["damped"] = _stiff_scene(f_hi, duration, damping_hi=STIFF_DAMPED)
    lam_damped = rhs_eigenvalues(scenes["damped"])
    w_max["damped"], rk4_pred["damped"] = float(np.max(np.abs(lam_damped))), _predicted_step(R4, lam_damped)

    def cheapest(key, name):
        """The loosest rtol's run reaching the target (None: none did), or "skipped: ..."."""
        for rtol in STIFF_RTOLS:
            tr, status = _try(scenes[key], "momentum", name, rtol=rtol, atol=rtol, output_dt=STIFF_OUTPUT_DT_S,
                              duration=duration)
            if status.startswith("skipped"):
                return status
            r = row("adaptive" if key != "damped" else f"adaptive_damping_{STIFF_DAMPED:g}",
                    f_hi if key == "damped" else key, name, rtol=rtol, status=status, omega_max_rad_s=w_max[key],
                    rk4_step_limit_s=rk4_pred[key])
            if tr is None or status != "ok":
                continue
            att, _ = _errors(tr, ref(key, STIFF_OUTPUT_DT_S))
            r.update(att_err_rad=att, n_rhs=int(tr.meta["n_rhs"]), n_steps=int(tr.meta["n_steps"]), wall_s=tr.meta["wall_s"])
            if att <= STIFF_TARGET_RAD:
                return r
        return None

    adapt_res: dict = {}  # name -> {f or "damped": row reaching the target, or None}
    for name in adaptive:
        for key in [*freqs, "damped"]:
            r = cheapest(key, name)
            if isinstance(r, str):
                skipped[name] = r
                break
            adapt_res.setdefault(name, {})[key] = r

    # verdicts
    fastest = lams[f_hi][np.argmax(np.abs(lams[f_hi]))]
    for name, cls in fixed.items():
        if name in skipped:
            case.add(name, math.nan, "s", skipped[name])
        else:
            case.add(name, *_fixed_verdict(name, cls, fixed_res[name], freqs, w_max, h0, tableaus, fastest, newton))
    for name in adaptive:
        if name in skipped:
            case.add(name, math.nan, "RHS evals", skipped[name])
        else:
            case.add(name, *_adaptive_verdict(name, adapt_res[name], freqs, w_max, duration, tableaus, fastest))

    fig = _plot_stiff(ctx.plt, case, freqs, duration, fixed_res, adapt_res, newton, w_max, w_tumble, rk4_pred, tableaus, lams)
    _save(ctx, case, fig, [[r[c] for c in header] for r in rows], header)
    return case


def _fixed_verdict(name, cls, res, freqs, w_max, h0, tableaus, fastest, newton) -> tuple:
    """``(value [s], unit, verdict)`` of a fixed-step method: its largest stable step per frequency."""
    f_lo, f_hi = freqs[0], freqs[-1]
    acc = {f: max((r["step_s"] for r in res[f][3] if r["passed"] and r["att_err_rad"] <= STIFF_TARGET_RAD), default=math.nan)
           for f in freqs}
    acc_txt = f"attitude error <= {STIFF_TARGET_RAD:g} rad up to h = " + ", ".join(f"{acc[f]:.3g} s ({f:g} Hz)" for f in freqs)
    failing = [f for f in freqs if res[f][1] is not None]
    if res[f_hi][0] is None or res[f_lo][0] is None:
        f = f_hi if res[f_hi][0] is None else f_lo
        return math.nan, "s", f"fails already at h = {h0:g} s at {f:g} Hz ({res[f][2]})"
    if failing:
        x = [w_max[f] * res[f][0] for f in failing]
        pred = ""
        if name in tableaus:
            bound = stability_boundary(stability_function(*tableaus[name]), fastest)
            pred = f" (its stability boundary on the fastest eigenvalue: {bound:.3g})"
        return res[f_hi][0], "s", (
            f"stability-bound: largest stable step {res[f_lo][0]:.3g} s at {f_lo:g} Hz, {res[f_hi][0]:.3g} s at "
            f"{f_hi:g} Hz; ω_max h_max = {min(x):.3g}–{max(x):.3g}{pred}; fails by: {res[f_hi][2]}; {acc_txt}")
    h_top = res[f_hi][0]
    defects = [d for f in freqs for d in newton.get((name, f), ([], []))[1]]
    newton_txt = f"; largest Newton defect {max(defects):.2g} (tolerance {cls.DEFECT_TOL:g})" if defects else ""
    return h_top, "s", (f"stable at every step tried, up to {h_top:g} s (ω_max h = {w_max[f_hi] * h_top:.3g} at "
                        f"{f_hi:g} Hz){newton_txt}; {acc_txt}")


def _adaptive_verdict(name, res, freqs, w_max, duration, tableaus, fastest) -> tuple:
    """``(value [RHS evals], unit, verdict)`` of an adaptive method: its cost of the target
    accuracy against the stiff mode's frequency (log-log slope)."""
    f_hi = freqs[-1]
    got = [f for f in freqs if res[f] is not None]
    missed = [f for f in freqs if res[f] is None]
    cost = ", ".join(f"{res[f]['n_rhs']} ({f:g} Hz, rtol {res[f]['rtol']:.2g})" for f in got)
    parts = []
    if len(got) >= 2:
        slope = float(np.polyfit(np.log(got), np.log([res[f]["n_rhs"] for f in got]), 1)[0])
        grows = "grows with" if slope > STIFF_SLOPE else "independent of"
        parts.append(f"cost {grows} the stiff mode (slope {slope:.2f}): RHS evals {cost}")
    elif got:
        parts.append(f"RHS evals {cost}")
    if missed:
        parts.append(f"does not reach {STIFF_TARGET_RAD:g} rad at {', '.join(f'{f:g}' for f in missed)} Hz")
    damped = res.get("damped")
    parts.append(f"stiff mode at damping {STIFF_DAMPED:g}: "
                 + (f"{damped['n_rhs']} at {f_hi:g} Hz" if damped else f"does not reach {STIFF_TARGET_RAD:g} rad"))
    if name in tableaus and res[f_hi] is not None and res[f_hi]["n_steps"] > 0:
        bound = stability_boundary(stability_function(*tableaus[name]), fastest)
        parts.append(f"mean ω_max h at {f_hi:g} Hz {w_max[f_hi] * duration / res[f_hi]['n_steps']:.3g} "
                     f"(stability boundary {bound:.3g})")
    return (float(res[f_hi]["n_rhs"]) if res[f_hi] else math.nan), "RHS evals", "; ".join(parts)


def _plot_stiff(plt, case, freqs, duration, fixed_res, adapt_res, newton, w_max, w_tumble, rk4_pred, tableaus, lams):
    from matplotlib.lines import Line2D

    fig, ((ax_e, ax_h), (ax_n, ax_c)) = plt.subplots(2, 2, figsize=(16, 11), constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    fcol = {f: cmap(0.85 * i / max(1, len(freqs) - 1)) for i, f in enumerate(freqs)}
    names = list(fixed_res)
    icol = _colours(plt, names)
    style = {n: (_STYLES[j % len(_STYLES)], _MARKERS[j % len(_MARKERS)]) for j, n in enumerate(names)}
    fail_y = 1e-2

    # (a) attitude error against the fixed step, per stiff-mode frequency
    for j, name in enumerate(names):
        ls, mk = style[name]
        lw = max(3.5 - 1.0 * j, 1.2)  # methods with equal errors (rk4, lie_rk4) stay visible
        for f in freqs:
            pts = fixed_res[name][f][3]
            good = [r for r in pts if r["passed"]]
            ax_e.loglog([r["step_s"] for r in good], [max(r["att_err_rad"], 1e-16) for r in good], color=fcol[f],
                        linestyle=ls, marker=mk, markersize=4 + lw, linewidth=lw, alpha=0.9)
            bad = [r for r in pts if not r["passed"]]
            ax_e.plot([r["step_s"] for r in bad], [fail_y] * len(bad), "x", color=fcol[f], markersize=8)
    for f in freqs:
        ax_e.axvline(rk4_pred[f], color=fcol[f], linestyle=":", linewidth=1)
    ax_e.axhline(STIFF_TARGET_RAD, color="red", linestyle="--", linewidth=0.9)
    handles = [Line2D([], [], color=fcol[f], linewidth=2.5, label=f"stiff mode {f:g} Hz (ω_max {w_max[f]:.3g} rad/s)") for f in freqs]
    handles += [Line2D([], [], color="k", linestyle=style[n][0], marker=style[n][1], linewidth=max(3.5 - 1.0 * j, 1.2),
                       label=n) for j, n in enumerate(names)]
    handles += [Line2D([], [], color="k", marker="x", linestyle="", label=f"unstable (drawn at {fail_y:g})"),
                Line2D([], [], color="0.4", linestyle=":", label="RK4 stability limit, predicted"),
                Line2D([], [], color="red", linestyle="--", label=f"target {STIFF_TARGET_RAD:g} rad")]
    ax_e.legend(handles=handles, fontsize=8, loc="lower right")
    ax_e.set_xlabel("fixed step h [s]")
    ax_e.set_ylabel("max attitude error vs reference [rad]")
    ax_e.set_title("(a) fixed step: attitude error against step size")
    ax_e.grid(True, which="both", alpha=0.3)

    # (b) largest stable step against the stiff mode's frequency
    for name in names:
        res = fixed_res[name]
        fs = [f for f in freqs if res[f][0] is not None]
        if not fs:
            continue
        bounded = any(res[f][1] is not None for f in fs)
        j = names.index(name)
        ax_h.loglog(fs, [res[f][0] for f in fs], color=icol[name], linestyle=style[name][0],
                    marker=style[name][1] if bounded else "^", markersize=max(13 - 4 * j, 7) if bounded else 10,
                    label=f"{name}: largest stable step" if bounded else f"{name}: stable at every step tried (the largest drawn)")
    ax_h.loglog(freqs, [rk4_pred[f] for f in freqs], color="k", linestyle="--", linewidth=1,
                label=f"RK4 prediction: stability boundary / ω_max ({rk4_pred[freqs[-1]] * w_max[freqs[-1]]:.3g} / ω_max)")
    ax_h.set_xlabel("stiff mode frequency [Hz]")
    ax_h.set_ylabel("largest stable fixed step [s]")
    ax_h.set_title(f"(b) largest stable fixed step (runs of {duration:g} s)")
    ax_h.legend(fontsize=8)
    ax_h.grid(True, which="both", alpha=0.3)

    # (c) Newton defect of one implicit step: stiff linear modes against a nonlinear tumble
    for (name, f), (hs, ds) in newton.items():
        if f == "tumble":
            label = f"{name}, rigid tumble of the long-horizon case (|ω| {w_tumble:.2g} rad/s, no modes)"
        else:
            label = f"{name}, stiff mode {f:g} Hz (ω_max h up to {w_max[f] * max(hs):.0f})"
        ax_n.loglog(hs, np.maximum(np.asarray(ds, dtype=float), 1e-16), marker="o", markersize=4,
                    color="k" if f == "tumble" else fcol[f], linewidth=2 if f == "tumble" else 1.2, label=label)
    for name in {n for n, _ in newton}:
        ax_n.axhline(INTEGRATORS[name].DEFECT_TOL, color="red", linestyle="--", linewidth=0.9,
                     label=f"{name} stops above {INTEGRATORS[name].DEFECT_TOL:g}")
    ax_n.set_xlabel("fixed step h [s]")
    ax_n.set_ylabel("largest Newton defect of one step [-] (0 drawn at 1e-16)")
    ax_n.set_title("(c) implicit step: Newton defect, stiff linear modes vs a nonlinear rigid tumble")
    ax_n.legend(fontsize=8)
    ax_n.grid(True, which="both", alpha=0.3)

    # (d) adaptive methods: RHS evaluations for a fixed accuracy
    acol = _colours(plt, list(adapt_res))
    f_hi = freqs[-1]
    for name, res in adapt_res.items():
        fs = [f for f in freqs if res[f] is not None]
        ax_c.loglog(fs, [res[f]["n_rhs"] for f in fs], color=acol[name], marker="o", label=name)
        miss = [f for f in freqs if res[f] is None]
        if miss:
            ax_c.plot(miss, [max((r["n_rhs"] for r in res.values() if r), default=1e3)] * len(miss), "x",
                      color=acol[name], markersize=9)
    for name, res in adapt_res.items():
        if res.get("damped"):
            ax_c.plot([f_hi], [res["damped"]["n_rhs"]], marker="D", markersize=9, markerfacecolor="none",
                      markeredgewidth=1.5, color=acol[name], linestyle="")
    ax_c.plot([], [], marker="D", markerfacecolor="none", color="k", linestyle="",
              label=f"open: the {f_hi:g} Hz mode damped at {STIFF_DAMPED:g} instead of {STIFF_DAMPING:g}")
    if "dop853" in adapt_res and "dop853" in tableaus:
        R = stability_function(*tableaus["dop853"])
        stages = len(tableaus["dop853"][1])
        bound = [stages * duration * w_max[f] / stability_boundary(R, lams[f][np.argmax(np.abs(lams[f]))]) for f in freqs]
        ax_c.loglog(freqs, bound, color="0.3", linestyle=":", linewidth=1.5,
                    label=f"dop853 with every step on its stability boundary ({stages} RHS per step)")
    ax_c.set_xlabel("stiff mode frequency [Hz]")
    ax_c.set_ylabel(f"RHS evaluations to reach {STIFF_TARGET_RAD:g} rad")
    ax_c.set_title(f"(d) adaptive: cost of {STIFF_TARGET_RAD:g} rad attitude accuracy")
    ax_c.legend(fontsize=8)
    ax_c.grid(True, which="both", alpha=0.3)
    fig.suptitle(case.title)
    return fig


STABILITY_CASES = {
    "rate_step": _case_rate_step,
    "long_horizon": _case_long_horizon,
    "dzhanibekov": _case_dzhanibekov,
    "max_step": _case_max_step,
    "quat_norm": _case_quat_norm,
    "cmg_singularity": _case_cmg,
    "stiff_modes": _case_stiff_modes,
}


def stability_study(*, out: Path | str, quick: bool = False, cases=None, log=print) -> list[Case]:
    """Run the stability cases (all, or the named ones); write ``stability_<case>.csv/.png``
    per case and ``stability_summary.csv`` / ``stability_summary.md`` with every verdict."""
    plt = _pyplot()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = list(STABILITY_CASES) if cases is None else list(cases)
    unknown = [c for c in names if c not in STABILITY_CASES]
    if unknown:
        raise ValueError(f"unknown stability case {unknown[0]!r}; valid: {', '.join(STABILITY_CASES)}")
    ctx = _Ctx(out, quick, plt, log)
    results = []
    for name in names:
        t0 = time.perf_counter()
        case = STABILITY_CASES[name](ctx)
        log(f"{case.title} ({time.perf_counter() - t0:.1f} s)")
        log(f"  detector: {case.detector}")
        for v in case.verdicts:
            log(f"  {v['method']:<48} {_fmt(v['value']) if isinstance(v['value'], float) else v['value']:>10} "
                f"{v['unit']:<9} {v['verdict']}")
        results.append(case)
    rows = [[c.name, v["method"], c.detector, v["value"], v["unit"], v["verdict"]] for c in results for v in c.verdicts]
    _write_csv(out / "stability_summary.csv", ["case", "method", "detector", "value", "unit", "verdict"], rows)
    md = ["| case | method | value | verdict |", "|---|---|---:|---|"]
    md += [f"| {r[0]} | {r[1]} | {_fmt(r[3])} {r[4]} | {r[5]} |" for r in rows]
    (out / "stability_summary.md").write_text("\n".join(md) + "\n")
    return results
