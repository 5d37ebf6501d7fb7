"""The station's orbit at time t: one model for the equations, the measurements and the drawing.

Two forms (a scene's ``[orbit]``):

* **circular** (``radius``/``altitude``, ``inclination``, ``u0``): ``u = u0 + n t``, the
  expressions of :mod:`stationbed.model.environment`, unchanged (its scenes keep their numbers
  bit for bit);
* **two-body** (``r_N``/``v_N`` or ``elements``, optionally ``j2``): Kepler's equation solved by a
  fixed number of Newton steps (:func:`stationbed.core.kepler.newton_steps`, proven to machine
  precision for the scene's eccentricity) inside the compiled code; with J2, the node, the perigee
  and the mean anomaly drift at their first-order secular rates (the given state is taken as the
  mean elements at t = 0; short-period J2 terms are left out). No new states.

LVLH ``O`` on any orbit: z to nadir (``-r̂``), y = -orbit normal (``-ĥ``), x completes
(``ĥ × r̂``, along-track in the orbit plane, perpendicular to r). ``C_ON`` has these rows. With
``u = argp + ν`` the argument of latitude, the frame turns at
``omega_ON_O = (0, -u̇, 0) + Ω̇ C_ON ẑ_N``: on a two-body orbit ``u̇ = ν̇ = h / r²``.

Every function here accepts numpy or casadi (``t`` may be symbolic, or a numpy array of times:
then vectors have shape (3, n_t) and matrices (3, 3, n_t)).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from ..core.constants import R_EARTH_M
from ..core.kepler import J2_EARTH, j2_rates, mean_from_true, newton_steps, solve_kepler
from ..core.rotation import quat_mult
from ..core.symbolic import is_symbolic, matrix, trig, vector
from .environment import C_ON, Q_OR, q_ON

__all__ = ["OrbitAt", "orbit_kind", "orbit_size", "orbit_params", "orbit_at", "orbit_numeric", "orbit_plane", "KEPLER_SIZE"]

#: numbers of a two-body orbit in ``p`` (see :func:`orbit_params`)
KEPLER_SIZE = 17
#: numbers of a circular orbit in ``p``: radius, inclination, u0, n, cos i, sin i
CIRCULAR_SIZE = 6


class OrbitAt(NamedTuple):
    """The orbit at time t."""

    #: mean motion [rad/s] (the mean anomaly's rate on a two-body orbit)
    n: Any
    #: cos, sin of the inclination
    cos_i: Any
    sin_i: Any
    #: cos, sin of the argument of latitude u
    cos_u: Any
    sin_u: Any
    #: position [m] and velocity [m/s] of the mass centre, N components
    r_N: Any
    v_N: Any
    #: unit vector from the Earth's centre to the station, N components
    r_hat_N: Any
    #: mu / r³ [1/s²] (n² on a circular orbit)
    mu_r3: Any
    #: DCM from N to LVLH
    C_ON: Any
    #: angular velocity of LVLH relative to N, O components [rad/s]
    omega_ON_O: Any
    #: quaternion of LVLH relative to N, scalar first, continuous in t
    q_ON: Any


def orbit_kind(orbit) -> tuple:
    """The orbit's part of the structure: ``()`` circular, ``(newton_steps, j2)`` two-body.

    Parameters
    ----------
    orbit : stationbed.scene.Orbit
    """
    if not orbit.kepler:
        return ()
    return (newton_steps(orbit.elements_rad[1]), bool(orbit.j2))


def orbit_plane(orbit) -> tuple[float, float]:
    """``(inclination, raan)`` [rad] of the orbit plane at t = 0 (zeros without an orbit; the
    circular form's node lies on N's x axis)."""
    if orbit is None:
        return 0.0, 0.0
    if not orbit.kepler:
        return orbit.inclination, 0.0
    _, _, i, raan, _, _ = orbit.elements_rad
    return i, raan


def orbit_size(kind: tuple) -> int:
    """Length of the orbit's slice of ``p`` for the structure part ``kind``."""
    return KEPLER_SIZE if kind else CIRCULAR_SIZE


def orbit_params(orbit) -> np.ndarray:
    """The orbit's numbers in ``p``.

    Circular: ``radius, i, u0, n, cos i, sin i``. Two-body: ``a, e, i, cos i, sin i, Ω0, Ω̇, ω0, ω̇,
    M0, Ṁ, sqrt(1 - e²), mu, cos Ω0, sin Ω0, cos ω0, sin ω0`` (Ω the node, ω the perigee; the rates
    are zero without J2, Ṁ is then ``sqrt(mu / a³)``).
    """
    if not orbit.kepler:
        i = orbit.inclination  # cos/sin of a parameter: computed once here, not per RHS stage
        return np.array([orbit.radius_m, i, orbit.u0, orbit.mean_motion, math.cos(i), math.sin(i)])
    a, e, i, raan, argp, nu = orbit.elements_rad
    mu = orbit.mu
    if orbit.j2:
        raan_dot, argp_dot, M_dot = j2_rates(a, e, i, mu, J2_EARTH, R_EARTH_M)
    else:
        raan_dot, argp_dot, M_dot = 0.0, 0.0, math.sqrt(mu / a**3)
    M0 = mean_from_true(nu, e)
    return np.array([a, e, i, math.cos(i), math.sin(i), raan, raan_dot, argp, argp_dot, M0, M_dot,
                     math.sqrt(1.0 - e * e), mu, math.cos(raan), math.sin(raan), math.cos(argp), math.sin(argp)])


