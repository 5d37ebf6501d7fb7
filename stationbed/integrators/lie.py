"""Integrators on the attitude's Lie group: :class:`LieRK4` (Runge-Kutta-Munthe-Kaas 4) and
:class:`LGVI` (the Lie-group variational integrator), with their quaternion helpers."""

from __future__ import annotations

from typing import ClassVar

import casadi as ca

from ..core.rotation import dcm, quat_conj, quat_mult
from ..core.rotation import skew as _skew
from .fixed_step import RK4, FixedStep
from .tableau import CLASSICAL_RK4, ButcherTableau

__all__ = ["LieRK4", "LGVI"]


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


class LieRK4(FixedStep):
    """Runge-Kutta-Munthe-Kaas of order 4 (RKMK4, the classical tableau) on the attitude.

    Generic over formulations: the attitude is the first four states ``q_BN``; at each stage
    the body rate is recovered from the RHS as ``ω = 2 vec(conj(q) ⊗ q̇)`` (exact for
    ``q̇ = ½ q ⊗ (0, ω)``), the attitude is advanced on SO(3) as ``q = q0 ⊗ exp(Θ)`` with
    ``Θ̇ = dexp⁻¹_{-Θ}(ω) ≈ ω + ½ Θ × ω + 1/12 Θ × (Θ × ω)`` (right-trivialised; the series
    truncated after the terms order 4 needs, Hairer-Lubich-Wanner IV.8), and the other states
    by the same tableau (``TABLEAU``, read as data: the Θ stages are not those of the explicit
    stage builder). Fixed step (``simulation.step``, default 1 s), four RHS per step.

    ``|q| = 1`` by construction: every stage and step attitude is ``q0 ⊗ exp(...)``, a product
    of unit quaternions. In floating point each product rounds (a random walk of ~1e-16 per
    step); ``NORMALISE`` (default on) divides by ``|q|`` after each step to remove that walk,
    a change at round-off level, never a correction of truncation error.

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.fixed_step.FixedStep` (``step`` [s] is the fixed step).
    """

    name = "lie_rk4"
    TABLEAU: ClassVar[ButcherTableau] = CLASSICAL_RK4
    order = TABLEAU.order
    RHS_PER_STEP = TABLEAU.stages
    RHS_INLINE_MAX_OPS = RK4.RHS_INLINE_MAX_OPS  # (the same stages: see RK4)
    NORMALISE: ClassVar[bool] = True

    @classmethod
    def _step(cls, rhs, t, x, h, u, p, tol):
        tab = cls.TABLEAU
        A, B, C = tab.a_float(), tab.b_float(), tab.c_float()
        q0, y0 = x[0:4], x[4:]
        K_th, K_y = [], []
        for i in range(tab.stages):
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

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.fixed_step.FixedStep` (``step`` [s] is the fixed step).
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
        """The :class:`~.fixed_step.FixedStep` functions; ``ValueError`` (with the reason) for a
        system that is not a rigid body in the momentum form."""
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


