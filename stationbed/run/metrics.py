"""The run metrics: the one definition of every per-run figure of merit (closed-loop summary,
Monte Carlo table, ``compare``), computed by one incremental reduction over output rows.

:data:`METRICS` names each metric with its unit and meaning; :class:`RunMetrics` reduces rows
batch by batch as a run emits them (the rows need not be kept); :func:`trajectory_metrics`
applies the same reduction to a finished trajectory (a :class:`~.trajectory.Trajectory` or a
pandas DataFrame with the CSV columns), so a metric read back from a CSV equals the one the
run reported.

Conventions (issue 32: no metric is a count of output rows, so none scales with ``output_dt``):

- **Means and totals are time integrals**, by the trapezoid rule between consecutive output
  rows: ``mean(f) = ∫ f dt / ∫ dt`` over the window (a window of one row: that row's value).
  They converge to the continuous time mean as ``output_dt`` shrinks and differ between two
  output grids only by how each resolves the signal (a stationary noise: its sampling
  scatter; an edge, e.g. a dropout starting: at most ``output_dt / 2``), not by the number of
  rows: tests/test_metrics_output_dt.py runs one scene at ``output_dt`` 10, 2 and 1 s. An
  interval counts only when both of its rows have a value (a NaN ``att_err_deg``: a controller
  without a reference at that row).
- **Maxima and minima are over the output rows**: a peak shorter than ``output_dt`` can be
  missed (the tick grid inside the compiled loops is not reduced).
- ``att_err_deg`` NaN is ignored; inf is kept (a number the run produced: it makes ``max`` inf).
- ``rms_att_err_deg`` is ``sqrt(mean(err**2))`` over ``t >= settle_s`` (all rows when
  ``settle_s`` is None).
- **The estimation metrics** (``max_est_err_deg``, ``rms_est_err_deg``, ``mean_nees``,
  ``est_inside_3sigma``) are over the *converged, settled* window ``t >= max(settle_s,
  est_converged_s)``: the initial error is the draw from P0 and says nothing of the filter's
  accuracy; how long the filter takes is ``est_converged_s``, the time of the first row after
  which ``|est_err|`` stays at or below :data:`CONVERGED_FRACTION` of the filter's initial
  uncertainty (the norm of ``est_3sigma`` at the run's first row: P0's 3σ). A filter that is
  outside at its last row never converged: ``est_converged_s`` is inf and the estimation
  metrics are over ``t >= settle_s`` (all rows when None).
- ``st_dropout_s`` is the time a star-tracker head's held sample is invalid (``st_valid`` 0)
  after its first valid sample (:func:`~stationbed.loop.flight.st_dropouts`: before it the head
  has delivered nothing yet), integrated over the whole run and summed over the heads [s].
- ``max_torque_cmd_Nm`` is the largest ``|(tau_cmd_x, tau_cmd_y, tau_cmd_z)|`` over the rows
  (NaN rows, e.g. a gimbal-rate law's, ignored).
- A metric whose columns the run does not have, or that saw no usable row, is absent from
  :meth:`RunMetrics.values` (never a made-up 0).
- Every sum is exact until it is rounded once (``math.fsum`` of the per-interval terms): the
  values do not depend on how the rows were batched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.linalg import row_norms
from ..loop.flight import st_dropouts
from .working_h import WorkingH

__all__ = ["Metric", "METRICS", "RunMetrics", "trajectory_metrics", "CONVERGED_FRACTION", "ESTIMATION_WINDOW"]

#: the estimate has converged once |est_err| stays at or below this fraction of the filter's
#: initial uncertainty (the norm of est_3sigma at the first row, P0's 3σ): the error has fallen
#: by an order of magnitude below what the filter started out allowing (for the ISS-like set of
#: iss_lvlh_hold_estimated: 0.030 deg, against a settled error of ~4e-4 deg RMS and 1.5e-3 deg at most)
CONVERGED_FRACTION = 0.1


@dataclass(frozen=True)
class Metric:
    """One per-run figure of merit.

    Attributes
    ----------
    unit : str
        Its unit ("deg", "N m s", "1" for a ratio, "ticks", "s").
    description : str
        One line: what it measures, over which part of the run.
    worse : str
        "high" when a larger value is worse (a requirement gives a ``max``), "low" when a smaller
        one is (``min_singularity``: a requirement gives a ``min``).
    """

    unit: str
    description: str
    worse: str = "high"


#: name -> :class:`Metric`; the one definition of the project's per-run metrics
METRICS: dict[str, Metric] = {
    "max_att_err_deg": Metric("deg", "largest attitude error (att_err_deg) over the output rows"),
    "final_att_err_deg": Metric("deg", "attitude error of the last output row"),
    "rms_att_err_deg": Metric("deg", "RMS attitude error, time mean (trapezoid between rows) over t >= settle_s"),
    "max_h_Nms": Metric("N m s", "largest momentum |h| of the CMG cluster's working units over the output rows "
                        "(a failed unit's held rotor momentum left out)"),
    "max_h_fraction": Metric("1", "largest |h| of the working units as a fraction of their momentum capacity over "
                             "the output rows (each row's: a fault that holds a unit's gimbals takes its share out)"),
    "min_singularity": Metric("1", "smallest CMG singularity measure (cmg_singularity) over the rows", "low"),
    "rate_limited_ticks": Metric("ticks", "controller ticks whose gimbal-rate command was limited"),
    "momentum_saturated_ticks": Metric("ticks", "controller ticks at which the cluster was saturated"),
    "max_torque_cmd_Nm": Metric("N m", "largest commanded torque |tau_cmd| over the output rows"),
    # sensors and estimator (issue 20; windows issue 32): the columns of stationbed.loop.flight.flight_columns
    "est_converged_s": Metric("s", "time of the first row after which |est_err| stays <= CONVERGED_FRACTION (0.1) "
                              "of the first row's |est_3sigma| (inf: not converged)"),
    "max_est_err_deg": Metric("deg", "largest attitude estimation error |est_err| (truth vs MEKF) over the rows "
                              "at t >= max(settle_s, est_converged_s)"),
    "rms_est_err_deg": Metric("deg", "RMS of |est_err|, time mean over t >= max(settle_s, est_converged_s)"),
    "mean_nees": Metric("1", "time mean of the MEKF's NEES (6 states; consistent: 6) over t >= max(settle_s, est_converged_s)"),
    "est_inside_3sigma": Metric("1", "fraction of the time and axes with |est_err| <= its 3 sigma, "
                                "over t >= max(settle_s, est_converged_s)", "low"),
    "st_dropout_s": Metric("s", "time a star-tracker head's held sample is invalid, over the run, summed over heads"),
    # thrusters (issue 21): totals over the run, the last row's thr_* columns (loop/thrusters.py ``columns``)
    "propellant_kg": Metric("kg", "propellant used by the thrusters, Σ F t_on / (Isp g0), over the run"),
    "propellant_kg_per_orbit": Metric("kg", "propellant_kg per orbital period (2π / mean motion) of the run's length"),
    "thruster_firings": Metric("firings", "thruster pulses started (a pulse continuing the previous tick's is one)"),
    "thruster_control_s": Metric("s", "time in thruster-only control (hand-over at CMG saturation)"),
    "thruster_impulse_Ns": Metric("N s", "total thruster impulse Σ F t_on over the run"),
    # fault detection (issue 34): the last row's fdir_* columns (run/fdir_run.py)
    "fdir_detect_s": Metric("s", "time flight software declared a CMG fault (the last row's fdir_t_cmg_s; -1: none)"),
    "fdir_unit": Metric("1", "the CMG unit flight software blamed (the last row's fdir_cmg_unit; 0: none)"),
}

#: the estimation metrics taken over the converged, settled window (module docstring)
ESTIMATION_WINDOW = ("max_est_err_deg", "rms_est_err_deg", "mean_nees", "est_inside_3sigma")

#: metric -> the thr_* column whose last row holds it (cumulative columns)
_THRUSTER_TOTALS = {"propellant_kg": "thr_propellant_kg", "thruster_firings": "thr_firings",
                    "thruster_control_s": "thr_control_s", "thruster_impulse_Ns": "thr_impulse_Ns"}


def _interval_terms(t: np.ndarray, f: np.ndarray, prev) -> tuple[np.ndarray, np.ndarray]:
    """The trapezoid terms ``(f_a + f_b) / 2 (t_b - t_a)`` and the lengths ``t_b - t_a`` of the
    intervals ending at each row of a batch, (m, k) each; the interval ending at row 0 starts at
    ``prev`` = (t, f) of the row before (None: no row before, a term of 0). An interval with a NaN
    end or of no length adds 0 to both (which leaves an exact sum as it is)."""
    t0, f0 = (t[0], f[0]) if prev is None else prev
    tt, ff = np.concatenate(([t0], t)), np.concatenate((f0[None], f))
    dt = np.diff(tt)[:, None]
    terms = 0.5 * (ff[:-1] + ff[1:]) * dt
    if np.isfinite(terms).all() and dt.min() >= 0.0:  # (the common case: the same numbers, fewer calls)
        return terms, np.broadcast_to(dt, terms.shape)
    ok = ~np.isnan(ff)
    use = ok[:-1] & ok[1:] & (dt > 0.0)
    return np.where(use, terms, 0.0), np.where(use, dt, 0.0)


class _TimeIntegral:
    """``∫ f dt`` of ``k`` quantities over consecutive output rows by the trapezoid rule, the
    time each spans, and each one's largest value: fed batch by batch (the interval across two
    batches is the same term), every sum kept exact (``math.fsum`` of the terms, :func:`_folded`)
    so the result does not depend on the batching. A NaN is a row without a value: the intervals
    touching it add nothing."""

    def __init__(self, k: int = 1):
        self.k = k
        self.reset()

    def reset(self) -> None:
        k = self.k
        self.prev = None  # (t, f) of the last row taken
        self.chunks: list[tuple[np.ndarray, np.ndarray]] = []  # (terms, spans) per batch, (m, k) each
        self.n_terms = 0
        self.partials = ([[] for _ in range(k)], [[] for _ in range(k)])  # a long run's, folded
        self.n = np.zeros(k, dtype=np.int64)  # rows with a value
        self.last = np.full(k, math.nan)  # the last value: the mean of a window of no length
        self.max = np.full(k, math.nan)

    def add(self, t: np.ndarray, f: np.ndarray) -> None:
        """Rows at times ``t`` (m,) with values ``f`` (m, k), following the rows taken before."""
        if len(t):
            self.take(t, f, *_interval_terms(t, f, self.prev))

    def take(self, t, f, terms, spans) -> None:
        """Rows ``t``, ``f`` with the terms of the intervals ending at each (:func:`_interval_terms`)."""
        if not len(t):
            return
        self.prev = (float(t[-1]), f[-1].copy())
        ok = ~np.isnan(f)
        if ok.all():
            self.n += len(f)
            self.max = np.fmax(self.max, f.max(axis=0))
            self.last = f[-1].copy()
        elif (seen := ok.any(axis=0)).any():
            self.n += ok.sum(axis=0)
            self.max = np.fmax(self.max, np.fmax.reduce(f, axis=0))
            j = len(f) - 1 - np.argmax(ok[::-1], axis=0)  # each column's last row with a value
            self.last[seen] = f[j[seen], np.flatnonzero(seen)]
        if len(terms):
            self.chunks.append((terms, spans))
            self.n_terms += len(terms)
        if self.n_terms > _FOLD_AT:  # a long run: kept as the exact partials of its sums
            for i, parts in enumerate(self.partials):
                col = np.concatenate([c[i] for c in self.chunks]).T.tolist()
                for j in range(self.k):
                    parts[j] = _folded(parts[j] + col[j])
            self.chunks, self.n_terms = [], 0

    def _sum(self, i: int, j: int) -> float:
        """The correctly rounded sum of the terms (i = 0) or lengths (i = 1) of quantity ``j``."""
        rest = np.concatenate([c[i][:, j] for c in self.chunks]).tolist() if self.chunks else []
        return math.fsum(self.partials[i][j] + rest)

    def total(self, j: int = 0) -> float:
        return self._sum(0, j)

    def mean(self, j: int = 0) -> float | None:
        """Quantity ``j``'s time mean (a window of no length: its value), None without a row."""
        if not self.n[j]:
            return None
        span = self._sum(1, j)
        return self._sum(0, j) / span if span > 0.0 else float(self.last[j])


