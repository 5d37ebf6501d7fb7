"""Dormand-Prince 8(5,3): the compiled step, the C segment driver and its Python fallback, and
the one statement of the step-size control rules (:class:`StepControl`).

Three loops apply the same rules: the C driver ``dop853_driver.c`` (one call per window of
requested times, the steps continuing across windows; it keeps its own copy of the constants,
checked against :class:`StepControl` by a test that reads the C source),
:meth:`DOP853._window_python` (the no-compiler fallback) and the batch lockstep
(:mod:`.dop853_batch`), the last two by calling :class:`StepControl`.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import casadi as ca
import numpy as np
from scipy.integrate import DOP853 as _ScipyDOP853

from ..core.compile import FastCall, sx_function
from .base import IntegrationError, Integrator

__all__ = ["DOP853", "StepControl"]

_DP = ctypes.POINTER(ctypes.c_double)


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(_DP)


_DRIVERS: dict[str, object] = {}


def _c_driver(lib_path: str):
    """The C step-control driver of a compiled library (loaded once per process)."""
    f = _DRIVERS.get(lib_path)
    if f is None:
        f = ctypes.CDLL(lib_path).sb_dop853_window
        f.restype = ctypes.c_int
        _DRIVERS[lib_path] = f
    return f


def _norm(v):
    """Euclidean norm of a vector, or of each row of a stack of vectors.

    One vector goes through ``np.linalg.norm(v)`` (a dot product), a stack through its row-wise
    reduction: each is the arithmetic its loop has always used, so the numbers stay the same.
    """
    return np.linalg.norm(v) if v.ndim == 1 else np.linalg.norm(v, axis=-1)


class StepControl:
    """DOP853's step-size control (Hairer's rules, as scipy's ``DOP853``), on numpy values.

    Every rule takes scalars (one run; it returns numpy scalars) or arrays (one entry per
    sample of a batch) and is the C driver's arithmetic (``fmin``/``fmax``: a NaN operand
    yields the other one). A step of
    size ``h`` from ``t`` with ``remaining = t_end - t``:

    1. :meth:`propose`: ``h = fmin(h_mem, max_step)``; within ``LAND_RTOL`` of ``remaining``
       it lands on the end (``clipped``), above ``SPLIT * remaining`` it is cut to that (two
       even steps rather than a step and a sliver).
    2. :meth:`underflow`: ``h <= UNDERFLOW_RTOL * max(1, |t|)`` stops the run.
    3. The compiled step returns the error norm ``err`` (Hairer's mix of the 5th- and
       3rd-order estimates, weighted by ``atol + rtol max(|x|, |x_new|)``); a non-finite
       ``err`` at a finite state counts as ``inf``. :meth:`accepted`: ``err <= 1``.
    4. :meth:`after_accept`: the next step is ``h * factor``, ``factor = fmin(MAX_FACTOR,
       SAFETY err^ERROR_EXPONENT)`` (``MAX_FACTOR`` for ``err = 0``), at most 1 right after a
       rejection; a step clipped to land on the end keeps the larger remembered step.
    5. :meth:`after_reject`: ``h * fmax(MIN_FACTOR, SAFETY err^ERROR_EXPONENT)``.

    The starting step of a run is :meth:`initial_step`.
    """

    SAFETY = 0.9
    MIN_FACTOR = 0.2
    MAX_FACTOR = 10.0
    #: -1 / (q + 1), q = 7 the order of the embedded error estimate
    ERROR_EXPONENT = -1.0 / 8.0
    #: a proposed step within this fraction of the remaining time lands on the segment end
    LAND_RTOL = 1e-12
    #: a step longer than this fraction of the remaining time is cut to it
    SPLIT = 0.5
    #: a step at or below this fraction of max(1 s, |t|) is an underflow
    UNDERFLOW_RTOL = 1e-12
    #: err at or below this is accepted
    ACCEPT_ERR = 1.0

    @classmethod
    def propose(cls, h_mem, max_step, remaining):
        """The step to attempt.

        Parameters
        ----------
        h_mem : float or ndarray
            Remembered step size [s].
        max_step : float
            Largest step [s] (``inf``: none).
        remaining : float or ndarray
            Time to the segment end [s].

        Returns
        -------
        h : float or ndarray
            The step [s].
        clipped : bool or ndarray of bool
            The step lands on the segment end.
        """
        h = np.fmin(h_mem, max_step)
        clipped = h >= remaining * (1.0 - cls.LAND_RTOL)
        h = np.where(clipped, remaining, np.where(h > cls.SPLIT * remaining, cls.SPLIT * remaining, h))
        return h[()], clipped

    @classmethod
    def underflow(cls, h, t):
        """Whether the step ``h`` [s] at time ``t`` [s] is too small to continue."""
        return h <= cls.UNDERFLOW_RTOL * np.fmax(1.0, np.abs(t))

    @classmethod
    def accepted(cls, err):
        """Whether a step with error norm ``err`` (dimensionless) is accepted."""
        return err <= cls.ACCEPT_ERR

    @classmethod
    def after_accept(cls, h_mem, h, err, clipped, rejected):
        """The remembered step after an accepted step.

        Parameters
        ----------
        h_mem : float or ndarray
            Remembered step before this one [s].
        h : float or ndarray
            The step just taken [s].
        err : float or ndarray
            Its error norm (>= 0).
        clipped : bool or ndarray of bool
            It was clipped to land on the segment end.
        rejected : bool or ndarray of bool
            The attempt before it was rejected.

        Returns
        -------
        float or ndarray
            The next step size [s].
        """
        with np.errstate(divide="ignore"):
            grow = np.where(err == 0.0, cls.MAX_FACTOR, np.fmin(cls.MAX_FACTOR, cls.SAFETY * err**cls.ERROR_EXPONENT))
        factor = np.where(rejected, np.fmin(1.0, grow), grow)
        return np.where(clipped, np.fmax(h_mem, h * factor), h * factor)[()]

    @classmethod
    def after_reject(cls, h, err):
        """The step to retry with after a rejected step ``h`` [s] of error norm ``err`` (> 1)."""
        with np.errstate(divide="ignore"):
            return h * np.fmax(cls.MIN_FACTOR, cls.SAFETY * err**cls.ERROR_EXPONENT)

    @staticmethod
    def initial_step(f, t, x, f0, t_end, atol, rtol, max_step, order):
        """Hairer & Wanner's starting step (II.4), as scipy's ``select_initial_step``.

        Parameters
        ----------
        f : callable
            ``f(t, x) -> xdot`` with the shapes of ``t``, ``x`` (one more RHS evaluation).
        t : float or ndarray, shape (n,)
            Start time [s].
        x : ndarray, shape (nx,) or (n, nx)
            State at ``t``.
        f0 : ndarray, shape of ``x``
            Its derivative.
        t_end : float
            Segment end [s].
        atol : ndarray, shape (nx,) or (n, nx)
            Absolute tolerance per component.
        rtol : float or ndarray, shape (n, 1)
            Relative tolerance.
        max_step : float
            Largest step [s].
        order : int
            Order of the method.

        Returns
        -------
        float or ndarray, shape (n,)
            The first step [s].
        """
        nx = x.shape[-1]
        scale = atol + np.abs(x) * rtol
        d0 = _norm(x / scale) / math.sqrt(nx)
        d1 = _norm(f0 / scale) / math.sqrt(nx)
        with np.errstate(divide="ignore", invalid="ignore"):
            h0 = np.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / d1)
        h0 = np.fmin(h0, t_end - t)
        f1 = f(t + h0, x + h0[..., None] * f0)
        d2 = _norm((f1 - f0) / scale) / math.sqrt(nx) / h0
        with np.errstate(divide="ignore"):
            h1 = np.where(
                (d1 <= 1e-15) & (d2 <= 1e-15),
                np.fmax(1e-6, h0 * 1e-3),
                (0.01 / np.fmax(d1, d2)) ** (1.0 / (order + 1)),
            )
        return np.fmin(np.fmin(100 * h0, h1), max_step)


class DOP853(Integrator):
    """Dormand-Prince 8(5,3) with Hairer's error norm and step control (as scipy's DOP853).

    The Butcher table is scipy's (``scipy.integrate.DOP853.A/B/C/E3/E5``): data, not code. The
    step (12 stages + FSAL + error norm) and the step with the 7th-order dense output are
    generated C; the C driver (``dop853_driver.c``) runs the step control over a window of
    requested times in one call (a whole segment, or the windows of
    :meth:`begin_segment`/:meth:`continue_segment`, the steps running on across them), or,
    without a compiler, :meth:`_window_python` does step by step. Both follow
    :class:`StepControl`. The step size is remembered across segments.

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.base.Integrator` (``rtol``, ``atol``, ``max_step`` apply).

    Attributes
    ----------
    n_rejected : int
        Rejected step attempts so far.
    """

    name = "dop853"
    order = 8
    adaptive = True
    #: always a call: inlined, the step and its dense output hold 29 copies of the RHS (16
    #: arrays: 1.7 MB of C, 51 s to compile; called: 0.43 MB, 6 s); called is as fast or faster
    #: (one orbit of iss_lvlh_gravity_gradient: 0.83-0.99x of inlined) and bit-identical
    RHS_INLINE_MAX_OPS = 0
    extra_c = (Path(__file__).with_name("dop853_driver.c")).read_text()
    #: RHS evaluations of a step (12 stages, the 13th is the next step's first: FSAL)
    N_STAGES = 12
    #: extra RHS evaluations of a step with dense output
    N_DENSE_STAGES = 3

    @classmethod
    def build(cls, rhs, nx, nu, npar):
        """``dop853_step`` and ``dop853_dense``: ``(t, x, k1, h, u, p, tol) -> (x_new, k_new,
        err[, F])`` with ``tol = [rtol, atol (nx,)]`` and ``F`` (nx, 7) the dense-output
        coefficients."""
        A, B, C = _ScipyDOP853.A, _ScipyDOP853.B, _ScipyDOP853.C
        E3, E5 = _ScipyDOP853.E3, _ScipyDOP853.E5
        t = ca.SX.sym("t")
        x = ca.SX.sym("x", nx)
        k1 = ca.SX.sym("k1", nx)
        h = ca.SX.sym("h")
        u = ca.SX.sym("u", nu)
        p = ca.SX.sym("p", npar)
        tol = ca.SX.sym("tol", 1 + nx)  # rtol, atol per component
        K = [k1]
        for s in range(1, cls.N_STAGES):
            dy = sum(float(A[s, j]) * K[j] for j in range(s) if A[s, j] != 0.0)
            K.append(rhs(t + float(C[s]) * h, x + h * dy, u, p))
        x_new = x + h * sum(float(B[i]) * K[i] for i in range(cls.N_STAGES) if B[i] != 0.0)
        K.append(rhs(t + h, x_new, u, p))
        scale = tol[1:] + ca.fmax(ca.fabs(x), ca.fabs(x_new)) * tol[0]
        err5 = sum(float(E5[i]) * K[i] for i in range(len(E5)) if E5[i] != 0.0) / scale
        err3 = sum(float(E3[i]) * K[i] for i in range(len(E3)) if E3[i] != 0.0) / scale
        e5 = ca.sumsqr(err5)
        e3 = ca.sumsqr(err3)
        denom = e5 + 0.01 * e3
        err = ca.if_else(denom > 0, ca.fabs(h) * e5 / ca.sqrt(ca.fmax(denom, 1e-300) * nx), 0.0)
        step = sx_function("dop853_step", [t, x, k1, h, u, p, tol], [x_new, K[-1], err])
        # Dense output (Hairer's 7th-order interpolant, scipy's Dop853DenseOutput): three extra
        # stages, then y(t + θh) = x + Σ F-polynomial in θ. Used only for steps that contain an
        # output time, so outputs never cap the step size.
        A_EXTRA, C_EXTRA, D = _ScipyDOP853.A_EXTRA, _ScipyDOP853.C_EXTRA, _ScipyDOP853.D
        Kx = list(K)
        for j, (a_row, c) in enumerate(zip(A_EXTRA, C_EXTRA)):
            s = cls.N_STAGES + 1 + j
            dy = sum(float(a_row[i]) * Kx[i] for i in range(s) if a_row[i] != 0.0)
            Kx.append(rhs(t + float(c) * h, x + h * dy, u, p))
        dx = x_new - x
        F = [dx, h * k1 - dx, 2 * dx - h * (K[-1] + k1)]
        for row in D:
            F.append(h * sum(float(row[i]) * Kx[i] for i in range(len(row)) if row[i] != 0.0))
        dense = sx_function(
            "dop853_dense", [t, x, k1, h, u, p, tol], [x_new, K[-1], err, ca.horzcat(*F)]
        )
        return [step, dense]

    def __init__(self, funcs, p, nx, **kw):
        super().__init__(funcs, p, nx, **kw)
        self._tol = np.concatenate([[self.rtol], self.atol])
        self._step = FastCall.of(funcs["dop853_step"])
        self._dense = FastCall.of(funcs["dop853_dense"])
        for fc in (self._step, self._dense):
            fc.args[5][:] = self.p
            fc.args[6][:] = self._tol
        self.h = None  # step size memory across segments
        self.n_rejected = 0
        self._c = None
        if "__lib__" in funcs and not self.force_python:
            self._c = _c_driver(funcs["__lib__"])
            self._P = np.ascontiguousarray(self.P)
            self._P_ptr = _ptr(self._P)

    def _params_changed(self) -> None:
        super()._params_changed()  # (the C driver reads self.p itself, changed in place)
        for fc in (self._step, self._dense):
            fc.args[5][:] = self.p

    #: use the Python step loop even when the C driver is available (tests compare the two)
    force_python = False

    def _initial_step(self, t, x, f0, u, t_end):
        """:meth:`StepControl.initial_step` of this run (one RHS evaluation, counted)."""
        return StepControl.initial_step(
            lambda t1, x1: self.f(t1, x1, u), t, x, f0, t_end, self.atol, self.rtol, self.max_step, self.order
        )

    # scipy's Dop853DenseOutput evaluates y = x + θ(F0 + (1-θ)(F1 + θ(F2 + ...))) by Horner;
    # the same polynomial in the power basis: y = x + Σ_m θ^m (Σ_j P[m, j] F_j), so a batch of
    # output times costs one Vandermonde matrix and two small matrix products.
    _BASIS = [(1, 0), (1, 1), (2, 1), (2, 2), (3, 2), (3, 3), (4, 3)]  # θ^a (1-θ)^b for F_j
    #: (8, 7) power-basis coefficients of the dense output: θ^m weight of F_j
    P = np.zeros((8, 7))
    for _j, (_a, _b) in enumerate(_BASIS):
        _c = np.polynomial.polynomial.polymul([0.0] * _a + [1.0], np.polynomial.polynomial.polypow([1.0, -1.0], _b))
        P[: _c.size, _j] = _c
    del _j, _a, _b, _c

    @classmethod
    def _interpolate(cls, x0, F, theta):
        """The 7th-order dense output at fractions ``theta`` (k,) of the step: (k, nx)."""
        return x0 + np.vander(theta, 8, increasing=True) @ (cls.P @ F)

    # -- a segment, window by window (the C driver, or the same loop in Python) ---------------
    def begin_segment(self, t0, t_end, x0, u):
        """Start the segment ``[t0, t_end]`` (see :meth:`~.base.Integrator.begin_segment`): the
        step control then runs across :meth:`continue_segment` windows, never landing on a
        window's end, so the numbers are those of one call over all the times."""
        super().begin_segment(t0, t_end, x0, u)
        self._t_end = float(t_end)
        self._u = np.array(u, dtype=float)  # (the caller's u changes at the next segment)
        self._x = np.array(x0, dtype=float)
        self._k1 = self.f(t0, self._x, self._u)
        if self.h is None:
            self.h = self._initial_step(t0, self._x, self._k1, self._u, self._t_end)
        #: [t, t_prev, h_prev]: the time reached, start and size of the last accepted step
        self._st = np.array([float(t0), float(t0), 0.0])
        self._xp = np.zeros(self.nx)  # the last accepted step's start state ...
        self._F = np.zeros(7 * self.nx)  # ... and dense-output coefficients (7, nx)
        for fc in (self._step, self._dense):
            fc.args[4][:] = self._u
        self._c_state = None  # ctypes pointers to these buffers, made at the first C window

    def continue_segment(self, ts):
        ts = np.ascontiguousarray(ts, dtype=float)
        out = np.empty((ts.size, self.nx))
        self._fill(ts, out)
        return out

    def _integrate(self, ts, x0, u):
        out = np.empty((ts.size, self.nx))
        out[0] = x0
        self.begin_segment(ts[0], ts[-1], x0, u)
        try:
            self._fill(np.ascontiguousarray(ts[1:]), out[1:])
        except IntegrationError as e:
            e.partial = out[: 1 + len(e.partial)]
            raise
        return out

    def _fill(self, ts, out):
        """Fill ``out`` (len(ts), nx) with the states at ``ts``, the next window of the segment."""
        status, n, reason = self._window_python(ts, out) if self._c is None else self._window_c(ts, out)
        if status != 0:
            raise IntegrationError(self._st[0], reason, out[:n])

    def _window_c(self, ts, out):
        if self._c_state is None:  # the segment's buffers, the same for all its windows
            self._c_state = (
                [_ptr(a) for a in (self._st, self._x, self._k1, self._xp, self._F, self._u, self.p, self._tol)],
                np.zeros(4, dtype=np.int64),
            )
        (st, x, k1, xp, F, u, p, tol), info = self._c_state
        info[:] = 0
        h = ctypes.c_double(self.h)
        status = self._c(
            ctypes.c_int(self.nx), ctypes.c_int(ts.size), _ptr(ts), ctypes.c_double(self._t_end), st,
            x, k1, xp, F, u, p, tol, ctypes.byref(h), ctypes.c_double(self.max_step), self._P_ptr, _ptr(out),
            info.ctypes.data_as(ctypes.POINTER(ctypes.c_longlong)),
        )
        self.h = h.value
        self.n_rhs += int(info[0])
        self.n_steps += int(info[1])
        self.n_rejected += int(info[2])
        reason = "step size underflow" if status == 1 else "state is not finite (NaN or inf)"
        return status, int(info[3]), reason

    def _window_python(self, ts, out):
        """The C driver's loop step by step in Python (the no-compiler fallback): returns
        (status, rows filled, reason) as the C driver."""
        ctl = StepControl
        st, x, k1, t_end, nx = self._st, self._x, self._k1, self._t_end, self.nx
        t = st[0]
        n = ts.size
        # requested times inside the last accepted step (it ended past the previous window)
        i = int(np.searchsorted(ts, t, side="left"))
        if i:
            out[:i] = self._interpolate(self._xp, self._F.reshape(7, nx), (ts[:i] - st[1]) / st[2])
        if i < n and ts[i] == t:
            out[i] = x
            i += 1
        rejected = False
        while i < n and t < t_end:
            h, clipped = ctl.propose(self.h, self.max_step, t_end - t)
            if ctl.underflow(h, t):
                st[0] = t
                return 1, i, f"step size underflow (h = {h:.3g} s)"
            # requested times inside this step need the interpolant
            dense = ts[i] < t_end and ts[i] < t + h
            s = self._dense if dense else self._step
            a = s.args
            a[0][0] = t
            a[1][:] = x
            a[2][:] = k1
            a[3][0] = h
            s()
            self.n_rhs += self.N_STAGES + (self.N_DENSE_STAGES if dense else 0)
            err = s.res[2][0]
            if not math.isfinite(err):
                if not np.all(np.isfinite(x)):
                    st[0] = t
                    return 2, i, "state is not finite (NaN or inf)"
                err = math.inf
            if ctl.accepted(err):
                t_new = t_end if clipped else t + h
                if dense:
                    self._xp[:] = x
                    self._F[:] = s.res[3].reshape(-1)
                    st[1], st[2] = t, h
                    j = int(np.searchsorted(ts, t_new, side="left"))
                    out[i:j] = self._interpolate(x, self._F.reshape(7, nx), (ts[i:j] - t) / h)
                    i = j
                t = t_new
                x[:] = s.res[0]
                k1[:] = s.res[1]
                if i < n and ts[i] == t:
                    out[i] = x
                    i += 1
                self.n_steps += 1
                self.h = ctl.after_accept(self.h, h, err, clipped, rejected)
                rejected = False
            else:
                self.n_rejected += 1
                self.h = ctl.after_reject(h, err)
                rejected = True
        if t >= t_end:  # the segment end's state (also for a time within rounding of it)
            out[i:] = x
            i = n
        st[0] = t
        return 0, i, ""
