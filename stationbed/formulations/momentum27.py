"""``momentum27``: TP-2511 Eq. 27, the angular-momentum equation expanded and solved for ω̇.

``I ω̇ + Σ I_p ω̇_p + ω × I ω + Σ ω_p × I_p ω_p
  + Σ [ω_p × I_p ω - I_p (ω_p × ω) + ω × I_p ω_p] = L - ḣ - ω × h``

State ``[q_BN (4), omega_BN_B (3)]``. ``ω̇_p`` is the B-frame derivative of the array's relative
rate; ``İ_p = ω_p × I_p - I_p ω_p ×`` is what produced the bracket.
"""

from __future__ import annotations

import casadi as ca

from .base import Formulation, inv3, omega_state_kinematics


class Momentum27Form(Formulation):
    name = "momentum27"
    state_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    state_kinds = ("attitude",) * 4 + ("rate",) * 3
    description = "TP-2511 Eq. 27: expanded momentum equation, omega as state"

    def _omega(self, t, x, p):
        return x[4:7]

    def _state(self, t, q, omega, p):
        return ca.vertcat(q, omega)

    def _rhs(self, t, x, u, p):
        m = self.model
        arrays = m.arrays(t, p)
        I = m.inertia(t, p, arrays)
        w = x[4:7]
        rhs = m.external_torque(t, x[0:4], u, p, I) - ca.cross(w, ca.mtimes(I, w))
        for I_p, w_p, wd_p, *_ in arrays:
            rhs = rhs - ca.mtimes(I_p, wd_p) - ca.cross(w_p, ca.mtimes(I_p, w_p))
            rhs = rhs - (
                ca.cross(w_p, ca.mtimes(I_p, w))
                - ca.mtimes(I_p, ca.cross(w_p, w))
                + ca.cross(w, ca.mtimes(I_p, w_p))
            )
        return ca.vertcat(omega_state_kinematics(x), ca.mtimes(inv3(I), rhs))
