"""The fused closed loop: controller, steering law and dynamics in one compiled loop (DESIGN §9).

When a controller offers a symbolic form (``Controller.symbolic``), a whole stretch of ticks
between two output rows runs in one compiled call: per tick, measure -> control -> actuate ->
one step of the integrator's ``explicit_step`` (RK4), composed from the same SX functions the
per-tick path compiles (``meas``, ``actuate``, ``rhs``), as a casadi ``mapaccum`` loop generated
as C. Python then runs once per output row instead of once per tick.

Conditions (otherwise the per-tick loop runs, with the same numbers): a ``fusable`` integrator
(``rk4``) with one step per control period, torque-window edges inside the run only on the tick
grid (a chunk is split there and each stretch holds its own torque,
:func:`~.segments.held_torque_from`; an edge inside a tick needs the per-tick loop's cut), no
array rate step with them, no sensor delay, a controller with ``symbolic``.

Sensor noise: before each compiled call Python draws the noise of its ticks from the loop's
generator, in the per-tick loop's order (per tick: attitude, then rate; :func:`_draw`), and
passes them as a per-tick input of the ``mapaccum``; the compiled tick corrupts the measurement
the controller sees by the corruption plug-in's expressions (loop/corruption.py, inlined: the
per-tick loop calls them compiled). Same draws, same operations: the fused and per-tick noisy
runs agree to round-off (tests/test_fused_noise.py).
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions, sx_function
from ..loop.corruption import corrupt_symbolic, draws_layout
from . import law_state
from .chunk_layout import chunk_carry, chunk_info, chunk_par
from .controller import ControllerError, one_line
from .fused_rows import rows_functions, run_rows
from .rates import carry_width, environment_rate, held_chunk
from .segments import close_chunk, edge_ticks, finish_chunks, held_torque_from, run_pieces, tick_pieces, torque_at
from .system import chain_end_inputs, environment_split as rates_split
from .thrust_fused import fused_thrust_ok, run_fused_thrust

__all__ = ["fused_ok", "run_fused"]

_CHUNKS: dict[tuple, dict] = {}


def fused_ok(comp) -> bool:
    """Whether the run composed by ``comp`` can run fused: a controller with a ``symbolic`` form, a ``fusable``
    integrator at one step per period, every discontinuity inside the run on the tick grid
    (:func:`~.segments.edge_ticks`), no sensor delay (sensor noise is drawn in Python and applied inside
    the compiled tick: :func:`_noise_width`)."""
    ctrl = comp.ctrl
    integ = comp.integ
    return (
        callable(getattr(ctrl, "symbolic", None))
        and integ.fusable
        and math.ceil(comp.period / integ.h_nominal - 1e-9) == 1
        and edge_ticks(comp) is not None
        and not (comp.noisy and comp.delay > 0)
        and comp.system.sx is not None
        and not (comp.flight is not None and comp.noisy)
        and comp.replan is None  # a failure detected mid-run: per tick (run/detection.py)
        and fused_thrust_ok(comp)  # thrusters (issue 21): their own fused chunk, or per tick
    )


def _noise_flags(comp) -> tuple[bool, bool]:
    """(attitude noise on, rate noise on): which corruptions of the plug-in apply."""
    if not comp.noisy:
        return False, False
    return comp.sensor.attitude_noise > 0, comp.sensor.rate_noise > 0


def _noise_width(flags) -> int:
    """Draws per tick: 3 for the attitude, then 3 for the rate (the per-tick loop's order;
    :func:`~stationbed.loop.draws_layout`)."""
    return draws_layout(*flags).size


def _corrupt_sx(y, nz, flags, layout):
    """``y`` corrupted by this tick's draws ``nz``: the corruption plug-in's expressions
    (loop/corruption.py), inlined; the per-tick loop calls the same ones compiled."""
    return corrupt_symbolic(y, nz, flags, layout)


def _build(comp, n: int, flags=(False, False), rate: int = 0) -> dict:
    """Compiled ``info`` (one tick's command, actuation, reference) and ``chunk`` (n ticks);
    with sensor noise (``flags``), both take each tick's draws as an extra input."""
    system, ctrl = comp.system, comp.ctrl
    sx = system.sx
    form = system.formulation
    model = form.model
    nx, npar = form.nx, model.layout.size
    ncp = len(_symbolic_params(ctrl))
    t, t0, h = ca.SX.sym("t"), ca.SX.sym("t0"), ca.SX.sym("h")
    ns = law_state.initial(ctrl).size  # the law's own state rides after x (law_state.py)
    xa = ca.SX.sym("x", nx + ns)
    x, s = xa[:nx], xa[nx:]
    p = ca.SX.sym("p", npar)
    cp = ca.SX.sym("cp", ncp)
    u_ext = ca.SX.sym("u_ext", 3)
    y = sx["meas"](t, x, p)
    nn = _noise_width(flags)
    nz = ca.SX.sym("nz", nn)
    if nn:
        y = _corrupt_sx(y, nz, flags, comp.meas_layout)
    cmd, q_ref, s1 = law_state.symbolic(ctrl, t, y, cp, s, comp.n_cmd)
    # the actuator chain's end (the CMG cluster or the ideal torquer), u by the input layout
    # (t_step with rate steps: they lie outside a fused run, it keeps u's layout)
    act, u, sat = chain_end_inputs(sx, model, comp.end, ctrl.command, t, h, x, cmd, u_ext, p)
    ins = [t, xa, cp, u_ext, p] + ([nz] if nn else [])
    info = sx_function("fused_info", ins, [chunk_info(comp.n_cmd, act.numel(), ns).pack(cmd=cmd, act=act, q_ref=q_ref, s=s1)])
    rhs = sx["rhs"]
    x1 = ca.vertcat(system.integrator_cls.explicit_step(rhs, t, x, h, u, p), s1)
    # carry: tick index i (exact integer in a double: t = t0 + i h, no accumulation), state,
    # counts of rate-limited and saturated ticks; n_act masks the unused tail of the chunk
    i = ca.SX.sym("i")
    cnt = ca.SX.sym("cnt", 2)
    n_act = ca.SX.sym("n_act")
    nx += ns
    x_i = ca.SX.sym("x_i", nx)
    one = sx_function("one", [t, xa, cp, u_ext, p, h] + ([nz] if nn else []), [x1, sat])
    nz_i = ca.SX.sym("nz_i", nn)
    x_new, fl = one(t0 + i * h, x_i, cp, u_ext, p, h, *([nz_i] if nn else []))
    active = i < n_act
    C, P = chunk_carry(nx), chunk_par(ncp, npar)  # the carry and the parameters, by name (chunk_layout.py)
    carry = C.pack(i=i, x=x_i, counts=cnt)
    carry_new = C.pack(
        i=i + 1,
        x=ca.if_else(active, x_new, x_i),
        counts=cnt + ca.if_else(active, ca.vertcat(fl[0] > 0.5, fl[1] > 0.5), ca.SX.zeros(2)),
    )
    step = sx_function("fused_step", [carry, P.pack(t0=t0, h=h, n_act=n_act, cp=cp, u_ext=u_ext, p=p)] + ([nz_i] if nn else []),
                       [carry_new])
    acc = step.mapaccum("fused_acc", n)
    c0 = ca.MX.sym("c0", C.size)
    par = ca.MX.sym("par", P.size)
    noise = [ca.MX.sym("noise", nn, n)] if nn else []  # column i: tick i's draws
    traj = acc(c0, ca.repmat(par, 1, n), *noise)
    chunk = ca.Function("fused_chunk", [c0, par] + noise, [traj[:, -1]])
    if rate:  # the environment at its own rate (rates.py): same tick, environment held per block
        L_env = ca.SX.sym("L_env", 3)
        u_held = ca.substitute(u, u_ext, u_ext + L_env)
        x1h = system.integrator_cls.explicit_step(rates_split(system)["rhs_fast"], t, x, h, u_held, p)
        x1h = ca.vertcat(x1h, s1)
        one_h = sx_function("one", [t, xa, cp, u_ext, p, h, L_env] + ([nz] if nn else []), [x1h, sat])
        chunk = held_chunk(system, one_h, rate, n, chunk_carry(nx, env=carry_width(rate)), P, nn)  # (chunk_layout.py)
    tag = f"fused_{form.name}_{type(ctrl).__name__}_{n}_{model.structure.key}"
    if rate:
        tag += f"_env{rate}"
    if nn:
        tag += f"_noise{int(flags[0])}{int(flags[1])}"
    many = rows_functions(info, chunk, n, nx, carry_width(rate), ncp, npar, nn)  # many rows per call (fused_rows.py)
    funcs = compile_functions([info, chunk] + many, tag)
    rows = {int(f.name().rsplit("_", 1)[1]): FastCall(funcs[f.name()]) for f in many}
    return {"info": FastCall(funcs["fused_info"]), "chunk": FastCall(funcs["fused_chunk"]), "ncp": ncp, "ns": ns,
            "rows": rows}


#: True: the hand-composed fused loops below fly the runs they composed (their last use: the
#: bit-for-bit comparison with the composed loop, tests/test_composed.py; issue 33 deletes them)
HAND_COMPOSED = False


def composed_takes(comp) -> bool:
    """Whether the composed loop (issue 33, run/composed.py) flies the fused run of ``comp``:
    every fused run, unless :data:`HAND_COMPOSED` asks for the hand-composed loop of a
    combination one composed (thrusters with ``[[sensor]]`` tables or a law with a state had none)."""
    if comp.thrust is not None and (comp.flight is not None or law_state.has_state(comp.ctrl)):
        return True
    return not HAND_COMPOSED


def run_fused(comp, res, K: int) -> None:
    """Run ticks 0..K of the run composed by ``comp`` with the fused loop, handing back to
    ``res`` (:class:`~.composition.RunState`) the same rows as the per-tick loop."""
    ctrl = comp.ctrl
    if composed_takes(comp):
        # the combinations no hand-composed loop composed: the loop composed from its blocks (issue 33)
        from .composed import run_composed

        return run_composed(comp, res, K, _symbolic_params(ctrl), edge_ticks(comp))
    if comp.thrust is not None:  # thrusters (issue 21)
        noise = {"flags": _noise_flags(comp), "width": _noise_width, "corrupt": _corrupt_sx, "draw": _draw}
        return run_fused_thrust(comp, res, K, _symbolic_params(ctrl), edge_ticks(comp), noise)
    if comp.flight is not None:  # sensors and estimator (issue 20)
        from .fused_flight import run_fused_flight

        return run_fused_flight(comp, res, K, _symbolic_params(ctrl), edge_ticks(comp))
    n = comp.n_per_out
    flags = _noise_flags(comp)
    nn = _noise_width(flags)
    rate = environment_rate(comp)
    ne = carry_width(rate)  # the held environment's carry (rates.py), passed from chunk to chunk
    env_c = np.zeros(ne)
    key = (id(comp.system), type(ctrl), n, ctrl.command, flags, rate, law_state.initial(ctrl).size)
    if key not in _CHUNKS:
        t0 = time.perf_counter()
        _CHUNKS[key] = _build(comp, n, flags, rate)
        _CHUNKS[key]["build_s"] = time.perf_counter() - t0
    fns = _CHUNKS[key]
    info, chunk = fns["info"], fns["chunk"]
    cp = np.asarray(_symbolic_params(ctrl), dtype=float)
    nx0 = comp.system.formulation.nx
    s_law = law_state.initial(ctrl)  # the law's own state, carried after x (law_state.py)
    nx = nx0 + s_law.size
    p, period, duration = comp.p, comp.period, comp.duration
    u_ext = held_torque_from(comp.scene, 0.0, comp.bps, duration)
    edges = edge_ticks(comp)  # where the held torque may change: a chunk is split there
    info.args[2][:] = cp
    info.args[3][:] = u_ext
    info.args[4][:] = p
    c0, par = chunk.args[:2]
    if nn:  # each tick's draws: written before each call (a chunk's columns, then the row tick's)
        noise, info_nz = chunk.args[2], info.args[5]
        noise[:] = 0.0
    # the chunk's carry and parameters and the row's info, by name (chunk_layout.py: the builder's)
    C, P = chunk_carry(nx, env=ne), chunk_par(len(cp), len(p))
    i_h = P.slice("h")
    c_x, c_env = C.slice("x"), C.slice("env")
    par[:] = P.pack(t0=0.0, h=period, n_act=0.0, cp=cp, u_ext=u_ext, p=p)
    out = comp.end.outputs  # the chain end's reported values (act): u_cmg, m, rate_limited, saturated
    n_act = out.size if comp.has_cluster else 0
    IL = chunk_info(comp.n_cmd, n_act, s_law.size)
    if IL.size != info.res[0].size:
        raise AssertionError(f"fused info has {info.res[0].size} values, its layout {IL!r} {IL.size}")
    r_cmd, r_act, r_q, r_s = IL.slice("cmd"), IL.slice("act"), IL.slice("q_ref"), IL.slice("s")
    i_u, i_lim, i_sat = (out.slice("u_cmg"), out.slice("rate_limited").start, out.slice("saturated").start) if n_act else (0, 0, 0)
    x = np.concatenate([res.x, s_law])
    s_end = None
    tail_flag = 0
    ticks = 0
    res.used_fused = True
    row_ks = sorted(set(range(0, K, n)) | {K})  # the row ticks, as in the per-tick loop
    try:
        j0 = 0
        if not edges:  # the leading full rows, many per compiled call (fused_rows.py)
            draw = (lambda k: _draw(comp, k, flags)) if nn else None
            j0, x, env_c, tail_flag, ticks, stop = run_rows(comp, res, fns, row_ks, K, x, env_c, cp, u_ext, p, draw,
                                                            s_law.size)
            if stop is not None:
                raise stop
        held_at = torque_at(comp, edges, u_ext)  # each piece's held torque
        for j, k in enumerate(row_ks):
            if j < j0:
                continue
            t = min(k * period, duration)
            n_tick = row_ks[j + 1] - k if k < K else 1
            if nn:  # the draws of ticks k .. k + n_tick - 1, in the per-tick loop's order
                draws = _draw(comp, n_tick, flags)
                info_nz[:] = draws[0]
            # the row at tick k: the command, actuation and reference of this tick
            info.args[0][0] = t
            info.args[1][:] = x
            info()
            r = info.res[0]
            cmd, act, q_ref = r[r_cmd], r[r_act], r[r_q]
            lim = sat = 0
            u_cmg = None
            if n_act:
                lim, sat = int(act[i_lim] > 0.5), int(act[i_sat] > 0.5)
                u_cmg = act[i_u]
            res.row(t, x[:nx0], lim | sat | tail_flag, u_cmg=u_cmg, cmd=cmd, q_ref=q_ref)  # streamed in batches
            if k == K:
                s_end = r[r_s].copy()  # the law's update at the last tick
                break
            # ticks k .. k + n_tick - 1 in one call per piece (tick k's actuation is recomputed inside: same)
            c0[c_x], c0[c_env] = x, env_c
            counts = run_pieces(chunk, C, P, tick_pieces(k, n_tick, edges, duration, period), k, period,
                                held_at, draws if nn else None)
            x, env_c = c0[c_x].copy(), c0[c_env].copy()
            par[i_h] = period
            ticks += n_tick
            tail_flag = close_chunk(res, ticks, counts, lim, sat, x, min((k + n_tick) * period, duration))
    finally:
        law_state.hand_back(ctrl, x[nx0:] if s_end is None else s_end)
        finish_chunks(res, x[:nx0], ticks)


def _draw(comp, n: int, flags) -> np.ndarray:
    """The sensor draws of the next ``n`` ticks, (n, 3 or 6), from the run's generator in the
    per-tick loop's order (the plug-in's :meth:`~stationbed.loop.Corruption.draw`)."""
    c = comp.corruption
    if c is None or c.flags != tuple(flags):
        raise AssertionError(f"sensor draws {flags} asked of a run whose corruption is {c and c.flags}")
    return c.draw(comp.rng, n)


def _symbolic_params(ctrl):
    """``ctrl.symbolic_params()``; ControllerError naming the controller if the user's code raises."""
    try:
        return ctrl.symbolic_params()
    except Exception as e:
        raise ControllerError(f"controller '{ctrl.name}': symbolic_params() raised {type(e).__name__}: {one_line(e)}") from e
