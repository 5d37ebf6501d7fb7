"""What each ``[[fault]]`` kind does to the truth (issue 34): a :class:`~.schedule.Step` at the
fault's tick (and one at ``until`` that clears it), made by the kind's effect registered in
:data:`FAULT_EFFECTS` (the kind's scene side: :mod:`stationbed.scene.faults`).

Truth-side kinds (the CMG unit's numbers: :data:`~stationbed.model.cmg.base.UNIT_TAIL`):

* ``cmg_failed``: the unit's gimbals held (``rate_cap`` 0) and its rotor stopped at t
  (``spin_down_s = 0``: ``rotor`` 0) or spinning down with time constant ``spin_down_s`` = τ:
  a staircase of steps, one every :data:`SPIN_DOWN_STEPS_PER_TAU`-th of τ (at least a tick, on
  the tick grid), the rotor's momentum ``exp(-(t_j - t) / τ)`` of the nominal at each step t_j,
  0 from :data:`SPIN_DOWN_END_TAU` τ on. At every step the rotor's momentum lost goes to the
  body through the bearing: the system's angular momentum is kept (the state jumps). Flight
  software is not told: the steering law keeps the unit until it is (``[knowledge]``, FDIR).
* ``gimbal_stuck``: the unit's gimbals held at their angles at t (``rate_cap`` 0); its rotor
  spins on. ``gimbal_rate_limit``: its gimbal rates clamped to ``limit`` [rad/s] after the
  steering law (the cluster's own limit still applies). Both may clear (``until``).
* ``wheel_speed_drop``: the unit's rotor momentum drops to ``1 - fraction`` of the nominal at t
  (the state jumps, momentum kept).
* ``thruster_stuck_off``: the thruster's valve ignores its commands (``ok`` 0);
  ``thruster_stuck_on``: it fires the whole of every tick (``leak`` 1), its propellant counted
  in the ledger and its torque on the body. Both may clear.

Flight software never sees these numbers (the thrusters' mapping, the steering law and the
dump law are unchanged); what it learns is the FDIR's (issue 34 item 2).
"""

from __future__ import annotations

import math
from typing import Callable

from ..scene.faults import FAULT_KINDS, fault_tick
from .schedule import SOURCES, Step

__all__ = ["FAULT_EFFECTS", "register_fault_effect", "fault_steps", "held_units", "capacity_steps", "SPIN_DOWN_STEPS_PER_TAU",
           "SPIN_DOWN_END_TAU"]

#: a spinning-down rotor's staircase: steps per time constant (the rotor's momentum is exact at
#: each step; between steps it is held, so the body gets its momentum in 1/20 τ impulses)
SPIN_DOWN_STEPS_PER_TAU = 20
#: ... and the rotor stopped (0) from this many time constants on (exp(-7) = 9e-4 of it left)
SPIN_DOWN_END_TAU = 7.0

#: kind -> ``effect(fault, comp) -> (plant edits, block edits, jump)``, or a list of
#: ``(ticks after the fault's, plant edits, block edits, jump)`` for a staircase (module docstring)
FAULT_EFFECTS: dict[str, Callable] = {}


def register_fault_effect(kind: str):
    """Decorator: the effect of fault ``kind`` (registered in :data:`FAULT_KINDS` first)."""
    def deco(f):
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault effect {kind!r}: no such fault kind (register its FaultKind first)")
        FAULT_EFFECTS[kind] = f
        return f
    return deco


def held_units(scene, geo, columns) -> list:
    """The units whose gimbals a ``gimbal_stuck`` fault of the truth holds, for the working
    units' momentum (:class:`~.working_h.WorkingH` ``held_units``; ``geo`` the cluster's
    :class:`~stationbed.model.cmg.CmgGeometry`, None: no cluster): per fault ``(t, until, momentum(row))``, the
    unit's rotor momentum (B [N m s], the nominal rotor's: the fault leaves it spinning) at the
    row's gimbal angles, which from ``t`` are the angles it is held at. Like a unit failed from
    the start (``[cmg] failed``, ``held_momentum_B``), its momentum is then not the working
    units': ``max_h`` leaves it out. (``cmg_failed`` stops its rotor: nothing is left to hold.)"""
    stuck = [f for f in getattr(scene, "fault", None) or () if f.kind == "gimbal_stuck" and f.enabled]
    if geo is None or not stuck or not geo.gimballed:
        return []
    col = {c: i for i, c in enumerate(columns)}
    gi = [col[g] for g in geo.gimbal_names]
    cfg = scene.cmg

    def momentum(unit):
        return lambda row: geo.unit_momenta_B(cfg, row[gi])[unit - 1]

    return [(f.t, math.inf if f.until is None else f.until, momentum(f.unit)) for f in stuck]


#: the kinds after which (over their window) a unit is out of the working units: its gimbals held
OUT_KINDS = ("cmg_failed", "gimbal_stuck")


