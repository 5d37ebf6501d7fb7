"""The fused flight loop with the environment at its own rate (``[simulation] environment_rate``).

:mod:`.rates` holds the environment torques (aero, solar pressure) of the truth-fed fused loop
over blocks of N ticks: evaluated at a block's first tick, extrapolated to its middle, held. The
flight loop (:mod:`.fused_flight`) does the same with its own tick (the truth row, the sensors
and the MEKF, the law on the estimate, actuation, one RK4 step of the right-hand side without
the environment kinds with ``u_ext + L_hold``): the same blocks, the same extrapolation
(:func:`.rates.held_chunk`'s formulas; docs/design.md "Effects at their own rate" bounds what the
hold changes), so a scene with ``environment_rate = N`` runs both loops at the same accuracy and
the estimated loop's cost is compared with the truth-fed loop's like for like. The default
``"auto"`` is the bound's choice here too (run/rate_auto.py: the MEKF is kinematic, so the
hold's bound holds on the estimate's loop); ``environment_rate = 0`` is the every-stage loop.

The chunk's carry is the flight loop's (:func:`.chunk_layout.flight_carry`) with the held
environment's ``(L_prev, t_prev, have)`` after it (``env``: :data:`.chunk_layout.ENV`), passed
from chunk to chunk.
"""

from __future__ import annotations

import math

import casadi as ca

from ..loop import Layout
from .rates import held_environment
from .system import environment_split

__all__ = ["held_flight_chunk"]


def held_flight_chunk(system, tick_h, C: Layout, rate: int, n: int, P: Layout, nw: int) -> ca.Function:
    """``ffl_chunk(c0, par, w) -> carry`` of ``n`` ticks, the environment held over blocks of
    ``rate`` ticks.

    Parameters
    ----------
    system : System  Its :func:`~.system.environment_split` gives ``env_B(t, x, p)``.
    tick_h : Function  ``(c, par_h, w) -> c_next``: one tick of the flight loop's carry (first
        the tick index i, then ``C``'s fields; without ``env``), ``par_h = (par, L_hold)``, the
        tail past ``n_act = par[2]`` held.
    C : Layout  The carry with ``env`` (:data:`~.chunk_layout.ENV`) last.
    rate, n : int  Ticks per block, ticks per chunk.
    P : Layout  The chunk's ``par = (t0, h, n_act, k0, cp, u_ext, p, ps)`` (:func:`~.chunk_layout.flight_par`).
    nw : int  Noise values per tick.
    """
    env_B = environment_split(system)["env_B"]
    nb = math.ceil(n / rate)
    nc = C.slice("env").start  # the tick's carry: C's fields before env
    cb, pb, wb = ca.MX.sym("cb", nc), ca.MX.sym("pb", P.size + 3), ca.MX.sym("wb", nw * rate)
    c = cb
    for j in range(rate):  # the block's ticks as calls with the block's parameters, not a mapaccum
        c = tick_h(c, pb, wb[j * nw : (j + 1) * nw])  # (a mapaccum wants them repeated: P.size copies per tick)
    block = ca.Function("ffl_block", [cb, pb, wb], [c])
    co, po, wo = ca.MX.sym("co", C.size), ca.MX.sym("po", P.size), ca.MX.sym("wo", nw * rate)
    L_hold, env_next = held_environment(env_B, C, P, rate, co, po)  # as the truth-fed loop's blocks (rates.py)
    c_new = block(co[:nc], ca.vertcat(po, L_hold), wo)
    outer = ca.Function("ffl_outer", [co, po, wo], [ca.vertcat(c_new, *env_next)])
    acc_o = outer.mapaccum("ffl_held_acc", nb)
    c0, par0, noise = ca.MX.sym("c0", C.size), ca.MX.sym("par", P.size), ca.MX.sym("noise", nw, nb * rate)
    traj = acc_o(c0, ca.repmat(par0, 1, nb), ca.reshape(noise, nw * rate, nb))
    return ca.Function("ffl_chunk", [c0, par0, noise], [traj[:, -1]])
