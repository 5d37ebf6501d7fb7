"""``stationbed compare OUTDIR_A OUTDIR_B [...]``: runs overlaid in one PNG, and a table of the
project's run metrics (:data:`stationbed.run.metrics.METRICS`, computed by
:func:`~stationbed.run.metrics.trajectory_metrics`: the same definitions the closed-loop summary
and the Monte Carlo use) with one column per run."""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path

import numpy as np

from ..core.plotting import pyplot, save_png
from ..run.metrics import ESTIMATION_WINDOW, METRICS, trajectory_metrics
from ..run.trajectory import Trajectory
from .dashboard import load_run, run_state, time_axis
from .signals import h_fraction, relative_rate

__all__ = ["compare", "metrics_table", "settled_metrics", "metric_scope", "WHOLE_RUN", "default_png"]

#: the run folders' names in a default file name are cut to this many characters in all
NAMES_MAX_CHARS = 80


def default_png(outdirs) -> Path:
    """The comparison's own file in the first folder's parent: ``compare_<A>_vs_<B>..._<hash>.png``,
    the folders' names and 8 hex digits of the SHA-256 of their resolved paths (in order). The
    same comparison writes the same file again; another (other runs, or the same names in other
    folders) never replaces it."""
    paths = [Path(d).resolve() for d in outdirs]
    names = "_vs_".join(re.sub(r"[^A-Za-z0-9._-]+", "-", p.name) for p in paths)[:NAMES_MAX_CHARS]
    tag = hashlib.sha256("\0".join(map(str, paths)).encode()).hexdigest()[:8]
    return paths[0].parent / f"compare_{names}_{tag}.png"


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}"


#: metrics the closed loop counts over every controller tick of the run (not in the rows): a
#: settling time cannot apply to them
WHOLE_RUN = frozenset(k for k, m in METRICS.items() if m.unit == "ticks")
#: the metric of the last row: the same with or without a settling time
LAST_ROW = frozenset({"final_att_err_deg"})
#: metrics of the run from its first row (a settling time would cut off what they measure)
FROM_START = frozenset({"est_converged_s"})


def metric_scope(key: str, settle_s: float | None) -> str:
    """Over which part of each run metric ``key`` is taken, as the table says it."""
    if key in WHOLE_RUN:
        return "all ticks"
    if key in LAST_ROW:
        return "last row"
    if key in FROM_START:
        return "all rows"
    if key in ESTIMATION_WINDOW:
        return "converged" if settle_s is None else f"t >= {settle_s:g} s, converged"
    return "all rows" if settle_s is None else f"t >= {settle_s:g} s"


def settled_metrics(tr, summary: dict, settle_s: float | None, where: str = "the run") -> dict:
    """The :data:`METRICS` of one run with ``settle_s`` applied to every metric of its rows (max,
    RMS, min, not only the RMS): the reduction over the rows at ``t >= settle_s``; the tick counts
    stay the whole run's. ValueError when no row is that late."""
    if settle_s is None:
        return trajectory_metrics(tr, summary=summary)
    keep = tr.t >= settle_s
    if not keep.any():
        raise ValueError(f"--settle {settle_s:g} s: no row of {where} is that late "
                         f"(its rows end at t = {tr.t[-1]:g} s)")
    out = trajectory_metrics(Trajectory(tr.columns, tr.data[keep]), summary=summary, settle_s=settle_s)
    whole = trajectory_metrics(tr, summary=summary, settle_s=settle_s)
    out.update({k: whole[k] for k in FROM_START & set(whole)})
    # the estimation window starts at the later of settle_s and the convergence of the whole run
    out.update({k: whole[k] for k in set(ESTIMATION_WINDOW) & set(whole)})
    return out


def metrics_table(names, metrics, settle_s: float | None = None) -> str:
    """A plain-text table: one row per metric of :data:`METRICS` that some run has, one column per
    run, and the part of the run it is taken over (``t >= settle`` where a settling time applies)."""
    width = max(12, *(len(n) + 2 for n in names))
    lines = [f"{'metric':<26}{'unit':<7}{'over':<20}" + "".join(f"{n:>{width}}" for n in names)]
    for key, m in METRICS.items():
        vals = [mt.get(key) for mt in metrics]
        if all(v is None for v in vals):
            continue
        lines.append(f"{key:<26}{m.unit:<7}{metric_scope(key, settle_s):<20}" + "".join(f"{_fmt(v):>{width}}" for v in vals))
    if len(lines) == 1:
        return "no run metric applies: the runs have no closed-loop columns (att_err_deg, h, tau_cmd)"
    return "\n".join(lines)


def _norm(tr, *cols):
    return np.linalg.norm(tr.cols(*cols), axis=1) if cols[0] in tr.columns else None


