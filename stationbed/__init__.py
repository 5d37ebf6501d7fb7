"""stationbed: a space-station attitude control test bed.

TP-2511 (Rheinfurth & Carroll 1985) rotational equations with articulated solar arrays, in
several independent forms that are checked against each other and against closed-form truths.

The names below are imported on first use (PEP 562), not by ``import stationbed``: the command
line must be able to start ``run --rrd``'s recording process before casadi, scipy and pydantic
are imported (stationbed/_rrd_child.py).
"""

import importlib as _importlib
import types as _types

_LAZY = {
    "Scene": "scene",
    "SceneError": "scene",
    "load_scene": "scene",
    "SimulationError": "simulate",
    "simulate": "simulate",
    "Trajectory": "trajectory",
    "FORMULATIONS": "formulations",
    "INTEGRATORS": "integrators",
    "BatchResult": "batch",
    "disperse_initial": "batch",
    "simulate_batch": "batch",
    "Controller": "controller",
    "ControllerParams": "controller",
}

__all__ = sorted(_LAZY)
__version__ = "0.1.0"


def __getattr__(name):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(_importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


class _Package(_types.ModuleType):
    """``stationbed.simulate`` stays the function when the submodule of the same name is
    imported (the import system then sets the package attribute to the module)."""

    def __setattr__(self, name, value):
        if name in _LAZY and isinstance(value, _types.ModuleType):
            return  # keep the lazily resolved function/class
        super().__setattr__(name, value)


import sys as _sys  # noqa: E402

_sys.modules[__name__].__class__ = _Package
