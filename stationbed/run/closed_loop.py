"""The closed loop: sense -> control (integer ticks, zero-order hold) -> actuate -> integrate ->
record, with the per-tick compiled path and the fused loop (:mod:`.fused`)."""

from __future__ import annotations

import math

import numpy as np

from ..core.compile import FastCall
from ..loop.flight import Flight
from ..model.moon import moon_position
from ..model.sun import julian_date
from ..model import Structure
from ..model.cmg import cluster_functions
from ..scene import knowledge_scene
from .detection import replan, replan_of
from .docking import PLANT_FACTS
from .controller import (
    ControllerError,
    Measurement,
    Plant,
    command_values,
    one_line,
)
from .measurement import command_fields, measurement_fields
from ..loop.cmg_cluster import chain_end
from .chain import chain_advance, chain_for, chain_summary
from .composition import Composition, ControllerFailure, FlightMemory, RunState
from .fused import fused_ok, run_fused, why_not_fused
from .blocks import parts_ok, rate_summary
from .initial import initial_state, initial_x
from .laws import build_controller
from .pacing import paced
from .rows import ROW_BATCH
from .controller_error import law_failure, replan_failure
from .parts import NOISE_BLOCK, GenericTick, run_parts
from .schedule import loop_hook, steps_summary
from .segments import held_torque_from, segment_input
from .fdir_run import fdir_for

__all__ = ["ControlLoop", "ControllerFailure", "ROW_BATCH", "plant_facts", "NOISE_BLOCK"]



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


PLANT_FACTS.append(plant_facts)  # (a configuration update designs on it: run/docking.py)


