"""The lockstep batch executor: many samples of one compiled system advance together, one
control period per step, the law called once per tick for all of them (issue 22).

Per tick: the law's :meth:`~.controller.Controller.update_batch` (every measurement field with a
leading sample axis; a law with only a ``symbolic`` form: that form compiled and mapped over the
samples, :mod:`.law_compiled`) -> the composed tick's compiled ``act`` part mapped over the
samples (casadi ``Function.map`` of the very function the per-tick loop calls, :mod:`.parts`:
the held environment, the actuator chain, its end, one fixed step, the next tick's measurement
and sensing, the ideal measurement's delay and noise; the map calls that machine code once per
sample, so a sample's numbers are its single run's, bit for bit) -> rows at the output ticks
(each sample's own :class:`~.rows.Rows` and metrics). Each sample keeps its own numbers, carry,
draws (its own streams: :class:`~.blocks.Draws`) and pieces (its rows cut at its own
edges on the tick grid, as :func:`~.segments.tick_pieces` cuts them for every executor); its
scheduled steps (faults, docking events: :mod:`.schedule`, ``lockstep_hook``) apply where its
piece starts (every step's tick starts one), on its own row of the carry and the numbers.

A tick holding a discontinuity between ticks is a piece of its own, the edge tick's compiled
case mapped too (its results taken for the samples in one); a fault detected mid-run designs
the sample's law again at its tick (``lockstep_hook``). A sample whose single run cannot step
the composed parts (an array rate step, an actuator that is not symbolic, ``[fdir]``, a
detection with a law's own ``update_batch``) runs its own :class:`~.closed_loop.ControlLoop`. A sample that fails (a bad or non-finite command, the law
raising, a non-finite state) stops alone, with its single run's reason and time; the batch goes on.

:func:`executor` says which executor a run gets: ``fused`` (a law with ``symbolic``, where the
fused loop applies), ``batch`` (the composed parts, :func:`~.blocks.parts_ok`) or ``per-tick``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..integrators.dop853_batch import mapped
from .closed_loop import ControlLoop, ControllerFailure
from .controller import BatchMeasurement, Controller
from .fused import fused_ok
from .blocks import Draws, held_rate, numbers, parts_ok, structure_key
from .law_state import law_numbers
from .parts import NOISE_BLOCK, parts
from .prepare import prepare
from .rows import Rows
from .schedule import lockstep_hook
from .segments import breakpoints, edge_ticks, held_torque_from, max_edges, off_grid_ticks, tick_edges, tick_pieces

__all__ = ["executor", "run_lockstep", "vectorised"]


def vectorised(ctrl) -> bool:
    """Whether the law overrides :meth:`Controller.update_batch` or has a ``symbolic`` form
    (evaluated compiled for every sample at once), else the default loops."""
    return type(ctrl).update_batch is not Controller.update_batch or ctrl.has_symbolic()


def _tick_ok(comp) -> bool:
    # a run the per-tick loop flies on the composed parts (blocks.parts_ok: one fixed step per
    # tick, every actuator symbolic) runs them mapped; a fault detected mid-run (run/detection.py)
    # too, its law designing again at its tick (schedule.lockstep_hook), except with a law that
    # writes its own update_batch (its batch stand-in holds copies of the members' numbers)
    own_batch = type(comp.ctrl).update_batch is not Controller.update_batch
    return not (comp.replan is not None and own_batch) and parts_ok(comp) is None


def executor(loop) -> str:
    """``"fused"``, ``"batch"`` or ``"per-tick"``: the executor a sample of ``loop`` (a
    :class:`~.closed_loop.ControlLoop`) runs on. The batch only for a law that is
    :func:`vectorised`: with the default ``update_batch`` (each member's ``update`` in a Python
    loop) the law's Python is per sample either way, and the batch's own per-tick numpy on top
    made it 1.09-1.28x the per-tick loop's CPU in groups of 4-16 (docs/speed.md, "The lockstep
    batch")."""
    if loop.fused and fused_ok(loop.comp):
        return "fused"
    if _tick_ok(loop.comp) and vectorised(loop.comp.ctrl):
        return "batch"
    return "per-tick"


