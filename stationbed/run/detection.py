"""Fault detection's delay (issue 20): when a failed CMG unit becomes known to the law.

``[knowledge] failure_detected_after_s = T``: the truth's failed units (``[cmg] failed``, failed
from t = 0) are unknown to the law until the first controller tick at or after T; at that tick
the loop hands the law the plant of :func:`~stationbed.scene.knowledge.detected_scene` through
:func:`replan`: ``law.plant`` becomes it and the law's ``_replan(plant)`` runs — a hook a law
may define (e.g. to keep an integrator or a schedule in progress); without it, ``_reset(plant)``
designs again on the new plant (``n_updates`` and ``q_ref_BN`` are kept either way). The per-tick loop does it (a law's ``symbolic`` form
holds the plant's numbers as constants of a compiled chunk, so the fused and lockstep executors
leave a run with a replan inside it to the per-tick loop; the numbers are the same).
"""

from __future__ import annotations

import math

__all__ = ["Replan", "replan", "replan_of"]


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
