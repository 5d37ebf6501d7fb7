"""``stationbed compare OUTDIR_A OUTDIR_B [...]``: runs overlaid in one PNG, and a table of the
project's run metrics (:data:`stationbed.run.metrics.METRICS`, computed by
:func:`~stationbed.run.metrics.trajectory_metrics`: the same definitions the closed-loop summary
and the Monte Carlo use) with one column per run."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.plotting import pyplot, save_png
from ..run.metrics import METRICS, trajectory_metrics
from .dashboard import load_run, time_axis

__all__ = ["compare", "metrics_table"]


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}"


def metrics_table(names, metrics) -> str:
    """A plain-text table: one row per metric of :data:`METRICS` that some run has, one column per run."""
    width = max(12, *(len(n) + 2 for n in names))
    lines = [f"{'metric':<26}{'unit':<7}" + "".join(f"{n:>{width}}" for n in names)]
    for key, m in METRICS.items():
        vals = [mt.get(key) for mt in metrics]
        if all(v is None for v in vals):
            continue
        lines.append(f"{key:<26}{m.unit:<7}" + "".join(f"{_fmt(v):>{width}}" for v in vals))
    return "\n".join(lines)


def compare(outdirs, png=None, settle_s: float | None = None) -> tuple[str, Path]:
    """Overlay the runs of ``outdirs`` and tabulate their metrics.

    Parameters
    ----------
    outdirs : list of paths  Run folders (trajectory.csv, summary.json).
    png : path, optional  Output file (default: ``compare.png`` in the first folder's parent).
    settle_s : float, optional  Settling time [s] for ``rms_att_err_deg`` (None: all rows).

    Returns
    -------
    (table text, PNG path)
    """
    if len(outdirs) < 1:
        raise ValueError("compare needs at least one run folder")
    runs = [load_run(d) for d in outdirs]
    names = []
    for d, (_, meta) in zip(outdirs, runs):
        label = Path(d).name
        ctrl = meta.get("summary", {}).get("controller")
        names.append(f"{label}" if not ctrl or ctrl == label else f"{label} ({ctrl})")
    metrics = [trajectory_metrics(tr, summary=meta.get("summary") or {}, settle_s=settle_s) for tr, meta in runs]
    table = metrics_table(names, metrics)
    plt = pyplot()
    png = Path(png) if png is not None else Path(outdirs[0]).resolve().parent / "compare.png"
    panels = [("attitude error to the reference [deg]", lambda tr: tr["att_err_deg"] if "att_err_deg" in tr.columns else None),
              ("pitch attitude error att_err_y_deg [deg]", lambda tr: tr["att_err_y_deg"] if "att_err_y_deg" in tr.columns else None),
              ("CMG momentum |h| [N m s]", lambda tr: np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1) if "hx" in tr.columns else None),
              ("torque command |τ_cmd| [N m]",
               lambda tr: np.linalg.norm(tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z"), axis=1) if "tau_cmd_x" in tr.columns else None)]
    panels = [p for p in panels if any(p[1](tr) is not None for tr, _ in runs)]
    t_end = max(float(tr.t[-1]) for tr, _ in runs if len(tr))
    div, tlabel = time_axis(t_end)
    ncol = 2
    nrow = (len(panels) + 1) // 2
    fig, axes = plt.subplots(nrow, ncol, figsize=(14, 3.6 * nrow + 0.8), sharex=True, squeeze=False)
    for ax, (title, get) in zip(axes.flat, panels):
        for (tr, _), name in zip(runs, names):
            y = get(tr)
            if y is not None:
                ax.plot(tr.t / div, y, lw=1.1, label=name)
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(tlabel)
        ax.tick_params(labelbottom=True)
    scenes = sorted({meta.get("scene", "?") for _, meta in runs})
    fig.suptitle(f"compare: {', '.join(names)} ({', '.join(scenes)})", fontsize=11)
    save_png(plt, fig, png, dpi=100)
    return table, png
