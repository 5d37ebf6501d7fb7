"""Progress of long commands on stderr: a tqdm bar on a terminal, rate-limited plain lines
otherwise, nothing when quiet.

Who does what: the command line chooses the mode once (:func:`configure`); studies, runs and
compiles report through :func:`task` and the ``"stationbed"`` logger without knowing the mode;
a library user (the Python API) sees no progress until they call :func:`configure` themselves.

Modes
-----
``"tty"``
    A tqdm bar per open task (nested tasks stack below; transient ones vanish when done); a
    task that ends within ``delay_s`` never draws. The elapsed time moves even while the work
    sends no update (a compile, one long run).
``"plain"``
    For logs and pipes: nothing for a task that ends within ``delay_s``, then at most one line
    every ``interval_s`` in all, ``stationbed: <task>: <where it is>, <wall time> s elapsed``,
    and a ``... done`` line for a task that printed any. A heartbeat repeats the innermost
    task's line when the work itself is silent for ``interval_s``, so no stretch is silent
    longer than that. No carriage returns, no bars: a log stays a log, and the CLI's error
    line (``stationbed: error: ...``) stays the last one (an exception closes every task
    without a "done" line; :func:`close_all` stops everything before the error is printed).
``"quiet"``
    No progress and no notices; warnings still show (as ``pip -q``): a warning such as "running
    without compiled code, ~10x slower" changes what the user should make of a result.

The library default is quiet with no logging handler (docs/design.md): library calls run inside
loops (a study runs hundreds of simulations, the tests thousands), and a notebook or a test run
must not fill with bars it did not ask for; ``configure()`` turns them on with one call.
tqdm's notebook widgets (``tqdm.auto``) were not chosen: they need ipywidgets, and the console
bar already works in a notebook.

Logging: :func:`configure` installs one handler on the ``"stationbed"`` logger that writes
``stationbed: <message>`` for INFO (``compiling <structure> ...``) and ``stationbed: warning:
<message>`` for warnings, on the same stream (above a bar, never inside it). Quiet keeps the
handler at WARNING level. Without :func:`configure`, logging's own defaults apply (warnings
reach stderr bare, INFO is dropped), as for any library.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, TextIO

from tqdm import tqdm

__all__ = [
    "MODES", "PREFIX", "DELAY_S", "INTERVAL_S", "TICK_S", "LOGGER", "Task",
    "configure", "reset", "close_all", "mode", "task", "echo",
]

MODES = ("tty", "plain", "quiet")
#: every line this module writes starts with it (as the CLI's ``stationbed: error: ...``)
PREFIX = "stationbed: "
#: a task that ends within this wall time [s] shows nothing (no bar, no line)
DELAY_S = 2.0
#: plain mode: at most one progress line per this wall time [s], and at least one while a task
#: older than DELAY_S is open (the heartbeat)
INTERVAL_S = 5.0
#: how often the heartbeat looks [s] (redraws the bars' elapsed time, checks for silence)
TICK_S = 0.5
#: the package's logger (core/compile.py's notices and warnings)
LOGGER = "stationbed"

#: one lock for the tasks, the lines and the heartbeat (taken before tqdm's own lock)
_LOCK = threading.RLock()


@dataclass
class _Settings:
    mode: str = "quiet"
    stream: TextIO | None = None  # None: sys.stderr at the time of writing (pytest swaps it)
    clock: Callable[[], float] = time.monotonic
    delay_s: float = DELAY_S
    interval_s: float = INTERVAL_S
    heartbeat: bool = True
    handler: logging.Handler | None = None
    level: int = logging.NOTSET  # the logger's level before configure()
    open_tasks: list = field(default_factory=list)
    last_line: float | None = None  # clock() of the last plain progress line
    ticker: threading.Thread | None = None
    stop: threading.Event = field(default_factory=threading.Event)

    def out(self) -> TextIO:
        return self.stream if self.stream is not None else sys.stderr


_S = _Settings()


def _write(line: str, stream: TextIO | None = None) -> None:
    """One line on ``stream`` (default the progress stream), above any bar on screen."""
    fh = stream if stream is not None else _S.out()
    with _LOCK:
        drawn = [t.bar for t in _S.open_tasks if isinstance(t, _BarTask) and t.drawn()]
        for bar in drawn:  # (tqdm.write would also draw the bars still within their delay)
            bar.clear()
        print(line, file=fh, flush=True)
        for bar in drawn:
            bar.refresh()


class _Handler(logging.Handler):
    """The ``"stationbed"`` logger on the progress stream, one prefixed line per record (as
    every CLI line)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            kind = "warning: " if record.levelno >= logging.WARNING else ""
            msg = " | ".join(part.strip() for part in record.getMessage().splitlines() if part.strip())  # one line
            _write(f"{PREFIX}{kind}{msg}")
        except Exception:  # noqa: BLE001 - logging's contract: a handler never raises
            self.handleError(record)


