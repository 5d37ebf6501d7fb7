"""Fixed-step methods: the shared driver :class:`FixedStep` (compiled single and 64-step calls,
exact landing on requested times, defect check of implicit iterations) and classical
Runge-Kutta 4 (:class:`RK4`), the one fusable integrator."""

from __future__ import annotations

import math
from typing import ClassVar

import casadi as ca
import numpy as np

from ..core.compile import FastCall, sx_function
from .base import IntegrationError, Integrator
from .rk import explicit_rk_step
from .tableau import CLASSICAL_RK4, ButcherTableau

__all__ = ["FixedStep", "RK4"]


class FixedStep(Integrator):
    """Driver for the fixed-step methods (``rk4``, ``lie_rk4``, ``lgvi``, ``radau``).

    A subclass writes ``_step(rhs, t, x, h, u, p, tol) -> (x_new, defect)`` in casadi SX, one
    step of size ``h`` (``tol`` = ``[rtol, atol per component]``). ``defect`` is its inner
    iteration's remaining error (dimensionless, see ``DEFECT_TOL``; 0 for explicit methods).
    The driver compiles that step and a masked ``mapaccum`` of ``MAX_STEPS_PER_CALL`` steps,
    splits each requested interval into ``ceil(dt / step)`` equal steps (so output and
    discontinuity times are hit exactly), and raises :class:`IntegrationError` when the state
    is not finite or the largest defect of a call exceeds ``DEFECT_TOL`` (an implicit
    iteration that did not converge: the step is too large).

    A subclass also sets ``RHS_PER_STEP`` (RHS evaluations one step makes, for ``n_rhs``).

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.base.Integrator`; ``step`` [s] is the nominal step (default
        ``DEFAULT_STEP_S``), ``rtol``/``atol`` weight an implicit method's defect.

    Attributes
    ----------
    h_nominal : float
        The nominal step [s]; an interval ``dt`` takes ``ceil(dt / h_nominal)`` equal steps.
    """

    adaptive = False
    DEFAULT_STEP_S = 1.0
    MAX_STEPS_PER_CALL = 64
    ONE_STEP_CALLS = 8
    DEFECT_TOL: ClassVar[float] = math.inf
    DEFECT_WHAT: ClassVar[str] = ""

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def build(cls, rhs, nx, nu, npar):
        """``<name>_one`` (one step) and ``<name>_multi`` (up to ``MAX_STEPS_PER_CALL`` steps).

        ``<name>_one([t, x, d], [h, u, p, tol]) -> [t + h, x_new, max(d, defect)]``;
        ``<name>_multi(txd0, hup, n_act)`` runs the first ``n_act`` of the steps (the others
        with ``h = 0``, the identity). ``tol = [rtol, atol (nx,)]``.
        """
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

    def _params_changed(self) -> None:
        super()._params_changed()
        tol = np.concatenate([[self.rtol], self.atol])
        for fc in (self._multi, self._one):
            hup = fc.args[1]
            hup[hup.size - self.p.size - tol.size : hup.size - tol.size] = self.p

    def _check(self, t, txd, partial=None):
        x = txd[1:-1]
        if not math.isfinite(x.sum()):
            raise IntegrationError(t, "state is not finite (NaN or inf)", partial)
        if txd[-1] > self.DEFECT_TOL:
            raise IntegrationError(
                t, f"{self.name}: {self.DEFECT_WHAT} did not converge (defect {txd[-1]:.3g}); reduce the step", partial
            )

    def advance(self, t0, t1, x0, u):
        """One period in a few single-step compiled calls (the closed loop's hot path).

        Parameters
        ----------
        t0, t1 : float
            Start and end [s].
        x0 : ndarray, shape (nx,)
            State at ``t0``.
        u : ndarray, shape (nu,)
            Held input.

        Returns
        -------
        ndarray, shape (nx,)
            State at ``t1`` after ``ceil((t1 - t0) / h_nominal)`` equal steps.
        """
        n = max(1, math.ceil((t1 - t0) / self.h_nominal - 1e-9))
        if n > self.ONE_STEP_CALLS:
            return super().advance(t0, t1, x0, u)
        hup = self._one.args[1]
        hup[0] = (t1 - t0) / n
        hup[1 : 1 + u.size] = u
        res = self._single_steps(t0, x0, n)
        self.count_steps(n)
        self._check(t1, res)
        return res[1:-1].copy()

    def _single_steps(self, t0, x0, n):
        """``n`` steps from ``x0`` at ``t0`` through the one-step function (its ``hup`` already
        holds the step, the input, the parameters and the tolerances); its result buffer."""
        txd = self._one.args[0]
        txd[0] = t0
        txd[1:-1] = x0
        txd[-1] = 0.0
        res = self._one.res[0]
        for _ in range(n):
            self._one()
            txd[:] = res
        return res

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
                self.count_steps(k)
            if n:  # the rest one step per call (the block call would run all 64, masked)
                self._one.args[1][:] = hup
                res = self._single_steps(t, x, n)
                self._check(t + n * hup[0], res, out[:i])
                x = res[1:-1].copy()
                self.count_steps(n)
            out[i] = x
        return out


class RK4(FixedStep):
    """Classical 4th-order Runge-Kutta with a fixed step (``simulation.step``, default 1 s).

    Each requested interval is split into ``ceil(dt / step)`` equal steps, so output and
    discontinuity times are hit exactly (the :class:`FixedStep` driver). Explicit: no defect.
    The stages come from the table :data:`~.tableau.CLASSICAL_RK4` through the one stage
    builder :func:`~.rk.explicit_rk_step`. Fusable: one step per control period is composed
    with the controller into one compiled tick.
    """

    name = "rk4"
    TABLEAU: ClassVar[ButcherTableau] = CLASSICAL_RK4
    order = TABLEAU.order
    RHS_PER_STEP = TABLEAU.stages
    fusable = True
    #: inlined up to ~34 rigid arrays: the 4 stages then share the RHS's time- and
    #: parameter-only parts (10-15 % faster than calling it on the shipped rigid scenes) and the
    #: C compiler's time grows only ~2x faster than with calls (16 arrays: 8 s vs 5 s);
    #: every shipped scene (largest: iss_flexible_lvlh_hold, hamel, 5721) stays inlined
    RHS_INLINE_MAX_OPS = 6000

    @classmethod
    def explicit_step(cls, rhs, t, x, h, u, p):
        """One step of the table (see :meth:`Integrator.explicit_step`)."""
        return explicit_rk_step(cls.TABLEAU, rhs, t, x, h, u, p)

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        return cls.explicit_step(rhs, t, x, h, u, p), 0.0
