"""Design plants for the shipped laws: the rigid station a controller knows from its
:class:`~stationbed.run.controller.Plant` facts, linearised by :func:`~.plant.linearization`
(the one linearisation in the project, on the simulator's own equations).

A controller knows the plant's inertia about O and the orbital rate; the rigid equivalent is a
scene of one body with that inertia on a circular orbit of that mean motion (gravity gradient
as the scene says), optionally with an ideal CMG cluster (the state ``h``; the steering law
delivers the torque command to the body, ``ḣ = -τ - ω × h``).
"""

from __future__ import annotations

import numpy as np

from ..core.constants import MU_EARTH_M3_S2
from ..scene import scene_from_dict
from .plant import Linearization, linearization

__all__ = ["rigid_scene", "design_linearization"]


def rigid_scene(inertia_O_B, mean_motion: float, *, gravity_gradient: bool = True, cmg: bool = False):
    """The rigid station of a controller's plant facts, as a :class:`~stationbed.scene.Scene`.

    Parameters
    ----------
    inertia_O_B : (3, 3)  Inertia about the composite mass centre, B axes [kg m²].
    mean_motion : float  Orbital rate n [rad/s] (the orbit radius is ``(μ/n²)^(1/3)``).
    gravity_gradient : bool
    cmg : bool  Add an ideal cluster without limits (its state is ``h`` [N m s]).
    """
    radius = (MU_EARTH_M3_S2 / float(mean_motion) ** 2) ** (1.0 / 3.0)
    d = {
        "name": "design_model",
        "simulation": {"duration": 1.0},
        "body": {"mass": 1.0, "inertia": np.asarray(inertia_O_B, float).tolist(), "cm": [0.0, 0.0, 0.0]},
        "orbit": {"radius": radius, "gravity_gradient": bool(gravity_gradient)},
    }
    if cmg:
        d["cmg"] = {"kind": "ideal"}
    return scene_from_dict(d)


def design_linearization(inertia_O_B, mean_motion: float, about="lvlh", *, q_ref=(1.0, 0.0, 0.0, 0.0),
                         gravity_gradient: bool = True, cmg: bool = False, trim: bool = True) -> Linearization:
    """:func:`~.plant.linearization` of :func:`rigid_scene` (states ``θ, δω`` and, with
    ``cmg``, ``h``; inputs: the body torque, then the disturbance torque)."""
    scene = rigid_scene(inertia_O_B, mean_motion, gravity_gradient=gravity_gradient, cmg=cmg)
    return linearization(scene, about, q_ref=q_ref, trim=trim)
