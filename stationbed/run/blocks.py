"""A run's blocks (issue 33): its :class:`~.composition.Composition` read as the plant and the
blocks of :mod:`stationbed.loop.block`, composed once (:func:`composed`, cached by the
composition's one key).

The blocks of a run, in the tick's order: the sensing (``[[sensor]]`` tables and the
``[estimator]``: :func:`~stationbed.loop.block.sensing_block`), the law (its symbolic form and
state, :mod:`.law_state`), the actuators before the chain's end (the ``[[thruster]]`` tables:
:func:`~stationbed.loop.block.actuator_block`) and the end (the CMG cluster or the ideal
torquer at the plant's state, :func:`~.system.chain_end_inputs`). A block that cannot be
symbolic (a law without ``symbolic``, the LP mapping) is a block with ``symbolic = False``
and the reason: :func:`blocker` names it.
"""

from __future__ import annotations

import time

import casadi as ca

from ..core.layout import Layout
from ..loop.block import Block, actuator_block, corruption_block, sensing_block
from ..loop.compose import Composed, Plant, compose
from . import law_state
from .chunk_layout import ENV
from .rates import environment_rate, hold_value
from .system import chain_end_inputs, environment_split

__all__ = ["plant_of", "law_block", "end_block", "run_blocks", "composed", "blocker", "structure_key"]

_COMPOSED: dict = {}


def plant_of(comp, rate: int = 0) -> Plant:
    """The plant of ``comp`` for the composer: the compiled system's SX ``meas`` and ``rhs``, the
    integrator's fixed step, the measurement's and the held input's layouts; with an environment
    ``rate``, the right-hand side without the environment kinds (:func:`~.system.environment_split`)."""
    system = comp.system
    form = system.formulation
    model = form.model
    held = environment_split(system)["rhs_fast"] if rate else None
    return Plant(system.sx["meas"], system.sx["rhs"], system.integrator_cls.explicit_step, form.nx, model.layout.size,
                 comp.meas_layout, model.input_layout, (form.name, system.integrator_cls.name, model.structure.key), held)


def env_block(comp, rate: int) -> Block:
    """The environment torques (aero, SRP: the kinds with ``needs_env``) evaluated once every
    ``rate`` ticks and held (issue 25's blocks, run/rates.py): memory the last evaluation
    ``(L_prev, t_prev, have)`` and the held value ``L_hold``; inputs the plant's state and the
    block's active ticks ``n_b``; numbers the model's. Its step is :func:`.rates.hold_value` on
    the split's ``env_B``, as the hand-composed held chunks evaluate it."""
    system = comp.system
    nx, npar = system.formulation.nx, system.formulation.model.layout.size
    env_B = environment_split(system)["env_B"]
    X = Layout(**{f: ENV.shape(f)[0] for f in ENV.names}, L_hold=3)
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    xe, u, p = X.symbol("xe"), ca.SX.sym("u", nx + 1), ca.SX.sym("p", npar)
    x, n_b = u[:nx], u[nx]
    L_now = env_B(t, x, p)
    L_hold = hold_value(L_now, X.get(xe, "L_prev"), t, X.get(xe, "t_prev"), X.get(xe, "have"), n_b, h)
    x1 = X.pack(L_prev=L_now, t_prev=t, have=1.0, L_hold=L_hold, symbolic=True)
    f = ca.Function("env_step", [k, t, h, xe, u, ca.SX.sym("w", 0), p], [x1, L_hold])
    return Block("env", "env", f, X, Layout(p=npar), Layout(), Layout(x=nx, n_b=1), Layout(L_hold=3), every=rate,
                 key=("env", rate))


def law_block(comp, cp) -> Block:
    """The law as a block: input the measurement it sees, outputs its command and reference,
    memory its own state (``symbolic_state``), numbers ``symbolic_params``; not symbolic when
    the law has no ``symbolic`` form (a Python or FMU law)."""
    ctrl = comp.ctrl
    ny, ncmd = comp.meas_layout.size, comp.n_cmd
    Y = Layout(cmd=ncmd, q_ref=4)
    if not callable(getattr(ctrl, "symbolic", None)):
        f = ca.Function("law", [ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h"), ca.SX(0, 1), ca.SX.sym("y", ny),
                                ca.SX(0, 1), ca.SX(0, 1)], [ca.SX(0, 1), ca.SX.zeros(Y.size)])
        return Block("law", "law", f, Layout(), Layout(), Layout(), Layout(y=ny), Y, symbolic=False,
                     why=f"controller '{ctrl.name}' has no symbolic form (a Python law, called per tick)")
    s0 = law_state.initial(ctrl)
    ncp = len(cp)
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    s, y, cps = ca.SX.sym("s", s0.size), ca.SX.sym("y", ny), ca.SX.sym("cp", ncp)
    cmd, q_ref, s1 = law_state.symbolic(ctrl, t, y, cps, s, ncmd)
    f = ca.Function("law", [k, t, h, s, y, ca.SX.sym("w", 0), cps], [s1, ca.vertcat(cmd, q_ref)])
    return Block("law", "law", f, Layout(s=s0.size), Layout(cp=ncp), Layout(), Layout(y=ny), Y,
                 key=(type(ctrl).__name__, ctrl.command, s0.size, ncp), x0=s0, p0=cp)


