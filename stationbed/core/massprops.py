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
    "wing_pair_inertia",
    "largest_axis",
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


def wing_pair_inertia(mass: float, span: float, chord: float, offset: float, e_along, e_normal) -> np.ndarray:
    """Inertia about its mass centre of a wing pair: two uniform thin plates, one each side of it.

    Each wing (``mass / 2``) runs from ``offset`` to ``offset + span`` along ``±e_along`` and is
    ``chord`` wide along ``e_chord = e_normal × e_along``, centred on that axis; zero thickness
    along ``e_normal``. With ``x`` the distance along ``e_along``, ``<x²> = ((o + L)³ - o³) / (3 L)``:

    ``I_along = m b² / 12``, ``I_chord = m <x²>``, ``I_normal = I_along + I_chord`` (a thin
    plate: the triangle inequality met with equality). ``offset = 0`` is one plate ``2 L`` long:
    ``I_chord = m (2L)² / 12``.

    Parameters
    ----------
    mass : float  Both wings [kg].
    span : float  One wing, root to tip [m].
    chord : float  Its width [m].
    offset : float  From the mass centre (the gimbal axis) to each wing's root [m].
    e_along, e_normal : array_like, shape (3,)  Orthogonal unit vectors, the frame's components.

    Returns
    -------
    ndarray, shape (3, 3)  [kg m²], the frame of ``e_along`` (P axes for an array).
    """
    e_l, e_n = np.asarray(e_along, float), np.asarray(e_normal, float)
    e_c = np.cross(e_n, e_l)
    x2 = ((offset + span) ** 3 - offset**3) / (3.0 * span)
    I_l, I_c = mass * chord * chord / 12.0, mass * x2
    return I_l * np.outer(e_l, e_l) + I_c * np.outer(e_c, e_c) + (I_l + I_c) * np.outer(e_n, e_n)


def largest_axis(J) -> tuple[np.ndarray, float]:
    """The principal axis of the largest moment (a plate's normal) and how distinct it is.

    Returns
    -------
    axis : ndarray, shape (3,)  Unit vector (sign arbitrary), J's frame.
    margin : float  ``(I_max - I_mid) / I_max``: 0 when the two largest moments are equal (the
        axis is then any in their plane and names no face).
    """
    moments, vecs = np.linalg.eigh(np.asarray(J, float))
    return vecs[:, 2], float((moments[2] - moments[1]) / moments[2])
