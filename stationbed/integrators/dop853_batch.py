"""DOP853 for many samples in lockstep: one mapped call of the compiled step per attempt, the
step-size control of every sample at once in numpy (the batch runs of
:func:`stationbed.run.batch.simulate_batch`, DESIGN §9).

Each sample runs the algorithm of a single :class:`~.dop853.DOP853` run: the same compiled
step (always its dense variant here), the same rules (:class:`~.dop853.StepControl`, applied
to arrays), its own ``t`` and ``h``. A finished or failed sample is evaluated with ``h = 0``
and ignored.
"""

from __future__ import annotations

import numpy as np

from ..core.compile import FastCall
from .dop853 import DOP853, StepControl

__all__ = ["DOP853Lockstep", "mapped", "OK", "UNDERFLOW", "NONFINITE", "STATUS_TEXT"]

#: per-sample status codes
OK, UNDERFLOW, NONFINITE = 0, 1, 2
STATUS_TEXT = {OK: "ok", UNDERFLOW: "step size underflow", NONFINITE: "state is not finite (NaN or inf)"}

_MAPS: dict = {}


def mapped(f, n: int, threads: int) -> FastCall:
    """``f`` mapped over ``n`` samples (all inputs mapped), as a reusable FastCall.

    Parameters
    ----------
    f : casadi.Function
        The function of one sample.
    n : int
        Number of samples; the mapped inputs and outputs are ``n`` copies side by side.
    threads : int
        ``> 1``: a casadi ``"thread"`` map with that many threads; else ``"serial"``.

    Returns
    -------
    FastCall
        Shared per ``(f, n, threads)`` in this process.
    """
    key = (id(f), n, threads)
    hit = _MAPS.get(key)
    if hit is None or hit[0] is not f:
        m = f.map(n, "thread", threads) if threads > 1 else f.map(n, "serial")
        hit = _MAPS[key] = (f, FastCall(m))
    return hit[1]


