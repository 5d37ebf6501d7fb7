"""One block contract for every part of the closed loop's tick (issue 33, docs/design.md "One
loop, built once").

A block is a discrete-time system on the control tick, written **once** as a casadi function

``(x_next, y) = step(k, t, h, x, u, w, p)``

* ``k`` the tick index, ``t`` its time [s], ``h`` its length [s];
* ``x`` the block's memory (:attr:`Block.state`), ``p`` its numbers (:attr:`Block.params`),
  ``w`` its standard-normal draws of the tick (:attr:`Block.noise`), ``u`` what it reads
  (:attr:`Block.inputs`), ``y`` what it reports (:attr:`Block.outputs`): each a named
  :class:`~stationbed.core.layout.Layout`, so the composer (:mod:`.compose`) wires blocks by
  field name and nobody writes a position.

Optional, each exact (an executor that does not use it gives the same numbers):

* :attr:`Block.idle` ``(k, t, h, x, u, p) -> flag``: when 1, the step is the block's *idle
  form* (an actuator: its memory kept, the whole request passed on, no channel on), so a
  composed tick may skip it (the quiet tick);
* :attr:`Block.plain` ``step_plain`` with :attr:`Block.is_plain` ``(k) -> flag``: on the ticks
  where ``is_plain(k)``, ``step_plain`` (an SX function, no switch left) is the step (a sensor
  suite between its slower sensors' samples); ``is_plain`` None: on every tick (an SX block);
* :attr:`Block.every`: its period in ticks (a block samples on ticks ``k % every == 0``; the
  suite's own sensors keep theirs inside it).

:attr:`Block.symbolic` is False for a block that cannot be a casadi expression (a Python or
FMU law, the LP thruster mapping): it keeps the run off the fused path, and the composer names
it (:func:`~.compose.off_path`). Roles (:data:`ROLES`) say where in the tick a block sits:
``env`` (an effect evaluated once every ``every`` ticks and held: its output ``L_hold`` is added
to the held external torque, the plant then steps its right-hand side without it), ``sense`` (truth row -> what the law sees), ``law`` (what it sees -> the command), ``actuator``
(a request -> the rest it leaves to the next, its pulse channels), ``end`` (the chain's end: the
plant's held input from what is left).

Adapters of the existing plug-ins (no numbers change: the same casadi functions are called):
:func:`actuator_block` (an :class:`~.actuator.Actuator` before the chain's end),
:func:`sensing_block` (the :class:`~.flight.Flight` suite and estimator); the ideal
measurement's delay and corruption (``[controller.sensor]``): :func:`delay_block`,
:func:`corruption_block`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..core.layout import Layout

__all__ = ["Block", "ROLES", "actuator_block", "sensing_block", "delay_block", "corruption_block", "ACT_OUT", "off_path"]

#: where a block sits in the tick, in the order the composer calls them
ROLES = ("env", "sense", "law", "actuator", "end")


@dataclass(frozen=True, eq=False)
class Block:
    """One part of the tick (module docstring): its layouts, its step, its exact shortcuts."""

    name: str  #: the block's name (unique in a composition: its fields in the carry are named by it)
    role: str  #: one of :data:`ROLES`
    step: ca.Function  #: ``(k, t, h, x, u, w, p) -> (x_next, y)``
    state: Layout
    params: Layout
    noise: Layout
    inputs: Layout
    outputs: Layout
    every: int = 1  #: its period in ticks
    idle: ca.Function | None = None  #: ``(k, t, h, x, u, p) -> flag``: the exact idle form applies
    plain: ca.Function | None = None  #: the step on a plain tick (SX), or None
    is_plain: object = None  #: ``is_plain(k)`` (casadi), with :attr:`plain`
    symbolic: bool = True  #: False: a Python/FMU block, the run is flown per tick
    why: str = ""  #: for a block that is not symbolic: one line saying why (the summary)
    key: tuple = field(default=())  #: what its expressions depend on (equal keys: equal functions)
    x0: object = None  #: its memory at t = 0 (numpy), when the block knows it alone
    p0: object = None  #: its numbers (numpy)
    #: an actuator whose channels are on the whole tick (``FULL_TICK``): its torques are added to
    #: the held torque, no edge cut inside the tick (the same numbers)
    full_tick: bool = False
    #: a block that is not symbolic: its step in Python, ``(k, t, h, x, u, p) -> (x_next, y)`` on
    #: numpy vectors of the same layouts (what a per-tick executor calls in its place: the LP mapping)
    python: object = None

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"block {self.name!r}: role {self.role!r}, expected one of {ROLES}")
        if self.symbolic:
            want = [self.state.size, self.inputs.size, self.noise.size, self.params.size]
            shape_ok = self.step.n_in() == 7 and self.step.n_out() == 2
            got = [self.step.size1_in(i) for i in (3, 4, 5, 6)] if shape_ok else None
            if not shape_ok or got != want:
                raise ValueError(f"block {self.name!r}: step must be (k, t, h, x[{want[0]}], u[{want[1]}], "
                                 f"w[{want[2]}], p[{want[3]}]) -> (x_next, y), got {self.step}")
            if self.step.numel_out(1) != self.outputs.size:
                raise ValueError(f"block {self.name!r}: step reports {self.step.size1_out(1)} values, "
                                 f"its outputs layout {self.outputs.size}")

    def call(self, k, t, h, x, u, w, p, plain: bool = False):
        """``(x_next, y)`` on symbols (the plain step when ``plain`` and the block has one)."""
        f = self.plain if (plain and self.plain is not None) else self.step
        return f(k, t, h, x, u, w, p)


#: an actuator block's outputs beside its own ``out``: the request left to the next block, its
#: channels' on-times over the tick and torques (3 per channel, column-major)
def ACT_OUT(n_channels: int, out: Layout) -> Layout:
    return Layout(tau_rest_B=3, on_s=n_channels, torque_B=3 * n_channels, out=out.size)


def actuator_block(act, name: str = "thrusters") -> Block:
    """The :class:`~.actuator.Actuator` plug-in ``act`` as a block before the chain's end: inputs
    its ``READS`` fields (by their measurement names: ``h_B``; ``q_BN_true``: the true
    measurement's, rule 2 of the contract) then the request ``tau_B``; outputs :func:`ACT_OUT`; its ``_idle`` as the idle
    form (rule 7 of the actuator contract). The same casadi function the per-tick loop compiles."""
    f = act.function()
    n = act.n_channels
    reads = act.reads
    U = Layout(**{f_: reads.slice(f_).stop - reads.slice(f_).start for f_ in reads.names}, tau_B=3)
    Y = ACT_OUT(n, act.outputs)
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    x, u, p, w = act.state.symbol("x"), U.symbol("u"), act.param_layout.symbol("p"), ca.SX(0, 1)
    r = u[: reads.size]  # its READS fields, in READS order (the composer wires them by name)
    x1, rest, on_s, tq, out = f(t, h, x, r, U.get(u, "tau_B"), p)
    step = ca.Function(f"{name}_step", [k, t, h, x, u, ca.SX.sym("w", 0), p],
                       [x1, Y.pack(tau_rest_B=rest, on_s=on_s, torque_B=tq, out=out)])
    idle_f = act.idle_function()
    idle = None
    if idle_f is not None:
        idle = ca.Function(f"{name}_idle", [k, t, h, x, u, p], [idle_f(t, x, r, U.get(u, "tau_B"), p)])
    return Block(name, "actuator", step, act.state, act.param_layout, Layout(), U, Y, idle=idle,
                 symbolic=not act.python_only, why=act.why, key=(type(act).__name__, act.key),
                 x0=act.x0, p0=act.params, full_tick=act.FULL_TICK,
                 python=_python_step(act, reads.size, U, Y) if act.python_only else None)


def _python_step(act, n_r: int, U: Layout, Y: Layout):
    """The step of a ``python_only`` actuator (rule 9 of the contract: its ``command_numeric``)
    in the block's layouts: ``u`` (``U``) its reads then ``tau_B``, ``y`` :func:`ACT_OUT`."""

    def step(k, t, h, x, u, p):
        x1, rest, on_s, torque_B, out = act.command_numeric(t, h, x, u[:n_r], U.get(u, "tau_B"))
        return x1, Y.pack(tau_rest_B=rest, on_s=on_s, torque_B=np.asarray(torque_B).T.ravel(), out=out)
    return step


def sensing_block(flight, name: str = "sensing") -> Block:
    """The scene's sensors and estimator (:class:`~.flight.Flight`) as one ``sense`` block:
    input the true measurement ``y`` (the executor's measurement layout), outputs what the law
    sees ``y_seen`` (the same layout: the estimate in place of the truth with an
    ``[estimator]``) and the suite's outputs ``ys``; its memory the previous tick's time and
    true rate, ``theta_B = ∫ω dt`` and the suite's state. The flight's MX tick (its sensors
    behind switches) is the step; its plain tick (SX) the plain step."""
    S = flight.suite
    X = Layout(t_prev=1, theta_B=3, omega_prev=3, xs=S.STATE.size)
    U = Layout(y=flight.ny)
    Y = Layout(y_seen=flight.ny, ys=S.OUTPUTS.size)
    P = Layout(ps=flight.params.size)
    om = flight.meas.slice("omega_BN_B")

    def wrap(fl, cls, fname, opts):
        k, t, h = cls.sym("k"), cls.sym("t"), cls.sym("h")
        x, u, w, p = X.symbol("x", cls), U.symbol("u", cls), S.NOISE.symbol("w", cls), P.symbol("p", cls)
        th1, xs1, seen, ys = fl(k, t, X.get(x, "t_prev"), u, X.get(x, "theta_B"), X.get(x, "omega_prev"),
                                X.get(x, "xs"), w, p)
        x1 = ca.vertcat(t, th1, u[om], xs1)
        return ca.Function(fname, [k, t, h, x, u, w, p], [x1, ca.vertcat(seen, ys)], opts)

    step = wrap(flight.function(), ca.MX, f"{name}_step", {"always_inline": True})
    fp = flight.plain_function()
    plain = wrap(fp, ca.SX, f"{name}_plain", {}) if fp is not None else None
    return Block(name, "sense", step, X, P, S.NOISE, U, Y, plain=plain,
                 is_plain=S.is_plain if plain is not None else None, key=("flight", flight.key), p0=flight.params)


def delay_block(delay: int, ny: int, name: str = "delay") -> Block:
    """The ideal measurement's delay (``[controller.sensor] delay``, ``delay`` >= 1 whole ticks)
    as a ``sense`` block: at tick k it passes on the measurement of tick ``k - delay``, tick 0's
    before that. Its memory ``ring`` holds the last ``delay`` measurements it was given, oldest
    first. The plain step (every tick but the first, ``is_plain``: k > 0) is the shift alone
    (out the oldest, in the tick's); the step is an explicit branch on ``k == 0`` (a casadi
    ``Function.if_else``: only the case taken runs), where the ring is filled with tick 0's
    measurement: copies only, so what the law sees is that measurement bit for bit."""
    SX, MX = ca.SX, ca.MX
    R = Layout(ring=delay * ny)

    def case(fname, first: bool):
        k, t, h, ring, y = SX.sym("k"), SX.sym("t"), SX.sym("h"), R.symbol("ring"), SX.sym("y", ny)
        x1, out = (ca.repmat(y, delay, 1), y) if first else (ca.vertcat(ring[ny:], y), ring[:ny])
        return ca.Function(fname, [k, t, h, ring, y, SX.sym("w", 0), SX.sym("p", 0)], [x1, out])

    plain = case(f"{name}_plain", first=False)
    branch = ca.Function.if_else(f"{name}_branch", case(f"{name}_first", first=True), plain)
    ins = [MX.sym("k"), MX.sym("t"), MX.sym("h"), R.symbol("ring", MX), MX.sym("y", ny), MX.sym("w", 0), MX.sym("p", 0)]
    step = ca.Function(f"{name}_step", ins, branch(ins[0] < 0.5, *ins))
    return Block(name, "sense", step, R, Layout(), Layout(), Layout(y=ny), Layout(y_seen=ny), plain=plain,
                 is_plain=_after_first, key=("delay", delay))


def _after_first(k):
    """Whether tick ``k`` (casadi) is past the first: the delay's ring is full."""
    return k > 0.5


def corruption_block(corruption, ny: int, name: str = "noise") -> Block:
    """The ideal measurement's noise (``[controller.sensor]``, :class:`~.corruption.Corruption`)
    as a ``sense`` block: the law sees the measurement corrupted by the tick's draws (attitude,
    then rate: :func:`~.corruption.draws_layout`); SX, plain on every tick. Its delay is the
    block before it (:func:`delay_block`)."""
    from .corruption import corrupt_symbolic, draws_layout  # noqa: PLC0415 (a sibling, imported where used)

    flags = corruption.flags
    W = draws_layout(*flags)
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    y, w = ca.SX.sym("y", ny), W.symbol("w")
    seen = corrupt_symbolic(y, w, flags, corruption.layout) if W.size else y
    f = ca.Function(f"{name}_step", [k, t, h, ca.SX.sym("x", 0), y, w, ca.SX.sym("p", 0)], [ca.SX(0, 1), seen])
    return Block(name, "sense", f, Layout(), Layout(), W, Layout(y=ny), Layout(y_seen=ny), plain=f,
                 key=("noise", tuple(flags)))


def off_path(blocks) -> Block | None:
    """The one block that keeps a composition off the compiled path (not symbolic), or None."""
    for b in blocks:
        if not b.symbolic:
            return b
    return None
