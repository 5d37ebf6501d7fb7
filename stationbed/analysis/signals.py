"""Quantities the dashboard and ``compare`` derive from a run's CSV columns alone (no scene needed).

* :func:`relative_rate` - the body rate relative to the controller's reference frame R,
  ``ω_BR_B = ω_BN_B - C_BR ω_RN_R``. The reference attitude is rebuilt from the logged error:
  ``att_err_x/y/z_deg`` is the rotation vector of ``q_BR`` in B (:func:`~stationbed.core.rotation.rotation_vector`),
  so ``q_RN = q_BN ⊗ conj(q_BR)``; ``ω_RN_R`` is the rotation between neighbouring rows' ``q_RN``
  over their time step (central differences inside, one-sided at the ends), exact for a reference
  that turns at a constant rate about a fixed axis (LVLH on a circular orbit, an inertial hold).
  LVLH turns at the orbital rate (0.065 deg/s at 400 km): the inertial rate ``ω_BN_B`` of a
  station that holds LVLH is that rate, and a transient of 1e-4 deg/s is invisible beside it.
* :func:`h_fraction` - the working units' ``|h|`` over their capacity at each row (never negative:
  a norm), from the run's summary (:meth:`WorkingH.fraction <stationbed.run.working_h.WorkingH.fraction>`:
  a failed or stuck unit's held momentum left out, a fault's unit out of the capacity from its
  time): the series whose largest value is the summary's ``max_h_fraction``.
* :func:`delivered_torque` - the torque the CMG cluster puts on the body,
  ``τ_B = -(dh/dt|_B + ω_BN_B × h_B)`` (the cluster's momentum balance about the composite mass
  centre: what the cluster gains the body loses), with ``dh/dt`` by central differences of the
  rows (so each value is the mean over two output intervals; a command held at 10 Hz is sampled
  at the row). Beside ``tau_cmd``, it shows what the steering law and the limits let through.
* :func:`cmg_limit_kinds` - what a row's ``cmg_saturated`` flag was: the cluster's momentum
  saturated or only a gimbal-rate (an ideal cluster's torque) limit. The flag is set for either
  since the previous row; the momentum is saturated where the working units' ``|h|`` reaches the
  run's threshold (``saturation_fraction`` of the working units' capacity at the row: the
  callers pass :func:`h_fraction` and ``h_saturation_Nms / h_capacity_Nms``).
"""


from __future__ import annotations

import numpy as np

from ..core.rotation import dcm, quat_conj, quat_mult, rotation_vector
from ..run.working_h import WorkingH

__all__ = ["ERR_AXES", "relative_rate", "h_fraction", "delivered_torque", "rate_of_change", "cmg_limit_kinds",
           "CMG_NO_LIMIT", "CMG_RATE_LIMIT", "CMG_MOMENTUM_SATURATED", "cmg_limit_name"]

#: the logged attitude error's axes (the rotation vector of q_BR in B) [deg]
ERR_AXES = ("att_err_x_deg", "att_err_y_deg", "att_err_z_deg")


