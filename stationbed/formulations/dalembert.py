"""``dalembert``: TP-2511 Eq. 16 in the matrix form of Eq. 42 (D'Alembert's principle).

``I ω̇ + ω × I ω + Σ [(C*_p ω) × ω_p + I_p ω̇_p + ω_p × I_p ω_p] = L - ḣ - ω × h``

with the Coriolis matrix ``C*_p = tr(I_p) E - 2 I_p`` (= 2 Σ m l lᵀ over the array's mass).
State ``[q_BN (4), omega_BN_B (3)]``.
"""

from __future__ import annotations

import casadi as ca

from ..core.massprops import coriolis_matrix
from .base import OmegaStateForm


class DAlembertForm(OmegaStateForm):
    """TP-2511 Eq. 16/42 with ``omega_BN_B`` as state (see the module docstring)."""

    name = "dalembert"
    description = "TP-2511 Eq. 16/42: D'Alembert form with the Coriolis matrix Cp*"

    def _array_term(self, omega_BN_B, I_p_B, omega_p_B, omega_p_dot_B):
        coriolis = ca.cross(ca.mtimes(coriolis_matrix(I_p_B), omega_BN_B), omega_p_B)
        return coriolis + ca.mtimes(I_p_B, omega_p_dot_B) + ca.cross(omega_p_B, ca.mtimes(I_p_B, omega_p_B))
