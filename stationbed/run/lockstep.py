"""The lockstep batch executor: many samples of one compiled system advance together, one
control period per step, the law called once per tick for all of them (issue 22).

Per tick: the law's :meth:`~.controller.Controller.update_batch` (every measurement field with a
leading sample axis; a law with only a ``symbolic`` form: that form compiled and mapped over the
samples, :mod:`.law_compiled`) -> one call of the compiled tick mapped over the samples (casadi
``Function.map`` of the same compiled ``tick_<cmd>`` the per-tick loop calls: actuate, one RK4
step, measure; the map calls that very machine code once per sample, so a sample's numbers are
its single run's, bit for bit) -> each sample's sensor (noise from its own generator, its own
delay; or the scene's sensors and estimator, their flight tick mapped the same way:
:mod:`.lockstep_flight`) -> rows at the output ticks (each sample's own :class:`~.rows.Rows`
and metrics).

A tick that a sample's single run integrates on the generic path (a discontinuity inside it or
at its end, the final tick) is run for that sample alone with its own
:class:`~.closed_loop.ControlLoop` (the same calls, the same numbers). A sample that fails (a
bad or non-finite command, the law raising, a non-finite state) stops alone, with its single
run's reason and time; the batch goes on.

:func:`executor` says which executor a run gets: ``fused`` (a law with ``symbolic``, where the
fused loop applies), ``batch`` (an RK4 tick at one step per period) or ``per-tick``.
"""

from __future__ import annotations

import time

import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..integrators.dop853_batch import mapped
from .closed_loop import ControlLoop, ControllerFailure
from .controller import BatchMeasurement, Controller
from .fused import fused_ok
from .held_env import HeldBlocks, held_functions, held_rate
from ..loop.corruption import corrupt_compiled, draws_layout
from .lockstep_flight import FlightBatch
from .prepare import prepare
from .rows import Rows
from .schedule import lockstep_hook
from .segments import breakpoints, held_torque_from

__all__ = ["executor", "run_lockstep", "vectorised"]

#: ticks of sensor noise drawn per call of a sample's generator (the same stream as per tick)
DRAW_BLOCK = 256


def vectorised(ctrl) -> bool:
    """Whether the law overrides :meth:`Controller.update_batch` or has a ``symbolic`` form
    (evaluated compiled for every sample at once), else the default loops."""
    return type(ctrl).update_batch is not Controller.update_batch or ctrl.has_symbolic()


def _tick_ok(comp) -> bool:
    # a run that flies [[sensor]] tables and an [estimator] (comp.flight, issue 20) runs its
    # flight tick mapped too (lockstep_flight.py); a fault detected mid-run (run/detection.py) and
    # [[thruster]] tables (comp.thrust, issue 21: the batch tick has no pulses) run per tick
    return comp.replan is None and comp.thrust is None and comp.tick_name is not None


def executor(loop) -> str:
    """``"fused"``, ``"batch"`` or ``"per-tick"``: the executor a sample of ``loop`` (a
    :class:`~.closed_loop.ControlLoop`) runs on."""
    if loop.fused and fused_ok(loop.comp):
        return "fused"
    if _tick_ok(loop.comp):
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


