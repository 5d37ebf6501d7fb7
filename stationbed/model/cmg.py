"""CMG cluster: momentum models, steering laws, singularity measure (TP-2511 §II.B; Wie 2005).

The cluster stores angular momentum ``h`` (B components) relative to the body. It enters every
formulation through ``H = I ω + Σ I_p ω_p + h`` and puts the torque ``-ḣ - ω × h`` on the body
(``ḣ`` is the body-frame derivative). Three fidelities, chosen by the scene's ``[cmg] kind``:

``ideal``
    a momentum store: state ``h``; held input: the body-torque command ``τ``; inside a period
    ``ḣ = -τ - ω × h``, so the body receives exactly ``τ``. Torque and momentum limits are applied
    at the control tick (``|τ| ≤ max_torque``, no growth of ``|h|`` past ``max_momentum``) and
    reported.
``dgcmg``
    double-gimbal CMGs (ISS-style, default 4 x 4760 N m s): rotor momentum of constant magnitude
    ``h_rotor`` along the spin axis ``s(δ_o, δ_i) = sin δ_i e1 + cos δ_i (cos δ_o e3 - sin δ_o e2)``
    where ``e1`` is the body-fixed outer-gimbal axis and ``(e1, e2, e3)`` the unit's right-handed
    triad at zero angles (``e2`` the inner-gimbal axis, ``e3`` the spin axis). State: the outer
    and inner gimbal angles; held input: the gimbal rates. No gimbal stops; gimbal lock at
    ``δ_i = ±90°``.
``sgcmg_pyramid``
    four single-gimbal CMGs, gimbal axes ``g_i = (sin β cos φ_i, sin β sin φ_i, cos β)``,
    ``φ_i = 0, 90, 180, 270 deg``, skew ``β`` (53.13 deg default), spin
    ``s_i = cos δ_i s0_i + sin δ_i (g_i × s0_i)`` with ``s0_i = (-sin φ_i, cos φ_i, 0)``: Wie's
    pyramid, zero momentum at ``δ = 0``.

For the gimballed kinds ``ḣ = A(δ) δ̇`` with ``A = ∂h/∂δ`` (casadi AD). Steering laws map a
requested ``ḣ`` to gimbal rates with the normalised Jacobian ``Â = A / h_rotor``:

* ``mp``   Moore-Penrose: ``δ̇ = Âᵀ (Â Âᵀ)⁻¹ ḣ / h_rotor`` (a 1e-12 floor keeps the inverse finite
  exactly at a singularity, where the law stalls);
* ``sr``   singularity-robust: ``Âᵀ (Â Âᵀ + λ I)⁻¹``, ``λ = λ0 exp(-μ det(Â Âᵀ))``;
* ``odsr`` Wie's dithered singularity escape/avoidance (JGCD 28(5), 2005): ``Âᵀ (Â Âᵀ + λ E)⁻¹``
  with ``E = [[1, ε3, ε2], [ε3, 1, ε1], [ε2, ε1, 1]]``, ``ε_i = ε0 sin(ω t + φ_i)``,
  ``φ = (0, π/2, π)``.

The singularity measure is ``m = sqrt(det(Â Âᵀ))`` (dimensionless, 0 at a singularity).
Gimbal rates above ``max_gimbal_rate`` are scaled down together (the torque direction is kept)
and flagged, never clipped silently.

All functions take casadi SX (they build the compiled model); :func:`cluster_functions`
wraps them as numeric casadi Functions for tests and controllers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..core.linalg import inv3

__all__ = [
    "CmgModel",
    "dgcmg_triads",
    "pyramid_axes",
    "capacity",
    "steer",
    "singularity_measure",
    "rate_limit",
    "STEERING_LAWS",
    "MP_FLOOR",
    "cluster_functions",
]

#: Numerical floor added to Â Âᵀ by the Moore-Penrose law: keeps it finite at an exact
#: singularity (where it then stalls) and changes nothing measurable elsewhere (det ≥ 1e-6).
MP_FLOOR = 1e-12
STEERING_LAWS = ("mp", "sr", "odsr")
#: o-DSR dither phases (Wie 2005) [rad]
DITHER_PHASES = (0.0, math.pi / 2, math.pi)


def dgcmg_triads(outer_axes_B=None) -> np.ndarray:
    """Per unit the triad ``(e1, e2, e3)`` (outer axis, inner axis, spin at zero angles), shape (n, 3, 3).

    Default layout (4 units): outer axes ``+x, +y, -x, -y`` with spins ``+z, +x, -z, -x``: zero
    total momentum at zero gimbal angles and full 3-axis authority there (an idealised layout,
    not the ISS flight geometry). A user layout gets, per outer axis ``e1``, the spin
    ``e3 = unit(e1 × a)`` with ``a`` the coordinate axis least aligned with ``e1``.
    """
    if outer_axes_B is None:
        e1s = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
        e3s = np.array([[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]], float)
    else:
        e1s = np.array(outer_axes_B, float)
        e1s /= np.linalg.norm(e1s, axis=1, keepdims=True)
        e3s = []
        for e1 in e1s:
            a = np.eye(3)[int(np.argmin(np.abs(e1)))]
            e3 = np.cross(e1, a)
            e3s.append(e3 / np.linalg.norm(e3))
        e3s = np.array(e3s)
    e2s = np.cross(e3s, e1s)
    return np.stack([e1s, e2s, e3s], axis=1)


def pyramid_axes(skew: float) -> tuple[np.ndarray, np.ndarray]:
    """Gimbal axes ``g`` and zero-angle spin axes ``s0`` of the 4-CMG pyramid, each shape (4, 3)."""
    phi = np.deg2rad([0.0, 90.0, 180.0, 270.0])
    sb, cb = math.sin(skew), math.cos(skew)
    g = np.stack([sb * np.cos(phi), sb * np.sin(phi), np.full(4, cb)], axis=1)
    s0 = np.stack([-np.sin(phi), np.cos(phi), np.zeros(4)], axis=1)
    return g, s0


def capacity(cfg) -> float:
    """Momentum capacity of the cluster [N m s]: the largest ``|h|`` flagged as saturation refers to it.

    ideal: ``max_momentum`` (inf when unlimited); dgcmg: ``n h_rotor`` (spherical envelope);
    pyramid: ``h_rotor min(2 + 2 cos β, 4 sin β)``, the envelope along x/y and along z
    (3.2 h_rotor at 53.13 deg, where the envelope is nearly spherical).
    """
    if cfg.kind == "ideal":
        return math.inf if cfg.max_momentum is None else cfg.max_momentum
    if cfg.kind == "dgcmg":
        return cfg.n_units * cfg.h_rotor
    return cfg.h_rotor * min(2 + 2 * math.cos(cfg.skew), 4 * math.sin(cfg.skew))


def singularity_measure(A_hat):
    """``sqrt(det(Â Âᵀ))`` for the normalised Jacobian (casadi)."""
    return ca.sqrt(ca.fmax(ca.det(ca.mtimes(A_hat, A_hat.T)), 0.0))


def steer(law: str, A_hat, hdot_hat, t, lambda0, mu, eps0, omega):
    """Gimbal rates [rad/s] for the requested ``ḣ / h_rotor`` [1/s] (casadi), by ``law``."""
    M = ca.mtimes(A_hat, A_hat.T)
    if law == "mp":
        reg = MP_FLOOR * ca.SX.eye(3)
    else:
        lam = lambda0 * ca.exp(-mu * ca.det(M))
        if law == "sr":
            reg = lam * ca.SX.eye(3)
        elif law == "odsr":
            e1, e2, e3 = (eps0 * ca.sin(omega * t + ph) for ph in DITHER_PHASES)
            E = ca.vertcat(ca.horzcat(1, e3, e2), ca.horzcat(e3, 1, e1), ca.horzcat(e2, e1, 1))
            reg = lam * E
        else:
            raise ValueError(f"unknown steering law {law!r}; valid: {', '.join(STEERING_LAWS)}")
    return ca.mtimes(A_hat.T, ca.mtimes(inv3(M + reg), hdot_hat))


def rate_limit(rates, max_rate):
    """Scale ``rates`` down together so that ``max|rate| ≤ max_rate``; returns ``(rates, limited 0/1)``."""
    peak = ca.mmax(ca.fabs(rates))
    scale = ca.fmin(1.0, max_rate / ca.fmax(peak, 1e-300))
    return rates * scale, ca.if_else(scale < 1.0, 1.0, 0.0)


@dataclass(frozen=True)
class CmgModel:
    """The cluster's symbolic model for one scene structure (kind, count, steering law).

    Parameter vector (``n_par`` values, filled by :meth:`params`): ``h_rotor`` or ``max_torque``,
    then limits and steering constants, then the geometry.
    """

    kind: str
    n_units: int
    steering: str

    # -- layout ----------------------------------------------------------------------
    @property
    def n_gimbals(self) -> int:
        return {"ideal": 0, "dgcmg": 2 * self.n_units, "sgcmg_pyramid": self.n_units}[self.kind]

    @property
    def nx(self) -> int:
        """State size: h (ideal) or the gimbal angles."""
        return 3 if self.kind == "ideal" else self.n_gimbals

    @property
    def nu(self) -> int:
        """Held input size: torque command (ideal) or gimbal rates."""
        return 3 if self.kind == "ideal" else self.n_gimbals

    @property
    def state_names(self) -> tuple[str, ...]:
        if self.kind == "ideal":
            return ("hx", "hy", "hz")
        return tuple(self.gimbal_names)

    @property
    def gimbal_names(self) -> list[str]:
        if self.kind == "dgcmg":
            return [f"gimbal_{i + 1}_{w}" for i in range(self.n_units) for w in ("outer", "inner")]
        if self.kind == "sgcmg_pyramid":
            return [f"gimbal_{i + 1}" for i in range(self.n_units)]
        return []

    @property
    def n_par(self) -> int:
        geo = {"ideal": 0, "dgcmg": 9 * self.n_units, "sgcmg_pyramid": 6 * self.n_units}[self.kind]
        return 7 + geo

    def params(self, cfg) -> np.ndarray:
        """Numbers of the scene's ``[cmg]`` table in the layout of :attr:`n_par`."""
        big = 1e300
        if self.kind == "ideal":
            head = [
                cfg.max_torque or big,
                cfg.max_momentum or big,
                cfg.saturation_fraction,
                0.0,
                0.0,
                0.0,
                0.0,
            ]
            return np.array(head)
        head = [
            cfg.h_rotor,
            cfg.max_gimbal_rate,
            cfg.saturation_fraction * capacity(cfg),
            cfg.sr_lambda0,
            cfg.sr_mu,
            cfg.dither_eps0,
            cfg.dither_omega,
        ]
        if self.kind == "dgcmg":
            geo = dgcmg_triads(cfg.outer_axes_B).ravel()
        else:
            g, s0 = pyramid_axes(cfg.skew)
            geo = np.concatenate([g, s0], axis=1).ravel()
        return np.concatenate([head, geo])

    def initial_state(self, cfg) -> np.ndarray:
        if self.kind == "ideal":
            return np.array(cfg.h0_B, float)
        return np.array(cfg.gimbal0 if cfg.gimbal0 is not None else np.zeros(self.n_gimbals), float)

    # -- symbols -----------------------------------------------------------------------
    def _spins(self, xc, pc):
        """Per unit: the unit spin axis (B) and its derivatives by the unit's gimbal angle(s)."""
        geo = pc[7:]
        out = []
        for i in range(self.n_units):
            if self.kind == "dgcmg":
                e = geo[9 * i : 9 * i + 9]
                e1, e2, e3 = e[0:3], e[3:6], e[6:9]
                so, co = ca.sin(xc[2 * i]), ca.cos(xc[2 * i])
                si, ci = ca.sin(xc[2 * i + 1]), ca.cos(xc[2 * i + 1])
                r = co * e3 - so * e2  # e3 turned about the outer axis
                spin = si * e1 + ci * r
                out.append((spin, [ci * (-so * e3 - co * e2), ci * e1 - si * r]))
            else:
                e = geo[6 * i : 6 * i + 6]
                g, s0 = e[0:3], e[3:6]
                gs = ca.cross(g, s0)
                s, c = ca.sin(xc[i]), ca.cos(xc[i])
                out.append((c * s0 + s * gs, [-s * s0 + c * gs]))
        return out

    def h(self, xc, pc):
        """Cluster momentum relative to the body, B components [N m s]."""
        if self.kind == "ideal":
            return xc
        spins = [s for s, _ in self._spins(xc, pc)]
        return pc[0] * sum(spins[1:], spins[0])

    def A_hat(self, xc, pc):
        """Normalised Jacobian ``∂h/∂δ / h_rotor`` (analytic), shape (3, n_gimbals)."""
        return ca.horzcat(*[d for _, ds in self._spins(xc, pc) for d in ds])

    def h_dot(self, xc, uc, w, pc):
        """Body-frame derivative of h [N m]: ``-τ - ω × h`` (ideal) or ``A δ̇``."""
        if self.kind == "ideal":
            return -uc - ca.cross(w, xc)
        return pc[0] * ca.mtimes(self.A_hat(xc, pc), uc)

    def state_dot(self, xc, uc, w, pc):
        return self.h_dot(xc, uc, w, pc) if self.kind == "ideal" else uc

    def actuate(self, t, xc, tau_cmd, w, pc, direct_rates=None):
        """The held input for one control period, from a body-torque request (or direct rates).

        Returns ``(u_held, singularity, rate_limited, momentum_saturated)``; the flags are 0/1.
        ``w`` is omega_BN_B at the tick (the ``ω × h`` compensation of the torque request).
        """
        if self.kind == "ideal":
            max_tau, max_h, frac = pc[0], pc[1], pc[2]
            n = ca.norm_2(tau_cmd)
            scale = ca.fmin(1.0, max_tau / ca.fmax(n, 1e-300))
            tau = tau_cmd * scale
            limited = ca.if_else(scale < 1.0, 1.0, 0.0)
            h = xc
            hn = ca.norm_2(h)
            # store full and the request would fill it further (dh/dt·h = -τ·h > 0): drop that part
            full = ca.logic_and(hn >= max_h, ca.dot(tau, h) < 0)
            h_hat = h / ca.fmax(hn, 1e-300)
            tau = ca.if_else(full, tau - ca.dot(tau, h_hat) * h_hat, tau)
            sat = ca.if_else(ca.logic_or(full, hn >= frac * max_h), 1.0, 0.0)
            return tau, 1.0, limited, sat
        h_rotor, max_rate, h_sat, lam0, mu, eps0, om = (pc[i] for i in range(7))
        A_hat = self.A_hat(xc, pc)
        if direct_rates is None:
            hdot_cmd = -tau_cmd - ca.cross(w, self.h(xc, pc))
            rates = steer(self.steering, A_hat, hdot_cmd / h_rotor, t, lam0, mu, eps0, om)
        else:
            rates = direct_rates
        rates, limited = rate_limit(rates, max_rate)
        sat = ca.if_else(ca.norm_2(self.h(xc, pc)) >= h_sat, 1.0, 0.0)
        return rates, singularity_measure(A_hat), limited, sat


def cluster_functions(cfg) -> dict[str, ca.Function]:
    """Numeric casadi Functions of a scene's ``[cmg]`` table (for tests and controllers).

    ``h(x) -> h_B``; ``A(x) -> ∂h/∂x`` (gimballed: [N m s/rad]); ``actuate(t, x, tau, w) ->
    (u, m, rate_limited, saturated)``. Parameters are baked in.
    """
    model = CmgModel(cfg.kind, cfg.n_units, cfg.steering)
    p = ca.DM(model.params(cfg))
    x = ca.SX.sym("x", model.nx)
    tau = ca.SX.sym("tau", 3)
    w = ca.SX.sym("w", 3)
    t = ca.SX.sym("t")
    h = model.h(x, p)
    out = {
        "h": ca.Function("h", [x], [h]),
        "actuate": ca.Function("actuate", [t, x, tau, w], list(model.actuate(t, x, tau, w, p))),
    }
    if model.kind != "ideal":
        out["A"] = ca.Function("A", [x], [cfg.h_rotor * model.A_hat(x, p)])
    return out
