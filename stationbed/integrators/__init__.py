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
``lie_rk4``     Runge-Kutta-Munthe-Kaas 4 on the attitude (exp maps of unit quaternions), fixed step.
``lgvi``        Lie-group variational integrator (Lee, Leok & McClamroch), 2nd order, symplectic;
                rigid bodies in the momentum form only (refuses others with the reason).
``radau``       Radau IIA order 5, fixed step, simplified Newton in the compiled step (stiff cases).
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

from ..core.compile import FastCall, sx_function
from ..core.rotation import dcm, quat_conj, quat_mult
from ..core.rotation import skew as _skew

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
    extra_c = (Path(__file__).with_name("dop853_driver.c")).read_text()
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
# Fixed-step methods: a shared driver (rk4, and those with an inner iteration)
# ---------------------------------------------------------------------------------------


def _quat_exp(theta):
    """Unit quaternion ``exp((0, θ/2))`` of a rotation vector θ (casadi): ``(cos a, sin a θ̂)``, a = |θ|/2.

    ``sin(a)/a`` is a Taylor polynomial below a² = 1e-4 (truncation < 1e-22) so θ = 0 is exact.
    """
    a2 = ca.sumsqr(theta) / 4
    a = ca.sqrt(a2)
    small = a2 < 1e-4
    sinc = ca.if_else(small, 1 - a2 / 6 + a2 * a2 / 120 - a2 * a2 * a2 / 5040, ca.sin(a) / a)
    cos = ca.if_else(small, 1 - a2 / 2 + a2 * a2 / 24 - a2 * a2 * a2 / 720 + a2**4 / 40320, ca.cos(a))
    return ca.vertcat(cos, 0.5 * sinc * theta)


def _body_rate(q, q_dot):
    """``ω = 2 vec(conj(q) ⊗ q̇) / |q|²``: exact for ``q̇ = ½ q ⊗ (0, ω)`` at any |q| (casadi)."""
    return 2 * quat_mult(quat_conj(q), q_dot)[1:4] / ca.sumsqr(q)


