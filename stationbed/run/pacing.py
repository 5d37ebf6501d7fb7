"""Runs paced to the wall clock (``stationbed run --realtime [FACTOR]``, issue 36).

A :class:`Pacer` is a small clock the executors call at a boundary, never inside their
arithmetic: :meth:`Pacer.wait` ``(t)`` returns when the wall clock reaches the deadline of
simulated time ``t``, ``wall0 + (t - t0) / factor``. Deadlines are absolute (computed from the
first call, never from the previous wake-up), so sleeping late at one tick does not delay the
next: no drift, however long the run.

Where it is called (docs/design.md, "Real time"):

* the per-tick executor: before the law's call of every tick (:func:`paced`, the one hook in
  :mod:`.closed_loop`), so a law in another process (:mod:`.socket_law`) sees its ticks at
  the wall-clock rate;
* every executor, through :class:`~.rows.Rows`: before an output row is handed to the sink. The
  fused loops compute a compiled call of up to 64 rows ahead and hand each row over at its
  deadline (their natural boundary is the row: their ticks between rows run in C); the open
  loop likewise, a row at a time.

A call with a time not after the last one's returns at once (the per-tick executor's row at
tick k was paced at the law's call of tick k). Pacing never changes a number: it only sleeps.
"""

from __future__ import annotations

import math
import time

import numpy as np

__all__ = ["Pacer", "paced"]

#: a deadline released later than this counts as a miss [s] (whether the work overran it or the
#: sleep before it woke late)
#: (the scheduler's wake-up jitter, ~0.1 ms on Linux, is lateness, not a miss)
MISS_S = 1e-3


class Pacer:
    """Wall-clock deadlines for simulated times.

    Parameters
    ----------
    factor : float  Simulated seconds per wall-clock second (1: real time; 100: 100x faster).
    hold_late : bool  A socket law's reply later than the next tick's deadline holds the last
        command and counts a miss (:mod:`.socket_law`) instead of waiting up to its timeout.
    """

    def __init__(self, factor: float = 1.0, hold_late: bool = False):
        if not (factor > 0 and math.isfinite(factor)):
            raise ValueError(f"--realtime: the factor must be a positive number, got {factor}")
        self.factor = float(factor)
        self.hold_late = hold_late
        self.wall0 = None  # the wall clock [s, perf_counter] of t0
        self.t0 = 0.0
        self.t_last = -math.inf
        self.released = 0.0  # when the last wait returned
        self.per_tick = False  # the per-tick executor paces every tick (else: rows)
        self.n = 0
        self.misses = 0
        self.worst_late_s = 0.0
        self.last_late_s = 0.0
        self._work: list[float] = []  # wall time from one release to the next call [s]

    def deadline(self, t: float) -> float:
        """The wall clock (``time.perf_counter``) at which simulated time ``t`` is due."""
        return (self.wall0 if self.wall0 is not None else time.perf_counter()) + (t - self.t0) / self.factor

    def wait(self, t: float) -> None:
        """Return when simulated time ``t`` [s] is due (at once when ``t`` is not after the last)."""
        if t <= self.t_last:
            return
        now = time.perf_counter()
        if self.wall0 is None:  # the first call starts the clock (compilation is not paced)
            self.wall0, self.t0 = now, t
        else:
            self._work.append(now - self.released)
        due = self.wall0 + (t - self.t0) / self.factor
        if now < due:
            time.sleep(due - now)
            now = time.perf_counter()
        late = now - due
        if late > MISS_S:  # released late: work that overran, or a sleep that woke late
            self.misses += 1
        self.last_late_s = late
        if late > self.worst_late_s:
            self.worst_late_s = late
        self.t_last, self.released = t, now
        self.n += 1

    def summary(self) -> dict:
        """What the run's summary records: the factor asked and achieved, the deadlines kept and
        missed, the worst and the final lateness (the drift at the end) [ms], and the
        distribution of the work between two deadlines [ms]."""
        span = self.released - self.wall0 if self.wall0 is not None else 0.0
        w = np.array(self._work) * 1e3 if self._work else np.zeros(1)
        return {
            "realtime_factor": self.factor,
            "realtime_achieved_factor": (self.t_last - self.t0) / span if span > 0 else math.nan,
            "realtime_paced_at": "tick" if self.per_tick else "row",
            "realtime_deadlines": self.n,
            "realtime_misses": self.misses,
            "realtime_worst_late_ms": self.worst_late_s * 1e3,
            "realtime_final_late_ms": self.last_late_s * 1e3,
            "realtime_work_ms_p50": float(np.percentile(w, 50)),
            "realtime_work_ms_p99": float(np.percentile(w, 99)),
            "realtime_work_ms_max": float(w.max()),
        }


def paced(call_counted: tuple, pacer: Pacer | None) -> tuple:
    """A per-tick executor's law call ``(call, counted)`` (``Controller.tick_update``) that
    first waits for its tick's deadline; unchanged without a pacer."""
    if pacer is None:
        return call_counted
    call, counted = call_counted
    pacer.per_tick = True
    wait = pacer.wait

    def paced_call(t, meas):
        wait(t)
        return call(t, meas)

    return paced_call, counted
