"""Docking events as scheduled steps (issue 35; docs/docking.md, docs/design.md "Docking").

Each ``[[event]]`` is a :class:`~.schedule.Step` at its tick: the model's numbers ``p`` become
those of the configuration after it (:func:`~stationbed.scene.docking.configuration_changes`:
the scene with the vehicle docked or gone, its parameters by
:meth:`~stationbed.model.StationModel.params`: composite inertia about the new mass centre,
the vehicle's plates on or off) and the state jumps by the event's momentum
(:func:`~stationbed.model.docking.event_jump`, ``ΔH = K ω + c``). The compiled structure is the
same through it, so the run stays on its executor (fused, per tick, lockstep).

Knowledge: the law flies the configuration it was told of. ``update_after_s`` after an event
(the first tick at or after it) it is told the new one: a law with a ``symbolic`` form gets the
numbers it would design on the new plant (a copy of it designs, :func:`law_numbers_after`) as a
step of its block's numbers ("law"), on every executor; ``"never"`` leaves it on the old ones.

Actuators whose numbers depend on the mass properties (the thrusters: each one's torque
``(r_i - c) × F_i ĝ_i`` about the composite mass centre c, docked vehicles included) get the
truth's numbers of the new configuration in the event's step and flight software's (the
thrusters' mapping on the c it is told of) in the update's
(:meth:`~stationbed.loop.actuator.Actuator.configuration_numbers`), as steps of their block's numbers.
"""

from __future__ import annotations

import copy
import math

import casadi as ca
import numpy as np

from ..model.docking import event_jump, event_terms
from ..scene.docking import configuration_changes
from .detection import replan
from .schedule import SOURCES, Step

__all__ = ["configurations", "docking_steps", "event_tick", "update_tick", "law_numbers_after"]

#: the compiled kick of each (structure, formulation): ``kick(t, x, p_before, p_after, K, c)``
_KICKS: dict[tuple, ca.Function] = {}


def configurations(scene) -> list:
    """The scene's configurations: ``[scene, after event 0, after event 1, ...]`` (scenes whose
    vehicles sit where the events left them, with the events still to come)."""
    return [scene] + [scene.replace(configuration_changes(scene, n), source=f"event[{n - 1}]")
                      for n in range(1, len(scene.event) + 1)]


def event_tick(event, period: float) -> int:
    """The control tick of an event (its time is a whole number of periods: scene/docking.py)."""
    return int(round(event.t / period))


def update_tick(event, period: float) -> int | None:
    """The tick the law is told of the configuration after ``event``: the first at or after
    ``t + update_after_s`` (None: never)."""
    if event.update_after_s == "never":
        return None
    return event_tick(event, period) + max(0, math.ceil(event.update_after_s / period - 1e-9))


def _kick_function(form) -> ca.Function:
    key = (form.model.structure.key, type(form).__name__)
    f = _KICKS.get(key)
    if f is None:
        nx, npar = form.nx, form.model.layout.size
        t, x, pb, pa = ca.SX.sym("t"), ca.SX.sym("x", nx), ca.SX.sym("pb", npar), ca.SX.sym("pa", npar)
        K, c = ca.SX.sym("K", 3, 3), ca.SX.sym("c", 3)
        f = _KICKS[key] = ca.Function("dock_kick", [t, x, pb, pa, K, c], [event_jump(form, t, x, pb, pa, K, c)])
    return f


def _kick(form, K, c):
    f = _kick_function(form)
    K, c = ca.DM(np.asarray(K, float)), ca.DM(np.asarray(c, float))

    def kick(t, x, p_before, p_after):
        return np.array(f(t, x, p_before, p_after, K, c)).ravel()

    return kick


#: ``plant_facts(scene, system, period)`` (run/closed_loop.py registers it: it imports this module's
#: importers, so this module may not import it)
PLANT_FACTS: list = []


def law_numbers_after(ctrl, system, period: float, known_scene) -> np.ndarray | None:
    """The ``symbolic_params`` of the law ``ctrl`` once told ``known_scene`` (what flight
    software believes after a configuration update): a copy of the law designs on that plant
    (its ``_replan`` or ``_reset``, :func:`~.detection.replan`); None for a law without a
    ``symbolic`` form. ``ctrl`` itself is not changed."""
    if not callable(getattr(ctrl, "symbolic_params", None)):
        return None
    other = copy.copy(ctrl)
    other.__dict__ = {k: copy.deepcopy(v) for k, v in ctrl.__dict__.items() if k not in ("_law", "_batch_law")}
    replan(other, PLANT_FACTS[0](known_scene, system, period))
    return np.asarray([float(v) for v in other.symbolic_params()], float)


def _actuator_numbers(comp, truth=None, known=None) -> dict:
    """Block name -> {index: value}: the actuators' numbers of a configuration, the truth's
    from the scene ``truth`` or flight software's from ``known``
    (:meth:`~stationbed.loop.actuator.Actuator.configuration_numbers`; kinds with none left out)."""
    out = {}
    for a in comp.actuators:
        nums = a.cluster.configuration_numbers(truth=truth, known=known)
        if nums:
            out[a.name] = nums
    return out


def docking_steps(comp) -> list[Step]:
    """The steps of the scene's ``[[event]]`` tables (a :data:`~.schedule.SOURCES` entry)."""
    scene = comp.scene
    if not scene.event:
        return []
    form = comp.system.formulation
    model = form.model
    period = comp.period
    configs = configurations(scene)
    ps = [model.params(c) for c in configs]
    ticks = comp.ticks()
    steps = []
    for i, e in enumerate(scene.event):
        if e.done:  # (history: the scene is the configuration after it)
            continue
        k = event_tick(e, period)
        K, c = event_terms(configs[i], configs[i + 1], e)
        changed = np.nonzero(ps[i + 1] != ps[i])[0]
        plant = {int(j): float(ps[i + 1][j]) for j in changed}
        info = {"event": i, "kind": e.kind, "vehicle": e.vehicle, "port": e.port or configs[i].vehicle[
            [v.name for v in configs[i].vehicle].index(e.vehicle)].port}
        said = {k: v for a in comp.actuators for k, v in a.cluster.configuration_summary(configs[i + 1]).items()}
        truth = _actuator_numbers(comp, truth=configs[i + 1])  # e.g. the thrusters' arms about the new mass centre
        steps.append(Step(k, f"event[{i}] {e.kind} {e.vehicle}", plant, truth, False, info=dict(info, **said),
                          kick=_kick(form, K, c)))
        ku = update_tick(e, period)
        if ku is None or ku > ticks:
            continue
        from ..scene.knowledge import knowledge_scene  # noqa: PLC0415

        known = knowledge_scene(configs[i + 1])
        cp = law_numbers_after(comp.ctrl, comp.system, period, known)
        if cp is None:
            raise ValueError(f"event[{i}].update_after_s: controller '{comp.ctrl.name}' has no symbolic form, so it "
                             "cannot be told a new configuration mid-run; give update_after_s = \"never\"")
        try:  # (the thrusters' mapping on the c flight software is told of)
            told = {"law": dict(enumerate(cp.tolist())), **_actuator_numbers(comp, known=known)}
        except ValueError as err:
            raise ValueError(f"event[{i}].update_after_s: {err}") from None
        steps.append(Step(ku, f"event[{i}] update", {}, told, False, info=dict(info, update=True)))
    return steps


SOURCES.append(docking_steps)
