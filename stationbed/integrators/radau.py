"""Radau IIA of order 5 (:class:`RadauIIA`): the implicit fixed-step method for stiff cases,
its stages solved by simplified Newton iterations inside the compiled step."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .fixed_step import FixedStep

__all__ = ["RadauIIA"]


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
    """``M⁻¹ b`` from the packed factor ``a`` of :func:`_lu` (forward, then back substitution)."""
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

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.fixed_step.FixedStep` (``step`` [s] is the fixed step; ``rtol``/``atol`` weight the defect).
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


