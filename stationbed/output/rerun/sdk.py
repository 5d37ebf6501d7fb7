"""The rerun SDK, imported on first use, and the names every stationbed recording is filed under.

``import rerun`` costs ~0.3-0.5 s: it is paid only when a recording is made
(:func:`import_rerun`); ``stationbed run --rrd`` pays it in the recording child
(:mod:`stationbed.output.rerun.child`) while the parent simulates.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

from ...core.paths import WriteFailed, writing

__all__ = ["APPLICATION_ID", "TIMELINE", "import_rerun", "RrdFile", "saving"]

#: Application id of every recording (run and check recordings alike).
APPLICATION_ID = "stationbed"
#: Timeline of every temporal entity: seconds since the start of the run (a rerun duration
#: timeline, stored as integer nanoseconds).
TIMELINE = "sim_time"


def import_rerun():
    """The ``rerun`` module, imported now (deferred: the import costs ~0.3-0.5 s).

    Returns
    -------
    module
        ``rerun`` (rerun-sdk).
    """
    import rerun as rr

    return rr


#: Bytes copied from rerun's pipe to the file at a time.
COPY_BYTES = 1 << 20
#: Longest wait [s] for the copy to end once rerun has closed its end (it has only the pipe's
#: last bytes left to write).
COPY_JOIN_S = 60.0


class RrdFile:
    """The ``.rrd`` file a recording goes to, written by stationbed, not by rerun's file sink.

    rerun's own sink (``rec.save(path)``) hangs on a full disk (rerun 0.41: its writer thread dies
    on ENOSPC and the next blocking ``flush`` waits for it forever) or ends as if the file were
    complete. Here rerun saves into a FIFO and a thread copies the stream to ``path``: a failed
    write is kept (and the rest of the stream read and dropped, so rerun never blocks), and
    :meth:`close` raises it as :class:`~stationbed.core.paths.WriteFailed` naming the file.
    The file is new (a link at ``path`` is replaced, never written through).

    Use: ``f = RrdFile(path)``, ``rec.save(f.fifo)``, log, ``rec.disconnect()``, ``f.close()``
    (or :func:`saving`).
    """

    def __init__(self, path):
        self.path = Path(path)
        self.error: OSError | None = None
        with writing(self.path) as p:
            p.parent.mkdir(parents=True, exist_ok=True)  # a recording may go to a folder of its own
            self._out = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        self._dir = tempfile.mkdtemp(prefix="stationbed_rrd_")
        self.fifo = os.path.join(self._dir, "stream.rrd")
        os.mkfifo(self.fifo)
        self._thread = threading.Thread(target=self._copy, name="stationbed-rrd-copy", daemon=True)
        self._thread.start()

    def _copy(self) -> None:
        try:
            fd = os.open(self.fifo, os.O_RDONLY)  # until rerun opens its end
        except OSError as e:
            self.error = e
            return
        try:
            while chunk := os.read(fd, COPY_BYTES):
                if self.error is not None:
                    continue  # drain: rerun must never block on a full pipe
                view, done = memoryview(chunk), 0
                try:
                    while done < len(view):
                        done += os.write(self._out, view[done:])
                except OSError as e:
                    self.error = e
        finally:
            os.close(fd)

    def close(self, *, check: bool = True) -> None:
        """After ``rec.disconnect()``: wait for the copy, close the file, remove the FIFO; raise
        :class:`~stationbed.core.paths.WriteFailed` when a write failed (``check``)."""
        if self._out is None:
            return
        if self._thread.is_alive():
            try:  # rerun never opened the FIFO (it failed first): end the copy's wait (else harmless)
                os.close(os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                pass
        self._thread.join(COPY_JOIN_S)
        if self._thread.is_alive() and self.error is None:
            self.error = TimeoutError(f"the recording's last bytes took over {COPY_JOIN_S:g} s")
        os.close(self._out)
        self._out = None
        shutil.rmtree(self._dir, ignore_errors=True)
        if check and self.error is not None:
            raise WriteFailed(self.path, self.error)


@contextmanager
def saving(rec, path):
    """``rec`` recording into the new file ``path`` (:class:`RrdFile`) for the block; disconnected
    and the file closed after it (:class:`~stationbed.core.paths.WriteFailed` on a failed write)."""
    f = RrdFile(path)
    try:
        rec.save(f.fifo)
        yield rec
    except BaseException:
        rec.disconnect()
        f.close(check=False)
        raise
    rec.disconnect()
    f.close()
