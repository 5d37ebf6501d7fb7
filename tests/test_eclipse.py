"""Sun ephemeris, Earth rotation angle and the Earth's shadow (stationbed/model/sun.py).

Truths used (none calls the library's geometry):

* published dates: the 2024 equinoxes and solstices (USNO/IMCCE: Mar 20 03:06, Jun 20 20:51,
  Sep 22 12:44, Dec 21 09:21 UTC), where the sun's apparent ecliptic longitude is 0, 90, 180,
  270 deg, i.e. its declination is 0 or ±ε; perihelion and aphelion 2024 (Jan 3 00:39 UTC,
  0.983307 AU; Jul 5 05:06 UTC, 1.016725 AU);
* the ERA of IERS Conventions 2010 at J2000.0 (280.46061837504 deg) and its rate of one turn per
  sidereal day;
* eclipse entry and exit of a circular orbit from plane geometry written in the test: in the
  cylindrical shadow when ``cos β cos(u - u_noon) < -sqrt(1 - (R_E/r)²)``; the conical shadow's
  umbra and penumbra edges where the angle between the Earth's and the sun's centres seen from
  the station equals ``b ∓ a`` (apparent radii), computed by the test's own vectors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed.model.sun import (
    earth_rotation_angle, julian_date, shadow_conical, shadow_cylindrical, sun_position,
)

#: the Astronomical Almanac's stated accuracy of the low-precision sun (1950-2050) [deg], plus the
#: published times' rounding to the minute (the sun moves 0.0007 deg per minute)
EPHEMERIS_DEG = 0.01 + 0.0007
#: the distance series' accuracy [AU]: its terms stop at 1.4e-4 AU (cos 2g), the next are ~1e-5
DISTANCE_AU = 3e-5
#: the test's geometry and the library's agree to the bisection tolerance [s]
BISECT_S = 1e-3
#: 1 AU [m] (IAU 2012), the Earth's equatorial radius [m] (WGS-84), the sun's radius [m] (IAU 2015)
AU = 1.495978707e11
R_E = 6378137.0
R_SUN = 6.957e8
OBLIQUITY_2024_DEG = 23.4362


@pytest.mark.parametrize(
    "epoch, lon_deg",
    [("2024-03-20T03:06:00Z", 0.0), ("2024-06-20T20:51:00Z", 90.0), ("2024-09-22T12:44:00Z", 180.0),
     ("2024-12-21T09:21:00Z", 270.0)],
    ids=["march_equinox", "june_solstice", "september_equinox", "december_solstice"],
)
def test_sun_at_equinoxes_and_solstices(epoch, lon_deg):
    s_N, _ = sun_position(julian_date(epoch))
    lam = math.radians(lon_deg)
    eps = math.radians(OBLIQUITY_2024_DEG)
    expected = np.array([math.cos(lam), math.cos(eps) * math.sin(lam), math.sin(eps) * math.sin(lam)])
    angle = math.degrees(math.acos(min(1.0, float(s_N @ expected))))
    assert angle < EPHEMERIS_DEG


@pytest.mark.parametrize("epoch, au", [("2024-01-03T00:39:00Z", 0.983307), ("2024-07-05T05:06:00Z", 1.016725)],
                         ids=["perihelion", "aphelion"])
def test_sun_distance_at_apsides(epoch, au):
    _, d = sun_position(julian_date(epoch))
    assert abs(d / AU - au) < DISTANCE_AU


def test_earth_rotation_angle():
    assert_allclose(math.degrees(earth_rotation_angle(2451545.0)), 280.46061837504, atol=1e-9)
    sidereal_day = 86400.0 / 1.00273781191135448  # s of UT1
    later = earth_rotation_angle(2451545.0 + 100 * sidereal_day / 86400.0)
    assert_allclose(later, earth_rotation_angle(2451545.0), atol=1e-9)


# -- shadow ------------------------------------------------------------------------------------
ALT = 400e3
R = R_E + ALT
INCL = 0.9
N_RATE = math.sqrt(3.986004418e14 / R**3)


def _geometry(beta, u_noon=0.3):
    """The orbit and sun of the test: r_N(u), unit sun ŝ with the given beta angle."""
    ci, si = math.cos(INCL), math.sin(INCL)
    x_node, y_90, normal = np.array([1.0, 0, 0]), np.array([0, ci, si]), np.array([0, -si, ci])
    s = math.cos(beta) * (math.cos(u_noon) * x_node + math.sin(u_noon) * y_90) + math.sin(beta) * normal

    def r_N(u):
        return R * (math.cos(u) * x_node + math.sin(u) * y_90)

    return r_N, s


def _bisect(f, lo, hi):
    flo = f(lo)
    while hi - lo > BISECT_S * N_RATE:
        mid = 0.5 * (lo + hi)
        if (f(mid) > 0) == (flo > 0):
            lo, flo = mid, f(mid)
        else:
            hi = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("beta", [0.0, 0.4, 1.0], ids=["beta0", "beta0.4", "beta1.0"])
def test_cylindrical_entry_exit(beta):
    u_noon = 0.3
    r_N, s = _geometry(beta, u_noon)
    half = math.acos(math.sqrt(1 - (R_E / R) ** 2) / math.cos(beta))  # from midnight, in u
    mid = u_noon + math.pi
    nu = lambda u: shadow_cylindrical(r_N(u), s) - 0.5  # noqa: E731
    entry = _bisect(nu, mid - half - 0.2, mid)
    exit_ = _bisect(nu, mid, mid + half + 0.2)
    assert_allclose([entry, exit_], [mid - half, mid + half], atol=2 * BISECT_S * N_RATE)


def test_no_eclipse_at_high_beta():
    r_N, s = _geometry(1.4)  # cos β < sqrt(1 - (R_E/R)²): the orbit never enters the shadow
    us = np.linspace(0, 2 * math.pi, 721)
    assert min(shadow_cylindrical(r_N(u), s) for u in us) == 1.0
    assert min(shadow_conical(r_N(u), s, AU) for u in us) == 1.0


def _c_minus_edge(r_N, s, sign):
    """c - (b + sign a) seen from the station, the test's own geometry."""
    def f(u):
        r = r_N(u)
        d = AU * s - r
        a = math.asin(R_SUN / np.linalg.norm(d))
        b = math.asin(R_E / np.linalg.norm(r))
        c = math.acos(float(-r @ d) / (np.linalg.norm(r) * np.linalg.norm(d)))
        return c - (b + sign * a)
    return f


