"""Scene files (TOML, SI, radians) -> validated, frozen :class:`Scene` objects.

The schema is DESIGN §5. Parsing is ``tomllib``; validation is pydantic (``extra="forbid"``,
no NaN/inf). Every failure becomes a :class:`SceneError` whose message is one line naming the
file, the field path and the reason, with the nearest valid key suggested for typos.
"""

from .base import QUAT_NORM_TOL, SceneError
from .load import Scene, load_scene, scene_from_dict
from .tables import *  # noqa: F401,F403  (every table class, for callers and tests)
from .tables import __all__ as _tables

__all__ = ["Scene", "SceneError", "load_scene", "scene_from_dict", "QUAT_NORM_TOL", *_tables]
