"""stationbed: a space-station attitude control test bed.

TP-2511 (Rheinfurth & Carroll 1985) rotational equations with articulated solar arrays, in
several independent forms that are checked against each other and against closed-form truths.
"""

from .scene import Scene, SceneError, load_scene
from .simulate import SimulationError, simulate
from .trajectory import Trajectory
from .formulations import FORMULATIONS
from .integrators import INTEGRATORS
from .batch import BatchResult, disperse_initial, simulate_batch
from .controller import Controller, ControllerParams

__all__ = [
    "BatchResult",
    "Controller",
    "ControllerParams",
    "disperse_initial",
    "simulate_batch",
    "FORMULATIONS",
    "INTEGRATORS",
    "Scene",
    "SceneError",
    "SimulationError",
    "Trajectory",
    "load_scene",
    "simulate",
]
__version__ = "0.1.0"
