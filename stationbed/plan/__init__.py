"""Planned slews (issue 26): the optimal attitude-command history between two attitudes, on the
scene's rotational model with its law inside the optimisation (the zero-propellant manoeuvre).

* :mod:`.model`: the rigid station, CMG momentum, gravity gradient and the ISS-style law;
* :mod:`.collocation`: Hermite-Simpson direct collocation on casadi Opti + IPOPT;
* :mod:`.scene_problem`: a scene's ``[plan]`` table -> :class:`~.collocation.Problem`;
* :mod:`.files`: plan.csv, plan.json, the chart, and reading a plan back (the ``schedule`` law).

Layer: above ``run`` (it takes the simulator's own inertia and plant facts through
:func:`stationbed.run.closed_loop.plant_facts`), beside ``analysis``, below ``controllers`` (the
``schedule`` law replays a plan, and plans one itself when given none).
"""

from .collocation import PlanError, Problem, Solution, solve
from .files import read_plan, write_plan
from .scene_problem import plan_scene, scene_problem

__all__ = ["PlanError", "Problem", "Solution", "solve", "plan_scene", "scene_problem", "read_plan", "write_plan"]
