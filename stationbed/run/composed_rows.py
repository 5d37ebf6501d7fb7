"""Many output rows of the composed loop in one compiled call (issue 33; the mechanism of
the truth-fed and the flight loops' bulk rows of issues 25 and 20, now for any composition).

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

import math

import casadi as ca
import numpy as np

from ..core.layout import Layout
from ..integrators import IntegrationError
from ..core.compile import FastCall

__all__ = ["ROW_CALLS", "rows_functions", "run_rows", "row_flags_and_held"]

#: rows per compiled call, largest first (the rows left over go row by row). A call of R rows
#: saves R - 1 calls' Python; padding a call with idle rows would still run their ticks (the
#: chunk masks a tick's result, it does not skip its arithmetic), so calls are always full.
ROW_CALLS = (64, 8)


def _full_rows(comp, row_ks, n: int, K: int) -> int:
    """How many leading rows run ``n`` full ticks each (the last tick's period not cut short):
    the first row ``j`` that does not (it is the last, its tick is ``K``, the next row is not
    ``n`` ticks on, or its last tick ends past the duration), in numpy (a row at a time was
    ~0.15 ms a run of 800 rows, issue 25)."""
    period, duration = comp.period, comp.duration
    ks = np.asarray(row_ks, dtype=np.int64)
    a = ks[:-1]
    ok = (a < K) & (np.diff(ks) == n) & ~(duration - (a + n - 1) * period < period * (1 - 1e-12))
    return len(a) if ok.all() else int(np.argmin(ok))


def row_flags_and_held(m: int, act, cmd, counts, tail_flag: int, cmg, ng: int, torque: bool) -> tuple:
    """The first ``m`` bulk rows' saturation flags and held columns, as the row-by-row loop makes
    them: a row's flag is its own tick's (rate limited or saturated) or any tick after the
    previous row's tick (its chunk: ``counts`` less the row tick's own); ``tail_flag`` carries
    the chunk before the first row. ``cmg`` = (u_cmg slice, rate-limited index, saturated index)
    of the chain end's ``act``, or None without a cluster. Returns (flag, after, held pieces):
    the gimbals' held input and the flag (with a cluster), the torque command (NaN when the law
    commands rates) and the attitude error's four NaN columns (filled by the rows)."""
    lim = sat = np.zeros(m)
    if cmg is not None:
        i_u, i_lim, i_sat = cmg
        lim, sat = (act[:m, i_lim] > 0.5).astype(float), (act[:m, i_sat] > 0.5).astype(float)
    after = ((counts[:m, 0] - lim) + (counts[:m, 1] - sat) > 0.5).astype(float)
    prev = np.concatenate(([float(tail_flag)], after[:-1]))
    flag = np.maximum(np.maximum(lim, sat), prev)
    held = []
    if cmg is not None:
        held += [act[:m, i_u][:, :ng], flag[:, None]]
    held += [cmd[:m] if torque else np.full((m, 3), math.nan), np.full((m, 4), math.nan)]
    return flag, after, held


def _held_matches(res, held, act, cmd, q_ref, flag) -> bool:
    """Whether the bulk held values of the first row are what the executors' own row holds
    (:meth:`~.composition.RunState.held_row`, with this row's actuation, command and reference set)."""
    comp = res.comp
    if act is not None:
        res.u[comp.u_cmg] = act
    if comp.n_cmd == 3:
        res.last_cmd = tuple(cmd)
    comp.ctrl.q_ref_BN = tuple(q_ref)
    vals, _ = res.held_row(flag)
    vals = np.asarray(vals, dtype=float)
    return vals.shape == held.shape and bool(np.array_equal(vals, held, equal_nan=True))


_REPORTS: dict = {}


def _report(mekf, R: int) -> FastCall:
    """The filter's report over R rows: its SX function mapped (casadi's virtual machine, as
    :meth:`~stationbed.loop.flight.Flight.row` evaluates it row by row: the same numbers)."""
    f = mekf.report_function()
    hit = _REPORTS.get((id(f), R))
    if hit is None or hit[0] is not f:
        hit = _REPORTS[(id(f), R)] = (f, FastCall(f.map(R)))
    return hit[1]



def rows_functions(cm, row: ca.Function, chunk: ca.Function, n: int) -> list:
    """``cl_rows_R`` for each R of :data:`ROW_CALLS` (module docstring); ``par`` the
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


def run_rows(comp, res, cm, calls: dict, row_ks, K: int, c0: np.ndarray, par: np.ndarray, draws,
             tail_flag: int = 0) -> tuple:
    """Run the leading full rows of a composed run (or of a stretch of it between scheduled
    steps: ``row_ks`` its rows' ticks, ``tail_flag`` the flag carried into its first row) in
    calls of ``R`` rows.

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
    flight, fm = comp.flight, res.flight
    sense = next((b for b in cm.sense if b.name == "sensing"), None)  # the flight's block
    period, duration = comp.period, comp.duration
    out_l = comp.end.outputs
    has_cmg = comp.has_cluster
    cmg = (out_l.slice("u_cmg"), out_l.slice("rate_limited").start, out_l.slice("saturated").start) if has_cmg else None
    torque = comp.ctrl.command == "torque"
    nw = cm.noise.size
    j = ticks = 0
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
                sl = flight.row_slices
                if rep is not None:  # the filter's report against the truth (Flight.row's numbers)
                    q = xs_[:, comp.state_layout.slice("q_BN")]
                    rep.args[0][:] = fl_xs[:, sl["mekf"]].ravel()
                    rep.args[1][:] = (q / np.sqrt([qi.dot(qi) for qi in q])[:, None]).ravel()
                    rep.args[2][:] = fl_xs[:, sl["gyro"][0]][:, sl["gyro"][1]].ravel()
                    rep()
                    err, s3, nees = rep.res[0].reshape(R, 3), rep.res[1].reshape(R, 6), rep.res[2]
                    held += [np.degrees(err[:m]), np.degrees(s3[:m, :3]), fl_ys[:m, sl["bias"]], nees[:m, None]]
                held += [fl_ys[:m, sl["valid"]]]
            for a in comp.memories:  # the chain's columns from their memory before each row's tick
                held += [C.get(cs, a.name)[:m][:, a.idx]]
            held = np.hstack(held)
            if j == 0:
                if sense is not None:
                    fm.xs, fm.ys = fl_xs[0], fl_ys[0]
                for a in comp.memories:
                    a.x_row = C.get(cs[0], a.name)
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
