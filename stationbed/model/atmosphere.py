"""Atmospheric density for the aerodynamic torque.

The embedded model is the exponential atmosphere of Vallado, *Fundamentals of Astrodynamics and
Applications*, 4th ed. (2013), Table 8-4 (after the CIRA-72 / US Standard 1976 values): in each
altitude band ``h0 <= h < h1``, ``ρ = ρ0 exp(-(h - h0)/H)``. Altitude is over a spherical Earth
of the WGS-84 equatorial radius, ``h = |r_N| - R_E`` (at 51.6 deg latitude the ellipsoid is
~14 km lower: the density read here is then ~20 % low at 400 km; ``density_scale`` covers it).
It is a static mean atmosphere: no solar-activity, day/night or seasonal variation. The scale
heights are the table's own log-slopes between band bases (:func:`continuous_scale_heights`), so
the density is continuous across band edges.

``[atmosphere] model = "msis"`` needs the optional ``pymsis`` package (``pip install
stationbed[msis]``): its NRLMSIS 2.0 densities at the epoch, F10.7 and Ap replace the table's
band values (per band: MSIS's cos-latitude-weighted mean over a latitude/longitude grid at the
band's base, and the log-slope to the next base), so the compiled code is the same.

All symbolic helpers take casadi; the numeric ones numpy.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.constants import R_EARTH_M

__all__ = ["EXPONENTIAL_TABLE", "OMEGA_EARTH_RAD_S", "band_table", "continuous_scale_heights", "density",
           "density_symbolic", "msis_table"]

#: Earth's rotation rate [rad/s] (IERS Conventions 2010, nominal)
OMEGA_EARTH_RAD_S = 7.292115e-5

#: Vallado (2013) Table 8-4: base altitude h0 [km], nominal density ρ0 [kg/m³], scale height H [km]
EXPONENTIAL_TABLE = np.array([
    [0, 1.225, 7.249], [25, 3.899e-2, 6.349], [30, 1.774e-2, 6.682], [40, 3.972e-3, 7.554],
    [50, 1.057e-3, 8.382], [60, 3.206e-4, 7.714], [70, 8.770e-5, 6.549], [80, 1.905e-5, 5.799],
    [90, 3.396e-6, 5.382], [100, 5.297e-7, 5.877], [110, 9.661e-8, 7.263], [120, 2.438e-8, 9.473],
    [130, 8.484e-9, 12.636], [140, 3.845e-9, 16.149], [150, 2.070e-9, 22.523], [180, 5.464e-10, 29.740],
    [200, 2.789e-10, 37.105], [250, 7.248e-11, 45.546], [300, 2.418e-11, 53.628], [350, 9.518e-12, 53.298],
    [400, 3.725e-12, 58.515], [450, 1.585e-12, 60.828], [500, 6.967e-13, 63.822], [600, 1.454e-13, 71.835],
    [700, 3.614e-14, 88.667], [800, 1.170e-14, 124.64], [900, 5.245e-15, 181.05], [1000, 3.019e-15, 268.00],
])
N_BANDS = len(EXPONENTIAL_TABLE)


def continuous_scale_heights(table=EXPONENTIAL_TABLE) -> np.ndarray:
    """Scale heights [km] that make the model continuous: in each band the log-slope between its
    base density and the next band's (the last band keeps its tabulated H).

    Vallado's scale heights are these slopes rounded to the table's digits (they differ by at most
    0.05 % of H; the density at a band's top by at most 0.14 %, in the 0-25 km band, and 0.002 %
    above 25 km). Continuity matters: a circular orbit exactly on a band's base (400 km) would
    otherwise see the density jump with the round-off of ``|r_N|``, which an adaptive integrator
    at rtol 1e-9 pays for with ~25 x more steps.
    """
    h, rho = table[:, 0], table[:, 1]
    H = table[:, 2].astype(float).copy()
    H[:-1] = np.diff(h) / np.log(rho[:-1] / rho[1:])
    return H


def band_table(table=EXPONENTIAL_TABLE) -> np.ndarray:
    """The table as the compiled code reads it, flattened, shape (3 N,).

    In band k, ``ln ρ = c0_k + c1_k h`` with ``c0_k = ln ρ0 + h0/H``, ``c1_k = -1/H`` (H from
    :func:`continuous_scale_heights`); stored as ``(h0_k [m], c0_k - c0_{k-1}, c1_k - c1_{k-1})``
    (the first band absolute), so that the code sums one step per band crossed (``h >= h0_k``):
    5 operations a band, one exp in all.
    """
    h0 = table[:, 0] * 1e3
    H = continuous_scale_heights(table) * 1e3
    c0, c1 = np.log(table[:, 1]) + h0 / H, -1.0 / H
    return np.column_stack([h0, np.diff(c0, prepend=0.0), np.diff(c1, prepend=0.0)]).ravel()


def density(h_m, table=EXPONENTIAL_TABLE):
    """Density of the model [kg/m³] at altitude ``h_m`` [m] (numpy; below 0 km the first band,
    above 1000 km the last), with the continuous scale heights."""
    h_m = np.asarray(h_m, dtype=float)
    i = np.clip(np.searchsorted(table[:, 0] * 1e3, h_m, side="right") - 1, 0, len(table) - 1)
    H = continuous_scale_heights(table)
    return table[i, 1] * np.exp(-(h_m - table[i, 0] * 1e3) / (H[i] * 1e3))


def density_symbolic(r_N, bands, scale):
    """Density [kg/m³] at ``r_N`` (casadi): the band holding ``h = |r_N| - R_E``.

    Parameters
    ----------
    r_N : casadi SX, shape (3, 1)  Position from the Earth's centre [m].
    bands : casadi SX, shape (3 N,)  :func:`band_table`.
    scale : casadi SX  ``density_scale`` (dimensionless).
    """
    h = ca.norm_2(r_N) - R_EARTH_M
    c0, c1 = bands[1], bands[2]
    for k in range(1, bands.numel() // 3):
        above = h >= bands[3 * k]
        c0 = c0 + above * bands[3 * k + 1]
        c1 = c1 + above * bands[3 * k + 2]
    return scale * ca.exp(c0 + c1 * h)


def msis_table(epoch: str, f107: float, f107a: float, ap: float) -> np.ndarray:
    """The exponential table refitted to NRLMSIS 2.0 (``pymsis``) at the epoch and space weather.

    Each band's ρ0 is MSIS's global mean density at h0 and its scale height the log-slope to the
    next band's h0 (the last band keeps the table's H). Raises ValueError when pymsis is missing.
    """
    try:
        import pymsis  # optional extra: stationbed[msis]
    except ImportError:
        raise ValueError("atmosphere.model: 'msis' needs the optional package pymsis (pip install 'stationbed[msis]')") from None
    lats, lons = np.linspace(-80.0, 80.0, 9), np.linspace(0.0, 330.0, 12)
    alts = EXPONENTIAL_TABLE[:, 0]
    date = np.datetime64(epoch.replace("Z", ""))
    rho = np.empty(len(alts))
    for k, h in enumerate(alts):
        out = pymsis.calculate(date, lons[None, :], lats[:, None], h, f107s=[f107], f107as=[f107a], aps=[[ap] * 7])
        w = np.cos(np.radians(lats))[:, None] * np.ones((1, len(lons)))
        rho[k] = float(np.sum(np.squeeze(out)[..., pymsis.Variable.MASS_DENSITY] * w) / np.sum(w))
    table = EXPONENTIAL_TABLE.copy()
    table[:, 1] = rho
    table[:-1, 2] = np.diff(alts) / np.log(rho[:-1] / rho[1:])
    if not np.all(np.isfinite(table)) or np.any(table[:, 2] <= 0):
        raise ValueError("atmosphere.model: pymsis returned densities that do not fall with altitude")
    return table

