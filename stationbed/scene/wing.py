"""A solar-array wing pair declared once (issue 32): its inertia, ``[[surface]]`` plate and bending
beams are derived from ``appendage.wing``; and the check that an explicit inertia and a plate on
the same appendage face the same way.

A wing pair is two uniform thin wings, one each side of the array's mass centre (its gimbal
axes), each ``span`` long along ``±along`` from ``offset`` out, ``chord`` wide, facing
``normal``. On the ISS the wings run along the beta-gimbal mast (P x, the BGA axis) and face P z,
the normal sun tracking points at the sun (stationbed/model/appendages.py); the chord lies along
P y (the truss, the SARJ axis, at alpha = 0).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from ..core.beam import axis_vector
from ..core.massprops import largest_axis, wing_pair_inertia
from .base import FieldError, Strict
from .environment import Surface

__all__ = ["AxisName", "Wing", "WingBending", "wing_surface", "wing_beam", "check_plate_faces",
           "PLATE_NORMAL_TOL_DEG", "PLATE_MOMENT_MARGIN", "PLATE_AREA_FRACTION"]

AxisName = Literal["x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z"]

#: An explicit inertia and a plate on the same appendage may differ by this much in where they face
#: [deg]: a rounded plate model, not a mistake (the drifted ISS scenes differed by 90 deg).
PLATE_NORMAL_TOL_DEG = 10.0
#: The inertia names a face only when its largest moment exceeds the middle one by this fraction
#: (a rod or a cube has no face); the drifted ISS inertia had 2 %.
PLATE_MOMENT_MARGIN = 0.01
#: Plates smaller than this fraction of the inertia's equivalent plate (``12 sqrt(I1 I2) / m``,
#: the two smaller moments) are parts of the appendage, a radiator say, and may face anywhere.
PLATE_AREA_FRACTION = 0.25


class Wing(Strict):
    """``appendage.wing``: the array as a wing pair (mass: the appendage's ``mass``).

    ``span`` [m] is one wing, root to tip (the pair is ``2 offset + 2 span`` tip to tip),
    ``chord`` [m] its width, ``offset`` [m] from the gimbal axis to each wing's root, ``along``
    the wings' axis and ``normal`` the sun-facing normal (P axis names). The plate is
    ``2 span chord`` [m²], ``two_sided`` by default; ``cd``, ``absorbed``, ``specular``,
    ``diffuse`` as in ``[[surface]]``."""

    span: float = Field(gt=0.0)
    chord: float = Field(gt=0.0)
    offset: float = Field(default=0.0, ge=0.0)
    along: AxisName = "x"
    normal: AxisName = "+z"
    two_sided: bool = True
    cd: float = Field(default=2.2, gt=0.0)
    absorbed: float | None = Field(default=None, ge=0.0, le=1.0)
    specular: float | None = Field(default=None, ge=0.0, le=1.0)
    diffuse: float | None = Field(default=None, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _axes(self):
        if self.along.lstrip("+-") == self.normal.lstrip("+-"):
            raise FieldError("normal", f"'{self.normal}' lies along the wings ('along' = '{self.along}'): "
                                       "give a perpendicular axis")
        self.plate()  # the optical fractions checked as a [[surface]]'s, naming them here
        return self

    @property
    def area(self) -> float:
        """Both wings [m²]."""
        return 2.0 * self.span * self.chord

    def e_along(self) -> np.ndarray:
        return np.abs(axis_vector(self.along))

    def e_normal(self) -> np.ndarray:
        return axis_vector(self.normal)

    def e_chord(self) -> np.ndarray:
        """``normal × along``: the chord's direction, P components."""
        return np.cross(self.e_normal(), self.e_along())

    def inertia_P(self, mass: float) -> np.ndarray:
        """The pair's inertia about its mass centre [kg m²], P axes (:func:`wing_pair_inertia`)."""
        return wing_pair_inertia(mass, self.span, self.chord, self.offset, self.e_along(), self.e_normal())

    def plate(self, on: str = "body", name: str = "") -> Surface:
        """The pair's ``[[surface]]`` plate on appendage ``on``."""
        keys = {k: getattr(self, k) for k in ("two_sided", "cd", "absorbed", "specular", "diffuse")}
        return Surface(name=name, on=on, area=self.area, normal=self.e_normal().tolist(), **keys)


class WingBending(Strict):
    """``appendage.mode.wing``: the mode is the bending of one wing of the appendage's ``wing``,
    a uniform cantilever from its root (:func:`wing_beam`): ``side`` ``"+"`` or ``"-"`` of
    ``along``, ``deflection`` ``"normal"`` (out of plane) or ``"chord"`` (in plane), mode
    number ``n``."""

    side: Literal["+", "-"]
    deflection: Literal["normal", "chord"]
    n: int = Field(default=1, ge=1, le=6)


def wing_surface(appendage) -> Surface:
    """The ``[[surface]]`` plate of an appendage's wing, named ``<appendage>_wing``."""
    return appendage.wing.plate(on=appendage.name, name=f"{appendage.name}_wing")


def wing_beam(wing: Wing, bending: WingBending, mass: float) -> dict:
    """The ``Beam`` keys of one wing's bending: ``span`` long from its root (``offset`` out along
    ``side along``), of half the pair's ``mass`` [kg]."""
    axis = wing.along.lstrip("+-")
    e_d = wing.e_normal() if bending.deflection == "normal" else wing.e_chord()
    deflection = "xyz"[int(np.argmax(np.abs(e_d)))]
    root = (wing.offset * (1.0 if bending.side == "+" else -1.0) * wing.e_along()).tolist()
    return {"length": wing.span, "root": root, "span": bending.side + axis, "deflection": deflection,
            "n": bending.n, "mass": 0.5 * mass}


def check_plate_faces(scene) -> None:
    """Each ``[[surface]]`` plate on an appendage agrees with its declaration (one-line FieldError).

    On a wing appendage no plate is allowed (the wing is its plate). On one with an explicit
    inertia that names a face (:data:`PLATE_MOMENT_MARGIN`), a plate of at least
    :data:`PLATE_AREA_FRACTION` of the inertia's equivalent plate must face along the axis of the
    largest moment within :data:`PLATE_NORMAL_TOL_DEG` (either side)."""
    apps = {a.name: a for a in scene.appendage}
    for i, s in enumerate(scene.surface):
        a = apps.get(s.on)
        if a is None or s.normal is None:
            continue
        if a.wing is not None:
            raise FieldError(f"surface[{i}].on", f"appendage '{a.name}' declares a wing, which is its plate: give the "
                                                 f"plate's coefficients in appendage.{a.name}.wing and remove this table")
        axis, margin = largest_axis(a.inertia)
        moments = np.linalg.eigvalsh(np.asarray(a.inertia, float))
        if margin < PLATE_MOMENT_MARGIN or s.area < PLATE_AREA_FRACTION * 12.0 * math.sqrt(moments[0] * moments[1]) / a.mass:
            continue
        n = np.asarray(s.normal, float) / np.linalg.norm(s.normal)
        angle = math.degrees(math.acos(min(abs(float(n @ axis)), 1.0)))
        if angle > PLATE_NORMAL_TOL_DEG:
            face = "[" + ", ".join(f"{x:.3g}" for x in axis * np.sign(axis[np.argmax(np.abs(axis))]) + 0.0) + "]"
            raise FieldError(f"surface[{i}].normal", f"faces {angle:.0f} deg away from appendage.{a.name}.inertia's plate "
                                                     f"normal (its largest moment's axis, P {face}; limit "
                                                     f"{PLATE_NORMAL_TOL_DEG:g} deg): declare the array once with "
                                                     f"appendage.{a.name}.wing, or turn one of them")