def end_block(comp) -> Block:
    """The chain's end (the CMG cluster or the ideal torquer) at the plant's state: inputs the
    plant's state ``x``, the request left to it ``tau`` and the held external torque ``u_ext``;
    outputs its report ``act``, the model's held input ``u`` and ``sat`` (rate limited,
    saturated); numbers the model's (it is part of the plant)."""
    system = comp.system
    form = system.formulation
    model = form.model
    nx, npar, ncmd = form.nx, model.layout.size, comp.n_cmd
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    x, tau, u_ext, p = ca.SX.sym("x", nx), ca.SX.sym("tau", ncmd), ca.SX.sym("u_ext", 3), ca.SX.sym("p", npar)
    extra = {}
    p_end = p
    if comp.fdir is not None:  # the units flight software isolated: out of the steering law
        n_units = comp.fdir.spec.n_units
        excl = extra["cmg_excluded"] = ca.SX.sym("cmg_excluded", n_units)
        p_end = known_working(model, p, excl)
    act, u, sat = chain_end_inputs(system.sx, model, comp.end, comp.command, t, h, x, tau, u_ext, p_end)
    U = Layout(x=nx, tau=ncmd, u_ext=3, **{f: v.numel() for f, v in extra.items()})
    Y = Layout(act=act.numel(), u=u.numel(), sat=2)
    # (a function's input must be purely symbolic: one symbol, the fields substituted in)
    u_in = ca.SX.sym("u", U.size)
    f = ca.Function("end", [k, t, h, ca.SX.sym("xe", 0), u_in, ca.SX.sym("w", 0), p],
                    [ca.SX(0, 1), ca.substitute(ca.vertcat(act, u, sat), ca.vertcat(x, tau, u_ext, *extra.values()), u_in)])
    return Block("end", "end", f, Layout(), Layout(p=npar), Layout(), U, Y,
                 key=(type(comp.end).__name__, comp.command, tuple(extra)))


def known_working(model, p, excluded):
    """The model's numbers ``p`` with each CMG unit's ``working`` flag times ``1 - excluded``:
    the steering law's view once flight software has isolated a unit (its gimbals then held,
    as a failed unit's are; model/cmg/base.py ``working``)."""
    geo = model.cmg.geometry
    at = model.layout["cmg"].start + geo.n_par - geo.n_units * (len(_tail_groups(geo)))
    parts = [p[:at]] + [p[at + i] * (1 - excluded[i]) for i in range(geo.n_units)] + [p[at + geo.n_units:]]
    return ca.vertcat(*parts)


def _tail_groups(geo) -> tuple:
    """The per-unit groups at the tail of the cluster's numbers, ``working`` first."""
    from ..model.cmg import base  # noqa: PLC0415 (a lower layer: read where used)

    return getattr(base, "UNIT_TAIL", ("working",))


def run_blocks(comp, cp, rate: int = 0) -> list[Block]:
    """The blocks of the run composed by ``comp`` (module docstring), in the tick's order; with
    an environment ``rate`` (ticks per evaluation), the held environment first."""
    blocks = [env_block(comp, rate)] if rate else []
    if comp.flight is not None:
        blocks.append(sensing_block(comp.flight))
    if comp.corruption is not None:  # [controller.sensor] noise (its delay: per tick, fused.fused_ok)
        blocks.append(corruption_block(comp.corruption, comp.meas_layout.size))
    blocks.append(law_block(comp, cp))
    if comp.thrust is not None:
        b = actuator_block(comp.thrust.cluster)
        if comp.thrust.lp:
            b = Block(b.name, b.role, b.step, b.state, b.params, b.noise, b.inputs, b.outputs, symbolic=False,
                      why="mapping = 'lp' runs scipy's HiGHS in Python each tick")
        blocks.append(b)
    if comp.fdir is not None:  # the last of the chain: it sees what is left to the CMGs
        blocks.append(comp.fdir.block)
    blocks.append(end_block(comp))
    return blocks


def blocker(comp, cp=()) -> Block | None:
    """The one block of ``comp`` that keeps it off the compiled path, or None."""
    for b in run_blocks(comp, cp):
        if not b.symbolic:
            return b
    return None


def structure_key(comp, cp) -> tuple:
    """What the run's composed functions depend on, read without building a block (numbers are
    inputs, never in the key): the compiled system, the law's class, command, state and
    parameter sizes, the flight's key, the thrusters' structure, the chain end's kind."""
    ctrl = comp.ctrl
    th = comp.thrust
    return (id(comp.system), type(ctrl), ctrl.command, law_state.initial(ctrl).size, len(cp),
            None if comp.flight is None else comp.flight.key,
            None if th is None else (th.cluster.key, th.lp), type(comp.end).__name__, held_rate(comp),
            None if comp.fdir is None else comp.fdir.block.key,
            None if comp.corruption is None else comp.corruption.flags)


def held_rate(comp) -> int:
    """The environment's ticks per evaluation the composed loop holds (0: every stage): the
    scene's rate (:func:`.rates.environment_rate`), except with thrusters, whose per-tick loop
    evaluates every stage (the fused run keeps its numbers)."""
    return 0 if comp.thrust is not None else environment_rate(comp)


def composed(comp, cp) -> tuple[Composed, float]:
    """The run's composition composed (cached by its structure, :func:`structure_key`) and the
    seconds it took to build now (0 when cached)."""
    key = structure_key(comp, cp)
    hit = _COMPOSED.get(key)
    if hit is not None and hit[0] is comp.system:
        return hit[1], 0.0
    t0 = time.perf_counter()
    rate = held_rate(comp)
    c = compose(plant_of(comp, rate), run_blocks(comp, cp, rate))
    _COMPOSED[key] = (comp.system, c)
    return c, time.perf_counter() - t0
