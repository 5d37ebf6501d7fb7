"""Output rows: the CSV columns of a scene, states turned into rows (compiled outputs plus the
loop's held values), streamed to a sink in batches as they are computed, kept or not.

Batches are bounded (:data:`ROW_BATCH` rows, :data:`FLUSH_S` seconds of work), so a run that
is killed has handed every row to its sink but the last batch (the bulk rows of the fused
loops: the last :data:`BULK_ROWS`), and a run that does not keep its rows (``keep=False``)
holds that much in memory whatever its length.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..core.compile import FastCall
from ..core.linalg import row_norms
from ..core.rotation import rotation_angle_vector
from ..integrators import IntegrationError
from ..loop.flight import flight_columns
from ..model.cmg import CmgModel
from ..model.torques import TORQUES
from ..scene import Scene
from ..scene.thrusters import flown_thrusters
from .metrics import RunMetrics
from .system import OUT_CHUNK
from .chain import chain_columns
from .fdir_run import fdir_columns
from .trajectory import Trajectory, base_columns
from .working_h import WorkingH

__all__ = ["trajectory_columns", "ATT_ERR_AXES", "Rows", "SinkError", "check_rows", "ROW_BATCH", "FLUSH_S", "BULK_ROWS"]

#: most rows in one batch handed to the sink (and in one integrator call of the open loop)
ROW_BATCH = 64
#: a batch is handed on once this much wall time [s] has passed since the last one, even short
FLUSH_S = 1.0
#: bulk rows (:meth:`Rows.hold_many`, a fused loop's compiled call of up to 64 rows) are made and
#: checked at once, then wait until this many (or FLUSH_S, or a flush) for their attitude error,
#: the sink (still in batches of ROW_BATCH) and the metrics, done once for them all: the same rows
#: and numbers, ~70 µs less Python per call (issue 25)
BULK_ROWS = 8 * ROW_BATCH


class SinkError(OSError):
    """A sink could not take a batch of rows (disk full, file too large, ...).

    Its message is one line naming the file, the reason and what the file holds.

    Parameters
    ----------
    path : str
        The file.
    last_t : float or None
        Time [s] of the last complete row in the file (None: no row).
    cause : OSError
        The error of the write.
    held : str, optional
        What the file holds, when not "the rows up to t = last_t" (e.g. "only the header").
    """

    def __init__(self, path, last_t, cause: OSError, held: str | None = None):
        super().__init__(cause.errno, cause.strerror)
        self.path = str(path)
        self.last_t = last_t
        if held is None:
            held = "no row" if last_t is None else f"the rows up to t = {last_t:.10g} s"
        self.held = held
        self.message = f"cannot write {self.path}: {cause.strerror or cause}; it holds {held}"

    def __str__(self) -> str:
        return self.message

    def __reduce__(self):
        return (_sink_error, (self.path, self.last_t, self.errno, self.strerror, self.held))


def _sink_error(path, last_t, errno, strerror, held):
    return SinkError(path, last_t, OSError(errno, strerror), held)


#: per-axis attitude error: the rotation vector from the controller's reference to B, B components
#: [deg] (≈ 2 vec(q_BR) for small errors; its norm is att_err_deg)
ATT_ERR_AXES = ["att_err_x_deg", "att_err_y_deg", "att_err_z_deg"]


def trajectory_columns(scene: Scene) -> list[str]:
    """The CSV columns of a run of ``scene`` (DESIGN §6 core, then CMG, controller, sun)."""
    cols = base_columns(scene.appendage_names)
    if scene.cmg is not None:
        cmg = CmgModel.of(scene.cmg)
        cols += ["hx", "hy", "hz"]
        names = cmg.gimbal_names
        cols += names + [f"{n}_rate" for n in names]
        if cmg.gimballed:
            cols.append("cmg_singularity")
        cols.append("cmg_saturated")
    if scene.controller is not None:
        cols += ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg", *ATT_ERR_AXES]
        cols += flight_columns(scene)  # sensors and estimator (issue 20)
        cols += chain_columns(scene)  # the actuator chain: magnetic torquers, thrusters (issues 21, 33)
        cols += fdir_columns(scene)  # fault detection and modes (issue 34)
        if scene.fault:  # scheduled faults (issue 34): how many are active at the row's time
            cols.append("faults_active")
    if scene.sun is not None:
        cols += [f"track_err_deg_{n}" for n in scene.appendage_names]
    for kind in TORQUES.values():  # kinds the scene names outside [[torque]] (gravity gradient: [orbit])
        if kind.output and kind.scene_model is None and kind.present(scene):
            cols += [f"{kind.output}_{c}" for c in "xyz"]
    for t in scene.torque:  # environment torques (issue 14), B components [N m]
        if TORQUES[t.kind].output:
            cols += [f"{TORQUES[t.kind].output}_{c}" for c in "xyz"]
    if scene.sun is not None and scene.sun.eclipse != "none":
        cols.append("eclipse")  # fraction of the sun's disc seen
    modes = [(a.name, k + 1) for a in scene.appendage for k in range(len(a.mode))]
    if modes:
        cols += [f"eta_{n}_{k}" for n, k in modes] + [f"etadot_{n}_{k}" for n, k in modes] + ["U_strain"]
    if scene.event:  # issue 35: the configuration flown, and the one the law was told of
        cols += ["config", "config_known"]
    return cols


def _configuration_times(scene) -> tuple[np.ndarray, np.ndarray]:
    """The times [s] the truth's configuration changes (each ``[[event]]``; -inf: a past one) and
    the times the law is told of each (``t + update_after_s``; inf: never); the ``config`` and
    ``config_known`` columns count those at or before a row's time."""
    done = np.array([-math.inf if e.done else e.t for e in scene.event], float)  # (a past event: from the start)
    known = np.array([-math.inf if e.done else math.inf if e.update_after_s == "never" else e.t + e.update_after_s
                      for e in scene.event])
    return done, known


