"""The loop, composed once (issue 33): from a scene's blocks (:mod:`.block`) and its plant, the
tick's parts and the whole tick as casadi functions, with one cache key.

The tick, in order (docs/design.md "One loop, built once")::

    y  = meas(t, x)                                      the plant's true measurement
    v  = sense blocks in order (y -> y_seen)             sensors, estimator: what the law sees
    cmd, q_ref = law(v)                                  the law, with its own state
    tau = cmd; per actuator of the chain, in order:      thrusters, ... (reads v by field name)
          tau, on_s, torque_B = actuator(tau)
    u   = end(x, tau)                                    the chain's end: the plant's held input
    x'  = step(x, u) over [t, t + h], cut at every pulse edge inside the tick

Parts an executor may call on their own (:meth:`Composed.sense`, :meth:`Composed.law`,
:meth:`Composed.advance`) and the whole tick (:meth:`Composed.tick`, ``(c, par, w) -> c_next``
on the named carry :attr:`Composed.carry`, parameters :attr:`Composed.par` and the tick's draws
:attr:`Composed.noise`), a chunk of ``n`` ticks (:meth:`Composed.chunk`, ``mapaccum``) and the
output row's values (:meth:`Composed.row`).

The speed cases are one mechanism, the distinct sets of due blocks and idle actuators, each its
own compiled case (a casadi ``Function.conditional`` / ``if_else`` of explicit branch
functions: the generated C evaluates only the case taken):

* a *plain* tick (every sense block with a plain form is on a plain tick: its slower sensors
  hold) runs the front of the tick (measurement, sensing, law, the quiet step) as one SX
  function; any other tick the general front (the sensing's switches kept lazy);
* a *quiet* tick (every actuator of the chain in its exact idle form) steps the plant on the
  law's request at once; a busy tick runs the chain, then, when nothing fires and the end gets
  the request unchanged, keeps the quiet step, else one plain step or the step split at the
  pulse edges (:func:`~.actuator.split_step`).

Every case gives the numbers the full tick would (the idle and plain forms are exact): the
per-tick executor, which calls the composition's parts around a law it calls itself
(:meth:`Composed.sense_part`, :meth:`Composed.act_part`: the law is the one block it may leave
out), flies the same run to round-off (tests/test_executor_matrix.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from ..core.compile import closed_parametric, sx_function
from ..core.layout import Layout
from .actuator import TRUE_SUFFIX, split_step
from .block import Block, off_path
from .compose_parts import PartsMixin

__all__ = ["Plant", "Composed", "compose", "off_path"]


@dataclass(frozen=True, eq=False)
class Plant:
    """What the composer needs of the plant: its true measurement ``meas(t, x, p) -> y`` (SX, in
    ``meas_layout``), right-hand side ``rhs(t, x, u, p)``, the integrator's one fixed step
    ``step(rhs, t, x, h, u, p)``, the sizes and the held input's layout (``u_ext`` first of
    what a pulse adds to)."""

    meas: ca.Function
    rhs: ca.Function
    step: object
    nx: int
    npar: int
    meas_layout: Layout
    input_layout: Layout
    key: tuple
    #: the right-hand side without the effects an ``env`` block holds (None: the plant has none)
    rhs_held: ca.Function | None = None


def compose(plant: Plant, blocks: list[Block], n_edges: int = 0) -> "Composed":
    """The composition of ``blocks`` (any order: sorted by role, kept in order within one);
    ``n_edges`` > 0: the edge tick's case (:attr:`Composed.n_edges`)."""
    return Composed(plant, blocks, n_edges)