class FixedStep(Integrator):
    """Driver for the fixed-step methods below (``rk4``, ``lie_rk4``, ``lgvi``, ``radau``).

    A subclass writes ``_step(rhs, t, x, h, u, p, tol) -> (x_new, defect)`` in casadi SX, one
    step of size ``h`` (``tol`` = ``[rtol, atol per component]``). ``defect`` is its inner
    iteration's remaining error (dimensionless, see ``DEFECT_TOL``; 0 for explicit methods).
    The driver compiles that step and a masked ``mapaccum`` of ``MAX_STEPS_PER_CALL`` steps,
    splits each requested interval into ``ceil(dt / step)`` equal steps (so output and
    discontinuity times are hit exactly), and raises :class:`IntegrationError` when the state
    is not finite or the largest defect of a call exceeds ``DEFECT_TOL`` (an implicit
    iteration that did not converge: the step is too large).

    A subclass also sets ``RHS_PER_STEP`` (RHS evaluations one step makes, for ``n_rhs``).
    """

    adaptive = False
    DEFAULT_STEP_S = 1.0
    MAX_STEPS_PER_CALL = 64
    ONE_STEP_CALLS = 8
    RHS_PER_STEP: ClassVar[int] = 0
    DEFECT_TOL: ClassVar[float] = math.inf
    DEFECT_WHAT: ClassVar[str] = ""

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def build(cls, rhs, nx, nu, npar):
        t = ca.SX.sym("t")
        x = ca.SX.sym("x", nx)
        d = ca.SX.sym("d")  # the largest defect so far (carried through the mapaccum)
        h = ca.SX.sym("h")
        u = ca.SX.sym("u", nu)
        p = ca.SX.sym("p", npar)
        tol = ca.SX.sym("tol", 1 + nx)
        x_new, defect = cls._step(rhs, t, x, h, u, p, tol)
        one = sx_function(
            f"{cls.name}_one", [ca.vertcat(t, x, d), ca.vertcat(h, u, p, tol)], [ca.vertcat(t + h, x_new, ca.fmax(d, defect))]
        )
        n = cls.MAX_STEPS_PER_CALL
        multi = one.mapaccum(f"{cls.name}_multi_acc", n)
        txd0 = ca.MX.sym("txd0", 2 + nx)
        hup = ca.MX.sym("hup", 1 + nu + npar + 1 + nx)
        n_act = ca.MX.sym("n_act")
        hs = ca.if_else(ca.DM(list(range(n))).T < n_act, hup[0], 0.0)  # h = 0 steps are the identity
        traj = multi(txd0, ca.vertcat(hs, ca.repmat(hup[1:], 1, n)))
        return [one, ca.Function(f"{cls.name}_multi", [txd0, hup, n_act], [traj[:, -1]])]

    def __init__(self, funcs, p, nx, **kw):
        super().__init__(funcs, p, nx, **kw)
        self.h_nominal = float(self.step) if self.step else self.DEFAULT_STEP_S
        self._multi = FastCall.of(funcs[f"{self.name}_multi"])
        self._one = FastCall.of(funcs[f"{self.name}_one"])
        tol = np.concatenate([[self.rtol], self.atol])
        for fc in (self._multi, self._one):
            hup = fc.args[1]
            hup[hup.size - self.p.size - tol.size : hup.size - tol.size] = self.p
            hup[hup.size - tol.size :] = tol

    def _check(self, t, txd, partial=None):
        x = txd[1:-1]
        if not math.isfinite(x.sum()):
            raise IntegrationError(t, "state is not finite (NaN or inf)", partial)
        if txd[-1] > self.DEFECT_TOL:
            raise IntegrationError(
                t, f"{self.name}: {self.DEFECT_WHAT} did not converge (defect {txd[-1]:.3g}); reduce the step", partial
            )

    def advance(self, t0, t1, x0, u):
        """One period in a few single-step compiled calls (the closed loop's hot path)."""
        n = max(1, math.ceil((t1 - t0) / self.h_nominal - 1e-9))
        if n > self.ONE_STEP_CALLS:
            return super().advance(t0, t1, x0, u)
        m = self._one
        txd, hup = m.args
        hup[0] = (t1 - t0) / n
        hup[1 : 1 + u.size] = u
        txd[0] = t0
        txd[1:-1] = x0
        txd[-1] = 0.0
        res = m.res[0]
        for _ in range(n):
            m()
            txd[:] = res
        self.n_rhs += self.RHS_PER_STEP * n
        self.n_steps += n
        self._check(t1, res)
        return res[1:-1].copy()

    def _integrate(self, ts, x0, u):
        out = np.empty((ts.size, self.nx))
        out[0] = x0
        m = self._multi
        txd, hup, n_act = m.args
        hup[1 : 1 + u.size] = u
        x = x0.copy()
        for i in range(1, ts.size):
            dt = ts[i] - ts[i - 1]
            n = max(1, math.ceil(dt / self.h_nominal - 1e-9))
            hup[0] = dt / n
            t = ts[i - 1]
            while n >= self.MAX_STEPS_PER_CALL:  # whole blocks: one call each
                k = self.MAX_STEPS_PER_CALL
                txd[0] = t
                txd[1:-1] = x
                txd[-1] = 0.0
                n_act[0] = k
                m()
                self._check(t, m.res[0], out[:i])
                x = m.res[0][1:-1].copy()
                t += k * hup[0]
                n -= k
                self.n_rhs += self.RHS_PER_STEP * k
                self.n_steps += k
            if n:  # the rest one step per call (the block call would run all 64, masked)
                one = self._one
                o_txd, o_hup = one.args
                o_hup[:] = hup
                o_txd[0] = t
                o_txd[1:-1] = x
                o_txd[-1] = 0.0
                res = one.res[0]
                for _ in range(n):
                    one()
                    o_txd[:] = res
                self._check(t + n * hup[0], res, out[:i])
                x = res[1:-1].copy()
                self.n_rhs += self.RHS_PER_STEP * n
                self.n_steps += n
            out[i] = x
        return out


