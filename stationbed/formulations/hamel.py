"""``hamel``: Quinn's Boltzmann–Hamel equation (seed 000, Eq. 20) from energies, by casadi AD.

The user-facing model is two scalars, written as casadi expressions:

``T(ω, C, t, xe) = ½ ωᵀ I ω + Σ_p (ωᵀ I_p ω_p + ½ ω_pᵀ I_p ω_p) + ωᵀ h``

(body and arrays about O; ``h`` the CMG momentum relative to the body; the rotor-only energy
does not depend on ω or C and drops out), and the gravity-gradient potential of a point-mass
Earth on a circular orbit (Quinn Eq. 27–28 with ``I = tr(J) E - J``, constants dropped),

``V(C) = (3/2) n² R̂_Nᵀ C_BNᵀ I C_BN R̂_N``,  ``n² = μ/|R|³``.

The rotation obeys Quinn Eq. 20 (his tilde is the transpose of :func:`skew`, so
``ω̃ᵀ p = ω × p``)::

    d/dt(∂T/∂ω) + ω × ∂T/∂ω - ∂T/∂C + ∂V/∂C = M

with ``∂f/∂C`` the orientation gradient of DESIGN §4: ``δf = gᵀ δθ`` for
``δC_BN = -skew(δθ) C_BN``; computed here by AD of ``f((E - skew(θ)) C_BN)`` at ``θ = 0``
(for ``f = bᵀ C n`` it is ``b × (C n)``, Quinn Eq. 13–19). Since ``Ċ_BN = -skew(ω) C_BN``,
``δθ = ω dt`` along the motion, and the total derivative of ``p = ∂T/∂ω`` is

``ṗ = (∂p/∂ω) ω̇ + ∂p/∂t + (∂p/∂xe) ẋe + (∂p/∂θ) ω``,

``ẋe`` being the model's extra-state dynamics (CMG state, driven joints), which never depend on
ω̇. ``∂p/∂ω = ∂²T/∂ω²`` is the inertia about O, so

``ω̇ = (∂²T/∂ω²)⁻¹ [M - ω × p + ∂T/∂C - ∂V/∂C - ∂p/∂t - (∂p/∂xe) ẋe - (∂p/∂θ) ω]``.

``M`` is every external torque of the scene *except* the conservative kinds (gravity gradient),
which enter only through ``V`` (:meth:`StationModel.external_torque` with ``with_potential=False``
and :meth:`StationModel.potential`). State ``[q_BN (4), omega_BN_B (3)]``.

Flexible arrays (stationbed/model/flex.py) add the elastic kinetic energy
``T_e = ½ η̇ᵀ M_eff η̇ + η̇ᵀ (Δᵀ ω + Dᵀ ω_p)`` and the first-order deformation-dependent inertia's
``T₁ = ½ Wᵀ δJ W + (ω × ρ)·(W × u)`` (linear in η) to T, the strain energy ``½ ηᵀ K η`` to V and a
Rayleigh dissipation ``R = ½ η̇ᵀ C η̇``; the modal coordinates obey Lagrange's equation (Quinn
Eq. 31b) ``d/dt(∂T/∂η̇) - ∂T/∂η + ∂V/∂η + ∂R/∂η̇ = 0``. With velocities ``v = [ω; η̇]`` and
``P = ∂T/∂v`` everything above holds with p → P (plus ``(∂P/∂η) η̇`` in Ṗ), and the mass matrix
``∂²T/∂v² = [I Δ; Δᵀ M_eff]`` is solved by the Schur complement on its modal block. The
states then continue ``..., η, η̇`` after the extra states.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.rotation import dcm, quat_kinematics, skew
from ..core.linalg import inv3
from ..model import StationModel
from .base import Formulation


def orientation_gradient(f, C, theta):
    """``∂f/∂C`` (DESIGN §4) of ``f`` built on ``(E - skew(θ)) C``: AD in θ, at θ = 0.

    Parameters
    ----------
    f : casadi SX scalar  An expression of ``theta`` (built on :func:`perturbed`).
    C : casadi SX, shape (3, 3)  The unperturbed attitude (documents the argument; unused).
    theta : casadi SX symbol, shape (3, 1)  Small rotation [rad], B components.

    Returns
    -------
    casadi SX, shape (3, 1)  The gradient, still containing ``theta`` (the caller substitutes 0).
    """
    return ca.gradient(f, theta)


def perturbed(C, theta):
    """``(E - skew(θ)) C``: the attitude matrix after a small rotation ``θ``.

    Parameters
    ----------
    C : casadi SX, shape (3, 3)  Attitude ``C_BN``.
    theta : casadi SX, shape (3, 1)  Small rotation [rad], B components.

    Returns
    -------
    casadi SX, shape (3, 3)
    """
    return ca.mtimes(ca.SX.eye(3) - skew(theta), C)


class HamelForm(Formulation):
    """Quinn's Boltzmann-Hamel equation from ``T`` and ``V`` by AD (see the module docstring)."""

    name = "hamel"
    core_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    core_kinds = ("attitude",) * 4 + ("rate",) * 3
    description = "Quinn 1990 Eq. 20: Boltzmann-Hamel form, equations by AD of T and V"
    omega_is_state = True

    def __init__(self, model: StationModel):
        super().__init__(model)
        self._terms = self._build_terms()

    # -- the user-facing energies ---------------------------------------------------------
    def kinetic(self, t, q_BN, C_BN, omega_BN_B, xe, p, u=None):
        """``T(ω, C, t, xe, η̇)`` [J] (array kinematics without ω do not depend on q or C);
        ``xe`` holds the model's extra states, then ``η`` and ``η̇``. The structure's energy
        (:meth:`StationModel.kinetic_energy`) plus ``ωᵀh``: the rotors' own energy does not
        depend on ω or C and drops out."""
        return self.model.kinetic_energy(t, q_BN, omega_BN_B, xe, p, u=u, h_coupling=True)

    def potential(self, t, q_BN, C_BN, xe, p, u=None):
        """The conservative torques' potential (gravity gradient: ``(3/2) n² R̂_Bᵀ I R̂_B``,
        ``R̂_B = C_BN R̂_N``; 0 off orbit; :meth:`StationModel.potential`) plus the arrays' strain
        energy ``½ ηᵀ K η`` [J]."""
        m = self.model
        arrays = m.arrays(t, q_BN, xe, p, u=u)
        V = ca.SX(0)
        if any(kind.conservative for kind in m.torques):
            V = m.potential(t, C_BN, m.inertia(t, p, arrays), p)
        if m.n_modes:
            V = V + m.modal(arrays, p).strain(m.eta(xe))
        return V

    def dissipation(self, t, q_BN, xe, p, u=None):
        """Rayleigh's dissipation function ``½ η̇ᵀ C η̇`` of the modal damping [W/2]."""
        m = self.model
        if not m.n_modes:
            return ca.SX(0)
        eta_dot = m.modal_state(xe)
        return 0.5 * ca.dot(eta_dot, m.modal(m.arrays(t, q_BN, xe, p, u=u), p).C * eta_dot)

    # -- equations by AD ----------------------------------------------------------------
    def _build_terms(self) -> ca.Function:
        """The partials of T, V (and R) as one SX Function (inlined into the RHS when called).

        Velocities ``v = [ω; η̇]``, momenta ``P = ∂T/∂v``; coordinates: the attitude (through
        θ), the extra states ``xe`` (CMG, driven joints: their rates come from the model) and
        ``η``."""
        m = self.model
        N = m.n_modes
        omega_BN_B = ca.SX.sym("w", 3)
        t = ca.SX.sym("t")
        q_BN = ca.SX.sym("q", 4)
        C_BN = ca.SX.sym("C", 3, 3)
        xm = ca.SX.sym("xe", m.n_extra)
        eta = ca.SX.sym("eta", N)
        eta_dot = ca.SX.sym("eta_dot", N)
        p = ca.SX.sym("p", m.layout.size)
        u = ca.SX.sym("u", m.nu)
        theta = ca.SX.sym("theta", 3)
        xe = ca.vertcat(xm, eta, eta_dot)
        C_perturbed = perturbed(C_BN, theta)
        T = self.kinetic(t, q_BN, C_perturbed, omega_BN_B, xe, p, u)
        V = self.potential(t, q_BN, C_perturbed, xe, p, u)
        v = ca.vertcat(omega_BN_B, eta_dot)
        mom = ca.gradient(T, v)  # P = ∂T/∂v
        outs = [
            mom,
            ca.jacobian(mom, v),  # ∂²T/∂v²: the inertia about O, couplings Δ, modal masses
            ca.jacobian(mom, t),
            ca.jacobian(mom, xm),
            ca.jacobian(mom, theta),
            ca.jacobian(mom, eta),
            orientation_gradient(T, C_BN, theta),
            orientation_gradient(V, C_BN, theta),
            ca.gradient(T - V, eta),  # ∂T/∂η - ∂V/∂η
            ca.gradient(self.dissipation(t, q_BN, xe, p, u), eta_dot),
        ]
        f = ca.Function("hamel_terms", [omega_BN_B, t, q_BN, C_BN, xm, eta, eta_dot, p, u, theta], outs)
        return f

    def terms(self, t, q_BN, omega_BN_B, xe, p, u):
        """The partials of T, V and R at the state, θ = 0.

        Parameters
        ----------
        t : Time [s].
        q_BN : shape (4,)  Euler parameters of B relative to N.
        omega_BN_B : shape (3,)  Body rate [rad/s].
        xe : The extra states with ``η, η̇``.
        p : The parameter vector.
        u : shape (nu,) or None  The held input (None: zeros).

        Returns
        -------
        tuple ``(P, ∂P/∂v, ∂P/∂t, ∂P/∂xe, ∂P/∂θ, ∂P/∂η, ∂T/∂C, ∂V/∂C, ∂(T-V)/∂η, ∂R/∂η̇)``
        """
        m = self.model
        u = np.zeros(m.nu) if u is None else u
        return self._terms(
            omega_BN_B, t, q_BN, dcm(q_BN), xe[0 : m.n_extra], m.eta(xe), m.modal_state(xe), p, u, np.zeros(3)
        )

    def _rhs(self, t, x, u, p):
        """``∂²T/∂v² v̇ = [M - ω × p_ω + ∂T/∂C - ∂V/∂C; ∂(T-V)/∂η - ∂R/∂η̇] - Ṗ|_v̇=0``, solved by the
        Schur complement on the modal block ``∂²T/∂η̇²`` (a symbolic linear solve of that block:
        the hub's recoil couples the arrays' modes, so it is not diagonal)."""
        m = self.model
        N = m.n_modes
        q_BN, omega_BN_B, xe = self.attitude(x), self.core_vector(x), self.extra(x)
        mom, Mvv, dp_dt, dp_dxe, dp_dth, dp_deta, gT, gV, dL_deta, dR = self.terms(t, q_BN, omega_BN_B, xe, p, u)
        xe_dot = m.extra_dot(t, q_BN, xe, u, omega_BN_B, p)
        eta_dot = m.modal_state(xe)
        I_O_B = Mvv[0:3, 0:3]
        arrays = m.arrays(t, q_BN, xe, p, u=u) if m.needs_arrays else None
        M_B = m.external_torque(t, q_BN, u, p, I_O_B, with_potential=False, arrays=arrays)
        # the rate of P with v̇ = 0: explicit time, extra states, attitude (δθ = ω dt), modes
        Pdot0 = dp_dt + ca.mtimes(dp_dxe, xe_dot) + ca.mtimes(dp_dth, omega_BN_B) + ca.mtimes(dp_deta, eta_dot)
        rhs = M_B - ca.cross(omega_BN_B, mom[0:3]) + gT - gV - Pdot0[0:3]
        if not N:
            return ca.vertcat(quat_kinematics(q_BN, omega_BN_B), ca.mtimes(inv3(I_O_B), rhs)), omega_BN_B
        r_eta = dL_deta - dR - Pdot0[3:]
        B = Mvv[0:3, 3:]
        sol = ca.solve(Mvv[3:, 3:], ca.horzcat(r_eta, B.T))  # the modal block, as AD gives it
        omega_dot_B = ca.mtimes(inv3(I_O_B - ca.mtimes(B, sol[:, 1:4])), rhs - ca.mtimes(B, sol[:, 0]))
        eta_ddot = sol[:, 0] - ca.mtimes(sol[:, 1:4], omega_dot_B)
        return ca.vertcat(quat_kinematics(q_BN, omega_BN_B), omega_dot_B), omega_BN_B, ca.vertcat(eta_dot, eta_ddot)

    def _omega(self, t, x, p):
        return self.core_vector(x)

    def _core(self, t, q_BN, omega_BN_B, xe, p):
        return omega_BN_B
