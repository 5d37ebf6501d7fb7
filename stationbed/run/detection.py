"""Fault detection's delay (issue 20): when a failed CMG unit becomes known to the law.

``[knowledge] failure_detected_after_s = T``: the truth's failed units (``[cmg] failed``, failed
from t = 0) are unknown to the law until the first controller tick at or after T; at that tick
the loop hands the law the plant of :func:`~stationbed.scene.knowledge.detected_scene` through
:func:`replan`: ``law.plant`` becomes it and the law's ``_replan(plant)`` runs — a hook a law
may define (e.g. to keep an integrator or a schedule in progress); without it, ``_reset(plant)``
designs again on the new plant (``n_updates`` and ``q_ref_BN`` are kept either way).

The detection is a scheduled step (run/schedule.py, :func:`detection_steps`): its tick cuts the
fused loop's chunk, and there the executor hands the law the state it carried, calls the
redesign in Python (:meth:`Step.redesign <.schedule.Step>`) and writes the law's new
``symbolic_params`` and state into the compiled loop's numbers and carry (the law's numbers are
parameters of the composed tick, never constants). The per-tick loop calls the law itself and
lets it design again at that tick (``ControlLoop.redesign``); the numbers are the same.
"""

from __future__ import annotations

import math

import numpy as np

from .schedule import SOURCES, Step

__all__ = ["Replan", "replan", "replan_of", "detection_steps"]


def replan(law, plant) -> None:
    """Tell ``law`` (a :class:`~.controller.Controller`) the plant flight software now believes:
    its ``_replan(plant)`` when it has one, else its ``_reset(plant)``."""
    law.plant = plant
    getattr(law, "_replan", law._reset)(plant)


class Replan:
    """The tick at which the law is told of the failure, and the plant it is then told."""

    def __init__(self, tick: int, scene, system, period: float, plant_facts):
        self.tick = tick
        self._args = (scene, system, period, plant_facts)

    def plant(self):
        """The plant the law designs on after the detection (built when needed)."""
        from ..scene.knowledge import detected_scene  # noqa: PLC0415 - the scene layer, below this one

        scene, system, period, plant_facts = self._args
        return plant_facts(scene, system, period, known=detected_scene(scene))


def replan_of(scene, system, period: float, duration: float, plant_facts) -> Replan | None:
    """The run's :class:`Replan`, or None: no ``failure_detected_after_s``, no failed unit the law
    does not already know of, or a detection at or after the run's last tick."""
    k = scene.knowledge
    if k is None or k.failure_detected_after_s is None or scene.cmg is None:
        return None
    from ..scene.knowledge import knowledge_changes  # noqa: PLC0415

    believed = set(knowledge_changes(scene).get("cmg.failed", []))
    if set(scene.cmg.failed) <= believed:
        return None
    tick = max(0, math.ceil(k.failure_detected_after_s / period - 1e-9))
    if tick * period >= duration:
        return None
    return Replan(tick, scene, system, period, plant_facts)


def detection_steps(comp) -> list[Step]:
    """The run's detection as a scheduled step (a :data:`~.schedule.SOURCES` entry): at the
    detection tick the law designs again (``Step.redesign``) on the plant of :class:`Replan`;
    none without one. ControllerFailure at the tick's time naming the law's hook if it raises
    (the per-tick loop's message)."""
    r = comp.replan
    if r is None:
        return []

    def redesign(t: float, s) -> tuple[np.ndarray, np.ndarray]:
        from . import law_state  # noqa: PLC0415 (its peers import this module)
        from .controller_error import replan_failure  # noqa: PLC0415

        ctrl = comp.ctrl
        try:
            law_state.hand_back(ctrl, s)
            replan(ctrl, r.plant())
        except Exception as e:
            raise replan_failure(ctrl, t, e) from e
        return np.asarray([float(v) for v in ctrl.symbolic_params()], float), law_state.initial(ctrl)

    return [Step(r.tick, "failure detected", info={"step": "detection"}, redesign=redesign)]


SOURCES.append(detection_steps)
