"""Running Monte Carlo samples: one sample (draw, closed or open loop run, metrics, envelope
rows) and one chunk of samples (the unit of work a Dask worker gets).

A chunk returns its table (one row per sample) and its envelope arrays; it writes nothing, so a
worker needs no shared file system and a chunk that is run twice (a worker died) gives the same
result. Samples of one structure share one compiled system: the first sample of a process
loads it from the disk cache (the driver built it before dispatch), the others find it in the
process's cache (:func:`stationbed.run.system.build_system`).
"""

from __future__ import annotations

import logging
import math
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ...model.cmg import capacity
from ...run.controller import one_line
from ...run.metrics import METRICS, RunMetrics
from ...run.rows import trajectory_columns
from ...run.lockstep import run_lockstep
from ...run.simulation import SimulationError, simulate
from ...run.trajectory import Trajectory
from ...run.working_h import WorkingH
from ...scene.thrusters import flown_thrusters
from .dispersions import draw, sample_seed

__all__ = ["run_sample", "run_batch", "run_chunk", "held_warnings", "ID_COLUMNS", "ENVELOPE_SERIES", "EnvelopeSink",
           "scene_metrics", "metric_needs"]

#: the leading columns of the table
ID_COLUMNS = ["index", "seed", "status", "reason", "redraws", "stopped_at_s", "executor"]
#: per-sample downsampled series kept for the envelopes
ENVELOPE_SERIES = ("att_err_deg", "h_fraction")


class EnvelopeSink:
    """Keeps the rows of a run at the envelope times (multiples of ``dt``): attitude error [deg]
    and the working units' |h| over their capacity at the row (NaN where the run has no such
    column): :meth:`WorkingH.fraction <stationbed.run.working_h.WorkingH.fraction>`, the series
    whose largest value is the run's ``max_h_fraction``.

    Parameters
    ----------
    columns : list of str  The run's columns.
    dt : float  Envelope sampling [s].
    n_times : int  Envelope times ``0, dt, ..., (n_times - 1) dt``.
    working : WorkingH or None  The run's working units (:meth:`WorkingH.of_scene
        <stationbed.run.working_h.WorkingH.of_scene>` with the start's capacity; None: no fraction).
    """

    def __init__(self, columns, dt: float, n_times: int, working: WorkingH | None = None):
        col = {c: i for i, c in enumerate(columns)}
        self.dt = dt
        self.values = np.full((n_times, len(ENVELOPE_SERIES)), np.nan)
        self._err = col.get("att_err_deg")
        self._working = working

    def write(self, rows: np.ndarray) -> None:
        k = rows[:, 0] / self.dt
        i = np.rint(k)
        on = (np.abs(k - i) < 1e-9 * np.maximum(1.0, i)) & (i < len(self.values))
        # every row to the working units (a held unit's momentum is its window's first row's)
        frac = None if self._working is None else self._working.fraction(rows)
        if not on.any():
            return
        idx = i[on].astype(int)
        if self._err is not None:
            self.values[idx, 0] = rows[on][:, self._err]
        if frac is not None:
            self.values[idx, 1] = frac[on]


def _capacity(scene) -> float | None:
    return None if scene.cmg is None else capacity(scene.cmg)


def scene_metrics(scene) -> list[str]:
    """The :data:`METRICS` a run of ``scene`` reports, in their order: the run's own reduction
    (:class:`~stationbed.run.metrics.RunMetrics` over the run's columns, with the cluster's
    capacity, the orbit period of a thruster scene and the tick counts of a closed loop flying a
    cluster, as the run gives them) fed one made-up row: a metric it does not report then has no
    column, capacity or count to come from. The study's table has these columns only."""
    columns = trajectory_columns(scene)
    cap = _capacity(scene)
    period = 2.0 * math.pi / scene.orbit.mean_motion if scene.orbit is not None and flown_thrusters(scene) else None
    m = RunMetrics(columns, h_capacity_Nms=cap, orbit_period_s=period)
    row = np.zeros((1, len(columns)))
    row[0, columns.index("t")] = 1.0  # s, after the start (a per-orbit figure needs a run length)
    m.update(row)
    if scene.controller is not None and scene.cmg is not None:  # the closed loop counts its ticks
        m.count_ticks(0, 0)
    got = m.values()
    return [name for name in METRICS if name in got]


#: what a scene needs for a metric to be reported (the one-line refusal of a requirement on it)
_NEEDS = {
    **dict.fromkeys(("max_att_err_deg", "final_att_err_deg", "rms_att_err_deg", "max_torque_cmd_Nm"),
                    "a [controller] (its reference gives the attitude error, its command the torque)"),
    "max_h_Nms": "a [cmg] table",
    "max_h_fraction": "a [cmg] with a momentum capacity (an ideal one: max_momentum)",
    "min_singularity": "a gimballed [cmg] (dgcmg or sgcmg_pyramid)",
    **dict.fromkeys(("rate_limited_ticks", "momentum_saturated_ticks"), "a [controller] flying a [cmg]"),
    **dict.fromkeys(("max_est_err_deg", "rms_est_err_deg", "mean_nees", "est_inside_3sigma"),
                    "an [estimator] (with its [[sensor]] tables)"),
    "st_dropout_s": "[[sensor]] star trackers",
    **dict.fromkeys(("propellant_kg", "thruster_firings", "thruster_control_s", "thruster_impulse_Ns"),
                    "[[thruster]] tables"),
    "propellant_kg_per_orbit": "[[thruster]] tables and an [orbit]",
}


def metric_needs(name: str) -> str:
    """What a scene needs for the metric ``name`` to be reported (words for an error message)."""
    return _NEEDS.get(name, "columns that a run of this scene does not have")


