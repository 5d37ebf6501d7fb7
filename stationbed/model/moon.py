"""The Moon for a scene with an epoch: the Astronomical Almanac's low-precision lunar coordinates.

The Astronomical Almanac, section D, "Low-precision formulae for geocentric coordinates of the
Moon" (stated accuracy 0.3 deg in ecliptic longitude, 0.2 deg in latitude, 0.003 deg in
horizontal parallax, 1950-2050): ecliptic longitude λ, latitude β and horizontal parallax π as
short trigonometric series in T (Julian centuries from J2000.0), then the geocentric direction
in the mean equator and equinox of date (the frame of :func:`stationbed.model.sun.sun_position`,
N) and the distance ``R_E / sin π``. Used by the star tracker's Moon exclusion (issue 20): a
0.3 deg error is far inside the exclusion cones of current heads (10-25 deg).
"""

from __future__ import annotations

import math

import numpy as np

from .sun import JD_J2000

__all__ = ["moon_position", "EARTH_RADIUS_PARALLAX_M"]

#: the Earth's equatorial radius the Almanac's horizontal parallax refers to [m]
EARTH_RADIUS_PARALLAX_M = 6378140.0


def _sind(x):
    return math.sin(math.radians(x))


def _cosd(x):
    return math.cos(math.radians(x))


def moon_position(jd: float) -> tuple[np.ndarray, float, float, float]:
    """Geocentric unit vector to the Moon (N), its distance [m], and λ, β [deg] (ecliptic of date).

    Parameters
    ----------
    jd : float  Julian date [days] (TT; UTC is 69 s off: 0.01 deg of the Moon's motion).
    """
    T = (jd - JD_J2000) / 36525.0
    lam = (218.32 + 481267.881 * T + 6.29 * _sind(135.0 + 477198.87 * T) - 1.27 * _sind(259.3 - 413335.36 * T)
           + 0.66 * _sind(235.7 + 890534.22 * T) + 0.21 * _sind(269.9 + 954397.74 * T)
           - 0.19 * _sind(357.5 + 35999.05 * T) - 0.11 * _sind(186.5 + 966404.03 * T))
    beta = (5.13 * _sind(93.3 + 483202.02 * T) + 0.28 * _sind(228.2 + 960400.89 * T)
            - 0.28 * _sind(318.3 + 6003.15 * T) - 0.17 * _sind(217.6 - 407332.21 * T))
    par = (0.9508 + 0.0518 * _cosd(135.0 + 477198.87 * T) + 0.0095 * _cosd(259.3 - 413335.36 * T)
           + 0.0078 * _cosd(235.7 + 890534.22 * T) + 0.0028 * _cosd(269.9 + 954397.74 * T))
    l = _cosd(beta) * _cosd(lam)  # noqa: E741 (the Almanac's names)
    m = 0.9175 * _cosd(beta) * _sind(lam) - 0.3978 * _sind(beta)
    n = 0.3978 * _cosd(beta) * _sind(lam) + 0.9175 * _sind(beta)
    u = np.array([l, m, n])
    return u / np.linalg.norm(u), EARTH_RADIUS_PARALLAX_M / _sind(par), lam % 360.0, beta