class Rows:
    """Turns states into output rows (compiled outputs + the loop's held values) and streams them.

    Every value is placed in its CSV column by name: the compiled outputs by the system's
    ``out_layout``, the state's gimbal angles by the cluster's gimbal names, and the loop's held
    values by :attr:`held_columns` (the order in which the closed loop hands them over).

    Rows reach the sink in batches of at most :data:`ROW_BATCH` rows: :meth:`emit` hands one on
    at once; :meth:`hold` collects rows one by one and hands them on when the batch is full or
    :data:`FLUSH_S` has passed (and :meth:`flush` at the end).

    Parameters
    ----------
    scene : Scene
    system : System  The compiled system of the run.
    p : ndarray  The parameter vector of the scene.
    sink : object with ``write(rows)`` or None  Receives every batch of rows as it is made.
    keep : bool  Keep every row for :meth:`trajectory`; ``False``: only the last one (the sink
        has them all; :attr:`summary`, a :class:`~.metrics.RunMetrics`, has the reductions over them).
    """

    def __init__(self, scene, system, p, sink, keep: bool = True):
        self.form = system.formulation
        self.nx = self.form.nx
        self._q = self.form.state_layout.slice("q_BN")  # the attitude in the state, by name
        self.n_out = system.n_out
        self.out = FastCall.of(system.funcs["out_map"])
        #: the parameters the rows are made with (a scheduled step sets them: :meth:`set_params`);
        #: copied into the shared buffer at each :meth:`make`, as another run of the same system
        #: in this process (the environment rate's probe, run/rate_auto.py) writes it too
        self.p = np.array(p, dtype=float)
        self.out.args[2][:] = p
        self.columns = trajectory_columns(scene)
        self.scene = scene
        self.sink = sink
        #: a :func:`stationbed.core.progress.task` told the time of every batch (or None)
        self.progress = None
        #: a :class:`~.pacing.Pacer` (``--realtime``): each row is handed over at its deadline
        self.clock = None
        self.keep = keep
        self.rows: list[np.ndarray] = []
        mc = getattr(scene, "montecarlo", None)
        #: the run's :class:`~.metrics.RunMetrics` (the closed loop sets the cluster capacity)
        period = None if scene.orbit is None or not flown_thrusters(scene) else 2.0 * math.pi / scene.orbit.mean_motion
        self.summary = RunMetrics(self.columns, settle_s=None if mc is None else mc.settle_s, orbit_period_s=period,
                                  working=WorkingH.of_scene(scene, self.columns))
        self._pending = ([], [], [])  # times, states, held values of rows not yet made
        self._q_refs = []  # the controller's reference per pending row (None: no reference)
        self._bulk = []  # bulk rows made and checked, not yet handed on: (rows, q_refs, q) per call
        self._n_bulk = 0
        self._flushed_at = time.perf_counter()
        col = {c: i for i, c in enumerate(self.columns)}
        names = scene.appendage_names
        cmg = self.form.model.cmg
        gimbals = [] if cmg is None else cmg.gimbal_names
        # compiled output group -> its columns (the track errors are reported in degrees)
        targets = {"omega_BN_B": ["wx", "wy", "wz"], "H_O_N": ["HNx", "HNy", "HNz"], "T": ["T"],
                   "h_B": ["hx", "hy", "hz"], "cmg_singularity": ["cmg_singularity"], "U_strain": ["U_strain"]}
        for k, n in enumerate(names):
            targets[f"alpha{k}"], targets[f"beta{k}"] = [f"alpha_{n}"], [f"beta_{n}"]
            targets[f"track_err{k}"] = [f"track_err_deg_{n}"]
        modes = [f"{a.name}_{m + 1}" for a in scene.appendage for m in range(len(a.mode))]
        targets["eta"] = [f"eta_{m}" for m in modes]
        targets["etadot"] = [f"etadot_{m}" for m in modes]
        targets.update({kind.output: [f"{kind.output}_{c}" for c in "xyz"] for kind in TORQUES.values() if kind.output})
        targets["eclipse"] = ["eclipse"]
        #: (column indices, slice of the compiled output, in degrees?) per compiled group
        self.plan = [
            (np.array([col[c] for c in targets[name]]), sl, name.startswith("track_err"))
            for name, sl in system.out_layout.items()
        ]
        # the same placing as two gathers (issue 25: ~14 groups' assignments were ~25 µs of a
        # 64-row batch): every group's columns at once, then the ones in degrees (no column twice)
        by = [[], []]
        for cols, sl, degrees in self.plan:
            by[degrees].append((cols, np.arange(*sl.indices(self.n_out))))
        self._gather = [(np.concatenate([c for c, _ in g]), np.concatenate([i for _, i in g])) if g else None
                        for g in by]
        dst = np.concatenate([cols for cols, _, _ in self.plan]) if self.plan else np.zeros(0, int)
        cols, times = np.unique(dst, return_counts=True)
        if (times > 1).any():  # two outputs claiming one column: a bug in the targets above
            raise AssertionError(f"rows: columns placed twice: {[self.columns[c] for c in cols[times > 1]]}")
        self.q_cols = np.array([col[c] for c in ("qw", "qx", "qy", "qz")])
        self.gimbal_cols = np.array([col[g] for g in gimbals], dtype=int)
        g0 = self.form.state_layout.slice("x_cmg").start if "x_cmg" in self.form.state_layout else 0
        self._gimbals = slice(g0, g0 + len(self.gimbal_cols))  # the gimbal angles: x_cmg's first
        #: the loop's held values per row, in the order the closed loop hands them over
        self.held_columns = []
        if cmg is not None:
            self.held_columns += [f"{g}_rate" for g in gimbals] + ["cmg_saturated"]
        if scene.controller is not None:
            self.held_columns += ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg", *ATT_ERR_AXES]
            self.held_columns += flight_columns(scene)
            self.held_columns += chain_columns(scene)
            self.held_columns += fdir_columns(scene)
        self.held_cols = np.array([col[c] for c in self.held_columns], dtype=int)
        self._err_col = col.get("att_err_deg")
        self._config = (col["config"], col["config_known"], *_configuration_times(scene)) if scene.event else None
        self._axes_cols = [col[c] for c in ATT_ERR_AXES] if self._err_col is not None else []
        self._faults = None  # (column, tick-grid starts, ends [s]) of the scheduled faults
        if "faults_active" in col:
            per = scene.controller.period
            grid = lambda v: round(v / per) * per  # noqa: E731 (the tick time the step applies at)
            on = [f for f in scene.fault if f.enabled]
            self._faults = (col["faults_active"], np.array([grid(f.t) for f in on]),
                            np.array([math.inf if f.until is None else grid(f.until) for f in on]))

    def make(self, ts, xs, held=None) -> np.ndarray:
        """Rows for times ``ts`` and states ``xs``.

        Parameters
        ----------
        ts : array_like, shape (k,)  Times [s].
        xs : array_like, shape (k, nx)  States of the formulation.
        held : array_like, shape (k, len(held_columns)), optional
            The loop's values per row (:attr:`held_columns`); zeros when None (open loop).

        Returns
        -------
        ndarray, shape (k, len(columns))
        """
        ts = np.asarray(ts, dtype=float)
        xs = np.asarray(xs, dtype=float).reshape(len(ts), self.nx)
        comp = np.empty((len(ts), self.n_out))
        o = self.out
        o.args[2][:] = self.p
        for k in range(0, len(ts), OUT_CHUNK):
            n = min(OUT_CHUNK, len(ts) - k)
            o.args[0][:n] = ts[k : k + n]
            o.args[1].reshape(OUT_CHUNK, self.nx)[:n] = xs[k : k + n]
            o()
            comp[k : k + n] = o.res[0].reshape(OUT_CHUNK, self.n_out)[:n]
        rows = np.zeros((len(ts), len(self.columns)))
        rows[:, 0] = ts
        q = xs[:, self._q]
        rows[:, self.q_cols] = q / row_norms(q, keepdims=True)
        plain, degrees = self._gather
        if plain is not None:
            rows[:, plain[0]] = comp[:, plain[1]]
        if degrees is not None:
            rows[:, degrees[0]] = np.rad2deg(comp[:, degrees[1]])
        rows[:, self.gimbal_cols] = xs[:, self._gimbals]
        if held is not None and len(self.held_cols):
            rows[:, self.held_cols] = np.asarray(held, dtype=float).reshape(len(ts), -1)
        if self._faults is not None:  # a fault is active from its tick (that row sees it) to its until's
            c, t0, t1 = self._faults
            rows[:, c] = ((ts[:, None] >= t0) & (ts[:, None] < t1)).sum(axis=1)
        if self._config is not None:  # (times on the tick grid: an event's own row counts it)
            c_done, c_known, done, known = self._config
            rows[:, c_done] = np.searchsorted(done, ts + 1e-9 * np.maximum(1.0, ts), side="right")
            rows[:, c_known] = np.sum(known[None, :] <= ts[:, None] + 1e-9 * np.maximum(1.0, ts[:, None]), axis=1)
        return rows

    def set_params(self, p) -> None:
        """The parameters of the rows from now on (a scheduled step: run/schedule.py)."""
        self.p[:] = p

    def emit(self, rows: np.ndarray) -> None:
        """Hand ``rows`` (k, len(columns)) to the sink, then count and (``keep``) keep them.

        Raises
        ------
        SinkError
            From the sink: the rows are not counted.
        """
        self._send_bulk()
        if self.clock is not None and len(rows) > 1:  # paced: a row at a time, each at its deadline
            for i in range(len(rows)):
                self.emit(rows[i : i + 1])
            return
        if len(rows):
            if self.clock is not None:
                self.clock.wait(float(rows[0, 0]))
            if self.sink is not None:
                self.sink.write(rows)
            self._count(rows)

    def _count(self, rows: np.ndarray) -> None:
        """Count (and ``keep``, keep) rows the sink has taken."""
        if len(rows):
            self._flushed_at = time.perf_counter()
            self.summary.update(rows)
            if self.progress is not None:
                self.progress.update(float(rows[-1, 0]))
            if self.keep:
                self.rows.append(rows)

    def hold(self, t: float, x, held, q_ref=None) -> None:
        """Add the row at ``t`` (state ``x``, the loop's ``held`` values, the controller's
        reference ``q_ref`` (4,) or None) to the pending batch; the batch is made and emitted
        when full or :data:`FLUSH_S` after the last one. ``att_err_deg`` is the angle between
        ``q_ref`` and the row's attitude (NaN without a reference), computed a batch at a time
        (:func:`~stationbed.core.rotation.rotation_angle` is row-wise: the same numbers)."""
        if self.clock is not None:
            self.clock.wait(t)
        ts, xs, hs = self._pending
        ts.append(t)
        xs.append(np.array(x, dtype=float))
        hs.append(held)
        self._q_refs.append(q_ref)
        if len(ts) >= ROW_BATCH or time.perf_counter() - self._flushed_at >= FLUSH_S:
            self.flush()

    def hold_many(self, ts, xs, held, q_refs) -> None:
        """Rows at times ``ts`` (k,) with states ``xs`` (k, nx), the loop's ``held`` values
        (k, len(held_columns)) and the controller's references ``q_refs`` (k, 4), all at once:
        the rows pending first, then these (the rows :meth:`hold` one by one and :meth:`flush`
        would make, in bulk; issue 25). They are made and checked now (IntegrationError at a
        non-finite core value, the rows before it handed on); their attitude error, the sink
        and the metrics wait for :data:`BULK_ROWS` rows (or :data:`FLUSH_S`, or :meth:`flush`)
        and take them all at once (row by row the same numbers; the sink in ROW_BATCH rows)."""
        if self._pending[0]:
            self.flush()
        rows = self.make(ts, xs, held)
        bad = ~np.all(np.isfinite(rows[:, :12]), axis=1)
        k = int(np.argmax(bad)) if bad.any() else len(rows)
        q_refs = np.array(q_refs[:k], dtype=float) if self._err_col is not None else None
        q = np.array(xs[:k, self._q], dtype=float) if self._err_col is not None else None
        if self.clock is None:  # (copies: the caller's arrays may be a compiled call's buffers)
            self._bulk.append((rows[:k], q_refs, q))
            self._n_bulk += k
        else:  # paced (run/pacing.py): each row waits for its deadline; handed over every FLUSH_S
            for i in range(k):
                self.clock.wait(float(rows[i, 0]))
                self._bulk.append((rows[i : i + 1], None if q is None else q_refs[i : i + 1],
                                   None if q is None else q[i : i + 1]))
                self._n_bulk += 1
                if time.perf_counter() - self._flushed_at >= FLUSH_S:
                    self._send_bulk()
        if k < len(rows):
            self._send_bulk()
            raise IntegrationError(rows[k, 0], "outputs are not finite (NaN or inf)")
        if self._n_bulk >= BULK_ROWS or time.perf_counter() - self._flushed_at >= FLUSH_S:
            self._send_bulk()

    def _send_bulk(self) -> None:
        """Hand on the bulk rows waiting: their attitude error at once, the sink in batches of
        :data:`ROW_BATCH`, the rows it took counted at once (a SinkError: those before it)."""
        if not self._bulk:
            return
        parts, self._bulk, self._n_bulk = self._bulk, [], 0
        rows = parts[0][0] if len(parts) == 1 else np.concatenate([p[0] for p in parts])
        if self._err_col is not None and len(rows):
            q_ref, q = (np.concatenate([p[i] for p in parts]) for i in (1, 2))
            angle, axes = rotation_angle_vector(q_ref, q)
            rows[:, self._err_col] = np.degrees(angle)
            # per axis: the error rotation vector, B components [deg] (its norm is att_err_deg)
            rows[:, self._axes_cols] = np.degrees(axes)
        taken = len(rows) if self.sink is None else 0
        try:
            while taken < len(rows):
                self.sink.write(rows[taken : taken + ROW_BATCH])
                taken = min(taken + ROW_BATCH, len(rows))
        finally:
            self._count(rows[:taken])

    def flush(self) -> None:
        """Make and emit the pending rows; raises IntegrationError at a non-finite core value
        (the rows before it are emitted)."""
        self._send_bulk()
        ts, xs, hs = self._pending
        if ts:
            rows = self.make(ts, xs, hs)
            refs = self._q_refs
            have = [i for i, q in enumerate(refs) if q is not None]
            if have and self._err_col is not None:
                q_ref = np.array([refs[i] for i in have], dtype=float)
                q = np.array([xs[i][self._q] for i in have])
                angle, axes = rotation_angle_vector(q_ref, q)
                rows[have, self._err_col] = np.degrees(angle)
                # per axis: the error rotation vector, B components [deg] (its norm is att_err_deg)
                rows[np.ix_(have, self._axes_cols)] = np.degrees(axes)
            ts.clear(), xs.clear(), hs.clear(), refs.clear()
            check_rows(rows[:, :12], lambda ok: self.emit(rows[: len(ok)]))

    def trajectory(self, meta) -> Trajectory:
        """The rows kept so far as a :class:`Trajectory` with ``meta`` (to which ``n_rows``, the
        rows emitted, is added); without ``keep``, the last row only."""
        meta["n_rows"] = self.summary.n_rows
        if self.keep:
            data = np.vstack(self.rows) if self.rows else np.zeros((0, len(self.columns)))
        else:
            last = self.summary.last
            data = np.zeros((0, len(self.columns))) if last is None else last[None]
        return Trajectory(self.columns, data, meta)


def check_rows(rows: np.ndarray, emit) -> None:
    """Emit the finite rows; raise at the first non-finite one."""
    bad = ~np.all(np.isfinite(rows), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        emit(rows[:i])
        raise IntegrationError(rows[i, 0], "outputs are not finite (NaN or inf)")
    emit(rows)
