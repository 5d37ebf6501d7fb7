"""The fused closed loop flown on sensors and an estimate (issue 20): :mod:`.fused` with the
scene's :class:`~stationbed.loop.Flight` tick inlined.

Per tick, in one compiled ``mapaccum`` (as the per-tick loop does it, call by call): the true
measurement ``y = meas(t, x)``; the flight tick (truth row, sensors, MEKF; what the law sees);
the law on what it sees; actuation; one RK4 step (the truth row and every part of the step
that depends on ``(t, x, p)`` alone computed once, in one SX function: ``_build``'s ``split``,
docs/design.md "The flight loop's speed"). The step is an MX function around the SX
dynamics, so the suite's ``Switch`` nodes stay lazy in the generated C (a sensor computes only on
its samples). The carry holds the tick index, the state, the saturation counts and the flight's
memory: the previous tick's time and true rate, ``theta_B`` and the suite state. The noise of
each tick is a per-tick input, drawn in Python in tick order (:class:`~stationbed.loop.flight.TickNoise`:
the same numbers as the per-tick loop's blocks).

A *plain* tick (``Suite.is_plain``: the every-tick sensors sample, no slower one does) runs as
one SX function instead (``Flight.plain_function``: the truth row, the sensors, the filter's
propagation, the law and the step in one graph, nothing lazy left to keep), the general tick
above on the others; the step is a three-case switch (held tail, general, plain).

The leading full output rows run many per compiled call (:mod:`.flight_rows`, bit-identical);
with ``[simulation] environment_rate`` the environment is held over blocks of ticks
(:mod:`.flight_rates`, as :mod:`.rates` does for the truth-fed loop).

Neither executor reads the other's internals: both call the same ``Flight.function()``
(compiled there, inlined here), read the run's composition (``comp.flight``, its noise stream
``comp.tick_noise``) and hand the flight's memory back through the run's state
(``res.flight``: ``t_prev``, ``theta_B``, ``omega_prev``, ``xs``, ``ys``; run/composition.py).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions, sx_function
from ..loop import Layout
from ..loop.flight import READS, SEEN
from . import law_state
from .chunk_layout import FLIGHT_INFO_IN, chunk_info, flight_carry, flight_par, flight_rows_par, law_carry, vertcat_by
from .flight_rates import held_flight_chunk
from .flight_rows import flight_rows_functions, run_flight_rows
from .rates import carry_width, environment_rate
from .segments import close_chunk, finish_chunks, held_torque_from, run_pieces, tick_pieces, torque_at
from .system import chain_end_inputs, environment_split

__all__ = ["run_fused_flight"]

_CHUNKS: dict[tuple, dict] = {}


def _build(comp, n: int, symbolic_params, rate: int = 0) -> dict:
    system, ctrl, flight = comp.system, comp.ctrl, comp.flight
    sx = system.sx
    form = system.formulation
    model = form.model
    nx, npar = form.nx, model.layout.size
    ncp = len(symbolic_params)
    S = flight.suite
    ns, nw, nps = S.STATE.size, S.NOISE.size, flight.params.size
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    nls = law_state.initial(ctrl).size  # the law's own state rides after x (law_state.py)
    X = law_carry(nx, nls)  # the carried state: the plant's, then the law's (law_state.py)
    xa, p, cp, u_ext = ca.SX.sym("x", X.size), ca.SX.sym("p", npar), ca.SX.sym("cp", ncp), ca.SX.sym("u_ext", 3)
    x, s = X.get(xa, "x"), X.get(xa, "s")
    # the law's measurement is computed inside the core, as the truth-fed fused loop does (its
    # sines and cosines shared with the RK4's first stage); with an estimator the flight's
    # estimate replaces its SEEN fields, given as the core's input ``est``
    y = sx["meas"](t, x, p)
    M = flight.meas  # the measurement's layout (run/measurement.py)
    est_fields = list(SEEN) if flight.mekf is not None else []
    E = Layout(**{f: M.slice(f).stop - M.slice(f).start for f in est_fields})  # the estimate's fields, in SEEN's order
    est = ca.SX.sym("est", E.size)
    y_seen = y
    for f in est_fields:
        o = M.slice(f)
        y_seen = ca.vertcat(y_seen[: o.start], est[E.slice(f)], y_seen[o.stop :])
    cmd, q_ref, s1 = law_state.symbolic(ctrl, t, y_seen, cp, s, comp.n_cmd)
    act, u, sat = chain_end_inputs(sx, model, comp.end, ctrl.command, t, h, x, cmd, u_ext, p)  # the chain's end
    x1 = ca.vertcat(system.integrator_cls.explicit_step(sx["rhs"], t, x, h, u, p), s1)
    IL = chunk_info(comp.n_cmd, act.numel(), nls)  # the row's info (chunk_layout.py)
    core = sx_function("ff_core", [t, xa, est, cp, u_ext, p, h], [x1, sat, vertcat_by(IL, cmd=[cmd], act=[act], q_ref=[q_ref], s=[s1])])
    if rate:  # the environment held over blocks (flight_rates.py): the RHS without it, u_ext + L_env
        L_env = ca.SX.sym("L_env", 3)
        x1h = system.integrator_cls.explicit_step(environment_split(system)["rhs_fast"], t, x, h,
                                                  ca.substitute(u, u_ext, u_ext + L_env), p)
    # the truth row: only the measurement's fields the flight reads (the rest are zeros it ignores)
    y_truth = ca.SX.zeros(flight.ny)
    for f in READS:
        y_truth[M.slice(f)] = y[M.slice(f)]
    meas = sx_function("ffl_truth", [t, x, p], [y_truth])
    fl = flight.function()
    # the tick's step: the truth row and the core's parts that depend on (t, x, p) alone (the
    # model's stage-1 kinematics: arrays, orbit, rate) in one SX function ``pre``, its values
    # handed to the rest of the core (``body``): computed once per tick, the same operations
    step_in = [t, xa, p]

    def split(name: str, ins: list, outs: list) -> tuple[ca.Function, ca.Function]:
        shared = ca.cse([y_truth] + outs)
        rest, syms, vals = ca.extract_parametric(shared[1:], ca.vertcat(*step_in))
        pre = sx_function(f"{name}_pre", step_in, [shared[0], ca.vertcat(*vals)])
        body = sx_function(f"{name}_body", [ca.vertcat(*syms)] + ins, rest)
        return pre, body

    core_in = [t, xa, est, cp, u_ext, p, h]
    if rate:
        pre, body = split("ff_core_h", core_in + [L_env], [ca.vertcat(x1h, s1), sat])
        whole = ca.Function("ff_core_h_whole", core_in + [L_env], [ca.vertcat(x1h, s1), sat])
    else:
        pre, body = split("ff_core", core_in, [x1, sat])
        whole = ca.Function("ff_core_whole", core_in, [x1, sat])
    # a plain tick (the every-tick sensors sample, no other: 9 ticks in 10 of the estimated
    # scene) as one SX function: the truth row, the flight's sensors and the filter's
    # propagation, the law and the step in one graph (its switches gone: nothing lazy is left
    # to keep), the same operations on the same numbers as the general tick below
    flp = flight.plain_function()

    def seen(ys, cls=ca.MX):
        return ca.vertcat(*[S.OUTPUTS.get(ys, SEEN[f]) for f in est_fields]) if est_fields else cls(0, 1)

    MX = ca.MX
    # the row tick: its command, actuation, reference and the flight's state and outputs after it
    ti, xi, cpi, ui, pi_ = MX.sym("t"), MX.sym("x", X.size), MX.sym("cp", ncp), MX.sym("u_ext", 3), MX.sym("p", npar)
    ki, tpi, thi, omi = MX.sym("k"), MX.sym("t_prev"), MX.sym("th", 3), MX.sym("om", 3)
    xsi, wi, psi = MX.sym("xs", ns), MX.sym("w", nw), MX.sym("ps", nps)
    yi = meas(ti, X.get(xi, "x") if nls else xi, pi_)
    _, xs1, _, ys = fl(ki, ti, tpi, yi, thi, omi, xsi, wi, psi)
    _, _, info_out = core(ti, xi, seen(ys), cpi, ui, pi_, 0.0)
    info_in = dict(t=ti, x=xi, cp=cpi, u_ext=ui, p=pi_, k=ki, t_prev=tpi, theta_B=thi, omega_prev=omi, xs=xsi, w=wi, ps=psi)
    info = ca.Function("ffl_info", [info_in[a] for a in FLIGHT_INFO_IN], [info_out, xs1, ys])
    # the chunk's step: the carry holds the law's state with x
    C = flight_carry(X.size, ns, carry_width(rate))
    P = flight_par(ncp, npar, nps)
    T = flight_carry(X.size, ns)  # one tick's carry (the held environment's, if any, is the block's)

    def one_tick(held: bool, PT, plain: bool) -> ca.Function:
        """``(c, par, w) -> c_next``, one tick: the general tick (MX: the truth row and the
        core's first stage in ``pre``, the flight with its switches, ``body``), or with ``plain``
        a plain tick as one SX function (``flp``: the flight's plain tick; ``whole``: the core
        unsplit, which ``cse`` shares with the truth row): the same numbers."""
        cls = ca.SX if plain else MX
        c, par, w = cls.sym("c", T.size), cls.sym("par", PT.size), cls.sym("w", nw)
        i, xc, cnt, tp, th, om, xs = (T.get(c, f) for f in T.names)
        t0, hh, k0 = (par[PT.slice(f).start] for f in ("t0", "h", "k0"))
        cpc, uc, pc, psc = (PT.get(par, f) for f in ("cp", "u_ext", "p", "ps"))
        tt = t0 + i * hh
        held_L = [PT.get(par, "L_hold")] if held else []
        if plain:
            yt = meas(tt, X.get(xc, "x") if nls else xc, pc)
            th1, xs1, _, ys = flp(k0 + i, tt, tp, yt, th, om, xs, w, psc)
            x_new, fl_sat = whole(tt, xc, seen(ys, cls), cpc, uc, pc, hh, *held_L)
        else:
            yt, vals = pre(tt, xc, pc)
            th1, xs1, _, ys = fl(k0 + i, tt, tp, yt, th, om, xs, w, psc)
            x_new, fl_sat = body(vals, tt, xc, seen(ys), cpc, uc, pc, hh, *held_L)
        c_new = T.pack(i=i + 1, x=x_new, counts=cnt + ca.vertcat(fl_sat[0] > 0.5, fl_sat[1] > 0.5), t_prev=tt,
                       theta_B=th1, omega_prev=M.get(yt, "omega_BN_B"), xs=xs1)
        return ca.Function("ffl_tick_plain" if plain else "ffl_tick", [c, par, w], [c_new], {"cse": True} if plain else {})

    def tick_step(held: bool) -> ca.Function:
        """``(c, par[, L_hold]) , w -> c_next``: one tick, the tail past n_act held."""
        PT = flight_par(ncp, npar, nps, **({"L_hold": 3} if held else {}))
        c, par, w = MX.sym("c", T.size), MX.sym("par", PT.size), MX.sym("w", nw)
        i = T.get(c, "i")
        n_act, k0 = (par[PT.slice(f).start] for f in ("n_act", "k0"))
        # the chunk's unused tail (i >= n_act) holds the carry: a Switch, so an active tick pays no
        # blend of the ~130 carried numbers (an MX if_else computes both sides and mixes them)
        tick = one_tick(held, PT, plain=False)
        hold = ca.Function("ffl_hold", [c, par, w], [ca.vertcat(i + 1, c[T.slice("i").stop :])])  # (i first: T's order)
        if flp is None:
            step = ca.Function.if_else("ffl_step", tick, hold)
            return ca.Function("ffl_step", [c, par, w], [step(i < n_act, c, par, w)], {"always_inline": True})
        # three cases, one switch: 0 the unused tail (held), 1 a tick with a slower sensor's
        # sample (the general tick), 2 a plain tick (one SX function)
        cases = ca.Function.conditional("ffl_cases", [hold, tick, one_tick(held, PT, plain=True)], hold)
        case = (i < n_act) * (1 + S.is_plain(k0 + i))
        return ca.Function("ffl_step", [c, par, w], [cases(case, c, par, w)], {"always_inline": True})

    if rate:
        chunk = held_flight_chunk(system, tick_step(True), C, rate, n, P, nw)
    else:
        acc = tick_step(False).mapaccum("ffl_acc", n)
        c0, parm, wm = MX.sym("c0", C.size), MX.sym("par", P.size), MX.sym("noise", nw, n)
        traj = acc(c0, ca.repmat(parm, 1, n), wm)
        chunk = ca.Function("ffl_chunk", [c0, parm, wm], [traj[:, -1]])
    tag = f"fusedflight_{form.name}_{type(ctrl).__name__}_{n}_{model.structure.key}_{flight.tag}"
    if rate:
        tag += f"_env{rate}"
    many = flight_rows_functions(info, chunk, C, n, flight_rows_par(ncp, npar, nps), nw)  # many rows per call (flight_rows.py)
    funcs = compile_functions([info, chunk] + many, tag)
    rows = {int(f.name().rsplit("_", 1)[1]): FastCall(funcs[f.name()]) for f in many}
    return {"info": FastCall(funcs["ffl_info"]), "chunk": FastCall(funcs["ffl_chunk"]), "nls": nls, "ncp": ncp, "rows": rows}


def run_fused_flight(comp, res, K: int, symbolic_params, edges) -> None:
    """Run ticks 0..K of the run composed by ``comp`` fused with its flight, handing back to
    ``res`` the per-tick loop's rows and the flight's memory."""
    ctrl, flight = comp.ctrl, comp.flight
    n = comp.n_per_out
    cp = np.asarray(symbolic_params, dtype=float)
    rate = environment_rate(comp)  # the environment held over blocks of ticks (flight_rates.py), 0: every stage
    key = (id(comp.system), type(ctrl), n, ctrl.command, flight.key, law_state.initial(ctrl).size, rate)  # structure
    if key not in _CHUNKS:
        t_build = time.perf_counter()
        _CHUNKS[key] = _build(comp, n, cp, rate)
        _CHUNKS[key]["build_s"] = time.perf_counter() - t_build
    fns = _CHUNKS[key]
    info, chunk = fns["info"], fns["chunk"]
    nx0 = comp.system.formulation.nx
    s_law = law_state.initial(ctrl)  # the law's own state, carried after x (law_state.py)
    nx, ls = nx0 + s_law.size, s_law.size
    S = flight.suite
    C = flight_carry(nx, S.STATE.size, carry_width(rate))  # its slices, taken once (the loop below runs per output row)
    cx, ct, cth, com, cxs = (C.slice(f) for f in ("x", "t_prev", "theta_B", "omega_prev", "xs"))
    X = law_carry(nx0, ls)
    p, period, duration = comp.p, comp.period, comp.duration
    u_ext = held_torque_from(comp.scene, 0.0, comp.bps, duration)
    ia = dict(zip(FLIGHT_INFO_IN, info.args))  # the row's info inputs, by name (the builder's order)
    ia["cp"][:], ia["u_ext"][:], ia["p"][:], ia["ps"][:] = cp, u_ext, p, flight.params
    c0, par = chunk.args[:2]
    P = flight_par(len(cp), p.size, flight.params.size)  # the chunk's parameters (the builder's layout)
    par[P.slice("h")] = period
    par[P.slice("cp")] = cp
    i_ext = P.slice("u_ext")
    par[i_ext] = u_ext
    par[P.slice("p")] = p
    par[P.slice("ps")] = flight.params
    ncmd = comp.n_cmd
    out = comp.end.outputs  # the chain end's reported values (act): u_cmg, m, rate_limited, saturated
    n_act = out.size if comp.has_cluster else 0
    IL = chunk_info(ncmd, n_act, ls)  # the row's info (the builder's layout)
    i_cmd, i_act, i_q, i_s = (IL.slice(f) for f in IL.names)
    i_u, i_lim, i_sat = (out.slice("u_cmg"), out.slice("rate_limited").start, out.slice("saturated").start) if n_act else (0, 0, 0)
    fm = res.flight  # the flight's memory, handed back at the end
    # the carry between chunk calls lives in the chunk's own input (c0): one copy per call
    c0[:] = 0.0
    c0[cx], c0[ct], c0[cth], c0[com], c0[cxs] = np.concatenate([res.x, s_law]), fm.t_prev, fm.theta_B, fm.omega_prev, fm.xs
    x, s_end = c0[cx].copy(), None
    tail_flag = ticks = 0
    res.used_fused = True
    row_ks = sorted(set(range(0, K, n)) | {K})
    try:
        j0 = 0
        if not edges:  # the leading full rows, many per compiled call (flight_rows.py)
            j0, tail_flag, ticks, stop = run_flight_rows(comp, res, fns["rows"], row_ks, K, C, c0, par[P.slice("cp").start :], ls)
            x = c0[cx].copy()
            if stop is not None:
                raise stop
        held_at = torque_at(comp, edges, u_ext)  # each piece's held torque
        for j, k in enumerate(row_ks):
            if j < j0:
                continue
            t = min(k * period, duration)
            n_tick = row_ks[j + 1] - k if k < K else 1
            draws = comp.tick_noise.rows(k, n_tick)
            ia["t"][0] = t
            ia["x"][:] = x
            ia["k"][0], ia["t_prev"][0] = k, c0[ct][0]
            ia["theta_B"][:], ia["omega_prev"][:], ia["xs"][:] = c0[cth], c0[com], c0[cxs]
            ia["w"][:] = draws[0]
            info()
            r = info.res[0]
            cmd = r[i_cmd]
            act = r[i_act]
            lim = sat = 0
            u_cmg = None
            if n_act:
                lim, sat = int(act[i_lim] > 0.5), int(act[i_sat] > 0.5)
                u_cmg = act[i_u]
            res.row(t, X.get(x, "x"), lim | sat | tail_flag, u_cmg=u_cmg, cmd=cmd, q_ref=r[i_q],
                    xs=info.res[1].copy(), ys=info.res[2].copy())
            if k == K:
                fm.theta_B, fm.omega_prev, fm.t_prev = c0[cth].copy(), c0[com].copy(), float(c0[ct][0])
                s_end = r[i_s].copy()  # the law's update at the last tick
                break
            counts = run_pieces(chunk, C, P, tick_pieces(k, n_tick, edges, duration, period), k, period,
                                held_at, draws)
            x = c0[cx].copy()
            ticks += n_tick
            tail_flag = close_chunk(res, ticks, counts, lim, sat, x, min((k + n_tick) * period, duration))
    finally:
        law_state.hand_back(ctrl, X.get(x, "s") if s_end is None else s_end)
        finish_chunks(res, X.get(x, "x"), ticks)
