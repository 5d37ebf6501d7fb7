"""The rigid ISS scenes several stability cases run: a torque-free tumble in deep space and a
gravity-gradient libration in a 400 km orbit."""

from __future__ import annotations

import math

from ...scene import MU_EARTH_M3_S2, Scene, scene_from_dict

__all__ = ["ISS_INERTIA_KG_M2", "ORBIT", "orbital_rate", "tumble_scene", "gravity_gradient_scene"]

#: ISS inertia (JEOD, with its products of inertia) [kg m²]
ISS_INERTIA_KG_M2 = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]
#: a circular orbit at 400 km, 51.6 deg inclination (radius [m], inclination [rad])
ORBIT = {"radius": 6778137.0, "inclination": 0.9006, "u0": 0.0, "gravity_gradient": True}


def orbital_rate() -> float:
    """Mean motion n of :data:`ORBIT` [rad/s] (one orbit: 2π/n, 92.6 min)."""
    return math.sqrt(MU_EARTH_M3_S2 / ORBIT["radius"] ** 3)


def tumble_scene(duration: float, output_dt: float) -> Scene:
    """A rigid ISS tumbling torque-free in deep space (|ω| = 1.4 mrad/s): T and H_N constant.

    Parameters
    ----------
    duration, output_dt : float
        [s].

    Returns
    -------
    Scene
    """
    return scene_from_dict({
        "name": "study_tumble",
        "simulation": {"duration": duration, "output_dt": output_dt},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [1.0e-3, -0.6e-3, 0.8e-3]},
        "body": {"mass": 4.0e5, "inertia": ISS_INERTIA_KG_M2, "cm": [0.0, 0.0, 0.0]},
    }, source="study tumble scene")


def gravity_gradient_scene(duration: float, output_dt: float) -> Scene:
    """A rigid ISS in :data:`ORBIT` with gravity gradient, 0.1 rad off LVLH: the Jacobi integral
    is constant (:func:`~stationbed.studies.probes.jacobi_integral`).

    Parameters
    ----------
    duration, output_dt : float
        [s].

    Returns
    -------
    Scene
    """
    return scene_from_dict({
        "name": "study_gravity_gradient",
        "simulation": {"duration": duration, "output_dt": output_dt},
        "initial": {"frame": "lvlh", "q_BN": [math.cos(0.05), math.sin(0.05), 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 4.0e5, "inertia": ISS_INERTIA_KG_M2, "cm": [0.0, 0.0, 0.0]},
        "orbit": dict(ORBIT),
    }, source="study gravity-gradient scene")
