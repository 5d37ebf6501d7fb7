"""``montecarlo.rrd``: the study's envelope beside the worst sample's 3-D replay and a table of the
worst samples (issue 24).

* ``montecarlo/envelope/<series>``: percentile lines over the samples (``att_err_deg``,
  ``h_fraction``) on ``sim_time``; ``montecarlo/worst/<series>``: the sample with the largest
  value of that series, drawn over its envelope;
* ``montecarlo/worst_samples``: a markdown table (rerun ``TextDocument``) of the
  :data:`WORST_ROWS` samples with the largest ``max_att_err_deg``: index, status, the metrics and
  the drawn values (``stationbed montecarlo SCENE --sample K`` replays any of them alone);
* ``world/...`` and ``events``: the worst sample (largest ``max_att_err_deg``) run again, exactly
  as the study ran it (:func:`.replay.sample_scene`), and drawn as a run's recording draws the
  station (:class:`~stationbed.output.rerun.drawing.StationDrawing`: surfaces, arrays, CMG
  arrows, sun, eclipse, events).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from ...output.rerun.drawing import StationDrawing
from ...output.rerun.geometry import StationGeometry
from ...output.rerun.sdk import APPLICATION_ID, TIMELINE, import_rerun, saving
from ...run.metrics import METRICS
from .samples import ID_COLUMNS, held_warnings
from .stats import quiet_nan

__all__ = ["write_recording", "worst_table", "WORST_ROWS", "REPLAY_METRIC"]

#: rows of the worst-samples table
WORST_ROWS = 10
#: the metric that ranks the samples (largest first) and picks the one replayed in 3-D
REPLAY_METRIC = "max_att_err_deg"
#: metrics shown in the table, in order (those the study has)
TABLE_METRICS = ("max_att_err_deg", "rms_att_err_deg", "max_h_fraction", "min_singularity", "momentum_saturated_ticks")


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return "nan" if not math.isfinite(v) else f"{v:.4g}"
    return str(v)


def worst_table(df, n: int = WORST_ROWS) -> tuple[str, list[int]]:
    """Markdown table of the ``n`` samples with the largest :data:`REPLAY_METRIC`, and their indices
    (largest first; samples without the metric, refused or failed before a row, last)."""
    ranked = df.sort_values(REPLAY_METRIC, ascending=False, na_position="last").head(n)
    drawn = [c for c in df.columns if c not in ID_COLUMNS and c not in METRICS]
    metrics = [m for m in TABLE_METRICS if m in df.columns]
    cols = ["index", "status"] + metrics + drawn
    lines = [f"### {len(ranked)} worst of {len(df)} samples by {REPLAY_METRIC}", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in ranked.iterrows():
        lines.append("| " + " | ".join(_fmt(r[c]) for c in cols) + " |")
    lines += ["", "Replay one alone: `stationbed montecarlo SCENE --sample K --rrd sample.rrd`."]
    return "\n".join(lines) + "\n", [int(k) for k in ranked["index"]]


def _replay_worst(rec, scene, k: int) -> bool:
    """Run sample ``k`` again and draw it under ``world/`` (and its events); False when it cannot run."""
    from ...run.simulation import SimulationError, simulate
    from ...scene import SceneError
    from .replay import sample_scene

    try:
        s = sample_scene(scene, k)
    except SceneError:  # refused: nothing to replay
        return False
    refused = None
    with held_warnings():  # the study has said this sample's warnings already: not twice
        try:
            tr = simulate(s)
        except SimulationError as e:  # a failed sample: its rows up to the failure
            tr = e.trajectory
        except Exception as e:  # a law's reset or the model refused it (the study's row says why)
            refused = e
    if refused is not None:
        logging.getLogger("stationbed").warning(f"montecarlo.rrd: no 3-D replay of sample {k}: {refused}")
        return False
    if not len(tr):
        return False
    rr = import_rerun()
    drawing = StationDrawing(s, tr.columns)
    drawing.log_static(rec)
    index = [rr.TimeColumn(TIMELINE, duration=tr.t)]
    drawing.send(rec, lambda path, columns: rec.send_columns(path, indexes=index, columns=columns), tr)
    return True


def _blueprint(scene, series, replayed: bool, worst_k, t_end: float):
    import rerun.blueprint as rrb

    whole = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(seconds=0.0),
                                                  end=rrb.TimeRangeBoundary.absolute(seconds=t_end)))
    plots = [rrb.TimeSeriesView(name=f"{s}: envelope (percentiles) and the worst sample", origin="montecarlo",
                                contents=[f"/montecarlo/envelope/{s}", f"/montecarlo/worst/{s}"], axis_x=whole)
             for s in series]
    table = rrb.TextDocumentView(name="worst samples", origin="montecarlo/worst_samples")
    left = [table]
    if replayed:
        L = StationGeometry(scene).extent
        eye = rrb.EyeControls3D(position=L * np.array([2.0, -2.0, 1.4]), look_target=[0, 0, 0], eye_up=[0, 0, 1])
        left = [rrb.Spatial3DView(name=f"worst sample {worst_k} (N axes, CM at origin)", origin="world",
                                  eye_controls=eye), table]
    right = plots + ([rrb.TextLogView(name=f"events of sample {worst_k}", origin="events")] if replayed else [])
    shares = [3] * len(plots) + ([1] if replayed else [])
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*left, row_shares=[3, 2] if replayed else None),
                       rrb.Vertical(*right, row_shares=shares)),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, playback_speed=max(1.0, t_end / 60.0), play_state="paused"),
    )


def write_recording(path: Path, scene, t, env, df, *, percentiles, replay: bool = True) -> Path:
    """The study's recording (module docstring).

    Parameters
    ----------
    path : Path
    scene : stationbed.scene.Scene
        The study's scene (with ``[montecarlo]``).
    t : ndarray, shape (n_t,)
        Envelope times [s].
    env : ndarray, shape (n_samples, n_t, 2)
        ``att_err_deg`` and ``h_fraction`` per sample at ``t`` (NaN where a sample has none).
    df : pandas.DataFrame
        The study's table (one row per sample, in sample order).
    percentiles : callable
        ``percentiles(n_samples)``: the percentile lines the sample count supports.
    replay : bool
        Run the worst sample again for the 3-D view.
    """
    rr = import_rerun()
    rec = rr.RecordingStream(APPLICATION_ID)
    with saving(rec, path):  # a full disk: WriteFailed naming the file, never a hang
        rec.send_recording_name(f"{scene.name} montecarlo")
        idx = df["index"].to_numpy()
        series = []
        for j, name in enumerate(("att_err_deg", "h_fraction")):
            y = env[:, :, j]
            if np.all(np.isnan(y)):
                continue
            series.append(name)
            shown = percentiles(len(y))
            with quiet_nan():
                lines = np.stack([np.nanpercentile(y, p, axis=0) for p in shown], axis=1)
                worst = int(np.nanargmax(np.nanmax(y, axis=1)))
            ent = f"montecarlo/envelope/{name}"
            rec.log(ent, rr.SeriesLines(names=[f"p{p:g}" for p in shown]), static=True)
            rec.send_columns(ent, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=rr.Scalars.columns(scalars=lines))
            ent = f"montecarlo/worst/{name}"
            rec.log(ent, rr.SeriesLines(names=[f"sample {int(idx[worst])}"], colors=[(230, 40, 40)], widths=[2.0]),
                    static=True)
            rec.send_columns(ent, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=rr.Scalars.columns(scalars=y[worst]))
        text, ranked = worst_table(df)
        rec.log("montecarlo/worst_samples", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
        worst_k = ranked[0] if ranked and REPLAY_METRIC in df.columns and math.isfinite(
            float(df.loc[df["index"] == ranked[0], REPLAY_METRIC].iloc[0])) else None
        replayed = replay and worst_k is not None and _replay_worst(rec, scene, worst_k)
        rec.send_blueprint(_blueprint(scene, series, replayed, worst_k, float(t[-1]) if len(t) else 0.0), make_active=True, make_default=True)
        rec.flush()
    return path
