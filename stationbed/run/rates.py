"""Effects at their own rate: the fused tick with the environment torques evaluated once per
block of ticks (issue 25, docs/design.md "Effects at their own rate").

Aero and solar pressure on the scene's surfaces (with the shadow fraction inside SRP) change at
orbital rate, yet the every-stage loop evaluates them at each of RK4's four stages on every face:
~35 % of a fused tick of ``iss_lvlh_hold``. With ``[simulation] environment_rate = N`` (N >= 1)
the fused loop evaluates them once every N control ticks, at the block's first tick, and holds
over the block the value linearly extrapolated to the block's middle from the previous
evaluation,

    L_hold = L_k + (L_k - L_prev) / (t_k - t_prev) * (n_b h / 2),

(``n_b`` the block's active ticks; the first block of a run holds ``L_k``). The block's mean
torque is then right to second order in its length, the error of a constant hold's first order
cancels; what is left, and how it reaches the attitude through the loop, is bounded in
docs/design.md and checked against the every-stage evaluation by tests/test_effect_rates.py.

Composition: the tick (``one``: actuate, one RK4 step of the right-hand side *without* the
environment kinds, :func:`~.system.environment_split`, with ``u_ext + L_hold``) is called N times
into a block (N calls with the block's one parameter vector), and the blocks ``ceil(n / N)`` times into the chunk of ``n``
ticks; the tail of the last block is masked by the tick counter (``i < n_act``), as the
every-stage chunk masks its tail. The carry gains ``(L_prev, t_prev, have_prev)``, which the
executor passes from chunk to chunk (:func:`carry_width`).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..core.layout import Layout
from .chunk_layout import ENV, chunk_carry, vertcat_by
from .rate_auto import AUTO, auto_choice, g_norms, hold_bound_rad, torque_rates  # noqa: F401 (the bound: re-exported)
from .system import environment_split, has_environment

__all__ = ["environment_rate", "carry_width", "held_chunk", "hold_value", "g_norms", "hold_bound_rad", "torque_rates"]

#: the extra carry of a held-environment chunk (chunk_layout.ENV: L_prev, t_prev, have_prev)
ENV_CARRY = ENV.size


def environment_rate(loop) -> int:
    """The environment rate the fused loop runs for ``loop`` (ticks per evaluation; 0 = every
    integrator stage): the scene's ``[simulation] environment_rate`` when the scene has
    environment torques, else 0; ``"auto"`` (the default) is the bound's choice
    (:func:`~.rate_auto.auto_choice`). The per-tick executors hold it in the same blocks where
    they can cut the run into them (:func:`~.held_env.held_rate`). At most the ticks of an
    output row: a block never spans one (each chunk starts its own), so a longer one is the same
    run, and a block is built as that many calls (10**6 of them took 1.5 GiB, issue 32)."""
    asked = getattr(loop.scene.simulation, "environment_rate", 0)
    if not has_environment(loop.system):
        return 0
    if asked == AUTO:
        return min(auto_choice(loop)["ticks"], loop.n_per_out)
    return min(max(int(asked or 0), 0), loop.n_per_out)


def carry_width(rate: int) -> int:
    """Extra carry values of a chunk at ``rate`` (0 for the every-stage chunk)."""
    return ENV_CARRY if rate else 0


def held_chunk(system, one, rate: int, n: int, C: Layout, P: Layout, nn: int) -> ca.Function:
    """``fused_chunk(c0, par[, noise]) -> carry`` of ``n`` ticks with the environment held over
    blocks of ``rate`` ticks.

    Parameters
    ----------
    system : System  Its :func:`~.system.environment_split` gives ``env_B(t, x, p)``.
    one : casadi Function  ``one(t, x, cp, u_ext, p, h, L_env[, nz]) -> (x1, flags)``: one tick
        with ``u_ext + L_env`` as the held external torque.
    rate, n : int  Ticks per block, ticks per chunk.
    C : Layout  The chunk's carry (:func:`~.chunk_layout.chunk_carry` with ``env``: :data:`~.chunk_layout.ENV`).
    P : Layout  The chunk's parameters (:func:`~.chunk_layout.chunk_par`: ``t0, h, n_act, cp, u_ext, p``).
    nn : int  Sensor draws per tick (0: none).
    """
    env_B = environment_split(system)["env_B"]
    nb = math.ceil(n / rate)
    nx = C.shape("x")[0]
    T = chunk_carry(nx)  # one tick's carry: (i, x, counts), the block's env apart
    PH = Layout(**{f: P.shape(f)[0] for f in P.names}, L_hold=3)  # a tick's par: P's, then L_hold
    # one tick in the chunk's carry
    i, x_i, cnt = ca.SX.sym("i"), ca.SX.sym("x_i", nx), ca.SX.sym("cnt", 2)
    par = ca.SX.sym("par", PH.size)
    t0, h, n_act = (par[PH.slice(f).start] for f in ("t0", "h", "n_act"))
    nz_i = ca.SX.sym("nz_i", nn)
    x_new, fl = one(t0 + i * h, x_i, PH.get(par, "cp"), PH.get(par, "u_ext"), PH.get(par, "p"), h, PH.get(par, "L_hold"),
                    *([nz_i] if nn else []))
    active = i < n_act
    tick = ca.Function(
        "held_tick", [vertcat_by(T, i=[i], x=[x_i], counts=[cnt]), par] + ([nz_i] if nn else []),
        [vertcat_by(T, i=[i + 1], x=[ca.if_else(active, x_new, x_i)],
                    counts=[cnt + ca.if_else(active, ca.vertcat(fl[0] > 0.5, fl[1] > 0.5), ca.SX.zeros(2))])],
        {"cse": True},
    )
    cb, pb = ca.MX.sym("cb", T.size), ca.MX.sym("pb", PH.size)
    nzb = [ca.MX.sym("nzb", nn * rate)] if nn else []
    c = cb
    for j in range(rate):  # the block's ticks as calls with the one parameter vector (a mapaccum
        c = tick(c, pb, *([nzb[0][j * nn : (j + 1) * nn]] if nn else []))  # copies it per tick)
    block = ca.Function("held_block", [cb, pb] + nzb, [c])
    # one block: evaluate the environment at its first tick, hold the extrapolated mid value
    co = ca.MX.sym("co", C.size)
    po = ca.MX.sym("po", P.size)
    nzo = [ca.MX.sym("nzo", nn * rate)] if nn else []
    L_hold, env_next = held_environment(env_B, C, P, rate, co, po)
    c_new = block(co[: T.size], ca.vertcat(po, L_hold), *nzo)
    outer = ca.Function(
        "held_outer", [co, po] + nzo,
        [vertcat_by(Layout(tick=T.size, env=ENV.size), tick=[c_new], env=env_next)],  # (C's order: the tick's fields, then env)
    )
    acc_o = outer.mapaccum("held_acc", nb)
    c0 = ca.MX.sym("c0", C.size)
    par0 = ca.MX.sym("par", P.size)
    noise = [ca.MX.sym("noise", nn, nb * rate)] if nn else []  # column i: tick i's draws
    traj = acc_o(c0, ca.repmat(par0, 1, nb), *([ca.reshape(noise[0], nn * rate, nb)] if nn else []))
    return ca.Function("fused_chunk", [c0, par0] + noise, [traj[:, -1]])


def held_environment(env_B, C: Layout, P: Layout, rate: int, co, po) -> tuple:
    """One block's held environment in a chunk's carry ``co`` (with ``env``: :data:`~.chunk_layout.ENV`)
    and parameters ``po`` (``t0, h, n_act, p``): ``(L_hold, env_next)``. The environment is
    evaluated at the block's first tick and held at its value extrapolated to the block's middle
    from the last block's (``L_now`` alone for the first block); ``env_next`` is the carry's
    ``(L_prev, t_prev, have)`` after the block (unchanged past the active ticks). The truth-fed
    (:func:`held_chunk`) and the flight loop's (run/flight_rates.py) blocks both use it."""
    i, x = co[C.slice("i").start], C.get(co, "x")[: env_B.size1_in(1)]  # (a law's state may ride after x: law_state.py)
    env = C.get(co, "env")
    L_prev, t_prev, have = ENV.get(env, "L_prev"), env[ENV.slice("t_prev").start], env[ENV.slice("have").start]
    t0, h, n_act = (po[P.slice(f).start] for f in ("t0", "h", "n_act"))
    t_now = t0 + i * h
    L_now = env_B(t_now, x, P.get(po, "p"))
    n_b = ca.fmin(rate, ca.fmax(n_act - i, 0))  # active ticks in this block
    L_hold = hold_value(L_now, L_prev, t_now, t_prev, have, n_b, h)
    live = n_b > 0
    return L_hold, [ca.if_else(live, L_now, L_prev), ca.if_else(live, t_now, t_prev), ca.if_else(live, 1.0, have)]


def hold_value(L_now, L_prev, t_now, t_prev, have, n_b, h):
    """The block's held torque (casadi, SX or MX): ``L_now`` extrapolated to the middle of the
    block's ``n_b`` ticks of ``h`` from the previous evaluation ``(L_prev, t_prev)`` when there
    is one (``have``), else ``L_now``. Written once: the fused blocks (:func:`held_environment`)
    and the per-tick ``env_block`` (:mod:`.held_env`) use it."""
    dt = ca.if_else(have > 0.5, t_now - t_prev, 1.0)
    zero = type(L_now).zeros(3)
    return L_now + ca.if_else(have > 0.5, (L_now - L_prev) / dt * (n_b * h / 2), zero)