class _Estimation:
    """The estimation metrics' windows, both a suffix of the rows: ``settled`` (t >= settle_s)
    and ``converged`` (the settled rows after the last row whose |est_err| was above the
    convergence threshold), each with |est_err|² (its max too), NEES and the fraction of axes
    inside 3σ; the intervals' terms computed once for both."""

    def __init__(self):
        self.settled = _TimeIntegral(3)  # |e|², nees, inside
        self.converged = _TimeIntegral(3)
        self.prev = None  # the last row's (t, values)
        self.threshold = None  # [deg]: CONVERGED_FRACTION x the first row's |est_3sigma|
        self.t_converged = None  # the first row after the last one above the threshold
        self.outside_last = False  # the last row seen was above the threshold

    def add(self, t, e, s3, nees, settled) -> None:
        n2 = np.einsum("ij,ij->i", e, e)
        if self.threshold is None:
            self.threshold = CONVERGED_FRACTION * float(np.sqrt(s3[0] @ s3[0]))
            self.t_converged = float(t[0])
        vals = np.column_stack((n2, nees, (np.abs(e) <= s3).sum(axis=1) / 3.0))
        above = np.flatnonzero(n2 > self.threshold * self.threshold)
        start = 0
        if len(above):  # the converged window starts again after the last row above
            start = int(above[-1]) + 1
            self.converged.reset()
            self.outside_last = start == len(t)
            self.t_converged = None if self.outside_last else float(t[start])
        elif self.outside_last:  # the last batch ended above: its next row is the first after
            self.outside_last = False
            self.t_converged = float(t[0])
        terms, spans = _interval_terms(t, vals, self.prev)
        prev, self.prev = self.prev, (float(t[-1]), vals[-1].copy())
        first = int(np.argmax(settled)) if settled.any() else len(t)  # the settled rows: a suffix
        for w, s in ((self.settled, first), (self.converged, max(first, start))):
            # its intervals: those whose first row is in the window (the batch's row before the
            # window's first is not; the last batch's last row is if the window took it)
            k0 = 0 if s == 0 and w.prev is not None and w.prev[0] == (prev and prev[0]) else s + 1
            w.take(t[s:], vals[s:], terms[k0:], spans[k0:])

    def values(self) -> dict[str, float]:
        if self.threshold is None:
            return {}
        conv = not self.outside_last
        w = self.converged if conv and self.converged.n[0] else self.settled
        out = {"est_converged_s": self.t_converged if conv else math.inf}
        if w.n[0]:
            out.update(max_est_err_deg=float(np.sqrt(w.max[0])), rms_est_err_deg=math.sqrt(w.mean(0)),
                       mean_nees=w.mean(1), est_inside_3sigma=w.mean(2))
        return out