def capacity_steps(scene, geo) -> list:
    """The working units' capacity as the truth's CMG faults change it, for the working units'
    momentum (:class:`~.working_h.WorkingH` ``capacity_steps``; ``geo`` as :func:`held_units`): ``(t, capacity)`` [s, N m s] at each
    time the set of units out changes, in time order; ``capacity`` None where none is out (the
    capacity at the start). A unit is out over its fault's window when the fault holds its
    gimbals (``cmg_failed``, ``gimbal_stuck``): the capacity is then the cluster's with it
    failed as ``[cmg] failed`` states one (:func:`~stationbed.model.cmg.capacity`). Empty
    without such a fault."""
    out = [f for f in getattr(scene, "fault", None) or () if f.kind in OUT_KINDS and f.enabled]
    if geo is None or not out or not geo.gimballed:
        return []
    cfg = scene.cmg
    ends = [(f.t, math.inf if f.until is None else f.until, f.unit) for f in out]
    steps = []
    for t in sorted({e for a, b, _ in ends for e in (a, b) if math.isfinite(e)}):
        units = sorted({u for a, b, u in ends if a <= t < b} - set(cfg.failed))
        cap = geo.capacity(cfg.model_copy(update={"failed": sorted(set(cfg.failed) | set(units))})) if units else None
        if not steps or steps[-1][1] != cap:
            steps.append((t, cap))
    return steps


def _cmg(comp, unit: int, **values) -> dict:
    """p edits setting the CMG ``unit``'s per-unit numbers ``values`` (UNIT_TAIL names)."""
    model = comp.model
    g = model.cmg.geometry
    base = model.layout["cmg"].start
    return {base + g.unit_index(name, unit): float(v) for name, v in values.items()}


@register_fault_effect("cmg_failed")
def _cmg_failed(f, comp):
    tau = f.param("spin_down_s")
    if tau == 0.0:
        return _cmg(comp, f.unit, rate_cap=0.0, rotor=0.0), {}, True
    every = max(1, round(tau / SPIN_DOWN_STEPS_PER_TAU / comp.period))  # ticks between steps
    end = math.ceil(SPIN_DOWN_END_TAU * tau / comp.period)
    steps = [(0, _cmg(comp, f.unit, rate_cap=0.0), {}, False)]
    steps += [(j, _cmg(comp, f.unit, rotor=math.exp(-j * comp.period / tau)), {}, True) for j in range(every, end, every)]
    return steps + [(end, _cmg(comp, f.unit, rotor=0.0), {}, True)]


@register_fault_effect("gimbal_stuck")
def _gimbal_stuck(f, comp):
    return _cmg(comp, f.unit, rate_cap=0.0), {}, False


@register_fault_effect("gimbal_rate_limit")
def _gimbal_rate_limit(f, comp):
    return _cmg(comp, f.unit, rate_cap=f.param("limit")), {}, False


@register_fault_effect("wheel_speed_drop")
def _wheel_speed_drop(f, comp):
    return _cmg(comp, f.unit, rotor=1.0 - f.param("fraction")), {}, True


def _valve(comp, name: str, field: str, value: float) -> dict:
    th = next(a.cluster for a in comp.actuators if a.name == "thrusters")
    i = th.names.index(name)
    return {"thrusters": {th.param_layout.slice(field).start + i: value}}


@register_fault_effect("thruster_stuck_off")
def _thruster_stuck_off(f, comp):
    return {}, _valve(comp, f.unit, "ok", 0.0), False


@register_fault_effect("thruster_stuck_on")
def _thruster_stuck_on(f, comp):
    return {}, _valve(comp, f.unit, "leak", 1.0), False


def fault_steps(comp) -> list[Step]:
    """The steps of the scene's ``[[fault]]`` tables (a :data:`~.schedule.SOURCES` entry)."""
    steps = []
    period = comp.period
    for i, f in enumerate(comp.scene.fault):
        if not f.enabled:
            continue
        effect = FAULT_EFFECTS.get(f.kind)
        if effect is None:
            raise ValueError(f"fault[{i}].kind: '{f.kind}' has no effect registered (stationbed/run/faults.py)")
        out = effect(f, comp)
        info = {"fault": f.name if f.name is not None else i, "kind": f.kind, "unit": f.unit}
        label = f"fault[{i}] {f.kind} {f.unit}"
        k0 = fault_tick(f.t, period, f"fault[{i}].t")
        K = comp.ticks()
        parts = out if isinstance(out, list) else [(0, *out)]
        start = None
        for j, plant, blocks, jump in parts:  # (a staircase: its later steps within the run only)
            if k0 + j <= K:
                s = Step(k0 + j, label, plant, blocks, jump, info=info if j == 0 else dict(info, step=j))
                start = s if j == 0 else start
                steps.append(s)
        if f.until is not None:
            steps.append(Step(fault_tick(f.until, period, f"fault[{i}].until"), label + " clears", clears=start,
                              info=dict(info, clears=True)))
    return steps


SOURCES.append(fault_steps)
