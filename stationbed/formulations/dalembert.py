"""``dalembert``: TP-2511 Eq. 16 in the matrix form of Eq. 42 (D'Alembert's principle).

``I ω̇ + ω × I ω + Σ [(C*_p ω) × ω_p + I_p ω̇_p + ω_p × I_p ω_p] = L - ḣ - ω × h``

with the Coriolis matrix ``C*_p = tr(I_p) E - 2 I_p`` (= 2 Σ m l lᵀ over the array's mass).
State ``[q_BN (4), omega_BN_B (3)]``.
"""

from __future__ import annotations

import casadi as ca

from .base import Formulation, coriolis_matrix, inv3, omega_state_kinematics


class DAlembertForm(Formulation):
    name = "dalembert"
    state_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    state_kinds = ("attitude",) * 4 + ("rate",) * 3
    description = "TP-2511 Eq. 16/42: D'Alembert form with the Coriolis matrix Cp*"

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
            C_star = coriolis_matrix(I_p)
            rhs = rhs - (
                ca.cross(ca.mtimes(C_star, w), w_p) + ca.mtimes(I_p, wd_p) + ca.cross(w_p, ca.mtimes(I_p, w_p))
            )
        return ca.vertcat(omega_state_kinematics(x), ca.mtimes(inv3(I), rhs))
