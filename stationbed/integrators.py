"""Steppers behind one interface (DESIGN §7, modelled on scipy's ``OdeSolver``).

An :class:`Integrator` advances a state across one *smooth segment*: an interval over which the
held input ``u`` is constant and the scene has no discontinuity (the simulation loop splits
the run at torque-window edges and control ticks, so discontinuities are integrated across
exactly, by stopping at them). Within a segment it must land exactly on each requested time.

Registered integrators
----------------------
``dop853``      Dormand-Prince 8(5,3), error-controlled (rtol/atol), dense output; the step
                (12 stages + FSAL + error norm) is generated C and a C driver runs the step
                control, one call per segment (a Python loop when no compiler is present).
``rk4``         Classical Runge-Kutta 4, fixed step (``simulation.step``, default 1 s), up to
                64 steps per compiled call.
``scipy_dop853``, ``scipy_rk45``, ``scipy_radau``, ``scipy_bdf``, ``scipy_lsoda``
                scipy ``solve_ivp`` on the compiled right-hand side: reference paths.

Time-dependent terms (array profiles, orbit) are evaluated at the stage times.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path
from typing import ClassVar

import casadi as ca
import numpy as np
from scipy.integrate import DOP853 as _ScipyDOP853
from scipy.integrate import solve_ivp

from ._compile import FastCall, sx_function

__all__ = ["Integrator", "IntegrationError", "INTEGRATORS", "get_integrator"]

_DP = ctypes.POINTER(ctypes.c_double)


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(_DP)


_DRIVERS: dict[str, object] = {}


def _c_driver(lib_path: str):
    """The C step-control driver of a compiled library (loaded once per process)."""
    f = _DRIVERS.get(lib_path)
    if f is None:
        f = ctypes.CDLL(lib_path).sb_dop853_segment
        f.restype = ctypes.c_int
        _DRIVERS[lib_path] = f
    return f


class IntegrationError(RuntimeError):
    """The integrator could not continue; ``t`` is where it stopped."""

    def __init__(self, t: float, reason: str, partial: np.ndarray | None = None):
        super().__init__(f"integration stopped at t = {t:.6g} s: {reason}")
        self.t = t
        self.reason = reason
        self.partial = partial  # rows already integrated in the current segment


class Integrator:
    """Base class. Rules for implementers:

    1. Set ``name``, ``order`` and ``adaptive``.
    2. ``build(rhs, nx, nu, npar)`` (classmethod) returns the casadi Functions the integrator
       wants compiled (they are compiled once per model structure together with the RHS);
       ``rhs`` is ``f(t, x, u, p) -> xdot``.
    3. ``_integrate(ts, x0, u)`` returns the states at every time of ``ts`` (``ts[0]`` is the
       start, ``x0`` the state there) as an array ``(len(ts), nx)``; it adds the RHS
       evaluations it made to ``self.n_rhs`` and accepted steps to ``self.n_steps``.
    4. It may keep memory between calls (step size) - segments follow each other in time.
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 0
    adaptive: ClassVar[bool] = False

    def __init__(self, funcs: dict, p: np.ndarray, nx: int, *, rtol=1e-9, atol=1e-12, step=None, max_step=None):
        self.funcs = funcs
        self.p = np.asarray(p, dtype=float)
        self.nx = nx
        self.rtol = float(rtol)
        # atol: a scalar, or one value per state component (simulate passes the scaled vector)
        self.atol = np.broadcast_to(np.asarray(atol, dtype=float), (nx,)).copy()
        self.step = step
        self.max_step = math.inf if max_step is None else float(max_step)
        self.n_rhs = 0
        self.n_steps = 0
        self._rhs = FastCall.of(funcs["rhs"])
        self._rhs.args[3][:] = self.p

    #: C source appended to the generated code (a driver calling the built functions by name)
    extra_c: ClassVar[str] = ""

    @classmethod
    def build(cls, rhs: ca.Function, nx: int, nu: int, npar: int) -> list[ca.Function]:
        return []

    def f(self, t, x, u) -> np.ndarray:
        """One right-hand-side evaluation (counted)."""
        a = self._rhs.args
        a[0][0] = t
        a[1][:] = x
        a[2][:] = u
        self._rhs()
        self.n_rhs += 1
        return self._rhs.res[0].copy()

    def integrate(self, ts, x0, u) -> np.ndarray:
        ts = np.asarray(ts, dtype=float)
        if ts.ndim != 1 or ts.size < 2 or np.any(np.diff(ts) <= 0):
            raise ValueError("ts must be an increasing sequence of at least two times")
        x0 = np.asarray(x0, dtype=float)
        if not np.all(np.isfinite(x0)):
            raise IntegrationError(ts[0], "state is not finite (NaN or inf)")
        return self._integrate(ts, x0, np.asarray(u, dtype=float))

    def advance(self, t0: float, t1: float, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The state at ``t1`` from ``x0`` at ``t0`` with held input ``u`` (one control period)."""
        if not np.all(np.isfinite(x0)):
            raise IntegrationError(t0, "state is not finite (NaN or inf)")
        return self._integrate(np.array([t0, t1]), x0, u)[-1]

    def _integrate(self, ts, x0, u):  # pragma: no cover - abstract
        raise NotImplementedError


# ---------------------------------------------------------------------------------------
# Dormand-Prince 8(5,3)
# ---------------------------------------------------------------------------------------


class DOP853(Integrator):
    """Dormand-Prince 8(5,3) with Hairer's error norm and step control (as scipy's DOP853).

    The Butcher table is scipy's (``scipy.integrate.DOP853.A/B/C/E3/E5``): data, not code.
    """

    name = "dop853"
    order = 8
    adaptive = True
    extra_c = (Path(__file__).with_name("_dop853_driver.c")).read_text()
    SAFETY = 0.9
    MIN_FACTOR = 0.2
    MAX_FACTOR = 10.0
    N_STAGES = 12

    @classmethod
    def build(cls, rhs, nx, nu, npar):
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

    #: use the Python step loop even when the C driver is available (tests compare the two)
    force_python = False

    def _initial_step(self, t, x, f0, u, t_end):
        """Hairer & Wanner's starting step (II.4), as in scipy's ``select_initial_step``."""
        scale = self.atol + np.abs(x) * self.rtol
        d0 = np.linalg.norm(x / scale) / math.sqrt(self.nx)
        d1 = np.linalg.norm(f0 / scale) / math.sqrt(self.nx)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, t_end - t)
        f1 = self.f(t + h0, x + h0 * f0, u)
        d2 = np.linalg.norm((f1 - f0) / scale) / math.sqrt(self.nx) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / (self.order + 1))
        return min(100 * h0, h1, self.max_step)

    # scipy's Dop853DenseOutput evaluates y = x + θ(F0 + (1-θ)(F1 + θ(F2 + ...))) by Horner;
    # the same polynomial in the power basis: y = x + Σ_m θ^m (Σ_j P[m, j] F_j), so a batch of
    # output times costs one Vandermonde matrix and two small matrix products.
    _BASIS = [(1, 0), (1, 1), (2, 1), (2, 2), (3, 2), (3, 3), (4, 3)]  # θ^a (1-θ)^b for F_j
    P = np.zeros((8, 7))
    for _j, (_a, _b) in enumerate(_BASIS):
        _c = np.polynomial.polynomial.polymul([0.0] * _a + [1.0], np.polynomial.polynomial.polypow([1.0, -1.0], _b))
        P[: _c.size, _j] = _c
    del _j, _a, _b, _c

    @classmethod
    def _interpolate(cls, x0, F, theta):
        """The 7th-order dense output at fractions ``theta`` (k,) of the step."""
        return x0 + np.vander(theta, 8, increasing=True) @ (cls.P @ F)

    def _integrate(self, ts, x0, u):
        if self._c is None:
            return self._integrate_python(ts, x0, u)
        ts = np.ascontiguousarray(ts, dtype=float)
        out = np.empty((ts.size, self.nx))
        x = np.array(x0, dtype=float)
        k1 = self.f(ts[0], x, u)
        if self.h is None:
            self.h = self._initial_step(ts[0], x, k1, u, ts[-1])
        u = np.ascontiguousarray(u, dtype=float)
        h = ctypes.c_double(self.h)
        t_stop = ctypes.c_double(0.0)
        info = np.zeros(4, dtype=np.int64)
        status = self._c(
            ctypes.c_int(self.nx), ctypes.c_int(ts.size), _ptr(ts), _ptr(x), _ptr(k1), _ptr(u), _ptr(self.p),
            _ptr(self._tol), ctypes.byref(h), ctypes.c_double(self.max_step), _ptr(self._P), _ptr(out),
            info.ctypes.data_as(ctypes.POINTER(ctypes.c_longlong)), ctypes.byref(t_stop),
        )
        self.h = h.value
        self.n_rhs += int(info[0])
        self.n_steps += int(info[1])
        self.n_rejected += int(info[2])
        if status != 0:
            reason = "step size underflow" if status == 1 else "state is not finite (NaN or inf)"
            raise IntegrationError(t_stop.value, reason, out[: int(info[3])])
        return out

    def _integrate_python(self, ts, x0, u):
        """The same algorithm as the C driver, step by step in Python (no-compiler fallback)."""
        out = np.empty((ts.size, self.nx))
        out[0] = x0
        x = x0.copy()
        t = ts[0]
        t_end = ts[-1]
        k1 = self.f(t, x, u)
        if self.h is None:
            self.h = self._initial_step(t, x, k1, u, t_end)
        for fc in (self._step, self._dense):
            fc.args[4][:] = u
        i = 1  # next requested time
        rejected = False
        while t < t_end:
            remaining = t_end - t
            h = min(self.h, self.max_step)
            clipped = h >= remaining * (1.0 - 1e-12)
            if clipped:
                h = remaining
            elif h > 0.5 * remaining:
                h = 0.5 * remaining  # two even steps rather than one step and a sliver
            if h <= 1e-12 * max(1.0, abs(t)):
                raise IntegrationError(t, f"step size underflow (h = {h:.3g} s)", out[:i])
            # interior requested times inside this step need the interpolant
            dense = (i < ts.size - 1) and ts[i] < t + h
            s = self._dense if dense else self._step
            a = s.args
            a[0][0] = t
            a[1][:] = x
            a[2][:] = k1
            a[3][0] = h
            s()
            self.n_rhs += self.N_STAGES + (3 if dense else 0)
            err = s.res[2][0]
            if not math.isfinite(err):
                if not np.all(np.isfinite(x)):
                    raise IntegrationError(t, "state is not finite (NaN or inf)", out[:i])
                err = math.inf
            if err <= 1.0:
                t_new = t_end if clipped else t + h
                if dense:
                    j = min(int(np.searchsorted(ts, t_new, side="left")), ts.size - 1)
                    F = s.res[3].reshape(7, self.nx)
                    out[i:j] = self._interpolate(x, F, (ts[i:j] - t) / h)
                    i = j
                t = t_new
                x[:] = s.res[0]
                k1[:] = s.res[1]
                if i < ts.size and ts[i] == t:
                    out[i] = x
                    i += 1
                self.n_steps += 1
                factor = self.MAX_FACTOR if err == 0.0 else min(self.MAX_FACTOR, self.SAFETY * err ** (-1.0 / 8.0))
                if rejected:
                    factor = min(1.0, factor)
                self.h = max(self.h, h * factor) if clipped else h * factor
                rejected = False
            else:
                self.n_rejected += 1
                self.h = h * max(self.MIN_FACTOR, self.SAFETY * err ** (-1.0 / 8.0))
                rejected = True
        out[-1] = x
        return out


# ---------------------------------------------------------------------------------------
# Classical RK4, fixed step
# ---------------------------------------------------------------------------------------


class RK4(Integrator):
    """Classical 4th-order Runge-Kutta with a fixed step (``simulation.step``, default 1 s).

    Each requested interval is split into ``ceil(dt / step)`` equal steps, so output and
    discontinuity times are hit exactly; the steps of one interval run in one compiled call.
    """

    name = "rk4"
    order = 4
    adaptive = False
    DEFAULT_STEP_S = 1.0
    MAX_STEPS_PER_CALL = 64

    @classmethod
    def build(cls, rhs, nx, nu, npar):
        t = ca.SX.sym("t")
        x = ca.SX.sym("x", nx)
        h = ca.SX.sym("h")
        u = ca.SX.sym("u", nu)
        p = ca.SX.sym("p", npar)
        k1 = rhs(t, x, u, p)
        k2 = rhs(t + h / 2, x + h / 2 * k1, u, p)
        k3 = rhs(t + h / 2, x + h / 2 * k2, u, p)
        k4 = rhs(t + h, x + h * k3, u, p)
        x_new = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        one = sx_function("rk4_one", [ca.vertcat(t, x), ca.vertcat(h, u, p)], [ca.vertcat(t + h, x_new)])
        # n steps in one call: mapaccum over the (t, x) carry; n_active masks the unused tail
        n = cls.MAX_STEPS_PER_CALL
        multi = one.mapaccum("rk4_multi_acc", n)
        # MX outer function: the generated C is a loop over one compiled step, not n copies
        tx0 = ca.MX.sym("tx0", 1 + nx)
        hup = ca.MX.sym("hup", 1 + nu + npar)
        n_act = ca.MX.sym("n_act")
        hs = ca.if_else(ca.DM(list(range(n))).T < n_act, hup[0], 0.0)
        rest = ca.repmat(hup[1:], 1, n)
        traj = multi(tx0, ca.vertcat(hs, rest))
        return [one, ca.Function("rk4_multi", [tx0, hup, n_act], [traj[:, -1]])]

    def __init__(self, funcs, p, nx, **kw):
        super().__init__(funcs, p, nx, **kw)
        self.h_nominal = float(self.step) if self.step else self.DEFAULT_STEP_S
        self._multi = FastCall.of(funcs["rk4_multi"])
        self._one = FastCall.of(funcs["rk4_one"])
        for fc in (self._multi, self._one):
            hup = fc.args[1]
            hup[hup.size - self.p.size :] = self.p

    #: up to this many steps per period run as single-step calls (the multi-step call always
    #: evaluates all MAX_STEPS_PER_CALL steps, masked, so it pays only for long intervals)
    ONE_STEP_CALLS = 8

    def advance(self, t0, t1, x0, u):
        """One period in (usually) one compiled call: the closed loop's hot path."""
        n = max(1, math.ceil((t1 - t0) / self.h_nominal - 1e-9))
        if n > self.ONE_STEP_CALLS:
            return super().advance(t0, t1, x0, u)
        m = self._one
        tx, hup = m.args
        h = (t1 - t0) / n
        hup[0] = h
        hup[1 : 1 + u.size] = u
        tx[0] = t0
        tx[1:] = x0
        res = m.res[0]
        for i in range(n):
            m()
            tx[:] = res
        tx[0] = t1
        self.n_rhs += 4 * n
        self.n_steps += n
        x = res[1:]
        if not math.isfinite(x.sum()):
            raise IntegrationError(t1, "state is not finite (NaN or inf)")
        return x.copy()

    def _integrate(self, ts, x0, u):
        out = np.empty((ts.size, self.nx))
        out[0] = x0
        m = self._multi
        tx, hup, n_act = m.args
        hup[1 : 1 + u.size] = u
        hup[1 + u.size :] = self.p
        x = x0.copy()
        for i in range(1, ts.size):
            dt = ts[i] - ts[i - 1]
            n = max(1, math.ceil(dt / self.h_nominal - 1e-9))
            h = dt / n
            hup[0] = h
            t = ts[i - 1]
            while n > 0:
                k = min(n, self.MAX_STEPS_PER_CALL)
                tx[0] = t
                tx[1:] = x
                n_act[0] = k
                m()
                x = m.res[0][1:].copy()
                t += k * h
                n -= k
                self.n_rhs += 4 * k
                self.n_steps += k
            if not np.all(np.isfinite(x)):
                raise IntegrationError(ts[i], "state is not finite (NaN or inf)", out[:i])
            out[i] = x
        return out


