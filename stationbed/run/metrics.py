"""The run metrics: the one definition of every per-run figure of merit (closed-loop summary,
Monte Carlo table, ``compare``), computed by one incremental reduction over output rows.

:data:`METRICS` names each metric with its unit and meaning; :class:`RunMetrics` reduces rows
batch by batch as a run emits them (the rows need not be kept); :func:`trajectory_metrics`
applies the same reduction to a finished trajectory (a :class:`~.trajectory.Trajectory` or a
pandas DataFrame with the CSV columns), so a metric read back from a CSV equals the one the
run reported.

Conventions (all reductions are over the *output rows* of the run, i.e. at ``output_dt``,
except the tick counts, which the closed loop counts at every controller tick):

- ``att_err_deg`` NaN (a controller without a reference) is ignored; inf is kept (it is a
  number the run produced, and it makes ``max`` inf).
- ``rms_att_err_deg`` is ``sqrt(mean(err**2))`` over the rows with ``t >= settle_s`` (all rows
  when ``settle_s`` is None) whose error is not NaN.
- ``max_torque_cmd_Nm`` is the largest ``|(tau_cmd_x, tau_cmd_y, tau_cmd_z)|`` over the rows
  (NaN rows, e.g. a gimbal-rate law's, ignored).
- A metric whose columns the run does not have, or that saw no usable row, is absent from
  :meth:`RunMetrics.values` (never a made-up 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.linalg import row_norms

__all__ = ["Metric", "METRICS", "RunMetrics", "trajectory_metrics"]


@dataclass(frozen=True)
class Metric:
    """One per-run figure of merit.

    Attributes
    ----------
    unit : str
        Its unit ("deg", "N m s", "1" for a ratio, "ticks").
    description : str
        One line: what it measures, over which rows.
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
    "rms_att_err_deg": Metric("deg", "RMS attitude error over the output rows at t >= settle_s"),
    "max_h_Nms": Metric("N m s", "largest momentum |h| of the CMG cluster's working units over the output rows "
                        "(a failed unit's held rotor momentum left out)"),
    "max_h_fraction": Metric("1", "max_h_Nms as a fraction of the working units' momentum capacity"),
    "min_singularity": Metric("1", "smallest CMG singularity measure (cmg_singularity) over the rows", "low"),
    "rate_limited_ticks": Metric("ticks", "controller ticks whose gimbal-rate command was limited"),
    "momentum_saturated_ticks": Metric("ticks", "controller ticks at which the cluster was saturated"),
    "max_torque_cmd_Nm": Metric("N m", "largest commanded torque |tau_cmd| over the output rows"),
    # sensors and estimator (issue 20): the columns of stationbed.loop.flight.flight_columns
    "max_est_err_deg": Metric("deg", "largest attitude estimation error |est_err| (truth vs MEKF) over the output rows"),
    "rms_est_err_deg": Metric("deg", "RMS attitude estimation error |est_err| over the output rows"),
    "mean_nees": Metric("1", "mean of the MEKF's NEES (6 states; consistent: 6) over the output rows"),
    "est_inside_3sigma": Metric("1", "fraction of the output rows and axes with |est_err| <= its 3 sigma", "low"),
    "st_dropout_rows": Metric("rows", "output rows at which a star-tracker head's held sample is invalid, summed over heads"),
    # thrusters (issue 21): totals over the run, the last row's thr_* columns (run/thrust.py)
    "propellant_kg": Metric("kg", "propellant used by the thrusters, Σ F t_on / (Isp g0), over the run"),
    "propellant_kg_per_orbit": Metric("kg", "propellant_kg per orbital period (2π / mean motion) of the run's length"),
    "thruster_firings": Metric("firings", "thruster pulses started (a pulse continuing the previous tick's is one)"),
    "thruster_control_s": Metric("s", "time in thruster-only control (hand-over at CMG saturation)"),
    "thruster_impulse_Ns": Metric("N s", "total thruster impulse Σ F t_on over the run"),
}

#: metric -> the thr_* column whose last row holds it (cumulative columns)
_THRUSTER_TOTALS = {"propellant_kg": "thr_propellant_kg", "thruster_firings": "thr_firings",
                    "thruster_control_s": "thr_control_s", "thruster_impulse_Ns": "thr_impulse_Ns"}


