"""The closed loop: sense -> control (integer ticks, zero-order hold) -> actuate -> integrate ->
record, with the per-tick compiled path and the fused loop (:mod:`.fused`)."""

from __future__ import annotations

import math
import struct

import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..loop.flight import Flight
from ..model.moon import moon_position
from ..model.sun import julian_date
from ..model import Structure
from ..model.cmg import cluster_functions
from ..scene import knowledge_scene
from .detection import replan, replan_of
from .controller import (
    ControllerError,
    Measurement,
    Plant,
    command_values,
    measurement_layout,
    one_line,
)
from .fused import fused_ok, run_fused
from .initial import initial_state, initial_x
from .laws import build_controller
from .rates import rate_summary
from .rows import ROW_BATCH
from .segments import held_torque_from, segment_input

__all__ = ["ControlLoop", "ControllerFailure", "ROW_BATCH", "plant_facts", "NOISE_BLOCK"]

#: sensor noise rows drawn at a time by the per-tick loop (any size gives the same numbers)
NOISE_BLOCK = 256


def plant_facts(scene, system, period: float, known=None) -> Plant:
    """The :class:`Plant` facts a controller designs with: what flight software believes, never
    the truth being flown. Built from the *knowledge scene* of ``scene``
    (:func:`stationbed.scene.knowledge_scene`: the scene with its ``[knowledge]`` substituted,
    failed CMG units unknown unless listed there): its inertia about O at t = 0 (the compiled
    ``inertia`` of ``system`` at the knowledge's own state and parameters), orbital rate and CMG
    limits; ``plant.scene`` is the knowledge scene (also used by :mod:`stationbed.analysis`
    and :mod:`stationbed.plan`, which design and plan on knowledge too). ``known``: another
    belief of the same scene (:func:`~stationbed.scene.knowledge.detected_scene`)."""
    known = knowledge_scene(scene) if known is None else known
    model = system.formulation.model
    if Structure.of(known) != model.structure:
        raise ValueError("[knowledge] changes the model's structure (e.g. a circular orbit believed two-body); "
                         "it may change values only")
    p = model.params(known)
    x = initial_x(system, known, *initial_state(known), p)
    inertia = FastCall.of(system.funcs["inertia"])
    inertia.args[0][0] = 0.0
    inertia.args[1][:] = x
    inertia.args[2][:] = p
    inertia()
    c = known.cmg
    cmg = model.cmg
    plant = Plant(
        scene=known,
        inertia_O_B=inertia.res[0].reshape(3, 3).T.copy(),
        mean_motion=None if known.orbit is None else known.orbit.mean_motion,
        period=period,
    )
    if c is not None:
        geometry = cmg.geometry
        plant.cmg_kind = c.kind
        plant.h_capacity = geometry.capacity(c)
        plant.max_torque = geometry.max_torque(c)
        plant.n_gimbals = cmg.n_gimbals
        plant.max_gimbal_rate = geometry.max_gimbal_rate(c)
        plant.h_rotor = geometry.rotor_momentum(c)
        plant.cmg_functions = cluster_functions(c)
    return plant


class ControllerFailure(Exception):
    """The controller raised or returned a bad command at time ``t`` [s]; ``reason`` is one line.

    When it raised, that exception is this one's ``__cause__`` (with its traceback)."""
    def __init__(self, t: float, reason: str):
        super().__init__(reason)
        self.t = t
        self.reason = reason