def rate_of_change(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``dy/dt`` of rows ``y`` (k, m) at times ``t`` (k,): central differences inside, one-sided at
    the ends (second-order on a uniform grid for the inside rows); NaN where a step is not > 0."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    out = np.full(y.shape, np.nan)
    if len(t) < 2:
        return out
    lo = np.r_[0, np.arange(len(t) - 2), len(t) - 2]  # the rows each difference spans
    hi = np.r_[1, np.arange(2, len(t)), len(t) - 1]
    dt = t[hi] - t[lo]
    ok = dt > 0
    out[ok] = (y[hi[ok]] - y[lo[ok]]) / dt[ok, None]
    return out


def _q_from_rotation_vector(phi: np.ndarray) -> np.ndarray:
    """Rows of rotation vectors [rad] -> scalar-first unit quaternions."""
    angle = np.linalg.norm(phi, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 1e-300, np.sin(half) / np.where(angle > 1e-300, angle, 1.0), 0.5)
    return np.hstack([np.cos(half)[:, None], phi * scale[:, None]])


def relative_rate(tr) -> np.ndarray | None:
    """``ω_BR_B`` [rad/s] per row (k, 3): the body rate relative to the controller's reference R;
    None when the run logged no per-axis attitude error (open loop, a law without a reference).
    Rows without a reference (NaN error) are NaN."""
    if not all(c in tr.columns for c in ERR_AXES):
        return None
    q_BN = tr.cols("qw", "qx", "qy", "qz")
    w_BN_B = tr.cols("wx", "wy", "wz")
    q_BR = _q_from_rotation_vector(np.radians(tr.cols(*ERR_AXES)))
    q_RN = np.array([quat_mult(q, quat_conj(e)) for q, e in zip(q_BN, q_BR)]).reshape(-1, 4)
    n = len(q_RN)
    out = np.full((n, 3), np.nan)
    if n < 2:
        return out
    lo = np.r_[0, np.arange(n - 2), n - 2]
    hi = np.r_[1, np.arange(2, n), n - 1]
    dt = tr.t[hi] - tr.t[lo]
    good = (dt > 0) & np.isfinite(q_RN[lo]).all(axis=1) & np.isfinite(q_RN[hi]).all(axis=1)
    if not good.any():
        return out
    # the rotation from R at row lo to R at row hi, in R's axes, over the step: ω_RN_R
    w_RN_R = np.full((n, 3), np.nan)
    w_RN_R[good] = rotation_vector(q_RN[lo[good]], q_RN[hi[good]]) / dt[good, None]
    C_BR = np.array([dcm(q) for q in q_BR]).reshape(-1, 3, 3)
    return w_BN_B - np.einsum("kij,kj->ki", C_BR, w_RN_R)


def h_fraction(tr, summary: dict) -> np.ndarray | None:
    """The working units' ``|h|`` over their capacity at each row (>= 0) of a run whose summary
    is ``summary`` (summary.json's: the capacity, held momenta and the capacity's steps), or None
    without CMG columns or a finite capacity."""
    return WorkingH.of_summary(tr.columns, summary).fraction(tr.data)


def delivered_torque(tr) -> np.ndarray | None:
    """``-(dh/dt + ω × h)`` [N m] per row (k, 3), B components: the CMG cluster's torque on the
    body, from the logged ``h`` (see the module docstring); None without CMG columns."""
    if "hx" not in tr.columns:
        return None
    h = tr.cols("hx", "hy", "hz")
    return -(rate_of_change(tr.t, h) + np.cross(tr.cols("wx", "wy", "wz"), h))


#: the kinds of a row's CMG limit flag (:func:`cmg_limit_kinds`)
CMG_NO_LIMIT, CMG_RATE_LIMIT, CMG_MOMENTUM_SATURATED = 0, 1, 2
#: |h| within this fraction below the threshold counts as reaching it: the flag compares the
#: tick's |h| with the threshold in double precision, the row gives the same state's h to 17
#: digits, and the norm is taken again here (a few ulp)
H_SAT_REL_TOL = 1e-9


def cmg_limit_name(gimballed: bool) -> str:
    """What limits a cluster short of its momentum saturation: the gimbal rates, or (an ideal
    cluster) the torque."""
    return "gimbal-rate limit" if gimballed else "torque limit"


def cmg_limit_kinds(flag, h, h_sat: float | None, h_before: float = np.nan,
                    ticks: tuple[int, int] | None = None) -> np.ndarray:
    """The kind of each row's CMG limit flag: :data:`CMG_NO_LIMIT`, :data:`CMG_RATE_LIMIT` or
    :data:`CMG_MOMENTUM_SATURATED`.

    Parameters
    ----------
    flag : ndarray, shape (k,)  The rows' ``cmg_saturated`` (1: a limit at a tick since the previous row).
    h : ndarray, shape (k,)  The working units' ``|h|`` over their capacity at each row
        (:func:`h_fraction`; or ``|h|`` [N m s] against a threshold in N m s).
    h_sat : float or None  The threshold of saturation, in ``h``'s unit (``saturation_fraction``;
        None or inf: the cluster cannot saturate, every flag is a rate or torque limit).
    h_before : float  ``h`` of the row before the first (a recording's earlier batch).
    ticks : (rate_limited_ticks, momentum_saturated_ticks), optional  The run's counts: a run
        with no saturated tick has only rate limits, one with no rate-limited tick only saturation.

    Returns
    -------
    ndarray of int, shape (k,)
        A flagged row is saturated when |h| reached the threshold at it or at the row before
        (the ticks between them are the ones the flag covers), else rate (torque) limited.
    """
    flag = np.asarray(flag, float) >= 0.5
    h = np.asarray(h, float)
    reached = np.zeros(len(h), bool)
    if h_sat is not None and np.isfinite(h_sat):
        at = h >= h_sat * (1.0 - H_SAT_REL_TOL)
        before = np.r_[h_before, h[:-1]] >= h_sat * (1.0 - H_SAT_REL_TOL) if len(h) else at
        reached = at | before
    if ticks is not None:
        rate_ticks, sat_ticks = ticks
        if not sat_ticks:
            reached[:] = False
        elif not rate_ticks:
            reached[:] = True
    return np.where(flag, np.where(reached, CMG_MOMENTUM_SATURATED, CMG_RATE_LIMIT), CMG_NO_LIMIT)