class RunMetrics:
    """Reductions over the output rows of one run, updated batch by batch.

    Parameters
    ----------
    columns : list of str
        The run's columns (:func:`~.rows.trajectory_columns`).
    settle_s : float or None
        Settling time [s]: ``rms_att_err_deg`` counts the rows at ``t >= settle_s`` (None: all).
    h_capacity_Nms : float or None
        The CMG cluster's momentum capacity [N m s] for ``max_h_fraction`` (None or not finite:
        no fraction): its working units' (:func:`~stationbed.model.cmg.capacity`).
    h_held_B : array_like, shape (3,), optional
        The failed units' held rotor momentum, B components [N m s]
        (:func:`~stationbed.model.cmg.held_momentum_B`): ``max_h_Nms`` is that of the working
        units, ``|h - h_held_B|`` (None: no failed unit).

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
                 h_held_B=None, orbit_period_s: float | None = None):
        col = {c: i for i, c in enumerate(columns)}
        self.columns = list(columns)
        self.settle_s = settle_s
        self.h_capacity_Nms = h_capacity_Nms
        self.h_held_B = None if h_held_B is None else np.asarray(h_held_B, dtype=float).reshape(3)
        self._t = col.get("t", 0)
        self._h = [col[c] for c in ("hx", "hy", "hz")] if "hx" in col else None
        self._sing = col.get("cmg_singularity")
        self._err = col.get("att_err_deg")
        self._tau = [col[c] for c in ("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")] if "tau_cmd_x" in col else None
        self._est = [col[f"est_err_{a}_deg"] for a in "xyz"] if "est_err_x_deg" in col else None
        self._s3 = [col[f"est_3sigma_{a}_deg"] for a in "xyz"] if self._est else None
        self._nees = col.get("nees")
        self._st = [i for c, i in col.items() if c.startswith("st_valid_")]
        self._thr = {m: col[c] for m, c in _THRUSTER_TOTALS.items() if c in col}
        self.orbit_period_s = orbit_period_s
        # max, err² per row, rows, nees per row, inside, dropouts; the two sums taken at the end
        # with math.fsum (correctly rounded): the same totals whatever batches the rows came in
        self._est_red = [0.0, [], 0, [], 0, 0]
        self.n_rows = 0
        self.last = None
        self.rate_limited_ticks = self.momentum_saturated_ticks = None
        self._max_h = None
        self._min_sing = None
        self._err_max = math.nan  # NaN-ignoring running max (np.fmax)
        self._err_finite = False  # a value that is not NaN was seen
        # err**2 of the settled, non-NaN rows (a long run's folded into the exact partials of their
        # sum, Shewchuk's, as math.fsum), summed with math.fsum at the end (correctly rounded): the
        # value cannot depend on how the rows were batched (timed flushes)
        self._sq_partials: list[float] = []
        self._sq_n = 0
        self._tau_max = math.nan

    def update(self, rows: np.ndarray) -> None:
        """Account for a batch ``rows`` (k, len(columns)), k >= 1."""
        self.n_rows += len(rows)
        self.last = rows[-1].copy()
        if self._h is not None:
            hb = rows[:, self._h] if self.h_held_B is None else rows[:, self._h] - self.h_held_B
            h = float(row_norms(hb).max())
            self._max_h = h if self._max_h is None else float(np.maximum(self._max_h, h))
        if self._sing is not None:
            m = float(rows[:, self._sing].min())
            self._min_sing = m if self._min_sing is None else float(np.minimum(self._min_sing, m))
        if self._err is not None:
            err = rows[:, self._err]
            self._err_finite |= bool(np.isfinite(err).any())
            self._err_max = float(np.fmax(self._err_max, np.fmax.reduce(err)))
            use = ~np.isnan(err)
            if self.settle_s is not None:
                use &= rows[:, self._t] >= self.settle_s
            if use.any():
                e = err[use]
                self._sq_partials += (e * e).tolist()
                if len(self._sq_partials) > _FOLD_AT:
                    self._sq_partials = _folded(self._sq_partials)
                self._sq_n += int(use.sum())
        if self._est is not None:
            r = self._est_red
            e = rows[:, self._est]
            n2 = np.einsum("ij,ij->i", e, e)
            r[0] = max(r[0], float(np.sqrt(n2.max())))
            r[1] += n2.tolist()
            r[2] += len(rows)
            r[3] += rows[:, self._nees].tolist()
            if len(r[1]) > _FOLD_AT:  # a long run: kept as the exact partials of its sum
                r[1], r[3] = _folded(r[1]), _folded(r[3])
            r[4] += int((np.abs(e) <= rows[:, self._s3]).sum())
        if self._st:
            self._est_red[5] += int((rows[:, self._st] < 0.5).sum())
        if self._tau is not None:
            tau = row_norms(rows[:, self._tau])
            self._tau_max = float(np.fmax(self._tau_max, np.fmax.reduce(tau)))

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
                out["max_h_fraction"] = float(self._max_h / cap)
        if self._min_sing is not None:
            out["min_singularity"] = self._min_sing
        if self._err_finite:
            out["final_att_err_deg"] = float(self.last[self._err])
            out["max_att_err_deg"] = self._err_max
            if self._sq_n:
                out["rms_att_err_deg"] = math.sqrt(math.fsum(self._sq_partials) / self._sq_n)
        if self._tau is not None and not math.isnan(self._tau_max):
            out["max_torque_cmd_Nm"] = self._tau_max
        r = self._est_red
        if self._est is not None and r[2]:
            out.update(max_est_err_deg=r[0], rms_est_err_deg=math.sqrt(math.fsum(r[1]) / r[2]),
                       mean_nees=math.fsum(r[3]) / r[2],
                       est_inside_3sigma=r[4] / (3 * r[2]))
        if self._st and self.n_rows:
            out["st_dropout_rows"] = r[5]
        if self._thr and self.n_rows:
            for m, i in self._thr.items():
                out[m] = int(round(self.last[i])) if m == "thruster_firings" else float(self.last[i])
            t_end = float(self.last[self._t])
            if self.orbit_period_s and t_end > 0:
                out["propellant_kg_per_orbit"] = out["propellant_kg"] * self.orbit_period_s / t_end
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
        counts, the cluster capacity (``h_capacity_Nms``) and a failed unit's held momentum
        (``h_held_B_Nms``) come from it. Taken from
        ``traj.meta`` when None and the trajectory has one.
    settle_s : float, optional
        Settling time [s] for ``rms_att_err_deg`` (None: all rows).

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
    cap = summary.get("h_capacity_Nms")
    if cap is None and "max_h_fraction" in summary and summary.get("max_h_fraction"):
        cap = summary["max_h_Nms"] / summary["max_h_fraction"]
    m = RunMetrics(columns, settle_s=settle_s, h_capacity_Nms=cap, h_held_B=summary.get("h_held_B_Nms"),
                   orbit_period_s=summary.get("orbit_period_s"))
    if len(data):
        m.update(np.asarray(data, dtype=float))
    if "rate_limited_ticks" in summary:
        m.count_ticks(summary["rate_limited_ticks"], summary["momentum_saturated_ticks"])
    return m.values()
