"""The fused executor of a composed loop (issue 33): any composition of the run's blocks
(:mod:`.blocks`: sensing, the law with its state, the actuator chain, its end) flown by one
compiled chunk per output row, the tick composed once by :mod:`stationbed.loop.compose`.

It knows no block: it writes the carry, the parameters and the draws by the composition's
named layouts (each block's memory and numbers under its name), calls the composed ``row`` at
each output row and the composed ``chunk`` over the row's ticks (cut into pieces at the
scene's edges, :func:`~.segments.tick_pieces`: a tick holding one between ticks runs the edge
tick's compiled case, its step split there), and hands the rows, the
flight's memory, the actuators' memory and the law's state back through the run's state.

It replaced the hand-composed fused loops of issues 20-25 (``fused.py``'s chunk,
``fused_flight.py``, ``thrust_fused.py``, their bulk rows and held-environment chunks) after
giving their rows bit for bit on every combination they flew; it also flies the combinations
they never composed (thrusters with ``[[sensor]]`` tables, thrusters with a law that has a
state).
"""

from __future__ import annotations

import hashlib
import time

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from . import law_state
from .blocks import Draws, composed, numbers, structure_key
from .composed_rows import rows_functions, run_rows
from .schedule import bulk_stop, composed_hook
from .segments import close_chunk, finish_chunks, held_torque_from, max_edges, off_grid_ticks, run_pieces, tick_edges, tick_pieces

__all__ = ["run_composed", "BUILT"]

_CHUNKS: dict[tuple, dict] = {}
#: the seconds each composed structure took to build and compile (benchmarks read it)
BUILT: dict[str, float] = {}


def _functions(comp, cp) -> dict:
    n = comp.n_per_out
    hit = _CHUNKS.get((structure_key(comp, cp), n))
    if hit is not None and hit["system"] is comp.system:
        return hit
    t0 = time.perf_counter()
    cm, _ = composed(comp, cp)
    key = (cm.key, n)
    tag = "composed_" + hashlib.sha256(repr(key).encode()).hexdigest()[:16]
    row, chunk = cm.row(), cm.chunk(n)
    many = rows_functions(cm, row, chunk, n)  # many rows per call (composed_rows.py)
    edge = []
    if max_edges(comp):  # the edge tick's case: one tick, its step cut at the scene's edges inside it
        ce, _ = composed(comp, cp, edges=True)
        one = ce.chunk(1)
        edge = [ca.Function("cl_chunk_edge", one.mx_in(), one.call(one.mx_in()))]
    funcs = compile_functions([row, chunk] + many + edge, tag + ("_edges" if edge else ""))
    out = {"cm": cm, "row": FastCall(funcs["cl_row"]), "chunk": FastCall(funcs["cl_chunk"]), "system": comp.system,
           "rows": {int(f.name().rsplit("_", 1)[1]): FastCall(funcs[f.name()]) for f in many},
           "edge": FastCall(funcs["cl_chunk_edge"]) if edge else None}
    BUILT[tag] = out["build_s"] = time.perf_counter() - t0
    _CHUNKS[(structure_key(comp, cp), n)] = out
    return out


