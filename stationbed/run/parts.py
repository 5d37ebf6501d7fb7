"""The composed tick's parts a per-tick executor calls around a law it calls itself (issue 33):
:meth:`~stationbed.loop.compose.Composed.sense_part` and
:meth:`~stationbed.loop.compose.Composed.act_part` of the run's composition (:mod:`.blocks`,
the same blocks the fused loop composes), generated as C once per structure and cached (in
this process by :func:`~.blocks.structure_key`, on disk by the compile cache)."""

from __future__ import annotations

import hashlib
import struct

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from ..integrators import IntegrationError
from .blocks import Draws, composed, held_rate, numbers, structure_key
from .controller_error import law_failure
from .law_state import law_numbers
from .measurement import Measurement
from .schedule import parts_hook
from .segments import edge_ticks, held_torque_from, max_edges, off_grid_ticks, tick_edges, tick_pieces

__all__ = ["parts", "run_parts", "NOISE_BLOCK", "generic_parts", "GenericTick"]

#: ticks of draws taken at a time (any size gives the same numbers: each stream in tick order)
NOISE_BLOCK = 256

_PARTS: dict = {}


def parts(comp, cp=()) -> dict:
    """``{"cm": Composed, "sense": FastCall, "act": FastCall, "act_edge": FastCall or None}`` of
    the run composed by ``comp`` (``cp`` the law's symbolic numbers, when it has them: the
    composition's key only); ``act_edge`` the act part of the edge tick's case (a discontinuity
    inside a tick: its parameters end with the edges, :func:`~.segments.tick_edges`), when the
    run has one."""
    key = structure_key(comp, cp)
    hit = _PARTS.get(key)
    if hit is not None and hit["system"] is comp.system:
        return hit
    cm, _ = composed(comp, cp)
    tag = "parts_" + hashlib.sha256(repr(cm.key).encode()).hexdigest()[:16]
    fs = [cm.sense_part(), cm.act_part()]
    if max_edges(comp):
        ce, _ = composed(comp, cp, edges=True)
        a = ce.act_part()
        fs.append(ca.Function("cl_act_edge", a.mx_in(), a.call(a.mx_in())))
        tag += "_edges"
    funcs = compile_functions(fs, tag)
    out = {"cm": cm, "sense": FastCall(funcs["cl_sense"]), "act": FastCall(funcs["cl_act"]), "system": comp.system,
           "act_edge": FastCall(funcs["cl_act_edge"]) if len(fs) > 2 else None}
    _PARTS[key] = out
    return out


