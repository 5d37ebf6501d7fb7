"""Flexible arrays: modal integrals (Quinn 1990 Eq. 22–24) and their coupling to the station.

An appendage may declare elastic modes. The elastic displacement of a point of the array, in
its own frame P, is ``u(a) = Φ(a) η`` (Quinn Eq. 22), ``a`` the point's position relative to
the array's mass centre. The model needs only the integrals of Quinn Eq. 24, per mode k
(P components):

- ``Φ̄_k = ∫ Φ_k dm``            translational participation [kg]          (Eq. 24a)
- ``Ĥ_k = ∫ a × Φ_k dm``         rotational participation about the array's mass centre [kg m]
  (Eq. 24b, his ``∫ ãᵀ... Φ``)
- ``M_k = ∫ Φ_kᵀ Φ_k dm``        modal mass [kg]; normal modes, so ``M_A`` is diagonal (Eq. 24e)
- ``K_k = ω_k² M_k``             modal stiffness [N/m], ``ω_k`` the clamped frequency (Eq. 29a)
- ``C_k = 2 ζ_k ω_k M_k``        modal damping (a Rayleigh dissipation ``½ η̇ᵀ C η̇``)

With the array's mass centre at ``ρ`` from the composite mass centre O (B components) and
``C_BP`` its orientation, the kinetic energy of the elastic motion, to first order in the
elastic coordinates (the *linear hybrid-coordinate* model, see docs/design.md), is

``T_e = ½ η̇ᵀ M_eff η̇ + η̇ᵀ (Δᵀ ω + Dᵀ ω_p)``,  ``D = C_BP Ĥ``,  ``Δ = D + ρ̃ C_BP Φ̄``,

``M_eff = diag(M) - Uᵀ U / m``, ``U = [C_BP Φ̄]`` over all arrays (``ω_p`` the array's rate
relative to B, in B; the ``Uᵀ U / m`` term is the hub's recoil, see :class:`Modes`). The strain
energy is ``½ ηᵀ K η``.

The deflection also changes the array's inertia, linearly in η (the first-order, deformation-
dependent inertia; see :meth:`Modes.first_order_kinetic`): with ``W = ω + ω_p`` the array's rate,
``δJ = C_BP (Σ_k η_k ∂J/∂η_k) C_PB`` and ``u = C_BP Φ̄ η`` (its mass centre's displacement
times its mass), T gains ``T₁ = ½ Wᵀ δJ W + (ω × ρ)·(W × u)``; the ``η η̇`` and ``η²`` terms
stay out (second order).

The beam shapes (:func:`~stationbed.core.beam.beam_mode`) live in :mod:`stationbed.core.beam`.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import casadi as ca

from ..core.linalg import inv3
from ..core.rotation import skew

__all__ = ["Modes"]


class _Array(NamedTuple):
    """One flexible array's pieces for the first-order inertia terms (B components unless named)."""

    n: int  # its number of modes
    C_PB: Any
    C_BP: Any
    w_p: Any  # ω_p, its rate relative to B [rad/s]
    wd_p: Any  # ω̇_p (B-frame derivative) or None
    rho: Any  # its mass centre from O [m]
    U: Any  # C_BP Φ̄ (3 x n) [kg]
    dJ_P: list  # ∂J/∂η_k (3 x 3, P axes) [kg m]