def run_sample(scene, k: int, env_times: int = 0) -> tuple[dict, np.ndarray | None]:
    """Draw and run sample ``k`` of ``scene`` (which has a ``[montecarlo]`` table).

    Returns
    -------
    row : dict
        :data:`ID_COLUMNS`, the drawn values, every :data:`METRICS` name (NaN when the run has
        no value for it).
    envelope : ndarray, shape (env_times, len(ENVELOPE_SERIES)), or None
        The run's rows at the envelope times (NaN after a failure), None when ``env_times`` is 0.
    """
    row, s, sink = _drawn(scene, k, env_times)
    result = None
    if s is not None:
        try:
            result = simulate(s, keep=False, sink=sink)
        except Exception as e:  # noqa: BLE001 - recorded as the sample's failure (_finished)
            result = e
        row["executor"] = "fused" if isinstance(result, Trajectory) and result.meta.get("summary", {}).get("fused") \
            else "per-tick"
    return _finished(row, result, sink, env_times)


def _drawn(scene, k: int, env_times: int, data: dict | None = None):
    """Sample ``k`` drawn: its row so far, its scene (None when refused) and envelope sink
    (``data``: ``scene.model_dump()``, shared by a chunk's samples)."""
    mc = scene.montecarlo
    row = {"index": k, "seed": sample_seed(mc.seed, k), "status": "ok", "reason": "", "redraws": 0,
           "stopped_at_s": math.nan, "executor": ""}
    s, dr, redraws, refused = draw(scene, k, data)
    row["redraws"] = redraws
    row.update(dr.values)
    sink = None
    if refused is not None:
        row["status"], row["reason"] = "refused", refused
        return row, None, None
    if env_times:
        columns = trajectory_columns(s)
        sink = EnvelopeSink(columns, mc.envelope_dt, env_times, WorkingH.of_scene(s, columns, _capacity(s)))
    return row, s, sink


def _finished(row: dict, result, sink, env_times: int):
    """The row and envelope of a sample from its run's result: a Trajectory, or the exception
    its run raised (a SimulationError: failed at a time; another: a refused reset or model)."""
    metrics: dict = {}
    env = None
    if result is not None:
        if isinstance(result, SimulationError):
            row["status"], row["reason"], row["stopped_at_s"] = "failed", result.reason, float(result.t)
            metrics = result.trajectory.meta.get("summary", {})
        elif isinstance(result, BaseException):  # a controller's reset or the scene's model refused
            row["status"], row["reason"] = "failed", f"{type(result).__name__}: {one_line(result)}"
        else:
            metrics = result.meta.get("summary", {})
        if sink is not None:
            env = sink.values
    for name in METRICS:
        v = metrics.get(name)
        row[name] = float(v) if v is not None else math.nan
    if env_times and env is None:
        env = np.full((env_times, len(ENVELOPE_SERIES)), np.nan)
    return row, env


def run_batch(scene, k0: int, k1: int, env_times: int = 0) -> list[tuple[dict, np.ndarray | None]]:
    """Samples ``k0 .. k1-1`` drawn, then run together (:func:`~stationbed.run.lockstep.run_lockstep`:
    in lockstep where the law and scene allow, else fused or per tick, one by one); the same
    rows as :func:`run_sample` of each, with the executor that ran it."""
    data = scene.model_dump()  # read only: each draw copies what it changes (Scene.replace)
    drawn = [_drawn(scene, k, env_times, data) for k in range(k0, k1)]
    todo = [i for i, d in enumerate(drawn) if d[1] is not None]
    results = run_lockstep([drawn[i][1] for i in todo], sinks=[drawn[i][2] for i in todo])
    by = dict(zip(todo, results))
    out = []
    for i, (row, s, sink) in enumerate(drawn):
        kind, res = by.get(i, ("", None))
        row["executor"] = kind
        out.append(_finished(row, res, sink, env_times))
    return out


class _Held(logging.Filter):
    """Holds the "stationbed" logger's warnings (kept, not printed) while a worker runs a chunk."""

    def __init__(self):
        super().__init__()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            msg = record.getMessage()
            if msg not in self.messages:
                self.messages.append(msg)
            return False
        return True


@contextmanager
def held_warnings(log: bool = True):
    """The warnings of the block, as one-line messages, instead of on this process's stderr:
    Python warnings, and with ``log`` the "stationbed" logger's. A Dask worker's stderr is the
    user's terminal, without the command line's ``stationbed:`` prefix, once per worker: the
    driver says them (:func:`.engine.run_study`), once per study."""
    held = _Held()
    logger = logging.getLogger("stationbed")
    if log:
        logger.addFilter(held)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            yield held.messages
    finally:
        logger.removeFilter(held)
    for w in caught:
        msg = f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})"
        if msg not in held.messages:
            held.messages.append(msg)


def run_chunk(scene, k0: int, k1: int, env_times: int = 0, hold_log: bool = False) -> dict:
    """Samples ``k0 .. k1-1``: ``{"k0", "k1", "rows": [row dicts], "envelope": ndarray
    (k1 - k0, env_times, len(ENVELOPE_SERIES)) or None, "warnings": [str]}``. The chunk's
    Python warnings (and with ``hold_log``, on a Dask worker, the "stationbed" logger's) are
    returned for the driver to say once, not printed here."""
    rows, envs = [], []
    with held_warnings(hold_log) as said:
        for row, env in run_batch(scene, k0, k1, env_times):
            rows.append(row)
            envs.append(env)
    return {"k0": k0, "k1": k1, "rows": rows, "envelope": np.stack(envs) if env_times else None,
            "warnings": list(said)}
