"""Circular orbit, LVLH frame, gravity gradient.

Orbit (DESIGN §5): ``R_N(t) = radius (cos u, sin u cos i, sin u sin i)``, ``u = u0 + n t``,
``n = sqrt(mu / radius³)``; the ascending node lies on N's x axis.

LVLH ``O`` (DESIGN §3): x along the velocity, z to nadir, y = -orbit normal. ``C_ON`` has the
O axes, in N components, as its rows. The LVLH frame turns relative to N at
``omega_ON_O = (0, -n, 0)``.

All functions accept numpy or casadi arguments (``t`` may be symbolic).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = [
    "orbit_position_N",
    "C_ON",
    "omega_ON_O",
    "gravity_gradient_torque",
]


def _trig(u):
    if isinstance(u, (ca.SX, ca.MX, ca.DM)):
        return ca.cos(u), ca.sin(u)
    return np.cos(u), np.sin(u)


def _stack(items, like):
    if isinstance(like, (ca.SX, ca.MX, ca.DM)):
        return ca.vertcat(*items)
    return np.array(items, dtype=float)


def orbit_position_N(u, radius, inclination):
    """Position of the station's mass centre, N components [m], at argument of latitude ``u``."""
    cu, su = _trig(u)
    ci, si = _trig(inclination)
    return _stack([radius * cu, radius * su * ci, radius * su * si], u)


def C_ON(u, inclination):
    """DCM from N to LVLH at argument of latitude ``u`` (rows: x_O, y_O, z_O in N)."""
    cu, su = _trig(u)
    ci, si = _trig(inclination)
    rows = [
        [-su, cu * ci, cu * si],  # x_O: along velocity
        [0.0, si, -ci],  # y_O: minus the orbit normal (0, -si, ci)
        [-cu, -su * ci, -su * si],  # z_O: nadir
    ]
    if isinstance(u, (ca.SX, ca.MX)) or isinstance(inclination, (ca.SX, ca.MX)):
        return ca.vertcat(*[ca.horzcat(*r) for r in rows])
    return np.array(rows, dtype=float)


def omega_ON_O(mean_motion: float) -> np.ndarray:
    """Angular velocity of LVLH relative to N, O components [rad/s]: ``(0, -n, 0)``."""
    return np.array([0.0, -mean_motion, 0.0])


def gravity_gradient_torque(R_hat_B, I_O_B, mean_motion_sq):
    """``L_gg = 3 n² R̂_B × (I R̂_B)`` with ``n² = mu/|R|³`` (point-mass Earth) [N m].

    ``R_hat_B`` is the unit vector from the Earth's centre to the station, B components; the
    sign of R̂ does not matter (the torque is quadratic in it).
    """
    if isinstance(R_hat_B, (ca.SX, ca.MX)) or isinstance(I_O_B, (ca.SX, ca.MX)):
        return 3.0 * mean_motion_sq * ca.cross(R_hat_B, ca.mtimes(I_O_B, R_hat_B))
    return 3.0 * mean_motion_sq * np.cross(R_hat_B, I_O_B @ R_hat_B)