class RK4(FixedStep):
    """Classical 4th-order Runge-Kutta with a fixed step (``simulation.step``, default 1 s).

    Each requested interval is split into ``ceil(dt / step)`` equal steps, so output and
    discontinuity times are hit exactly (the :class:`FixedStep` driver). Explicit: no defect.
    """

    name = "rk4"
    order = 4
    RHS_PER_STEP = 4

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        k1 = rhs(t, x, u, p)
        k2 = rhs(t + h / 2, x + h / 2 * k1, u, p)
        k3 = rhs(t + h / 2, x + h / 2 * k2, u, p)
        k4 = rhs(t + h, x + h * k3, u, p)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), 0.0


class LieRK4(FixedStep):
    """Runge-Kutta-Munthe-Kaas of order 4 (RKMK4, the classical tableau) on the attitude.

    Generic over formulations: the attitude is the first four states ``q_BN``; at each stage
    the body rate is recovered from the RHS as ``ω = 2 vec(conj(q) ⊗ q̇)`` (exact for
    ``q̇ = ½ q ⊗ (0, ω)``), the attitude is advanced on SO(3) as ``q = q0 ⊗ exp(Θ)`` with
    ``Θ̇ = dexp⁻¹_{-Θ}(ω) ≈ ω + ½ Θ × ω + 1/12 Θ × (Θ × ω)`` (right-trivialised; the series
    truncated after the terms order 4 needs, Hairer-Lubich-Wanner IV.8), and the other states
    by the same tableau. Fixed step (``simulation.step``, default 1 s), four RHS per step.

    ``|q| = 1`` by construction: every stage and step attitude is ``q0 ⊗ exp(...)``, a product
    of unit quaternions. In floating point each product rounds (a random walk of ~1e-16 per
    step); ``NORMALISE`` (default on) divides by ``|q|`` after each step to remove that walk,
    a change at round-off level, never a correction of truncation error.
    """

    name = "lie_rk4"
    order = 4
    RHS_PER_STEP = 4
    NORMALISE: ClassVar[bool] = True

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        A = [[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]]
        B = [1 / 6, 1 / 3, 1 / 3, 1 / 6]
        C = [0.0, 0.5, 0.5, 1.0]
        q0, y0 = x[0:4], x[4:]
        K_th, K_y = [], []
        for i in range(4):
            th = sum((h * a * K_th[j] for j, a in enumerate(A[i]) if a != 0.0), ca.SX.zeros(3))
            y = y0 + sum((h * a * K_y[j] for j, a in enumerate(A[i]) if a != 0.0), ca.SX.zeros(y0.shape[0]))
            q = quat_mult(q0, _quat_exp(th)) if i else q0
            xdot = rhs(t + C[i] * h, ca.vertcat(q, y), u, p)
            w = _body_rate(q, xdot[0:4])
            K_th.append(w + 0.5 * ca.cross(th, w) + ca.cross(th, ca.cross(th, w)) / 12 if i else w)
            K_y.append(xdot[4:])
        th = h * sum(b * k for b, k in zip(B, K_th))
        q1 = quat_mult(q0, _quat_exp(th))
        if cls.NORMALISE:
            q1 = q1 / ca.norm_2(q1)
        y1 = y0 + h * sum(b * k for b, k in zip(B, K_y))
        return ca.vertcat(q1, y1), ca.SX(0.0)


