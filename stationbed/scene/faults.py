"""Scene tables of the scheduled faults (issue 34; applied by :mod:`stationbed.run.schedule`).

```toml
[[fault]]
name = "cmg2"            # optional: the Monte Carlo's key path fault.cmg2.t (else fault[0].t)
t = 1800.0               # s, on the control tick grid (k * [controller] period)
kind = "cmg_failed"      # a registered kind (FAULT_KINDS)
unit = 2                 # the target: a CMG unit number (as [cmg] failed), a thruster's name...
spin_down_s = 0.0        # the kind's own parameters (FaultKind.params)
# until = 2400.0         # s, a window: the fault clears at this tick (kinds with windowed = True)
# probability = 0.3      # a Monte Carlo sample draws the fault with this probability (a run: always)
# enabled = false        # kept but not applied (a Monte Carlo sample whose draw said "no")
```

A kind is one :class:`FaultKind` in :data:`FAULT_KINDS` (:func:`register_fault_kind`): what it
targets and its parameters, checked here at load with one-line errors (a misspelt kind, unit or
parameter gets the nearest valid one). What it does to the truth is its effect, registered by
the same name in the run layer (:mod:`stationbed.run.faults`; sensor kinds: their own file).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Callable

from pydantic import ConfigDict, Field, model_validator

from .base import COLUMN_STEM, FieldError, Strict


def _flown(scene):
    from .thrusters import flown_thrusters  # noqa: PLC0415 (scene/thrusters.py imports the scene's tables)

    return flown_thrusters(scene)

__all__ = ["Fault", "FaultKind", "FaultParam", "FAULT_KINDS", "register_fault_kind", "check_faults", "fault_tick",
           "TARGETS"]

#: a fault time within this fraction of the period (and 1e-9 s) of a tick is that tick
TICK_TOL_REL = 1e-9


@dataclass(frozen=True)
class FaultParam:
    """One number of a fault kind: its default (None: required) and its bounds (inclusive)."""

    default: float | None = None
    low: float = -math.inf
    high: float = math.inf
    doc: str = ""


def _cmg_units(scene) -> list:
    if scene.cmg is None:
        return []
    from .tables import CMG_KINDS  # noqa: PLC0415

    return list(range(1, scene.cmg.n_units + 1)) if CMG_KINDS[scene.cmg.kind].gimbals else []


#: target type -> the scene's valid units of that type (and what a message calls them)
TARGETS: dict[str, tuple[Callable, str]] = {
    "cmg": (_cmg_units, "a gimballed [cmg] unit number"),
    "thruster": (lambda scene: [t.name for t in _flown(scene)], "a [[thruster]] name (a vehicle's: <vehicle>_<name>)"),
    "gyro": (lambda scene: [s.name for s in scene.sensor if s.kind == "gyro"], "a gyro [[sensor]] name"),
    "star_tracker": (lambda scene: [s.name for s in scene.sensor if s.kind == "star_tracker"],
                     "a star_tracker [[sensor]] name"),
}


@dataclass(frozen=True)
class FaultKind:
    """A fault kind: ``name`` (the scene's ``kind``), its ``target`` (a key of :data:`TARGETS`),
    its parameters, whether it may clear (``windowed``: ``until`` allowed) and one line for
    ``stationbed list``."""

    name: str
    target: str
    params: dict[str, FaultParam] = field(default_factory=dict)
    windowed: bool = True
    doc: str = ""


#: kind -> its :class:`FaultKind` (the truth-side kinds here; sensor kinds register their own)
FAULT_KINDS: dict[str, FaultKind] = {}


def register_fault_kind(kind: FaultKind) -> FaultKind:
    """Add ``kind`` to :data:`FAULT_KINDS` (a name registered twice is an error)."""
    if kind.name in FAULT_KINDS:
        raise ValueError(f"fault kind {kind.name!r} is registered twice")
    if kind.target not in TARGETS:
        raise ValueError(f"fault kind {kind.name!r}: target {kind.target!r} is none of {sorted(TARGETS)}")
    FAULT_KINDS[kind.name] = kind
    return kind


for _k in (
    FaultKind("cmg_failed", "cmg", {"spin_down_s": FaultParam(0.0, 0.0, math.inf, "s, the rotor's time constant; 0: it stops at t")},
              windowed=False, doc="a CMG unit fails: its gimbals held, its rotor stopped or spinning down (momentum to the body)"),
    FaultKind("gimbal_stuck", "cmg", doc="a CMG unit's gimbals held at their angles at t (the rotor spins on)"),
    FaultKind("gimbal_rate_limit", "cmg", {"limit": FaultParam(None, 0.0, math.inf, "rad/s, the degraded limit")},
              doc="a CMG unit's gimbal rates clamped to a degraded limit (steering unaware)"),
    FaultKind("wheel_speed_drop", "cmg", {"fraction": FaultParam(None, 0.0, 1.0, "of the rotor's momentum lost")},
              windowed=False, doc="a CMG rotor's speed drops by a fraction (momentum to the body)"),
    FaultKind("thruster_stuck_off", "thruster", doc="a thruster never fires (its commands are lost)"),
    FaultKind("thruster_stuck_on", "thruster", doc="a thruster fires continuously (a leak; propellant counted)"),
):
    register_fault_kind(_k)


def _near(word, valid) -> str:
    hit = difflib.get_close_matches(str(word), [str(v) for v in valid], n=1)
    return f" (did you mean {hit[0]!r}?)" if hit else ""


class Fault(Strict):
    """``[[fault]]``: one scheduled fault (module docstring); its kind's parameters are extra keys."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False, strict=True)

    name: str | None = Field(default=None, pattern=f"^{COLUMN_STEM}$", max_length=40)
    t: float = Field(ge=0.0)
    until: float | None = None
    kind: str
    unit: int | str
    probability: float = Field(default=1.0, ge=0.0, le=1.0)
    enabled: bool = True  # false: kept in the scene (its key paths, its columns) but never applied

    @model_validator(mode="after")
    def _kind_and_params(self):
        kind = FAULT_KINDS.get(self.kind)
        if kind is None:
            raise FieldError("kind", f"unknown fault kind {self.kind!r}{_near(self.kind, FAULT_KINDS)}; "
                                     f"valid: {', '.join(sorted(FAULT_KINDS))}")
        for key, value in (self.model_extra or {}).items():
            spec = kind.params.get(key)
            if spec is None:
                valid = sorted(kind.params) or ["none"]
                raise FieldError(key, f"not a parameter of kind '{self.kind}'{_near(key, kind.params)}; its "
                                      f"parameters: {', '.join(valid)}")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise FieldError(key, f"must be a finite number, got {value!r}")
            if not spec.low <= value <= spec.high:
                raise FieldError(key, f"must be in [{spec.low:g}, {spec.high:g}] ({spec.doc}), got {value:g}")
        for key, spec in kind.params.items():
            if spec.default is None and key not in (self.model_extra or {}):
                raise FieldError(key, f"kind '{self.kind}' needs '{key}' ({spec.doc})")
        if self.until is not None:
            if not kind.windowed:
                raise FieldError("until", f"kind '{self.kind}' does not clear (no window)")
            if not self.until > self.t:
                raise FieldError("until", f"must be after t ({self.t:g} s), got {self.until:g}")
        return self

    def param(self, key: str) -> float:
        """The kind parameter ``key``: the scene's value, else its default."""
        extra = self.model_extra or {}
        return float(extra[key]) if key in extra else float(FAULT_KINDS[self.kind].params[key].default)

    @property
    def target(self) -> str:
        return FAULT_KINDS[self.kind].target


def fault_tick(t: float, period: float, where: str) -> int:
    """The control tick k with ``k * period == t`` (within :data:`TICK_TOL_REL`); FieldError at
    ``where`` naming the two nearest tick times when ``t`` is between ticks."""
    k = round(t / period)
    if abs(k * period - t) <= TICK_TOL_REL * max(period, abs(t), 1.0):
        return int(k)
    lo = math.floor(t / period)
    raise FieldError(where, f"{t:.12g} s is not on the control tick grid (period {period:g} s): "
                            f"the nearest ticks are {lo * period:.12g} s and {(lo + 1) * period:.12g} s")


def check_faults(scene) -> None:
    """Every ``[[fault]]`` names a unit of its target type, lies on the tick grid inside the run,
    and has a unique name (one-line FieldError naming ``fault[i].<key>``)."""
    if not scene.fault:
        return
    if scene.controller is None:
        raise FieldError("fault", "faults are applied by the closed loop: add a [controller] table")
    period, duration = scene.controller.period, scene.simulation.duration
    names = [f.name for f in scene.fault if f.name is not None]
    if len(set(names)) != len(names):
        raise FieldError("fault", f"names must be unique, repeated: {sorted({n for n in names if names.count(n) > 1})}")
    for i, f in enumerate(scene.fault):
        units, what = TARGETS[f.target]
        valid = units(scene)
        if f.unit not in valid or isinstance(f.unit, bool):
            have = ", ".join(str(v) for v in valid) if valid else "none in this scene"
            raise FieldError(f"fault[{i}].unit", f"{f.unit!r} is not {what}{_near(f.unit, valid)}; valid: {have}")
        for key in ("t", "until"):
            v = getattr(f, key)
            if v is not None:
                fault_tick(v, period, f"fault[{i}].{key}")
                if v > duration:
                    raise FieldError(f"fault[{i}].{key}", f"{v:g} s is after the run's end ({duration:g} s)")
