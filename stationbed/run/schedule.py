"""Scheduled steps (issues 34 and 35): a change of the run's numbers at a control tick, the same
on every executor (docs/design.md "Scheduled steps and faults").

A :class:`Step` is applied at the *start* of control tick ``k`` (``t = k * period`` exactly, the
loop's integer clock), before that tick's measurement: it sets entries of the model's
parameter vector ``p`` (``comp.p``: e.g. a CMG unit's ``rotor`` or ``rate_cap``,
:data:`~stationbed.model.cmg.base.UNIT_TAIL`) and of blocks' numbers by the block's name (the
composed loop's ``par`` slices: ``"thrusters"`` -> ``ThrusterCluster.params``, ``"sensing"`` ->
``Flight.params``, :func:`block_numbers`), and, when it says ``jump``, moves the plant's state
across the step keeping the system's angular momentum (the compiled ``step_jump(t, x, p_before,
p_after)``, :meth:`~stationbed.formulations.base.Formulation.step_jump`). The measurement at
``t`` sees the state and the numbers after the step. A window (``until``) is a second step that
puts back the values the first one replaced.

The compiled structure never changes: a step is new numbers in the same buffers, so a run with
steps stays on its executor (the fused loop cuts its chunk there, as at any edge on the tick
grid: :func:`~.segments.edge_ticks`). The executors call :meth:`Stepper.apply` (and refresh
their own copies of p); :data:`SOURCES` makes the steps from the scene (``[[fault]]``:
:mod:`.faults`; a new source, e.g. ``[[event]]``, registers a function there).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..core.compile import FastCall

__all__ = ["Step", "Schedule", "Stepper", "SOURCES", "block_numbers", "schedule_of", "stepper", "refresh_loop",
           "composed_hook", "loop_hook", "parts_hook", "lockstep_hook", "bulk_stop", "steps_summary"]


@dataclass(eq=False)
class Step:
    """One scheduled step (module docstring).

    Attributes
    ----------
    k : int  The control tick it applies at (its time ``k * period``).
    label : str  What it is, for the summary (``"fault[0] cmg_failed unit 2"``).
    plant : dict  Index in p -> the value after the step.
    blocks : dict  Block name -> {index in its numbers -> the value after the step}.
    jump : bool  The state jumps, the system's angular momentum kept (``step_jump``).
    clears : Step or None  This step ends a window: it puts back what ``clears`` replaced.
    info : dict  What the summary reports of it (kind, unit, time...).
    """

    k: int
    label: str
    plant: dict = field(default_factory=dict)
    blocks: dict = field(default_factory=dict)
    jump: bool = False
    clears: "Step | None" = None
    info: dict = field(default_factory=dict)
    saved: dict = field(default_factory=dict)  # (owner, index) -> the value it replaced, set when applied
    #: a jump of its own, ``kick(t, x, p_before, p_after) -> x_after`` (numpy), applied after the
    #: numbers are set (and after ``step_jump``): a docking's momentum brought in (run/docking.py)
    kick: "Callable | None" = None
    #: the law designs again at the tick, in Python (a failure detected: run/detection.py):
    #: ``redesign(t, s) -> (cp, s_after)`` from the law's state ``s`` the executor carried, its new
    #: symbolic numbers and state; an executor that carries the law's numbers calls it between
    #: chunks (:func:`composed_hook`), one that calls the law in Python lets the law design itself
    redesign: "Callable | None" = None


#: functions ``(comp) -> list[Step]`` making a run's steps from its scene (``[[fault]]``: run/faults.py)
SOURCES: list[Callable] = []


def block_numbers(comp) -> dict[str, np.ndarray]:
    """The blocks' numbers a step may change, by block name (the composed loop's ``par`` slice
    of the same name): the arrays every executor reads them from (edited in place)."""
    out = {}
    for a in comp.actuators:  # the actuator chain (run/chain.py), by block name
        out[a.name] = a.cluster.params
    if comp.flight is not None:
        out["sensing"] = comp.flight.params
    if any("law" in s.blocks for s in comp.schedule.steps):  # a configuration update told (run/docking.py)
        out["law"] = np.asarray([float(v) for v in comp.ctrl.symbolic_params()], float)
    return out


def _law_buffers(ctrl, i: int | None = None):
    """Where a compiled law reads its numbers: the per-tick law's buffer (``i`` None) or sample
    ``i``'s row of the lockstep batch's (None before the law's first call)."""
    law = ctrl.__dict__.get("_law" if i is None else "_batch_law")
    if law is None or law.fc is None:
        return None
    cp = law.fc.args[2]
    return cp if i is None else cp.reshape(len(law.members), -1)[i]


class Schedule:
    """A run's steps in tick order (``steps``), from :data:`SOURCES`; ``ticks`` the ticks with one."""

    def __init__(self, steps: list[Step]):
        self.steps = sorted(steps, key=lambda s: s.k)  # (stable: the scene's order within a tick)
        self.ticks = sorted({s.k for s in self.steps})
        self._at = {k: [s for s in self.steps if s.k == k] for k in self.ticks}

    def __bool__(self) -> bool:
        return bool(self.steps)

    def at(self, k: int) -> list[Step]:
        """The steps at tick ``k`` (in the scene's order)."""
        return self._at.get(k, [])


def schedule_of(comp) -> Schedule:
    """The :class:`Schedule` of the run composed by ``comp`` (every source's steps; the sources'
    modules are imported by :attr:`~.composition.Composition.schedule`)."""
    steps = []
    for src in SOURCES:
        steps += src(comp)
    return Schedule(steps)


class Stepper:
    """Applies a run's schedule for one executor: :meth:`apply` at a step's tick edits ``comp.p``
    and the blocks' numbers in place, jumps the state, and refreshes the copies of p every
    executor shares (the integrator's, the output rows': the rows before the step are flushed
    with the old numbers first). Each tick is applied once (an executor may ask twice)."""

    def __init__(self, comp, res):
        self.comp, self.res = comp, res
        self.schedule = comp.schedule
        self.ticks = set(self.schedule.ticks)
        self.done: set[int] = set()
        self.numbers = block_numbers(comp)
        self._jump = None

    def due(self, k: int) -> bool:
        return k in self.ticks and k not in self.done

    def apply(self, k: int, x: np.ndarray) -> np.ndarray:
        """The state just after the steps at tick ``k`` from the state ``x`` just before (a new
        array; ``x`` itself when nothing jumps). No-op when tick ``k`` has none or was applied."""
        if not self.due(k):
            return x
        self.done.add(k)
        comp = self.comp
        p = comp.p
        p_before = p.copy()
        jump = False
        kicks = []
        for s in self.schedule.at(k):
            if s.clears is not None:  # a window's end: what its start replaced, put back
                edits = dict(s.clears.saved)
            else:
                edits = {("p", i): v for i, v in s.plant.items()}
                edits.update({(name, i): v for name, e in s.blocks.items() for i, v in e.items()})
            for (name, i), v in edits.items():
                arr = p if name == "p" else self.numbers[name]
                s.saved[(name, i)] = float(arr[i])
                arr[i] = v
            jump |= s.jump
            if s.kick is not None and s.clears is None:
                kicks.append(s.kick)
        self.res.rows.flush()  # the rows before the step, with the numbers before it
        self.res.rows.set_params(p)
        comp.integ.set_params(p)
        if jump:
            if self._jump is None:
                self._jump = FastCall.of(comp.system.funcs["step_jump"])
            a = self._jump.args
            a[0][0] = k * comp.period
            a[1][:] = x
            a[2][:] = p_before
            a[3][:] = p
            self._jump()
            x = self._jump.res[0].copy()
        for kick in kicks:
            x = kick(k * comp.period, x, p_before, p)
        return x

    def summary(self) -> list[dict]:
        """The steps applied, in order (their ``info`` and time [s]; a staircase's first step only)."""
        return [dict(s.info, t=s.k * self.comp.period) for s in self.schedule.steps
                if s.k in self.done and "step" not in s.info]


def stepper(comp, res) -> Stepper:
    """The run's :class:`Stepper` (one per run state ``res``, kept on it: the summary reads it)."""
    st = getattr(res, "stepper", None)
    if st is None:
        st = res.stepper = Stepper(comp, res)
    return st


def refresh_loop(loop) -> None:
    """After a step: the per-tick loop's own copies of p and of the blocks' numbers (its
    measurement's, the generic path's blocks', the compiled law's)."""
    comp = loop.comp
    p = comp.p
    loop.meas.args[2][:] = p
    if loop.generic is not None:  # the generic path's blocks (run/parts.py GenericTick)
        loop.generic.refresh()
    law = getattr(getattr(loop.res, "stepper", None), "numbers", {}).get("law")
    buf = None if law is None else _law_buffers(comp.ctrl)
    if buf is not None:
        buf[:] = law


def composed_hook(comp, res, c0, cx, par, P, C=None):
    """The fused loop's ``step(a)`` (run/composed.py, :func:`~.segments.run_pieces`): at a step's
    tick, the carry's state ``c0[cx]`` jumped and ``par``'s p and block slices rewritten; with
    the carry's layout ``C``, a step's ``redesign`` too (the law's numbers in ``par`` and its
    state in ``c0``, under the law block's name ``"law"``); None when the run has no steps."""
    if not comp.schedule:
        return None
    st = stepper(comp, res)

    def step(a: int) -> None:
        if st.due(a):
            c0[cx] = st.apply(a, c0[cx].copy())
            par[P.slice("p")] = comp.p
            for name, arr in st.numbers.items():
                if name in P:
                    par[P.slice(name)] = arr
            for s in st.schedule.at(a) if C is not None else ():
                if s.redesign is not None:
                    cp, s_law = s.redesign(a * comp.period, C.get(c0, "law").copy())
                    par[P.slice("law")], c0[C.slice("law")] = cp, s_law
    return step


def loop_hook(loop):
    """The per-tick loop's generic path's ``(ticks, step)``: the ticks with a scheduled step and
    ``step(k, t)``, called after integrating up to tick ``k`` (time ``t``) instead of sensing
    there: the step applied to the loop's state (in place), the loop's copies of p refreshed
    (:func:`refresh_loop`), then tick k sensed. At k = 0 nothing is sensed (the loop senses
    tick 0 itself)."""
    comp = loop.comp
    if not comp.schedule:
        return set(), None
    st = stepper(comp, loop.res)

    def step(k: int, t: float) -> None:
        loop.x[:] = st.apply(k, loop.x.copy())
        refresh_loop(loop)
        if k > 0:
            loop._sense(k, t)
    return set(st.ticks), step


def parts_hook(loop, c, cx, par, P):
    """The per-tick loop's composed parts' ``step(k)`` (run/parts.py), called where a piece of
    ticks starts (every step's tick starts one: :func:`~.segments.edge_ticks`), before its
    sensing: at a step's tick, as :func:`composed_hook` on the parts' carry ``c`` and numbers
    ``par``, and the loop's own copies refreshed (:func:`refresh_loop`: the law it calls in
    Python reads its compiled numbers there); None when the run has no steps."""
    comp = loop.comp
    step = composed_hook(comp, loop.res, c, cx, par, P)
    if step is None:
        return None
    st = stepper(comp, loop.res)

    def at(k: int) -> None:
        if st.due(k):
            step(k)
            refresh_loop(loop)
    return at


def steps_summary(comp, res) -> dict:
    """The summary's ``faults``: the steps applied, in order (empty without a schedule)."""
    st = getattr(res, "stepper", None)
    if not comp.scene.fault and not comp.scene.event:  # (a detection's redesign alone reports nothing here)
        return {}
    applied = [] if st is None else st.summary()
    out = {"faults": [s for s in applied if "event" not in s]}
    if comp.scene.event:  # docking events and the law's configuration updates (run/docking.py)
        out["events"] = [s for s in applied if "event" in s]
    return out


def lockstep_hook(batch, samples):
    """The lockstep batch's ``step(i, k)`` (run/lockstep.py), called where a live sample ``i``
    starts a piece of ticks at tick ``k`` (every step's tick starts one), before it senses: at
    a step's tick, as :func:`parts_hook` on its row of the mapped parts' carry and numbers
    (``batch.C[i]``, ``batch.PAR[i]``), its loop refreshed, its law's numbers written into the
    compiled batch law's (``batch.law_batch``); None when no sample has steps."""
    if not any(s.loop.comp.schedule for s in samples):
        return None
    P, cx = batch.cm.par, batch.cm.carry.slice("x")

    def step(i: int, k: int) -> None:
        lo = samples[i].loop
        comp = lo.comp
        if not comp.schedule:
            return
        st = stepper(comp, lo.res)
        if not st.due(k):
            return
        batch.C[i, cx] = st.apply(k, batch.C[i, cx].copy())
        row = batch.PAR[i]
        row[P.slice("p")] = comp.p
        for name, arr in st.numbers.items():
            if name in P:
                row[P.slice(name)] = arr
        refresh_loop(lo)
        law = st.numbers.get("law")
        buf = None if law is None else _law_buffers(batch.law_batch, i)
        if buf is not None:
            buf[:] = law
        if any(s.redesign is not None for s in st.schedule.at(k)):
            _batch_redesign(batch, i, k, lo)
    return step


def _batch_redesign(batch, i: int, k: int, lo) -> None:
    """Sample ``i``'s law designs again at tick ``k`` (a step's ``redesign``) in the lockstep
    batch: a law evaluated compiled for the batch (``symbolic``) is handed its state from the
    batch law's row, designs again, and its new numbers and state go into that row (before the
    batch law's first call the batch takes them from the law itself); a law called in Python
    (each member's ``update``) designs again itself, as per tick (``ControlLoop.redesign``)."""
    comp = lo.comp
    t = k * comp.period
    if not comp.ctrl.has_symbolic():
        lo.redesign(t)
        return
    law = batch.law_batch.__dict__.get("_batch_law")
    fc = None if law is None else law.fc
    rows = None if fc is None else fc.args[3].reshape(len(law.members), -1)
    s_now = rows[i].copy() if rows is not None else _initial_state(comp.ctrl)
    redesign = next(s.redesign for s in comp.schedule.at(k) if s.redesign is not None)
    cp, s_after = redesign(t, s_now)
    if fc is not None:
        _law_buffers(batch.law_batch, i)[:] = cp
        rows[i] = s_after


def _initial_state(ctrl):
    from . import law_state  # noqa: PLC0415

    return law_state.initial(ctrl)


def bulk_stop(ticks, row_ks, j: int) -> int:
    """The row (index in ``row_ks``, the output rows' ticks) at which a stretch of bulk rows
    starting at row ``j`` must stop: the row holding the first step tick (``ticks``, sorted)
    after row j's tick, or starting at it (the step applies before that row); the last row
    without one."""
    i = bisect.bisect_right(ticks, row_ks[j])
    if i == len(ticks):
        return len(row_ks) - 1
    return bisect.bisect_right(row_ks, ticks[i]) - 1