class RunMetrics:
    """Reductions over the output rows of one run, updated batch by batch.

    Parameters
    ----------
    columns : list of str
        The run's columns (:func:`~.rows.trajectory_columns`).
    settle_s : float or None
        Settling time [s]: ``rms_att_err_deg`` and the estimation metrics count ``t >= settle_s``
        (None: all rows; the estimation metrics also after ``est_converged_s``).
    h_capacity_Nms : float or None
        The CMG cluster's momentum capacity [N m s] for ``max_h_fraction`` (None or not finite:
        no fraction): its working units' (:func:`~stationbed.model.cmg.capacity`).
    h_held_B, held_units, capacity_steps : optional
        The working units' facts (:class:`~.working_h.WorkingH`: the failed units' held rotor
        momentum, the units a scheduled fault holds, the capacity's steps), when ``working`` is
        not given. ``max_h_Nms`` is the largest working ``|h|`` of a row; ``max_h_fraction``
        the largest of each row's ``|h_work|`` over that row's capacity (the series
        :meth:`WorkingH.fraction <.working_h.WorkingH.fraction>` gives the charts); without
        steps, ``max_h_Nms / h_capacity_Nms`` (the same number: a division by one positive
        number keeps the order).
    working : WorkingH, optional
        The working units' momentum per row (:meth:`WorkingH.of_scene <.working_h.WorkingH.of_scene>`).

    Attributes
    ----------
    n_rows : int
        Rows seen.
    last : ndarray or None
        The last row.
    rate_limited_ticks, momentum_saturated_ticks : int or None
        Tick counts, not in the rows: set by :meth:`count_ticks` (None: not counted).
    """

    def __init__(self, columns, settle_s: float | None = None, h_capacity_Nms: float | None = None,
                 h_held_B=None, orbit_period_s: float | None = None, held_units=None, capacity_steps=None,
                 working: WorkingH | None = None):
        col = {c: i for i, c in enumerate(columns)}
        self.columns = list(columns)
        self.settle_s = settle_s
        self.h_capacity_Nms = h_capacity_Nms
        self.working = working if working is not None else \
            WorkingH(columns, h_held_B=h_held_B, held_units=held_units, capacity_steps=capacity_steps)
        self._max_h_start = None  # max |h| of the working units over the rows at the start's capacity
        self._max_frac = None  # max |h| / capacity over the rows at a step's capacity
        self._t = col.get("t", 0)
        self._sing = col.get("cmg_singularity")
        self._err = col.get("att_err_deg")
        self._tau = [col[c] for c in ("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")] if "tau_cmd_x" in col else None
        self._est = [col[f"est_err_{a}_deg"] for a in "xyz"] if "est_err_x_deg" in col else None
        self._s3 = [col[f"est_3sigma_{a}_deg"] for a in "xyz"] if self._est else None
        self._nees = col.get("nees")
        self._st = [i for c, i in col.items() if c.startswith("st_valid_")]
        self._thr = {m: col[c] for m, c in _THRUSTER_TOTALS.items() if c in col}
        self._fdir = {m: col[c] for m, c in (("fdir_detect_s", "fdir_t_cmg_s"), ("fdir_unit", "fdir_cmg_unit")) if c in col}
        self.orbit_period_s = orbit_period_s
        self._est_red = _Estimation() if self._est is not None else None
        self._dropout = _TimeIntegral()  # heads invalid, over the run
        self._st_seen = [False] * len(self._st)  # a head's first valid sample came (st_dropouts)
        self.n_rows = 0
        self.last = None
        self.rate_limited_ticks = self.momentum_saturated_ticks = None
        self._max_h = None
        self._min_sing = None
        self._err_max = math.nan  # NaN-ignoring running max (np.fmax)
        self._err_finite = False  # a value that is not NaN was seen
        self._sq = _TimeIntegral()  # err² of the settled rows, integrated in time
        self._tau_max = math.nan

    def update(self, rows: np.ndarray) -> None:
        """Account for a batch ``rows`` (k, len(columns)), k >= 1."""
        self.n_rows += len(rows)
        self.last = rows[-1].copy()
        t = rows[:, self._t]
        settled = np.ones(len(rows), bool) if self.settle_s is None else t >= self.settle_s
        if self.working.has_h:
            hn, cap = self.working.norms(rows)
            h = float(hn.max())
            self._max_h = h if self._max_h is None else float(np.maximum(self._max_h, h))
            if self.capacity_steps:  # each row over its own capacity (the start's: known at the end)
                start, stepped = np.isnan(cap), ~np.isnan(cap)
                if start.any():
                    m = float(hn[start].max())
                    self._max_h_start = m if self._max_h_start is None else max(self._max_h_start, m)
                if stepped.any():
                    m = float((hn[stepped] / cap[stepped]).max())
                    self._max_frac = m if self._max_frac is None else max(self._max_frac, m)
        if self._sing is not None:
            m = float(rows[:, self._sing].min())
            self._min_sing = m if self._min_sing is None else float(np.minimum(self._min_sing, m))
        if self._err is not None:
            err = rows[:, self._err]
            self._err_finite |= bool(np.isfinite(err).any())
            self._err_max = float(np.fmax(self._err_max, np.fmax.reduce(err)))
            self._sq.add(t[settled], (err[settled] ** 2)[:, None])
        if self._est is not None:
            self._est_red.add(t, rows[:, self._est], rows[:, self._s3], rows[:, self._nees], settled)
        if self._st:
            drops = np.zeros((len(rows), 1))
            for j, c in enumerate(self._st):
                d, self._st_seen[j] = st_dropouts(rows[:, c], self._st_seen[j])
                drops[:, 0] += d
            self._dropout.add(t, drops)
        if self._tau is not None:
            tau = row_norms(rows[:, self._tau])
            self._tau_max = float(np.fmax(self._tau_max, np.fmax.reduce(tau)))

    # the working units' facts (what the summary records of them)
    @property
    def h_held_B(self):
        return self.working.h_held_B

    @property
    def held_units(self) -> list:
        return self.working.held_units

    @property
    def capacity_steps(self) -> list:
        return self.working.capacity_steps

    def count_ticks(self, rate_limited: int, momentum_saturated: int) -> None:
        """Set the tick counts the closed loop keeps (they are not in the rows)."""
        self.rate_limited_ticks = int(rate_limited)
        self.momentum_saturated_ticks = int(momentum_saturated)

    # the reductions, each None when it has no value
    @property
    def max_h_Nms(self) -> float | None:
        return self._max_h

    @property
    def min_singularity(self) -> float | None:
        return self._min_sing

    @property
    def max_att_err_deg(self) -> float | None:
        return self._err_max if self._err_finite else None

    def values(self) -> dict[str, float]:
        """The metrics that have a value, by :data:`METRICS` name (ticks as int)."""
        out: dict[str, float] = {}
        if self.rate_limited_ticks is not None:
            out["rate_limited_ticks"] = self.rate_limited_ticks
            out["momentum_saturated_ticks"] = self.momentum_saturated_ticks
        if self._max_h is not None:
            out["max_h_Nms"] = self._max_h
            cap = self.h_capacity_Nms
            if cap is not None and math.isfinite(cap):
                if not self.capacity_steps:
                    out["max_h_fraction"] = float(self._max_h / cap)
                else:
                    parts = ([self._max_h_start / cap] if self._max_h_start is not None else []) + \
                        ([self._max_frac] if self._max_frac is not None else [])
                    out["max_h_fraction"] = float(max(parts))
        if self._min_sing is not None:
            out["min_singularity"] = self._min_sing
        if self._err_finite:
            out["final_att_err_deg"] = float(self.last[self._err])
            out["max_att_err_deg"] = self._err_max
            if self._sq.n[0]:
                out["rms_att_err_deg"] = math.sqrt(self._sq.mean())
        if self._tau is not None and not math.isnan(self._tau_max):
            out["max_torque_cmd_Nm"] = self._tau_max
        if self._est_red is not None:
            out.update(self._est_red.values())
        if self._st and self.n_rows:
            out["st_dropout_s"] = self._dropout.total()
        if self._thr and self.n_rows:
            for m, i in self._thr.items():
                out[m] = int(round(self.last[i])) if m == "thruster_firings" else float(self.last[i])
            t_end = float(self.last[self._t])
            if self.orbit_period_s and t_end > 0:
                out["propellant_kg_per_orbit"] = out["propellant_kg"] * self.orbit_period_s / t_end
        if self._fdir and self.n_rows:
            out.update({m: float(self.last[i]) for m, i in self._fdir.items()})
        return out


