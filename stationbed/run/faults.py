"""What each ``[[fault]]`` kind does to the truth (issue 34): a :class:`~.schedule.Step` at the
fault's tick (and one at ``until`` that clears it), made by the kind's effect registered in
:data:`FAULT_EFFECTS` (the kind's scene side: :mod:`stationbed.scene.faults`).

Truth-side kinds (the CMG unit's numbers: :data:`~stationbed.model.cmg.base.UNIT_TAIL`):

* ``cmg_failed``: the unit's gimbals held (``rate_cap`` 0) and its rotor stopped at t
  (``spin_down_s = 0``: ``rotor`` 0) or spinning down with time constant ``spin_down_s`` = τ:
  a staircase of steps, one every :data:`SPIN_DOWN_STEPS_PER_TAU`-th of τ (at least a tick, on
  the tick grid), the rotor's momentum ``exp(-(t_j - t) / τ)`` of what it had at t at each step t_j,
  0 from :data:`SPIN_DOWN_END_TAU` τ on. At every step the rotor's momentum lost goes to the
  body through the bearing: the system's angular momentum is kept (the state jumps). Flight
  software is not told: the steering law keeps the unit until it is (``[knowledge]``, FDIR).
* ``gimbal_stuck``: the unit's gimbals held at their angles at t (``rate_cap`` 0); its rotor
  spins on. ``gimbal_rate_limit``: its gimbal rates clamped to ``limit`` [rad/s] after the
  steering law (the cluster's own limit still applies). Both may clear (``until``).
* ``wheel_speed_drop``: the unit's rotor loses ``fraction`` of its momentum at t (of the nominal
  unless an earlier drop slowed it; the state jumps, momentum kept).
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

#: the kinds after which (over their window) a unit is out of the working units: its gimbals held
OUT_KINDS = ("cmg_failed", "gimbal_stuck")
#: the kinds that set a unit's rotor momentum (each on what the rotor has at its time)
ROTOR_KINDS = ("wheel_speed_drop", "cmg_failed")

__all__ = ["FAULT_EFFECTS", "register_fault_effect", "fault_steps", "held_units", "capacity_steps", "rotor_changes", "spin_down_staircase", "SPIN_DOWN_STEPS_PER_TAU",
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


def spin_down_staircase(tau: float, period: float) -> list:
    """A ``cmg_failed`` rotor's spin-down with time constant ``tau`` [s] on a control ``period``
    [s]: ``(ticks after the fault, rotor fraction of h_rotor)`` at each step after the first
    (module docstring), the last one 0."""
    every = max(1, round(tau / SPIN_DOWN_STEPS_PER_TAU / period))  # ticks between steps
    end = math.ceil(SPIN_DOWN_END_TAU * tau / period)
    return [(j, math.exp(-j * period / tau)) for j in range(every, end, every)] + [(end, 0.0)]


def _cmg_faults(scene, kinds) -> list:
    return [f for f in getattr(scene, "fault", None) or () if f.kind in kinds and f.enabled]


def rotor_changes(scene, before=None) -> dict:
    """Per unit the times its rotor's momentum is set by a truth fault, ``{unit: [(t, fraction
    of h_rotor), ...]}`` in time order (a fraction holds from its t to the next), each fault on
    what the faults before it left (:func:`_rotor_steps`): a ``wheel_speed_drop`` takes its
    ``fraction``, a ``cmg_failed`` stops the rotor or spins it down (:func:`spin_down_staircase`).
    A unit without one: not a key (its rotor at 1). ``before``: only the faults before that one
    (earlier, or at its time and declared first)."""
    out: dict = {}
    for f in sorted(_cmg_faults(scene, ROTOR_KINDS), key=lambda f: f.t):  # stable: at one time, the later fault's
        if before is not None and (f is before or f.t > before.t):
            break
        ch = out.setdefault(f.unit, [])
        ch.extend(_rotor_steps(f, _rotor_at(ch, f.t), scene.controller.period))
        ch.sort(key=lambda c: c[0])
    return out


def _rotor_steps(f, r0: float, period: float) -> list:
    """``(t, fraction of h_rotor)`` of a rotor fault ``f`` on a rotor at ``r0`` of h_rotor at its
    time: a ``wheel_speed_drop`` loses ``fraction`` of what the rotor has, a ``cmg_failed``
    stops it or spins it down from there (:func:`spin_down_staircase`)."""
    if f.kind == "wheel_speed_drop":
        return [(f.t, r0 * (1.0 - f.param("fraction")))]
    if f.param("spin_down_s") == 0.0:
        return [(f.t, 0.0)]
    return [(f.t + j * period, r0 * r) for j, r in spin_down_staircase(f.param("spin_down_s"), period)]


def _rotor_before(scene, fault) -> float:
    """The fraction of h_rotor ``fault``'s unit has at its time from the rotor faults before it."""
    return _rotor_at(rotor_changes(scene, before=fault).get(fault.unit, []), fault.t)