def configure(
    mode: str | None = None,
    *,
    stream: TextIO | None = None,
    clock: Callable[[], float] | None = None,
    delay_s: float = DELAY_S,
    interval_s: float = INTERVAL_S,
    heartbeat: bool = True,
) -> str:
    """Choose how progress reaches the user (the command line calls this once, first).

    Parameters
    ----------
    mode : {"tty", "plain", "quiet"}, optional
        Default: ``"tty"`` when the stream is a terminal, else ``"plain"``.
    stream : file, optional
        Where bars, lines and notices go; default ``sys.stderr`` (looked up when writing).
    clock : callable, optional
        Wall clock [s] of plain mode's delay and rate limit (default ``time.monotonic``; tests
        inject a fake one).
    delay_s, interval_s : float
        A task that ends within ``delay_s`` [s] shows nothing; plain mode prints at most one
        line every ``interval_s`` [s].
    heartbeat : bool
        Run the thread that keeps bars' elapsed time moving and repeats plain mode's line when
        the work is silent (off: output only at :meth:`Task.update`; tests with a fake clock).

    Returns
    -------
    str
        The mode chosen.

    Raises
    ------
    ValueError
        An unknown mode (the message lists the valid ones).
    """
    if mode is not None and mode not in MODES:
        raise ValueError(f"unknown progress mode {mode!r}; valid: {', '.join(MODES)}")
    reset()
    out = stream if stream is not None else sys.stderr
    if mode is None:
        isatty = getattr(out, "isatty", None)
        mode = "tty" if isatty is not None and isatty() else "plain"
    with _LOCK:
        _S.mode, _S.stream, _S.clock, _S.heartbeat = mode, stream, clock or time.monotonic, heartbeat
        _S.delay_s, _S.interval_s = delay_s, interval_s
        log = logging.getLogger(LOGGER)
        _S.level = log.level
        _S.handler = _Handler(logging.WARNING if mode == "quiet" else logging.INFO)
        log.addHandler(_S.handler)
        log.setLevel(_S.handler.level)
    return mode


def close_all() -> None:
    """Close every open task as failed and stop the heartbeat: nothing more is printed until a
    new task starts (the CLI calls it before its one-line error, which must be the last line)."""
    with _LOCK:
        for t in reversed(_S.open_tasks):
            t.close(ok=False)
        ticker, _S.ticker = _S.ticker, None
        _S.stop.set()
    if ticker is not None and ticker is not threading.current_thread():
        ticker.join(timeout=1.0)


def reset() -> None:
    """Back to the library default: quiet, the logger as it was before :func:`configure`."""
    close_all()
    with _LOCK:
        if _S.handler is not None:
            log = logging.getLogger(LOGGER)
            log.removeHandler(_S.handler)
            log.setLevel(_S.level)
        _S.__init__()


def forked_quiet() -> None:
    """In a forked child (a local Dask worker, studies/montecarlo/cluster.py): quiet, as a
    spawned one starts, with none of the parent's tasks, handler or heartbeat, and a fresh lock
    (the parent's heartbeat may have held it at the fork; its thread does not exist here)."""
    global _LOCK
    _LOCK = threading.RLock()
    if _S.handler is not None:
        log = logging.getLogger(LOGGER)
        log.removeHandler(_S.handler)
        log.setLevel(_S.level)
    _S.__init__()


def mode() -> str:
    """The current mode: ``"tty"``, ``"plain"`` or ``"quiet"``."""
    return _S.mode


def echo(line: str = "", file: TextIO | None = None) -> None:
    """``print(line, file=file)`` (default stdout) that does not tear a progress bar: the
    studies' result lines go through it.

    Parameters
    ----------
    line : str
    file : file, optional
        Default ``sys.stdout`` (looked up when writing).
    """
    _write(line, file if file is not None else sys.stdout)


class Task:
    """One long piece of work, as the user sees it (made by :func:`task`).

    Call :meth:`update` whenever the work moves on (cheap: a plain or quiet task compares two
    clock readings), and :meth:`close` when it ends; as a context manager it closes itself, and
    an exception closes it as failed (no "done" line). A quiet task does nothing.
    """

    def __init__(self, desc: str, total: float | None, unit: str, transient: bool):
        self.desc, self.total, self.unit, self.transient = desc, total, unit, transient
        self.done: float = 0.0
        self.detail: str | None = None
        self.closed = False

    def update(self, done: float, detail: str | None = None) -> None:
        """Where the work is.

        Parameters
        ----------
        done : float
            Absolute position, in ``unit`` (simulated time [s], cases finished ...).
        detail : str, optional
            What it does now (``"case 3/7 max_step: rk4/momentum h 4 s"``): after the bar, and
            instead of the position in plain lines; ``""`` clears it.
        """
        with _LOCK:
            self.done = done
            if detail is not None:
                self.detail = detail
            if not self.closed:
                self._show()

    def close(self, ok: bool = True) -> None:
        """End the task (``ok`` False: it failed or was interrupted; nothing claims it is done)."""
        with _LOCK:
            if self.closed:
                return
            self.closed = True
            if self in _S.open_tasks:
                _S.open_tasks.remove(self)
            self._end(ok)

    def __enter__(self) -> "Task":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(ok=exc_type is None)

    def where(self) -> str:
        """The position in words: the detail, else ``done/total unit (pct %)`` ("" when nothing
        is known yet)."""
        if self.detail:
            return self.detail
        spec = _spec(self.total)
        if self.total:
            pct = 100.0 * min(self.done / self.total, 1.0)
            return f"{self.done:{spec}}/{self.total:{spec}} {self.unit} ({pct:.0f} %)"
        return f"{self.done:{spec}} {self.unit}" if self.done else ""

    def _show(self) -> None:
        pass

    def _end(self, ok: bool) -> None:
        pass


