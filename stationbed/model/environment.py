"""Circular orbit, LVLH frame, gravity gradient.

Orbit (DESIGN §5): ``R_N(t) = radius (cos u, sin u cos i, sin u sin i)``, ``u = u0 + n t``,
``n = sqrt(mu / radius³)``; the ascending node lies on N's x axis.

LVLH ``O`` (DESIGN §3): x along the velocity, z to nadir, y = -orbit normal. ``C_ON`` has the
O axes, in N components, as its rows. The LVLH frame turns relative to N at
``omega_ON_O = (0, -n, 0)``.

All functions accept numpy or casadi arguments (``t`` may be symbolic).

These are the circular form's expressions; :mod:`stationbed.model.orbit` is the one orbit model
every caller uses (circular through these, two-body and J2 orbits on top).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.rotation import quat_mult
from ..core.symbolic import is_symbolic, trig, vector
from .sun import julian_date, sun_position

__all__ = [
    "orbit_position_N",
    "C_ON",
    "omega_ON_O",
    "gravity_gradient_torque",
    "sun_direction_N",
    "q_ON",
    "Q_OR",
]

#: Quaternion of LVLH relative to the radial/along-track/normal frame R (x radial, z orbit normal):
#: x_O = y_R, y_O = -z_R, z_O = -x_R.
Q_OR = (0.5, -0.5, -0.5, 0.5)


def orbit_position_N(u, radius, inclination):
    """Position of the station's mass centre on its circular orbit.

    Parameters
    ----------
    u : float, ndarray or casadi SX  Argument of latitude [rad].
    radius : float  Orbit radius [m].
    inclination : float or casadi SX  Orbit inclination [rad].

    Returns
    -------
    ndarray or casadi SX, shape (3,)  ``R_N``, N components [m].
    """
    cu, su = trig(u)
    ci, si = trig(inclination)
    return vector([radius * cu, radius * su * ci, radius * su * si], u)


def C_ON(u, inclination):
    """DCM from N to LVLH (rows: x_O, y_O, z_O in N components).

    Parameters
    ----------
    u : float or casadi SX  Argument of latitude [rad].
    inclination : float or casadi SX  Orbit inclination [rad].

    Returns
    -------
    ndarray or casadi SX, shape (3, 3)  ``C_ON``.
    """
    cu, su = trig(u)
    ci, si = trig(inclination)
    rows = [
        [-su, cu * ci, cu * si],  # x_O: along velocity
        [0.0, si, -ci],  # y_O: minus the orbit normal (0, -si, ci)
        [-cu, -su * ci, -su * si],  # z_O: nadir
    ]
    if is_symbolic(u, inclination):
        return ca.vertcat(*[ca.horzcat(*r) for r in rows])
    return np.array(rows, dtype=float)


def omega_ON_O(mean_motion: float) -> np.ndarray:
    """Angular velocity of LVLH relative to N: ``omega_ON_O = (0, -n, 0)``.

    Parameters
    ----------
    mean_motion : float  Orbital rate n [rad/s].

    Returns
    -------
    ndarray, shape (3,)  O components [rad/s].
    """
    return np.array([0.0, -mean_motion, 0.0])


def gravity_gradient_torque(R_hat_B, I_O_B, mean_motion_sq):
    """Gravity-gradient torque of a point-mass Earth, ``L_gg = 3 n² R̂_B × (I R̂_B)``.

    Parameters
    ----------
    R_hat_B : ndarray or casadi SX, shape (3,)  Unit vector from the Earth's centre to the
        station, B components (its sign does not matter: the torque is quadratic in it).
    I_O_B : ndarray or casadi SX, shape (3, 3)  Inertia about the mass centre O, B axes [kg m²].
    mean_motion_sq : float or casadi SX  ``n² = mu/|R|³`` [rad²/s²].

    Returns
    -------
    ndarray or casadi SX, shape (3,)  Torque about O, B components [N m].
    """
    if isinstance(R_hat_B, (ca.SX, ca.MX)) or isinstance(I_O_B, (ca.SX, ca.MX)):
        return 3.0 * mean_motion_sq * ca.cross(R_hat_B, ca.mtimes(I_O_B, R_hat_B))
    return 3.0 * mean_motion_sq * np.cross(R_hat_B, I_O_B @ R_hat_B)


def sun_direction_N(sun, inclination: float = 0.0, raan: float = 0.0) -> np.ndarray:
    """Unit vector to the sun, N components, from a scene's ``[sun]`` table.

    Parameters
    ----------
    sun : stationbed.scene.Sun  ``direction_N``, or ``beta`` [rad] and ``u_noon`` [rad], or
        ``epoch`` (the low-precision ephemeris of :mod:`stationbed.model.sun`, held at the epoch).
    inclination : float  Orbit inclination [rad] (0 without an orbit).
    raan : float  Right ascension of the orbit's ascending node at t = 0 [rad] (0: on N's x axis,
        as on the circular orbit).

    Returns
    -------
    ndarray, shape (3,)  ``s_N`` (unit vector).

    Notes
    -----
    With a solar beta angle ``β`` and the argument of latitude of orbit noon ``u_noon``:
    ``s_N = cos β (cos u_noon x̂_node + sin u_noon ŷ_90) + sin β n̂``, where ``x̂_node = (1,0,0)``,
    ``ŷ_90 = (0, cos i, sin i)`` span the orbit plane and ``n̂ = (0, -sin i, cos i)`` is the
    orbit normal (along ``R × V``). β > 0 puts the sun on the orbit normal's side.
    """
    if sun.direction_N is not None:
        v = np.array(sun.direction_N, dtype=float)
        return v / np.linalg.norm(v)
    if sun.epoch is not None:
        return sun_position(julian_date(sun.epoch))[0]
    b, u = sun.beta, sun.u_noon
    ci, si = np.cos(inclination), np.sin(inclination)
    if raan != 0.0:  # the node turned by raan about z_N
        cO, sO = np.cos(raan), np.sin(raan)
        in_plane = np.cos(u) * np.array([cO, sO, 0.0]) + np.sin(u) * np.array([-sO * ci, cO * ci, si])
        return np.cos(b) * in_plane + np.sin(b) * np.array([sO * si, -cO * si, ci])
    in_plane = np.cos(u) * np.array([1.0, 0.0, 0.0]) + np.sin(u) * np.array([0.0, ci, si])
    return np.cos(b) * in_plane + np.sin(b) * np.array([0.0, -si, ci])


def q_ON(u, inclination):
    """Quaternion (scalar first) of LVLH relative to N, continuous in ``u``: ``dcm(q_ON) = C_ON``.

    Parameters
    ----------
    u : float or casadi SX  Argument of latitude [rad].
    inclination : float or casadi SX  Orbit inclination [rad].

    Returns
    -------
    ndarray or casadi SX, shape (4,)  ``q_ON``.

    Notes
    -----
    ``q_ON = q_x(i) ⊗ q_z(u) ⊗ Q_OR`` (``dcm(a ⊗ b) = dcm(b) dcm(a)``): node, then the argument of
    latitude, then the fixed LVLH axes.
    """
    ci, si = trig(0.5 * inclination)
    cu, su = trig(0.5 * u)
    q_i = vector([ci, si, 0.0 * si, 0.0 * si], u)
    q_u = vector([cu, 0.0 * su, 0.0 * su, su], u)
    return quat_mult(quat_mult(q_i, q_u), vector(list(Q_OR), u))