def run_composed(comp, res, K: int, symbolic_params, edges) -> None:
    """Run ticks 0..K of the run composed by ``comp`` with the composed loop, handing back to
    ``res`` (:class:`~.composition.RunState`) the per-tick loop's rows and memories."""
    ctrl, flight = comp.ctrl, comp.flight
    cp = np.asarray(symbolic_params, dtype=float)
    fns = _functions(comp, cp)
    cm, row, chunk = fns["cm"], fns["row"], fns["chunk"]
    C, P, R = cm.carry, cm.par, cm.row_layout
    period, duration = comp.period, comp.duration
    s_law = law_state.initial(ctrl)
    law = cm.law_block.name
    fl = next((b for b in cm.sense if b.name == "sensing"), None)  # the flight's block
    sense = fl.name if fl is not None else None
    par = chunk.args[1]
    par[:] = 0.0
    par[P.slice("h")], par[P.slice("p")], par[P.slice(law)] = period, comp.p, cp
    # the external torque held from t = 0 (each stretch of bulk rows sets the torque held from its start)
    par[P.slice("u_ext")] = held_torque_from(comp.scene, 0.0, comp.bps, duration)
    if sense is not None:
        par[P.slice(sense)] = flight.params
        X = fl.state
    for name, (p, _) in numbers(comp, cp).items():  # each block's numbers, by its name
        if name in P and len(p):
            par[P.slice(name)] = p
    c0 = chunk.args[0]
    c0[:] = 0.0
    c0[C.slice("x")], c0[C.slice(law)] = res.x, s_law
    fm = res.flight
    if sense is not None:
        c0[C.slice(sense)] = fm.packed(X)
    for a in comp.memories:  # the chain's blocks' memory (the actuators, [fdir]), by each block's name
        c0[C.slice(a.name)] = a.x
    rc, rp, rw = row.args
    out = comp.end.outputs
    n_act = out.size if comp.has_cluster else 0
    i_u, i_lim, i_sat = (out.slice("u_cmg"), out.slice("rate_limited").start, out.slice("saturated").start) if n_act else (0, 0, 0)
    r_cmd, r_act, r_q, r_s = R.slice("cmd"), R.slice("act"), R.slice("q_ref"), R.slice(law)
    cx = C.slice("x")
    x, s_end = c0[cx].copy(), None
    tail_flag = ticks = 0
    res.used_fused = True
    n = comp.n_per_out
    row_ks = sorted(set(range(0, K, n)) | {K})
    draws_of = Draws(comp, cm)
    nw = draws_of.width

    def torque_at(ta):
        return held_torque_from(comp.scene, ta, comp.bps, duration)

    step = composed_hook(comp, res, c0, cx, par, P, C)  # scheduled steps (run/schedule.py), or None
    ne = max_edges(comp)  # the edge tick's case (a discontinuity between ticks), or None
    og = off_grid_ticks(comp)
    edge_case = (fns["edge"], lambda a, h: tick_edges(comp, a, h, ne) if a in og else None) if ne else None
    if step is not None:  # (one at tick 0 applies before the bulk rows too)
        step(0)
        x = c0[cx].copy()

    # the full rows many per compiled call (composed_rows.py), in stretches between the edges
    # (scheduled steps and changes of the held torque; tried at the first row and at the row
    # after each edge), each stretch holding the torque held from its start
    sched = sorted(set(comp.schedule.ticks) | set(edges or ()))
    bulk, try_at = True, {0}
    try:
        j0 = 0
        for j, k in enumerate(row_ks):
            if j < j0:
                continue
            t = min(k * period, duration)
            if step is not None:  # a step at the row's tick: before its measurement
                step(k)
                x = c0[cx].copy()
            if bulk and j in try_at and k in og:  # a row starting at an edge tick: row by row, bulk again after it
                try_at.add(j + 1)
            elif bulk and j in try_at:
                stop = bulk_stop(sched, row_ks, j)
                par[P.slice("u_ext")] = torque_at(t)
                jj, tail_flag, n_done, err = run_rows(comp, res, cm, fns["rows"], row_ks[j : stop + 1], K, c0, par,
                                                     draws_of, tail_flag)
                ticks += n_done
                x = c0[cx].copy()
                if err is not None:
                    raise err
                if stop < len(row_ks) - 1 and row_ks[stop] in sched:  # a step at that row's tick: on after it
                    try_at.add(stop)
                if jj:
                    j0 = j + jj
                    continue
            n_tick = row_ks[j + 1] - k if k < K else 1
            draws = draws_of.rows(k, n_tick) if nw else None
            # the row at tick k: the command, actuation and reference of this tick, the memory after it
            rc[:] = c0
            rc[C.slice("i")] = 0.0
            rp[:] = par
            rp[P.slice("t0")], rp[P.slice("k0")], rp[P.slice("u_ext")] = t, k, torque_at(t)
            rest = duration - t  # the tick's length: the period, the run's remainder for the last (0 at the end)
            rp[P.slice("h")] = period if rest >= period * (1 - 1e-12) else max(rest, 0.0)
            if nw:
                rw[:] = draws[0]
            row()
            r = row.res[0]
            cmd, a = r[r_cmd], r[r_act]
            lim = sat = 0
            u_cmg = None
            if n_act:
                lim, sat = int(a[i_lim] > 0.5), int(a[i_sat] > 0.5)
                u_cmg = a[i_u]
            for a in comp.memories:
                a.x_row = c0[C.slice(a.name)].copy()
            xs = ys = None
            if sense is not None:
                xs, ys = X.get(R.get(r, sense), "xs").copy(), fl.outputs.get(R.get(r, f"{sense}_y"), "ys").copy()
            res.row(t, x, lim | sat | tail_flag, u_cmg=u_cmg, cmd=cmd, q_ref=r[r_q], xs=xs, ys=ys)
            if k == K:
                if sense is not None:
                    fm.take(X, C.get(c0, sense))
                s_end = r[r_s].copy()  # the law's update at the last tick
                break
            counts = run_pieces(chunk, C, P, tick_pieces(k, n_tick, edges, duration, period), k, period, torque_at, draws,
                                step, edge_case)
            x = c0[cx].copy()
            par[P.slice("h")] = period
            ticks += n_tick
            tail_flag = close_chunk(res, ticks, counts, lim, sat, x, min((k + n_tick) * period, duration))
            if bulk and sched and bulk_stop(sched, row_ks, j) == j:  # a step inside this row's ticks
                try_at.add(j + 1)
    finally:
        law_state.hand_back(ctrl, C.get(c0, law) if s_end is None else s_end)
        for a in comp.memories:
            a.x = a.x_row = c0[C.slice(a.name)].copy()
        finish_chunks(res, x, ticks)
