"""Ctrl-C and SIGTERM stop a command the same way: :class:`KeyboardInterrupt`, counted.

Python turns SIGINT into :class:`KeyboardInterrupt`, but SIGTERM (``kill``, a CI job's timeout,
a container stopping) ends the process at once: no ``finally``, no ``atexit``, so an FMU's
extracted folder, a viewer server or a browser would be left behind. The command line
(:func:`handled`) gives both signals one handler that raises :class:`KeyboardInterrupt`, so every
command's own clean-up runs (a run keeps its rows and says so), and counts them: an interrupt
raised inside a Python FMU's own step is reported by the FMU as a fatal error, and the caller
asks :func:`since` whether that error was the interrupt.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

__all__ = ["handled", "handler", "count", "since"]

_COUNT = [0]


def handler(signum, frame):
    """SIGINT / SIGTERM: count it and raise :class:`KeyboardInterrupt` (as Python's own SIGINT handler)."""
    _COUNT[0] += 1
    raise KeyboardInterrupt


def count() -> int:
    """Signals handled by :func:`handler` in this process so far."""
    return _COUNT[0]


def since(mark: int) -> bool:
    """Whether a signal came since :func:`count` returned ``mark``."""
    return _COUNT[0] != mark


@contextmanager
def handled():
    """SIGINT and SIGTERM raise :class:`KeyboardInterrupt` inside the block (main thread only;
    a caller's own SIGINT handler is kept); the previous handlers come back after it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    mine = [s for s, h in before.items() if h in (signal.default_int_handler, signal.SIG_DFL)]
    for s in mine:
        signal.signal(s, handler)
    try:
        yield
    finally:
        for s in mine:
            signal.signal(s, before[s])
