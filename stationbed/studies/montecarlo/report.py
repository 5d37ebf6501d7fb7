"""The end of a Monte Carlo study: the table (``samples.parquet``), ``summary.json`` (counts,
per-metric statistics, requirement verdicts), the charts and the rerun recording
(``montecarlo.rrd``: envelope percentiles and the worst sample's series)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ...run.metrics import METRICS
from . import charts
from .detection import PREFIX as DETECT, detection_columns, detection_summary, detection_text
from .dispersions import TOLD
from .samples import ID_COLUMNS
from .stats import PERCENTILES, metric_stats, percentile_needs, requirement_verdicts

__all__ = ["finish", "summarise", "write_recording", "ENVELOPE_PERCENTILES", "recorded_percentiles", "table_text"]

#: percentile lines of the envelopes in the recording (those the sample count supports)
ENVELOPE_PERCENTILES = (50.0, 90.0, 99.73, 100.0)


def recorded_percentiles(n: int) -> list[float]:
    """The :data:`ENVELOPE_PERCENTILES` that ``n`` samples support (:func:`.stats.percentile_needs`)."""
    return [p for p in ENVELOPE_PERCENTILES if n >= percentile_needs(p)]


def _clean(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return _clean(x.item())
    return x


def drawn_of(df) -> list[str]:
    """The drawn-value columns of a table (between the id columns and the metrics), without their
    ``told.`` twins (what the law was told: a driver is a truth) and the ``detect.`` columns
    (derived: :mod:`.detection`)."""
    return [c for c in df.columns if c not in ID_COLUMNS and c not in METRICS and not c.startswith((TOLD, DETECT))]


def summarise(scene, df, **extra) -> dict:
    """``summary.json``'s content for the table ``df``."""
    mc = scene.montecarlo
    status = df["status"]
    bad = df[status != "ok"]
    return _clean({
        "scene": scene.name,
        "n": int(len(df)),
        "n_planned": mc.n,
        "seed": mc.seed,
        "settle_s": mc.settle_s,
        "counts": {"ok": int((status == "ok").sum()), "failed": int((status == "failed").sum()),
                   "refused": int((status == "refused").sum()), "redraws": int(df["redraws"].sum())},
        # which executor ran the samples (fused, batch: lockstep, per-tick; "" refused)
        "executors": {str(k): int(v) for k, v in df["executor"].value_counts().items() if k}
        if "executor" in df else {},
        "failures": [{"index": int(r["index"]), "status": r["status"], "reason": r["reason"]}
                     for _, r in bad.head(20).iterrows()],
        "metrics": metric_stats(df),
        "percentile_needs_n": {f"p{p:g}": percentile_needs(p) for p in PERCENTILES},
        "requirements": requirement_verdicts(df, mc.requirement),
        **({"fault_detection": det} if (det := detection_summary(scene, df)) is not None else {}),
        **extra,
    })


def table_text(summary: dict) -> str:
    """The summary as a plain-text table (the CLI prints it; the README shows it)."""
    lines = [f"{summary['scene']}: {summary['n']} samples, {summary['counts']['ok']} ok, "
             f"{summary['counts']['failed']} failed, {summary['counts']['refused']} refused "
             f"({summary['counts']['redraws']} redraws)"
             + (f"; executors: {', '.join(f'{k} {v}' for k, v in summary['executors'].items())}"
                if summary.get("executors") else "")]
    head = f"{'metric':26s} {'mean':>10s} {'std':>10s} {'p50':>10s} {'p99.73':>10s} {'max':>10s} {'at':>6s}"
    lines.append(head)
    blank = set()
    for name, s in summary["metrics"].items():
        f = lambda v: f"{'-':>10s}" if v is None else f"{v:10.4g}"  # noqa: E731
        blank |= {p for p in ("p50", "p99.73") if s.get(p) is None}
        lines.append(f"{name:26s} {f(s['mean'])} {f(s['std'])} {f(s.get('p50'))} {f(s.get('p99.73'))} {f(s['max'])} "
                     f"{s['max_index']:6d}")
    for p in sorted(blank, key=lambda p: float(p[1:])):
        need = percentile_needs(float(p[1:]))
        lines.append(f"{p} blank: it needs n >= {need} samples that ran (at least one expected beyond it); "
                     f"below that it would be the largest sample under another name")
    for r in summary["requirements"]:
        op = "<=" if r["bound"] == "max" else ">="
        word = r["verdict"]
        lines.append(f"requirement {r['metric']} {op} {r['limit']:g} in {100 * r['coverage']:g} % at "
                     f"{100 * r['confidence']:g} % confidence: {word} ({r['failures']} of {r['n']} fail; "
                     f"lower bound {r['success_lower_bound']:.4f}; 0 failures need n >= {r['n_needed_zero_failures']})"
                     + (f" - {r['note']}" if "note" in r else ""))
    if summary.get("fault_detection"):
        lines += detection_text(summary["fault_detection"])
    return "\n".join(lines)


def write_recording(path: Path, scene, t, env, df) -> Path:
    """``montecarlo.rrd``: envelope, worst samples' table and the worst sample's 3-D replay
    (:mod:`.recording`)."""
    from .recording import write_recording as write

    return write(path, scene, t, env, df, percentiles=recorded_percentiles)


def finish(scene, result, *, wall_s: float, workers: int, chunk: int, draw_charts: bool) -> None:
    """Statistics into ``result.summary``; with ``result.out``: the files."""
    out = result.out
    for col, v in detection_columns(result.df, scene).items():  # per sample, against the drawn truth
        result.df[col] = v
    files = {}
    if out is not None:
        files = {"table": "samples.parquet", "chunks": "chunks/"}
    result.summary = summarise(scene, result.df, wall_s=wall_s, workers=workers, chunk=chunk, files=files)
    if out is None:
        return
    result.df.to_parquet(out / "samples.parquet", index=False)
    made = []
    if draw_charts:
        made += charts_all(scene, result, out)
    env = result.envelope
    if env is not None and len(env):
        write_recording(out / "montecarlo.rrd", scene, result.envelope_t, env, result.df)
        made.append(out / "montecarlo.rrd")
    result.summary["files"]["made"] = [p.name for p in made]
    (out / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")


def charts_all(scene, result, out: Path) -> list[Path]:
    """Every chart of the study in ``out``."""
    df = result.df
    made = charts.histograms(df, out, scene.montecarlo.requirement)
    if result.envelope is not None and len(result.envelope):
        made += charts.envelopes(result.envelope_t, result.envelope, out, scene.name)
    drawn = drawn_of(df)
    wanted = [r.metric for r in scene.montecarlo.requirement] or ["max_att_err_deg"]
    for m in dict.fromkeys(wanted):
        if m in df:
            p = charts.scatter(df, m, drawn, out)
            if p is not None:
                made.append(p)
    return made