#: values of a per-row sum kept as they are before they are folded into exact partials
_FOLD_AT = 65536


def _folded(values: list[float]) -> list[float]:
    """The non-overlapping partials of the exact sum of ``values`` (:func:`_exact_add`):
    ``math.fsum`` of them, with values added after, is the correctly rounded sum of all."""
    partials: list[float] = []
    for v in values:
        _exact_add(partials, v)
    return partials


def _exact_add(partials: list[float], x: float) -> None:
    """Add ``x`` to the non-overlapping partials whose exact sum is the running total
    (Shewchuk 1997; the recipe behind ``math.fsum``): ``math.fsum(partials)`` is then the
    correctly rounded sum whatever the order and grouping of the additions."""
    i = 0
    for y in partials:
        if abs(x) < abs(y):
            x, y = y, x
        hi = x + y
        lo = y - (hi - x)
        if lo:
            partials[i] = lo
            i += 1
        x = hi
    partials[i:] = [x]


def trajectory_metrics(traj, summary: dict | None = None, settle_s: float | None = None) -> dict[str, float]:
    """The :data:`METRICS` of a finished run, by the same reduction the run itself uses.

    Parameters
    ----------
    traj : Trajectory or pandas.DataFrame
        The run's rows with the CSV columns.
    summary : dict, optional
        The run's summary (``summary.json``'s ``summary``, ``traj.meta["summary"]``): the tick
        counts, the cluster capacity (``h_capacity_Nms``, and its steps ``h_capacity_steps_Nms``)
        and a failed unit's held momentum (``h_held_B_Nms``) come from it. Taken from
        ``traj.meta`` when None and the trajectory has one.
    settle_s : float, optional
        Settling time [s] for ``rms_att_err_deg`` and the estimation metrics (None: all rows).

    Returns
    -------
    dict
        Metric name -> value, the metrics that have one.
    """
    if summary is None:
        summary = getattr(traj, "meta", {}).get("summary") or {}
    if hasattr(traj, "to_numpy"):  # a DataFrame
        columns, data = [str(c) for c in traj.columns], traj.to_numpy(dtype=float)
    else:
        columns, data = traj.columns, traj.data
    working = WorkingH.of_summary(columns, summary)
    m = RunMetrics(columns, settle_s=settle_s, h_capacity_Nms=working.capacity_Nms,
                   orbit_period_s=summary.get("orbit_period_s"), working=working)
    if len(data):
        m.update(np.asarray(data, dtype=float))
    if "rate_limited_ticks" in summary:
        m.count_ticks(summary["rate_limited_ticks"], summary["momentum_saturated_ticks"])
    return m.values()
