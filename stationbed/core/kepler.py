"""Two-body orbit mathematics: Kepler's equation, elements <-> state, J2 secular rates.

Elements ``(a, e, i, raan, argp, nu)``: semi-major axis [m], eccentricity, inclination, right
ascension of the ascending node, argument of perigee and true anomaly [rad] (Vallado,
*Fundamentals of Astrodynamics and Applications*, 4th ed., Alg. 9 and 10). The node vector of a
circular or equatorial orbit is undefined; the conventions used then are stated in
:func:`elements_from_rv`.

:func:`solve_kepler` accepts numpy or casadi arguments (a fixed number of Newton steps, so it
compiles into straight-line code); the conversions are numpy only (they run once per scene).
"""

from __future__ import annotations

import math

import numpy as np

from .symbolic import trig

__all__ = [
    "J2_EARTH",
    "newton_steps",
    "solve_kepler",
    "rv_from_elements",
    "elements_from_rv",
    "mean_from_true",
    "j2_rates",
    "KEPLER_MAX_E",
]

#: Earth's second zonal harmonic J2 (unnormalised; EGM96 / WGS-84 value 1.08262668e-3)
J2_EARTH = 1.08262668e-3
#: largest eccentricity for which :func:`newton_steps` proves convergence from its start
#: (the error bound contracts when ``C ε_0 = e³/(2(1-e)) < 1``, i.e. e < 0.77; 0.7 keeps a margin)
KEPLER_MAX_E = 0.7
#: the solved eccentric anomaly's error bound, below the rounding of an angle of order π [rad]
KEPLER_TOL_RAD = 1e-17


def newton_steps(e: float) -> int:
    """The number of Newton steps that solve Kepler's equation to :data:`KEPLER_TOL_RAD`.

    Proof (exact arithmetic). ``f(E) = E - e sin E - M`` has ``f' = 1 - e cos E >= 1 - e`` and
    ``|f''| = |e sin E| <= e`` everywhere, so one Newton step maps the error ``ε`` to at most
    ``C ε²`` with ``C = e / (2 (1 - e))`` (Taylor with the remainder's bound; it holds globally
    because the bounds do). The start ``E0 = M + e sin M`` errs by
    ``|E - E0| = e |sin E - sin M| <= e |E - M| = e² |sin E| <= e²``. The bound
    ``ε_{k+1} = C ε_k²`` from ``ε_0 = e²`` is iterated until below :data:`KEPLER_TOL_RAD`.
    e = 0: 1 step; e = 0.0078: 2; e = 0.05 and 0.1: 3; e = 0.3: 4; e = 0.5: 5; e = 0.7: 7.

    Parameters
    ----------
    e : float  Eccentricity, 0 <= e <= :data:`KEPLER_MAX_E`.

    Returns
    -------
    int
    """
    if not 0.0 <= e <= KEPLER_MAX_E:
        raise ValueError(f"eccentricity {e:g} outside [0, {KEPLER_MAX_E}] where the Kepler solver is proven")
    c, eps, k = e / (2.0 * (1.0 - e)), e * e, 0
    while eps > KEPLER_TOL_RAD:
        eps, k = c * eps * eps, k + 1
        if k > 20:  # pragma: no cover - excluded by KEPLER_MAX_E (C ε_0 < 1 there)
            raise ValueError(f"eccentricity {e:g}: the Newton error bound does not contract")
    return max(k, 1)


def solve_kepler(M, e, steps: int):
    """Eccentric anomaly E with ``E - e sin E = M`` (``steps`` Newton steps from ``M + e sin M``).

    Parameters
    ----------
    M : float, ndarray or casadi SX  Mean anomaly [rad] (any value: E follows it continuously).
    e : float or casadi SX  Eccentricity.
    steps : int  Newton steps (:func:`newton_steps`).

    Returns
    -------
    Same kind as M  E [rad].
    """
    _, s = trig(M)
    E = M + e * s
    for _ in range(steps):
        c, s = trig(E)
        E = E - (E - e * s - M) / (1.0 - e * c)
    return E


def _perifocal(raan, argp, i):
    """Unit vectors P (to perigee) and Q (90° ahead in the orbit plane), N components."""
    cO, sO, cw, sw, ci, si = math.cos(raan), math.sin(raan), math.cos(argp), math.sin(argp), math.cos(i), math.sin(i)
    P = np.array([cO * cw - sO * sw * ci, sO * cw + cO * sw * ci, sw * si])
    Q = np.array([-cO * sw - sO * cw * ci, -sO * sw + cO * cw * ci, cw * si])
    return P, Q


