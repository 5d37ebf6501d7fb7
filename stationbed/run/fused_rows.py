"""Many output rows of the fused loop in one compiled call (issue 25: less Python per row).

The fused loop (:mod:`.fused`) makes one compiled call per output row (the row's ``info``, then
the chunk of ticks up to the next row) and ~40 µs of Python around it: numpy writes, the row's
held values, the batch of rows. On ``iss_lvlh_hold`` that is ~25 ms of a ~0.1 s orbit. Here the
same two compiled functions are called ``R`` rows at a time by a third one,

    rows_R(carry, a, par) -> (carries, out):  per row r, from the carry (x, env):
        out_r   = (x, info(a_r h, x, cp, u_ext, p), counts of chunk)
        carry' = chunk((0, x, 0, 0, env), (a_r h, h, n, cp, u_ext, p))

(casadi ``mapaccum`` over rows, generated as C with the two functions it calls), and the rows'
held values are made with numpy for all ``R`` at once. Same functions, same inputs, same order of
operations: the same numbers as the row-by-row loop, bit for bit (tests/test_fused_rows.py).

Where it applies (else the row-by-row loop runs, as before): rows whose stretch is ``n`` full
ticks of one held torque (no torque-window edge inside the run, not the short last period), no
flight loop. Sensor noise: the draws of the R rows' ticks are drawn in one call, in the
row-by-row loop's order (one generator fills an array element by element: the same numbers as
R calls of one row each), and passed as a per-row input. :func:`run_rows` does the
leading run of such rows and hands the executor back its state to go on row by row.
The first row's held values are checked against the executors' own (``RunState.held_row``): a loop
whose rows hold other columns runs row by row.
A law's own state (law_state.py) rides after the plant's in the carry, as in the chunk: the
rows get the plant's state, and ``info`` ends with the law's next state, after ``q_ref``.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..integrators import IntegrationError
from .chunk_layout import chunk_carry, chunk_info, chunk_par, rows_carry, rows_out, rows_par, vertcat_by


__all__ = ["ROW_CALLS", "rows_functions", "run_rows"]

#: rows per compiled call, largest first (the rows left over go row by row). A call of R rows
#: saves R - 1 calls' Python; padding a call with idle rows would still run their ticks (the
#: chunk masks a tick's result, it does not skip its arithmetic), so calls are always full.
ROW_CALLS = (64, 8)


def rows_functions(info: ca.Function, chunk: ca.Function, n: int, nx: int, ne: int, ncp: int, npar: int, nn: int = 0) -> list:
    """``fused_rows_<R>`` for each R of :data:`ROW_CALLS`.

    Parameters
    ----------
    info : Function  ``fused_info(t, x, cp, u_ext, p[, nz]) -> (cmd, act, q_ref)``.
    chunk : Function  ``fused_chunk(c0, par[, noise]) -> carry`` of ``n`` ticks: ``c0 = (i, x,
        counts(2), env(ne))``, ``par = (t0, h, n_act, cp, u_ext, p)``, ``noise`` (nn, >= n)
        column i tick i's sensor draws.
    n : int  Ticks per row.
    nx, ne, ncp, npar, nn : int  Sizes of the state, of the held environment's carry, of the
        controller's and of the model's parameters, sensor draws per tick.

    Returns
    -------
    list of Function  ``fused_rows_R(c[nx + ne], a[1 x R], par[1 + ncp + 3 + npar][, nz[nn n x R]])
    -> (carries[(nx + ne) x R], out[(nx + ninfo + 2) x R])``: ``a`` the rows' first ticks, ``par``
    = ``(h, cp, u_ext, p)``, column r of ``nz`` row r's draws tick by tick; column r of ``out``
    is row r's state, its ``info`` and the chunk's counts of rate-limited and saturated ticks;
    of ``carries``, the carry after row r.
    """
    RC, RP = rows_carry(nx, ne), rows_par(ncp, npar)  # by name (chunk_layout.py), as the chunk's
    C, P = chunk_carry(nx, env=ne), chunk_par(ncp, npar)
    c = ca.MX.sym("c", RC.size)
    a = ca.MX.sym("a")
    par = ca.MX.sym("par", RP.size)
    nz = [ca.MX.sym("nz", nn * n)] if nn else []
    h = RP.get(par, "h")
    x = RC.get(c, "x")
    t = a * h  # as the executor: k * period, one IEEE product
    cp, u_ext, p = RP.get(par, "cp"), RP.get(par, "u_ext"), RP.get(par, "p")
    inf = info(t, x, cp, u_ext, p, *([nz[0][:nn]] if nn else []))
    c0 = vertcat_by(C, i=[0.0], x=[x], counts=[0.0, 0.0], env=[RC.get(c, "env")])
    noise = []
    if nn:  # the chunk's (nn, n_max) draws: this row's n ticks, the rest unused (masked ticks)
        cols = chunk.size_in(2)[1]
        noise = [ca.horzcat(ca.reshape(nz[0], nn, n), ca.MX.zeros(nn, cols - n))]
    rest = par[RP.slice("cp").start :]  # cp, u_ext, p: the chunk's parameters after n_act, in its order
    assert P.names[3:] == RP.names[1:] and P.names[:3] == ("t0", "h", "n_act")  # (one piece: the same C)
    res = chunk(c0, ca.vertcat(t, h, float(n), rest), *noise)
    carry = RC.pack(x=C.get(res, "x"), env=C.get(res, "env"))
    out = rows_out(nx, inf.numel()).pack(x=x, info=inf, counts=C.get(res, "counts"))
    row = ca.Function("fused_row", [c, a, par] + nz, [carry, out])
    fns = []
    for R in ROW_CALLS:
        acc = row.mapaccum(f"fused_rows_acc_{R}", R)
        cs, as_, ps = ca.MX.sym("c", nx + ne), ca.MX.sym("a", 1, R), ca.MX.sym("par", par.numel())
        nzs = [ca.MX.sym("nz", nn * n, R)] if nn else []
        carries, outs = acc(cs, as_, ca.repmat(ps, 1, R), *nzs)
        fns.append(ca.Function(f"fused_rows_{R}", [cs, as_, ps] + nzs, [carries, outs]))
    return fns


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


def run_rows(comp, res, fns: dict, row_ks, K: int, x, env_c, cp, u_ext, p, draw=None, ns: int = 0) -> tuple:
    """Run the leading full rows of a fused run in calls of :data:`ROW_CALLS` rows.

    Parameters
    ----------
    comp, res : Composition, RunState  The run (:mod:`.composition`): read, and handed back its
        rows, counts, held input and the law's last command and reference as the row-by-row
        loop hands them back.
    fns : dict  The fused build: ``"rows"`` maps R to the compiled ``fused_rows_R`` (FastCall).
    row_ks : list of int  The row ticks; K the last tick.
    x, env_c : ndarray  The state (the law's own state of ``ns`` values after the plant's,
        law_state.py) and the held environment's carry at tick 0.
    cp, u_ext, p : ndarray  The controller's parameters, the held external torque, the model's.
    draw : callable or None  ``draw(k)`` -> the sensor draws of the next k ticks, (k, nn), from
        the run's generator (``comp.rng``) in the row-by-row loop's order (None: no sensor noise).

    Returns
    -------
    (j, x, env_c, tail_flag, ticks, stop) : the first row left to the row-by-row loop, and its
    state, carry, saturation flag carried from the rows before, ticks run; ``stop`` an
    IntegrationError for the executor to raise (with its own bookkeeping, as its loop does) when
    a row's stretch ended in a non-finite state (the rows up to it handed to the sink) or a row
    came out non-finite, else None. ``(0, x, env_c, 0, 0, None)`` when nothing was run here.
    """
    calls = fns.get("rows") or {}
    n = comp.n_per_out
    n_rows = _full_rows(comp, row_ks, n, K)
    if not calls or n_rows < min(calls):
        return 0, x, env_c, 0, 0, None
    nx = len(x)
    period, duration = comp.period, comp.duration
    ncmd, ng = comp.n_cmd, comp.ng
    out_l = comp.end.outputs  # the chain end's reported values: u_cmg, m, rate_limited, saturated
    has_cmg = comp.has_cluster
    n_act = out_l.size if has_cmg else 0
    i_u, i_lim, i_sat = (out_l.slice("u_cmg"), out_l.slice("rate_limited").start,
                         out_l.slice("saturated").start) if has_cmg else (slice(0, 0), 0, 0)
    torque = comp.ctrl.command == "torque"
    IL = chunk_info(ncmd, n_act, ns)  # the row's info, the call's carry and output (chunk_layout.py)
    RC, RO = rows_carry(nx, len(env_c)), rows_out(nx, IL.size)
    # the generator's state before the first draw: a fallback to row by row draws the same again
    rng_state = comp.rng.bit_generator.state if draw is not None else None
    j = 0
    tail_flag = 0
    ticks = 0
    for R in sorted(calls, reverse=True):
        fc = calls[R]
        fc.args[2][:] = rows_par(len(cp), len(p)).pack(h=period, cp=cp, u_ext=u_ext, p=p)
        while n_rows - j >= R:
            ks = np.asarray(row_ks[j : j + R], dtype=float)
            fc.args[0][:] = RC.pack(x=x, env=env_c)
            fc.args[1][:] = ks
            if draw is not None:  # the R rows' ticks in order: column r = row r's ticks, tick by tick
                fc.args[3][:] = draw(R * n).ravel()
            fc()
            carries = fc.res[0].reshape(R, -1)  # column-major (nx + ne, R): row r's carry is a row here
            out = fc.res[1].reshape(R, -1)
            xs, info, counts = RO.get(out, "x")[:, : nx - ns], RO.get(out, "info"), RO.get(out, "counts")
            cmd, act, q_ref = IL.get(info, "cmd"), IL.get(info, "act"), IL.get(info, "q_ref")  # (rows: the plant's state)
            bad = ~np.all(np.isfinite(RC.get(carries, "x")), axis=1)
            m = int(np.argmax(bad)) + 1 if bad.any() else R  # rows whose stretch ran (the last may end in NaN)
            flag, after, held = row_flags_and_held(m, act, cmd, counts, tail_flag, (i_u, i_lim, i_sat) if has_cmg else None,
                                                   ng, torque)
            held = np.hstack(held)
            if j == 0 and not _held_matches(res, held[0], act[0, i_u] if has_cmg else None, cmd[0], q_ref[0], int(flag[0])):
                if rng_state is not None:
                    comp.rng.bit_generator.state = rng_state
                return 0, x, env_c, 0, 0, None  # the executor's row has other columns: row by row
            ts = np.minimum(ks[:m] * period, duration)
            try:  # (a non-finite output row: the rows before it are handed over)
                res.rows_many(ts, xs[:m], held, q_ref[:m], counts[:m], u_cmg=act[m - 1, i_u] if has_cmg else None,
                              cmd=cmd[m - 1])
            except IntegrationError as e:
                return j, x, env_c, tail_flag, ticks, e
            ticks += m * n
            tail_flag = int(after[-1])
            x = RC.get(carries[m - 1], "x").copy()
            env_c = RC.get(carries[m - 1], "env").copy()
            j += m
            if m < R:
                t_stop = min((row_ks[j - 1] + n) * period, duration)
                return j, x, env_c, tail_flag, ticks, IntegrationError(t_stop, "state is not finite (NaN or inf)")
    return j, x, env_c, tail_flag, ticks, None


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