def _panels(runs):
    """(title, values-of-a-run function) of the panels some run has values for."""
    deg = np.degrees(1.0)
    frac = lambda tr, meta: h_fraction(tr, meta.get("summary") or {})  # noqa: E731
    rel = lambda tr, meta: None if (w := relative_rate(tr)) is None else np.linalg.norm(w, axis=1) * deg  # noqa: E731
    panels = [("attitude error to the reference [deg]", lambda tr, meta: tr["att_err_deg"] if "att_err_deg" in tr.columns else None),
              ("pitch attitude error att_err_y_deg [deg]", lambda tr, meta: tr["att_err_y_deg"] if "att_err_y_deg" in tr.columns else None),
              ("body rate relative to the reference |ω_BR_B| [deg/s]", rel),
              ("CMG momentum |h| / capacity", frac),
              ("CMG momentum |h| [N m s]", lambda tr, meta: _norm(tr, "hx", "hy", "hz")),
              ("torque command |τ_cmd| [N m]", lambda tr, meta: _norm(tr, "tau_cmd_x", "tau_cmd_y", "tau_cmd_z"))]
    panels = [p for p in panels if any(p[1](tr, meta) is not None for tr, meta in runs)]
    if not panels:  # open loop: the motion itself
        panels = [("body rate |ω_BN_B| (inertial) [deg/s]", lambda tr, meta: _norm(tr, "wx", "wy", "wz") * deg),
                  ("angular momentum |H_O| [N m s]", lambda tr, meta: _norm(tr, "HNx", "HNy", "HNz")),
                  ("kinetic energy T [J]", lambda tr, meta: tr["T"] if "T" in tr.columns else None)]
    return panels


def compare(outdirs, png=None, settle_s: float | None = None) -> tuple[str, Path]:
    """Overlay the runs of ``outdirs`` and tabulate their metrics.

    Parameters
    ----------
    outdirs : list of paths  Run folders (trajectory.csv, or the partial rows of a failed run, and
        summary.json).
    png : path, optional  Output file (default: :func:`default_png`, named for the runs compared,
        in the first folder's parent).
    settle_s : float, optional  Settling time [s]: every metric of the rows (max, RMS, min) is
        taken over the rows at ``t >= settle_s`` (None: all rows); the table says which.

    Returns
    -------
    (table text, PNG path)
    """
    if len(outdirs) < 1:
        raise ValueError("compare needs at least one run folder")
    if settle_s is not None and not (math.isfinite(settle_s) and settle_s >= 0):
        raise ValueError(f"--settle must be a finite time >= 0 s, got {settle_s:g}")
    runs = [load_run(d) for d in outdirs]
    for d, (tr, meta) in zip(outdirs, runs):
        if len(tr) == 0:
            raise ValueError(f"{Path(d) / meta['rows_file']}: no rows (the run stopped before its first output row)")
    names = []
    for d, (_, meta) in zip(outdirs, runs):
        label = Path(d).name
        ctrl = meta.get("summary", {}).get("controller")
        names.append(f"{label}" if not ctrl or ctrl == label else f"{label} ({ctrl})")
        if meta.get("partial"):
            names[-1] += " [partial]"
    metrics = [settled_metrics(tr, meta.get("summary") or {}, settle_s, where=str(Path(d) / meta["rows_file"]))
               for d, (tr, meta) in zip(outdirs, runs)]
    table = metrics_table(names, metrics, settle_s)
    notes = [f"{n}: {run_state(meta)}" for n, (_, meta) in zip(names, runs) if meta.get("partial")]
    if notes:
        table += "\n" + "\n".join(notes)
    plt = pyplot()
    png = Path(png) if png is not None else default_png(outdirs)
    with np.errstate(all="ignore"):  # NaN rows are gaps
        panels = [(title, [get(tr, meta) for tr, meta in runs]) for title, get in _panels(runs)]
    t_end = max(float(tr.t[-1]) for tr, _ in runs)
    div, tlabel = time_axis(t_end)
    ncol = 2 if len(panels) > 1 else 1
    nrow = (len(panels) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(7 * ncol, 3.6 * nrow + 0.8), sharex=True, squeeze=False)
    for ax, (title, values) in zip(axes.flat, panels):
        for (tr, _), name, y in zip(runs, names, values):
            if y is not None:
                ax.plot(tr.t / div, y, lw=1.1, label=name)
        if settle_s is not None:
            ax.axvline(settle_s / div, color="0.5", lw=0.8, ls=":", label=f"settle {settle_s:g} s")
        if "/ capacity" in title:
            ax.set_ylim(bottom=0.0)
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for col in range(ncol):
        shown = [ax for ax in axes[:, col] if ax.get_visible()]
        shown[-1].set_xlabel(tlabel)
        shown[-1].tick_params(labelbottom=True)
    scenes = sorted({str(meta.get("scene", "?")) for _, meta in runs})
    fig.suptitle(f"compare: {', '.join(names)} ({', '.join(scenes)})", fontsize=11)
    save_png(plt, fig, png, dpi=100, title_in=0.35)
    return table, png
