"""The composed tick's parts a per-tick executor calls around a law it calls itself (issue 33):
:meth:`~.compose.Composed.sense_part` and :meth:`~.compose.Composed.act_part`, a mixin of
:class:`~.compose.Composed` (it reads the composition's layouts, blocks and private cases)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.compile import sx_function
from ..core.layout import Layout
from .block import off_path

__all__ = ["PartsMixin"]


class PartsMixin:
    """The per-tick parts of :class:`~.compose.Composed`."""

    # -- the parts a per-tick executor calls around a law it calls itself ----------------------
    def sense_part(self) -> ca.Function:
        """``(c, par, w) -> (c_sensed, v, outs)`` at the carry's tick (``t0 + i h``, ``k0 + i``):
        the true measurement, the sense blocks in order on the tick's draws ``w``; ``c_sensed``
        the carry with their memory after it, ``v`` what the law sees, ``outs`` their outputs
        (each block's under its name: :attr:`sense_outputs`)."""
        C, P, N = self.carry, self.par, self.noise
        MX = ca.MX
        c, par, w = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        return ca.Function("cl_sense", [c, par, w], list(self._sensed(c, par, w, C.get(c, "i"), C.get(c, "x"))))

    @property
    def sense_outputs(self) -> Layout:
        """The sense blocks' outputs side by side, each under its name (:meth:`sense_part`)."""
        return Layout(**{b.name: b.outputs.size for b in self.sense})

    def sense_on_part(self) -> ca.Function:
        """``(c, par, y, w) -> (c_sensed, v, outs)``: :meth:`sense_part` on the true measurement
        ``y`` it is handed (an executor that measures the plant itself: the generic path)."""
        C, P, N = self.carry, self.par, self.noise
        MX = ca.MX
        c, par, w = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        y = MX.sym("y", self.plant.meas_layout.size)
        return ca.Function("cl_sense_on", [c, par, y, w], list(self._sensed(c, par, w, C.get(c, "i"), C.get(c, "x"), y)))

    def _sensed(self, c, par, w, i, x, y=None):
        if y is None and self._sense_case() is not None:  # the plain tick's sensing where it applies
            return tuple(self._sense_case()(c, par, w))
        C, P = self.carry, self.par
        t, k = P.get(par, "t0") + i * P.get(par, "h"), P.get(par, "k0") + i
        if y is None:
            y = self.plant.meas(t, x, P.get(par, "p"))
        v, mem, outs = self._sense(k, t, P.get(par, "h"), y, c, w, par, plain=False)
        fields = {f: C.get(c, f) for f in C.names}
        fields.update(mem)
        outs = ca.vertcat(*(outs[b.name] for b in self.sense)) if self.sense else type(x)(0, 1)
        return C.pack(fields, symbolic=True), v, outs

    def _sense_case(self) -> ca.Function | None:
        """``(c, par, w) -> (c_sensed, v, outs)`` at the carry's tick as the fused tick chooses
        its front (:meth:`~.compose.Composed.tick`): on a plain tick (every sense block has a
        plain form and its ``is_plain``) the plain sensing as one SX function, else the general
        one (the switches lazy); an explicit branch, so the generated C evaluates only the case
        taken. None where there is no such choice (no sense block without a plain form on every
        tick). The plain forms are exact: the same numbers as the general sensing."""
        if "sense_case" in self._cache:
            return self._cache["sense_case"]
        plains = [b for b in self.sense if b.plain is not None]
        sometimes = [b for b in plains if b.is_plain is not None]
        if not self.sense or len(plains) < len(self.sense) or not sometimes:
            self._cache["sense_case"] = None
            return None
        C, P, N = self.carry, self.par, self.noise

        def sensed(cls, plain):
            c, par, w = C.symbol("c", cls), P.symbol("par", cls), N.symbol("w", cls)
            i, x, h = C.get(c, "i"), C.get(c, "x"), P.get(par, "h")
            t, k = P.get(par, "t0") + i * h, P.get(par, "k0") + i
            v, mem, outs = self._sense(k, t, h, self.plant.meas(t, x, P.get(par, "p")), c, w, par, plain=plain)
            fields = {f: C.get(c, f) for f in C.names}
            fields.update(mem)
            out = [C.pack(fields, symbolic=True), v, ca.vertcat(*(outs[b.name] for b in self.sense))]
            if plain:  # (dense: the two cases' outputs must have one sparsity)
                return sx_function("cl_sense_plain", [c, par, w], [ca.densify(e) for e in out])
            return ca.Function("cl_sense_general", [c, par, w], out)

        MX = ca.MX
        c, par, w = C.symbol("c", MX), P.symbol("par", MX), N.symbol("w", MX)
        k = P.get(par, "k0") + C.get(c, "i")
        flag = sometimes[0].is_plain(k)
        for b in sometimes[1:]:
            flag = ca.logic_and(flag, b.is_plain(k))
        case = ca.Function.if_else("cl_sense_case", sensed(ca.SX, True), sensed(MX, False))
        f = self._cache["sense_case"] = ca.Function("cl_sensed", [c, par, w], case(flag, c, par, w))
        return f

    def _acted_plain(self, c, par, cmd):
        """The rest of a tick without actuators (SX): the end on the law's request, one step;
        ``(c_next, act, x_next)``."""
        C, P = self.carry, self.par
        i, x, cnt = C.get(c, "i"), C.get(c, "x"), C.get(c, "counts")
        t0, h, u_ext, p = (P.get(par, f) for f in ("t0", "h", "u_ext", "p"))
        t = t0 + i * h
        act, u, sat = self._end(t, h, x, cmd, self._u_ext(c, u_ext), p, self._end_extra(c))
        x1 = self._step(t, x, h, u, p, self._edge(par))
        fields = {f: C.get(c, f) for f in C.names}
        fields.update(i=i + 1, x=x1, counts=cnt + ca.vertcat(sat[0] > 0.5, sat[1] > 0.5))
        return C.pack(fields, symbolic=True), act, x1

    def act_part(self) -> ca.Function:
        """``(c, par, cmd, v, w) -> (c_next, c_sensed, v_next, outs, act)``: the rest of the
        carry's tick on the law's command ``cmd`` (it saw ``v``): the ``env`` block where due,
        the actuators in order, the end, one fixed step cut at the pulse edges (the busy tick's
        parts, :meth:`_acted`); ``c_next`` the carry at the next tick (``i + 1``), ``act`` the
        end's report; then :meth:`sense_part` at the next tick on its draws ``w``
        (``c_sensed``, ``v_next``, ``outs``: valid when that tick has the same parameters)."""
        if off_path(self.actuators):
            raise ValueError(f"block {off_path(self.actuators).name!r} is not symbolic ({off_path(self.actuators).why})")
        C, P, N = self.carry, self.par, self.noise
        MX = ca.MX
        c, par, cmd, w = C.symbol("c", MX), P.symbol("par", MX), MX.sym("cmd", self.ncmd), N.symbol("w", MX)
        v = MX.sym("v", self.plant.meas_layout.size)
        ce = self._env_step(c, par) if self.env is not None else c
        if not self.actuators:  # one SX function (the right-hand side inlined where it is small)
            SX = ca.SX
            css, pss, cms = C.symbol("c"), P.symbol("par"), SX.sym("cmd", self.ncmd)
            c1s, acts, x1s = self._acted_plain(css, pss, cms)
            outs_s = [c1s, acts] + ([] if self.sense else [self.plant.meas(P.get(pss, "t0") + C.get(c1s, "i") * P.get(pss, "h"),
                                                                          x1s, P.get(pss, "p"))])
            c1, act, *y1 = sx_function("cl_core", [css, pss, cms], outs_s)(ce, par, cmd)
        else:
            i, x, cnt = C.get(ce, "i"), C.get(ce, "x"), C.get(ce, "counts")
            t0, h, k0, u_ext, p = (P.get(par, f) for f in ("t0", "h", "k0", "u_ext", "p"))
            t, k = t0 + i * h, k0 + i
            chain, _, pulse, _, _ = self._acted()
            y = self.plant.meas(t, x, p) if self._truth else None  # the truth, for what reads it
            reads = [r for a in self.actuators for r in self._reads(a, v, y, ce)]
            reads = ca.vertcat(*reads) if reads else MX(0, 1)
            rest, on, tq, full, xa = self._chain_lazy(k, t, h, ce, par, cmd, reads)
            held = self._u_ext(ce, u_ext)  # (plus the torque of the actuators on the whole tick)
            act, u, sat = self._end(t, h, x, rest, held + full if self._full_tick else held, p, self._end_extra(ce))
            x1 = pulse(ca.sum1(on) > 0, t, x, h, u, p, on, tq, *self._edge_args(par))
            fields = {f: C.get(ce, f) for f in C.names}
            fields.update({a.name: m for a, m in zip(self.actuators, xa)})
            fields.update(i=i + 1, x=x1, counts=cnt + ca.vertcat(sat[0] > 0.5, sat[1] > 0.5))
            c1, y1 = C.pack(fields, symbolic=True), []
        if self.sense or not y1:
            cs, v1, outs = self._sensed(c1, par, w, C.get(c1, "i"), C.get(c1, "x"))
        else:
            cs, v1, outs = c1, y1[0], MX(0, 1)
        return ca.Function("cl_act", [c, par, cmd, v, w], [c1, cs, v1, outs, act])

    # -- the chain, block by block, for an executor that integrates itself (the generic path) ---
    @property
    def chain(self) -> list:
        """The actuators in order, then the end."""
        return self.actuators + [self.end]

    def chain_pieces(self) -> list[tuple[int, int]]:
        """:attr:`chain` cut around each block that is not symbolic: ``(lo, hi)`` index ranges in
        order, each either symbolic blocks (:meth:`chain_part`) or one block that is not
        (:meth:`python_step`)."""
        out, lo = [], 0
        for j, b in enumerate(self.chain):
            if not b.symbolic:
                out += ([(lo, j)] if j > lo else []) + [(j, j + 1)]
                lo = j + 1
        return out + ([(lo, len(self.chain))] if lo < len(self.chain) else [])

    def chain_part(self, lo: int, hi: int) -> ca.Function:
        """``(c, par, tau, v, y) -> (c_next, rest, on_s, torque_B, act, u, sat)``: the symbolic
        blocks ``chain[lo:hi]`` in order at the carry's tick on the request ``tau`` (what the law
        saw ``v``, the true measurement ``y``): ``c_next`` the carry with their memory after,
        ``rest`` what they leave, ``on_s`` and ``torque_B`` their channels' (3 per channel,
        column-major); ``act``, ``u``, ``sat`` the end's report, the plant's held input (its
        ``u_ext`` the parameters' plus the end's torque) and (rate limited, saturated) on what
        is left, when the end is among them (else empty)."""
        C, P, M = self.carry, self.par, self.plant.meas_layout
        MX = ca.MX
        blocks = self.chain[lo:hi]
        if off_path(blocks):
            raise ValueError(f"block {off_path(blocks).name!r} is not symbolic ({off_path(blocks).why})")
        n_in = 3 if blocks[0] is not self.end else self.ncmd
        c, par, tau0, v, y = C.symbol("c", MX), P.symbol("par", MX), MX.sym("tau", n_in), MX.sym("v", M.size), MX.sym("y", M.size)
        i, x = C.get(c, "i"), C.get(c, "x")
        t0, h, k0, u_ext, p = (P.get(par, f) for f in ("t0", "h", "k0", "u_ext", "p"))
        t, k = t0 + i * h, k0 + i
        fields = {f: C.get(c, f) for f in C.names}
        tau, ons, tqs, end = tau0, [MX(0, 1)], [MX(0, 1)], [MX(0, 1)] * 3
        for b in blocks:
            if b is self.end:
                end = self._end(t, h, x, tau, self._u_ext(c, u_ext), p, self._end_extra(c))
                continue
            x1, out = b.call(k, t, h, C.get(c, b.name), ca.vertcat(*self._reads(b, v, y, c), tau), MX(0, 1), P.get(par, b.name))
            fields[b.name], tau = x1, b.outputs.get(out, "tau_rest_B")
            ons.append(b.outputs.get(out, "on_s"))
            tqs.append(b.outputs.get(out, "torque_B"))
        return ca.Function(f"cl_chain_{lo}_{hi}", [c, par, tau0, v, y],
                           [C.pack(fields, symbolic=True), tau, ca.vertcat(*ons), ca.vertcat(*tqs), *end])

    def python_step(self, j: int, c, par, tau, v, y):
        """Block ``chain[j]``, not symbolic, numerically at the carry's tick (its Python step,
        :attr:`~.block.Block.python`) on the request ``tau``: ``(its memory after, rest, on_s,
        torque_B)`` (numpy; ``v``, ``y`` as :meth:`chain_part`)."""
        C, P = self.carry, self.par
        b = self.chain[j]
        i = C.get(c, "i")[0]
        t0, h, k0 = (P.get(par, f)[0] for f in ("t0", "h", "k0"))
        u = np.concatenate([*self._reads(b, v, y, c), tau])
        x1, out = b.python(k0 + i, t0 + i * h, h, C.get(c, b.name), u, P.get(par, b.name))
        return x1, b.outputs.get(out, "tau_rest_B"), b.outputs.get(out, "on_s"), b.outputs.get(out, "torque_B")
