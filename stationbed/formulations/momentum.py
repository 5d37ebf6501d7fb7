"""``momentum``: TP-2511 Eq. 17-19, MSFC style.

State ``[q_BN (4), H_O_B (3)]``: the total angular momentum about O in B components. It obeys
``dH/dt|_B = L - ω × H`` and ω is recovered algebraically,
``ω = I⁻¹ (H - Σ I_p ω_p - h)``. No array acceleration is needed, and a step in an array rate
leaves H continuous (ω jumps) without any special handling.
"""

from __future__ import annotations

import casadi as ca

from ..rotation import quat_kinematics
from .base import Formulation, inv3


class MomentumForm(Formulation):
    name = "momentum"
    state_names = ("qw", "qx", "qy", "qz", "HBx", "HBy", "HBz")
    state_kinds = ("attitude",) * 4 + ("momentum",) * 3
    description = "TP-2511 Eq. 17-19: total angular momentum H in B as state, omega recovered"

    @staticmethod
    def _omega_from(H, arrays, I):
        """``ω = I⁻¹ (H - Σ I_p ω_p)``."""
        for I_p, w_p, *_ in arrays:
            H = H - ca.mtimes(I_p, w_p)
        return ca.mtimes(inv3(I), H)

    def _omega(self, t, x, p):
        arrays = self.model.arrays(t, p)
        return self._omega_from(x[4:7], arrays, self.model.inertia(t, p, arrays))

    def _rhs(self, t, x, u, p):
        m = self.model
        arrays = m.arrays(t, p)
        I = m.inertia(t, p, arrays)
        H = x[4:7]
        w = self._omega_from(H, arrays, I)
        L = m.external_torque(t, x[0:4], u, p, I)
        return ca.vertcat(quat_kinematics(x[0:4], w), L - ca.cross(w, H))

    def _state(self, t, q, omega, p):
        return ca.vertcat(q, self.momentum_of(t, omega, p))
