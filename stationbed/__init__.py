"""stationbed: a space-station attitude control test bed.

TP-2511 (Rheinfurth & Carroll 1985) rotational equations with articulated solar arrays, in
several independent forms that are checked against each other and against closed-form truths.

The names below are imported on first use (PEP 562), not by ``import stationbed``: the command
line must be able to start ``run --rrd``'s recording process before casadi, scipy and pydantic
are imported (stationbed/output/rerun/child.py).
"""

from .core.lazy import lazy_names as _lazy_names

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
    "plan_scene": "plan",
    "PlanError": "plan",
    "montecarlo": "studies.montecarlo",
    "MonteCarloResult": "studies.montecarlo",
    # quaternion helpers a controller writer needs (q scalar first; dcm(q_BN) = C_BN)
    "dcm": "core.rotation",
    "quat_mult": "core.rotation",
    "quat_conj": "core.rotation",
}

__all__ = sorted(_LAZY)
__version__ = "0.1.0"


__getattr__, __dir__ = _lazy_names(__name__, _LAZY)
