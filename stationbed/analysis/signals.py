"""Quantities the dashboard and ``compare`` derive from a run's CSV columns alone (no scene needed).

* :func:`relative_rate` - the body rate relative to the controller's reference frame R,
  ``ω_BR_B = ω_BN_B - C_BR ω_RN_R``. The reference attitude is rebuilt from the logged error:
  ``att_err_x/y/z_deg`` is the rotation vector of ``q_BR`` in B (:func:`~stationbed.core.rotation.rotation_vector`),
  so ``q_RN = q_BN ⊗ conj(q_BR)``; ``ω_RN_R`` is the rotation between neighbouring rows' ``q_RN``
  over their time step (central differences inside, one-sided at the ends), exact for a reference
  that turns at a constant rate about a fixed axis (LVLH on a circular orbit, an inertial hold).
  LVLH turns at the orbital rate (0.065 deg/s at 400 km): the inertial rate ``ω_BN_B`` of a
  station that holds LVLH is that rate, and a transient of 1e-4 deg/s is invisible beside it.
* :func:`h_fraction` - ``|h|`` over the cluster's capacity (never negative: a norm).
* :func:`delivered_torque` - the torque the CMG cluster puts on the body,
  ``τ_B = -(dh/dt|_B + ω_BN_B × h_B)`` (the cluster's momentum balance about the composite mass
  centre: what the cluster gains the body loses), with ``dh/dt`` by central differences of the
  rows (so each value is the mean over two output intervals; a command held at 10 Hz is sampled
  at the row). Beside ``tau_cmd``, it shows what the steering law and the limits let through.
"""

from __future__ import annotations

import numpy as np

from ..core.rotation import dcm, quat_conj, quat_mult, rotation_vector

__all__ = ["ERR_AXES", "relative_rate", "h_fraction", "delivered_torque", "rate_of_change"]

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


def h_fraction(tr, capacity_Nms: float | None) -> np.ndarray | None:
    """``|h| / capacity`` per row (>= 0), or None without CMG columns or a finite capacity."""
    if "hx" not in tr.columns or not capacity_Nms or not np.isfinite(capacity_Nms):
        return None
    return np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1) / float(capacity_Nms)


def delivered_torque(tr) -> np.ndarray | None:
    """``-(dh/dt + ω × h)`` [N m] per row (k, 3), B components: the CMG cluster's torque on the
    body, from the logged ``h`` (see the module docstring); None without CMG columns."""
    if "hx" not in tr.columns:
        return None
    h = tr.cols("hx", "hy", "hz")
    return -(rate_of_change(tr.t, h) + np.cross(tr.cols("wx", "wy", "wz"), h))
