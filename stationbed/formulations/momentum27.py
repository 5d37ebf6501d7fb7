"""``momentum27``: TP-2511 Eq. 27, the angular-momentum equation expanded and solved for ω̇.

``I ω̇ + Σ I_p ω̇_p + ω × I ω + Σ ω_p × I_p ω_p
  + Σ [ω_p × I_p ω - I_p (ω_p × ω) + ω × I_p ω_p] = L - ḣ - ω × h``

State ``[q_BN (4), omega_BN_B (3)]``. ``ω̇_p`` is the B-frame derivative of the array's relative
rate; ``İ_p = ω_p × I_p - I_p ω_p ×`` is what produced the bracket.
"""

from __future__ import annotations

import casadi as ca

from .base import OmegaStateForm


class Momentum27Form(OmegaStateForm):
    """TP-2511 Eq. 27 with ``omega_BN_B`` as state (see the module docstring)."""

    name = "momentum27"
    description = "TP-2511 Eq. 27: expanded momentum equation, omega as state"

    def _array_term(self, omega_BN_B, I_p_B, omega_p_B, omega_p_dot_B):
        bracket = (
            ca.cross(omega_p_B, ca.mtimes(I_p_B, omega_BN_B))
            - ca.mtimes(I_p_B, ca.cross(omega_p_B, omega_BN_B))
            + ca.cross(omega_BN_B, ca.mtimes(I_p_B, omega_p_B))
        )
        return ca.mtimes(I_p_B, omega_p_dot_B) + ca.cross(omega_p_B, ca.mtimes(I_p_B, omega_p_B)) + bracket