# ---------------------------------------------------------------------------------------
# scipy reference paths
# ---------------------------------------------------------------------------------------


class ScipyIVP(Integrator):
    """scipy ``solve_ivp`` on the compiled RHS (a reference path, not the fast one)."""

    name = "scipy_dop853"
    method = "DOP853"
    order = 8
    adaptive = True

    def _integrate(self, ts, x0, u):
        def fun(t, x):
            return self.f(t, x, u)

        kw = {}
        if math.isfinite(self.max_step):
            kw["max_step"] = self.max_step
        sol = solve_ivp(fun, (ts[0], ts[-1]), x0, method=self.method, t_eval=ts, rtol=self.rtol, atol=self.atol, **kw)
        if sol.status != 0:
            t_fail = float(sol.t[-1]) if sol.t.size else float(ts[0])
            raise IntegrationError(t_fail, f"solve_ivp({self.method}): {sol.message}", sol.y.T)
        self.n_steps += max(0, sol.t.size - 1)
        return sol.y.T.copy()


def _scipy(method: str, order: int) -> type[ScipyIVP]:
    return type(f"Scipy{method}", (ScipyIVP,), {"name": f"scipy_{method.lower()}", "method": method, "order": order})


INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls
    for cls in (
        DOP853,
        RK4,
        ScipyIVP,
        _scipy("RK45", 5),
        _scipy("Radau", 5),
        _scipy("BDF", 1),
        _scipy("LSODA", 1),
    )
}


def get_integrator(name_or_cls) -> type[Integrator]:
    """The integrator class for a registry name or an :class:`Integrator` subclass."""
    if isinstance(name_or_cls, type) and issubclass(name_or_cls, Integrator):
        return name_or_cls
    try:
        return INTEGRATORS[name_or_cls]
    except (KeyError, TypeError):
        raise ValueError(f"unknown integrator {name_or_cls!r}; valid: {', '.join(sorted(INTEGRATORS))}") from None
