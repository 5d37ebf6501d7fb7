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

:func:`beam_mode` gives the integrals of a uniform Euler–Bernoulli cantilever (root, span and
deflection directions in P), with the shape normalised to 1 at the tip: ``η_k`` is then the
tip deflection of mode k in metres.
"""

from __future__ import annotations

import functools
import math

import casadi as ca
import numpy as np

from .rotation import skew

__all__ = ["beam_mode", "BETA_L", "check_participation", "Modes"]

#: roots of 1 + cos(βL) cosh(βL) = 0: clamped-free Euler–Bernoulli beam, modes 1..6
BETA_L = (1.8751040687119611, 4.6940911329741745, 7.8547574382376126, 10.995540734875467, 14.137168391046471, 17.278759532088237)

AXES = {"x": 0, "y": 1, "z": 2}


def _axis(name: str) -> np.ndarray:
    sign = -1.0 if name.startswith("-") else 1.0
    e = np.zeros(3)
    e[AXES[name.lstrip("+-")]] = sign
    return e


def cantilever_shape(n: int, s: np.ndarray, length: float) -> np.ndarray:
    """Mode ``n`` (1-based) of a uniform clamped-free beam at stations ``s`` in [0, L], tip = 1.

    ``ψ = cosh x - cos x - σ (sinh x - sin x)``, ``x = β s``, evaluated without cancellation:
    ``cosh x - σ sinh x = ((1 - σ) eˣ + (1 + σ) e⁻ˣ) / 2`` with
    ``1 - σ = (sin βL - cos βL - e^(-βL)) / (sinh βL + sin βL)`` (σ → 1 as βL grows, and the
    direct form loses ~cosh βL of precision: 1.6e7 at mode 6)."""
    bl = BETA_L[n - 1]
    den = math.sinh(bl) + math.sin(bl)
    one_m = (math.sin(bl) - math.cos(bl) - math.exp(-bl)) / den  # 1 - σ
    sigma = 1.0 - one_m

    def psi(x):
        return 0.5 * (one_m * np.exp(x) + (1.0 + sigma) * np.exp(-x)) - np.cos(x) + sigma * np.sin(x)

    return psi(bl / length * np.asarray(s, float)) / psi(np.array(bl))


@functools.lru_cache(maxsize=8)
def _gauss_legendre(n: int):
    """Nodes and weights on [-1, 1] (cached: numpy computes them by an eigenvalue problem)."""
    return np.polynomial.legendre.leggauss(n)


def beam_mode(n: int, length: float, mass: float, root, span: str, deflection: str, n_quad: int = 96):
    """Quinn Eq. 24 integrals ``(Φ̄, Ĥ, M)`` of cantilever mode ``n``, P components about the
    array's mass centre (the P origin). The beam runs from ``root`` along ``span`` and bends
    along ``deflection`` (axis names like ``"y"`` or ``"-z"``); uniform mass per length.
    Gauss–Legendre quadrature with ``n_quad`` points (exact to ~1e-15 for n <= 6)."""
    e_s, e_d = _axis(span), _axis(deflection)
    if abs(e_s @ e_d) > 0.5:
        raise ValueError(f"span {span!r} and deflection {deflection!r} must be different axes")
    xg, wg = _gauss_legendre(n_quad)
    s = 0.5 * length * (xg + 1.0)
    w = 0.5 * length * wg * (mass / length)  # dm at each station
    psi = cantilever_shape(n, s, length)
    a = np.asarray(root, float)[None, :] + s[:, None] * e_s[None, :]  # points relative to the P origin
    phi_bar = float(np.sum(w * psi)) * e_d
    H_hat = np.sum((w * psi)[:, None] * np.cross(a, e_d[None, :]), axis=0)
    M = float(np.sum(w * psi * psi))
    return phi_bar, H_hat, M


def check_participation(mass: float, J: np.ndarray, modes) -> float:
    """Fraction of the array's mass or inertia left, in its worst direction, after its modes'
    effective masses: the smallest eigenvalue of ``S (diag(m E, J) - Σ_k v_k v_kᵀ / M_k) S``,
    ``v_k = [Φ̄_k; Ĥ_k]``, ``S = diag(E/√m, J^-½)`` (1: no mode; 0: the modes take it all).

    Modes of a real structure take at most all of its mass and inertia, so this is >= 0; a
    negative value means the declared participations are not physical (the coupled mass matrix
    would not be positive definite and the motion would be unstable)."""
    evals, evecs = np.linalg.eigh(np.asarray(J, float))
    S = np.zeros((6, 6))
    S[:3, :3] = np.eye(3) / math.sqrt(mass)
    S[3:, 3:] = evecs @ np.diag(evals**-0.5) @ evecs.T
    R = np.eye(6)
    for phi_bar, H_hat, M in modes:
        v = S @ np.concatenate([phi_bar, H_hat])
        R -= np.outer(v, v) / M
    return float(np.linalg.eigvalsh(R).min())


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
    """

    def __init__(self, m_total):
        self.m = m_total
        self._parts = {k: [] for k in ("Delta", "D", "Delta_dot", "U", "U_dot", "D_wp", "D_wdp", "M", "K", "C")}

    def add(self, C_PB, w_p, rho, modes, wd_p=None):
        """Append one array: ``modes`` holds per mode Φ̄ (3), Ĥ (3), M, K, C (P axes); ``wd_p``
        its relative rate's B-frame derivative, when known."""
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
        n_arrays = len(self._parts["D"])
        for k, v in self._parts.items():
            if k == "D_wdp" and len(v) < n_arrays:
                v = []  # some ω̇_p unknown: not available
            setattr(self, k, (ca.horzcat if k in ("Delta", "D", "Delta_dot", "U", "U_dot") else ca.vertcat)(*v))
        del self._parts
        return self

    # -- the modal mass matrix M_eff = diag(M) - UᵀU/m ---------------------------------
    def mass_times(self, v):
        return self.M * v - ca.mtimes(self.U.T, ca.mtimes(self.U, v)) / self.m

    def mass_rate_times(self, v):
        """``Ṁ_eff v = -(U̇ᵀ U + Uᵀ U̇) v / m``."""
        return -(ca.mtimes(self.U_dot.T, ca.mtimes(self.U, v)) + ca.mtimes(self.U.T, ca.mtimes(self.U_dot, v))) / self.m

    def solve(self, X):
        """``M_eff⁻¹ X`` by the Woodbury identity: one 3x3 inverse,
        ``M_eff⁻¹ = M⁻¹ + M⁻¹Uᵀ (m E - U M⁻¹ Uᵀ)⁻¹ U M⁻¹`` (M diagonal)."""
        from .formulations.base import inv3

        inv_m = ca.diag(1.0 / self.M)
        Y = ca.mtimes(inv_m, X)
        MU = ca.mtimes(inv_m, self.U.T)  # N x 3
        G = self.m * ca.SX.eye(3) - ca.mtimes(self.U, MU)
        return Y + ca.mtimes(MU, ca.mtimes(inv3(G), ca.mtimes(self.U, Y)))

    # -- energies and momenta -------------------------------------------------------------
    def momentum(self, w, eta_dot):
        """``p_η = M_eff η̇ + Δᵀ ω + Dᵀ ω_p`` (= ∂T/∂η̇)."""
        return self.mass_times(eta_dot) + ca.mtimes(self.Delta.T, w) + self.D_wp

    def momentum_rate(self, eta, eta_dot):
        """``ṗ_η = -K η - C η̇`` (Lagrange Eq. 31b: T_e has no η, V = ½ ηᵀKη, Rayleigh damping)."""
        return -self.K * eta - self.C * eta_dot

    def kinetic(self, w, eta_dot):
        """``T_e = ½ η̇ᵀ M_eff η̇ + η̇ᵀ (Δᵀ ω + Dᵀ ω_p)`` [J]."""
        return ca.dot(eta_dot, self.momentum(w, eta_dot) - 0.5 * self.mass_times(eta_dot))

    def strain(self, eta):
        """``½ ηᵀ K η`` [J]."""
        return 0.5 * ca.dot(eta, self.K * eta)
