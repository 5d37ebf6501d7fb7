"""Many output rows of the composed loop in one compiled call (issue 33; the mechanism of
:mod:`.fused_rows` and :mod:`.flight_rows`, for any composition).

``rows_R(c, a, par, w) -> (carries, out)``: per row r (casadi ``mapaccum`` over rows), from the
carry ``c`` at the row's first tick ``a_r``: the composed ``row`` at ``(t0 = a_r h, k0 = a_r)``,
then the composed ``chunk`` over the row's ``n`` ticks; ``out_r`` is the row's carry (its state
and each block's memory before the tick: the thrusters' row values), the row's values
(:attr:`~stationbed.loop.compose.Composed.row_layout`) and the chunk's counts. The rows' held
values are then made with numpy (the filter's report mapped over the rows, the thrusters'
columns indexed from their memory), as the row-by-row loop makes them: the same functions on the
same inputs, the same numbers (tests/test_composed.py). The first row's held values are checked
against the run state's own (``_held_matches``): a run whose rows hold other columns runs row by
row (its noise stream put back first).

Where it applies: the leading rows whose stretch is ``n`` full ticks of one held torque (no
torque-window edge in the run, not the short last period).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.layout import Layout
from ..integrators import IntegrationError
from .flight_rows import _report
from .fused_rows import ROW_CALLS, _full_rows, _held_matches, row_flags_and_held

__all__ = ["rows_functions", "run_rows"]


def rows_functions(cm, row: ca.Function, chunk: ca.Function, n: int) -> list:
    """``cl_rows_R`` for each R of :data:`~.fused_rows.ROW_CALLS` (module docstring); ``par`` the
    chunk's parameters (its ``t0``, ``k0``, ``n_act`` set per row)."""
    C, P, R_ = cm.carry, cm.par, cm.row_layout
    nw = cm.noise.size
    MX = ca.MX
    c, a, par, w = MX.sym("c", C.size), MX.sym("a"), MX.sym("par", P.size), MX.sym("w", nw * n)
    h = P.get(par, "h")
    t = a * h  # as the executor: k * period, one IEEE product
    fields = {f: P.get(par, f) for f in P.names}
    fields.update(t0=t, k0=a, n_act=MX(float(n)))
    prow = P.pack(fields, symbolic=True)
    c_row = C.pack({**{f: C.get(c, f) for f in C.names}, "i": MX(0.0), "counts": MX.zeros(2)}, symbolic=True)
    r = row(c_row, prow, w[:nw])
    res = chunk(c_row, prow, ca.reshape(w, nw, n))
    f = ca.Function("cl_row_one", [c, a, par, w], [res, ca.vertcat(c, r, C.get(res, "counts"))])
    fns = []
    for R in ROW_CALLS:
        acc = f.mapaccum(f"cl_rows_acc_{R}", R)
        cs, as_, ps_, ws = MX.sym("c", C.size), MX.sym("a", 1, R), MX.sym("par", P.size), MX.sym("w", nw * n, R)
        carries, outs = acc(cs, as_, ca.repmat(ps_, 1, R), ws)
        fns.append(ca.Function(f"cl_rows_{R}", [cs, as_, ps_, ws], [carries, outs]))
    return fns


