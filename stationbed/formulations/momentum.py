"""``momentum``: TP-2511 Eq. 17-19, MSFC style.

State ``[q_BN (4), H_O_B (3)]``: the total angular momentum about O in B components. It obeys
``dH/dt|_B = L - ω × H`` and ω is recovered algebraically,
``ω = I⁻¹ (H - Σ I_p ω_p - h)`` (h: CMG momentum). No array acceleration is needed, and a step in an array rate
leaves H continuous (ω jumps) without any special handling.
"""

from __future__ import annotations

import casadi as ca

from ..rotation import quat_kinematics
from .base import Formulation, inv3


class MomentumForm(Formulation):
    name = "momentum"
    core_names = ("qw", "qx", "qy", "qz", "HBx", "HBy", "HBz")
    core_kinds = ("attitude",) * 4 + ("momentum",) * 3
    description = "TP-2511 Eq. 17-19: total angular momentum H in B as state, omega recovered"

    def _omega_from(self, H, arrays, I, xe, p):
        """``ω = I⁻¹ (H - Σ I_p ω_p - h)``."""
        H = H - self.model.h(xe, p)
        for I_p, w_p, *_ in arrays:
            H = H - ca.mtimes(I_p, w_p)
        return ca.mtimes(inv3(I), H)

    def _omega(self, t, x, p):
        arrays = self.arrays(t, x, p)
        return self._omega_from(x[4:7], arrays, self.model.inertia(t, p, arrays), x[7:], p)

    def _rhs(self, t, x, u, p):
        m = self.model
        arrays = self.arrays(t, x, p, u=u)
        I = m.inertia(t, p, arrays)
        H = x[4:7]
        w = self._omega_from(H, arrays, I, x[7:], p)
        L = m.external_torque(t, x[0:4], u, p, I)
        return ca.vertcat(quat_kinematics(x[0:4], w), L - ca.cross(w, H)), w

    def _core(self, t, q, omega, xe, p):
        return self.momentum_of(t, q, omega, xe, p)
