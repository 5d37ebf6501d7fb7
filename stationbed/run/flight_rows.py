"""Many output rows of the fused flight loop in one compiled call (issue 20: its speed).

The fused flight loop (:mod:`.fused_flight`) makes two compiled calls per output row (the row's
``info``, then the chunk of ticks up to the next row) and ~45 µs of Python around them: the
noise rows, the filter's report (error, 3σ, NEES), the row's held values, the batch of rows.
On ``iss_lvlh_hold_estimated`` that is ~0.05 s of a ~0.2 s orbit, against ~0.01 s for the
truth-fed loop, which has its rows in bulk (:mod:`.fused_rows`). Here the same two compiled
functions are called ``R`` rows at a time by a third one,

    flight_rows_R(carry, a, par, w) -> (carries, out):  per row r, from the chunk's carry c:
        out_r  = (x, info(a_r h, x, cp, u_ext, p, a_r, c.t_prev, c.theta_B, c.omega_prev, c.xs,
                  w_r[tick a_r], ps), counts of chunk)
        carry' = chunk((0, x, 0, 0, c.t_prev, ...), (a_r h, h, n, a_r, cp, u_ext, p, ps), w_r)

(casadi ``mapaccum`` over rows), and the rows' held values, the filter's report included, are
made with numpy and one mapped report call for all ``R`` at once. Same functions, same inputs,
same order of operations, the report evaluated by the same casadi virtual machine as the row
by row loop's: the same numbers, bit for bit (tests/test_flight_rows.py). The noise of the R rows'
ticks is taken from :class:`~stationbed.loop.flight.TickNoise` in one call (tick order: the same
numbers as R calls).

Where it applies (else the row-by-row loop runs, as before): the leading rows whose stretch is
``n`` full ticks of one held torque (no torque-window edge in the run, not the short last
period). The first row's held values are checked against the executor's own (``_held_row``): a
loop whose rows hold other columns runs row by row (its noise stream put back first).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..loop import Layout
from .chunk_layout import FLIGHT_INFO_IN, chunk_info, flight_rows_out, vertcat_by
from .fused_rows import ROW_CALLS, _full_rows, _held_matches, row_flags_and_held

__all__ = ["flight_rows_functions", "run_flight_rows"]


def flight_rows_functions(info: ca.Function, chunk: ca.Function, C: Layout, n: int, RP: Layout, nw: int) -> list:
    """``flight_rows_<R>`` for each R of :data:`~.fused_rows.ROW_CALLS`.

    Parameters
    ----------
    info : Function  ``ffl_info(t, x, cp, u_ext, p, k, t_prev, theta, omega, xs, w, ps) -> (info,
        xs_next, ys)``.
    chunk : Function  ``ffl_chunk(c0, par, w) -> carry`` of ``n`` ticks, ``c0`` laid out by ``C``
        (:func:`.chunk_layout.flight_carry`), ``par = (t0, h, n_act, k0, cp, u_ext, p, ps)``
        (:func:`.chunk_layout.flight_par`), ``w`` (nw, n): column i tick i's noise row.
    RP : Layout  The call's ``par = (h, cp, u_ext, p, ps)`` (:func:`.chunk_layout.flight_rows_par`).

    Returns
    -------
    list of Function  ``flight_rows_R(c[C.size], a[1 x R], par[RP.size], w[nw n x R]) ->
    (carries[C.size x R], out[O.size x R])``: ``a`` the rows' first ticks, column r of ``w``
    row r's noise tick by tick; column r of ``out`` (``O``: :func:`.chunk_layout.flight_rows_out`)
    is row r's state, its ``info`` outputs, the flight's state and outputs and the chunk's counts
    of rate-limited and saturated ticks; of ``carries``, the carry after row r.
    """
    c, a = ca.MX.sym("c", C.size), ca.MX.sym("a")
    par, w = ca.MX.sym("par", RP.size), ca.MX.sym("w", nw * n)
    h, rest = par[RP.slice("h").start], par[RP.slice("h").stop :]  # rest: the chunk's par after t0, h, n_act, k0
    x, tp, th, om, xs = (C.get(c, f) for f in ("x", "t_prev", "theta_B", "omega_prev", "xs"))
    t = a * h  # as the executor: k * period, one IEEE product
    ins = dict(t=t, x=x, cp=RP.get(par, "cp"), u_ext=RP.get(par, "u_ext"), p=RP.get(par, "p"), k=a, t_prev=tp,
               theta_B=th, omega_prev=om, xs=xs, w=w[:nw], ps=RP.get(par, "ps"))
    inf, xs1, ys = info(*(ins[f] for f in FLIGHT_INFO_IN))
    env = {"env": C.get(c, "env")} if "env" in C else {}  # the held environment's carry (flight_rates.py)
    c0 = C.pack(i=0.0, x=x, counts=ca.MX.zeros(2), t_prev=tp, theta_B=th, omega_prev=om, xs=xs, **env, symbolic=True)
    cols = chunk.size_in(2)[1]  # (a held chunk has whole blocks: the columns past n are masked ticks)
    wn = ca.reshape(w, nw, n) if cols == n else ca.horzcat(ca.reshape(w, nw, n), ca.MX.zeros(nw, cols - n))
    res = chunk(c0, ca.vertcat(t, h, float(n), a, rest), wn)
    O = flight_rows_out(x.numel(), inf.numel(), xs1.numel(), ys.numel())
    out = vertcat_by(O, x=[x], info=[inf], xs=[xs1], ys=[ys], counts=[C.get(res, "counts")])
    row = ca.Function("flight_row", [c, a, par, w], [res, out])
    fns = []
    for R in ROW_CALLS:
        acc = row.mapaccum(f"flight_rows_acc_{R}", R)
        cs, as_, ps_, ws = ca.MX.sym("c", C.size), ca.MX.sym("a", 1, R), ca.MX.sym("par", RP.size), ca.MX.sym("w", nw * n, R)
        carries, outs = acc(cs, as_, ca.repmat(ps_, 1, R), ws)
        fns.append(ca.Function(f"flight_rows_{R}", [cs, as_, ps_, ws], [carries, outs]))
    return fns


_REPORTS: dict = {}


def _report(mekf, R: int) -> FastCall:
    """The filter's report over R rows: its SX function mapped (casadi's virtual machine, as
    :meth:`~stationbed.loop.flight.Flight.row` evaluates it row by row: the same numbers)."""
    f = mekf.report_function()
    hit = _REPORTS.get((id(f), R))
    if hit is None or hit[0] is not f:
        hit = _REPORTS[(id(f), R)] = (f, FastCall(f.map(R)))
    return hit[1]


def run_flight_rows(comp, res, calls: dict, row_ks, K: int, C: Layout, c0: np.ndarray, par_rest: np.ndarray, ls: int) -> tuple:
    """Run the leading full rows of a fused flight run in calls of ``R`` rows.

    Parameters
    ----------
    comp, res : Composition, RunState  The run (:mod:`.composition`): read, and handed back its
        rows, counts, held input, the law's last command and reference and the flight's memory
        as the row-by-row loop hands them back.
    calls : dict  R -> the compiled ``flight_rows_R`` (FastCall).
    row_ks : list of int  The row ticks; K the last tick.
    C : Layout  The chunk's carry; ``c0`` its value at tick 0 (updated in place).
    par_rest : ndarray  ``(cp, u_ext, p, ps)``.
    ls : int  Size of the law's own state (after the plant's in the carry's ``x``).

    Returns
    -------
    (j, tail_flag, ticks, stop) : the first row left to the row-by-row loop, the saturation flag
    carried from the rows before, ticks run, and an IntegrationError for the executor to raise
    when a row's stretch ended in a non-finite state (the rows up to it handed over), else None.
    """
    n = comp.n_per_out
    n_rows = _full_rows(comp, row_ks, n, K)
    if not calls or n_rows < min(calls):
        return 0, 0, 0, None
    flight, fm = comp.flight, res.flight
    mekf, S = flight.mekf, flight.suite
    cx, cxs = C.slice("x"), C.slice("xs")
    nx = cx.stop - cx.start
    nx0 = nx - ls
    ns, ny = S.STATE.size, S.OUTPUTS.size
    period, duration = comp.period, comp.duration
    ncmd, ng = comp.n_cmd, comp.ng
    out_l = comp.end.outputs  # the chain end's reported values (act): u_cmg, m, rate_limited, saturated
    has_cmg = comp.has_cluster
    n_act = out_l.size if has_cmg else 0
    i_u, i_lim, i_sat = (out_l.slice("u_cmg"), out_l.slice("rate_limited").start,
                         out_l.slice("saturated").start) if has_cmg else (slice(0, 0), 0, 0)
    torque = comp.ctrl.command == "torque"
    IL = chunk_info(ncmd, n_act, ls)  # the row's info and output, by name (chunk_layout.py: the builder's)
    O = flight_rows_out(nx, IL.size, ns, ny)
    sl = flight._rows
    valid = sl["valid"]
    j = tail_flag = ticks = 0
    noise0 = comp.tick_noise.state()  # a fallback to row by row draws the same again
    for R in sorted(calls, reverse=True):
        fc = calls[R]
        fc.args[2][:] = np.concatenate(([period], par_rest))
        rep = _report(mekf, R) if mekf is not None else None
        while n_rows - j >= R:
            ks = np.asarray(row_ks[j : j + R], dtype=float)
            fc.args[0][:] = c0
            fc.args[1][:] = ks
            comp.tick_noise.rows_into(row_ks[j], R * n, fc.args[3].reshape(R * n, -1))  # row r's ticks, tick by tick
            fc()
            carries = fc.res[0].reshape(R, -1)  # column-major (C.size, R): row r's carry is a row here
            out = fc.res[1].reshape(R, -1)
            xs_ = O.get(out, "x")[:, :nx0]
            info, fl_xs, fl_ys, counts = (O.get(out, f) for f in ("info", "xs", "ys", "counts"))
            cmd, act, q_ref = (IL.get(info, f) for f in ("cmd", "act", "q_ref"))
            bad = ~np.all(np.isfinite(carries[:, cx]), axis=1)
            m = int(np.argmax(bad)) + 1 if bad.any() else R  # rows whose stretch ran (the last may end in NaN)
            flag, after, held = row_flags_and_held(m, act, cmd, counts, tail_flag, (i_u, i_lim, i_sat) if has_cmg else None,
                                                   ng, torque)
            if rep is not None:  # the filter's report against the truth (Flight.row's numbers)
                q = xs_[:, comp.state_layout.slice("q_BN")]
                rep.args[0][:] = fl_xs[:, sl["mekf"]].ravel()
                # Flight.row's q / np.linalg.norm(q), which is q / sqrt(q.dot(q)) for a vector: the same dot
                rep.args[1][:] = (q / np.sqrt([qi.dot(qi) for qi in q])[:, None]).ravel()
                rep.args[2][:] = fl_xs[:, sl["gyro"][0]][:, sl["gyro"][1]].ravel()
                rep()
                err, s3, nees = rep.res[0].reshape(R, 3), rep.res[1].reshape(R, 6), rep.res[2]
                held += [np.degrees(err[:m]), np.degrees(s3[:m, :3]), fl_ys[:m, sl["bias"]], nees[:m, None]]
            held += [fl_ys[:m, valid]]
            held = np.hstack(held)
            if j == 0:
                res.x, fm.xs, fm.ys = xs_[0], fl_xs[0], fl_ys[0]
                if not _held_matches(res, held[0], act[0, i_u] if has_cmg else None, cmd[0],
                                     q_ref[0], int(flag[0])):
                    comp.tick_noise.restore(noise0)
                    return 0, 0, 0, None  # the executor's row has other columns: row by row
            ts = np.minimum(ks[:m] * period, duration)
            try:  # (a non-finite output row: the rows before it are handed over)
                res.rows_many(ts, xs_[:m], held, q_ref[:m], counts[:m], u_cmg=act[m - 1, i_u] if has_cmg else None,
                              cmd=cmd[m - 1])
            except IntegrationError as e:
                return j, tail_flag, ticks, e
            ticks += m * n
            tail_flag = int(after[-1])
            res.x, fm.xs, fm.ys = xs_[m - 1].copy(), fl_xs[m - 1].copy(), fl_ys[m - 1].copy()
            c0[:] = carries[m - 1]
            j += m
            if m < R:
                t_stop = min((row_ks[j - 1] + n) * period, duration)
                return j, tail_flag, ticks, IntegrationError(t_stop, "state is not finite (NaN or inf)")
    return j, tail_flag, ticks, None
