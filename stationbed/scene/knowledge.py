"""``[knowledge]``: what flight software believes of the plant, apart from the truth being flown
(docs/design.md "Knowledge is not truth").

A controller designs on a :class:`~stationbed.run.controller.Plant` built from the *knowledge
scene* (:func:`knowledge_scene`): the scene with what flight software believes substituted, in
this order:

1. ``cmg.failed = []``: a failed CMG unit is unknown to the law unless the scene says so;
2. ``[knowledge.values]``: any key path -> value (the Monte Carlo writes here the nominal value
   of every dispersion not marked ``known``, and the drawn value of those that are);
3. the named keys: ``inertia``, ``mass``, ``cm`` (the ``[body]``'s), ``failed_units`` (->
   ``cmg.failed``), ``[knowledge.cmg]`` (the cluster's limits) and ``[knowledge.orbit]`` (a whole
   orbit table).

The knowledge scene has no ``[knowledge]`` and no ``[montecarlo]`` table, and it is a new
object built from values: nothing in it refers to the scene being flown.
"""

from __future__ import annotations

import copy
import weakref
from typing import Any

from pydantic import Field, field_validator

from ..core.massprops import InvalidMassProperties, checked_inertia_rows
from .base import Mat3, Strict, Vec3
from .environment import Orbit

__all__ = ["Knowledge", "KnowledgeCmg", "knowledge_scene", "knowledge_changes", "detected_scene", "NAMED_PATHS"]


class KnowledgeCmg(Strict):
    """``[knowledge.cmg]``: the cluster's limits as flight software believes them (each replaces
    the ``[cmg]`` key of the same name; capacity follows from them and the working units)."""

    h_rotor: float | None = Field(default=None, gt=0.0)  # N m s per unit
    max_momentum: float | None = Field(default=None, gt=0.0)  # N m s (ideal)
    max_torque: float | None = Field(default=None, gt=0.0)  # N m (ideal)
    max_gimbal_rate: float | None = Field(default=None, gt=0.0)  # rad/s


class Knowledge(Strict):
    """``[knowledge]``: what flight software believes (each key defaults to the scene's own value,
    except ``failed_units``: no failure is known unless listed)."""

    inertia: Mat3 | None = None  # kg m², the main body's about its own mass centre (as [body] inertia)
    mass: float | None = Field(default=None, gt=0.0)  # kg, the main body's
    cm: Vec3 | None = None  # m, the main body's mass centre in B
    failed_units: list[int] | None = None  # CMG units known to have failed (1-based, as [cmg] failed)
    cmg: KnowledgeCmg | None = None
    orbit: Orbit | None = None  # the orbit flight software believes (a whole [orbit] table)
    values: dict[str, Any] = {}  # any other key path -> believed value (the Monte Carlo writes here)
    #: s: the truth's failed CMG units ([cmg] failed, failed from t = 0) become known to the law at
    #: this time (fault detection, isolation and recovery's delay); None: never (unless listed above)
    failure_detected_after_s: float | None = Field(default=None, ge=0.0)

    @field_validator("inertia")
    @classmethod
    def _physical(cls, J):
        if J is None:
            return J
        try:
            return checked_inertia_rows(J, "inertia")
        except InvalidMassProperties as e:
            raise ValueError(str(e).removeprefix("inertia: ")) from None


#: the scene key path each named ``[knowledge]`` key stands for (a ``known`` dispersion of one of
#: these is refused when the key is given: the scene would state two beliefs)
NAMED_PATHS = {"inertia": "body.inertia", "mass": "body.mass", "cm": "body.cm", "failed_units": "cmg.failed",
               "cmg": "cmg", "orbit": "orbit"}


def knowledge_changes(scene) -> dict:
    """The key path -> value changes that turn ``scene`` into its knowledge scene (in order)."""
    k = scene.knowledge
    changes: dict = {"knowledge": None, "montecarlo": None}
    if scene.cmg is not None and scene.cmg.failed:
        changes["cmg.failed"] = []
    if k is None:
        return changes
    changes.update(k.values)
    for name in ("inertia", "mass", "cm"):
        v = getattr(k, name)
        if v is not None:
            changes[f"body.{name}"] = v
    if k.failed_units is not None:
        changes["cmg.failed"] = list(k.failed_units)
    if k.cmg is not None:
        for name, v in k.cmg.model_dump(exclude_none=True).items():
            changes[f"cmg.{name}"] = v
    if k.orbit is not None:
        changes["orbit"] = k.orbit.model_dump(exclude_unset=True)
    return changes


def detected_scene(scene):
    """What flight software believes once the failure is detected
    (``[knowledge] failure_detected_after_s``): the knowledge scene with every truly failed CMG
    unit known (those it already believed failed stay so)."""
    changes = knowledge_changes(scene)
    truth = list(scene.cmg.failed) if scene.cmg is not None else []
    changes["cmg.failed"] = sorted(set(changes.get("cmg.failed", truth)) | set(truth))
    return copy.deepcopy(scene.replace(changes, source="[knowledge]"))


#: the knowledge scene of every scene asked about and still alive: id -> (weak reference to the
#: scene, its knowledge scene). A Monte Carlo sample asks three times (the scene's own check, its
#: draw's record of what the law was told, the controller's plant), and a chunk draws all its
#: samples before it runs the first: scenes are frozen, so one answer per scene, kept as long as
#: the scene lives (an entry leaves with its scene: no limit to evict a scene still to be run)
_KNOWN: dict[int, tuple] = {}


def knowledge_scene(scene):
    """What flight software believes: ``scene`` (a :class:`~stationbed.scene.Scene`) with the
    ``[knowledge]`` substitutions of this module's docstring; raises SceneError naming
    ``[knowledge]`` when that scene is refused (e.g. ``failed_units`` beyond the cluster).
    The same scene object gets the same (frozen) knowledge scene back.

    Nothing of ``scene`` is reachable from the answer: :meth:`Scene.replace` validates new
    tables from the scene's values (dumped to plain dicts and lists), and a table left at its
    default is made anew for each scene (``default_factory``), not one object shared by every
    scene built (which is why an earlier version deep-copied the answer, ~0.3 ms a sample)."""
    key = id(scene)
    hit = _KNOWN.get(key)
    if hit is not None and hit[0]() is scene:
        return hit[1]
    known = scene.replace(knowledge_changes(scene), source="[knowledge]")
    _KNOWN[key] = (weakref.ref(scene), known)
    weakref.finalize(scene, _forget, key, _KNOWN[key]).atexit = False  # (nothing to drop at exit)
    return known


def _forget(key: int, entry: tuple) -> None:
    """Drop the entry of a scene that is gone (unless its id was taken since by a new entry)."""
    if _KNOWN.get(key) is entry:
        del _KNOWN[key]