class ControlLoop:
    """Sense -> control (integer ticks, zero-order hold) -> actuate -> integrate -> record.

    Builds the run's :class:`~.composition.Composition` (``comp``) and its
    :class:`~.composition.RunState` (``res``), and is the per-tick executor: the law between
    the composed tick's compiled parts (:func:`~.parts.run_parts`) where the run steps whole
    fixed ticks (:func:`~.blocks.parts_ok`), else the generic path: one integrator call per
    period (split only at scene discontinuities and pulse edges inside it; the integrator keeps
    its memory across periods, so nothing restarts per tick). :meth:`run` hands the run
    to a fused executor when one applies (:func:`~.fused.fused_ok`). The per-tick executor's
    single-tick steps (:meth:`measure`, :meth:`actuate`, :meth:`advance`, :meth:`check_command`,
    :meth:`flags`, :meth:`redesign`) are public: the
    composed parts' path (:func:`~.parts.run_parts`) calls some of them.
    """

    def __init__(self, scene, system, integ, p, x, rows, duration, output_dt, bps, apply_jump, controller, fused):
        spec = scene.controller
        self.fused = fused
        period = spec.period
        f = system.funcs
        form = system.formulation
        model = form.model
        cmg = model.cmg
        ng = 0 if cmg is None else cmg.n_gimbals
        ctrl = build_controller(spec, base_dir=scene.folder) if controller is None else controller
        if ctrl.command == "gimbal_rates" and ng == 0:
            raise ValueError(
                f"controller '{ctrl.name}' commands gimbal rates: the scene needs a gimballed [cmg]"
            )
        plant = plant_facts(scene, system, period)  # knowledge, never the truth flown
        self.capacity = math.inf if cmg is None else cmg.geometry.capacity(scene.cmg)  # the truth's working units
        try:
            ctrl.reset(plant)
        except ValueError:  # the law's own refusal of this plant (e.g. "needs an [orbit]"): bad input
            raise
        except Exception as e:  # a bug in the user's _reset: name the controller, keep the traceback
            raise ControllerError(f"controller '{ctrl.name}' raised {type(e).__name__} in reset: {one_line(e)}") from e
        # measurement: compiled, written into y; the controller sees views of y (or of a noisy,
        # delayed copy)
        self.meas = FastCall.of(f["meas"])
        self.meas.args[2][:] = p
        layout = measurement_fields(ng, len(scene.appendage))
        sensor = spec.sensor
        noisy = sensor.attitude_noise > 0 or sensor.rate_noise > 0 or sensor.delay > 0
        flight = _flight(scene, period, layout, sensor.seed) if scene.sensor else None  # issue 20
        comp = self.comp = Composition(
            scene=scene, system=system, integ=integ, p=p, bps=bps, apply_jump=apply_jump,
            period=period, duration=duration, n_per_out=int(round(output_dt / period)),
            state_layout=form.state_layout, input_layout=model.input_layout, meas_layout=layout,
            command_layout=command_fields(ctrl.command, ng),
            ctrl=ctrl, replan=replan_of(scene, system, period, duration, plant_facts),  # fault detection
            sensor=sensor, noisy=noisy, delay=int(round(sensor.delay / period)) if noisy else 0,
            flight=flight, tick_noise=None if flight is None else flight.noise(),
            end=chain_end(model),
            actuators=chain_for(scene, ctrl, layout, plant),  # the chain before its end (run/chain.py)
            fdir=fdir_for(scene, model, plant),  # [fdir] (issue 34), or None
        )
        self.res = RunState(comp, rows, x)
        n_y = self.meas.res[0].size
        if noisy or flight is not None:
            self.seen = np.zeros(n_y)  # what the law sees
            self.M = Measurement(self.seen, layout)
        else:
            self.M = Measurement(self.meas.res[0], layout)
        if flight is not None:
            self._init_flight()
        #: the generic path's tick on the composed blocks (:class:`~.parts.GenericTick`), while it runs
        self.generic = None

    # -- the executors' view of the run (read: comp; handed back: res) ---------------------------
    @property
    def x(self) -> np.ndarray:
        return self.res.x

    @x.setter
    def x(self, v) -> None:
        self.res.x = v

    @property
    def ctrl(self):
        return self.comp.ctrl

    @property
    def rows(self):
        return self.res.rows

    @property
    def used_fused(self) -> bool:
        return self.res.used_fused

    @property
    def n_per_out(self) -> int:
        return self.comp.n_per_out

    @property
    def scene(self):
        return self.comp.scene

    @property
    def system(self):
        return self.comp.system

    # -- sensing (issue 20) ---------------------------------------------------------------
    def _init_flight(self) -> None:
        """The sensors and estimator's memory at t = 0 (the law sees ``seen``, the flight
        tick's ``y_seen``)."""
        comp = self.comp
        fl = comp.flight
        y0 = self.measure(0.0, self.x)
        ml = comp.meas_layout
        xs = fl.initial(ml.get(y0, "q_BN"), ml.get(y0, "omega_BN_B"))
        self.res.flight = FlightMemory(0.0, np.zeros(3), np.zeros(3), xs, np.zeros(fl.suite.OUTPUTS.size))

    def measure(self, t: float, x) -> np.ndarray:
        """The true measurement at ``(t, x)`` (the compiled ``meas``; a view of its buffer)."""
        m = self.meas
        m.args[0][0] = t
        m.args[1][:] = x
        m()
        return m.res[0]

    # -- one tick ------------------------------------------------------------------------
    def _sense(self, k: int, t: float) -> None:
        y = self.measure(t, self.x)
        self.M.t = t
        self._after_sense(k, t, y)

    def _after_sense(self, k: int, t: float, y: np.ndarray) -> None:
        """The sense blocks (the sensing, the ideal measurement's delay and noise) on the true
        measurement ``y``: ``seen``, what the law sees."""
        if self.generic.sense_fc is not None:
            self.seen[:] = self.generic.sense(k, t, y)

    def actuate(self, k: int, t: float, cmd, count: bool = True) -> int:
        """The actuator chain at tick k (time ``t``) on the law's command: its blocks in order
        (:meth:`~.parts.GenericTick.act`) set the held input (the CMG cluster's ``u_cmg``, or the
        ideal torquer's torque) and the channels' on-times; returns the saturation flag (0/1)."""
        comp = self.comp
        y = self.meas.res[0]
        return self.flags(self.generic.act(k, t, self.x, cmd, self.seen if (comp.noisy or comp.flight is not None) else y, y),
                          count)

    def advance(self, t0: float, t1: float, cmd) -> None:
        """Generic path: one integrator call per period, split at the discontinuities inside it
        and, with an actuator chain, at every pulse edge of its channels (run/chain.py: the held
        input and the channels' on-times and torques set by :meth:`actuate`; a channel on adds
        its torque to the held external torque)."""
        comp = self.comp
        res = self.res
        g = self.generic
        if comp.actuators:  # and at every channel's on/off edge
            return chain_advance(comp, res, t0, t1, g.on_s, g.torque_B, g.held_B)
        inner = [b for b in comp.bps if t0 < b < t1]
        edges = [t0] + inner + [t1]
        i_ext = comp.input_layout.slice("u_ext")
        for a, b in zip(edges[:-1], edges[1:]):
            segment_input(comp.scene, comp.model, a, b, res.u)
            u = res.u.copy()
            if not comp.has_cluster:
                u[i_ext] += g.held_B
            # an array rate step at b: continue from the state just after it
            self.x[:] = comp.apply_jump(b, comp.integ.advance(a, b, self.x, u))

    def run(self) -> None:
        """Run ticks 0..K (the fused loop when :func:`~stationbed.run.fused.fused_ok`, else per
        tick), streaming the rows; raises IntegrationError or ControllerFailure with the time."""
        comp, res = self.comp, self.res
        K = comp.ticks()
        if self.fused:
            if fused_ok(comp):
                return run_fused(comp, res, K)
        # the loop checks commands itself, and counts the law's calls where Controller.update
        # would have (Controller.tick_update)
        ctrl = comp.ctrl
        update, counted = paced(ctrl.tick_update(), res.rows.clock)  # --realtime: every tick at its deadline
        self.calls = self.n_fixed = 0
        try:
            if parts_ok(comp) is None:  # the composed parts around the law (parts.py)
                run_parts(self, K, update)
            else:
                self._run_generic(K, update)
        finally:
            ctrl.hand_back_compiled()  # the law's state its compiled form carried (law_compiled.py)
            if not counted:
                ctrl.count_compiled_updates(self.calls)
            comp.integ.count_steps(self.n_fixed)
            res.rows.flush()

    def redesign(self, t: float) -> None:
        """A failure detected at ``t``: the law designs again (the user's code: reported as update's)."""
        comp = self.comp
        ctrl = comp.ctrl
        plant = comp.replan.plant()
        try:
            ctrl.hand_back_compiled()
            replan(ctrl, plant)
            ctrl.reload_compiled()
        except Exception as e:
            raise replan_failure(ctrl, t, e) from e

    def _run_generic(self, K: int, update) -> None:
        """Ticks 0..K on the generic path: per tick the measurement, the run's composed blocks
        (:class:`~.parts.GenericTick`: the sense blocks on it, the chain's blocks in order around
        the law called here) and one integrator call per period split at the discontinuities and
        pulse edges inside it (an adaptive integrator, a discontinuity between ticks or an array
        rate step, an actuator that is not symbolic)."""
        comp, res = self.comp, self.res
        period, duration = comp.period, comp.duration
        sat_since_row = 0
        bps = [b for b in comp.bps if 0.0 < b < duration]
        u_ext = comp.input_layout.slice("u_ext")
        res.u[u_ext] = held_torque_from(comp.scene, 0.0, bps, duration)
        ctrl = comp.ctrl
        n_per_out = comp.n_per_out
        replan_at = comp.replan.tick if comp.replan is not None else -1
        M = self.M
        ticks = 0
        self.generic = GenericTick(comp, res)
        steps, step = loop_hook(self)  # scheduled steps (run/schedule.py): their ticks, the hook
        try:
            if 0 in steps:
                step(0, 0.0)
            self._sense(0, 0.0)
            for k in range(K + 1):
                t = k * period  # integer tick clock: no accumulated drift
                if k == K:
                    t = duration
                if k == replan_at:
                    self.redesign(t)
                M.t = t
                self.calls += 1
                try:
                    cmd = update(t, M)
                except Exception as e:  # the user's code: report it (chained), keep the trajectory
                    raise law_failure(ctrl, t, e) from e
                t_next = (k + 1) * period
                if t_next > duration:
                    t_next = duration
                cmd = self.check_command(t, cmd)
                # the final tick's actuation is reported in its row but never integrated:
                # it is not counted in the summary
                sat_since_row |= self.actuate(k, t, cmd, count=k < K)
                if k % n_per_out == 0 or k == K:
                    if len(cmd) == 3:
                        res.last_cmd = cmd
                    res.rows.hold(t, self.x, *res.held_row(sat_since_row, t))
                    sat_since_row = 0
                if k == K:
                    break
                ticks += 1
                self.advance(t, t_next, cmd)
                if k + 1 in steps:  # a scheduled step at t_next: applied, then sensed
                    step(k + 1, t_next)
                else:
                    self._sense(k + 1, t_next)
        finally:
            res.ticks = ticks

    def check_command(self, t: float, cmd) -> np.ndarray:
        """The command as floats (:func:`~.controller.command_values`), or ControllerFailure at
        ``t`` naming the controller and what it returned (generic path; the fast path when its
        plain write failed, or after it met a non-finite state)."""
        comp = self.comp
        try:
            return command_values(cmd, comp.n_cmd, comp.ctrl.command)
        except ValueError as e:
            raise ControllerFailure(t, f"controller '{comp.ctrl.name}' returned {e}") from None

    def flags(self, r, count: bool = True) -> int:
        """The chain end's reported values ``r`` (``out``): the held ``u_cmg`` kept, the
        rate-limited and saturated flags counted; returns the row's flag."""
        if not self.comp.has_cluster:
            return 0
        out = self.comp.end.outputs
        self.res.u[self.comp.u_cmg] = r[out.slice("u_cmg")]
        lim, sat = r[out.slice("rate_limited")][0] > 0.5, r[out.slice("saturated")][0] > 0.5
        if count:
            self.res.count(lim, sat)
        return int(lim or sat)

    def summary(self) -> dict:
        """The run's summary: ticks, controller updates, and the :data:`~.metrics.METRICS` of the
        run (saturation counts, max |h| and its fraction of capacity, min singularity measure,
        attitude error, commanded torque: what ``summary.json`` holds), from the reductions kept
        as the rows are emitted (:class:`~.metrics.RunMetrics`: the rows need not be kept)."""
        comp, res = self.comp, self.res
        rs = res.rows.summary
        ctrl = comp.ctrl
        out = {
            "controller": ctrl.name,
            "fused": res.used_fused,
            "period_s": comp.period,
            "ticks": res.ticks,
            "controller_updates": ctrl.n_updates,
        }
        if comp.has_cluster:
            rs.count_ticks(res.n_rate_limited, res.n_momentum_saturated)
            rs.h_capacity_Nms = self.capacity
            if math.isfinite(self.capacity):
                out["h_capacity_Nms"] = float(self.capacity)  # the working units'
                # |h| at which a tick counts as momentum saturated (the dashboard tells it from a rate limit)
                out["h_saturation_Nms"] = float(comp.scene.cmg.saturation_fraction * self.capacity)
            if rs.h_held_B is not None:  # failed units: their held momentum, left out of max_h
                out["h_held_B_Nms"] = rs.h_held_B.tolist()
            held = [u for u in rs.held_units if not callable(u[2])]  # units a fault held (gimbal_stuck, cmg_failed), as the rows met them
            if held:
                out["h_held_units_Nms"] = [{"t": a, "until": None if math.isinf(b) else b, "h_B": h.tolist()}
                                           for a, b, h in held]
            if rs.capacity_steps:  # the working units' capacity as a fault takes units out (None: the start's)
                out["h_capacity_steps_Nms"] = [{"t": a, "capacity_Nms": c} for a, c in rs.capacity_steps]
        if not res.used_fused:  # the one block (or part of the clock) that kept it off the fused path
            out["not_fused"] = why_not_fused(comp) or "fused = False asked"
        out.update(rs.values())
        out.update(rate_summary(self.comp, self.res.used_fused, self.res.held_rate))  # the effect rates run (issue 25)
        out.update(chain_summary(comp))
        if comp.fdir is not None:
            out.update(comp.fdir.summary(comp, xs=self.res.flight.xs if comp.flight is not None else None))
        out.update(steps_summary(comp, res))  # the scheduled faults applied, with their times
        try:  # the user's code: a raising summary() must not hide the run's own result or failure
            out.update(ctrl.summary())
        except Exception as e:
            out["controller_summary_error"] = f"{type(e).__name__}: {one_line(e)}"
        return out


def _flight(scene, period: float, layout, seed):
    """The scene's sensors and estimator (:class:`~stationbed.loop.Flight`), the Moon held at the
    epoch as the Sun; ``layout`` the measurement's :class:`~stationbed.core.layout.Layout`."""
    moon = None
    if scene.sun is not None and scene.sun.epoch is not None:
        u, dist, _, _ = moon_position(julian_date(scene.sun.epoch))
        moon = u * dist
    return Flight(scene, period, layout, seed=seed, moon_R_N=moon)

