"""One closed-loop run's composition, and what its executors hand back (issue 20, docs/loop.md
"The composition and its executors").

A run is *declared* once, by :class:`Composition`: the plant (scene, compiled system,
integrator, parameters, discontinuities), the clock, the named layouts (state, held input,
measurement, command), the law, the measurement (the ideal sensor's noise and delay, the
``[[sensor]]`` flight suite and estimator, their noise streams) and the actuator chain (the
actuators in chain order (run/chain.py), then its end: the CMG cluster or the ideal torquer, loop/cmg_cluster.py). Every
executor reads it and none rebinds its fields (it is frozen; the objects it holds that a run
advances are the noise streams, drawn in tick order, the law, whose reference ``q_ref_BN`` an
executor sets from the compiled law's, and the actuators' memory): the per-tick loop (:class:`~.closed_loop.ControlLoop`),
the fused loop (:mod:`.composed`, the tick composed once from the run's blocks, :mod:`.blocks`),
the per-tick loop's and the lockstep batch's compiled parts of that tick (:mod:`.parts`, :mod:`.lockstep`).

An executor hands its results back through :class:`RunState` only: the state as it goes and at
the end (``x``, the held input ``u``), each output row (:meth:`RunState.row`, or
:meth:`RunState.rows_many` for many), the saturation counts (:meth:`RunState.count`), the ticks
run, the law's last command, the flight suite's memory (:class:`FlightMemory`) and the
actuators' (``comp.actuators``). The rows and the summary are made from the composition and
the run state alone, so no executor reads another's private attributes
(tests/test_composition.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Callable

import numpy as np

from ..core.layout import Layout
from ..loop.corruption import Corruption
from .controller import command_values
from .controller_error import ControllerFailure  # (defined there: run/detection.py raises it too)

__all__ = ["Composition", "RunState", "FlightMemory", "ControllerFailure"]




@dataclass(frozen=True, eq=False)
class Composition:
    """What a closed-loop run is made of (read by every executor, written by none)."""

    # -- the plant ---------------------------------------------------------------------------
    scene: Any
    system: Any  #: the compiled :class:`~.system.System`
    integ: Any  #: the integrator (its step memory is the plant's, counted by the executors)
    p: np.ndarray  #: the model's parameters
    bps: list  #: the scene's discontinuities in (0, duration) and beyond (segments.breakpoints)
    apply_jump: Callable  #: ``apply_jump(t, x)``: the state just after an array rate step at t
    # -- the clock ---------------------------------------------------------------------------
    period: float  #: the control period [s]
    duration: float  #: the run's length [s]
    n_per_out: int  #: ticks per output row
    # -- the layouts -------------------------------------------------------------------------
    state_layout: Layout  #: the plant's state (formulation.state_layout)
    input_layout: Layout  #: the model's held input (u_ext, u_cmg, t_step)
    meas_layout: Layout  #: the measurement the law sees (measurement.measurement_fields)
    command_layout: Layout  #: the law's command: ``tau_B`` (3) or ``gimbal_rates`` (n gimbals)
    # -- the law -----------------------------------------------------------------------------
    ctrl: Any  #: the :class:`~.controller.Controller`, reset on the knowledge's plant
    replan: Any  #: a failure detected mid-run (run/detection.py), or None
    # -- the measurement ---------------------------------------------------------------------
    sensor: Any  #: ``[controller.sensor]``: the ideal measurement's noise and delay
    noisy: bool  #: whether that noise or delay is on
    delay: int  #: its delay in ticks
    flight: Any  #: the ``[[sensor]]`` suite and estimator (:class:`~stationbed.loop.Flight`) or None
    tick_noise: Any  #: the suite's noise stream by tick (``Flight.noise()``) or None
    # -- the actuators -----------------------------------------------------------------------
    end: Any  #: the chain's end: the CMG cluster's or the ideal torquer's plug-in
    #: the actuators before the end, in chain order (:class:`~.chain.ActuatorLoop`: magnetic
    #: torquers, thrusters, ...; :func:`~.chain.chain_for`)
    actuators: tuple = ()
    fdir: Any = None  #: ``[fdir]`` (:class:`~.fdir_run.FdirLoop`): the chain's last block before the end

    # -- derived (looked up once: the executors read them per row) ------------------------------
    @cached_property
    def model(self):
        return self.system.formulation.model

    @cached_property
    def corruption(self):
        """The ideal measurement's noise as its plug-in (:class:`~stationbed.loop.Corruption`;
        its delay is a block of its own, :func:`~stationbed.loop.block.delay_block`), or None
        when ``[controller.sensor]`` is off."""
        if not self.noisy:
            return None
        return Corruption(self.sensor.attitude_noise, self.sensor.rate_noise, self.meas_layout)

    @cached_property
    def ideal_noise(self):
        """The corruption's draws by tick from tick 0 (its noise stream, as ``tick_noise`` is the
        suite's: :meth:`~stationbed.loop.Corruption.noise` on the ``[controller.sensor]`` seed's
        generator), or None without draws (no noise, or a delay alone)."""
        c = self.corruption
        if c is None or c.width == 0:
            return None
        return c.noise(np.random.default_rng(self.sensor.seed), self.ticks() + 1)

    @property
    def layout(self) -> dict:
        """The measurement's name -> (offset, size) (``meas_layout.offsets()``; the form this
        field had before it was a Layout, for code written against it)."""
        return self.meas_layout.offsets()

    @property
    def command(self) -> str:
        """``"torque"`` or ``"gimbal_rates"``: what the law commands."""
        return self.ctrl.command

    @cached_property
    def n_cmd(self) -> int:
        return self.command_layout.size

    @cached_property
    def ng(self) -> int:
        """Gimbals of the CMG cluster (0 without one, or a momentum store)."""
        cmg = self.model.cmg
        return 0 if cmg is None else cmg.n_gimbals

    @cached_property
    def nu_cmg(self) -> int:
        return self.model.nu_cmg

    @cached_property
    def has_cluster(self) -> bool:
        """Whether the chain ends in a CMG cluster (else the ideal torquer)."""
        return self.model.cmg is not None

    @cached_property
    def n_act(self) -> int:
        """Values the chain's end reports per tick (``u_cmg, m, rate_limited, saturated``)."""
        return self.end.outputs.size

    @cached_property
    def chain(self) -> tuple:
        """The actuator chain in order, as plug-ins: :attr:`actuators` (magnetic torquers,
        thrusters), then the end (the CMG cluster or the ideal torquer), which takes what is left."""
        return tuple(a.cluster for a in self.actuators) + (self.end,)

    @cached_property
    def memories(self) -> tuple:
        """The chain's blocks whose memory the executors hand back by the block's name:
        :attr:`actuators` in chain order, then ``[fdir]`` (the chain's last block). Each has
        ``name``, ``x`` (after the last tick), ``x_row`` (before the current one, what a row
        reports), ``idx`` (the row's values in its memory) and ``row()``."""
        return (*self.actuators, *(() if self.fdir is None else (self.fdir,)))

    @cached_property
    def u_cmg(self) -> slice:
        """The CMG cluster's held input in ``u`` (input layout)."""
        return self.input_layout.slice("u_cmg")

    @cached_property
    def schedule(self):
        """The run's scheduled steps (:class:`~.schedule.Schedule`: ``[[fault]]``, events)."""
        from . import detection, docking, faults  # noqa: F401,PLC0415 (the sources of steps register themselves)
        from .schedule import schedule_of  # noqa: PLC0415 (schedule.py reads this class's fields)

        return schedule_of(self)

    def ticks(self) -> int:
        """K: the run's ticks are 0..K (the last at ``duration``)."""
        return max(1, math.ceil(self.duration / self.period - 1e-9))


