"""The station's static shape as drawn: equivalent boxes of the body and arrays, truss and mast.

A body of mass ``m`` and inertia ``I`` is drawn as the uniform box with the same mass and principal
moments (:func:`box_half_sizes`); the arrays' boxes sit at their mass centres, a truss box spans
the arrays and a mast joins it to the body. Everything is in B about the composite mass centre;
:attr:`StationGeometry.extent` ``L`` is the length every other drawing is scaled by.
"""

from __future__ import annotations

import itertools

import numpy as np

from ...core.massprops import composite_cm
from ...scene.docking import mass_centre_B

__all__ = ["MIN_BOX_FRACTION", "box_half_sizes", "StationGeometry"]

#: Thinnest box drawn, as a fraction of the box's largest side: a flat array (triangle
#: inequality met with equality, Iz = Ix + Iy) would otherwise have zero thickness.
MIN_BOX_FRACTION = 0.01
#: Truss thickness: this fraction of its longest side, at least ``TRUSS_MIN_THICKNESS_M``.
TRUSS_THICKNESS_FRACTION = 0.02
TRUSS_MIN_THICKNESS_M = 0.25


def box_half_sizes(mass: float, inertia) -> tuple[np.ndarray, np.ndarray]:
    """Uniform box with the same mass and principal moments.

    For a box of sides ``a, b, c`` along its principal axes ``Ix = m (b² + c²) / 12`` etc., so
    ``a² = 6 (Iy + Iz - Ix) / m`` (and cyclic).

    Parameters
    ----------
    mass : float
        [kg]
    inertia : array_like, shape (3, 3)
        About the mass centre, in the frame the box is drawn in [kg m²].

    Returns
    -------
    half_sizes : ndarray, shape (3,)
        Half side lengths along the principal axes [m], at least ``MIN_BOX_FRACTION`` of the
        largest.
    C_FA : ndarray, shape (3, 3)
        Columns are the principal axes in the frame F of ``inertia`` (a proper rotation, maps
        principal-axis components into F components).
    """
    moments, C_FA = np.linalg.eigh(np.asarray(inertia, dtype=float))
    if np.linalg.det(C_FA) < 0:
        C_FA[:, 2] *= -1.0
    Ix, Iy, Iz = moments
    sides_sq = 6.0 / mass * np.array([Iy + Iz - Ix, Ix + Iz - Iy, Ix + Iy - Iz])
    sides = np.sqrt(np.clip(sides_sq, 0.0, None))
    sides = np.maximum(sides, MIN_BOX_FRACTION * sides.max())
    return 0.5 * sides, C_FA


def _corners_extent(center, half_sizes, C_FA) -> float:
    """Largest distance [m] of a box's corners from the origin."""
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    return float(np.max(np.linalg.norm(center + (signs * half_sizes) @ C_FA.T, axis=1)))


class StationGeometry:
    """Static drawing of a scene in B, about the composite mass centre.

    Parameters
    ----------
    scene : stationbed.scene.Scene

    Attributes
    ----------
    r_cm_B : ndarray, shape (3,)
        Composite mass centre in the scene's body coordinates, B components [m]: of the body,
        the arrays and the vehicles docked as the scene starts (the drawing's origin).
    body_center : ndarray, shape (3,)
        Body mass centre relative to the composite one, B components [m].
    body_half : ndarray, shape (3,)
        Half sizes of the body's box along its principal axes [m].
    body_C : ndarray, shape (3, 3)
        Principal axes of the body (columns, B components): the box's rotation, box -> B.
    arrays : list of tuple
        Per appendage ``(name, r_P_B, half_sizes, C_PA)``: mass centre relative to the composite
        one (B components [m]), box half sizes [m] and box -> P rotation.
    truss : tuple or None
        ``(center, half_sizes)`` of the truss box (B axes) spanning the arrays' mass centres (body
        and array for a single array); None without arrays.
    mast : tuple or None
        ``(center, half_sizes, C)`` of the box from the body to the truss centre, when that centre
        lies outside the body's box.
    extent : float
        ``L`` [m]: the largest distance of any box corner from the composite mass centre.
    """

    def __init__(self, scene):
        body, apps = scene.body, scene.appendage
        masses = [body.mass] + [a.mass for a in apps]
        cms = [body.cm] + [a.cm for a in apps]
        # the configuration's as it starts, docked vehicles included (:func:`~...scene.docking.mass_centre_B`,
        # the point the station turns about); a scene without vehicles (or duck-typed) the same sum
        self.r_cm_B = mass_centre_B(scene) if getattr(scene, "vehicle", None) else composite_cm(masses, cms)
        self.body_center = np.asarray(body.cm, float) - self.r_cm_B
        self.body_half, self.body_C = box_half_sizes(body.mass, body.inertia)
        extent = _corners_extent(self.body_center, self.body_half, self.body_C)
        self.arrays = []  # (name, r_P_B about the composite CM, half sizes, C_PA)
        for a in apps:
            half, C_PA = box_half_sizes(a.mass, a.inertia_P)
            r = np.asarray(a.cm, float) - self.r_cm_B
            self.arrays.append((a.name, r, half, C_PA))
            extent = max(extent, float(np.linalg.norm(r)) + float(np.linalg.norm(half)))
        # truss: the box spanning the arrays' mass centres (or body -> single array)
        pts = [r for _, r, _, _ in self.arrays]
        if len(pts) == 1:
            pts.append(self.body_center)
        self.truss = None
        if len(pts) >= 2:
            pts = np.array(pts)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            thick = max(TRUSS_THICKNESS_FRACTION * float(np.max(hi - lo)), TRUSS_MIN_THICKNESS_M)
            self.truss = (0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 0.5 * thick))
        # mast: body centre -> truss centre, when the truss centre is outside the body box
        self.mast = None
        if self.truss is not None:
            d = self.truss[0] - self.body_center
            if np.any(np.abs(self.body_C.T @ d) > self.body_half):
                z = d / np.linalg.norm(d)
                x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
                x /= np.linalg.norm(x)
                C = np.column_stack([x, np.cross(z, x), z])
                self.mast = (self.body_center + 0.5 * d, np.array([0.5 * thick, 0.5 * thick, 0.5 * np.linalg.norm(d)]), C)
        self.extent = extent  # L [m]
