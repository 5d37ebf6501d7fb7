"""Work-precision of the closed loop (``stationbed study precision`` on a scene with a
``[controller]``, issue 25).

The loop's own choices, each against a tight reference of the *same* loop (the same controller
at its period, its commands held over each period; DOP853 at ``REF_RTOL`` between ticks):

* the formulation (every registered one, or those named);
* RK4 sub-steps per tick (1: the fused loop when the law has a symbolic form; more: the per-tick
  loop with ``step = period / m``);
* the environment torques' rate (``[simulation] environment_rate``: 0 = every RK4 stage, N =
  once per N ticks held at the extrapolated mid-block value, stationbed/run/env_block.py; one sub-step).

Writes ``precision_loop.csv``, a chart of attitude error against CPU time per run (labelled per
choice) and the cheapest choice per target accuracy (``precision_loop_cheapest.md``). The
reference's own accuracy is stated by a cross-check: RK4 at ``CROSS_SUBSTEPS`` sub-steps per
tick, every stage, against it.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..run.simulation import simulate
from .common import registered_formulations, write_csv
from .plotting import MARKERS, colours
from .probes import max_errors

__all__ = ["LoopPrecisionResult", "loop_precision"]

#: the reference: the same loop, DOP853 between ticks at this rtol (atol a hundredth of it)
REF_RTOL = 1e-12
#: the reference's cross-check: RK4, every stage, at this many sub-steps per tick
CROSS_SUBSTEPS = 8
SUBSTEPS = [1, 2, 4]
ENV_RATES = [0, 1, 5, 10, 20, 50, 100]
QUICK_SUBSTEPS = [1, 2]
QUICK_ENV_RATES = [0, 10]
#: CPU-time repeats per point (median); CPU time, not wall time: the machine is shared
REPEATS = 3
TARGETS_RAD = (1e-3, 1e-6, 1e-9)
COLUMNS = ["formulation", "substeps", "environment_rate", "fused", "status", "att_err_rad", "rate_err_rad_s",
           "cpu_s"]


@dataclass
class LoopPrecisionResult:
    """What :func:`loop_precision` measured: ``rows`` keyed by ``COLUMNS`` (errors in rad and
    rad/s against the reference, CPU seconds per run), the reference and its cross-check
    (``reference``), the cheapest choice per target (``cheapest``) and the files written."""

    scene: str
    duration: float
    rows: list[dict]
    reference: dict
    cheapest: list[dict]
    files: list[Path] = field(default_factory=list)

    def table(self) -> str:
        """The cheapest-choice table as Markdown."""
        lines = [
            f"cheapest closed-loop choice (median CPU time) reaching each attitude accuracy on {self.scene}, "
            f"{self.duration:g} s (reference: {self.reference['method']}; its cross-check "
            f"{self.reference['cross_method']}: {self.reference['cross_att_rad']:.2g} rad):",
            "",
            "| target [rad] | formulation | RK4 sub-steps per tick | environment rate | att. error [rad] | CPU [s] |",
            "|---:|---|---:|---|---:|---:|",
        ]
        for c in self.cheapest:
            if c.get("formulation") is None:
                lines.append(f"| {c['target_rad']:.0e} | none reached it | | | | |")
                continue
            lines.append(f"| {c['target_rad']:.0e} | {c['formulation']} | {c['substeps']} | {_rate(c['environment_rate'])} "
                         f"| {c['att_err_rad']:.2g} | {c['cpu_s']:.3g} |")
        return "\n".join(lines)


def _rate(n: int) -> str:
    return "every stage" if n == 0 else f"every {n} ticks"


def _timed(scene, repeats, **kw):
    """The run and its median CPU time over ``repeats`` runs after a first (compiling) one."""
    tr = simulate(scene, **kw)
    cpu = []
    for _ in range(repeats):
        t0 = time.process_time()
        simulate(scene, **kw)
        cpu.append(time.process_time() - t0)
    return tr, statistics.median(cpu)


def loop_precision(scene, out: Path, duration: float, *, formulations=None, quick=False, repeats=None,
                   log=print, plt=None) -> LoopPrecisionResult:
    """Cost against accuracy of the closed loop's choices on ``scene`` (module docstring)."""
    out.mkdir(parents=True, exist_ok=True)
    period = scene.controller.period
    repeats = repeats or (1 if quick else REPEATS)
    forms = registered_formulations(formulations)
    common = {"duration": duration}
    ref = simulate(scene, integrator="dop853", rtol=REF_RTOL, atol=REF_RTOL / 100, **common)
    cross = simulate(scene, integrator="rk4", step=period / CROSS_SUBSTEPS, **common)
    cross_att, _ = max_errors(cross, ref)
    reference = {"method": f"dop853 rtol {REF_RTOL:.0e} between ticks",
                 "cross_method": f"rk4 {CROSS_SUBSTEPS} sub-steps per tick", "cross_att_rad": cross_att}
    log(f"reference {reference['method']}; cross-check {reference['cross_method']}: {cross_att:.3g} rad")
    rows = []
    points = [(m, 0) for m in (QUICK_SUBSTEPS if quick else SUBSTEPS)]
    points += [(1, n) for n in (QUICK_ENV_RATES if quick else ENV_RATES) if n]
    for form in forms:
        for m, n in points:
            sc = scene.replace({"simulation.environment_rate": n})  # 0: every stage (not the default "auto")
            row = {"formulation": form, "substeps": m, "environment_rate": n, "fused": False, "status": "ok",
                   "att_err_rad": math.inf, "rate_err_rad_s": math.inf, "cpu_s": math.nan}
            try:
                tr, cpu = _timed(sc, repeats, formulation=form, integrator="rk4", step=period / m, **common)
            except Exception as e:  # a formulation that refuses the scene is a result, not a crash
                row["status"] = f"failed: {type(e).__name__}: {str(e).splitlines()[0][:80]}"
            else:
                att, rate = max_errors(tr, ref)
                row.update(att_err_rad=att, rate_err_rad_s=rate, cpu_s=cpu, fused=bool(tr.meta["summary"]["fused"]))
                if n:
                    row["environment_rate"] = tr.meta["summary"]["environment_rate_ticks"]
            rows.append(row)
            log(f"  {form:<11} sub-steps {m} env {_rate(row['environment_rate']):<16} att {row['att_err_rad']:.3g} rad "
                f"cpu {row['cpu_s']:.3g} s {row['status']}")
    csv_path = out / "precision_loop.csv"
    write_csv(csv_path, COLUMNS, [[r[c] for c in COLUMNS] for r in rows])
    ok = [r for r in rows if r["status"] == "ok"]
    cheapest = []
    for target in TARGETS_RAD:
        cand = [r for r in ok if r["att_err_rad"] <= target]
        best = min(cand, key=lambda r: r["cpu_s"]) if cand else {}
        cheapest.append({"target_rad": target, **best})
    res = LoopPrecisionResult(scene.name, duration, rows, reference, cheapest)
    md = out / "precision_loop_cheapest.md"
    md.write_text(res.table() + "\n")
    png = out / "precision_loop.png"
    if plt is not None:
        _plot(plt, res, forms, png)
    res.files = [csv_path, md] + ([png] if plt is not None else [])
    return res


