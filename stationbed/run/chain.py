"""The actuator chain of a closed-loop run (issue 33): the scene's actuator kinds before the
chain's end, in chain order (:func:`~stationbed.loop.actuator.chain_kinds`), each an
:class:`ActuatorLoop` holding its plug-in and its memory, which every executor reads and hands
back here by the same names. No executor names a kind: every executor composes the plug-ins
as blocks (run/blocks.py) and writes each one's memory and numbers by its name; the generic
per-tick path calls the chain's blocks in order (run/parts.py ``GenericTick``), then
:func:`chain_advance`.
"""

from __future__ import annotations

import numpy as np

from ..loop.actuator import ACTUATORS, chain_kinds, pulse_pieces
from ..scene import knowledge_scene
from .segments import segment_input

__all__ = ["ActuatorLoop", "chain_for", "chain_advance", "chain_columns", "chain_summary", "chain_summary_parts"]


class ActuatorLoop:
    """One actuator of the chain in a run: the plug-in (``cluster``, its block's name ``name``)
    and its memory (``x`` after the last tick, ``x_row`` before the current one: what a row
    reports)."""

    def __init__(self, cluster, layout):
        self.cluster = cluster
        self.name = cluster.kind
        self.x = cluster.x0.copy()  # the actuator's memory after the last tick
        self.x_row = self.x.copy()  # ... before the current tick (what a row reports)
        if not getattr(cluster, "commanded", False):  # its READS are measurement fields (KeyError naming one
            cluster.reads_in(layout)  # that is not; a commanded one reads the [fdir] mode manager's memory too)
        self.idx = cluster.row_index()
        self.fused_reason = None  # why the fused loop did not take it (summary)

    @property
    def lp(self) -> bool:
        """Whether the plug-in runs in Python each tick (it keeps the run per tick)."""
        return bool(self.cluster.python_only)

    def row(self, x=None) -> list[float]:
        """The row's values (the plug-in's columns) from the memory ``x`` before the tick."""
        return np.asarray(self.x_row if x is None else x, dtype=float)[self.idx].tolist()

    def summary(self) -> dict:
        out = self.cluster.summary(self.x)
        if self.fused_reason:
            out[f"{self.name}_not_fused"] = self.fused_reason
        return out


def chain_for(scene, ctrl, layout, plant) -> tuple:
    """The run's actuators before the chain's end, in chain order (empty without any); each
    built on the truth flown, what flight software knows and the law's ``plant`` facts."""
    kinds = chain_kinds(scene)
    if not kinds:
        return ()
    if ctrl.command != "torque":
        raise ValueError(f"controller '{ctrl.name}' commands gimbal rates: {kinds[0].kind} share a torque request "
                         "with the CMGs (use a torque-commanding law)")
    known = knowledge_scene(scene)
    return tuple(ActuatorLoop(k.from_scene(scene, known, plant), layout) for k in kinds)


def chain_columns(scene) -> list[str]:
    """The CSV columns of the scene's chain, in chain order."""
    return [c for k in chain_kinds(scene) for c in k.columns(scene)]


def chain_summary_parts(s: dict) -> list[str]:
    """The run summary line's parts of every registered actuator kind (its ``summary_parts``, in
    chain order: none for a kind the run's summary ``s`` does not hold)."""
    return [part for k in sorted(ACTUATORS.values(), key=lambda c: (c.ORDER, c.kind)) for part in k.summary_parts(s)]


def chain_summary(comp) -> dict:
    """What the run's summary adds from each actuator of the chain (its kind's ``summary``)."""
    out = {}
    for a in comp.actuators:
        out.update(a.summary())
    return out


def chain_advance(comp, res, t0: float, t1: float, on_s, torque_B, held_B=None) -> None:
    """Integrate ``[t0, t1]`` split at the scene's breakpoints and every channel's edge (the
    chain's channels in order: on-times ``on_s``, torques ``torque_B`` (3, n)); over each piece
    the channels on add their torque to the held external torque (``res.u``, plus ``held_B``:
    the ideal torquer's at the chain's end; the state ``res.x`` advanced in place)."""
    cuts = [(t0 + a, t0 + b, on) for a, b, on in pulse_pieces(on_s, t1 - t0)]
    cuts[-1] = (cuts[-1][0], t1, cuts[-1][2])
    inner = [b for b in comp.bps if t0 < b < t1]
    i_ext = comp.input_layout.slice("u_ext")
    for a, b, on in cuts:
        edges = [a] + [e for e in inner if a < e < b] + [b]
        tq = torque_B[:, on].sum(axis=1) + (0.0 if held_B is None else held_B)
        for s0, s1 in zip(edges[:-1], edges[1:]):
            segment_input(comp.scene, comp.model, s0, s1, res.u)
            u = res.u.copy()
            u[i_ext] += tq
            res.x[:] = comp.apply_jump(s1, comp.integ.advance(s0, s1, res.x, u))
