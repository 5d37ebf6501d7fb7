"""stationbed: a space-station attitude control test bed.

TP-2511 (Rheinfurth & Carroll 1985) rotational equations with articulated solar arrays, in
several independent forms that are checked against each other and against closed-form truths.

The names below are imported on first use (PEP 562), not by ``import stationbed``: the command
line must be able to start ``run --rrd``'s recording process before casadi, scipy and pydantic
are imported (stationbed/output/rerun/child.py).
"""

import importlib as _importlib

_LAZY = {
    "Scene": "scene",
    "SceneError": "scene",
    "load_scene": "scene",
    "SimulationError": "run.simulation",
    "simulate": "run.simulation",
    "Trajectory": "run.trajectory",
    "FORMULATIONS": "formulations",
    "INTEGRATORS": "integrators",
    "BatchResult": "run.batch",
    "disperse_initial": "run.batch",
    "simulate_batch": "run.batch",
    "Controller": "run.controller",
    "ControllerParams": "run.controller",
    "Measurement": "run.controller",
    "Plant": "run.controller",
    "linearize": "analysis.plant",
    "OperatingPoint": "analysis.plant",
    "loop_analysis": "analysis.margins",
    "montecarlo": "studies.montecarlo",
    "MonteCarloResult": "studies.montecarlo",
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
