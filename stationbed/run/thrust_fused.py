"""The fused closed loop with thrusters (issue 21): :mod:`.fused` with the
:class:`~stationbed.loop.thrusters.ThrusterCluster` tick inlined.

Per tick, in one compiled ``mapaccum``: one SX function ``thr_quiet`` (as :mod:`.fused`'s whole
tick: the law, the thrusters' exact idle test
(:meth:`~stationbed.loop.actuator.Actuator.idle_function`), the measured h, the quiet tick (the
law's request to the CMGs, one RK4 step) packed as the next carry, the chunk's unused tail held
by an SX blend) and whether the tick is busy (active and not idle). A busy tick runs the
thrusters' command (the same casadi function the per-tick loop compiles); when nothing fires and
the CMGs get the law's request exactly (``rest == cmd``) its step is ``thr_quiet``'s (same inputs,
same operations); otherwise the CMGs' actuation of the rest, then **either** one plain RK4 step
(nothing fires) **or** the tick split at every pulse edge
(:func:`~stationbed.loop.actuator.split_step`: n + 1 RK4 pieces). The choices are casadi
``Function.if_else`` of explicit branch functions, so the generated C evaluates only the branch
taken and computes nothing twice (an ``if_else(..., short_circuit=True)`` on expressions
rebuilds a branch from its free symbols and recomputes inside it what came before the choice). The carry holds the tick index, the state, the saturation
counts and the thrusters' memory (their ledger included).

Sensor noise (``[controller.sensor]``) is drawn in Python per tick and applied in the compiled
tick as :mod:`.fused` does (same draws, same operations). Taken when :func:`fused_thrust_ok`
(no ``[[sensor]]`` tables, no environment rate, the closed-form mapping); otherwise the per-tick loop runs and the summary says why
(``thrusters_not_fused``).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions, sx_function
from ..loop.actuator import split_step
from .controller import ControllerError, one_line
from . import law_state
from .chunk_layout import chunk_carry, chunk_info, chunk_par
from .rates import environment_rate
from .segments import close_chunk, finish_chunks, held_torque_from, run_pieces, tick_pieces
from .system import chain_end_inputs

__all__ = ["fused_thrust_ok", "run_fused_thrust"]

_CHUNKS: dict[tuple, dict] = {}


def fused_thrust_ok(comp) -> bool:
    """Whether the fused loop can fly the run's thrusters (always True without thrusters);
    sets ``comp.thrust.fused_reason`` when it cannot."""
    th = comp.thrust
    if th is None:
        return True
    why = None
    if th.lp:
        why = "mapping = 'lp' runs scipy's HiGHS in Python each tick"
    elif environment_rate(comp):
        why = "an environment rate with thrusters is flown per tick"
    elif comp.noisy and law_state.has_state(comp.ctrl):
        why = "[controller.sensor] noise with a law that has a state and thrusters is flown per tick"
    th.fused_reason = why
    return why is None


def _build(comp, n: int, symbolic_params, noise) -> dict:
    system, ctrl, th = comp.system, comp.ctrl, comp.thrust
    sx = system.sx
    form = system.formulation
    model = form.model
    nx, npar = form.nx, model.layout.size
    ncp = len(symbolic_params)
    cl = th.cluster
    na, npa, nch = cl.state.size, cl.params.size, cl.n_channels
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    x, p, cp, u_ext = ca.SX.sym("x", nx), ca.SX.sym("p", npar), ca.SX.sym("cp", ncp), ca.SX.sym("u_ext", 3)
    xa, pa = ca.SX.sym("xa", na), ca.SX.sym("pa", npa)
    flags = noise["flags"]
    nn = noise["width"](flags)
    nz = ca.SX.sym("nz", nn)
    y = sx["meas"](t, x, p)
    if nn:  # the law sees the noisy measurement, as fused.py's tick (h_B is not corrupted)
        y = noise["corrupt"](y, nz, flags, comp.meas_layout)
    try:
        cmd, q_ref = ctrl.symbolic(t, y, cp)
        cmd = ca.vertcat(cmd)
    except Exception as e:
        raise ControllerError(f"controller '{ctrl.name}': symbolic() raised {type(e).__name__}: {one_line(e)}") from e
    if cmd.numel() != 3:
        raise ControllerError(f"controller '{ctrl.name}': symbolic() returned {cmd.numel()} command values, expected 3")
    xa1, rest, on_s, tq, _ = cl.function()(t, h, xa, y[th.reads_at], cmd, pa)

    def act_u(tau):  # the chain's end (the CMG cluster) on what the thrusters leave it
        return chain_end_inputs(sx, model, comp.end, "torque", t, h, x, tau, u_ext, p)

    act, u, _ = act_u(rest)
    step, rhs = system.integrator_cls.explicit_step, sx["rhs"]
    idle_f = cl.idle_function()
    idle = idle_f(t, xa, y[th.reads_at], cmd, pa) if idle_f is not None else ca.SX(0)
    _, u_q, sat_q = act_u(cmd)
    C, P = chunk_carry(nx, xa=na), chunk_par(ncp, npar, pa=npa)  # by name (chunk_layout.py), as the executor
    nc, npar_all = C.size, P.size
    # every tick, one SX function as fused.py's whole tick (its common subexpressions shared): the
    # law, the idle test, the measured h, the quiet tick (the law's request to the CMGs, one step)
    # packed as the next carry, the chunk's unused tail (i >= n_act) held by an SX blend (cheap in
    # SX), and whether this tick is busy (active and not idle)
    cs, ps_ = ca.SX.sym("c", nc), ca.SX.sym("par", npar_all)
    i_s, x_s, cnt_s, xa_c = (C.get(cs, f) for f in ("i", "x", "counts", "xa"))
    t0_s, hh_s, nact_s = (P.get(ps_, f) for f in ("t0", "h", "n_act"))
    sub_from = [t, x, cp, u_ext, p, h, xa, pa]
    sub_to = [t0_s + i_s * hh_s, x_s, P.get(ps_, "cp"), P.get(ps_, "u_ext"), P.get(ps_, "p"), hh_s, xa_c, P.get(ps_, "pa")]
    x_q, cmd_q, idle_q, sat_qq, hB_q = ca.substitute([step(rhs, t, x, h, u_q, p), cmd, idle, sat_q, y[th.reads_at]],
                                                     sub_from, sub_to)
    act_s = i_s < nact_s
    c_quiet = C.pack(i=i_s + 1, x=ca.if_else(act_s, x_q, x_s),
                     counts=cnt_s + ca.if_else(act_s, ca.vertcat(sat_qq[0] > 0.5, sat_qq[1] > 0.5), ca.SX.zeros(2)), xa=xa_c)
    quiet = sx_function("thr_quiet", [cs, ps_, nz], [c_quiet, ca.logic_and(act_s, idle_q < 0.5), cmd_q, hB_q])
    cmd_s = ca.SX.sym("cmd", 3)
    h_s = ca.SX.sym("h_B", 3)  # the measured h, from thr_quiet (not measured again)
    xa1_s, rest_s, on_s, tq, _ = cl.function()(t, h, xa, h_s, cmd_s, pa)
    # the thrusters' command alone; `same`: nothing fires and the CMGs get the law's request
    # exactly (rest == cmd), so the tick's step is thr_quiet's (same inputs, same operations)
    same = ca.logic_and(ca.sum1(on_s != 0) == 0, ca.sum1(rest_s != cmd_s) == 0)
    thr_cmd = sx_function("thr_cmd", [t, h, xa, h_s, cmd_s, pa], [xa1_s, rest_s, on_s, tq, same])
    r_s = ca.SX.sym("rest", 3)
    _, u_b, sat_b = act_u(r_s)
    thr_act = sx_function("thr_act", [t, x, r_s, u_ext, p, h], [u_b, sat_b])
    core = sx_function("thr_core", [t, x, cp, u_ext, p, h, xa, pa, nz],
                       [chunk_info(3, act.numel()).pack(cmd=cmd, act=act, q_ref=q_ref, s=ca.SX(0, 1))])
    us, ons, tqs = ca.SX.sym("u", u.numel()), ca.SX.sym("on", nch), ca.SX.sym("tq", 3 * nch)
    # explicit branch functions (casadi's Function.if_else): the branch is evaluated from the
    # inputs as given, nothing before the choice is computed again inside it
    plain = sx_function("thr_plain", [t, x, h, us, p, ons, tqs], [step(rhs, t, x, h, us, p)])
    split = sx_function("thr_split", [t, x, h, us, p, ons, tqs],
                        [split_step(step, rhs, t, x, h, us, p, ons, ca.reshape(tqs, 3, nch), model.input_layout)])
    pulse = ca.Function.if_else("thr_pulse", split, plain)
    MX = ca.MX
    ti, xi, cpi, ui, pi_, hi, xai, pai = (MX.sym("t"), MX.sym("x", nx), MX.sym("cp", ncp), MX.sym("u_ext", 3),
                                          MX.sym("p", npar), MX.sym("h"), MX.sym("xa", na), MX.sym("pa", npa))
    nzi = MX.sym("nz", nn)
    info = ca.Function("thr_info", [ti, xi, cpi, ui, pi_, hi, xai, pai, nzi],
                       [core(ti, xi, cpi, ui, pi_, hi, xai, pai, nzi)])
    c, par = MX.sym("c", nc), MX.sym("par", npar_all)
    nzc = MX.sym("nz", nn)
    quiet_c, busy_c, cmd_c, h_c = quiet(c, par, nzc)
    # the busy tick (active, not idle): the thrusters' command; then, when nothing fires and the
    # CMGs get the law's request (rest == cmd: dumping ticks in assist), thr_quiet's step with the
    # thrusters' new memory; otherwise the CMGs' actuation of the rest and a plain step or the
    # split one (only if one fires). A quiet tick (or the unused tail) passes thr_quiet's carry on.
    bc, bpar, bq, bcmd, bhB = MX.sym("c", nc), MX.sym("par", npar_all), MX.sym("q", nc), MX.sym("cmd", 3), MX.sym("h_B", 3)
    # (MX: a scalar field by its index, as a plain bc[0] makes the same graph)
    bi, bx, bcnt, bxa = bc[C.slice("i").start], bc[C.slice("x")], bc[C.slice("counts")], bc[C.slice("xa")]
    bh, bu = bpar[P.slice("h").start], bpar[P.slice("u_ext")]
    bt = bpar[P.slice("t0").start] + bi * bh
    bp, bpa = bpar[P.slice("p")], bpar[P.slice("pa")]
    xa_new, rest, on, tqq, same_c = thr_cmd(bt, bh, bxa, bhB, bcmd, bpa)
    ar, aon, atq = MX.sym("rest", 3), MX.sym("on", nch), MX.sym("tq", 3 * nch)
    a_in = [bc, bpar, bq, ar, aon, atq]
    uu, fl = thr_act(bt, bx, ar, bu, bp, bh)
    x_b = pulse(ca.sum1(aon) > 0, bt, bx, bh, uu, bp, aon, atq)
    acted = ca.Function("thr_acted", a_in, [ca.vertcat(bi + 1, x_b, bcnt + ca.vertcat(fl[0] > 0.5, fl[1] > 0.5))])  # i, x, counts
    kept = ca.Function("thr_kept", a_in, [bq[: C.slice("counts").stop]])  # i, x, counts of thr_quiet
    head = ca.Function.if_else("thr_same", kept, acted)(same_c, bc, bpar, bq, rest, on, tqq)
    b_in = [bc, bpar, bq, bcmd, bhB]
    busy = ca.Function("thr_busy_tick", b_in, [ca.vertcat(head, xa_new)])
    tick = ca.Function.if_else("thr_tick", busy, ca.Function("thr_pass", b_in, [bq]))
    c_new = tick(busy_c, c, par, quiet_c, cmd_c, h_c)
    stepf = ca.Function("thr_step", [c, par, nzc], [c_new])
    acc = stepf.mapaccum("thr_acc", n)
    c0, parm, noise = MX.sym("c0", nc), MX.sym("par", npar_all), MX.sym("noise", nn, n)  # column i: tick i's draws
    chunk = ca.Function("thr_chunk", [c0, parm, noise], [acc(c0, ca.repmat(parm, 1, n), noise)[:, -1]])
    tag = f"thrfused8_n{int(flags[0])}{int(flags[1])}_{form.name}_{type(ctrl).__name__}_{n}_{cl.key}_{model.structure.key}"
    funcs = compile_functions([info, chunk], tag)
    return {"info": FastCall(funcs["thr_info"]), "chunk": FastCall(funcs["thr_chunk"]), "ncp": ncp}


def run_fused_thrust(comp, res, K: int, symbolic_params, edges, noise) -> None:
    """Run ticks 0..K of the run composed by ``comp`` fused with its thrusters, handing back to
    ``res`` the same rows as the per-tick loop (and the thrusters' memory to ``comp.thrust``).

    ``noise``: :mod:`.fused`'s sensor-noise helpers, ``flags`` (which corruptions apply),
    ``width`` (draws per tick), ``corrupt`` (the compiled corruption), ``draw`` (the draws of the
    next ticks in the per-tick loop's order); handed over by ``run_fused``, which imports this
    module."""
    ctrl, th = comp.ctrl, comp.thrust
    cl = th.cluster
    n = comp.n_per_out
    flags = noise["flags"]
    nn = noise["width"](flags)
    key = (id(comp.system), type(ctrl), n, cl.key, flags)
    if key not in _CHUNKS:
        t0 = time.perf_counter()
        _CHUNKS[key] = _build(comp, n, symbolic_params, noise)
        _CHUNKS[key]["build_s"] = time.perf_counter() - t0
    fns = _CHUNKS[key]
    info, chunk = fns["info"], fns["chunk"]
    cp = np.asarray(symbolic_params, dtype=float)
    nx, na = comp.system.formulation.nx, cl.state.size
    p, period, duration = comp.p, comp.period, comp.duration
    info.args[2][:] = cp
    info.args[4][:] = p
    info.args[7][:] = cl.params
    c0, par, noise_in = chunk.args
    noise_in[:] = 0.0  # (run_pieces writes each piece's draws into it)
    # the chunk's carry and parameters and the row's info, by name (chunk_layout.py: the builder's)
    C, P = chunk_carry(nx, xa=na), chunk_par(len(cp), len(p), pa=cl.params.size)
    c_x, c_xa = C.slice("x"), C.slice("xa")
    par[:] = P.pack(t0=0.0, h=period, n_act=0.0, cp=cp, u_ext=np.zeros(3), p=p, pa=cl.params)
    out = comp.end.outputs  # the CMG cluster's reported values (act): u_cmg, m, rate_limited, saturated
    IL = chunk_info(3, out.size)
    r_cmd, r_act, r_q = IL.slice("cmd"), IL.slice("act"), IL.slice("q_ref")
    i_u, i_lim, i_sat = out.slice("u_cmg"), out.slice("rate_limited").start, out.slice("saturated").start
    x = np.array(res.x, dtype=float)
    xa = th.x.copy()
    tail_flag = 0
    ticks = 0
    res.used_fused = True
    row_ks = sorted(set(range(0, K, n)) | {K})
    try:
        for j, k in enumerate(row_ks):
            t = min(k * period, duration)
            n_tick = row_ks[j + 1] - k if k < K else 1
            if nn:  # the draws of ticks k .. k + n_tick - 1, in the per-tick loop's order
                draws = noise["draw"](comp, n_tick, flags)
                info.args[8][:] = draws[0]
            info.args[0][0] = t
            info.args[1][:] = x
            u_row = held_torque_from(comp.scene, t, comp.bps, duration)
            info.args[3][:] = u_row
            info.args[5][0] = th.tick_length(comp, t)
            info.args[6][:] = xa
            info()
            r = info.res[0]
            cmd, act, q_ref = r[r_cmd], r[r_act], r[r_q]
            lim, sat = int(act[i_lim] > 0.5), int(act[i_sat] > 0.5)
            th.x_row = xa
            res.row(t, x, lim | sat | tail_flag, u_cmg=act[i_u], cmd=cmd, q_ref=q_ref)
            if k == K:
                break
            c0[c_x], c0[c_xa] = x, xa
            # (the row's torque when a piece starts at the row: not looked up twice)
            counts = run_pieces(chunk, C, P, tick_pieces(k, n_tick, edges, duration, period), k, period,
                                lambda ta: u_row if ta == t else held_torque_from(comp.scene, ta, comp.bps, duration),
                                draws if nn else None)
            x, xa = c0[c_x].copy(), c0[c_xa].copy()
            ticks += n_tick
            tail_flag = close_chunk(res, ticks, counts, lim, sat, x, min((k + n_tick) * period, duration))
    finally:
        th.x = th.x_row = xa
        finish_chunks(res, x, ticks)