class LGVI(FixedStep):
    """Lie-group variational integrator (Lee, Leok & McClamroch 2005/2007) for a rigid body.

    Discrete update, ``R = C_NB``, ``Π = H_O_B``, moment ``M(t, q)`` (gravity gradient, held
    torque): ``h Π̂' = F J_d - J_d Fᵀ`` with ``Π' = Π_k + h/2 M_k`` and ``J_d = ½ tr(J) E - J``,
    then ``R_{k+1} = R_k F``, ``Π_{k+1} = Fᵀ Π' + h/2 M_{k+1}``. Second order, symplectic,
    momentum-preserving (``H_O_N = R Π`` is invariant to round-off without moment).

    ``F`` is parametrised by a unit quaternion ``f = (√(1 - |v|²), v)``, for which the implicit
    equation reads ``h Π' = 2 f0 J v + 2 v × J v``; it is solved by ``N_NEWTON`` Newton steps
    from ``f = exp(h J⁻¹Π'/2)`` (quadratic convergence: the defect is the last Newton update of v, which
    must be below ``DEFECT_TOL``; it fails when ``h |ω|`` approaches π). ``q_{k+1} = q_k ⊗ f``:
    ``|q| = 1`` by construction; ``NORMALISE`` removes the rounding walk as in :class:`LieRK4`.

    It applies to a rigid body in the momentum form (state ``q_BN, H_O_B``): the inertia
    ``J`` and the moment are read from the RHS (``J⁻¹ = ∂ω/∂H``, ``M = Ḣ + ω × H``), and
    :meth:`build` refuses (``ValueError``) a system where ``ω`` is not ``J⁻¹ H`` with a
    constant ``J`` (articulated arrays, CMG momentum), that has extra states (CMG, driven
    joints), or whose moment depends on the rate state (an ω-state formulation).
    """

    name = "lgvi"
    order = 2
    RHS_PER_STEP = 2
    N_NEWTON = 6
    #: the last Newton update of v (dimensionless, |v| = sin of half the step's rotation)
    DEFECT_TOL = 1e-10
    DEFECT_WHAT = "the Newton iteration for F_k"
    NORMALISE: ClassVar[bool] = True

    @classmethod
    def _rigid_parts(cls, rhs, nx, nu, npar):
        """``(Jinv(p), M(t, q, u, p))`` read from the RHS, or ValueError saying why not."""
        why = "lgvi integrates a rigid body in the momentum form (state q_BN, H_O_B)"
        if nx != 7:
            raise ValueError(f"{why}: this system has {nx - 7} extra states (CMG, driven array joints or elastic modes)")
        t, q, s = ca.SX.sym("t"), ca.SX.sym("q", 4), ca.SX.sym("s", 3)
        u, p = ca.SX.sym("u", nu), ca.SX.sym("p", npar)
        # ω at the identity attitude (so the quaternion algebra folds away structurally)
        q_id = ca.SX(ca.DM([1.0, 0.0, 0.0, 0.0]))
        w = _body_rate(q_id, rhs(t, ca.vertcat(q_id, s), u, p)[0:4])
        Jinv = ca.jacobian(w, s)
        if ca.depends_on(Jinv, ca.vertcat(t, s, u)):
            raise ValueError(f"{why}: the inertia changes with time (articulated arrays) or ω is not linear in H")
        if not ca.depends_on(Jinv, p):
            raise ValueError(f"{why}: the rate state is ω itself (an ω-state formulation; use 'momentum')")
        if ca.depends_on(ca.substitute(w, s, ca.SX.zeros(3)), ca.vertcat(t, u, p)):
            raise ValueError(f"{why}: ω is not J⁻¹ H (relative momentum of arrays or CMG)")
        # Ḣ = M - ω × H: the moment is Ḣ at H = 0 (a function of t, q and the held torque)
        M = rhs(t, ca.vertcat(q, ca.SX.zeros(3)), u, p)[4:7]
        return ca.Function("lgvi_parts", [p], [Jinv]), ca.Function("lgvi_moment", [t, q, u, p], [M])

    @classmethod
    def build(cls, rhs, nx, nu, npar):
        cls._rigid_parts(rhs, nx, nu, npar)  # refuse early with the reason
        return super().build(rhs, nx, nu, npar)

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        f_Jinv, f_M = cls._rigid_parts(rhs, x.shape[0], u.shape[0], p.shape[0])
        Jinv = f_Jinv(p)
        J = ca.inv(Jinv)
        J = 0.5 * (J + J.T)
        q, Pi = x[0:4], x[4:7]
        Pi_p = Pi + h / 2 * f_M(t, q, u, p)
        v = _quat_exp(h * ca.mtimes(Jinv, Pi_p))[1:4]  # start: F = exp(h ω̂), exact for a sphere
        dv = ca.SX.zeros(3)
        for _ in range(cls.N_NEWTON):
            f0 = ca.sqrt(1 - ca.sumsqr(v))
            Jv = ca.mtimes(J, v)
            g = 2 * f0 * Jv + 2 * ca.cross(v, Jv) - h * Pi_p
            # ∂g/∂v: ∂f0/∂v = -vᵀ/f0, ∂(v × Jv)/∂v = v̂ J - (Jv)^
            dg = 2 * f0 * J - 2 * ca.mtimes(Jv, v.T) / f0 + 2 * (ca.mtimes(_skew(v), J) - _skew(Jv))
            dv = -ca.solve(dg, g)
            v = v + dv
        f = ca.vertcat(ca.sqrt(1 - ca.sumsqr(v)), v)
        q1 = quat_mult(q, f)
        if cls.NORMALISE:
            q1 = q1 / ca.norm_2(q1)
        F = dcm(f).T  # the active rotation of f (R_{k+1} = R_k F)
        Pi1 = ca.mtimes(F.T, Pi_p) + h / 2 * f_M(t + h, q1, u, p)
        return ca.vertcat(q1, Pi1), ca.norm_inf(dv)


