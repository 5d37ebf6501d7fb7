"""``momentum``: TP-2511 Eq. 17-19, MSFC style.

State ``[q_BN (4), H_O_B (3)]``: the total angular momentum about O in B components. It obeys
``dH/dt|_B = L - ω × H`` and ω is recovered algebraically,
``ω = I⁻¹ (H - Σ I_p ω_p - h)`` (h: CMG momentum). No array acceleration is needed, and a step in an array rate
leaves H continuous (ω jumps) without any special handling.

Flexible arrays keep that character: their second modal state is the modal momentum
``p_η = ∂T/∂η̇ = M_eff η̇ + Δᵀ ω + Dᵀ ω_p``, whose rate is ``∂T₁/∂η - K η - C η̇`` (Lagrange
Eq. 31b, no acceleration; ``T₁`` the first-order deformation-dependent inertia's energy), and
``(ω, η̇)`` are recovered together from ``(H, p_η)``
(:meth:`StationModel.velocities`).
"""

from __future__ import annotations

import casadi as ca

from ..core.rotation import quat_kinematics
from .base import Formulation


class MomentumForm(Formulation):
    """State ``[q_BN (4), H_O_B (3)]``; ω (and η̇) recovered from the momenta."""

    name = "momentum"
    core_names = ("qw", "qx", "qy", "qz", "HBx", "HBy", "HBz")
    core_kinds = ("attitude",) * 4 + ("momentum",) * 3
    description = "TP-2511 Eq. 17-19: total angular momentum H in B as state, omega recovered"

    modal_state_prefix = "peta"

    def _velocities(self, t, x, p, u=None):
        """``(omega_BN_B, η̇, I_O_B, modal, arrays)`` at state ``x``."""
        m = self.model
        arrays = self.arrays(t, x, p, u=u)
        I_O_B = m.inertia(t, p, arrays)
        modal = m.modal(arrays, p)
        omega_BN_B, eta_dot = m.velocities(self.core_vector(x), m.modal_state(self.extra(x)), arrays, modal, I_O_B, self.extra(x), p)
        return omega_BN_B, eta_dot, I_O_B, modal, arrays

    def _omega(self, t, x, p):
        return self._velocities(t, x, p)[0]

    def modal_rates(self, t, x, p):
        """``η̇`` recovered from the state (its second modal state is ``p_η``)."""
        return self._velocities(t, x, p)[1]

    def _rhs(self, t, x, u, p):
        m = self.model
        q_BN, H_O_B = self.attitude(x), self.core_vector(x)
        omega_BN_B, eta_dot, I_O_B, modal, arrays = self._velocities(t, x, p, u)
        L_B = m.external_torque(t, q_BN, u, p, I_O_B, arrays=arrays)
        core_dot = ca.vertcat(quat_kinematics(q_BN, omega_BN_B), L_B - ca.cross(omega_BN_B, H_O_B))
        if not m.n_modes:
            return core_dot, omega_BN_B
        eta = m.eta(self.extra(x))
        p_dot = modal.momentum_rate(eta, eta_dot, omega_BN_B)
        return core_dot, omega_BN_B, ca.vertcat(eta_dot, p_dot)

    def _core(self, t, q_BN, omega_BN_B, xe, p):
        return self.momentum_of(t, q_BN, omega_BN_B, xe, p)

    def _modal_state(self, t, q_BN, omega_BN_B, xe, p):
        m = self.model
        return self.modal_momenta(m.modal(m.arrays(t, q_BN, xe, p), p), omega_BN_B, m.modal_state(xe))
