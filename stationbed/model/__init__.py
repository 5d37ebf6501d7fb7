"""The station model: what a scene's equations contain (:class:`Structure`), the parameter
layout, and the symbolic station quantities (:class:`StationModel`: inertia, arrays, modal
coupling, CMG cluster, external torques, environment). Imports only ``core`` and ``scene``."""

from .station import StationModel
from .structure import JOINTS, ParamLayout, Structure

__all__ = ["StationModel", "Structure", "ParamLayout", "JOINTS"]