def _rotor_at(changes, t: float) -> float:
    r = 1.0
    for a, c in changes:
        if a <= t:
            r = c
    return r


def held_units(scene, geo, columns) -> list:
    """The units whose gimbals a fault of the truth holds, for the working units' momentum
    (:class:`~.working_h.WorkingH` ``held_units``; ``geo`` the cluster's
    :class:`~stationbed.model.cmg.CmgGeometry`, None: no cluster): per stretch of a held window
    over which the unit's rotor is constant, ``(t, until, momentum(row))``, the unit's rotor
    momentum (B [N m s]) at the row's gimbal angles, which from ``t`` are the angles it is held
    at, times its rotor's fraction there (:func:`rotor_changes`). A ``gimbal_stuck`` holds it
    over its window (its rotor spins on, at what a ``wheel_speed_drop`` left); a ``cmg_failed``
    from t on, its rotor spinning down (``spin_down_s`` = 0: stopped, nothing to hold). Like a
    unit failed from the start (``[cmg] failed``, ``held_momentum_B``), its momentum is then not
    the working units': ``max_h`` leaves it out."""
    held = _cmg_faults(scene, ("gimbal_stuck", "cmg_failed"))
    if geo is None or not held or not geo.gimballed:
        return []
    col = {c: i for i, c in enumerate(columns)}
    gi = [col[g] for g in geo.gimbal_names]
    cfg = scene.cmg
    rotors = rotor_changes(scene)

    def momentum(unit, r):
        return lambda row: r * geo.unit_momenta_B(cfg, row[gi])[unit - 1]

    out = []
    for f in held:
        a, b = f.t, math.inf if f.until is None else f.until
        ch = rotors.get(f.unit, [])
        cuts = [a] + sorted({c for c, _ in ch if a < c < b}) + [b]
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            r = _rotor_at(ch, lo)
            if r > 0.0:
                out.append((lo, hi, momentum(f.unit, r)))
    return out


def capacity_steps(scene, geo) -> list:
    """The working units' capacity as the truth's CMG faults change it, for the working units'
    momentum (:class:`~.working_h.WorkingH` ``capacity_steps``; ``geo`` as :func:`held_units`):
    ``(t, capacity)`` [s, N m s] at each time it changes, in time order; ``capacity`` None where
    it is the start's. A unit is out over its fault's window when the fault holds its gimbals
    (``cmg_failed``, ``gimbal_stuck``); a ``wheel_speed_drop`` weighs the unit's rotor at its
    fraction. The capacity is the cluster's with the units out failed as ``[cmg] failed``
    states them (:func:`~stationbed.model.cmg.capacity`), and with a rotor at a fraction the
    envelope's (:meth:`~stationbed.model.cmg.base.GimballedGeometry.rotor_capacity`, the
    saturation flag's). Empty without such a fault."""
    out = _cmg_faults(scene, OUT_KINDS)
    dropped = {f.unit for f in _cmg_faults(scene, ("wheel_speed_drop",))}
    rotors = {u: ch for u, ch in rotor_changes(scene).items() if u in dropped}
    if geo is None or not (out or rotors) or not geo.gimballed:
        return []
    cfg = scene.cmg
    ends = [(f.t, math.inf if f.until is None else f.until, f.unit) for f in out]
    times = {e for a, b, _ in ends for e in (a, b) if math.isfinite(e)} | {c for ch in rotors.values() for c, _ in ch}
    steps = []
    for t in sorted(times):
        units = sorted({u for a, b, u in ends if a <= t < b} | set(cfg.failed))
        r = [0.0 if i + 1 in units else _rotor_at(rotors.get(i + 1, []), t) for i in range(geo.n_units)]
        if any(0.0 < x < 1.0 for x in r):
            cap = geo.rotor_capacity(cfg, r)
        else:
            units = sorted({i + 1 for i, x in enumerate(r) if x == 0.0})
            cap = geo.capacity(cfg.model_copy(update={"failed": units})) if units != sorted(cfg.failed) else None
        if (steps[-1][1] if steps else None) != cap:
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
    r0 = _rotor_before(comp.scene, f)  # a rotor a wheel_speed_drop slowed spins down from there
    steps = [(0, _cmg(comp, f.unit, rate_cap=0.0), {}, False)]
    return steps + [(j, _cmg(comp, f.unit, rotor=r0 * r), {}, True) for j, r in spin_down_staircase(tau, comp.period)]


@register_fault_effect("gimbal_stuck")
def _gimbal_stuck(f, comp):
    return _cmg(comp, f.unit, rate_cap=0.0), {}, False


@register_fault_effect("gimbal_rate_limit")
def _gimbal_rate_limit(f, comp):
    return _cmg(comp, f.unit, rate_cap=f.param("limit")), {}, False


@register_fault_effect("wheel_speed_drop")
def _wheel_speed_drop(f, comp):
    return _cmg(comp, f.unit, rotor=_rotor_before(comp.scene, f) * (1.0 - f.param("fraction"))), {}, True


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