def _spec(total: float | None) -> str:
    """Format of a position: whole units from a total of 10 up, else 3 significant digits."""
    return ".0f" if total is None or total >= 10 else ".3g"


class _PlainTask(Task):
    """Lines: none before ``delay_s``, then at most one per ``interval_s`` (for all tasks)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.start = _S.clock()
        self.printed = False

    def _show(self) -> None:
        now = _S.clock()
        if now - self.start < _S.delay_s:
            return
        if _S.last_line is not None and now - _S.last_line < _S.interval_s:
            return
        _S.last_line = now
        self.printed = True
        where = self.where()
        _write(f"{PREFIX}{self.desc}: {where + ', ' if where else ''}{now - self.start:.0f} s elapsed")

    def _end(self, ok: bool) -> None:
        if ok and self.printed:  # a task the log saw running is seen to end
            _write(f"{PREFIX}{self.desc}: done, {_S.clock() - self.start:.0f} s")


class _BarTask(Task):
    """A tqdm bar, drawn once the task has lasted ``delay_s``."""

    def __init__(self, *args):
        super().__init__(*args)
        spec = _spec(self.total)
        if self.total:
            fmt = "{desc}: {percentage:3.0f}%|{bar}| {n:SPEC}/{total:SPEC} {unit} [{elapsed}<{remaining}]{postfix}"
        else:
            fmt = "{desc}: {n:SPEC} {unit} [{elapsed}]{postfix}"
        self.bar = tqdm(total=self.total, desc=self.desc, unit=self.unit, file=_S.out(), delay=_S.delay_s,
                        bar_format=fmt.replace("SPEC", spec), leave=False if self.transient else None,
                        miniters=0, dynamic_ncols=True)

    def drawn(self) -> bool:
        """Whether the bar is on screen (it waits ``delay_s`` before the first draw)."""
        return self.bar.last_print_t >= self.bar.start_t + self.bar.delay

    def _show(self) -> None:
        if self.detail is not None:
            self.bar.set_postfix_str(self.detail, refresh=False)
        self.bar.update(self.done - self.bar.n)  # 0 on a heartbeat: redraws the elapsed time

    def _end(self, ok: bool) -> None:
        self.bar.close()


def task(desc: str, total: float | None = None, unit: str = "it", *, transient: bool = False) -> Task:
    """Start reporting one long piece of work in the current mode.

    Parameters
    ----------
    desc : str
        What it is, as the user reads it: ``"run iss_lvlh_hold"``, ``"study stability"``.
    total : float, optional
        The position at which it is done (a run's duration [s], the number of cases); None
        when unknown (a compile).
    unit : str
        Unit of the position: ``"s"`` (simulated seconds), ``"cases"`` ...
    transient : bool
        A terminal bar that vanishes when done (nested tasks always do).

    Returns
    -------
    Task
        Use as a context manager, or call :meth:`Task.close` in a ``finally``.
    """
    cls = {"tty": _BarTask, "plain": _PlainTask, "quiet": Task}[_S.mode]
    with _LOCK:
        t = cls(desc, total, unit, transient)
        if cls is not Task:
            _S.open_tasks.append(t)
            if _S.heartbeat and _S.ticker is None:
                _S.stop = threading.Event()
                _S.ticker = threading.Thread(target=_heartbeat, args=(_S.stop,), name="stationbed-progress", daemon=True)
                _S.ticker.start()
    return t


def _tick() -> None:
    """One heartbeat: redraw the bars (their elapsed time), or repeat the line of the innermost
    plain task past its delay when nothing was printed for ``interval_s`` (an outer task speaks
    while short inner ones come and go)."""
    with _LOCK:
        if _S.mode == "tty":
            for t in _S.open_tasks:
                t._show()
            return
        now = _S.clock()
        for t in reversed(_S.open_tasks):
            if now - t.start >= _S.delay_s:
                t._show()
                return


def _heartbeat(stop: threading.Event) -> None:
    """The heartbeat thread: ticks every ``TICK_S`` while a task is open, then ends."""
    while not stop.wait(TICK_S):
        with _LOCK:
            if stop.is_set():
                return
            if not _S.open_tasks:
                if _S.ticker is threading.current_thread():
                    _S.ticker = None
                return
            _tick()