def _plot(plt, res: LoopPrecisionResult, forms, path: Path) -> None:
    """Attitude error against CPU time: a colour per formulation, a marker per sub-step count,
    the environment-rate points joined and labelled with their rate."""
    col = colours(plt, forms)
    fig, ax = plt.subplots(figsize=(11, 6.5), constrained_layout=True)
    subs = sorted({r["substeps"] for r in res.rows})
    for form in forms:
        pts = [r for r in res.rows if r["formulation"] == form and r["status"] == "ok"]
        for j, m in enumerate(subs):
            mp = [r for r in pts if r["substeps"] == m and r["environment_rate"] == 0]
            ax.scatter([r["cpu_s"] for r in mp], [max(r["att_err_rad"], 1e-16) for r in mp], color=col[form],
                       marker=MARKERS[j % len(MARKERS)], s=60, zorder=3,
                       label=f"{form}, {m} RK4 sub-step{'s' if m > 1 else ''}/tick, every stage")
        env = sorted((r for r in pts if r["substeps"] == 1), key=lambda r: r["environment_rate"])
        if len(env) > 1:
            ax.plot([r["cpu_s"] for r in env], [max(r["att_err_rad"], 1e-16) for r in env], color=col[form],
                    linestyle=":", marker=".", linewidth=1)
            for r in env:
                if r["environment_rate"]:
                    ax.annotate(f"env/{r['environment_rate']}", (r["cpu_s"], max(r["att_err_rad"], 1e-16)),
                                textcoords="offset points", xytext=(4, 4), fontsize=7, color=col[form])
    for tgt in TARGETS_RAD:
        ax.axhline(tgt, color="0.6", linestyle=":", linewidth=0.8)
    ax.axhline(res.reference["cross_att_rad"], color="red", linestyle="--", linewidth=0.9,
               label="reference cross-check")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time per run (median) [s]")
    ax.set_ylabel("max attitude error against the reference [rad]")
    ax.set_title(f"{res.scene}, {res.duration:g} s closed loop: cost against accuracy "
                 "(dotted: the environment every N ticks, 'env/N')")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.savefig(path, dpi=110)
    plt.close(fig)
