"""The sun for a scene with an epoch, the Earth's rotation angle, and the Earth's shadow.

* :func:`sun_position` - the Astronomical Almanac's low-precision solar coordinates (AA, section
  C "Low precision formulas for the Sun"; stated accuracy 0.01 deg in direction between 1950 and
  2050): mean longitude ``L``, mean anomaly ``g``, ecliptic longitude
  ``λ = L + 1.915° sin g + 0.020° sin 2g``, obliquity ``ε = 23.439° - 4e-7° n``, distance
  ``R = 1.00014 - 0.01671 cos g - 0.00014 cos 2g`` AU, ``n`` days from J2000.0. The direction is
  in the mean equator and equinox of date; N is taken as that frame (x to the equinox, z to the
  Earth's pole), which differs from GCRF by precession (~0.014 deg per year from 2000).
* :func:`earth_rotation_angle` - ERA (IAU 2000, IERS Conventions 2010 Eq. 5.15) with UT1 = UTC
  (|UT1 - UTC| < 0.9 s, 0.004 deg).
* :func:`shadow_cylindrical`, :func:`shadow_conical` - the fraction of the sun's disc seen from
  ``r_N`` (1 lit, 0 umbra): a cylinder of the Earth's radius behind the Earth, or the two cones
  with the penumbra's partial occultation of two discs (Montenbruck & Gill, Satellite Orbits,
  2000, section 3.4.2). Both take numpy or casadi arguments.

The epoch's sun is held over a run (it moves ~1 deg/day, 0.04 deg/hour): see docs/design.md.
"""

from __future__ import annotations

import datetime as _dt
import math

import casadi as ca
import numpy as np

from ..core.constants import R_EARTH_M
from ..core.symbolic import is_symbolic

__all__ = [
    "AU_M", "R_SUN_M", "P_SUN_1AU_N_M2", "julian_date", "sun_position", "earth_rotation_angle",
    "shadow_cylindrical", "shadow_conical", "SHADOW_MODELS", "sun_distance_m",
]

#: astronomical unit [m] (IAU 2012 Resolution B2)
AU_M = 1.495978707e11
#: nominal solar radius [m] (IAU 2015 Resolution B3)
R_SUN_M = 6.957e8
#: solar radiation pressure on a perfect absorber at 1 AU [N/m²] (Wertz, Spacecraft Attitude
#: Determination and Control, 1978, Eq. 17-8; 1361 W/m² / c)
P_SUN_1AU_N_M2 = 4.56e-6
#: Julian date of J2000.0 (2000-01-01 12:00 TT; UTC used as the time scale here, 64 s off)
JD_J2000 = 2451545.0


def julian_date(epoch: str | _dt.datetime) -> float:
    """Julian date of a UTC epoch.

    Parameters
    ----------
    epoch : str or datetime  ISO 8601, e.g. ``"2024-03-20T03:06:00Z"`` (no zone: UTC).

    Returns
    -------
    float  Julian date [days].
    """
    if isinstance(epoch, str):
        epoch = _dt.datetime.fromisoformat(epoch.replace("Z", "+00:00"))
    if epoch.tzinfo is None:
        epoch = epoch.replace(tzinfo=_dt.timezone.utc)
    j2000 = _dt.datetime(2000, 1, 1, 12, 0, 0, tzinfo=_dt.timezone.utc)
    return JD_J2000 + (epoch - j2000).total_seconds() / 86400.0


def sun_position(jd: float) -> tuple[np.ndarray, float]:
    """Unit vector to the sun and its distance (AA low-precision formula, 0.01 deg, 1950-2050).

    Parameters
    ----------
    jd : float  Julian date (UTC) [days].

    Returns
    -------
    s_N : ndarray, shape (3,)  Unit vector from the Earth to the sun, mean equator and equinox
        of date (N).
    distance : float  Earth-sun distance [m].
    """
    n = jd - JD_J2000
    L = math.radians((280.460 + 0.9856474 * n) % 360.0)
    g = math.radians((357.528 + 0.9856003 * n) % 360.0)
    lam = L + math.radians(1.915) * math.sin(g) + math.radians(0.020) * math.sin(2 * g)
    eps = math.radians(23.439 - 4.0e-7 * n)
    R_au = 1.00014 - 0.01671 * math.cos(g) - 0.00014 * math.cos(2 * g)
    s_N = np.array([math.cos(lam), math.cos(eps) * math.sin(lam), math.sin(eps) * math.sin(lam)])
    return s_N, R_au * AU_M