class _Sample:
    """One sample's set-up, as :func:`~.simulation.simulate` makes it (its own loop and rows)."""

    def __init__(self, scene, sink, keep, fused, calls: dict | None = None):
        shared = FastCall._cache
        # this sample's own compiled-call buffers (parameters, state), not shared with a sample
        # of its lockstep batch: new ones, or ``calls``, those of a sample that is done with them
        FastCall._cache = {} if calls is None else calls
        try:
            self._setup(scene, sink, keep, fused)
        finally:
            FastCall._cache = shared

    def _setup(self, scene, sink, keep, fused):
        sim = scene.simulation
        run = prepare(scene, sim.formulation, sim.integrator, rtol=sim.rtol, atol=sim.atol)
        self.scene, self.run = scene, run
        system, p = run.system, run.p
        self.rows = Rows(scene, system, p, sink, keep)
        duration = sim.duration
        bps, steps = breakpoints(scene, duration)
        form, funcs = system.formulation, system.funcs
        jump = FastCall.of(funcs["jump"]) if (form.omega_is_state and steps and sim.impulse_jump) else None

        def apply_jump(t, x):
            if jump is None or t not in steps:
                return x
            a = jump.args
            a[0][0] = t * (1.0 - 1e-15) - 1e-300
            a[1][0] = t
            a[2][:] = x
            a[3][:] = p
            jump()
            return jump.res[0].copy()

        self.meta = {"scene": scene.name, "formulation": form.name, "integrator": system.integrator_cls.name,
                     "rtol": sim.rtol, "atol": sim.atol, "build_s": system.build_s, "evaluator": system.evaluator}
        self.loop = ControlLoop(scene, system, run.integrator, p, run.x0.copy(), self.rows, duration,
                                sim.output_dt, bps, apply_jump, None, fused)
        self.kind = executor(self.loop)


def run_lockstep(scenes, *, sinks=None, fused: bool = True, keep: bool = False):
    """Run the closed-loop ``scenes`` (samples of one study), those that can in lockstep.

    Returns, per scene in order, ``(kind, result)``: the executor (``fused``, ``batch``,
    ``per-tick``; ``open-loop`` without a ``[controller]``; :func:`executor`'s choice, so a
    sample's kind does not depend on the others: a ``batch`` sample alone in its group runs the
    per-tick loop, the same calls) and a :class:`~.trajectory.Trajectory` or the exception the single run would
    have raised (a :class:`~.simulation.SimulationError` with its partial trajectory).
    ``sinks``: per scene a row sink (as :func:`~.simulation.simulate`'s ``sink``) or None.
    Samples that cannot run in lockstep run one by one, each through its own loop as
    :func:`~.simulation.simulate` runs it (fused or per tick)."""
    from .simulation import SimulationError, simulate  # noqa: PLC0415 - simulation imports this module's peers

    out: list = [None] * len(scenes)
    groups: dict[tuple, list[int]] = {}
    samples: dict[int, _Sample] = {}
    sinks = [None] * len(scenes) if sinks is None else list(sinks)
    # the compiled-call buffers of the last sample that ran on its own (it is done with them: the
    # next sample takes them over, as simulate's runs share the process's, instead of ~0.6 ms of
    # new ones per sample); a sample of a lockstep batch keeps its own
    spare: dict = {}
    for i, s in enumerate(scenes):
        if s.controller is None:  # open loop: simulate's own path
            try:
                out[i] = ("open-loop", simulate(s, keep=keep, sink=sinks[i]))
            except Exception as e:  # noqa: BLE001
                out[i] = ("open-loop", e)
            continue
        try:
            smp = _Sample(s, sinks[i], keep, fused, spare)
        except Exception as e:  # noqa: BLE001 - the single run raises the same: recorded per sample
            out[i] = ("per-tick", e)
            continue
        if smp.kind == "batch":
            spare = {}
        else:  # fused or per tick: this sample's own loop, as simulate runs it
            try:
                out[i] = (smp.kind, _single(smp, SimulationError))
            except Exception as e:  # noqa: BLE001
                out[i] = (smp.kind, e)
            continue
        sim = s.simulation
        comp = smp.loop.comp
        key = (structure_key(comp, law_numbers(comp.ctrl)), sim.duration, sim.output_dt, comp.period)
        groups.setdefault(key, []).append(i)
        samples[i] = smp
    for idx in groups.values():
        if len(idx) == 1:  # alone: the per-tick loop is the same work (the same calls, the same numbers),
            i = idx[0]     # labelled "batch", its executor: a sample's label cannot depend on who shares its chunk
            out[i] = ("batch", _single(samples[i], SimulationError))
            continue
        for i, res in zip(idx, _Lockstep([samples[i] for i in idx]).run(SimulationError)):
            out[i] = ("batch", res)
    return out


