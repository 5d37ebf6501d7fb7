"""The held environment, one block (issues 25, 33): the environment torques evaluated once per
block of ticks (docs/design.md "Effects at their own rate"): the rate a run holds, the held
value's expression, the block's memory and its step, in one file.

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

Composition (issue 33): the held environment is a block of the composed tick
(:func:`env_block`, composed by loop/compose.py): at a block's first tick (``i % N == 0`` in a
chunk, whose first tick starts one) it evaluates the environment and holds ``L_hold``, the
plant stepping the right-hand side *without* the environment kinds
(:func:`~.system.environment_split`) with ``u_ext + L_hold``; its memory ``(L_prev, t_prev,
have)`` rides in the carry from chunk to chunk.
"""

from __future__ import annotations

import casadi as ca

from ..core.layout import Layout
from ..loop.block import Block
from .rate_auto import AUTO, auto_choice
from .system import environment_split, has_environment

__all__ = ["ENV", "env_block", "environment_rate", "hold_value"]

#: the held environment's memory, passed from chunk to chunk (and block to block): the last
#: evaluation ``L_prev`` (3, B components [N m]), its time ``t_prev`` [s], ``have`` (1: there is one)
ENV = Layout(L_prev=3, t_prev=1, have=1)


def environment_rate(loop) -> int:
    """The environment rate the fused loop runs for ``loop`` (ticks per evaluation; 0 = every
    integrator stage): the scene's ``[simulation] environment_rate`` when the scene has
    environment torques, else 0; ``"auto"`` (the default) is the bound's choice
    (:func:`~.rate_auto.auto_choice`). The per-tick executors hold it in the same blocks where
    they step the composed parts (:func:`~.blocks.held_rate`). At most the ticks of an
    output row: a block never spans one (each chunk starts its own), so a longer one is the same
    run, and a block is built as that many calls (10**6 of them took 1.5 GiB, issue 32)."""
    asked = getattr(loop.scene.simulation, "environment_rate", 0)
    if not has_environment(loop.system):
        return 0
    if asked == AUTO:
        return min(auto_choice(loop)["ticks"], loop.n_per_out)
    return min(max(int(asked or 0), 0), loop.n_per_out)


def hold_value(L_now, L_prev, t_now, t_prev, have, n_b, h):
    """The block's held torque (casadi, SX or MX): ``L_now`` extrapolated to the middle of the
    block's ``n_b`` ticks of ``h`` from the previous evaluation ``(L_prev, t_prev)`` when there
    is one (``have``), else ``L_now``. Written once: the composed ``env`` block
    (:func:`~.blocks.env_block`) uses it, whichever executor steps it."""
    dt = ca.if_else(have > 0.5, t_now - t_prev, 1.0)
    zero = type(L_now).zeros(3)
    return L_now + ca.if_else(have > 0.5, (L_now - L_prev) / dt * (n_b * h / 2), zero)


def env_block(comp, rate: int) -> Block:
    """The environment torques (aero, SRP: the kinds with ``needs_env``) evaluated once every
    ``rate`` ticks and held (issue 25's blocks): memory the last evaluation
    ``(L_prev, t_prev, have)`` and the held value ``L_hold``; inputs the plant's state and the
    block's active ticks ``n_b``; numbers the model's. Its step is :func:`hold_value` on
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