def run_rows(comp, res, cm, calls: dict, row_ks, K: int, c0: np.ndarray, par: np.ndarray, draws) -> tuple:
    """Run the leading full rows of a composed run in calls of ``R`` rows.

    ``c0`` the carry at tick 0 (updated in place to the carry after the rows run), ``par`` the
    chunk's parameters (``h`` the period, the blocks' numbers), ``draws`` the run's draws by tick
    (run/composed.py ``Draws``). Returns ``(j, tail_flag, ticks,
    stop)``: the first row left to the row-by-row loop, the saturation flag carried from the rows
    before, ticks run, and an IntegrationError for the executor to raise when a row's stretch
    ended in a non-finite state (the rows up to it handed over), else None."""
    n = comp.n_per_out
    n_rows = _full_rows(comp, row_ks, n, K)
    if not calls or n_rows < min(calls):
        return 0, 0, 0, None
    C, RL = cm.carry, cm.row_layout
    O = Layout(c=C.size, row=RL.size, counts=2)
    flight, th, fm = comp.flight, comp.thrust, res.flight
    sense = next((b for b in cm.sense if b.name == "sensing"), None)  # the flight's block
    act_b = cm.actuators[0] if cm.actuators else None
    period, duration = comp.period, comp.duration
    out_l = comp.end.outputs
    has_cmg = comp.has_cluster
    cmg = (out_l.slice("u_cmg"), out_l.slice("rate_limited").start, out_l.slice("saturated").start) if has_cmg else None
    torque = comp.ctrl.command == "torque"
    nw = cm.noise.size
    j = tail_flag = ticks = 0
    noise0 = draws.state() if nw else None  # a fallback to row by row draws the same again
    for R in sorted(calls, reverse=True):
        fc = calls[R]
        fc.args[2][:] = par
        rep = _report(flight.mekf, R) if flight is not None and flight.mekf is not None else None
        while n_rows - j >= R:
            ks = np.asarray(row_ks[j : j + R], dtype=float)
            fc.args[0][:] = c0
            fc.args[1][:] = ks
            if nw:  # the R rows' ticks in order: column r = row r's ticks, tick by tick
                if sense is not None and nw == sense.noise.size:
                    comp.tick_noise.rows_into(row_ks[j], R * n, fc.args[3].reshape(R * n, -1))
                else:
                    fc.args[3][:] = draws.rows(row_ks[j], R * n).ravel()
            fc()
            carries = fc.res[0].reshape(R, -1)
            out = fc.res[1].reshape(R, -1)
            cs, rows, counts = O.get(out, "c"), O.get(out, "row"), O.get(out, "counts")
            xs_ = C.get(cs, "x")
            cmd, act, q_ref = (RL.get(rows, f) for f in ("cmd", "act", "q_ref"))
            bad = ~np.all(np.isfinite(C.get(carries, "x")), axis=1)
            m = int(np.argmax(bad)) + 1 if bad.any() else R
            flag, after, held = row_flags_and_held(m, act, cmd, counts, tail_flag, cmg, comp.ng, torque)
            fl_xs = fl_ys = None
            if sense is not None:
                fl_xs = sense.state.get(RL.get(rows, sense.name), "xs")
                fl_ys = sense.outputs.get(RL.get(rows, f"{sense.name}_y"), "ys")
                sl = flight._rows
                if rep is not None:  # the filter's report against the truth (Flight.row's numbers)
                    q = xs_[:, comp.state_layout.slice("q_BN")]
                    rep.args[0][:] = fl_xs[:, sl["mekf"]].ravel()
                    rep.args[1][:] = (q / np.sqrt([qi.dot(qi) for qi in q])[:, None]).ravel()
                    rep.args[2][:] = fl_xs[:, sl["gyro"][0]][:, sl["gyro"][1]].ravel()
                    rep()
                    err, s3, nees = rep.res[0].reshape(R, 3), rep.res[1].reshape(R, 6), rep.res[2]
                    held += [np.degrees(err[:m]), np.degrees(s3[:m, :3]), fl_ys[:m, sl["bias"]], nees[:m, None]]
                held += [fl_ys[:m, sl["valid"]]]
            if act_b is not None:  # the thrusters' columns from their memory before each row's tick
                xa = C.get(cs, act_b.name)
                th.row(xa[0])  # (finds its indices once)
                held += [xa[:m][:, th._row_idx]]
            held = np.hstack(held)
            if j == 0:
                if sense is not None:
                    fm.xs, fm.ys = fl_xs[0], fl_ys[0]
                if th is not None:
                    th.x_row = C.get(cs[0], act_b.name)
                res.x = xs_[0]
                if not _held_matches(res, held[0], act[0, cmg[0]] if has_cmg else None, cmd[0], q_ref[0], int(flag[0])):
                    if noise0 is not None:
                        draws.restore(noise0)
                    return 0, 0, 0, None  # the executor's row has other columns: row by row
            ts = np.minimum(ks[:m] * period, duration)
            try:
                res.rows_many(ts, xs_[:m], held, q_ref[:m], counts[:m], u_cmg=act[m - 1, cmg[0]] if has_cmg else None,
                              cmd=cmd[m - 1])
            except IntegrationError as e:
                return j, tail_flag, ticks, e
            ticks += m * n
            tail_flag = int(after[-1])
            res.x = xs_[m - 1].copy()
            if sense is not None:
                fm.xs, fm.ys = fl_xs[m - 1].copy(), fl_ys[m - 1].copy()
            c0[:] = carries[m - 1]
            j += m
            if m < R:
                t_stop = min((row_ks[j - 1] + n) * period, duration)
                return j, tail_flag, ticks, IntegrationError(t_stop, "state is not finite (NaN or inf)")
    return j, tail_flag, ticks, None
