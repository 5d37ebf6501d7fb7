"""Scene files (TOML, SI, radians) -> validated, frozen :class:`Scene` objects.

The schema is DESIGN §5. Parsing is ``tomllib``; validation is pydantic in strict mode
(``extra="forbid"``, no NaN/inf, no ``true`` or ``"100"`` for a number). Every failure becomes a
:class:`SceneError` whose message is one line naming the file, the field path and the reason
(with what was given, and the nearest valid key for typos). :meth:`Scene.replace` changes
values at key paths (the command line's ``--set``, read by :func:`parse_assignment`) and
validates the result the same way.
"""

from .assign import parse_assignment, parse_assignments
from .base import ATOL_MIN, MIN_TIME_S, QUAT_NORM_TOL, RTOL_MIN, TIME_RESOLUTION, SceneError
from .docking import Event, Port, Vehicle, configuration_changes, docked_at
from .knowledge import Knowledge, KnowledgeCmg, knowledge_scene
from .load import Scene, load_scene, scene_from_dict, sensing_from_dict
from .plan import PLAN_OBJECTIVES, PlanSpec
from .sensors import GyroSensor, MekfEstimator, Sensing, StarTrackerSensor
from .tables import *  # noqa: F401,F403  (every table class, for callers and tests)
from .tables import __all__ as _tables

__all__ = [
    "Scene", "SceneError", "load_scene", "scene_from_dict", "parse_assignment", "parse_assignments",
    "GyroSensor", "StarTrackerSensor", "MekfEstimator", "Sensing", "sensing_from_dict",
    "Knowledge", "KnowledgeCmg", "knowledge_scene", "PlanSpec", "PLAN_OBJECTIVES", "QUAT_NORM_TOL", "RTOL_MIN", "ATOL_MIN", "MIN_TIME_S", "TIME_RESOLUTION",
    "Port", "Vehicle", "Event", "configuration_changes", "docked_at", *_tables,
]