class ControlLoop:
    """Sense -> control (integer ticks, zero-order hold) -> actuate -> integrate -> record.

    One integrator call per period (split only at scene discontinuities inside it); the
    integrator keeps its memory (step size) across periods, so nothing restarts per tick.
    """

    def __init__(self, scene, system, integ, p, x, rows, duration, output_dt, bps, apply_jump, controller, fused):
        spec = scene.controller
        self.system, self.fused, self.used_fused = system, fused, False
        self.scene, self.integ, self.p, self.x, self.rows = scene, integ, p, x, rows
        self.duration, self.bps, self.apply_jump = duration, bps, apply_jump
        self.period = spec.period
        self.n_per_out = int(round(output_dt / spec.period))
        f = system.funcs
        model = system.formulation.model
        self.model = model
        cmg = model.cmg
        self.ng = 0 if cmg is None else cmg.n_gimbals
        if controller is None:
            controller = build_controller(spec, base_dir=scene.folder)
        self.ctrl = controller
        if self.ctrl.command == "gimbal_rates" and self.ng == 0:
            raise ValueError(
                f"controller '{self.ctrl.name}' commands gimbal rates: the scene needs a gimballed [cmg]"
            )
        plant = plant_facts(scene, system, self.period)  # knowledge, never the truth flown
        self.capacity = math.inf if cmg is None else cmg.geometry.capacity(scene.cmg)  # the truth's working units
        try:
            self.ctrl.reset(plant)
        except ValueError:  # the law's own refusal of this plant (e.g. "needs an [orbit]"): bad input
            raise
        except Exception as e:  # a bug in the user's _reset: name the controller, keep the traceback
            raise ControllerError(f"controller '{self.ctrl.name}' raised {type(e).__name__} in reset: {one_line(e)}") from e
        self.replan = replan_of(scene, system, self.period, duration, plant_facts)  # fault detection
        # measurement: compiled, written into y; the controller sees views of y (or of a noisy,
        # delayed copy)
        self.meas = FastCall.of(f["meas"])
        self.meas.args[2][:] = p
        self.layout = measurement_layout(self.ng, len(scene.appendage))
        sensor = spec.sensor
        self.noisy = sensor.attitude_noise > 0 or sensor.rate_noise > 0 or sensor.delay > 0
        if self.noisy:
            self.delay = int(round(sensor.delay / self.period))
            self.history = np.zeros((self.delay + 1, self.meas.res[0].size))
            self.rng = np.random.default_rng(sensor.seed)
            self.seen = np.zeros(self.meas.res[0].size)
            self.M = Measurement(self.seen, self.layout)
        else:
            self.M = Measurement(self.meas.res[0], self.layout)
        self.sensor = sensor
        self.flight = None  # the scene's [[sensor]] and [estimator] (issue 20), flown each tick
        if scene.sensor:
            self._init_flight(scene)
        self.act = None
        if cmg is not None:
            name = "actuate_rates" if self.ctrl.command == "gimbal_rates" else "actuate"
            self.act = FastCall.of(f[name])
            self.act.args[3][:] = p
        self.u = np.zeros(model.nu)
        self.nu_cmg = model.nu_cmg
        self.n_cmd = self.ng if self.ctrl.command == "gimbal_rates" else 3
        self.last_cmd = (0.0, 0.0, 0.0)
        self.meas_out = None  # where the fused tick writes y, when the controller reads it there
        self.u_ext = None  # the fused tick's held-torque input, when the loop has a fused tick
        self.n_slow = 0  # periods integrated by the generic path
        self.ticks = 0
        self.n_rate_limited = 0
        self.n_momentum_saturated = 0

    # -- sensing (issue 20) ---------------------------------------------------------------
    def _init_flight(self, scene) -> None:
        """The sensors and estimator: the law sees ``seen`` (the flight tick's ``y_seen``)."""
        moon = None
        if scene.sun is not None and scene.sun.epoch is not None:  # held at the epoch, as the Sun
            u, dist, _, _ = moon_position(julian_date(scene.sun.epoch))
            moon = u * dist
        fl = self.flight = Flight(scene, self.period, self.layout, seed=self.sensor.seed, moon_R_N=moon)
        m = self.meas
        m.args[0][0] = 0.0
        m.args[1][:] = self.x
        m()
        y0 = m.res[0]
        (oq, _), (ow, _) = self.layout["q_BN"], self.layout["omega_BN_B"]
        self.xs = fl.initial(y0[oq : oq + 4], y0[ow : ow + 3])
        self.ys = np.zeros(fl.suite.OUTPUTS.size)
        self.th, self.om_prev, self.t_prev = np.zeros(3), np.zeros(3), 0.0
        self.tick_noise = fl.noise()
        self._w, self._w_k0 = np.zeros((0, fl.suite.NOISE.size)), 0
        if not self.noisy:
            self.seen = np.zeros(self.meas.res[0].size)
            self.M = Measurement(self.seen, self.layout)

    def _noise_row(self, k: int) -> np.ndarray:
        """Tick k's sensor draws (drawn :data:`NOISE_BLOCK` ticks at a time, in tick order)."""
        i = k - self._w_k0
        if i >= len(self._w):
            self._w_k0, i = k, 0
            self._w = self.tick_noise.rows(k, NOISE_BLOCK)
        return self._w[i]

    def _fly(self, k: int, t: float, y: np.ndarray) -> np.ndarray:
        """Tick k of the sensing from the true measurement ``y``: returns what the law sees."""
        fc = self.flight.compiled()
        a = fc.args
        a[0][0], a[1][0], a[2][0] = k, t, self.t_prev
        a[3][:] = y
        a[4][:] = self.th
        a[5][:] = self.om_prev
        a[6][:] = self.xs
        a[7][:] = self._noise_row(k)
        fc()
        self.th[:], self.xs[:], self.ys[:] = fc.res[0], fc.res[1], fc.res[3]
        o, _ = self.layout["omega_BN_B"]
        self.om_prev[:] = y[o : o + 3]
        self.t_prev = t
        return fc.res[2]

    # -- one tick ------------------------------------------------------------------------
    def _sense(self, k: int, t: float) -> None:
        m = self.meas
        m.args[0][0] = t
        m.args[1][:] = self.x
        m()
        self.n_slow += 1 if k > 0 else 0
        if self.meas_out is not None:
            self.meas_out[:] = m.res[0]
        self.M.t = t
        self._after_sense(k, t, m.res[0])

    def _after_sense(self, k: int, t: float, y: np.ndarray) -> None:
        """The sensing, then the ideal path's noise and delay, on the true measurement ``y``."""
        if self.flight is not None:
            y = self._fly(k, t, y)
            if not self.noisy:
                self.seen[:] = y
                return
        if self.noisy:
            self._corrupt(k, y)

    def _corrupt(self, k: int, y=None) -> None:
        y = self.meas.res[0] if y is None else y
        slot = k % (self.delay + 1)
        if k == 0:
            self.history[:] = y
        self.history[slot] = y
        self.seen[:] = self.history[(k - self.delay) % (self.delay + 1)] if k >= self.delay else self.history[0]
        s = self.sensor
        if s.attitude_noise > 0:
            o = self.layout["q_BN"][0]
            q = self.seen[o : o + 4]
            d = 0.5 * self.rng.normal(0.0, s.attitude_noise, 3)
            qn = np.array(
                [
                    q[0] - q[1] * d[0] - q[2] * d[1] - q[3] * d[2],
                    q[1] + q[0] * d[0] + q[2] * d[2] - q[3] * d[1],
                    q[2] + q[0] * d[1] + q[3] * d[0] - q[1] * d[2],
                    q[3] + q[0] * d[2] + q[1] * d[1] - q[2] * d[0],
                ]
            )
            q[:] = qn / np.linalg.norm(qn)
        if s.rate_noise > 0:
            o = self.layout["omega_BN_B"][0]
            self.seen[o : o + 3] += self.rng.normal(0.0, s.rate_noise, 3)

    def _actuate(self, t: float, cmd, count: bool = True) -> int:
        """Set the held input from the command; returns the saturation flag (0/1)."""
        if self.act is None:  # no cluster: the torque request acts directly (ideal torquer)
            return 0
        a = self.act
        a.args[0][0] = t
        a.args[1][:] = self.x
        a.args[2][: self.n_cmd] = cmd
        a()
        return self._flags(a.res[0], count)

    def _advance(self, t0: float, t1: float, cmd) -> None:
        """Generic path: one integrator call per period, split at discontinuities inside it."""
        inner = [b for b in self.bps if t0 < b < t1]
        edges = [t0] + inner + [t1]
        for a, b in zip(edges[:-1], edges[1:]):
            segment_input(self.scene, self.model, a, b, self.u)
            u = self.u.copy()
            if self.act is None:
                u[0:3] += cmd
            # an array rate step at b: continue from the state just after it
            self.x[:] = self.apply_jump(b, self.integ.advance(a, b, self.x, u))
        if self.u_ext is not None:
            # the fused tick holds this torque from t1 on: the stretch that *starts* at t1, not
            # the segment that ended there (an edge on the tick grid ends a segment at t1)
            self.u_ext[:] = held_torque_from(self.scene, t1, self.bps, self.duration)

    def _held_row(self, sat_flag: int):
        vals = []
        if self.model.cmg is not None:
            vals += list(self.u[3 : 3 + self.ng]) if self.ng else []
            vals.append(float(sat_flag))
        q_ref = self.ctrl.q_ref_BN
        if q_ref is not None:
            if q_ref.__class__ is not np.ndarray or q_ref.dtype != np.float64 or q_ref.shape != (4,):
                q_ref = self._check_q_ref(q_ref)
        tau = self.last_cmd if self.ctrl.command == "torque" else (math.nan,) * 3
        vals += list(tau) + [math.nan] * 4  # att_err_deg and its axes: from q_ref, by the rows a batch at a time
        if self.flight is not None:
            q = np.asarray(self.x[:4], dtype=float)
            vals += self.flight.row(self.xs, self.ys, q / np.linalg.norm(q))
        return vals, q_ref

    def run(self) -> None:
        """Run ticks 0..K (the fused loop when :func:`~stationbed.run.fused.fused_ok`, else per
        tick), streaming the rows; raises IntegrationError or ControllerFailure with the time."""
        period, duration = self.period, self.duration
        K = max(1, math.ceil(duration / period - 1e-9))
        if self.fused:
            if fused_ok(self):
                return run_fused(self, K)
        sat_since_row = 0
        flush = self.rows.flush  # rows are held and streamed in batches (ROW_BATCH, FLUSH_S)

        tick = self._fast_tick()
        bps = [b for b in self.bps if 0.0 < b < duration]
        ib = 0  # next breakpoint
        self.u[0:3] = held_torque_from(self.scene, 0.0, bps, duration)
        if tick is not None:
            self.u_ext[:] = self.u[0:3]
            fc, xin, res_x, res_y, res_act = tick
            a_t, a_h, a_cmd = fc.args[0], fc.args[1], fc.args[3]
        # the loop checks commands itself; Controller.update counts the calls
        update, ctrl, n_per_out = self.ctrl.update, self.ctrl, self.n_per_out
        nu = self.nu_cmg
        i_lim, i_sat = nu + 1, nu + 2
        has_act = self.act is not None
        ncmd = self.n_cmd
        noisy = self.noisy or self.flight is not None
        M = self.M
        ticks = 0
        h_set = -1.0
        next_bp = bps[0] if bps else math.inf
        fast = tick is not None
        if fast:
            trigger = fc._trigger  # FastCall's bound buffer trigger: one C call, no wrapper
            pack_cmd = struct.Struct(f"={ncmd}d").pack_into
            ndarray, f64 = np.ndarray, np.dtype(np.float64)
        try:
            self._sense(0, 0.0)
            for k in range(K + 1):
                t = k * period  # integer tick clock: no accumulated drift
                if k == K:
                    t = duration
                if self.replan is not None and k == self.replan.tick:  # a failure detected
                    replan(ctrl, self.replan.plant())
                M.t = t
                try:
                    cmd = update(t, M)
                except Exception as e:  # the user's code: report it (chained), keep the trajectory
                    raise ControllerFailure(t, f"controller '{ctrl.name}' raised {type(e).__name__}: {one_line(e)}") from e
                t_next = (k + 1) * period
                if t_next > duration:
                    t_next = duration
                smooth = fast and k < K and next_bp > t_next  # a step at t_next needs the jump
                if smooth:  # fused: actuate + one RK4 step + measure, one compiled call
                    a_t[0] = t
                    if t_next - t != h_set:
                        h_set = t_next - t
                        a_h[0] = h_set
                    # a tuple or list of ncmd real numbers, or a float64 array of ncmd values, is
                    # written as is; anything else, or a failed write (wrong size, strings...),
                    # goes to the checker, which raises or returns the values as floats
                    cls = cmd.__class__
                    try:
                        if cls is tuple or cls is list:
                            pack_cmd(a_cmd, 0, *cmd)  # exactly ncmd numbers; no strings, no None
                        elif cls is ndarray and cmd.dtype is f64 and len(cmd) == ncmd:
                            a_cmd[:] = cmd  # (a (ncmd, 1) array raises ValueError)
                        else:
                            raise TypeError
                    except (TypeError, ValueError, struct.error):
                        cmd = self._check_command(t, cmd)
                        a_cmd[:] = cmd
                    trigger()
                    if has_act and (res_act[i_lim] or res_act[i_sat]):
                        sat_since_row |= self._flags(res_act)
                else:
                    cmd = self._check_command(t, cmd)
                    # the final tick's actuation is reported in its row but never integrated:
                    # it is not counted in the summary
                    sat_since_row |= self._actuate(t, cmd, count=k < K)
                if k % n_per_out == 0 or k == K:
                    if len(cmd) == 3:
                        self.last_cmd = cmd
                    if smooth and has_act:
                        self.u[3 : 3 + nu] = res_act[:nu]  # the row's held rates (flags counted above)
                    self.rows.hold(t, self.x, *self._held_row(sat_since_row))
                    sat_since_row = 0
                if k == K:
                    break
                ticks += 1
                if smooth:
                    v = res_x[4]
                    if not -1e300 < v < 1e300:
                        self.ticks = ticks
                        self._check_command(t, cmd)
                        raise IntegrationError(t_next, "state is not finite (NaN or inf)")
                    xin[:] = res_x
                    if noisy:
                        self.meas.res[0][:] = res_y
                        self._after_sense(k + 1, t_next, res_y)
                else:
                    self.ticks = ticks
                    while ib < len(bps) and bps[ib] <= t_next:
                        ib += 1
                    next_bp = bps[ib] if ib < len(bps) else math.inf
                    self._advance(t, t_next, cmd)
                    self._sense(k + 1, t_next)
        finally:
            self.ticks = ticks
            if tick is not None:
                n_fast = self.ticks - self.n_slow
                self.integ.count_steps(n_fast)
            flush()

    def _check_command(self, t: float, cmd) -> np.ndarray:
        """The command as floats (:func:`~.controller.command_values`), or ControllerFailure at
        ``t`` naming the controller and what it returned (generic path; the fast path when its
        plain write failed, or after it met a non-finite state)."""
        try:
            return command_values(cmd, self.n_cmd, self.ctrl.command)
        except ValueError as e:
            raise ControllerFailure(t, f"controller '{self.ctrl.name}' returned {e}") from None

    def _check_q_ref(self, q_ref) -> np.ndarray:
        """The controller's ``q_ref_BN`` as 4 floats, or ControllerFailure at the tick's time
        naming the controller and what it set (a string, a (4, 1) array...)."""
        try:
            return command_values(q_ref, 4, "q_ref_BN, scalar first", finite=False)
        except ValueError as e:
            raise ControllerFailure(self.M.t, f"controller '{self.ctrl.name}' set q_ref_BN to {e}") from None

    def _fast_tick(self):
        """The fused tick when the integrator is fusable (RK4) with one step per period, else None."""
        integ = self.integ
        f = integ.funcs
        name = "tick_rates" if self.ctrl.command == "gimbal_rates" else "tick_torque"
        if not integ.fusable or name not in f:
            return None
        if math.ceil(self.period / integ.h_nominal - 1e-9) != 1:
            return None
        fc = FastCall.of(f[name])
        fc.args[5][:] = self.p
        fc.args[2][:] = self.x
        self.x = fc.args[2]  # the loop's state lives in the tick's input buffer
        self.u_ext = fc.args[4]
        if not self.noisy and self.flight is None:  # the controller reads the tick's output directly (no copy)
            self.meas_out = fc.res[1]
            self.M = Measurement(self.meas_out, self.layout)
        return fc, fc.args[2], fc.res[0], fc.res[1], fc.res[2]

    def _flags(self, r, count: bool = True) -> int:
        if self.act is None:
            return 0
        nu = self.nu_cmg
        self.u[3 : 3 + nu] = r[:nu]
        lim, sat = r[nu + 1] > 0.5, r[nu + 2] > 0.5
        if count:
            self.n_rate_limited += lim
            self.n_momentum_saturated += sat
        return int(lim or sat)

    def summary(self) -> dict:
        """The run's summary: ticks, controller updates, and the :data:`~.metrics.METRICS` of the
        run (saturation counts, max |h| and its fraction of capacity, min singularity measure,
        attitude error, commanded torque: what ``summary.json`` holds), from the reductions kept
        as the rows are emitted (:class:`~.metrics.RunMetrics`: the rows need not be kept)."""
        rs = self.rows.summary
        out = {
            "controller": self.ctrl.name,
            "fused": self.used_fused,
            "period_s": self.period,
            "ticks": self.ticks,
            "controller_updates": self.ctrl.n_updates,
        }
        if self.model.cmg is not None:
            rs.count_ticks(self.n_rate_limited, self.n_momentum_saturated)
            rs.h_capacity_Nms = self.capacity
            if math.isfinite(self.capacity):
                out["h_capacity_Nms"] = float(self.capacity)  # the working units'
            if rs.h_held_B is not None:  # failed units: their held momentum, left out of max_h
                out["h_held_B_Nms"] = rs.h_held_B.tolist()
        out.update(rs.values())
        out.update(rate_summary(self))  # the effect rates run (issue 25)
        try:  # the user's code: a raising summary() must not hide the run's own result or failure
            out.update(self.ctrl.summary())
        except Exception as e:
            out["controller_summary_error"] = f"{type(e).__name__}: {one_line(e)}"
        return out
