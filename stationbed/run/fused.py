"""The fused closed loop's entry: whether a run flies fused, and flying it (DESIGN §9).

A run flies fused when every block of its composition is symbolic and the clock allows it
(:func:`fused_ok`); the composed loop (:mod:`.composed`, the tick composed once from the run's
blocks by :mod:`stationbed.loop.compose`, issue 33) then runs a whole output row's ticks in one
compiled call (a casadi ``mapaccum`` generated as C), many rows per call where it can.
Otherwise the per-tick loop runs, with the same numbers to round-off, and the summary names the
one block that forces it (``not_fused``, :func:`why_not_fused`; ``<kind>_not_fused`` too for an
actuator's reasons, e.g. ``thrusters_not_fused``).
"""

from __future__ import annotations

import math

from .law_state import law_numbers
from .segments import edge_ticks

__all__ = ["fused_ok", "why_not_fused", "run_fused"]


def why_not_fused(comp) -> str | None:
    """The one reason the run composed by ``comp`` cannot fly fused, naming the block or the
    part of the clock that forces it off the compiled path (None: it flies fused). The only
    place that decides it: :func:`fused_ok` is this is None, the summary reports it
    (``not_fused``). In order: the law (a Python or FMU law has no ``symbolic`` form), the
    integrator (not one fixed explicit step per tick), an array rate step (the state jumps
    inside a tick), the actuator chain (the LP mapping). Not reasons: a discontinuity between
    ticks (its tick is the edge tick's compiled case, :func:`~.segments.tick_edges`), a failure
    detected mid-run (the law designs again at its tick, a scheduled step:
    :func:`~.detection.detection_steps`), the ideal measurement's delay and noise (blocks, with
    ``[[sensor]]`` tables, a law with a state, any actuator)."""
    ctrl = comp.ctrl
    integ = comp.integ
    if not callable(getattr(ctrl, "symbolic", None)):
        return f"law: controller '{ctrl.name}' has no symbolic form (called in Python per tick)"
    if not integ.fusable or math.ceil(comp.period / integ.h_nominal - 1e-9) != 1 or comp.system.sx is None:
        return f"integrator: '{integ.name}' is not one fixed explicit step per tick"
    if edge_ticks(comp) is None:
        return "plant: an array rate step (the per-tick loop cuts there and jumps)"
    return _chain_why(comp)


def fused_ok(comp) -> bool:
    """Whether the run composed by ``comp`` can run fused (:func:`why_not_fused` is None)."""
    return why_not_fused(comp) is None


def _chain_why(comp) -> str | None:
    """Why the fused loop cannot fly the run's actuator chain, as ``"<kind>: <why>"`` (None
    without one, or when it can); kept on the actuator's ``fused_reason`` (the summary's
    ``<kind>_not_fused``)."""
    for a in comp.actuators:
        why = None
        if a.lp:
            why = a.cluster.why
        a.fused_reason = why
        if why is not None:
            return f"{a.name}: {why}"
    return None


def run_fused(comp, res, K: int) -> None:
    """Run ticks 0..K of the run composed by ``comp`` with the composed loop, handing back to
    ``res`` (:class:`~.composition.RunState`) the same rows as the per-tick loop."""
    from .composed import run_composed  # noqa: PLC0415 (the executor, imported where it runs)

    return run_composed(comp, res, K, law_numbers(comp.ctrl), edge_ticks(comp))