def _single(smp: _Sample, SimulationError):
    loop = smp.loop
    t0 = time.perf_counter()
    try:
        loop.run()
    except (IntegrationError, ControllerFailure) as e:
        smp.meta.update(status="failed", stopped_at=e.t, summary=loop.summary())
        err = SimulationError(e.t, e.reason, smp.rows.trajectory(smp.meta))
        err.__cause__ = e.__cause__
        return err
    return _done(smp, time.perf_counter() - t0)


def _done(smp: _Sample, wall: float):
    integ = smp.loop.comp.integ
    smp.meta.update(status="ok", wall_s=wall, n_rhs=integ.n_rhs, n_steps=integ.n_steps)
    smp.meta["summary"] = smp.loop.summary()
    return smp.rows.trajectory(smp.meta)


class _Lockstep:
    """The samples of one group (one composed structure, law class, duration, period) in
    lockstep: the composed parts (:mod:`.parts`) mapped over the samples, each sample with its
    own numbers, carry, pieces and draws."""

    def __init__(self, samples: list[_Sample]):
        self.S = samples
        n = self.n = len(samples)
        lp = samples[0].loop.comp  # (every sample's composition has the same structure)
        self.ncmd, self.has_act = lp.n_cmd, lp.has_cluster
        out = lp.end.outputs  # the chain end's reported values (act)
        self.i_u = out.slice("u_cmg") if self.has_act else None
        self.i_flags = slice(out.slice("rate_limited").start, out.slice("saturated").stop) if self.has_act else None
        self.cps = [law_numbers(s.loop.comp.ctrl) for s in samples]
        fns = parts(lp, self.cps[0])
        self.cm = cm = fns["cm"]
        # the parts mapped over the samples: casadi's map calls the very machine code once per sample
        self.sense = mapped(fns["sense"].f, n, 1)
        self.act = mapped(fns["act"].f, n, 1)
        # the edge tick's case (a discontinuity inside a tick), mapped too: run on the ticks where a
        # sample is in one (each such tick a piece of its own), its results taken for those samples
        self.act_edge = mapped(fns["act_edge"].f, n, 1) if fns.get("act_edge") is not None else None
        self.edge_at = [off_grid_ticks(s.loop.comp) for s in samples]
        self.edge_now: dict[int, np.ndarray] = {}  # sample -> its current piece's edges
        C, P = cm.carry, cm.par
        nw, ny, ns = cm.noise.size, lp.meas_layout.size, cm.sense_outputs.size
        a, r = self.act.args, self.act.res
        self.C, self.PAR, self.CMD = a[0].reshape(n, C.size), a[1].reshape(n, P.size), a[2].reshape(n, -1)
        self.V, self.W = a[3].reshape(n, ny), a[4].reshape(n, nw)
        self.C1, self.CS = r[0].reshape(n, C.size), r[1].reshape(n, C.size)
        self.V1, self.OUTS, self.ACT = r[2].reshape(n, ny), r[3].reshape(n, ns), r[4].reshape(n, -1)
        sa, sr = self.sense.args, self.sense.res
        self.SC, self.SPAR, self.SW = sa[0].reshape(n, C.size), sa[1].reshape(n, P.size), sa[2].reshape(n, nw)
        self.SCS, self.SV, self.SOUTS = sr[0].reshape(n, C.size), sr[1].reshape(n, ny), sr[2].reshape(n, ns)
        self.seen = np.zeros((n, ny))  # what each sample's law sees (its sense blocks' output)
        self.outs = np.zeros((n, ns))
        self.M = BatchMeasurement(self.seen, lp.meas_layout)
        self.draws = [Draws(s.loop.comp, cm) for s in samples]  # each sample's own streams (sensors, noise)
        # every sample's draws of a block of ticks, (n, ticks, nw), from tick w0: each sample asks its
        # stream for the same ticks in the same order (all start at tick 0 and step together), so one
        # block serves all and a tick's draws are one copy, not n Python calls
        self.wblk, self.w0 = np.zeros((n, 0, nw)), 0

    # -- sensors -------------------------------------------------------------------------
    def _w(self, k: int, K: int) -> np.ndarray:
        """Every sample's draws of tick k, (n, nw) (a block of ticks at a time, in tick order)."""
        if k - self.w0 >= self.wblk.shape[1]:
            m = min(NOISE_BLOCK, K + 1 - k)
            blk = np.empty((self.n, m, self.wblk.shape[2]))
            for i, d in enumerate(self.draws):
                blk[i] = d.rows(k, m)
            self.wblk, self.w0 = blk, k
        return self.wblk[:, k - self.w0]

    def _start(self, due, k: int, K: int) -> None:
        """The samples ``due`` start a piece at tick k (their next ``(a, b, h)``): their numbers,
        then their first sensing (the sense part mapped; the others' results unused)."""
        P, C = self.cm.par, self.cm.carry
        for i in due:
            a, b, h = self.piece[i]
            comp = self.S[i].loop.comp
            if self.step is not None and self.alive[i]:  # a scheduled step at tick a (it starts a piece)
                self.step(i, a)
            t0 = min(a * comp.period, comp.duration)
            row = self.PAR[i]
            row[P.slice("t0")], row[P.slice("h")], row[P.slice("n_act")], row[P.slice("k0")] = t0, h, b - a, a
            row[P.slice("u_ext")] = held_torque_from(comp.scene, t0, comp.bps, comp.duration)
            self.edge_now.pop(i, None)
            if a in self.edge_at[i]:
                self.edge_now[i] = tick_edges(comp, a, h, max_edges(comp))
            self.C[i, C.slice("i")] = 0.0
        if self.W.shape[1]:
            self.SW[due] = self._w(k, K)[due]
        self.SPAR[:] = self.PAR
        self.SC[:] = self.C
        self.sense()
        self.C[due] = self.SCS[due]
        self.seen[due] = self.SV[due]
        self.outs[due] = self.SOUTS[due]

    def _act_edges(self) -> None:
        """The act part of the edge tick's case for the samples in an edge tick (:attr:`edge_now`),
        on the act part's inputs, its results written over theirs (the others' unused)."""
        fe, n, np_ = self.act_edge, self.n, self.cm.par.size
        for dst, src in zip(fe.args, self.act.args):
            if dst.size == src.size:
                dst[:] = src
        pe = fe.args[1].reshape(n, -1)
        pe[:, :np_] = self.PAR
        pe[:, np_:] = 0.0
        for i, e in self.edge_now.items():
            pe[i, np_:] = e
        fe()
        idx = list(self.edge_now)
        for dst, src in zip(self.act.res, fe.res):
            d, r = dst.reshape(n, -1), src.reshape(n, -1)
            d[idx] = r[idx]

    # -- the run -------------------------------------------------------------------------
    def run(self, SimulationError) -> list:
        S, n = self.S, self.n
        lp = S[0].loop.comp
        cm = self.cm
        C, P, SO = cm.carry, cm.par, cm.sense_outputs
        period, duration, n_per_out = lp.period, lp.duration, lp.n_per_out
        K = lp.ticks()
        ctrl = type(lp.ctrl).batch_of([s.loop.comp.ctrl for s in S])
        vec = vectorised(ctrl)
        self.C[:] = 0.0
        self.PAR[:] = 0.0
        for i, s in enumerate(S):
            comp = s.loop.comp
            self.PAR[i, P.slice("p")] = s.run.p
            for name, (p, x) in numbers(comp, self.cps[i]).items():  # each block's numbers and memory, by name
                if name in P and len(p):
                    self.PAR[i, P.slice(name)] = p
                if x is not None and name in C and len(x):
                    self.C[i, C.slice(name)] = x
            self.C[i, C.slice("x")] = s.loop.res.x
            s.loop.res.held_rate = held_rate(comp)[0]
        fl = next((b for b in cm.sense if b.name == "sensing"), None)  # each sample's flight memory, handed back
        if fl is not None:
            for i, s in enumerate(S):
                fm = s.loop.res.flight
                self.C[i, C.slice(fl.name)] = fm.packed(fl.state)
        chain = [C.slice(a.name) for a in lp.memories]  # the chain's blocks' memory, handed back by each block's name
        cx = C.slice("x")
        i_fin = cx.start + lp.state_layout.slice(lp.system.formulation.rate_field).start  # the per-tick loop's finite probe
        # each sample's pieces (its own edges on the grid), then the final tick
        its = []
        for s in S:
            c = s.loop.comp
            e = edge_ticks(c)
            its.append(iter([p for k0 in range(0, K, n_per_out)
                             for p in tick_pieces(k0, min(n_per_out, K - k0), e, duration, period)] + [(K, K + 1, 0.0)]))
        self.piece = [next(it) for it in its]
        alive = np.ones(n, dtype=bool)
        errors: dict[int, BaseException] = {}
        ticks = np.zeros(n, dtype=int)
        satrow = np.zeros(n, dtype=bool)
        lim_n = np.zeros(n, dtype=int)
        sat_n = np.zeros(n, dtype=int)
        ncmd, has_act, i_u, i_flags = self.ncmd, self.has_act, self.i_u, self.i_flags
        reads = bool(cm.actuators)
        nw = self.W.shape[1]
        wall0 = time.perf_counter()
        n_upd = np.zeros(n, dtype=int)
        n_all = [0, 0]  # updates, ticks counted for every sample (no numpy add per tick)
        n_alive = n

        def fail(i, e):
            nonlocal n_alive
            n_alive -= int(alive[i])
            alive[i] = False
            ctrl.batch_stopped.add(i)
            errors[i] = e

        M = self.M
        self.alive, self.law_batch = alive, ctrl  # (a scheduled step may tell a sample's law new numbers: run/docking.py)
        self.step = lockstep_hook(self, S)  # scheduled steps (run/schedule.py), applied where a piece starts, or None
        due = np.arange(n)  # the samples that start a piece at the next tick
        ends = np.array([p[1] for p in self.piece])  # the tick after each sample's current piece
        first_end = int(ends.min())
        try:
            for k in range(K + 1):
                t = k * period
                if k == K:
                    t = duration
                if due is not None:
                    self._start(due, k, K)
                    due = None
                M.t = t
                try:
                    cmd = ctrl.update_batch(t, M)
                    cmd = np.asarray(cmd, dtype=float)
                    if cmd.shape != (n, ncmd):
                        raise ValueError(f"update_batch returned shape {cmd.shape}, expected ({n}, {ncmd})")
                except Exception as e:  # the batch law itself failed: every sample with its reason
                    for i in np.flatnonzero(alive):
                        c = ControllerFailure(t, f"controller '{lp.ctrl.name}' update_batch raised "
                                                 f"{type(e).__name__}: {e}")
                        c.__cause__ = e
                        fail(i, c)
                    break
                for i, (reason, exc) in ctrl.batch_failed.items():
                    if alive[i]:
                        c = ControllerFailure(t, reason)
                        c.__cause__ = exc
                        fail(i, c)
                if vec:
                    if not math.isfinite(cmd.sum()):  # (a NaN or inf anywhere makes the sum one)
                        finite = np.isfinite(cmd).all(axis=1)
                        for i in np.flatnonzero(alive & ~finite):
                            try:
                                S[i].loop.check_command(t, cmd[i])
                            except ControllerFailure as e:
                                fail(i, e)
                    if n_alive < n:
                        n_upd += alive
                    else:
                        n_all[0] += 1
                    q_ref = ctrl.q_ref_BN
                    if q_ref is not None:
                        q_ref, why = _batch_q_ref(q_ref, n)
                        if why is not None:  # the law's stand-in set the wrong thing: every sample, its reason
                            for i in np.flatnonzero(alive):
                                fail(i, ControllerFailure(t, f"controller '{lp.ctrl.name}' update_batch set q_ref_BN "
                                                             f"to {why}"))
                            break
                if not alive.any():
                    break
                self.CMD[:] = cmd if n_alive == n else np.where(alive[:, None], cmd, 0.0)
                if reads:
                    self.V[:] = self.seen
                row = k % n_per_out == 0 or k == K
                if row:  # the memory a row reports: before the tick's actuation, after its sensing
                    X = self.C[:, cx].copy()
                    mem = [self.C[:, sl].copy() for sl in chain]
                    xs = fl.state.get(self.C[:, C.slice(fl.name)], "xs").copy() if fl is not None else None
                    ys = fl.outputs.get(self.outs[:, SO.slice(fl.name)], "ys").copy() if fl is not None else None
                if nw and k < K:
                    self.W[:] = self._w(k + 1, K)
                self.act()
                if self.edge_now:
                    self._act_edges()
                if has_act and (self.ACT[:, i_flags] > 0.5).any() and k < K:
                    lim = (self.ACT[:, i_flags.start] > 0.5) & alive
                    sat = (self.ACT[:, i_flags.start + 1] > 0.5) & alive
                    lim_n += lim
                    sat_n += sat
                    satrow |= lim | sat
                elif has_act and k == K:  # the final tick's actuation is reported in its row, not counted
                    satrow |= (self.ACT[:, i_flags] > 0.5).any(axis=1)
                if row:
                    for i in np.flatnonzero(alive):
                        lo = S[i].loop
                        res = lo.res  # what this sample's run is handed back
                        if ncmd == 3:
                            res.last_cmd = tuple(cmd[i].tolist())
                        if has_act:
                            res.u[lp.u_cmg] = self.ACT[i, i_u]
                        if vec:
                            res.comp.ctrl.q_ref_BN = None if q_ref is None else np.array(q_ref[i], dtype=float)
                        res.x[:] = X[i]
                        for a, m in zip(lo.comp.memories, mem):
                            a.x_row = m[i]
                        if xs is not None:
                            res.flight.xs, res.flight.ys = xs[i], ys[i]
                        try:
                            res.rows.hold(t, res.x, *res.held_row(int(satrow[i]), t))
                        except ControllerFailure as e:
                            fail(i, e)
                        satrow[i] = False
                if k == K:
                    break
                if n_alive < n:
                    ticks += alive
                else:
                    n_all[1] += 1
                v = self.C1[:, i_fin]
                # the per-tick loop's test of a finite state, -1e300 < v < 1e300, for all at once
                # (NaN fails both: the max of an array with a NaN is NaN)
                if not np.abs(v).max() < 1e300:
                    ok = (v > -1e300) & (v < 1e300)
                    for i in np.flatnonzero(alive & ~ok):
                        fail(i, IntegrationError(min((k + 1) * period, duration), "state is not finite (NaN or inf)"))
                if k + 1 < first_end:  # the next tick in the same piece: the act part's sensing serves it
                    self.C[:] = self.CS
                    self.seen[:] = self.V1
                    self.outs[:] = self.OUTS
                else:
                    inside = ends > k + 1
                    self.C[inside], self.seen[inside], self.outs[inside] = self.CS[inside], self.V1[inside], self.OUTS[inside]
                    self.C[~inside] = self.C1[~inside]
                    due = np.flatnonzero(~inside)
                    for i in due:
                        self.piece[i] = next(its[i])
                        ends[i] = self.piece[i][1]
                    first_end = int(ends.min())
        finally:
            ctrl.hand_back_compiled()  # (each sample's law state, from the compiled batch)
            wall = (time.perf_counter() - wall0) / n
            results = []
            for i, s in enumerate(S):
                lo, res = s.loop, s.loop.res
                res.ticks = int(ticks[i]) + n_all[1]
                lo.comp.ctrl.n_updates += int(n_upd[i]) + n_all[0]
                res.count(lim_n[i], sat_n[i])
                lo.comp.integ.count_steps(res.ticks)
                res.x = self.C[i, cx].copy()
                for a, sl in zip(lo.comp.memories, chain):
                    a.x = self.C[i, sl].copy()
                if fl is not None:
                    res.flight.take(fl.state, self.C[i, C.slice(fl.name)])
                s.rows.flush()
                e = errors.get(i)
                if e is None:
                    results.append(_done(s, wall))
                else:
                    s.meta.update(status="failed", stopped_at=e.t, summary=lo.summary())
                    err = SimulationError(e.t, e.reason, s.rows.trajectory(s.meta))
                    err.__cause__ = e.__cause__
                    results.append(err)
        return results


def _batch_q_ref(q_ref, n: int) -> tuple[np.ndarray | None, str | None]:
    """A batch law's ``q_ref_BN`` as an (n, 4) float array, or ``(None, why)``: what it set and the
    shape expected (one reference per sample, scalar first), for "set q_ref_BN to ..."."""
    try:
        arr = np.asarray(q_ref, dtype=float)
    except (TypeError, ValueError):
        return None, f"{type(q_ref).__name__} {str(q_ref)[:40]!r}, not ({n}, 4) real numbers (one reference per sample)"
    if arr.shape != (n, 4):
        return None, f"an array of shape {arr.shape}, expected ({n}, 4): one reference per sample, scalar first"
    return arr, None
