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
    name = "momentum27"
    description = "TP-2511 Eq. 27: expanded momentum equation, omega as state"

    def _array_term(self, w, I_p, w_p, wd_p):
        bracket = ca.cross(w_p, ca.mtimes(I_p, w)) - ca.mtimes(I_p, ca.cross(w_p, w)) + ca.cross(w, ca.mtimes(I_p, w_p))
        return ca.mtimes(I_p, wd_p) + ca.cross(w_p, ca.mtimes(I_p, w_p)) + bracket