def _circular(t, po) -> OrbitAt:
    """The circular orbit: the expressions the model has always used, in the same order."""
    radius, incl, u0, n, ci, si = (po[i] for i in range(6))
    arg = u0 + n * t
    cu, su = trig(arg)
    r_hat_N = vector([cu, su * ci, su * si], arg)
    r_N = radius * r_hat_N
    v_N = (radius * n) * vector([-su, cu * ci, cu * si], arg)
    if is_symbolic(arg):
        return OrbitAt(n, ci, si, cu, su, r_N, v_N, r_hat_N, n * n, C_ON(arg, incl), ca.vertcat(0.0, -n, 0.0), q_ON(arg, incl))
    z = np.zeros(np.shape(arg))  # numpy: every field with t's trailing shape
    C = C_ON(arg, incl) if not np.ndim(arg) else np.stack([C_ON(a, incl) for a in arg], axis=-1)
    w = np.array([z, z - n, z])
    return OrbitAt(n, ci, si, cu, su, r_N, v_N, r_hat_N, n * n, C, w, q_ON(arg, incl))


def _kepler(t, po, steps: int, j2: bool) -> OrbitAt:
    a, e, i, ci, si = (po[k] for k in range(5))
    raan0, raan_dot, argp0, argp_dot, M0, M_dot, sq, mu = (po[k] for k in range(5, 13))
    M = M0 + M_dot * t
    E = solve_kepler(M, e, steps)
    cE, sE = trig(E)
    den = 1.0 - e * cE
    r = a * den
    cnu, snu = (cE - e) / den, sq * sE / den
    if j2:
        raan, argp = raan0 + raan_dot * t, argp0 + argp_dot * t
        (cO, sO), (cw, sw) = trig(raan), trig(argp)
    else:
        raan, argp = raan0 + 0.0 * t, argp0 + 0.0 * t
        cO, sO, cw, sw = (po[k] for k in range(13, 17))
    cu, su = cw * cnu - sw * snu, sw * cnu + cw * snu
    node = [cO, sO, 0.0 * cO]  # N̂: ascending node
    ahead = [-sO * ci, cO * ci, si + 0.0 * cO]  # M̂ = ĥ × N̂
    normal = [sO * si, -cO * si, ci + 0.0 * cO]  # ĥ
    r_hat = [cu * n_ + su * m_ for n_, m_ in zip(node, ahead)]
    t_hat = [cu * m_ - su * n_ for n_, m_ in zip(node, ahead)]  # ĥ × r̂
    nu_dot = M_dot * sq / (den * den)  # h / r²
    u_dot = nu_dot + argp_dot if j2 else nu_dot
    r_dot = a * e * sE * M_dot / den
    r_N = [r * x for x in r_hat]
    v_N = [r_dot * x + (r * u_dot) * y for x, y in zip(r_hat, t_hat)]
    if j2:  # the node turns about ẑ_N
        v_N = [v_N[0] - raan_dot * r_N[1], v_N[1] + raan_dot * r_N[0], v_N[2]]
    rows = [t_hat, [-x for x in normal], [-x for x in r_hat]]
    w = [0.0 * u_dot, -u_dot, 0.0 * u_dot]
    if j2:  # + Ω̇ ẑ_N in O components (the third column of C_ON)
        w = [w[k] + raan_dot * rows[k][2] for k in range(3)]
    # q_ON = q_z(Ω) ⊗ q_x(i) ⊗ q_z(u) ⊗ Q_OR with u continuous: ν = E + 2 atan(β sin E / (1 - β cos E))
    beta = e / (1.0 + sq)
    atan = ca.atan if is_symbolic(t, po) else np.arctan
    u = argp + E + 2.0 * atan(beta * sE / (1.0 - beta * cE))
    like = E
    z = 0.0 if is_symbolic(E) else np.zeros(np.shape(E))  # numpy: broadcast constants to t's shape

    def vec(items):
        return vector([x + z for x in items], like)

    cO2, sO2 = trig(0.5 * raan)
    ci2, si2 = trig(0.5 * i)
    cu2, su2 = trig(0.5 * u)
    q = quat_mult(quat_mult(vec([cO2, 0.0, 0.0, sO2]), vec([ci2, si2, 0.0, 0.0])), vec([cu2, 0.0, 0.0, su2]))
    q = quat_mult(q, vec(Q_OR))
    return OrbitAt(M_dot, ci, si, cu, su, vec(r_N), vec(v_N), vec(r_hat), mu / (r * r * r),
                   matrix([[x + z for x in row] for row in rows], like), vec(w), q)


def orbit_at(t, po, kind: tuple) -> OrbitAt:
    """The orbit at time ``t`` from its slice ``po`` of ``p``.

    Parameters
    ----------
    t : float, ndarray or casadi SX  Time [s].
    po : ndarray or casadi SX  The orbit's numbers (:func:`orbit_params`).
    kind : tuple  :func:`orbit_kind` (the structure's).

    Returns
    -------
    OrbitAt
    """
    if not kind:
        return _circular(t, po)
    return _kepler(t, po, *kind)


def orbit_numeric(orbit, t) -> OrbitAt:
    """The orbit of a scene's ``[orbit]`` table at times ``t`` (numpy).

    Parameters
    ----------
    orbit : stationbed.scene.Orbit
    t : float or ndarray, shape (n_t,)  Time [s].
    """
    return orbit_at(np.asarray(t, dtype=float), orbit_params(orbit), orbit_kind(orbit))

