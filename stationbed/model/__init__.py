"""The station model: what a scene's equations contain (:class:`Structure`), the parameter
layout, and the symbolic station quantities (:class:`StationModel`: inertia, arrays
(:class:`ArrayState`), modal coupling, CMG cluster (:mod:`.cmg`, one module per geometry),
external torques (:mod:`.torques`, one class per kind), environment). Imports only ``core`` and
``scene``."""

from .station import ArrayState, StationModel
from .structure import JOINTS, ParamLayout, Structure
from .torques import TORQUES, TorqueKind

__all__ = ["StationModel", "ArrayState", "Structure", "ParamLayout", "JOINTS", "TORQUES", "TorqueKind"]