def test_conical_umbra_and_penumbra_edges():
    u_noon = 0.3
    r_N, s = _geometry(0.2, u_noon)
    mid = u_noon + math.pi
    pen_in = _bisect(_c_minus_edge(r_N, s, +1), mid - 1.5, mid)
    umb_in = _bisect(_c_minus_edge(r_N, s, -1), mid - 1.5, mid)
    eps = 1e-5  # rad of u on either side of an edge (0.07 s)
    nu = lambda u: shadow_conical(r_N(u), s, AU)  # noqa: E731
    assert nu(pen_in - eps) == 1.0 and 0.99 < nu(pen_in + eps) < 1.0
    assert nu(umb_in + eps) == 0.0 and 0.0 < nu(umb_in - eps) < 0.01
    # penumbra: ν falls monotonically, and is one half where the sun's centre is on the limb
    us = np.linspace(pen_in, umb_in, 50)
    assert np.all(np.diff([nu(u) for u in us]) <= 0)
    limb = _bisect(_c_minus_edge(r_N, s, 0), mid - 1.5, mid)
    # a small disc cut by a large one: half, up to the limb's curvature (a/b ~ 0.4 %)
    assert abs(nu(limb) - 0.5) < 0.01
    # the penumbra lasts a few seconds at 400 km (2a over the rate of c)
    assert 5.0 < (umb_in - pen_in) / N_RATE < 30.0
