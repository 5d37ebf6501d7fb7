"""A run's blocks (issue 33): its :class:`~.composition.Composition` read as the plant and the
blocks of :mod:`stationbed.loop.block`, composed once (:func:`composed`, cached by the
composition's one key).

The blocks of a run, in the tick's order: the sensing (``[[sensor]]`` tables and the
``[estimator]``: :func:`~stationbed.loop.block.sensing_block`), the law (its symbolic form and
state, :mod:`.law_state`), the actuators before the chain's end (``comp.actuators`` in chain order:
:func:`~stationbed.loop.block.actuator_block`) and the end (the CMG cluster or the ideal
torquer at the plant's state, :func:`~.system.chain_end_inputs`). A block that cannot be
symbolic (a law without ``symbolic``, the LP mapping) is a block with ``symbolic = False``
and the reason: :func:`blocker` names it.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from ..core.layout import Layout
from ..loop.block import Block, actuator_block, corruption_block, delay_block, sensing_block
from ..loop.compose import Composed, Plant, compose
from . import law_state
from .env_block import env_block, environment_rate
from .rate_auto import AUTO, auto_choice
from .segments import edge_ticks, max_edges
from .system import chain_end_inputs, environment_split, has_environment

__all__ = ["plant_of", "env_block", "law_block", "end_block", "run_blocks", "composed", "blocker", "structure_key", "fixed_tick",
           "parts_ok", "held_rate", "rate_summary", "Draws", "numbers"]

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


def law_block(comp, cp, in_python: bool = False) -> Block:
    """The law as a block: input the measurement it sees, outputs its command and reference,
    memory its own state (``symbolic_state``), numbers ``symbolic_params``; not symbolic (a
    stand-in without expression, memory or numbers) when the law has no ``symbolic`` form (a
    Python or FMU law), or ``in_python``: the executor calls the law itself and never the block
    (the generic path, :func:`~.parts.generic_parts`)."""
    ctrl = comp.ctrl
    ny, ncmd = comp.meas_layout.size, comp.n_cmd
    Y = Layout(cmd=ncmd, q_ref=4)
    has_form = callable(getattr(ctrl, "symbolic", None))
    if in_python or not has_form:
        f = ca.Function("law", [ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h"), ca.SX(0, 1), ca.SX.sym("y", ny),
                                ca.SX(0, 1), ca.SX(0, 1)], [ca.SX(0, 1), ca.SX.zeros(Y.size)])
        why = (f"controller '{ctrl.name}' is called in Python per tick" if has_form
               else f"controller '{ctrl.name}' has no symbolic form (a Python law, called per tick)")
        return Block("law", "law", f, Layout(), Layout(), Layout(), Layout(y=ny), Y, symbolic=False, why=why)
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


def run_blocks(comp, cp, rate: int = 0, law_in_python: bool = False) -> list[Block]:
    """The blocks of the run composed by ``comp`` (module docstring), in the tick's order; with
    an environment ``rate`` (ticks per evaluation), the held environment first; the law's a
    stand-in when ``law_in_python`` (:func:`law_block`)."""
    blocks = [env_block(comp, rate)] if rate else []
    if comp.flight is not None:
        blocks.append(sensing_block(comp.flight))
    if comp.delay:  # [controller.sensor] delay, then its noise, on what the sensing gives
        blocks.append(delay_block(comp.delay, comp.meas_layout.size))
    if comp.ideal_noise is not None:
        blocks.append(corruption_block(comp.corruption, comp.meas_layout.size))
    blocks.append(law_block(comp, cp, law_in_python))
    for a in comp.actuators:  # the chain, in order (run/chain.py)
        blocks.append(actuator_block(a.cluster, a.name))
    if comp.fdir is not None:  # the last of the chain: it sees what is left to the CMGs
        blocks.append(comp.fdir.block)
    blocks.append(end_block(comp))
    return blocks


def numbers(comp, cp) -> dict:
    """Each block's numbers and memory at the run's start, ``{name: (params, state or None)}``,
    of the run composed by ``comp`` (``cp`` the law's symbolic numbers): what an executor
    writes into a cached composition's parameters and carry by the blocks' names (a cached
    block's own ``p0``/``x0`` are those of the run that built it)."""
    out = {"law": (np.asarray(cp, dtype=float), law_state.initial(comp.ctrl))}
    if comp.flight is not None:
        out["sensing"] = (comp.flight.params, None)
    for a in comp.actuators:  # the chain, by each block's name (run/chain.py)
        out[a.name] = (a.cluster.params, a.x)
    if comp.fdir is not None:  # [fdir]: the chain's last block (run/fdir_run.py)
        out[comp.fdir.block.name] = (comp.fdir.block.p0, comp.fdir.x)
    return out


def blocker(comp, cp=()) -> Block | None:
    """The one block of ``comp`` that keeps it off the compiled path, or None."""
    for b in run_blocks(comp, cp):
        if not b.symbolic:
            return b
    return None


def structure_key(comp, cp) -> tuple:
    """What the run's composed functions depend on, read without building a block (numbers are
    inputs, never in the key): the compiled system, the law's class, command, state and
    parameter sizes, the flight's key, the chain's structure, the chain end's kind, the ideal
    measurement's delay and the fields its noise corrupts."""
    ctrl = comp.ctrl
    return (id(comp.system), type(ctrl), ctrl.command, law_state.initial(ctrl).size, len(cp),
            None if comp.flight is None else comp.flight.key,
            tuple((a.name, a.cluster.key, a.lp) for a in comp.actuators), type(comp.end).__name__, held_rate(comp)[0],
            None if comp.fdir is None else comp.fdir.block.key,
            comp.delay, None if comp.ideal_noise is None else comp.corruption.flags,
            *((("edges", max_edges(comp)),) if max_edges(comp) else ()))


def fixed_tick(comp) -> bool:
    """Whether the run's integrator is one fixed explicit step per tick (what a composed tick
    steps: the fused loop and the per-tick loop's compiled parts)."""
    integ = comp.integ
    return bool(integ.fusable and math.ceil(comp.period / integ.h_nominal - 1e-9) == 1 and comp.system.sx is not None)


def parts_ok(comp) -> str | None:
    """Why the per-tick loop cannot fly the run through the composed parts (None: it can): the
    integrator (not one fixed step per tick), an array rate step (the state jumps there: the
    generic path cuts and jumps), an actuator that is not symbolic. A discontinuity between
    ticks is not one: its tick is the edge tick's case (:func:`composed`, ``edges``)."""
    if not fixed_tick(comp):
        return "the integrator is not one RK4 step per tick"
    if edge_ticks(comp) is None:
        return "an array rate step (the generic path cuts there and jumps)"
    for a in comp.actuators:
        if a.lp:
            return f"an actuator that is not symbolic ({a.name}: {a.cluster.why})"
    return None


def held_rate(comp) -> tuple[int, str | None]:
    """``(ticks per block, why not)``: the environment rate the composed loop holds (0: every
    stage; :func:`.rates.environment_rate`), the same for every executor where it steps the
    composed tick or its parts; else 0 and why (:func:`parts_ok`; None without environment
    torques). Asked first, so a run that cannot hold never probes."""
    why = parts_ok(comp)
    if why is None:
        return environment_rate(comp), None
    return 0, f"{why}: the per-tick loop evaluates every stage" if has_environment(comp.system) else None


def rate_summary(loop, used_fused: bool, held: int = 0) -> dict:
    """What the run's summary records (``loop`` the run's composition, ``used_fused`` whether a
    fused executor ran, ``held`` the per-tick executor's ticks per block) of the effect rates:
    the environment's ticks per evaluation (0 = every integrator stage) as run, and as the scene
    asked; under ``"auto"`` also the bound of the rate run (``environment_rate_bound_rad``) or
    why it is every stage, and for a rate ``N`` asked and not run, why
    (``environment_rate_why``). A block never spans an output row (each chunk starts its own),
    so the run's rate is at most the ticks per row."""
    asked = getattr(loop.scene.simulation, "environment_rate", 0)
    asked = asked if asked == AUTO else int(asked or 0)
    ran = min(environment_rate(loop), loop.n_per_out) if (used_fused or held) else 0
    out = {"environment_rate_ticks": ran, "environment_rate_asked": asked}
    cannot = None if (used_fused or held) else held_rate(loop)[1]  # why a per-tick run did not hold
    if asked == AUTO:  # the same keys whichever executor ran
        if not has_environment(loop.system):
            c = {"bound_rad": None, "why": "no environment torque"}
        elif cannot is not None:  # auto chose a rate the loop cannot hold
            c = {"bound_rad": None, "why": cannot}
        else:
            c = auto_choice(loop)  # kept per scene: no second probe
        out["environment_rate_bound_rad"] = c["bound_rad"] if ran else None
        out["environment_rate_why"] = c["why"]
    elif asked and not ran:  # a rate asked and every stage run: why, as under auto
        out["environment_rate_why"] = ("no environment torque" if not has_environment(loop.system)
                                       else cannot or "the executor evaluates every stage")
    elif asked and ran < asked:  # more ticks asked than a row has: the row's (a block never spans one)
        out["environment_rate_why"] = f"at most the ticks of an output row ({loop.n_per_out}): a block never spans one"
    return out


def composed(comp, cp, edges: bool = False, law_in_python: bool = False) -> tuple[Composed, float]:
    """The run's composition composed (cached by its structure, :func:`structure_key`) and the
    seconds it took to build now (0 when cached); ``edges``: its edge tick's case (the step also
    cut at the scene's discontinuities inside the tick, :func:`~.segments.tick_edges`; the same
    blocks, the parameters with ``edge`` appended); ``law_in_python``: the law's block a
    stand-in, for an executor that calls the law itself (:func:`law_block`)."""
    key = (structure_key(comp, cp) + (("edge case",) if edges else ())
           + (("law in Python",) if law_in_python else ()))
    hit = _COMPOSED.get(key)
    if hit is not None and hit[0] is comp.system:
        return hit[1], 0.0
    t0 = time.perf_counter()
    rate = held_rate(comp)[0]
    c = compose(plant_of(comp, rate), run_blocks(comp, cp, rate, law_in_python), max_edges(comp) if edges else 0)
    _COMPOSED[key] = (comp.system, c)
    return c, time.perf_counter() - t0


class Draws:
    """The composition's draws by tick, each block's from its own stream (a
    :class:`~stationbed.loop.flight.TickNoise`), in tick order: the sensing block's
    (``comp.tick_noise``: its sensors' streams), the noise block's (``comp.ideal_noise``: the
    corruption's). ``rows(k0, n)`` -> (n, width); ``state()`` / ``restore()`` put every stream
    back (the rows asked again are the same numbers)."""

    def __init__(self, comp, cm):
        N = cm.noise
        self.width = N.size
        streams = {"sensing": comp.tick_noise, "noise": comp.ideal_noise}
        self.src = [(N.slice(name), streams[name]) for name in N.names]

    def rows(self, k0: int, n: int) -> np.ndarray:
        if len(self.src) == 1 and self.src[0][0] == slice(0, self.width):
            return self.src[0][1].rows(k0, n)
        out = np.zeros((n, self.width))
        for sl, stream in self.src:
            out[:, sl] = stream.rows(k0, n)
        return out

    def state(self):
        return [stream.state() for _, stream in self.src]

    def restore(self, st) -> None:
        for (_, stream), s in zip(self.src, st):
            stream.restore(s)