def rv_from_elements(a, e, i, raan, argp, nu, mu) -> tuple[np.ndarray, np.ndarray]:
    """Position [m] and velocity [m/s], N components, of classical elements (Vallado Alg. 10).

    Parameters
    ----------
    a : float  Semi-major axis [m]; e : float  eccentricity (< 1); i, raan, argp, nu : float [rad];
    mu : float  Gravitational parameter [m³/s²].
    """
    p = a * (1.0 - e * e)
    r = p / (1.0 + e * math.cos(nu))
    P, Q = _perifocal(raan, argp, i)
    r_N = r * (math.cos(nu) * P + math.sin(nu) * Q)
    v_N = math.sqrt(mu / p) * (-math.sin(nu) * P + (e + math.cos(nu)) * Q)
    return r_N, v_N


#: below this eccentricity (or sin i) the perigee (or node) is taken as undefined
_SMALL = 1e-12


def elements_from_rv(r_N, v_N, mu) -> tuple[float, float, float, float, float, float]:
    """Classical elements ``(a, e, i, raan, argp, nu)`` of a bound state (Vallado Alg. 9).

    Parameters
    ----------
    r_N : array_like, shape (3,)  Position [m]; v_N : array_like, shape (3,)  velocity [m/s];
    mu : float  [m³/s²].

    Notes
    -----
    Degenerate orbits: equatorial (sin i < 1e-12) puts the node on N's x axis (raan = 0);
    circular (e < 1e-12) puts the perigee at the node (argp = 0, nu = argument of latitude).
    These choices leave the position and velocity unchanged.
    """
    r = np.asarray(r_N, dtype=float)
    v = np.asarray(v_N, dtype=float)
    rn, v2 = np.linalg.norm(r), float(v @ v)
    h = np.cross(r, v)
    hn = np.linalg.norm(h)
    if hn == 0.0:
        raise ValueError("r_N and v_N are parallel: no orbit plane")
    energy = 0.5 * v2 - mu / rn
    if energy >= 0.0:
        raise ValueError(f"the state is not a bound orbit (specific energy {energy:.6g} J/kg >= 0)")
    a = -mu / (2.0 * energy)
    e_vec = ((v2 - mu / rn) * r - (r @ v) * v) / mu
    e = float(np.linalg.norm(e_vec))
    w = h / hn
    i = math.acos(max(-1.0, min(1.0, w[2])))
    node = np.array([-h[1], h[0], 0.0])
    if np.linalg.norm(node) < _SMALL * hn:
        node = np.array([1.0, 0.0, 0.0])
    node = node / np.linalg.norm(node)
    raan = math.atan2(node[1], node[0]) % (2.0 * math.pi)
    m = np.cross(w, node)  # 90° ahead of the node in the plane
    if e < _SMALL:
        e, argp = 0.0, 0.0
    else:
        argp = math.atan2(e_vec @ m, e_vec @ node) % (2.0 * math.pi)
    u = math.atan2(r @ m, r @ node)
    nu = (u - argp) % (2.0 * math.pi)
    return a, e, i, raan, argp, nu


def mean_from_true(nu: float, e: float) -> float:
    """Mean anomaly [rad] of the true anomaly ``nu`` [rad] (same revolution: M - nu in (-π, π))."""
    E = 2.0 * math.atan2(math.sqrt(1.0 - e) * math.sin(0.5 * nu), math.sqrt(1.0 + e) * math.cos(0.5 * nu))
    M = E - e * math.sin(E)
    return nu + math.remainder(M - nu, 2.0 * math.pi)


def j2_rates(a: float, e: float, i: float, mu: float, j2: float, r_eq: float) -> tuple[float, float, float]:
    """Secular rates of the node, the perigee and the mean anomaly under J2 (first order).

    Vallado Eq. 9-41 and 9-42 (Brouwer's first-order secular terms), ``p = a (1 - e²)``,
    ``n0 = sqrt(mu / a³)``:
    ``Ω̇ = -3/2 n0 J2 (R/p)² cos i``; ``ω̇ = 3/4 n0 J2 (R/p)² (4 - 5 sin² i)``;
    ``Ṁ = n0 (1 + 3/4 J2 (R/p)² sqrt(1 - e²) (2 - 3 sin² i))``.

    Returns
    -------
    (raan_dot, argp_dot, M_dot) : floats [rad/s]
    """
    n0 = math.sqrt(mu / a**3)
    k = j2 * (r_eq / (a * (1.0 - e * e))) ** 2
    s2 = math.sin(i) ** 2
    return (-1.5 * n0 * k * math.cos(i), 0.75 * n0 * k * (4.0 - 5.0 * s2), n0 * (1.0 + 0.75 * k * math.sqrt(1.0 - e * e) * (2.0 - 3.0 * s2)))