def earth_rotation_angle(jd: float) -> float:
    """Earth rotation angle ERA [rad] in [0, 2π) (IAU 2000; UT1 taken as UTC).

    Parameters
    ----------
    jd : float  Julian date [days].
    """
    du = jd - JD_J2000
    return 2.0 * math.pi * ((0.7790572732640 + 0.00273781191135448 * du + du) % 1.0)


def _ops(*xs):
    if is_symbolic(*xs):
        return ca.sqrt, ca.asin, ca.acos, ca.if_else, ca.fmin, ca.fmax
    return (np.sqrt, np.arcsin, np.arccos, lambda c, a, b: np.where(c, a, b), np.minimum, np.maximum)


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def shadow_cylindrical(r_N, s_N, sun_distance=None):
    """Fraction of the sun seen, cylindrical shadow: 0 when ``r_N·ŝ < 0`` and the distance from
    the Earth-sun line is below the Earth's radius, else 1.

    Parameters
    ----------
    r_N : ndarray or casadi SX, shape (3,)  Position from the Earth's centre [m].
    s_N : ndarray or casadi SX, shape (3,)  Unit vector to the sun.
    sun_distance : ignored (the same signature as :func:`shadow_conical`).

    Returns
    -------
    float or casadi SX  ν in {0, 1}.
    """
    sqrt, _, _, if_else, _, _ = _ops(r_N, s_N)
    along = _dot(r_N, s_N)
    perp2 = _dot(r_N, r_N) - along * along
    return if_else((along < 0) * (perp2 < R_EARTH_M * R_EARTH_M), 0.0, 1.0)


def shadow_conical(r_N, s_N, sun_distance):
    """Fraction of the sun's disc seen, conical (umbra and penumbra) shadow.

    Parameters
    ----------
    r_N : ndarray or casadi SX, shape (3,)  Position from the Earth's centre [m].
    s_N : ndarray or casadi SX, shape (3,)  Unit vector to the sun.
    sun_distance : float or casadi SX  Earth-sun distance [m].

    Returns
    -------
    float or casadi SX  ν in [0, 1].

    Notes
    -----
    Montenbruck & Gill 3.4.2: apparent radii ``a = asin(R_sun/|d|)`` (sun, ``d = s - r``) and
    ``b = asin(R_E/|r|)`` (Earth), separation ``c`` of their centres; the occulted area of the
    sun's disc is that of two overlapping circles.
    """
    sqrt, asin, acos, if_else, fmin, fmax = _ops(r_N, s_N, sun_distance)
    d = [sun_distance * s_N[i] - r_N[i] for i in range(3)]
    rn, dn = sqrt(_dot(r_N, r_N)), sqrt(_dot(d, d))
    a = asin(R_SUN_M / dn)
    b = asin(R_EARTH_M / rn)
    c = acos(fmin(fmax(-_dot(r_N, d) / (rn * dn), -1.0), 1.0))
    cs = fmax(c, 1e-12)
    x = (cs * cs + a * a - b * b) / (2 * cs)
    y = sqrt(fmax(a * a - x * x, 0.0))
    area = a * a * acos(fmin(fmax(x / a, -1.0), 1.0)) + b * b * acos(fmin(fmax((cs - x) / b, -1.0), 1.0)) - cs * y
    partial = 1.0 - area / (math.pi * a * a)
    inner = if_else(c < b - a, 0.0, if_else(c < a - b, 1.0 - (b * b) / (a * a), partial))
    return if_else(c >= a + b, 1.0, inner)


#: scene name -> shadow function ``f(r_N, s_N, sun_distance)``
SHADOW_MODELS = {"cylindrical": shadow_cylindrical, "conical": shadow_conical}


def sun_distance_m(sun) -> float:
    """Earth-sun distance of a scene's ``[sun]`` [m]: the ephemeris' at ``epoch``, else 1 AU."""
    if sun is None or sun.epoch is None:
        return AU_M
    return sun_position(julian_date(sun.epoch))[1]
