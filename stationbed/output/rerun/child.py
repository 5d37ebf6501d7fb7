"""``stationbed run --rrd``: the recording is written by a child process, off the run's critical path.

The command line starts the child first thing (:meth:`RecordingChild.start`, before the parent
imports the simulation's modules), so that the child's ``import rerun`` (~0.3-0.5 s) and its set-up
run on the second core while the parent imports, loads the scene and simulates. The child loads the
same scene file and, once the parent has opened the run (:meth:`RecordingChild.open`: the row
columns and the run's duration), builds the same :class:`~stationbed.output.rerun.sink.RrdSink` as an
in-process run would and feeds it every row the parent streams over its stdin.

Protocol on the child's stdin: the line :data:`MAGIC`, one JSON line ``{"columns": [...],
"duration": float | null, "scene": name}``, then the rows as little-endian float64, row after row
(``len(columns)`` values each), in whatever pieces the pipe delivers; end of file ends the run. The
parent never blocks on the pipe while it simulates (non-blocking writes, rows that do not fit wait
in the parent until the next batch or :meth:`RecordingChild.close`).

Failure behaviour:

* the run fails (``SimulationError``) or is interrupted: the parent still closes the pipe and waits,
  the child sends every row and closes the recording (footer written, ``rerun rrd verify`` passes);
* the parent is killed (SIGKILL): the pipe reaches end of file, the child records every row the
  parent had handed to the pipe and closes the file normally. The child runs in its own session, so
  a Ctrl-C on the terminal does not stop it half-way either;
* the child cannot start or dies: the parent's run goes on (rows are dropped), and
  :meth:`RecordingChild.close` returns the reason (one line), which the CLI reports.

The child skips ``stationbed/__init__.py`` (it imports the whole simulation stack, ~0.8 s, none of
which a recording needs): it is started with a bootstrap that registers a bare ``stationbed``
package and imports only :mod:`stationbed.output.rerun.sink` (with the modules it draws with) and
:mod:`stationbed.scene`.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

__all__ = ["RecordingChild", "MAGIC", "child_main"]

#: First line the parent sends; anything else on the child's stdin is a protocol error.
MAGIC = b"stationbed-rrd-rows 1\n"
#: Pipe capacity asked for (Linux ``F_SETPIPE_SZ``; 1 MiB is the unprivileged maximum by
#: default): a 3-orbit closed-loop run is ~0.6 MB of rows, so it fits while the child imports.
PIPE_BYTES = 1 << 20
#: Bytes read from the pipe at a time by the child.
READ_BYTES = 1 << 20
#: Longest wait [s] for the child to finish the file after the run; then it is killed and the
#: recording reported as failed (it only has to send what is left in the pipe and the footer).
CLOSE_TIMEOUT_S = 300.0
#: Prefix of the child's one-line error on its stderr.
CHILD_ERROR = "stationbed-rrd: "

_PACKAGE_DIR = Path(__file__).resolve().parents[2]  # stationbed/

# Runs in the child's ``python -I -c`` (isolated: neither the working folder nor PYTHONPATH comes first
# on sys.path, so a numpy.py beside the user cannot run): a bare ``stationbed`` package (no
# __init__ imports), then
# child_main(scene, rrd).
_BOOTSTRAP = (
    "import sys, types\n"
    "pkg = types.ModuleType('stationbed')\n"
    "pkg.__path__ = [sys.argv[1]]\n"
    "pkg.__package__ = 'stationbed'\n"
    "sys.modules['stationbed'] = pkg\n"
    "from stationbed.output.rerun.child import child_main, _exit\n"
    "_exit(child_main(sys.argv[2], sys.argv[3]))\n"
)


def _exit(code: int) -> None:
    """End the child at once: the recording is closed (footer written, file released) by then,
    and the interpreter's own shutdown (rerun's and pyarrow's teardown) would add ~0.1-0.3 s
    to the parent's wait for nothing."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


