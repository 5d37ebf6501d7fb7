"""Control-design analysis: linear plants of a scene (:mod:`.plant`), the design plants of
the shipped laws (:mod:`.design`), loop margins of a controller's symbolic form
(:mod:`.margins`), run dashboards and comparisons (:mod:`.dashboard`, :mod:`.compare`) and their
commands (:mod:`.cli`).

Layer: above ``run`` (the compiled system, the controller registry, trajectories), below the
shipped controllers (which design on it). Names are imported on first use (PEP 562), so the
command line can register its parsers without importing casadi.
"""

from ..core.lazy import lazy_names as _lazy_names

_LAZY = {
    "Linearization": "plant",
    "OperatingPoint": "plant",
    "linearization": "plant",
    "linearize": "plant",
    "tea_search": "plant",
    "LoopAnalysis": "margins",
    "loop_analysis": "margins",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = _lazy_names(__name__, _LAZY)
