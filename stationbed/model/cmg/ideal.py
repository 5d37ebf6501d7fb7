"""``ideal``: a momentum store (no gimbals, no rotors to draw).

State ``h`` (B components [N m s]); held input: the body-torque command ``τ`` [N m]. Inside a
period ``ḣ = -τ - ω × h``, so the body receives exactly ``τ``. The limits are applied at the
control tick and reported: ``|τ| ≤ max_torque`` (scaled, direction kept) and no growth of ``|h|``
past ``max_momentum`` (the part of ``τ`` that would fill a full store is removed).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .base import CmgGeometry

__all__ = ["IdealCluster"]

#: stands for "no limit" in p (a finite number keeps the generated code free of inf)
NO_LIMIT = 1e300


class IdealCluster(CmgGeometry):
    """A momentum store: ``h`` is the state, the torque command the input.

    Head of ``pc``: ``max_torque`` [N m], ``max_momentum`` [N m s] (1e300: none),
    ``saturation_fraction``, then five unused zeros.
    """

    kind = "ideal"
    gimbals_per_unit = 0
    state_kind = "momentum"

    @property
    def state_names(self) -> tuple[str, ...]:
        """The state is ``h_B`` itself [N m s]."""
        return ("hx", "hy", "hz")

    # -- numbers -----------------------------------------------------------------------
    def _head_params(self, cfg):
        return [cfg.max_torque or NO_LIMIT, cfg.max_momentum or NO_LIMIT, cfg.saturation_fraction, 0.0, 0.0, 0.0, 0.0, 0.0]

    def _capacity(self, cfg):
        return math.inf if cfg.max_momentum is None else cfg.max_momentum

    def _initial_state(self, cfg):
        return np.array(cfg.h0_B, float)

    def max_torque(self, cfg) -> float:
        """``max_torque`` [N m] (inf when unlimited)."""
        return cfg.max_torque or math.inf

    # -- symbols -----------------------------------------------------------------------
    def _h(self, xc, pc):
        return xc

    def _h_dot(self, xc, uc, omega_BN_B, pc):
        return -uc - ca.cross(omega_BN_B, xc)

    def _state_dot(self, xc, uc, omega_BN_B, pc):
        return self.h_dot(xc, uc, omega_BN_B, pc)

    def _actuate(self, t, xc, tau_cmd, omega_BN_B, pc, steering, direct_rates):
        max_tau, max_h, frac = pc[0], pc[1], pc[2]
        n = ca.norm_2(tau_cmd)
        # the same numbers as fmin(1, max_tau / n), written so that its derivative inside the
        # limit is exact (1) even at tau = 0 (stationbed.analysis differentiates the actuation)
        scale = ca.if_else(n > max_tau, max_tau / n, 1.0)
        tau = tau_cmd * scale
        limited = ca.if_else(scale < 1.0, 1.0, 0.0)
        h_B = xc
        hn = ca.norm_2(h_B)
        # store full and the request would fill it further (dh/dt·h = -τ·h > 0): drop that part
        full = ca.logic_and(hn >= max_h, ca.dot(tau, h_B) < 0)
        h_hat = h_B / ca.fmax(hn, 1e-300)
        tau = ca.if_else(full, tau - ca.dot(tau, h_hat) * h_hat, tau)
        sat = ca.if_else(ca.logic_or(full, hn >= frac * max_h), 1.0, 0.0)
        return tau, 1.0, limited, sat