# -- parent side --------------------------------------------------------------------------------
class RecordingChild:
    """The parent's handle on the recording child; a row sink once :meth:`open` has been called.

    Use: ``rec = RecordingChild.start(scene_path, rrd_path)`` as early as possible, then
    ``rec.open(columns, duration, scene_name)`` (or :meth:`abort` if the run never starts),
    :meth:`write` per batch, and :meth:`close`, which returns ``None`` when the recording is
    complete, else the reason it failed (one line). Neither ``write`` nor ``close`` raises on a
    failed child: the run goes on without it.

    Parameters
    ----------
    proc : subprocess.Popen or None
        The child (None: it could not start).
    stderr : file or None
        Temporary file holding the child's stderr (its one-line reason on failure).
    rrd_path : str or Path
        The recording the child writes.
    error : str, optional
        Why the child is not there (when ``proc`` is None).
    """

    def __init__(self, proc: subprocess.Popen | None, stderr, rrd_path, error: str | None = None):
        self.proc = proc
        self.rrd_path = Path(rrd_path) if rrd_path else None  # None: streamed only (run --live)
        self.columns: list[str] | None = None
        self.error = error  # first failure seen (child did not start, broken pipe, ...)
        self._stderr = stderr
        self._fd = proc.stdin.fileno() if proc is not None else None
        self._buf = bytearray()
        self._opened = False
        self._closed = False

    @classmethod
    def start(cls, scene_path, rrd_path) -> RecordingChild:
        """Start the child on ``scene_path`` writing ``rrd_path``; never raises (a child that
        cannot start is reported by :meth:`close`).

        Parameters
        ----------
        scene_path : str or Path
            The scene file (the child loads it itself).
        rrd_path : str or Path
            The ``.rrd`` file to write.

        Returns
        -------
        RecordingChild
        """
        stderr = None
        try:
            stderr = tempfile.TemporaryFile()
            proc = subprocess.Popen(
                [sys.executable, "-I", "-c", _BOOTSTRAP, str(_PACKAGE_DIR), str(scene_path), str(rrd_path or "")],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=stderr,
                start_new_session=True,  # a Ctrl-C or hang-up of the terminal leaves it to finish the file
                bufsize=0,
            )
        except OSError as e:
            if stderr is not None:
                stderr.close()
            return cls(None, None, rrd_path, error=f"cannot start the recording process ({e})")
        fd = proc.stdin.fileno()
        try:
            import fcntl

            fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        except (ImportError, AttributeError, OSError):  # not Linux, or over the limit: default size
            pass
        try:
            os.set_blocking(fd, False)
        except OSError:  # then a slow child can hold the run up, nothing worse
            pass
        return cls(proc, stderr, rrd_path)

    # -- sink
    def open(self, columns, duration: float | None, scene_name: str, changes: dict | None = None,
             live: str | None = None) -> RecordingChild:
        """Tell the child the run's row columns (and duration, for the blueprint); the child then
        creates the recording.

        Parameters
        ----------
        columns : list of str
            Column names of the rows :meth:`write` will hand over.
        duration : float or None
            Run length [s] (None: the scene's ``simulation.duration``).
        scene_name : str
            The run's scene name (the child checks it against the scene it loaded).
        changes : dict, optional
            Key-path assignments the run applied to the scene file (``--set`` and the run
            options); the child applies the same ones, so it draws the scene that ran.
        live : str, optional
            Also stream the recording to a rerun viewer (``run --live``, :mod:`.live`): a
            ``rerun+http://HOST:PORT/proxy`` URL, or ``"spawn"`` (start a viewer).

        Returns
        -------
        RecordingChild
            ``self``, the sink.
        """
        self.columns = list(columns)
        self._opened = True
        header = json.dumps(
            {"columns": self.columns, "duration": duration, "scene": scene_name, "changes": changes or {}, "live": live},
            default=str
        )
        self._send(MAGIC + header.encode() + b"\n")
        return self

    def write(self, rows) -> None:
        """Hand a batch of rows to the child without blocking.

        Parameters
        ----------
        rows : ndarray, shape (k, len(columns)) or (len(columns),)
        """
        import numpy as np

        if self.proc is None or self.error is not None:
            return
        rows = np.ascontiguousarray(np.atleast_2d(rows), dtype="<f8")
        if rows.size:
            self._send(rows.tobytes())

    def _send(self, data: bytes) -> None:
        if self.proc is None or self.error is not None:
            return
        self._buf += data
        self._pump()

    def _pump(self) -> None:
        """Write as much of the buffer as the pipe takes now (blocking only once it is set so)."""
        view = memoryview(self._buf)
        done = 0
        try:
            while done < len(view):
                try:
                    done += os.write(self._fd, view[done:])
                except BlockingIOError:
                    break
        except OSError as e:  # BrokenPipeError: the child has exited
            self.error = f"the recording process stopped reading ({e.strerror or e})"
            done = len(view)
        finally:
            view.release()
        del self._buf[:done]

    def close(self) -> str | None:
        """End of the rows: the child sends what is left and closes the file. Waits for it;
        returns ``None`` if the recording is complete, else why not (one line)."""
        if self._closed:
            return self.error
        self._closed = True
        proc = self.proc
        if proc is None:
            return self.error
        if self._buf and self.error is None:
            os.set_blocking(self._fd, True)
            self._pump()
        try:
            proc.stdin.close()
        except OSError:
            pass
        try:
            code = proc.wait(timeout=CLOSE_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            self.error = f"the recording process did not finish within {CLOSE_TIMEOUT_S:g} s"
        else:
            if code != 0:  # its own reason says more than the broken pipe the parent saw
                self.error = self._child_reason(code)
            elif self.error is None and self._opened and self.rrd_path is not None and not self.rrd_path.is_file():
                self.error = "the recording process wrote no file"
        if self._stderr is not None:
            self._stderr.close()
        return self.error

    def abort(self) -> None:
        """The run never started (bad scene, ...): stop the child, which has written nothing."""
        if self._closed:
            return
        if self._opened:  # the file exists: finish it properly
            self.close()
            return
        self._closed = True
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            if self._stderr is not None:
                self._stderr.close()

    def _child_reason(self, code: int) -> str:
        msg = ""
        if self._stderr is not None:
            self._stderr.seek(0)
            lines = [ln.strip() for ln in self._stderr.read().decode(errors="replace").splitlines() if ln.strip()]
            mine = [ln[len(CHILD_ERROR):] for ln in lines if ln.startswith(CHILD_ERROR)]
            msg = (mine or lines or [""])[-1]
        how = f"killed by signal {-code}" if code < 0 else f"exit status {code}"
        return f"the recording process failed ({how})" + (f": {msg}" if msg else "")


# -- child side ---------------------------------------------------------------------------------
def child_main(scene_path: str, rrd_path: str) -> int:
    """The child: import rerun and load the scene while the parent starts up, then record.

    Parameters
    ----------
    scene_path : str
        The scene file.
    rrd_path : str
        The ``.rrd`` file to write.

    Returns
    -------
    int
        Exit status. 0: the recording is complete (or the parent never opened the run: no file).
        1: a failure, one line ``stationbed-rrd: ...`` on stderr.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # finish the file; the parent's EOF ends the run
    try:
        import numpy as np

        from ...scene import load_scene
        from .sdk import import_rerun
        from .sink import RrdSink

        import_rerun()  # the slow import, done while the parent is busy
        try:
            scene = load_scene(scene_path)
        except Exception as e:  # the parent reports a bad scene itself and never opens the run
            scene, scene_error = None, e
        stdin = sys.stdin.buffer
        magic = stdin.readline()
        if not magic:
            return 0  # the run was never opened
        if magic != MAGIC:
            raise ValueError(f"unexpected data on stdin: {magic[:40]!r}")
        header = json.loads(stdin.readline())
        if scene is None:
            raise scene_error
        if header.get("changes"):
            scene = scene.replace(header["changes"], source=f"{scene_path} with the run's options")
        if header["scene"] != scene.name:
            raise ValueError(f"scene {scene_path} is {scene.name!r} here, {header['scene']!r} in the run")
        columns = header["columns"]
        row_bytes = 8 * len(columns)
        sink = RrdSink(scene, rrd_path or None, columns, duration=header["duration"], live=header.get("live"))
        try:
            buf = bytearray()
            while True:
                chunk = stdin.read1(READ_BYTES)
                if not chunk:
                    break  # the parent closed the pipe (done, failed or killed)
                buf += chunk
                n = len(buf) // row_bytes
                if n:
                    rows = np.frombuffer(bytes(buf[: n * row_bytes]), dtype="<f8").reshape(n, len(columns))
                    del buf[: n * row_bytes]
                    sink.write(rows)
            # a partial row left in buf: the parent died mid-write; it was never a whole row
        finally:
            sink.close()
        return 0
    except Exception as e:
        from ...core.paths import WriteFailed

        text = " | ".join(ln.strip() for ln in str(e).splitlines() if ln.strip())
        kind = "" if isinstance(e, WriteFailed) else f"{type(e).__name__}: "  # (it names the file itself)
        print(f"{CHILD_ERROR}{kind}{text}", file=sys.stderr, flush=True)
        return 1