@dataclass(eq=False)
class FlightMemory:
    """The flight suite's memory between ticks: the previous tick's time and true rate, the rate
    integral ``theta_B``, the suite's state ``xs`` and its outputs ``ys`` after the last tick."""

    t_prev: float
    theta_B: np.ndarray
    omega_prev: np.ndarray
    xs: np.ndarray
    ys: np.ndarray

    def packed(self, X) -> np.ndarray:
        """This memory as the sensing block's state (its layout ``X``: the carry an executor fills)."""
        return X.pack(t_prev=self.t_prev, theta_B=self.theta_B, omega_prev=self.omega_prev, xs=self.xs)

    def take(self, X, v) -> None:
        """The previous tick's time and rate and ``theta_B`` from the sensing block's state ``v``
        (layout ``X``) an executor carried (``xs`` and ``ys`` come with the rows)."""
        m = X.split(v)
        self.t_prev = float(m["t_prev"][0])
        self.theta_B[:], self.omega_prev[:] = m["theta_B"], m["omega_prev"]


class RunState:
    """What the executors of one run hand back: the rows, the state, the counts.

    Attributes
    ----------
    x : ndarray  The plant's state (after the last tick run; at the end, the final state).
    u : ndarray  The model's held input (``comp.input_layout``; ``u_cmg``: the CMG cluster's
        held input the last row reports).
    last_cmd : tuple  The law's last torque command a row reported.
    flight : FlightMemory or None  The flight suite's memory.
    ticks, n_rate_limited, n_momentum_saturated : int  Ticks integrated; ticks the CMGs were
        rate limited and momentum saturated (the final tick's actuation is reported, not counted).
    used_fused : bool  Whether a fused executor ran.
    """

    def __init__(self, comp: Composition, rows, x: np.ndarray):
        self.comp, self.rows = comp, rows
        self.x = x
        self.u = np.zeros(comp.input_layout.size)
        self.last_cmd = (0.0, 0.0, 0.0)
        self.flight: FlightMemory | None = None
        self.ticks = 0
        self.n_rate_limited = 0
        self.n_momentum_saturated = 0
        self.used_fused = False
        self.held_rate = 0  # a per-tick executor's environment blocks (the composed parts' env block; 0: every stage)
        # what a row reads of the composition, looked up once (a row per output sample)
        self._gimbals = slice(comp.u_cmg.start, comp.u_cmg.start + comp.ng) if comp.has_cluster else None
        self._q = comp.state_layout.slice("q_BN")
        self._u_cmg = comp.u_cmg if comp.has_cluster else None

    # -- rows ------------------------------------------------------------------------------
    def held_row(self, flag: int, t: float = math.nan):
        """The row's held values (after the state's columns) and the law's reference:
        the CMG cluster's held input and the saturation flag, the torque command (NaN when the
        law commands rates), the attitude error's four columns (NaN: from the reference, by the
        rows a batch at a time), the flight suite's and the actuators' columns."""
        comp = self.comp
        vals = []
        if self._gimbals is not None:
            vals += list(self.u[self._gimbals])
            vals.append(float(flag))
        ctrl = comp.ctrl
        q_ref = ctrl.q_ref_BN
        if q_ref is not None:
            if q_ref.__class__ is not np.ndarray or q_ref.dtype != np.float64 or q_ref.shape != (4,):
                q_ref = self._check_q_ref(q_ref, t)
        tau = self.last_cmd if ctrl.command == "torque" else (math.nan,) * 3
        vals += list(tau) + [math.nan] * 4  # att_err_deg and its axes: from q_ref, by the rows a batch at a time
        if comp.flight is not None:
            q = np.asarray(self.x[self._q], dtype=float)
            vals += comp.flight.row(self.flight.xs, self.flight.ys, q / np.linalg.norm(q))
        for a in comp.memories:
            vals += a.row()
        return vals, q_ref

    def row(self, t: float, x, flag: int, *, u_cmg=None, cmd=None, q_ref=None, xs=None, ys=None) -> None:
        """Hand back the output row at ``t``: the state ``x`` (kept as the state), the chain
        end's held ``u_cmg``, the law's command ``cmd`` (its last torque, when 3 values) and
        reference ``q_ref``, the flight suite's state and outputs after the row's tick."""
        self.x = x
        if u_cmg is not None:
            self.u[self._u_cmg] = u_cmg
        if cmd is not None and len(cmd) == 3:
            self.last_cmd = tuple(cmd)
        if q_ref is not None:
            self.comp.ctrl.q_ref_BN = tuple(q_ref)
        if xs is not None:
            self.flight.xs, self.flight.ys = xs, ys
        self.rows.hold(t, x, *self.held_row(flag, t))

    def rows_many(self, ts, xs, held, q_ref, counts, *, u_cmg=None, cmd=None) -> None:
        """Hand back many rows at once (:meth:`~.rows.Rows.hold_many`: times, states, held values,
        references; raises IntegrationError at a non-finite row, the rows before it kept), then,
        as :meth:`row` and :meth:`count` do for one row, the rows' ``counts`` (rate limited,
        saturated per row) and the last row's held ``u_cmg``, command ``cmd`` and reference."""
        self.rows.hold_many(ts, xs, held, q_ref)
        self.count(counts[:, 0].sum(), counts[:, 1].sum())
        if u_cmg is not None:
            self.u[self._u_cmg] = u_cmg
        if cmd is not None and len(cmd) == 3:
            self.last_cmd = tuple(cmd)
        self.comp.ctrl.q_ref_BN = tuple(q_ref[-1])

    def count(self, rate_limited: int, saturated: int) -> None:
        """Add ticks the CMGs were rate limited / momentum saturated."""
        self.n_rate_limited += int(rate_limited)
        self.n_momentum_saturated += int(saturated)

    def end(self, x, ticks: int, law_updates: int | None = None) -> None:
        """A fused executor's end (also after a failure): the final state, the ticks integrated
        (the integrator's steps: one per tick), the law's compiled updates, the rows flushed."""
        comp = self.comp
        self.x = x
        self.ticks = ticks
        comp.ctrl.count_compiled_updates(ticks + 1 if law_updates is None else law_updates)
        comp.integ.count_steps(ticks)
        self.rows.flush()

    def _check_q_ref(self, q_ref, t: float) -> np.ndarray:
        """The law's ``q_ref_BN`` as 4 floats, or ControllerFailure at the tick's time ``t``
        naming the controller and what it set (a string, a (4, 1) array...)."""
        try:
            return command_values(q_ref, 4, "q_ref_BN, scalar first", finite=False)
        except ValueError as e:
            raise ControllerFailure(t, f"controller '{self.comp.ctrl.name}' set q_ref_BN to {e}") from None