def run_parts(loop, K: int, update) -> None:
    """Ticks 0..K of the per-tick ``loop`` (:class:`~.closed_loop.ControlLoop`) on the composed
    parts: per tick the law (``update``, called here)
    between the compiled ``sense`` and ``act`` parts of the run's composition (the blocks the
    fused loop composes: sensing, the actuator chain in order, its end, the held
    environment). The ticks run in the fused loop's pieces (each row's ticks cut at the edges
    on the grid and before a short final period, :func:`~.segments.tick_pieces`): a piece's
    ticks share the parts' numbers, so the act part's sensing of the next tick serves it. A
    scheduled step's tick starts a piece (:func:`~.segments.edge_ticks`): the step applies
    there, before the piece's first sensing (:func:`~.schedule.parts_hook`)."""
    comp, res = loop.comp, loop.res
    ctrl = comp.ctrl
    cp = law_numbers(ctrl)
    fns = parts(comp, cp)
    cm, sense, act = fns["cm"], fns["sense"], fns["act"]
    C, P, S = cm.carry, cm.par, cm.sense_outputs
    period, duration, n_per_out = comp.period, comp.duration, comp.n_per_out
    edges = edge_ticks(comp)
    res.held_rate = held_rate(comp)[0]
    c, par, a_cmd, a_v, a_w = act.args
    s_c, s_par, s_w = sense.args
    c[:] = 0.0
    par[:] = 0.0
    par[P.slice("p")] = comp.p
    for name, (p, x) in numbers(comp, cp).items():  # each block's numbers and memory at t = 0, by its name
        if name in P and len(p):
            par[P.slice(name)] = p
        if x is not None and name in C and len(x):
            c[C.slice(name)] = x
    c[C.slice("x")] = res.x
    fl = next((b for b in cm.sense if b.name == "sensing"), None)  # the flight's memory, handed back
    if fl is not None:
        fm = res.flight
        c[C.slice(fl.name)] = fm.packed(fl.state)
    # the chain's blocks' memory (Composition.memories), handed back by each block's name
    chain = [(a, C.slice(a.name)) for a in comp.memories]
    out = comp.end.outputs
    has_act = comp.has_cluster
    i_u, i_lim, i_sat = (out.slice("u_cmg"), out.slice("rate_limited").start, out.slice("saturated").start) if has_act else (0, 0, 0)
    cx, ci = C.slice("x"), C.slice("i")
    i_fin = cx.start + comp.state_layout.slice(comp.system.formulation.rate_field).start  # the finite-state probe
    pt0, ph, pn, pk, pu = (P.slice(f) for f in ("t0", "h", "n_act", "k0", "u_ext"))
    a_c1, a_cs, a_v1, a_outs, a_act = act.res
    s_cs, s_v, s_outs = sense.res
    seen = a_v1  # what the law sees (the act part writes the next tick's)
    M = loop.M = Measurement(seen, comp.meas_layout)
    reads = bool(cm.actuators)  # the chain reads what the law saw
    draws, nw = Draws(comp, cm), cm.noise.size
    W, w0 = np.zeros((0, nw)), 0

    def w_of(k):  # tick k's draws (a block of ticks at a time, in tick order)
        nonlocal W, w0
        if k - w0 >= len(W):
            W, w0 = draws.rows(k, min(NOISE_BLOCK, K + 1 - k)), k
        return W[k - w0]

    step = parts_hook(loop, c, cx, par, P)  # scheduled steps (run/schedule.py: each starts a piece), or None
    n_edges, og = max_edges(comp), off_grid_ticks(comp)  # the ticks holding a discontinuity: the edge tick's case
    fe = fns["act_edge"]

    def edge_trigger(e):  # the act part of the edge tick's case on the act part's buffers
        def run():
            for dst, src in zip(fe.args, act.args):
                dst[: len(src)] = src
            fe.args[1][P.size:] = e
            fe()
            for dst, src in zip(act.res, fe.res):
                dst[:] = src
        return run

    def start(k, n, h):  # a piece of n ticks of h from tick k: its numbers, its first sensing
        nonlocal trigger
        trigger = act.trigger if k not in og else edge_trigger(tick_edges(comp, k, h, n_edges))
        if step is not None:  # a step at tick k: the state jumped, the numbers rewritten, before sensing
            step(k)
        t0 = min(k * period, duration)
        par[pt0], par[ph], par[pn], par[pk] = t0, h, n, k
        par[pu] = held_torque_from(comp.scene, t0, comp.bps, duration)
        s_par[:] = par
        c[ci] = 0.0
        s_c[:] = c
        if nw:
            s_w[:] = w_of(k)
        sense()
        c[:] = s_cs
        a_v1[:] = s_v
        return s_outs

    replan_at = comp.replan.tick if comp.replan is not None else -1
    ncmd = comp.n_cmd
    three = ncmd == 3
    fc = act
    trigger = fc._trigger  # FastCall's bound buffer trigger: one C call, no wrapper
    # the act part's buffers as memoryviews: Python floats in and out, ~half numpy's cost
    m_c, m_c1, m_cs, m_act, m_cmd = (memoryview(v) for v in (c, a_c1, a_cs, a_act, a_cmd))
    pack_cmd = struct.Struct(f"={ncmd}d").pack_into
    ndarray, f64 = np.ndarray, np.dtype(np.float64)
    sat_since_row = ticks = 0
    pieces = [p for k0 in range(0, K, n_per_out)
              for p in tick_pieces(k0, min(n_per_out, K - k0), edges, duration, period)] + [(K, K + 1, 0.0)]
    try:
        for a, b, h in pieces:
            outs = start(a, b - a, h)
            for k in range(a, b):
                t = k * period  # integer tick clock: no accumulated drift
                if k == K:
                    t = duration
                if k == replan_at:
                    loop.redesign(t)
                M.t = t
                loop.calls += 1
                try:
                    cmd = update(t, M)
                except Exception as e:  # the user's code: report it (chained), keep the trajectory
                    raise law_failure(ctrl, t, e) from e
                # a tuple or list of ncmd real numbers, or a float64 array of ncmd values, is
                # written as is; anything else, or a failed write (wrong size, strings...),
                # goes to the checker, which raises or returns the values as floats
                cls = cmd.__class__
                try:
                    if cls is tuple or cls is list:
                        if three:  # (three numbers through the memoryview: ~1/3 of pack_into's cost)
                            m_cmd[0], m_cmd[1], m_cmd[2] = cmd
                        else:
                            pack_cmd(a_cmd, 0, *cmd)  # exactly ncmd numbers; no strings, no None
                    elif cls is ndarray and cmd.dtype is f64 and len(cmd) == ncmd:
                        a_cmd[:] = cmd  # (a (ncmd, 1) array raises ValueError)
                    else:
                        raise TypeError
                except (TypeError, ValueError, OverflowError, struct.error):
                    cmd = loop.check_command(t, cmd)
                    a_cmd[:] = cmd
                if reads:
                    a_v[:] = seen
                row = k % n_per_out == 0 or k == K
                if row:  # the memory a row reports: before the tick's actuation, after its sensing
                    x = c[cx].copy()
                    for ac, sl in chain:
                        ac.x_row = c[sl].copy()
                    if fl is not None:
                        res.flight.xs = fl.state.get(c[C.slice(fl.name)], "xs").copy()
                        res.flight.ys = fl.outputs.get(S.get(outs, fl.name), "ys").copy()
                if nw and k < K:
                    a_w[:] = w_of(k + 1)
                trigger()
                # the final tick's actuation is reported in its row but never integrated:
                # it is not counted in the summary
                if has_act and (m_act[i_lim] or m_act[i_sat]):
                    sat_since_row |= loop.flags(a_act, count=k < K)
                if row:
                    if len(cmd) == 3:
                        res.last_cmd = cmd
                    if has_act:
                        res.u[comp.u_cmg] = a_act[i_u]
                    res.x = x
                    res.rows.hold(t, x, *res.held_row(sat_since_row, t))
                    sat_since_row = 0
                if k == K:
                    break
                ticks += 1
                loop.n_fixed += 1
                v = m_c1[i_fin]
                if not -1e300 < v < 1e300:
                    res.ticks = ticks
                    loop.check_command(t, cmd)
                    raise IntegrationError(min((k + 1) * period, duration), "state is not finite (NaN or inf)")
                if k + 1 < b:
                    m_c[:] = m_cs
                    outs = a_outs
                else:
                    m_c[:] = m_c1
    finally:
        res.ticks = ticks
        res.x = c[cx].copy()
        for ac, sl in chain:
            ac.x = c[sl].copy()
        if fl is not None:
            res.flight.take(fl.state, c[C.slice(fl.name)])


