"""The environment at its own rate in the per-tick and batch executors (issue 25, continued).

The fused loops hold aero and solar pressure (with the shadow inside SRP) over blocks of ticks
(:mod:`.rates`, the composed loop's env block): each output row's ticks are cut into pieces at the
discontinuities on the tick grid and before a short final period
(:func:`~.segments.tick_pieces`), each piece into blocks of N ticks from its start; at a block's
first tick the environment is evaluated and held at its value extrapolated to the block's
middle from the previous evaluation (:func:`.rates.hold_value`). This module gives the per-tick loop
(:mod:`.closed_loop`, a Python law called every tick) and the lockstep batch (:mod:`.lockstep`)
the same blocks and the same hold: a compiled tick without the environment kinds taking the
held torque (``tick_<cmd>_held``) and the block's evaluation (``env_block``), so a scene's
``environment_rate`` (or the bound's ``"auto"`` choice) is honoured by every executor, and a
Python law's run is the fused run's to round-off (tests/test_effect_rates.py).

Where the per-tick loop cannot cut the run into those blocks (a discontinuity between ticks or
an array rate step: the generic path integrates across it; thrusters, whose pulses split the
tick; an integrator other than one RK4 step per tick), it evaluates every stage and
:func:`held_rate` says why (the run's summary: ``environment_rate_why``).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.compile import compile_functions, sx_function
from ..loop.cmg_cluster import chain_end
from .chunk_layout import ENV
from .rate_auto import AUTO, auto_choice
from .rates import environment_rate, hold_value
from .segments import edge_ticks, held_torque_from, tick_pieces
from .system import chain_end_inputs, environment_split, has_environment

__all__ = ["held_rate", "blocks", "held_functions", "HeldBlocks", "rate_summary"]

_FUNCS: dict = {}


def held_rate(comp) -> tuple[int, str | None]:
    """``(ticks per block, why not)`` for the per-tick executors of the run composed by
    ``comp``: the rate the fused loop would run (:func:`.rates.environment_rate`; 0 = every stage)
    where the per-tick loop can cut the run into the fused loop's blocks, else 0 and the reason
    (None without environment torques). Asked first, so a run that cannot hold never probes."""
    if comp.actuators:
        why = f"{comp.actuators[0].name}: their pulses cut the tick, the per-tick loop evaluates every stage"
    elif comp.tick_name is None:
        why = "the integrator is not one RK4 step per tick: the per-tick loop evaluates every stage"
    elif edge_ticks(comp) is None:
        why = "a discontinuity between ticks (or an array rate step): the per-tick loop evaluates every stage"
    else:
        return environment_rate(comp), None
    return 0, why if has_environment(comp.system) else None


def rate_summary(loop, used_fused: bool, held: int = 0) -> dict:
    """What the run's summary records (``loop`` the run's composition, ``used_fused`` whether a
    fused executor ran, ``held`` the per-tick executor's ticks per block, :mod:`.held_env`) of
    the effect rates: the environment's ticks per evaluation (0 = every integrator stage) as run,
    and as the scene asked; under ``"auto"`` also the bound of the rate run
    (``environment_rate_bound_rad``) or why it is every stage, and for a rate ``N`` asked and not
    run, why (``environment_rate_why``). A block never spans an output row (each chunk starts
    its own), so the run's rate is at most the ticks per row."""
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


def blocks(K: int, n_per_out: int, edges, duration: float, period: float, rate: int):
    """The fused loop's blocks of ticks ``0 .. K - 1``, in order: ``(a, n_b, h, piece)`` is a
    block of ``n_b`` ticks of length ``h`` [s] starting at tick ``a``, ``piece`` whether it
    starts a stretch of held torque (:func:`~.segments.tick_pieces`: each row's ticks, cut at the
    ``edges`` on the grid and before a short final period). A generator: a long run's blocks are
    never held at once."""
    for k in range(0, K, n_per_out):
        for a, b, h in tick_pieces(k, min(k + n_per_out, K) - k, edges, duration, period):
            for s in range(a, b, rate):
                yield s, min(rate, b - s), h, s == a


