"""Mass properties: parallel axis, composite mass centre, physical validity.

Inertia matrices follow DESIGN §3: diagonal = moments, off-diagonal = products of inertia
with the minus sign included (``I_xy = -∫ x y dm``), so ``H = I @ omega``.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = [
    "InvalidMassProperties",
    "check_inertia",
    "checked_inertia_rows",
    "parallel_axis",
    "composite_cm",
    "coriolis_matrix",
]

#: Relative rounding allowed when checking symmetry / triangle inequality.
#: Inertias typed in a scene file carry ~7 significant digits; 1e-9 of the largest moment
#: is far below that and far above float64 rounding (1e-16).
INERTIA_REL_TOL = 1e-9


class InvalidMassProperties(ValueError):
    """A mass or inertia that no physical body can have."""


def check_inertia(J: np.ndarray, what: str = "inertia") -> np.ndarray:
    """Validate an inertia matrix about a mass centre and return it as a symmetric (3,3) array.

    Raises :class:`InvalidMassProperties` naming ``what`` for: wrong shape, NaN/inf,
    asymmetry, a non-positive principal moment, or a violated triangle inequality
    ``I1 + I2 >= I3`` (a point cloud can only have moments that satisfy it).
    """
    J = np.asarray(J, dtype=float)
    if J.shape != (3, 3):
        raise InvalidMassProperties(f"{what}: must be a 3x3 matrix, got shape {J.shape}")
    if not np.all(np.isfinite(J)):
        raise InvalidMassProperties(f"{what}: contains NaN or inf")
    scale = np.max(np.abs(J))
    if scale == 0.0:
        raise InvalidMassProperties(f"{what}: is all zeros")
    if np.max(np.abs(J - J.T)) > INERTIA_REL_TOL * scale:
        raise InvalidMassProperties(f"{what}: not symmetric (J[i][j] != J[j][i])")
    J = 0.5 * (J + J.T)
    moments = np.linalg.eigvalsh(J)
    if moments[0] <= 0.0:
        raise InvalidMassProperties(
            f"{what}: not positive definite (principal moments {_fmt(moments)} kg m^2)"
        )
    if moments[0] + moments[1] < moments[2] * (1.0 - INERTIA_REL_TOL):
        raise InvalidMassProperties(
            f"{what}: principal moments {_fmt(moments)} kg m^2 violate the triangle inequality "
            "I1 + I2 >= I3"
        )
    return J


def checked_inertia_rows(J, what: str = "inertia") -> list[list[float]]:
    """``check_inertia(np.array(J), what).tolist()``: a scene's inertia (rows of numbers) checked,
    as new rows of floats; an inertia checked before (the same bits) is not decomposed again (a
    Monte Carlo sample's scene and its knowledge scene validate the same few matrices: issue 25).
    Raises as :func:`check_inertia`."""
    a = np.array(J)
    if a.dtype != np.float64 or a.shape != (3, 3):
        return check_inertia(a, what).tolist()
    return [list(row) for row in _checked(a.tobytes(), what)]


@functools.lru_cache(maxsize=256)
def _checked(key: bytes, what: str) -> tuple:
    J = np.frombuffer(key, dtype=np.float64).reshape(3, 3)
    return tuple(tuple(row) for row in check_inertia(J, what).tolist())


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"


def parallel_axis(mass: float, r: np.ndarray) -> np.ndarray:
    """Inertia of a point mass ``mass`` at ``r`` about the origin: ``m (|r|² E - r rᵀ)``."""
    r = np.asarray(r, dtype=float)
    return mass * (r @ r * np.eye(3) - np.outer(r, r))


def composite_cm(masses, cms) -> np.ndarray:
    """Mass centre of a set of bodies: ``Σ m_i r_i / Σ m_i``."""
    masses = np.asarray(masses, dtype=float)
    cms = np.asarray(cms, dtype=float).reshape(-1, 3)
    return masses @ cms / masses.sum()


def coriolis_matrix(I_p):
    """TP-2511 Eq. 42 Coriolis matrix ``C*_p = tr(I_p) E - 2 I_p`` (numpy or casadi).

    For a point cloud about its mass centre it equals ``2 Σ m l lᵀ`` (tested).
    """
    try:
        import casadi as ca

        if isinstance(I_p, (ca.SX, ca.MX, ca.DM)):
            return ca.trace(I_p) * ca.DM.eye(3) - 2 * I_p
    except ImportError:  # pragma: no cover
        pass
    return np.trace(I_p) * np.eye(3) - 2.0 * np.asarray(I_p)