class DOP853Lockstep:
    """Per-sample DOP853 step control, all samples advanced by one mapped call per attempt.

    The step size ``h`` of each sample persists across segments (as a single run's).

    Parameters
    ----------
    funcs : dict
        Compiled functions of a DOP853 system (``rhs``, ``dop853_dense``).
    n, nx, nu : int
        Samples, states, held inputs.
    P : ndarray, shape (n, npar)
        Parameters per sample.
    TOL : ndarray, shape (n, 1 + nx)
        ``[rtol, atol per component]`` per sample.
    max_step : float
        Largest step [s] (``inf``: none).
    threads : int
        Threads of the mapped calls (see :func:`mapped`).

    Attributes
    ----------
    status : ndarray of int, shape (n,)
        ``OK``, ``UNDERFLOW`` or ``NONFINITE``.
    t_stop : ndarray, shape (n,)
        Where a failed sample stopped [s].
    iterations : int
        Lockstep step attempts (mapped calls).
    n_steps, n_rejected : ndarray of int, shape (n,)
        Accepted and rejected steps per sample.
    n_rhs : int
        RHS evaluations of all samples.
    """

    def __init__(self, funcs, n, nx, nu, P, TOL, max_step, threads):
        self.n, self.nx, self.nu = n, nx, nu
        self.max_step = max_step
        self.tol = TOL
        self.dense = mapped(funcs["dop853_dense"], n, threads)
        self.rhs = mapped(funcs["rhs"], n, threads)
        self.dense.args[5][:] = P.reshape(-1)
        self.dense.args[6][:] = TOL.reshape(-1)
        self.rhs.args[3][:] = P.reshape(-1)
        self.h = None
        self.status = np.zeros(n, dtype=int)
        self.t_stop = np.zeros(n)
        self.iterations = 0
        self.n_steps = np.zeros(n, dtype=int)
        self.n_rejected = np.zeros(n, dtype=int)
        self.n_rhs = 0
        self.PT = DOP853.P  # (8, 7) power-basis matrix of the dense output

    def f(self, t, x, u) -> np.ndarray:
        """The RHS of every sample: ``t`` (n,) [s], ``x`` (n, nx), ``u`` (nu,) -> (n, nx)."""
        r = self.rhs
        r.args[0][:] = t
        r.args[1][:] = x.reshape(-1)
        r.args[2][:] = np.tile(u, self.n)
        r()
        self.n_rhs += self.n
        return r.res[0].reshape(self.n, self.nx).copy()

    def _initial_step(self, t, x, f0, u, t_end):
        """:meth:`StepControl.initial_step` for every sample: (n,) [s]."""
        return StepControl.initial_step(
            lambda t1, x1: self.f(t1, x1, u), t, x, f0, t_end, self.tol[:, 1:], self.tol[:, :1], self.max_step,
            DOP853.order,
        )

    def segment(self, ts: np.ndarray, x0: np.ndarray, u: np.ndarray, out=None) -> np.ndarray:
        """The states of every sample at the times of one smooth segment.

        A diverging sample overflows quietly: ``status`` reports it.

        Parameters
        ----------
        ts : ndarray, shape (m,)
            Increasing times [s]; ``ts[0]`` is the start.
        x0 : ndarray, shape (n, nx)
            States at ``ts[0]``.
        u : ndarray, shape (nu,)
            Input held over the segment (the same for every sample).
        out : ndarray, shape (n, m, nx), optional
            Where to write (NaN filled by the caller); a new NaN array by default.

        Returns
        -------
        ndarray, shape (n, m, nx)
            ``out``; the rows of failed samples from their failure on stay NaN.
        """
        with np.errstate(all="ignore"):
            return self._segment(ts, x0, u, out)

    def _segment(self, ts, x0, u, out):
        ctl = StepControl
        n, nx = self.n, self.nx
        nts = ts.size
        if out is None:
            out = np.full((n, nts, nx), np.nan)
        out[:, 0] = x0
        live = self.status == OK
        x = np.where(live[:, None], x0, 0.0)
        t = np.full(n, ts[0])
        t_end = ts[-1]
        k1 = self.f(t, x, u)
        if self.h is None:
            self.h = self._initial_step(t, x, k1, u, t_end)
        h_mem = self.h
        i_next = np.ones(n, dtype=int)
        rejected = np.zeros(n, dtype=bool)
        d = self.dense
        a_t, a_x, a_k, a_h = d.args[0], d.args[1], d.args[2], d.args[3]
        d.args[4][:] = np.tile(u, n)
        r_x, r_k, r_err, r_F = d.res
        while True:
            active = live & (t < t_end)
            if not active.any():
                break
            self.iterations += 1
            h, clipped = ctl.propose(h_mem, self.max_step, t_end - t)
            under = active & ctl.underflow(h, t)
            if under.any():
                self._fail(under, UNDERFLOW, t)
                live &= ~under
                active &= ~under
            h = np.where(active, h, 0.0)
            a_t[:] = t
            a_x[:] = x.reshape(-1)
            a_k[:] = k1.reshape(-1)
            a_h[:] = h
            d()
            self.n_rhs += (DOP853.N_STAGES + DOP853.N_DENSE_STAGES) * int(active.sum())
            err = r_err.copy()
            bad_err = active & ~np.isfinite(err)
            if bad_err.any():
                bad_x = bad_err & ~np.all(np.isfinite(x), axis=1)
                if bad_x.any():
                    self._fail(bad_x, NONFINITE, t)
                    live &= ~bad_x
                    active &= ~bad_x
                err[bad_err] = np.inf
            acc = active & ctl.accepted(err)
            blown = acc & ~np.all(np.isfinite(r_x.reshape(n, nx)), axis=1)
            if blown.any():  # an accepted step to a non-finite state (simulate: its rows check)
                self._fail(blown, NONFINITE, t)
                live &= ~blown
                acc &= ~blown
                active &= ~blown
            rej = active & ~acc
            # the rules on every sample (whole arrays), then kept where they apply
            h_acc = ctl.after_accept(h_mem, h, err, clipped, rejected)
            h_rej = ctl.after_reject(h, err)
            if acc.any():
                ia = np.flatnonzero(acc)
                t_new = np.where(clipped, t_end, t + h)
                # dense output for requested interior times inside the accepted steps
                j = np.minimum(np.searchsorted(ts, t_new[ia], side="left"), nts - 1)
                cnt = np.maximum(j - i_next[ia], 0)
                if cnt.sum():
                    F = r_F.reshape(n, 7, nx)[ia]  # ca.horzcat(*F) of nx-vectors: column-major
                    PF = np.einsum("mj,sjk->smk", self.PT, F)
                    s = np.repeat(np.arange(ia.size), cnt)
                    first = np.repeat(np.cumsum(cnt) - cnt, cnt)
                    rows = i_next[ia][s] + (np.arange(s.size) - first)
                    smp = ia[s]
                    theta = (ts[rows] - t[smp]) / h[smp]
                    V = np.vander(theta, 8, increasing=True)
                    out[smp, rows] = x[smp] + np.einsum("tm,tmk->tk", V, PF[s])
                    i_next[ia] = np.maximum(i_next[ia], j)
                t[ia] = t_new[ia]
                x[ia] = r_x.reshape(n, nx)[ia]
                k1[ia] = r_k.reshape(n, nx)[ia]
                land = ia[(i_next[ia] < nts) & (ts[np.minimum(i_next[ia], nts - 1)] == t[ia])]
                out[land, i_next[land]] = x[land]
                i_next[land] += 1
                self.n_steps[ia] += 1
                h_mem[ia] = h_acc[ia]
                rejected[ia] = False
            if rej.any():
                self.n_rejected[rej] += 1
                h_mem[rej] = h_rej[rej]
                rejected[rej] = True
        out[live, -1] = x[live]
        self.h = h_mem
        return out

    def _fail(self, mask, code, t):
        self.status[mask] = code
        self.t_stop[mask] = t[mask]