def held_functions(system, command: str) -> dict:
    """The compiled ``tick_held(t, h, x, cmd, u_ext, p, L_env) -> (x1, y1, act)`` (the system's
    ``tick_<cmd>`` with the right-hand side without the environment kinds and ``u_ext + L_env``
    as the external torque: the fused loop's held tick) and ``env_block(t, x, p, env, n_b, h)
    -> (L_hold, env_next)`` (the environment at ``(t, x)``, held over the block: ``env`` is
    :data:`~.chunk_layout.ENV`'s ``(L_prev, t_prev, have)``), for ``system`` and the law's
    ``command``; compiled once per system (and kept on disk by the compile cache)."""
    key = (id(system), command)
    hit = _FUNCS.get(key)
    if hit is not None and hit[0] is system:
        return hit[1]
    split = environment_split(system)
    form = system.formulation
    model = form.model
    sx = system.sx
    nx, npar = form.nx, model.layout.size
    t, h, n_b = ca.SX.sym("t"), ca.SX.sym("h"), ca.SX.sym("n_b")
    x, u_ext, p, L_env = ca.SX.sym("x", nx), ca.SX.sym("u_ext", 3), ca.SX.sym("p", npar), ca.SX.sym("L_env", 3)
    ncmd = model.cmg.n_gimbals if command == "gimbal_rates" else 3
    cmd = ca.SX.sym("cmd", ncmd)
    act, u, _ = chain_end_inputs(sx, model, chain_end(model), command, t, h, x, cmd, u_ext + L_env, p)
    x1 = system.integrator_cls.explicit_step(split["rhs_fast"], t, x, h, u, p)
    tick = sx_function("tick_held", [t, h, x, cmd, u_ext, p, L_env], [x1, sx["meas"](t + h, x1, p), act])
    env = ca.SX.sym("env", ENV.size)
    L_now = split["env_B"](t, x, p)
    L_hold = hold_value(L_now, ENV.get(env, "L_prev"), t, env[ENV.slice("t_prev").start], env[ENV.slice("have").start],
                        n_b, h)
    block = sx_function("env_block", [t, x, p, env, n_b, h], [L_hold, ENV.pack(L_prev=L_now, t_prev=t, have=1.0)])
    tag = f"held_{form.name}_{system.integrator_cls.name}_{command}_{model.structure.key}"
    funcs = compile_functions([tick, block], tag)
    out = {"tick": funcs["tick_held"], "env": funcs["env_block"]}
    _FUNCS[key] = (system, out)
    return out


class HeldBlocks:
    """A run's blocks for a per-tick executor: at a block's first tick :meth:`start` evaluates
    the environment (the compiled ``env_block``; in the lockstep batch mapped over its samples,
    side by side, each sample with its own blocks: its own edges) and writes the held torque
    into the tick's ``L_env`` input.

    Parameters
    ----------
    comps : list of Composition  The samples' (one for the per-tick loop).
    rate, K : int  Ticks per block (:func:`held_rate`), the run's ticks.
    env : FastCall  ``env_block`` (its map over the samples).
    L_env : ndarray  The tick's ``L_env`` input (3 values per sample).
    p : ndarray  The model's parameters (per sample, side by side).

    Attributes
    ----------
    next : int  The next tick at which a sample starts a block.
    """

    def __init__(self, comps, rate: int, K: int, env, L_env, p):
        n = len(comps)
        self.comps = comps
        self.its = [blocks(K, c.n_per_out, edge_ticks(c), c.duration, c.period, rate) for c in comps]
        self.env, self.L_env = env, L_env.reshape(n, 3)
        env.args[2][:] = p
        env.args[3][:] = 0.0  # no evaluation yet (have = 0): a first block holds L_now
        self.carry, self.n_b, self.h = env.args[3].reshape(n, -1), env.args[4], env.args[5]
        self.starts = [0] * n
        self.next = 0

    def start(self, k: int, t: float, x) -> list[tuple[int, np.ndarray]]:
        """Tick ``k`` (time ``t`` [s], states ``x``) starts a block for some samples: evaluate
        and hold theirs; returns ``(i, u_ext)`` of those that also start a stretch of held torque
        (a row, or an edge on the grid): the external torque held from ``t``
        (:func:`~.segments.held_torque_from`, as the fused loop's pieces), which the executor
        gives its tick."""
        due, pieces = [i for i, s in enumerate(self.starts) if s == k], []
        for i in due:
            a, n_b, h, piece = next(self.its[i])
            if a != k:
                raise AssertionError(f"held environment: sample {i}'s block at tick {a}, asked at tick {k}")
            self.n_b[i], self.h[i], self.starts[i] = n_b, h, k + n_b
            if piece:
                c = self.comps[i]
                pieces.append((i, held_torque_from(c.scene, t, c.bps, c.duration)))
        e = self.env
        e.args[0][:] = t
        e.args[1][:] = x
        e()
        L, nxt = e.res[0].reshape(-1, 3), e.res[1].reshape(len(self.starts), -1)
        if len(due) == len(self.starts):
            self.L_env[:], self.carry[:] = L, nxt
        else:  # the others keep their block's hold and carry
            self.L_env[due], self.carry[due] = L[due], nxt[due]
        self.next = min(self.starts)
        return pieces