_GENERIC: dict = {}


def generic_parts(comp) -> dict:
    """``{"cm": Composed, "sense": FastCall or None, "chain": [(lo, hi, FastCall or None)]}``:
    the parts the generic path calls (:class:`GenericTick`) of the run composed by ``comp``:
    the sense blocks (the sensing, the ideal measurement's delay and noise) on a measurement
    they are handed (None: no sense block) and the chain's pieces in order
    (:meth:`~stationbed.loop.compose.Composed.chain_pieces`; None: a block that is not
    symbolic, called in Python). The law is called in Python by the path itself: its block a
    stand-in (:func:`~.blocks.law_block`), so a law's ``symbolic`` form is not built here and
    the generated C is the same whatever the law. Generated as C once per structure and cached."""
    key = structure_key(comp, ())
    hit = _GENERIC.get(key)
    if hit is not None and hit["system"] is comp.system:
        return hit
    cm, _ = composed(comp, (), law_in_python=True)
    pieces = [(lo, hi, all(b.symbolic for b in cm.chain[lo:hi])) for lo, hi in cm.chain_pieces()]
    fs = ([cm.sense_on_part()] if cm.sense else []) + [cm.chain_part(lo, hi) for lo, hi, sym in pieces if sym]
    tag = "generic_" + hashlib.sha256(repr((cm.key, pieces)).encode()).hexdigest()[:16]
    funcs = compile_functions(fs, tag)
    out = {"cm": cm, "sense": FastCall(funcs["cl_sense_on"]) if cm.sense else None, "system": comp.system,
           "chain": [(lo, hi, FastCall(funcs[f"cl_chain_{lo}_{hi}"]) if sym else None) for lo, hi, sym in pieces]}
    _GENERIC[key] = out
    return out