class Modes:
    """Symbolic modal matrices of all flexible arrays at one configuration (B components).

    Built from per-array pieces (``add``): ``Delta`` (3 x N) and ``D`` (3 x N) as in the module
    docstring, ``Delta_dot`` the B-frame derivative of ``Delta`` (``Ċ_BP = ω̃_p C_BP``),
    ``U = [C_BP Φ̄]`` (3 x N, the translational participations in B) and ``U_dot``; ``M``,
    ``K``, ``C`` the modal masses, stiffnesses and damping coefficients (N-vectors); ``D_wp`` and
    ``D_wdp`` the stacked ``Dᵀ ω_p`` and ``Dᵀ ω̇_p`` (the latter only when every array's ``ω̇_p``
    was given). ``m`` is the station's total mass.

    The elastic displacement moves the system's mass centre by ``U η / m`` unless the hub
    recoils; it does (no external force), so the velocities are relative to the moving mass
    centre and T loses ``½ |U η̇|² / m`` (König): the modal mass matrix is
    ``M_eff = diag(M) - Uᵀ U / m``, which couples the arrays. (``d/dt(Dᵀ ω_p) = Dᵀ ω̇_p``: the
    ``Ḋ`` part, ``(ω̃_p D)ᵀ ω_p``, vanishes.)

    Parameters
    ----------
    m_total : casadi SX  The station's total mass [kg].
    """

    def __init__(self, m_total):
        self.m = m_total
        self._arrays: list[_Array] = []  # per array, for the first-order inertia terms
        self._parts = {k: [] for k in ("Delta", "D", "Delta_dot", "U", "U_dot", "D_wp", "D_wdp", "M", "K", "C")}

    def add(self, C_PB, w_p, rho, modes, wd_p=None):
        """Append one array.

        Parameters
        ----------
        C_PB : casadi SX, shape (3, 3)  DCM from B to the array frame P.
        w_p : casadi SX, shape (3, 1)  ``omega_p_B``, the array's rate relative to B, B components [rad/s].
        rho : casadi SX, shape (3, 1)  Its mass centre from O, B components [m].
        modes : casadi SX, shape (15 n, 1)  Per mode Φ̄ (3) [kg], Ĥ (3) [kg m] (P axes), M [kg],
            K [N/m], C [N s/m], ∂J/∂η (xx, yy, zz, xy, xz, yz) [kg m] (P axes).
        wd_p : casadi SX, shape (3, 1), optional  ``omega_p_dot_B``, the B-frame derivative of
            ``w_p`` [rad/s²], when known.
        """
        n = modes.numel() // 15
        cols = [modes[15 * j : 15 * j + 15] for j in range(n)]
        C_BP = C_PB.T
        U = ca.horzcat(*[ca.mtimes(C_BP, c[0:3]) for c in cols])  # C_BP Φ̄ (3 x n)
        D = ca.horzcat(*[ca.mtimes(C_BP, c[3:6]) for c in cols])
        rho_x, wx = skew(rho), skew(w_p)
        U_dot = ca.mtimes(wx, U)
        P = self._parts
        P["U"].append(U)
        P["U_dot"].append(U_dot)
        P["D"].append(D)
        P["Delta"].append(D + ca.mtimes(rho_x, U))
        P["Delta_dot"].append(ca.mtimes(wx, D) + ca.mtimes(rho_x, U_dot))
        P["D_wp"].append(ca.mtimes(D.T, w_p))
        if wd_p is not None:
            P["D_wdp"].append(ca.mtimes(D.T, wd_p))
        for j, name in ((6, "M"), (7, "K"), (8, "C")):
            P[name].append(ca.vertcat(*[c[j] for c in cols]))
        dJ = [ca.vertcat(ca.horzcat(c[9], c[12], c[13]), ca.horzcat(c[12], c[10], c[14]), ca.horzcat(c[13], c[14], c[11]))
              for c in cols]
        self._arrays.append(_Array(n, C_PB, C_BP, w_p, wd_p, rho, U, dJ))

    def done(self):
        """Stack the arrays' pieces into the attributes listed in the class docstring; returns self."""
        n_arrays = len(self._parts["D"])
        for k, v in self._parts.items():
            if k == "D_wdp" and len(v) < n_arrays:
                v = []  # some ω̇_p unknown: not available
            setattr(self, k, (ca.horzcat if k in ("Delta", "D", "Delta_dot", "U", "U_dot") else ca.vertcat)(*v))
        del self._parts
        return self

    # -- the modal mass matrix M_eff = diag(M) - UᵀU/m ---------------------------------
    def mass_times(self, v):
        """``M_eff v`` (N-vector; ``M_eff = diag(M) - Uᵀ U / m`` [kg])."""
        return self.M * v - ca.mtimes(self.U.T, ca.mtimes(self.U, v)) / self.m

    def mass_rate_times(self, v):
        """``Ṁ_eff v = -(U̇ᵀ U + Uᵀ U̇) v / m``."""
        return -(ca.mtimes(self.U_dot.T, ca.mtimes(self.U, v)) + ca.mtimes(self.U.T, ca.mtimes(self.U_dot, v))) / self.m

    def solve(self, X):
        """``M_eff⁻¹ X`` by the Woodbury identity: one 3x3 inverse,
        ``M_eff⁻¹ = M⁻¹ + M⁻¹Uᵀ (m E - U M⁻¹ Uᵀ)⁻¹ U M⁻¹`` (M diagonal)."""
        inv_m = ca.diag(1.0 / self.M)
        Y = ca.mtimes(inv_m, X)
        MU = ca.mtimes(inv_m, self.U.T)  # N x 3
        G = self.m * ca.SX.eye(3) - ca.mtimes(self.U, MU)
        return Y + ca.mtimes(MU, ca.mtimes(inv3(G), ca.mtimes(self.U, Y)))

    # -- energies and momenta -------------------------------------------------------------
    def momentum(self, w, eta_dot):
        """``p_η = M_eff η̇ + Δᵀ ω + Dᵀ ω_p`` (= ∂T/∂η̇) at body rate ``w`` (omega_BN_B [rad/s])
        and modal rates ``eta_dot`` (N, 1)."""
        return self.mass_times(eta_dot) + ca.mtimes(self.Delta.T, w) + self.D_wp

    def momentum_rate(self, eta, eta_dot, w):
        """``ṗ_η = ∂T₁/∂η - K η - C η̇`` (Lagrange Eq. 31b: T_e has no η, T₁ is linear in it,
        V = ½ ηᵀKη, Rayleigh damping) at body rate ``w`` (omega_BN_B [rad/s])."""
        return self.centrifugal(w) - self.K * eta - self.C * eta_dot

    def kinetic(self, w, eta_dot):
        """``T_e = ½ η̇ᵀ M_eff η̇ + η̇ᵀ (Δᵀ ω + Dᵀ ω_p)`` [J] at body rate ``w`` (omega_BN_B [rad/s])."""
        return ca.dot(eta_dot, self.momentum(w, eta_dot) - 0.5 * self.mass_times(eta_dot))

    def strain(self, eta):
        """``½ ηᵀ K η`` [J] of the modal coordinates ``eta`` (N, 1)."""
        return 0.5 * ca.dot(eta, self.K * eta)

    # -- the first-order (deformation-dependent) inertia ----------------------------------
    def _deformed(self, eta):
        """Per array ``(array, J_η, u)``: ``J_η = Σ η_k ∂J/∂η_k`` [kg m²] in P axes (so
        ``δJ = C_BP J_η C_PB``) and ``u = C_BP Φ̄ η`` [kg m] (linear in ``eta``, so this also
        gives their η-rates). Products with δJ are taken in P (three matrix-vector products
        instead of two matrix products)."""
        out, i = [], 0
        for a in self._arrays:
            e = eta[i : i + a.n]
            i += a.n
            J_P = e[0] * a.dJ_P[0]
            for k in range(1, a.n):
                J_P = J_P + e[k] * a.dJ_P[k]
            out.append((a, J_P, ca.mtimes(a.U, e)))
        return out

    def inertia_delta(self, eta):
        """``δI = Σ [δJ + 2(ρ·u)E - ρuᵀ - uρᵀ]``: the first-order change of the inertia about O
        (each array's own, and its mass centre's parallel-axis term) [kg m²], (3, 3)."""
        dI = ca.SX.zeros(3, 3)
        for a, J_P, u in self._deformed(eta):
            dJ = ca.mtimes([a.C_BP, J_P, a.C_PB])
            dI = dI + dJ + 2.0 * ca.dot(a.rho, u) * ca.SX.eye(3) - ca.mtimes(a.rho, u.T) - ca.mtimes(u, a.rho.T)
        return dI

    def joint_momentum(self, eta):
        """``Σ [δJ ω_p + ρ × (ω_p × u)]``: the first-order momentum of the deflected arrays' own turning
        [N m s], (3, 1) (their mass centres leave the joint axes)."""
        h = ca.SX.zeros(3)
        for a, J_P, u in self._deformed(eta):
            # the matrix δJ (not three products in P): the forms build it for δI anyway
            h = h + ca.mtimes(ca.mtimes([a.C_BP, J_P, a.C_PB]), a.w_p) + ca.cross(a.rho, ca.cross(a.w_p, u))
        return h

    def first_order_momentum(self, eta, w):
        """``H₁ = ∂T₁/∂ω = δI ω + Σ [δJ ω_p + ρ × (ω_p × u)]`` [N m s], (3, 1) at body rate ``w``."""
        return ca.mtimes(self.inertia_delta(eta), w) + self.joint_momentum(eta)

    def first_order_kinetic(self, eta, w):
        """``T₁ = Σ [½ Wᵀ δJ W + (ω × ρ)·(W × u)]``, ``W = ω + ω_p`` [J] at body rate ``w``: the
        kinetic energy linear in η (velocity field ``W × (a + Φη)`` of the deflected array)."""
        T = ca.SX(0)
        for a, J_P, u in self._deformed(eta):
            W = w + a.w_p
            W_P = ca.mtimes(a.C_PB, W)
            T = T + 0.5 * ca.dot(W_P, ca.mtimes(J_P, W_P)) + ca.dot(ca.cross(w, a.rho), ca.cross(W, u))
        return T

    def centrifugal(self, w):
        """``∂T₁/∂η`` [N] (N, 1): per mode ``½ W_Pᵀ ∂J/∂η_k W_P + U_kᵀ((ω × ρ) × W)``,
        ``W_P = C_PB W`` (the centrifugal load of the turning station on the mode; T₁ is linear
        in η, so this does not depend on it)."""
        g = []
        for a in self._arrays:
            W = w + a.w_p
            W_P = ca.mtimes(a.C_PB, W)
            g_U = ca.mtimes(a.U.T, ca.cross(ca.cross(w, a.rho), W))
            g += [0.5 * ca.dot(W_P, ca.mtimes(a.dJ_P[k], W_P)) + g_U[k] for k in range(a.n)]
        return ca.vertcat(*g)

    def first_order_rate(self, eta, eta_dot, w):
        """The B-frame rate of ``H₁`` less ``δI ω̇`` [N m], (3, 1): per array
        ``δJ̇ W + δJ ω̇_p + ρ × (ω̇_p × u + W × u̇) + u̇ × (ω × ρ)`` with
        ``δJ̇ = δJ(η̇) + ω̃_p δJ - δJ ω̃_p`` and ``u̇ = u(η̇) + ω_p × u`` (``Ċ_BP = ω̃_p C_BP``),
        so ``δJ̇ W + δJ ω̇_p = C_BP [J_η̇ W_P + J_η C_PB (ω̇_p - ω_p × W)] + ω_p × δJ W``.
        Needs every array's ``ω̇_p``."""
        r = ca.SX.zeros(3)
        for (a, J_P, u), (_, J_P_rate, u_rate) in zip(self._deformed(eta), self._deformed(eta_dot)):
            if a.wd_p is None:
                raise ValueError("first_order_rate needs every array's omega_p_dot_B")
            W = w + a.w_p
            W_P = ca.mtimes(a.C_PB, W)
            u_dot = u_rate + ca.cross(a.w_p, u)
            inner = ca.mtimes(J_P_rate, W_P) + ca.mtimes(J_P, ca.mtimes(a.C_PB, a.wd_p - ca.cross(a.w_p, W)))
            r = (r + ca.mtimes(a.C_BP, inner) + ca.cross(a.w_p, ca.mtimes(a.C_BP, ca.mtimes(J_P, W_P)))
                 + ca.cross(a.rho, ca.cross(a.wd_p, u) + ca.cross(W, u_dot)) + ca.cross(u_dot, ca.cross(w, a.rho)))
        return r
