"""Row sinks that record: :class:`RrdSink` streams a run's rows into a rerun recording,
:class:`TeeSink` hands every batch to several sinks.

A recording holds the 3-D scene (:mod:`.drawing`), the time series on the ``sim_time`` timeline
[s] under ``telemetry/`` (:mod:`.series`) and the blueprint (:mod:`.blueprint`), all in one file.

:class:`RrdSink` streams: the rows :func:`stationbed.simulate` hands over are sent and flushed
to the file at most ``flush_interval_s`` of wall time after they arrive, and all of them when the
sink closes (which the command line does on every way out, failed runs included), so a run that
fails part-way leaves a complete, verifiable recording up to the failure; a killed process leaves
everything but the last interval. The static parts (geometry, axes, series names, blueprint) are
sent once when the sink opens.

Cost: the per-call overhead of the SDK (~0.1 ms per ``send_columns``, ~1 ms per blocking flush)
is what logging costs, so rows are collected and sent at most every ``flush_interval_s`` of wall
time (and on :meth:`RrdSink.close`), not per batch the simulation hands over.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...run.trajectory import Trajectory, base_columns
from .blueprint import run_blueprint
from .drawing import StationDrawing
from .sdk import APPLICATION_ID, TIMELINE, RrdFile, import_rerun
from .series import Telemetry

__all__ = ["RrdSink", "TeeSink", "FLUSH_INTERVAL_S"]

#: Wall time [s] rows may wait in an RrdSink before they are sent and flushed to the file.
#: Each send costs ~0.1 ms per entity (23 for iss_lvlh_hold) plus the flush; the closed loop
#: hands over 64 rows every ~40 ms, and sending each batch cost 15-18 % of a 3-orbit run against
#: ~5 % when collected (benchmarks/bench_rerun.py, docs/rerun.md). A killed process loses at
#: most this much; a failed run nothing (close sends the rest). 0: send and flush every batch.
FLUSH_INTERVAL_S = 0.5


class TeeSink:
    """Hands every batch of rows to several sinks (e.g. a :class:`~stationbed.output.csv.CsvSink`
    and an :class:`RrdSink`); :meth:`close` closes those that have a ``close`` method.

    Parameters
    ----------
    *sinks
        Objects with ``write(rows)``; the first one's ``columns`` are the tee's.
    """

    def __init__(self, *sinks):
        self.sinks = sinks
        self.columns = getattr(sinks[0], "columns", None) if sinks else None

    def write(self, rows: np.ndarray) -> None:
        """Hand ``rows`` to every sink, in order.

        Parameters
        ----------
        rows : ndarray, shape (k, len(columns))
        """
        for s in self.sinks:
            s.write(rows)

    def close(self) -> None:
        """Close every sink that can be closed; then raise the first failure, if any."""
        errors = []
        for s in self.sinks:
            close = getattr(s, "close", None)
            if close is not None:
                try:
                    close()
                except Exception as e:  # close the others, then report the first failure
                    errors.append(e)
        if errors:
            raise errors[0]


class RrdSink:
    """Streams trajectory rows of ``scene`` into a rerun recording at ``path``.

    Parameters
    ----------
    scene : stationbed.scene.Scene
    path : str or Path
        The ``.rrd`` file (parent folders are created).
    columns : list of str
        Column names of the rows :meth:`write` receives; they must include
        :func:`~stationbed.run.trajectory.base_columns` of the scene (columns are looked up by
        name). The CMG, controller and sun columns of
        :func:`~stationbed.run.rows.trajectory_columns` get their own entities
        (``telemetry/cmg/...``, ``telemetry/control/...``,
        ``telemetry/arrays/<name>/track_err_deg``), and so do the modal columns of flexible
        arrays (``telemetry/modes/...``); any other column is logged under
        ``telemetry/extra/<column>``.
    duration : float, optional
        Run length [s], for the blueprint only: the plots' time axis and the playback speed
        (default: the scene's ``simulation.duration``).
    flush_interval_s : float, optional
        Rows handed to :meth:`write` are collected and sent (one chunk per entity,
        ``send_columns``) and flushed to the file once this much wall time [s] has passed since
        the last send; :meth:`flush` and :meth:`close` send what is left. Default
        :data:`FLUSH_INTERVAL_S`; 0 sends and flushes every batch at once.
    live : str, optional
        Also stream the same recording to a rerun viewer or gRPC server (``run --live``,
        :mod:`.live`): a ``rerun+http://HOST:PORT/proxy`` URL, or ``"spawn"`` to start a viewer
        (``rr.spawn``). ``path`` may then be None (streamed only).

    Attributes
    ----------
    rec : rerun.RecordingStream
        The stream writing ``path``.
    n_rows : int
        Rows sent to the file so far.
    t_last : float or None
        Time of the last row sent [s].

    Notes
    -----
    Whatever has been sent is on disk: the file is readable up to the last send even if the
    process is killed (without the footer/manifest then, which :meth:`close` writes). Use as a
    context manager or call :meth:`close`.
    """

    def __init__(self, scene, path, columns, *, duration: float | None = None,
                 flush_interval_s: float = FLUSH_INTERVAL_S, live: str | None = None):
        rr = import_rerun()
        self.rr = rr
        self.scene = scene
        self.path = Path(path) if path is not None else None
        self.columns = list(columns)
        base = base_columns(scene.appendage_names)
        missing = [c for c in base if c not in self.columns]
        if missing:
            raise ValueError(f"rows lack the columns {missing} (every run has {base}), got {self.columns}")
        self.drawing = StationDrawing(scene, self.columns)
        self.telemetry = Telemetry(scene, self.columns)
        self.flush_interval_s = float(flush_interval_s)
        self._pending: list[np.ndarray] = []
        self.n_rows = 0  # rows sent to the file
        self.t_last = None  # time of the last row sent [s]
        self._closed = False
        self.rec = rr.RecordingStream(APPLICATION_ID)
        # stationbed writes the file (rerun saves into a FIFO it copies): a full disk is an error,
        # never a hang; with --live the viewer sees what the file gets: one stream, two sinks
        self._file = RrdFile(self.path) if self.path is not None else None
        try:
            if live is None:
                self.rec.save(self._file.fifo)
            else:
                from .live import grpc_sink

                file_sink = [rr.FileSink(self._file.fifo)] if self._file is not None else []
                self.rec.set_sinks(grpc_sink(self.rec, live), *file_sink)
        except BaseException:
            if self._file is not None:
                self._file.close(check=False)
            raise
        self.rec.send_recording_name(scene.name)
        self.rec.send_property("scene", rr.AnyValues(name=scene.name, description=scene.description))
        extra = [c for c in self.columns if c not in base]
        self.rec.send_blueprint(run_blueprint(scene, extra, duration), make_active=True, make_default=True)
        self.drawing.log_static(self.rec)
        self.telemetry.log_static(self.rec)
        self.rec.flush(timeout_sec=0.0)  # start writing the static parts, do not wait
        self._t_sent = time.monotonic()

    # -- context manager
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- streaming
    def write(self, rows: np.ndarray) -> None:
        """Take a batch of rows; send what is collected once ``flush_interval_s`` has passed
        since the last send.

        Parameters
        ----------
        rows : ndarray, shape (k, len(columns)) or (len(columns),)
            Values in the units of their columns (DESIGN §6).

        Raises
        ------
        ValueError
            The sink is closed.
        """
        if self._closed:
            raise ValueError("RrdSink is closed")
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        if rows.shape[0] == 0:
            return
        self._pending.append(rows)
        if self.flush_interval_s <= 0.0:
            self.flush()
        elif time.monotonic() - self._t_sent >= self.flush_interval_s:
            self._send_pending()
            self.rec.flush(timeout_sec=0.0)  # the SDK's writer thread puts it on disk meanwhile

    def flush(self) -> None:
        """Send the rows collected so far and wait until they are in the file."""
        self._send_pending()
        self.rec.flush()

    def _send_pending(self) -> None:
        if self._pending:
            rows = self._pending[0] if len(self._pending) == 1 else np.vstack(self._pending)
            self._pending = []
            self._send(Trajectory(self.columns, rows))
        self._t_sent = time.monotonic()

    def _send(self, rows: Trajectory) -> None:
        """One ``send_columns`` per entity for all of ``rows``, on their times."""
        rr, rec = self.rr, self.rec
        index = [rr.TimeColumn(TIMELINE, duration=rows.t)]

        def send(path, columns):
            rec.send_columns(path, indexes=index, columns=columns)

        self.drawing.send(rec, send, rows)
        self.telemetry.send(send, rows)
        self.n_rows += len(rows)
        self.t_last = float(rows.t[-1])

    def close(self) -> None:
        """Send what is left, write the file's footer and release it (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._send_pending()
        finally:
            self.rec.disconnect()  # flushes everything, writes the footer, closes rerun's end
            if self._file is not None:
                self._file.close()  # WriteFailed (naming the file) when a write failed
