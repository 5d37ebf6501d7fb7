"""The fused closed loop's entry: whether a run flies fused, and flying it (DESIGN §9).

A run flies fused when every block of its composition is symbolic and the clock allows it
(:func:`fused_ok`); the composed loop (:mod:`.composed`, the tick composed once from the run's
blocks by :mod:`stationbed.loop.compose`, issue 33) then runs a whole output row's ticks in one
compiled call (a casadi ``mapaccum`` generated as C), many rows per call where it can.
Otherwise the per-tick loop runs, with the same numbers to round-off, and the summary says why
(``thrusters_not_fused`` for the thrusters' reasons).
"""

from __future__ import annotations

import math

from . import law_state
from .controller import ControllerError, one_line
from .rates import environment_rate
from .segments import edge_ticks

__all__ = ["fused_ok", "run_fused"]


def fused_ok(comp) -> bool:
    """Whether the run composed by ``comp`` can run fused: a controller with a ``symbolic`` form, a ``fusable``
    integrator at one step per period, every discontinuity inside the run on the tick grid
    (:func:`~.segments.edge_ticks`), no sensor delay (its ring buffer is not a block yet), not the
    ideal measurement's noise with ``[[sensor]]`` tables, no failure detected mid-run, and
    thrusters the composed loop can fly (:func:`fused_thrust_ok`)."""
    ctrl = comp.ctrl
    integ = comp.integ
    return (
        callable(getattr(ctrl, "symbolic", None))
        and integ.fusable
        and math.ceil(comp.period / integ.h_nominal - 1e-9) == 1
        and edge_ticks(comp) is not None
        and not (comp.noisy and comp.delay > 0)
        and comp.system.sx is not None
        and not (comp.flight is not None and comp.noisy)
        and comp.replan is None  # a failure detected mid-run: per tick (run/detection.py)
        and fused_thrust_ok(comp)
    )


def fused_thrust_ok(comp) -> bool:
    """Whether the fused loop can fly the run's thrusters (always True without thrusters);
    sets ``comp.thrust.fused_reason`` when it cannot."""
    th = comp.thrust
    if th is None:
        return True
    why = None
    if th.lp:
        why = "mapping = 'lp' runs scipy's HiGHS in Python each tick"
    elif environment_rate(comp):
        why = "an environment rate with thrusters is flown per tick"
    elif comp.noisy and law_state.has_state(comp.ctrl):
        why = "[controller.sensor] noise with a law that has a state and thrusters is flown per tick"
    th.fused_reason = why
    return why is None


def run_fused(comp, res, K: int) -> None:
    """Run ticks 0..K of the run composed by ``comp`` with the composed loop, handing back to
    ``res`` (:class:`~.composition.RunState`) the same rows as the per-tick loop."""
    from .composed import run_composed  # noqa: PLC0415 (the executor, imported where it runs)

    return run_composed(comp, res, K, _symbolic_params(comp.ctrl), edge_ticks(comp))


def _symbolic_params(ctrl):
    """``ctrl.symbolic_params()``; ControllerError naming the controller if the user's code raises."""
    try:
        return ctrl.symbolic_params()
    except Exception as e:
        raise ControllerError(f"controller '{ctrl.name}': symbolic_params() raised {type(e).__name__}: {one_line(e)}") from e