def _lu(M):
    """No-pivot Doolittle LU of a casadi matrix, as a list of rows of scalars (L and U packed).

    For the Radau iteration matrices ``λ E - h J`` (Re λ > 0): the matrix need only be
    approximately factored (simplified Newton converges to the same solution), and constant
    zeros of the Jacobian stay zeros (casadi folds them), so the factor is cheap.
    """
    n = M.shape[0]
    a = [[M[i, j] for j in range(n)] for i in range(n)]
    for k in range(n):
        for i in range(k + 1, n):
            a[i][k] = a[i][k] / a[k][k]
            for j in range(k + 1, n):
                a[i][j] = a[i][j] - a[i][k] * a[k][j]
    return a


def _lu_solve(a, b):
    n = len(a)
    y = [b[i] for i in range(n)]
    for i in range(n):
        for j in range(i):
            y[i] = y[i] - a[i][j] * y[j]
    for i in reversed(range(n)):
        for j in range(i + 1, n):
            y[i] = y[i] - a[i][j] * y[j]
        y[i] = y[i] / a[i][i]
    return ca.vertcat(*y)


class RadauIIA(FixedStep):
    """Radau IIA, 3 stages, order 5 (stage order 3; L-stable, stiffly accurate), fixed step.

    The stage equations ``Z = h (A ⊗ E) F(x0 + Z)`` are solved by ``N_NEWTON`` simplified
    Newton iterations from ``Z = 0`` with the iteration matrix ``E - h A ⊗ J``, ``J`` the casadi
    Jacobian of the RHS at ``(t0, x0)``, all inside the compiled step. As in Hairer & Wanner's
    RADAU5 (IV.8), ``A⁻¹`` is brought to real block-diagonal form ``T⁻¹ A⁻¹ T =
    diag(γ, [[α, β], [-β, α]])``, so each step factors one real (``γ E - h J``) and one complex
    (``(α - iβ) E - h J``, as a 2nx real block) matrix of the state's size instead of one of
    three times that size. The defect is the last Newton update weighted by
    ``atol + rtol |x0|`` (the run's tolerances): above 1 the step fails ("did not converge;
    reduce the step"). The simplified iteration contracts by ~(h ‖∂J/∂x‖ |f|)² per iteration on
    smooth problems, so steps with ``h |ω|`` beyond ~0.5 rad need more iterations than it makes.
    ``RHS_PER_STEP`` counts 3 RHS per iteration plus the Jacobian as ``nx`` more.

    The quaternion is normalised after each step (a documented projection: the method itself
    does not keep |q| = 1; the projection removes the norm part of the step's truncation error).
    """

    name = "radau"
    order = 5
    N_NEWTON = 7
    RHS_PER_STEP = 3 * N_NEWTON  # + nx for the Jacobian, added per instance
    DEFECT_TOL = 1.0
    DEFECT_WHAT = "the simplified Newton iteration"
    _S6 = math.sqrt(6.0)
    A = np.array(
        [
            [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
            [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
            [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
        ]
    )
    C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1.0])

    @classmethod
    def _transform(cls):
        """``(T, Tinv_Ainv, γ, α, β)`` with ``T⁻¹ A⁻¹ T = [[γ,0,0],[0,α,β],[0,-β,α]]``."""
        Ainv = np.linalg.inv(cls.A)
        lam, V = np.linalg.eig(Ainv)
        r = int(np.argmin(np.abs(lam.imag)))
        c = int(np.argmax(lam.imag))  # α + iβ, β > 0
        T = np.column_stack([V[:, r].real, V[:, c].real, V[:, c].imag])
        Lam = np.linalg.solve(T, Ainv @ T)
        gamma, alpha, beta = Lam[0, 0], Lam[1, 1], Lam[1, 2]
        assert np.allclose(Lam, [[gamma, 0, 0], [0, alpha, beta], [0, -beta, alpha]], atol=1e-12)
        return T, np.linalg.solve(T, Ainv), gamma, alpha, beta

    def __init__(self, funcs, p, nx, **kw):
        super().__init__(funcs, p, nx, **kw)
        self.RHS_PER_STEP = 3 * self.N_NEWTON + nx

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        n = x.shape[0]
        A, C = cls.A, cls.C
        T, TiAi, gamma, alpha, beta = cls._transform()
        hJ = h * ca.jacobian(rhs(t, x, u, p), x)
        E = ca.SX.eye(n)
        # (Λ ⊗ E - h E ⊗ J) W = -(T⁻¹A⁻¹ ⊗ E) res,  ΔZ = (T ⊗ E) W   (multiplied through by h)
        lu1 = _lu(gamma * E - hJ)
        # complex block: ((α - iβ)E - hJ)(W2 + i W3) = r2 + i r3, as [[Re, -Im], [Im, Re]]
        lu2 = _lu(ca.vertcat(ca.horzcat(alpha * E - hJ, beta * E), ca.horzcat(-beta * E, alpha * E - hJ)))
        Z = [ca.SX.zeros(n) for _ in range(3)]
        dZ = Z
        for _ in range(cls.N_NEWTON):
            Fz = [rhs(t + float(C[i]) * h, x + Z[i], u, p) for i in range(3)]
            res = [Z[i] - h * sum(float(A[i, j]) * Fz[j] for j in range(3)) for i in range(3)]
            r = [-sum(float(TiAi[i, j]) * res[j] for j in range(3)) for i in range(3)]
            W1 = _lu_solve(lu1, r[0])
            W23 = _lu_solve(lu2, ca.vertcat(r[1], r[2]))
            W = [W1, W23[0:n], W23[n:]]
            dZ = [sum(float(T[i, j]) * W[j] for j in range(3)) for i in range(3)]
            Z = [Z[i] + dZ[i] for i in range(3)]
        x1 = x + Z[2]  # stiffly accurate: b = last row of A
        x1 = ca.vertcat(x1[0:4] / ca.norm_2(x1[0:4]), x1[4:])
        w = tol[1:] + tol[0] * ca.fabs(x)
        defect = ca.mmax(ca.vertcat(*[ca.fabs(d) / w for d in dZ]))
        return x1, defect


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
        LieRK4,
        LGVI,
        RadauIIA,
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