class Composed(PartsMixin):
    """The tick of one composition, its parts and its layouts (module docstring)."""

    def __init__(self, plant: Plant, blocks: list[Block], n_edges: int = 0):
        self.plant = plant
        #: the edge tick's case (> 0): its step also cut at up to ``n_edges`` of the scene's
        #: discontinuities inside the tick, the parameters' ``edge`` (times into the tick, then
        #: the held torque's jumps: :func:`~.actuator.split_step`); appended last, so the
        #: parameters before it are those of the composition without it
        self.n_edges = n_edges
        by = {r: [b for b in blocks if b.role == r] for r in ("env", "sense", "law", "actuator", "end")}
        if len(by["law"]) != 1 or len(by["end"]) != 1:
            raise ValueError(f"a composition needs one law and one chain end, got {len(by['law'])} and {len(by['end'])}")
        names = [b.name for b in blocks]
        if len(set(names)) != len(names) or {"i", "x", "counts"} & set(names):
            raise ValueError(f"block names must be unique and not i, x, counts: {names}")
        self.sense, self.actuators = by["sense"], by["actuator"]
        self.law_block, self.end = by["law"][0], by["end"][0]
        self.blocks = self.sense + [self.law_block] + self.actuators
        #: the held environment (an ``env`` block, at most one: its numbers are the plant's)
        self.env = by["env"][0] if by["env"] else None
        if len(by["env"]) > 1 or (self.env is not None and plant.rhs_held is None):
            raise ValueError("a composition holds at most one environment block, on a plant with rhs_held")
        #: the block that keeps the whole tick from being composed (a Python law, the LP
        #: mapping), or None; a per-tick executor still calls the parts around it
        self.blocker = off_path(self.blocks + [self.end])
        part = off_path(self.sense + [self.end])
        if part is not None:
            raise ValueError(f"block {part.name!r} is not symbolic ({part.why}): it cannot be composed")
        M = plant.meas_layout
        #: a field an actuator or the end reads that the measurement has not: the memory of the
        #: block whose state has that field, as the tick starts (what it decided the tick before)
        self.memory = {f: b for b in self.blocks for f in b.state.names}
        for a in self.actuators:  # an actuator reads the law's (or the true) measurement by field name
            for f in a.inputs.names:
                if f != "tau_B" and _field(f)[0] not in M and f not in self.memory:
                    raise KeyError(f"actuator block {a.name!r} reads {f!r}, the measurement has {M.names}")
        #: the end's inputs beyond its own (x, tau, u_ext): read from memory by name
        self.end_reads = [f for f in self.end.inputs.names if f not in ("x", "tau", "u_ext")]
        for f in self.end_reads:
            if f not in self.memory:
                raise KeyError(f"end block {self.end.name!r} reads {f!r}, no block's memory has it")
        self.ncmd = self.law_block.outputs.slice("cmd").stop
        #: the carry from tick to tick, by name: tick index in the chunk, plant state, counts of
        #: rate-limited and saturated ticks, then each block's memory under its name
        self.carry = Layout(i=1, x=plant.nx, counts=2, **{b.name: b.state.size for b in self.blocks},
                            **({self.env.name: self.env.state.size} if self.env is not None else {}))
        #: a chunk's parameters: first tick's time and index, step, active ticks, held external
        #: torque, the model's numbers, then each block's numbers under its name
        self.par = Layout(t0=1, h=1, n_act=1, k0=1, u_ext=3, p=plant.npar, **{b.name: b.params.size for b in self.blocks},
                          **({"edge": 4 * n_edges} if n_edges else {}))
        #: one tick's draws, by block
        self.noise = Layout(**{b.name: b.noise.size for b in self.blocks if b.noise.size})
        nact = self.end.outputs.slice("act").stop - self.end.outputs.slice("act").start
        #: one output row's values: the law's command and reference, the end's report, then the
        #: memory after the row's tick and the outputs of each sense block and the law
        self.row_layout = Layout(cmd=self.ncmd, act=nact, q_ref=4,
                                 **{b.name: b.state.size for b in self.sense + [self.law_block]},
                                 **{f"{b.name}_y": b.outputs.size for b in self.sense})
        self.key = (plant.key, tuple((b.name, b.role, b.every, b.key) for b in self.blocks + [self.end] +
                                     ([self.env] if self.env is not None else [])))
        if n_edges:
            self.key += (("edges", n_edges),)
        #: whether an actuator reads the true measurement (the front then evaluates it for them)
        self._truth = any(_field(f)[1] for a in self.actuators for f in a.inputs.names)
        #: an actuator without an idle form acts on every tick: no tick is quiet, so the front
        #: computes no quiet step (the busy tick's end and step on the request left are the
        #: quiet step's operations when nothing acts: the same numbers)
        self._never_quiet = any(a.idle is None for a in self.actuators)
        #: whether an actuator acts on the whole tick (its torque added to the held one, no edge)
        self._full_tick = any(a.full_tick for a in self.actuators)
        self._cache: dict = {}

    # -- the parts ----------------------------------------------------------------------------
    def _sense(self, k, t, h, y, c, w, par, plain: bool):
        """The sense blocks in order on the true measurement ``y``: (what the law sees, each
        block's memory after the tick, its outputs)."""
        C, P, N = self.carry, self.par, self.noise
        v, mem, outs = y, {}, {}
        for b in self.sense:
            wb = N.get(w, b.name) if b.name in N else type(y)(0, 1)
            x1, out = b.call(k, t, h, C.get(c, b.name), b.inputs.pack(y=v, symbolic=True), wb, P.get(par, b.name),
                             plain=plain)
            mem[b.name], outs[b.name] = x1, out
            v = b.outputs.get(out, "y_seen")
        return v, mem, outs

    def _law(self, k, t, h, v, c, par):
        b = self.law_block
        s1, out = b.call(k, t, h, self.carry.get(c, b.name), v, type(v)(0, 1), self.par.get(par, b.name))
        return b.outputs.get(out, "cmd"), b.outputs.get(out, "q_ref"), s1

    def _reads(self, a: Block, v, y, c):
        """What actuator ``a`` reads: fields of what the law sees ``v``, of the true measurement
        ``y`` for a ``<field>_true`` name (the actuator contract's rule 2), or of another block's
        memory in the carry ``c`` (a field no measurement has: :attr:`memory`)."""
        M = self.plant.meas_layout
        return [M.get(y if true else v, f) if f in M else self._recall(c, f)
                for f, true in map(_field, a.inputs.names) if f != "tau_B"]

    def _recall(self, c, f: str):
        """Field ``f`` of the memory of the block that keeps it, in the carry ``c``."""
        b = self.memory[f]
        return b.state.get(self.carry.get(c, b.name), f)

    def _end_extra(self, c) -> dict:
        return {f: self._recall(c, f) for f in self.end_reads}

    @property
    def _rhs(self):
        """The plant's right-hand side: without the held effects when an ``env`` block holds them."""
        return self.plant.rhs if self.env is None else self.plant.rhs_held

    def _u_ext(self, c, u_ext):
        """The held external torque of the tick: the scene's, plus the ``env`` block's held value."""
        if self.env is None:
            return u_ext
        return u_ext + self.env.state.get(self.carry.get(c, self.env.name), "L_hold")

    def _end(self, t, h, x, tau, u_ext, p, extra=None):
        e = self.end
        u = e.inputs.pack(x=x, tau=tau, u_ext=u_ext, **(extra or {}), symbolic=True)
        _, out = e.call(0, t, h, type(x)(0, 1), u, type(x)(0, 1), p)
        return e.outputs.get(out, "act"), e.outputs.get(out, "u"), e.outputs.get(out, "sat")

    def _chain(self, k, t, h, c, par, v, y, cmd):
        """The actuators in order on the law's request: (rest for the end, each one's memory
        after, on-times and torques of all channels)."""
        tau, mem, ons, tqs = cmd, {}, [], []
        for a in self.actuators:
            x1, out = a.call(k, t, h, self.carry.get(c, a.name), ca.vertcat(*self._reads(a, v, y, c), tau), type(cmd)(0, 1),
                             self.par.get(par, a.name))
            mem[a.name] = x1
            tau = a.outputs.get(out, "tau_rest_B")
            ons.append(a.outputs.get(out, "on_s"))
            tqs.append(a.outputs.get(out, "torque_B"))
        return tau, mem, ca.vertcat(*ons) if ons else type(cmd)(0, 1), ca.vertcat(*tqs) if tqs else type(cmd)(0, 1)

    def advance(self, t, x, h, u, p, on_s, torque_B, called: bool = False, edge=None):
        """One fixed step of the plant over ``[t, t + h]`` with the held input ``u``, cut at
        every pulse edge ``t + on_s[j]`` (channel j adds its ``torque_B`` column while on) and,
        in the edge tick's case, at the scene's edges ``edge`` (:func:`~.actuator.split_step`).
        ``called``: the pieces call one right-hand side rather than each inlining it (n + 1
        steps of 4 stages: the generated C and its compile time grow with them; the same
        operations, bit for bit)."""
        P = self.plant
        rhs = self._rhs
        if called:
            t_, x_, u_, p_ = ca.SX.sym("t"), ca.SX.sym("x", P.nx), ca.SX.sym("u", rhs.size1_in(2)), ca.SX.sym("p", P.npar)
            rhs = sx_function("cl_rhs", [t_, x_, u_, p_], [rhs(t_, x_, u_, p_)], called=True)
        if on_s.numel() == 0 and edge is None:
            return P.step(rhs, t, x, h, u, p)
        return split_step(P.step, rhs, t, x, h, u, p, on_s, ca.reshape(torque_B, 3, on_s.numel()), P.input_layout, edge)

    def _edge_args(self, par) -> list:
        """``[edge]`` in the edge tick's case, else none: the last input of ``cl_pulse``."""
        return [self.par.get(par, "edge")] if self.n_edges else []

    def _edge(self, par):
        """The edge tick's ``edge`` parameters in ``par`` (None: not the edge tick's case)."""
        return self.par.get(par, "edge") if self.n_edges else None

    def _step(self, t, x, h, u, p, edge=None):
        """One fixed step of the plant (SX), cut at the scene's edges ``edge`` in the edge tick's case."""
        if edge is None:
            return self.plant.step(self._rhs, t, x, h, u, p)
        return split_step(self.plant.step, self._rhs, t, x, h, u, p, ca.SX(0, 1), ca.SX(3, 0), self.plant.input_layout,
                          edge)

    # -- the tick -----------------------------------------------------------------------------
    def _front(self, plain: bool) -> ca.Function:
        """``(c, par, w) -> (c_quiet, busy, cmd, reads)`` of an active tick: measurement, sensing,
        law, the actuators' idle test, the quiet step (the law's request to the end) packed as
        the next carry. One SX function on a plain tick; else MX around two SX functions (the
        sensing's switches stay lazy): ``pre`` (the true measurement and every part of the rest
        that depends on the carry and parameters alone: the plant's stage-1 kinematics, computed
        once) and ``body`` (the rest, on what the sensing gives)."""
        C, P, N = self.carry, self.par, self.noise
        SX = ca.SX
        c, par = C.symbol("c"), P.symbol("par")
        x = C.get(c, "x")
        t0, h, k0, p = (P.get(par, f) for f in ("t0", "h", "k0", "p"))
        i = C.get(c, "i")
        t, k = t0 + i * h, k0 + i
        y = self.plant.meas(t, x, p)
        v_s = SX.sym("v", y.numel())
        mem_s = [b.state.symbol(b.name) for b in self.sense]
        outs = self._after(c, par, v_s, dict(zip((b.name for b in self.sense), mem_s)))
        if plain:
            w = N.symbol("w")
            v, mem, _ = self._sense(k, t, h, y, c, w, par, plain=True)
            outs = ca.substitute(outs, [v_s] + mem_s, [ca.densify(e) for e in [v] + [mem[b.name] for b in self.sense]])
            return sx_function("cl_front_plain", [c, par, w], outs)
        shared = ca.cse([y] + outs)
        rest, syms, vals = ca.extract_parametric(shared[1:], ca.vertcat(c, par))
        vals = closed_parametric(vals, syms)
        pre = sx_function("cl_pre", [c, par], [shared[0], ca.vertcat(*vals)])
        body = sx_function("cl_body", [ca.vertcat(*syms), c, par, v_s] + mem_s, rest)
        MX = ca.MX
        cm, pm, wm = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        im = C.get(cm, "i")
        tm, km = P.get(pm, "t0") + im * P.get(pm, "h"), P.get(pm, "k0") + im
        ym, valsm = pre(cm, pm)
        vm, memm, _ = self._sense(km, tm, P.get(pm, "h"), ym, cm, wm, pm, plain=False)
        return ca.Function("cl_front", [cm, pm, wm], body(valsm, cm, pm, vm, *[memm[b.name] for b in self.sense]))

    def _after(self, c, par, v, mem: dict) -> list:
        """The front after the sensing (SX): the law on what it sees ``v``, the actuators' idle
        test, the quiet step, the next carry with the sense blocks' memory ``mem``."""
        C, P = self.carry, self.par
        SX = ca.SX
        i, x, cnt = C.get(c, "i"), C.get(c, "x"), C.get(c, "counts")
        t0, h, k0, u_ext, p = (P.get(par, f) for f in ("t0", "h", "k0", "u_ext", "p"))
        t, k = t0 + i * h, k0 + i
        cmd, _, s1 = self._law(k, t, h, v, c, par)
        idle = SX(1)
        reads = []
        y = self.plant.meas(t, x, P.get(par, "p")) if self._truth else None  # the truth, for what reads it
        for a in self.actuators:
            r = self._reads(a, v, y, c)
            reads += r
            flag = a.idle(k, t, h, C.get(c, a.name), ca.vertcat(*r, cmd), P.get(par, a.name)) if a.idle is not None else 0
            idle = idle * flag
        if self._never_quiet:  # an actuator acts on every tick: the busy tick steps, no quiet step here
            fields = dict(i=i + 1, x=x, counts=cnt)
        else:
            _, u, sat = self._end(t, h, x, cmd, self._u_ext(c, u_ext), p, self._end_extra(c))
            x_q = self._step(t, x, h, u, p, self._edge(par))
            fields = dict(i=i + 1, x=x_q, counts=cnt + ca.vertcat(sat[0] > 0.5, sat[1] > 0.5))
        fields.update(mem)
        if self.env is not None:
            fields[self.env.name] = C.get(c, self.env.name)
        fields[self.law_block.name] = s1
        fields.update({a.name: C.get(c, a.name) for a in self.actuators})
        busy = 1 - idle if self.actuators else SX(0)
        return [C.pack(fields, symbolic=True), busy, cmd, ca.vertcat(*reads) if reads else SX(0, 1)]

    def _acted(self):
        """The busy tick's SX parts (cached): ``chain(k, t, h, c, par, cmd, reads) -> (rest,
        on_s, torque_B, same, memory of each actuator)`` (the actuators in order on symbols of
        their own: one graph, common parts shared; ``same``: nothing fires and the rest is the
        request), ``end(t, x, rest, u_ext, p, h) -> (u, sat)`` and ``pulse(fires, t, x, h, u, p,
        on_s, torque_B) -> x_next`` (the split step when a channel fires, else the plain one:
        explicit branches)."""
        hit = self._cache.get("acted")
        if hit is not None:
            return hit
        C, P = self.carry, self.par
        nr = sum(a.inputs.size - 3 for a in self.actuators)
        SX = ca.SX
        ts, hs, ks, cs, ps_, cmds, rs = SX.sym("t"), SX.sym("h"), SX.sym("k"), C.symbol("c"), P.symbol("par"), SX.sym("cmd", self.ncmd), SX.sym("r", nr)
        tau, mem, on_s, tq, full = cmds, {}, [], [], SX.zeros(3)
        at = 0
        for a in self.actuators:
            n_r = a.inputs.size - 3
            x1, out = a.call(ks, ts, hs, C.get(cs, a.name), ca.vertcat(rs[at: at + n_r], tau), SX(0, 1), P.get(ps_, a.name))
            at += n_r
            mem[a.name] = x1
            tau = a.outputs.get(out, "tau_rest_B")
            if a.full_tick:  # on the whole tick: added to the held torque, no edge
                full = full + ca.sum2(ca.reshape(a.outputs.get(out, "torque_B"), 3, -1))
            else:
                on_s.append(a.outputs.get(out, "on_s"))
                tq.append(a.outputs.get(out, "torque_B"))
        on_s, tq = ca.vertcat(SX(0, 1), *on_s), ca.vertcat(SX(0, 1), *tq)
        same = ca.logic_and(ca.sum1(on_s != 0) + ca.sum1(full != 0) == 0, ca.sum1(tau != cmds) == 0)
        chain = sx_function("cl_chain", [ks, ts, hs, cs, ps_, cmds, rs],
                            [tau, on_s, tq, same, full] + [mem[a.name] for a in self.actuators])
        # the end on the rest (SX), then the plain or the split step (explicit branches)
        xs_, rs_, us_ = SX.sym("x", self.plant.nx), SX.sym("rest", self.ncmd), SX.sym("u_ext", 3)
        pp = SX.sym("p", self.plant.npar)
        ex_s = {f: SX.sym(f, self.memory[f].state.shape(f)[0]) for f in self.end_reads}
        _, u_b, sat_b = self._end(ts, hs, xs_, rs_, us_, pp, ex_s)
        end_f = sx_function("cl_end", [ts, xs_, rs_, us_, pp, hs, *ex_s.values()], [u_b, sat_b])
        nch = on_s.numel()
        us, ons, tqs = SX.sym("u", u_b.numel()), SX.sym("on", nch), SX.sym("tq", 3 * nch)
        eds = [SX.sym("edge", 4 * self.n_edges)] if self.n_edges else []  # (the edge tick's case)
        plain = sx_function("cl_plain", [ts, xs_, hs, us, pp, ons, tqs, *eds], [self._step(ts, xs_, hs, us, pp, *eds)])
        split = sx_function("cl_split", [ts, xs_, hs, us, pp, ons, tqs, *eds],
                            [self.advance(ts, xs_, hs, us, pp, ons, tqs, called=True, edge=eds[0] if eds else None)])
        out = self._cache["acted"] = (chain, end_f, ca.Function.if_else("cl_pulse", split, plain), nr, nch)
        return out

    def _busy(self) -> ca.Function:
        """``(c, par, c_quiet, cmd, reads) -> c_next`` of a tick whose chain is not idle: the
        actuators in order; when nothing fires and the end gets the law's request unchanged, the
        quiet step is the tick's (same inputs, same operations); else the end on the rest and a
        plain step, or the step split at the pulse edges (only if one fires)."""
        C, P = self.carry, self.par
        MX = ca.MX
        chain, end_f, pulse, nr, nch = self._acted()
        c, par, cq, cmd, reads = C.symbol("c", MX), P.symbol("par", MX), C.symbol("q", MX), MX.sym("cmd", self.ncmd), MX.sym("r", nr)
        i, x, cnt = C.get(c, "i"), C.get(c, "x"), C.get(c, "counts")
        t0, h, k0, u_ext, p = (P.get(par, f) for f in ("t0", "h", "k0", "u_ext", "p"))
        t, k = t0 + i * h, k0 + i
        if self._never_quiet:  # each actuator behind its own idle test (a never-quiet chain keeps their skips)
            rest, on, tqq, full_c, xa = self._chain_lazy(k, t, h, c, par, cmd, reads)
            same_c = None
        else:
            rest, on, tqq, same_c, full_c, *xa = chain(k, t, h, c, par, cmd, reads)
        ar, aon, atq, afull = MX.sym("rest", self.ncmd), MX.sym("on", nch), MX.sym("tq", 3 * nch), MX.sym("full", 3)
        a_in = [c, par, cq, ar, aon, atq, afull]
        held = self._u_ext(c, u_ext)
        uu, fl = end_f(t, x, ar, held + afull if self._full_tick else held, p, h, *self._end_extra(c).values())
        x_b = pulse(ca.sum1(aon) > 0, t, x, h, uu, p, aon, atq, *self._edge_args(par))
        acted = ca.Function("cl_acted", a_in, [ca.vertcat(x_b, cnt + ca.vertcat(fl[0] > 0.5, fl[1] > 0.5))])
        kept = ca.Function("cl_kept", a_in, [ca.vertcat(C.get(cq, "x"), C.get(cq, "counts"))])
        if self._never_quiet:  # no quiet step to keep: the end and the step on what the chain leaves
            head = acted(c, par, cq, rest, on, tqq, full_c)  # (same_c unused)
        else:
            head = ca.Function.if_else("cl_same", kept, acted)(same_c, c, par, cq, rest, on, tqq, full_c)
        fields = {f: C.get(cq, f) for f in C.names}
        fields["x"], fields["counts"] = head[: self.plant.nx], head[self.plant.nx:]
        fields.update({a.name: m for a, m in zip(self.actuators, xa)})
        return ca.Function("cl_busy", [c, par, cq, cmd, reads], [C.pack(fields, symbolic=True)])

    def _chain_lazy(self, k, t, h, c, par, cmd, reads):
        """The chain as one call per actuator (MX around each one's SX step), an actuator with
        an idle form behind a ``Function.if_else`` on it: where it is idle its exact idle form
        (memory kept, request passed on, no channel on) and its command is not evaluated. For a
        chain that is never quiet (an actuator without an idle form acts on every tick), so
        the others still skip their ticks of nothing. ``(rest, on_s, torque_B, full, memories)``."""
        C, P, SX, MX = self.carry, self.par, ca.SX, ca.MX
        tau, at, on_s, tq, full, mem = cmd, 0, [], [], MX.zeros(3), []
        for a in self.actuators:
            n_r = a.inputs.size - 3
            ks, ts, hs, xs, rs, taus, ps = (SX.sym("k"), SX.sym("t"), SX.sym("h"), a.state.symbol("x"), SX.sym("r", n_r),
                                            SX.sym("tau", 3), a.params.symbol("p"))
            ins = [ks, ts, hs, xs, rs, taus, ps]
            x1, out = a.call(ks, ts, hs, xs, ca.vertcat(rs, taus), SX(0, 1), ps)
            on, tqa = a.outputs.get(out, "on_s"), a.outputs.get(out, "torque_B")
            f = sx_function(f"cl_{a.name}", ins, [x1, a.outputs.get(out, "tau_rest_B"), on, tqa])
            args = [k, t, h, C.get(c, a.name), reads[at: at + n_r], tau, P.get(par, a.name)]
            at += n_r
            if a.idle is not None:
                idle = sx_function(f"cl_{a.name}_idle", ins, [a.idle(ks, ts, hs, xs, ca.vertcat(rs, taus), ps)])
                kept = ca.Function(f"cl_{a.name}_kept", ins, [xs, taus, SX.zeros(on.numel()), SX.zeros(tqa.numel())])
                x1, tau, on, tqa = ca.Function.if_else(f"cl_{a.name}_lazy", kept, f)(idle(*args), *args)
            else:
                x1, tau, on, tqa = f(*args)
            mem.append(x1)
            if a.full_tick:
                full = full + ca.sum2(ca.reshape(tqa, 3, -1))
            else:
                on_s.append(on)
                tq.append(tqa)
        return tau, ca.vertcat(MX(0, 1), *on_s), ca.vertcat(MX(0, 1), *tq), full, mem

    def _env_step(self, c, par):
        """The carry with the ``env`` block stepped where a block of its ``every`` ticks starts
        (``i % every == 0``, inside the active ticks: blocks start at each chunk's first tick),
        held otherwise: an explicit branch, so the generated C evaluates it only when due."""
        C, P = self.carry, self.par
        e = self.env
        MX = ca.MX
        cs, ps = C.symbol("c", MX), P.symbol("par", MX)
        i, n_act = C.get(cs, "i"), P.get(ps, "n_act")
        t, h, k = P.get(ps, "t0") + i * P.get(ps, "h"), P.get(ps, "h"), P.get(ps, "k0") + i
        n_b = ca.fmin(e.every, ca.fmax(n_act - i, 0))  # the block's active ticks
        x1, _ = e.call(k, t, h, C.get(cs, e.name), ca.vertcat(C.get(cs, "x"), n_b), MX(0, 1), P.get(ps, "p"))
        fields = {f: C.get(cs, f) for f in C.names}
        fields[e.name] = x1
        due = ca.Function("cl_env_due", [cs, ps], [C.pack(fields, symbolic=True)])
        keep = ca.Function("cl_env_keep", [cs, ps], [cs])
        i0, na0 = C.get(c, "i"), P.get(par, "n_act")
        return ca.Function.if_else("cl_env", due, keep)(ca.logic_and(ca.fmod(i0, e.every) == 0, i0 < na0), c, par)

    def tick(self) -> ca.Function:
        """``(c, par, w) -> c_next``: one tick, its case chosen (module docstring); a tick past
        the chunk's active ticks (``i >= n_act``) holds the carry (its index counts on)."""
        hit = self._cache.get("tick")
        if hit is not None:
            return hit
        self._whole()
        C, P, N = self.carry, self.par, self.noise
        MX = ca.MX
        c, par, w = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        i, n_act, k0 = C.get(c, "i"), P.get(par, "n_act"), P.get(par, "k0")
        nr = sum(a.inputs.size - 3 for a in self.actuators)
        held = C.pack({**{f: C.get(c, f) for f in C.names}, "i": i + 1}, symbolic=True)  # (its index counts on)
        hold = ca.Function("cl_hold", [c, par, w], [held, MX(0), MX.zeros(self.ncmd), MX.zeros(nr)])
        general = self._front(plain=False)
        plains = [b for b in self.sense if b.plain is not None]
        sometimes = [b for b in plains if b.is_plain is not None]  # (is_plain None: plain on every tick)
        if len(plains) == len(self.sense) and not sometimes:  # no switch to keep lazy: one SX function
            front = ca.Function.if_else("cl_active", self._front(plain=True), hold)(i < n_act, c, par, w)
        elif len(plains) == len(self.sense):
            flag = sometimes[0].is_plain(k0 + i)
            for b in sometimes[1:]:
                flag = ca.logic_and(flag, b.is_plain(k0 + i))
            cases = ca.Function.conditional("cl_cases", [hold, general, self._front(plain=True)], hold)
            front = cases((i < n_act) * (1 + flag), c, par, w)
        else:
            front = ca.Function.if_else("cl_active", general, hold)(i < n_act, c, par, w)
        cq, busy, cmd, reads = front
        if self.actuators:
            q_s = MX.sym("q", C.size)
            b_in = [c, par, q_s, MX.sym("cmd", self.ncmd), MX.sym("r", nr)]
            pas = ca.Function("cl_pass", b_in, [q_s])
            c_new = ca.Function.if_else("cl_tick", self._busy(), pas)(busy, c, par, cq, cmd, reads)
        else:
            c_new = cq
        f = ca.Function("cl_step", [c, par, w], [c_new], {"always_inline": True})
        if self.env is not None:  # the held environment first: evaluated at a block's first tick, else passed on
            c2, par2, w2 = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
            f = ca.Function("cl_step", [c2, par2, w2], [f(self._env_step(c2, par2), par2, w2)], {"always_inline": True})
        self._cache["tick"] = f
        return f

    def chunk(self, n: int) -> ca.Function:
        """``(c0, par, noise (width, n)) -> c_n``: ``n`` ticks in one ``mapaccum`` (column j: tick
        j's draws; ticks past ``par.n_act`` hold)."""
        MX = ca.MX
        acc = self.tick().mapaccum("cl_acc", n)
        c0, par, wm = MX.sym("c0", self.carry.size), MX.sym("par", self.par.size), MX.sym("noise", self.noise.size, n)
        return ca.Function("cl_chunk", [c0, par, wm], [acc(c0, ca.repmat(par, 1, n), wm)[:, -1]])

    def row(self) -> ca.Function:
        """``(c, par, w) -> row`` (:attr:`row_layout`) at the chunk's first tick (``i`` = 0; ``h``
        the tick's length): the law's command and reference, the end's report on what the chain
        leaves it, the memory after the tick and the outputs of the sense blocks and the law."""
        self._whole()
        C, P, N = self.carry, self.par, self.noise
        MX = ca.MX
        c, par, w = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        x = C.get(c, "x")
        t, h, k, u_ext, p = (P.get(par, f) for f in ("t0", "h", "k0", "u_ext", "p"))
        y = self.plant.meas(t, x, p)
        v, mem, outs = self._sense(k, t, h, y, c, w, par, plain=False)
        cmd, q_ref, s1 = self._law(k, t, h, v, c, par)
        rest, _, _, _ = self._chain(k, t, h, c, par, v, y, cmd)
        act, _, _ = self._end(t, h, x, rest, u_ext, p, self._end_extra(c))
        vals = dict(cmd=cmd, act=act, q_ref=q_ref, **{b.name: mem[b.name] for b in self.sense})
        vals[self.law_block.name] = s1
        vals.update({f"{b.name}_y": outs[b.name] for b in self.sense})
        return ca.Function("cl_row", [c, par, w], [self.row_layout.pack(vals, symbolic=True)])


    def _whole(self) -> None:
        if self.blocker is not None:
            raise ValueError(f"block {self.blocker.name!r} is not symbolic ({self.blocker.why}): "
                             "the tick cannot be composed")

def _field(name: str) -> tuple[str, bool]:
    """``(measurement field, whether it is the truth's)`` of an actuator input's name: a name
    ending in ``_true`` reads the true measurement (the actuator contract's rule 2)."""
    return (name[: -len(TRUE_SUFFIX)], True) if name.endswith(TRUE_SUFFIX) else (name, False)
