"""The scene's ``[[surface]]`` tables as drawn boxes (issue 24): the station as the scene defines it.

A box surface is drawn at its ``size`` and ``centre``. A plate (``area``, ``normal``) has no
outline in the scene, so it is drawn as a thin rectangle of its area normal to ``normal``: a
wing's plate (``appendage.wing``) as ``2 span`` by ``chord`` along its axes; on another
appendage with the aspect ratio of that appendage's equivalent box (the two sides of the box
most nearly in the plate's plane, so an array's wings keep their length to width), on the body
square. Body surfaces are in B about the composite mass centre (``centre - r_cm``); an
appendage's are in its P axes from its mass centre, so they are drawn under the array's entity
and turn with its ``C_BP``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["DrawnSurface", "drawn_surfaces", "PLATE_THICKNESS_FRACTION"]

#: A plate is drawn this thick, as a fraction of its shorter side (at least PLATE_MIN_THICKNESS_M):
#: thin enough to read as a sheet, thick enough to stay visible edge-on.
PLATE_THICKNESS_FRACTION = 0.01
PLATE_MIN_THICKNESS_M = 0.05


class DrawnSurface(NamedTuple):
    """One surface as a box in its entity's frame.

    Attributes
    ----------
    name : str
        The surface's ``name`` (``surface_<i>`` when it has none).
    on : str
        ``"body"`` or the appendage's name.
    center : ndarray, shape (3,)
        Box centre in the entity's frame [m] (B about the composite mass centre, or P from the
        appendage's mass centre).
    half_sizes : ndarray, shape (3,)
        Half edges along the box's axes [m].
    C : ndarray, shape (3, 3)
        Box axes -> entity frame (columns: the box's axes).
    plate : bool
        True for a plate (area, normal), False for a box.
    """

    name: str
    on: str
    center: np.ndarray
    half_sizes: np.ndarray
    C: np.ndarray
    plate: bool


def _plate_axes(n, box_half=None, box_C=None):
    """(u, v, n̂, aspect) for a plate of normal n: u along the equivalent box's axis most in the
    plane with the larger projected side, aspect = side along u / side along v (1 without a box)."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    if box_half is None:
        ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = ref - n * (ref @ n)
        u /= np.linalg.norm(u)
        return u, np.cross(n, u), n, 1.0
    # the box's axes projected into the plate's plane, weighted by their sides
    proj = [(box_C[:, i] - n * (box_C[:, i] @ n)) * box_half[i] for i in range(3)]
    i_u = int(np.argmax([np.linalg.norm(p) for p in proj]))
    u = proj[i_u] / np.linalg.norm(proj[i_u])
    v = np.cross(n, u)
    side_u = float(np.linalg.norm(proj[i_u]))
    side_v = max(abs(float(p @ v)) for p in proj)
    return u, v, n, side_u / side_v if side_v > 0 else 1.0


def drawn_surfaces(scene, geom) -> list[DrawnSurface]:
    """The scene's surfaces as boxes, in order of its ``[[surface]]`` tables (empty without any).

    Parameters
    ----------
    scene : stationbed.scene.Scene
    geom : StationGeometry
        Its composite mass centre and the appendages' equivalent boxes (plate aspect ratios).

    Returns
    -------
    list of DrawnSurface
    """
    boxes = {name: (half, C) for name, _, half, C in geom.arrays}
    wings = {a.name: a.wing for a in getattr(scene, "appendage", []) if getattr(a, "wing", None) is not None}
    out = []
    for i, s in enumerate(getattr(scene, "surfaces", None) or []):
        name = s.name or f"surface_{i}"
        centre = np.asarray(s.centre, float)
        if s.on == "body":
            centre = centre - geom.r_cm_B
        if s.size is not None:
            out.append(DrawnSurface(name, s.on, centre, 0.5 * np.asarray(s.size, float), np.eye(3), False))
            continue
        wing = wings.get(s.on) if s.name == f"{s.on}_wing" else None
        if wing is not None:  # a wing's plate: its own span and chord (two wings, area kept)
            u, v, n = wing.e_along(), wing.e_chord(), wing.e_normal()
            side_u, side_v = 2.0 * wing.span, wing.chord
        else:
            box = boxes.get(s.on) if s.on != "body" else None
            u, v, n, aspect = _plate_axes(s.normal, *(box or (None, None)))
            side_v = float(np.sqrt(s.area / aspect))
            side_u = aspect * side_v
        thick = max(PLATE_THICKNESS_FRACTION * min(side_u, side_v), PLATE_MIN_THICKNESS_M)
        out.append(DrawnSurface(name, s.on, centre, 0.5 * np.array([side_u, side_v, thick]),
                                np.column_stack([u, v, n]), True))
    return out
