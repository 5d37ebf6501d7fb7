"""Control-design analysis: linear plants of a scene (:mod:`.plant`), the design plants of
the shipped laws (:mod:`.design`), loop margins of a controller's symbolic form
(:mod:`.margins`), run dashboards and comparisons (:mod:`.dashboard`, :mod:`.compare`) and their
commands (:mod:`.cli`).

Layer: above ``run`` (the compiled system, the controller registry, trajectories), below the
shipped controllers (which design on it). Names are imported on first use (PEP 562), so the
command line can register its parsers without importing casadi.
"""

import importlib as _importlib

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


def __getattr__(name):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(_importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value
