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

The beam shapes (:func:`~stationbed.core.beam.beam_mode`) live in :mod:`stationbed.core.beam`.
"""

from __future__ import annotations

import casadi as ca

from ..core.linalg import inv3
from ..core.rotation import skew

__all__ = ["Modes"]

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
        self._parts = {k: [] for k in ("Delta", "D", "Delta_dot", "U", "U_dot", "D_wp", "D_wdp", "M", "K", "C")}

    def add(self, C_PB, w_p, rho, modes, wd_p=None):
        """Append one array.

        Parameters
        ----------
        C_PB : casadi SX, shape (3, 3)  DCM from B to the array frame P.
        w_p : casadi SX, shape (3, 1)  ``omega_p_B``, the array's rate relative to B, B components [rad/s].
        rho : casadi SX, shape (3, 1)  Its mass centre from O, B components [m].
        modes : casadi SX, shape (9 n, 1)  Per mode Φ̄ (3) [kg], Ĥ (3) [kg m] (P axes), M [kg],
            K [N/m], C [N s/m].
        wd_p : casadi SX, shape (3, 1), optional  ``omega_p_dot_B``, the B-frame derivative of
            ``w_p`` [rad/s²], when known.
        """
        n = modes.numel() // 9
        cols = [modes[9 * j : 9 * j + 9] for j in range(n)]
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

    def momentum_rate(self, eta, eta_dot):
        """``ṗ_η = -K η - C η̇`` (Lagrange Eq. 31b: T_e has no η, V = ½ ηᵀKη, Rayleigh damping)."""
        return -self.K * eta - self.C * eta_dot

    def kinetic(self, w, eta_dot):
        """``T_e = ½ η̇ᵀ M_eff η̇ + η̇ᵀ (Δᵀ ω + Dᵀ ω_p)`` [J] at body rate ``w`` (omega_BN_B [rad/s])."""
        return ca.dot(eta_dot, self.momentum(w, eta_dot) - 0.5 * self.mass_times(eta_dot))

    def strain(self, eta):
        """``½ ηᵀ K η`` [J] of the modal coordinates ``eta`` (N, 1)."""
        return 0.5 * ca.dot(eta, self.K * eta)