def _generic_ticks(comp, K: int) -> set[int]:
    """The ticks k < K that the per-tick loop integrates on its generic path: a discontinuity
    in (t_k, t_k+1] (its ``smooth`` test, ``next_bp > t_next``)."""
    out = set()
    for b in comp.bps:
        if not 0.0 < b < comp.duration:
            continue
        k = max(0, int(b // comp.period) - 1)
        while k < K:
            t = k * comp.period
            t_next = min((k + 1) * comp.period, comp.duration)
            if t < b <= t_next:
                out.add(k)
                break
            k += 1
    return out


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
        key = (id(smp.run.system), type(comp.ctrl), comp.ctrl.command, sim.duration, sim.output_dt,
               comp.period, getattr(comp.flight, "key", None), held_rate(comp)[0])  # (each sample its own blocks)
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
    """The samples of one group (one compiled system, law class, duration, period) in lockstep."""

    def __init__(self, samples: list[_Sample]):
        self.S = samples
        n = self.n = len(samples)
        lp = samples[0].loop.comp  # (every sample's composition has the same structure)
        self.ncmd, self.has_act = lp.n_cmd, lp.has_cluster
        out = lp.end.outputs  # the chain end's reported values (act)
        self.i_u = out.slice("u_cmg") if self.has_act else None
        self.i_flags = slice(out.slice("rate_limited").start, out.slice("saturated").stop) if self.has_act else None
        self.rate = held_rate(lp)[0]  # the environment held per block (held_env.py: every sample's blocks)
        hf = held_functions(lp.system, lp.ctrl.command) if self.rate else None
        f = hf["tick"] if self.rate else lp.integ.funcs[lp.tick_name]
        fc = self.fc = mapped(f, n, 1)  # the compiled tick, called once per sample by casadi's map
        self.env = mapped(hf["env"], n, 1) if self.rate else None  # a block's environment, the same way
        nx = lp.system.formulation.nx
        self.T, self.H = fc.args[0], fc.args[1]
        self.X = fc.args[2].reshape(n, nx)
        self.CMD = fc.args[3].reshape(n, -1)
        self.UEXT = fc.args[4].reshape(n, 3)
        self.P = fc.args[5].reshape(n, -1)
        # FastCall densifies a sparse output (structural zeros, e.g. C_ON's off-diagonal in deep
        # space): each sample's row holds every entry, as the per-tick loop's buffer does
        nnz = [f.numel_out(j) for j in range(3)]
        self.X1 = fc.res[0][: n * nnz[0]].reshape(n, nnz[0])
        self.Y1 = fc.res[1][: n * nnz[1]].reshape(n, nnz[1])
        self.ACT = fc.res[2][: n * nnz[2]].reshape(n, nnz[2])
        self.ny1 = nnz[1]
        self.i_fin = lp.state_layout.slice(lp.system.formulation.rate_field).start  # the per-tick loop's finite probe
        ny = f.numel_out(1)
        self.raw = np.zeros((n, ny))  # each sample's measurement, before its sensor
        self.seen = np.zeros((n, ny))  # what the law sees (the raw buffer itself when no sample is noisy)
        # sensors: per sample its own generator, noise levels and delay
        sens = [s.loop.comp.sensor for s in samples]
        self.noisy = np.array([s.loop.comp.noisy for s in samples])
        self.sig_a = np.array([x.attitude_noise for x in sens])
        self.sig_r = np.array([x.rate_noise for x in sens])
        self.delay = np.array([s.loop.comp.delay for s in samples])
        self.hist = np.zeros((n, int(self.delay.max()) + 1, ny))
        self.NZ = draws_layout(True, True)  # each sample's draws by name (those off stay 0)
        self.z = np.zeros((n, DRAW_BLOCK, self.NZ.size))
        self.layout = lp.meas_layout
        self.any_noisy = bool(self.noisy.any())
        self.cor = None  # the corruption plug-in, both corruptions on, mapped over the samples
        if self.any_noisy and (self.noisy & ((self.sig_a > 0) | (self.sig_r > 0))).any():
            one = corrupt_compiled((True, True), lp.meas_layout).f
            if one.numel_in(0) != ny:
                raise AssertionError(f"measurement of {ny} values, its layout {lp.meas_layout!r}")
            self.cor = mapped(one, n, 1)
        self.flight = FlightBatch(samples, lp.meas_layout) if lp.flight is not None else None
        if not self.any_noisy and self.flight is None:
            self.seen = self.raw
        self.M = BatchMeasurement(self.seen, lp.meas_layout)

    # -- sensors -------------------------------------------------------------------------
    def _draw(self, k: int) -> None:
        """Each noisy sample's draws for ticks k .. k + DRAW_BLOCK - 1, from its own generator in
        its single run's order (its plug-in's :meth:`~stationbed.loop.Corruption.draw`)."""
        self.z[:] = 0.0
        for i, s in enumerate(self.S):
            c = s.loop.comp.corruption
            if c is None or c.width == 0:
                continue
            zi = c.draw(s.loop.comp.rng, DRAW_BLOCK)
            for f in c.draws.names:
                self.z[i, :, self.NZ.slice(f)] = zi[:, c.draws.slice(f)]

    def _sense(self, k: int, t: float = 0.0) -> None:
        """``seen`` from ``raw`` at tick k, as ``ControlLoop._corrupt`` per sample: each sample's delay
        (its ring buffer), then the corruption plug-in mapped over the samples."""
        seen, raw = self.seen, self.raw
        if self.flight is not None:  # [[sensor]] tables (and an [estimator]): their flight tick first
            self.flight.fly(k, t, raw, seen)
            if not self.any_noisy:
                return
            # then the ideal path's noise and delay on what the flight gives the law, as
            # ControlLoop._after_sense (allowed without an [estimator]: the truth-fed run)
            raw = seen.copy()
        elif not self.any_noisy:  # (seen is raw)
            return
        rows = np.arange(self.n)
        D = self.delay
        slot = k % (D + 1)
        if k == 0:
            self.hist[:] = raw[:, None, :]
        self.hist[rows, slot] = raw
        src = np.where(k >= D, (k - D) % (D + 1), 0)
        seen[:] = self.hist[rows, src]
        if self.cor is None:  # delays alone
            return
        kb = k % DRAW_BLOCK
        if kb == 0:
            self._draw(k)
        # the corruption plug-in (loop/corruption.py), compiled, mapped over the samples; each
        # sample keeps the fields its own run corrupts (the two corruptions touch disjoint fields
        # with the same operations, so a row is its single run's, bit for bit)
        cor = self.cor
        cor.args[0][:] = seen.ravel()
        cor.args[1][:] = self.z[:, kb].ravel()
        cor()
        out = cor.res[0].reshape(self.n, -1)
        for f, sig in (("q_BN", self.sig_a), ("omega_BN_B", self.sig_r)):
            on = self.noisy & (sig > 0)
            if on.any():
                sl = self.layout.slice(f)
                seen[on, sl] = out[on, sl]

    def _measure(self, i: int, t: float, x) -> None:
        self.raw[i] = self.S[i].loop.measure(t, x)

    # -- the run -------------------------------------------------------------------------
    def run(self, SimulationError) -> list:
        S, n = self.S, self.n
        lp = S[0].loop.comp
        period, duration, n_per_out = lp.period, lp.duration, lp.n_per_out
        K = lp.ticks()
        ctrl = type(lp.ctrl).batch_of([s.loop.comp.ctrl for s in S])
        vec = vectorised(ctrl)
        generic = [set() if self.rate else _generic_ticks(s.loop.comp, K) for s in S]  # (held: every edge on the grid)
        any_generic = set().union(*generic)
        i_ext = lp.input_layout.slice("u_ext")
        for i, s in enumerate(S):
            self.P[i] = s.run.p
            self.X[i] = s.loop.res.x
            bps = [b for b in s.loop.comp.bps if 0.0 < b < duration]
            self.UEXT[i] = held_torque_from(s.scene, 0.0, bps, duration)
            s.loop.res.u[i_ext] = self.UEXT[i]
            self._measure(i, 0.0, self.X[i])
        held = None
        if self.rate:  # each block's first tick: every sample's environment evaluated and held
            held = HeldBlocks([s.loop.comp for s in S], self.rate, K, self.env, self.fc.args[6], self.P.ravel())
            for s in S:
                s.loop.res.held_rate = self.rate
        blk = 0 if held is not None else -1
        alive = np.ones(n, dtype=bool)
        errors: dict[int, BaseException] = {}
        ticks = np.zeros(n, dtype=int)
        n_fast = np.zeros(n, dtype=int)
        satrow = np.zeros(n, dtype=bool)
        lim_n = np.zeros(n, dtype=int)
        sat_n = np.zeros(n, dtype=int)
        ncmd, has_act, i_u, i_flags = self.ncmd, self.has_act, self.i_u, self.i_flags
        wall0 = time.perf_counter()

        n_upd = np.zeros(n, dtype=int)
        n_all = [0, 0, 0]  # updates, ticks, fast ticks counted for every sample (no numpy add per tick)
        n_alive = n
        h_set = -1.0

        def fail(i, e):
            nonlocal n_alive
            n_alive -= int(alive[i])
            alive[i] = False
            ctrl.batch_stopped.add(i)
            errors[i] = e

        due, step = lockstep_hook(self, S, held)  # scheduled steps (run/schedule.py): by tick, the hook
        for i in due.get(0, ()):
            step(i, 0, 0.0)
        self._sense(0, 0.0)
        M = self.M
        try:
            for k in range(K + 1):
                t = k * period
                if k == K:
                    t = duration
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
                    finite = np.isfinite(cmd).all(axis=1)
                    if not finite.all():
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
                t_next = min((k + 1) * period, duration)
                all_smooth = k < K and k not in any_generic and n_alive == n
                if all_smooth:
                    smooth = alive
                else:
                    smooth = alive.copy()
                    if k == K:
                        smooth[:] = False
                    elif k in any_generic:
                        for i in range(n):
                            if k in generic[i]:
                                smooth[i] = False
                if all_smooth or smooth.any():
                    if k == blk:  # a block's first tick: every sample's environment, held over it
                        for i, torque in held.start(k, t, self.X.ravel()):  # (and a stretch of held torque starts)
                            self.UEXT[i] = S[i].loop.res.u[i_ext] = torque
                        blk = held.next
                    self.T[:] = t
                    if t_next - t != h_set:
                        h_set = t_next - t
                        self.H[:] = h_set
                    if n_alive == n:
                        self.CMD[:] = cmd
                    else:
                        self.CMD[:] = np.where(alive[:, None], cmd, 0.0)
                    self.fc()
                    if has_act:
                        if (self.ACT[:, i_flags] > 0.5).any():
                            lim = self.ACT[:, i_flags.start] > 0.5
                            sat = self.ACT[:, i_flags.start + 1] > 0.5
                            lim &= smooth
                            sat &= smooth
                            lim_n += lim
                            sat_n += sat
                            satrow |= lim | sat
                row = k % n_per_out == 0 or k == K
                for i in ([] if all_smooth else np.flatnonzero(alive & ~smooth)):  # the generic path, per sample
                    lo = S[i].loop
                    lo.res.x[:] = self.X[i]
                    satrow[i] |= bool(lo.actuate(t, cmd[i], count=k < K))
                if row:
                    for i in np.flatnonzero(alive):
                        res = S[i].loop.res  # what this sample's run is handed back
                        if ncmd == 3:
                            res.last_cmd = tuple(cmd[i].tolist())
                        if smooth[i] and has_act:
                            res.u[lp.u_cmg] = self.ACT[i, i_u]
                        if vec:
                            res.comp.ctrl.q_ref_BN = None if q_ref is None else np.array(q_ref[i], dtype=float)
                        res.x[:] = self.X[i]
                        if self.flight is not None:
                            self.flight.to_loop(i)
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
                v = self.X1[:, self.i_fin]
                # the per-tick loop's test of a finite state, -1e300 < v < 1e300, for all at once
                # (NaN fails both: the max of an array with a NaN is NaN)
                if all_smooth and np.abs(v).max() < 1e300:
                    self.X[:] = self.X1
                    self.raw[:, : self.ny1] = self.Y1
                    n_all[2] += 1
                else:
                    ok = (v > -1e300) & (v < 1e300)
                    for i in np.flatnonzero(smooth & ~ok):
                        fail(i, IntegrationError(t_next, "state is not finite (NaN or inf)"))
                    good = smooth & ok
                    self.X[good] = self.X1[good]
                    self.raw[good, : self.ny1] = self.Y1[good]
                    n_fast += good
                for i in ([] if all_smooth else np.flatnonzero(alive & ~smooth)):
                    lo = S[i].loop
                    try:
                        lo.advance(t, t_next, cmd[i])
                    except IntegrationError as e:
                        fail(i, e)
                        continue
                    bps = [b for b in lo.comp.bps if 0.0 < b < duration]
                    self.UEXT[i] = held_torque_from(S[i].scene, t_next, bps, duration)
                    self.X[i] = lo.res.x
                    self._measure(i, t_next, lo.res.x)
                for i in due.get(k + 1, ()):  # a scheduled step at t_next, before the batch senses
                    if alive[i]:
                        step(i, k + 1, t_next)
                self._sense(k + 1, t_next)
        finally:
            ctrl.hand_back_compiled()  # (each sample's law state, from the compiled batch)
            wall = (time.perf_counter() - wall0) / n
            results = []
            for i, s in enumerate(S):
                lo, res = s.loop, s.loop.res
                res.ticks = int(ticks[i]) + n_all[1]
                lo.comp.ctrl.n_updates += int(n_upd[i]) + n_all[0]
                res.count(lim_n[i], sat_n[i])
                lo.comp.integ.count_steps(int(n_fast[i]) + n_all[2])
                res.x[:] = self.X[i]
                if self.flight is not None:
                    self.flight.to_loop(i)
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