class GenericTick:
    """The generic path's tick on the run's composed blocks (:func:`generic_parts`): the sense
    blocks on the true measurement it is handed (:meth:`sense`), the chain's blocks in order on
    the law's command (:meth:`act`: compiled pieces, a block that is not symbolic in Python).
    The blocks' memory lives in the carry ``c``, handed back by block name after each call
    (``res.flight``, each memory's ``x`` of ``comp.memories``: the actuators, then ``[fdir]``); the numbers in ``par``
    (:meth:`refresh` after a scheduled step). The sense blocks' draws come from their streams
    (:class:`~.blocks.Draws`), :data:`NOISE_BLOCK` ticks at a time in tick order."""

    def __init__(self, comp, res):
        fns = generic_parts(comp)
        self.comp, self.res = comp, res
        cm = self.cm = fns["cm"]
        self.draws, self.K = Draws(comp, cm), comp.ticks()
        self.W, self.w0 = np.zeros((0, cm.noise.size)), 0
        C, P = cm.carry, cm.par
        self.c, self.par = np.zeros(C.size), np.zeros(P.size)
        self.refresh()
        for name, (_, x) in numbers(comp, ()).items():  # each block's memory at t = 0, by its name
            if name != "law" and x is not None and name in C and len(x):  # (the law keeps its own)
                self.c[C.slice(name)] = x
        self.fl = next((b for b in cm.sense if b.name == "sensing"), None)  # the flight's memory, handed back
        if self.fl is not None:
            fm = res.flight
            self.c[C.slice(self.fl.name)] = fm.packed(self.fl.state)
        self.sense_fc = fns["sense"]
        self.pieces = fns["chain"]
        self.chain = [(a, C.slice(a.name)) for a in comp.memories]  # the memories handed back, by name
        self.cx = C.slice("x")
        self.pt0, self.ph, self.pk = (P.slice(f).start for f in ("t0", "h", "k0"))
        self.period, self.duration = comp.period, comp.duration
        self.i_ext = comp.input_layout.slice("u_ext")
        # on_s and torque_B of the chain's channels over the tick (set by :meth:`act`)
        self.on_s, self.torque_B, self.held_B = np.zeros(0), np.zeros((3, 0)), np.zeros(3)

    def refresh(self) -> None:
        """``par``'s numbers from the run's (the model's p, each block's by its name)."""
        P = self.cm.par
        self.par[P.slice("p")] = self.comp.p
        for name, (p, _) in numbers(self.comp, ()).items():
            if name != "law" and name in P and len(p):
                self.par[P.slice(name)] = p

    def _at(self, k: int, t: float) -> None:
        par = self.par
        rest = self.duration - t  # the tick's length: the period, the remainder of the run for the last one
        par[self.pt0], par[self.pk] = t, k
        par[self.ph] = self.period if rest >= self.period * (1 - 1e-12) else max(rest, 0.0)

    def sense(self, k: int, t: float, y: np.ndarray) -> np.ndarray:
        """Tick k (time t) of the sense blocks on the true measurement ``y``: what the law sees."""
        if self.sense_fc is None:
            return y
        self._at(k, t)
        fc, C = self.sense_fc, self.cm.carry
        a = fc.args
        a[0][:], a[1][:], a[2][:] = self.c, self.par, y
        if len(a[3]):
            if k - self.w0 >= len(self.W):
                self.W, self.w0 = self.draws.rows(k, min(NOISE_BLOCK, self.K + 1 - k)), k
            a[3][:] = self.W[k - self.w0]
        fc()
        self.c[:] = fc.res[0]
        fl = self.fl
        if fl is not None:
            v, fm = self.c[C.slice(fl.name)], self.res.flight
            fm.take(fl.state, v)
            fm.xs[:] = fl.state.get(v, "xs")
            fm.ys[:] = fl.outputs.get(self.cm.sense_outputs.get(fc.res[2], fl.name), "ys")
        return fc.res[1]

    def act(self, k: int, t: float, x: np.ndarray, cmd, v: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Tick k (time t, plant state ``x``) of the chain on the law's command ``cmd`` (what
        the law saw ``v``, the true measurement ``y``): sets :attr:`on_s`, :attr:`torque_B`
        (3, channels) and :attr:`held_B` (the end's torque added to the held external one: the
        ideal torquer's); returns the end's report (``out``)."""
        self._at(k, t)
        c, cm = self.c, self.cm
        c[self.cx] = x
        for a, _ in self.chain:  # the memory a row reports: before the tick
            a.x_row = a.x
        tau, ons, tqs, rep = cmd, [], [], None
        for lo, hi, fc in self.pieces:
            if fc is None:  # a block that is not symbolic: its Python step
                x1, tau, on, tq = cm.python_step(lo, c, self.par, tau, v, y)
                c[cm.carry.slice(cm.chain[lo].name)] = x1
            else:
                a = fc.args
                a[0][:], a[1][:], a[2][:], a[3][:], a[4][:] = c, self.par, tau, v, y
                fc()
                r = fc.res
                if hi - lo > 1 or not len(r[5]):  # (a piece of the end alone keeps the carry)
                    c[:] = r[0]
                tau, on, tq = r[1], r[2], r[3]
                if len(r[5]):  # the end is the piece's last
                    rep = r[4]
                    self.held_B = r[5][self.i_ext]
            ons.append(on)
            tqs.append(tq)
        for a, sl in self.chain:
            a.x = c[sl].copy()
        if len(ons) == 1:  # (the buffers: read before the next tick's call)
            self.on_s, self.torque_B = ons[0], tqs[0].reshape(-1, 3).T
        else:
            self.on_s, self.torque_B = np.concatenate(ons), np.concatenate(tqs).reshape(-1, 3).T
        return rep
