"""Steering laws of a gimballed CMG cluster, the gimbal-rate limit and the singularity measure.

A law maps a requested ``ḣ`` to gimbal rates with the normalised Jacobian ``Â = A / h_rotor``
(``A = ∂h/∂δ``, shape (3, n_gimbals)):

* ``mp``   Moore-Penrose: ``δ̇ = Âᵀ (Â Âᵀ)⁻¹ ḣ / h_rotor`` (a 1e-12 floor keeps the inverse finite
  exactly at a singularity, where the law stalls);
* ``sr``   singularity-robust: ``Âᵀ (Â Âᵀ + λ I)⁻¹``, ``λ = λ0 exp(-μ det(Â Âᵀ))``;
* ``odsr`` Wie's dithered singularity escape/avoidance (JGCD 28(5), 2005): ``Âᵀ (Â Âᵀ + λ E)⁻¹``
  with ``E = [[1, ε3, ε2], [ε3, 1, ε1], [ε2, ε1, 1]]``, ``ε_i = ε0 sin(ω t + φ_i)``,
  ``φ = (0, π/2, π)``.

The singularity measure is ``m = sqrt(det(Â Âᵀ))`` (dimensionless, 0 at a singularity).
Gimbal rates above ``max_gimbal_rate`` are scaled down together (the torque direction is kept)
and flagged, never clipped silently. All functions build casadi SX expressions.
"""

from __future__ import annotations

import math

import casadi as ca

from ...core.linalg import inv3

__all__ = ["steer", "rate_limit", "singularity_measure", "STEERING_LAWS", "MP_FLOOR", "DITHER_PHASES"]

#: Numerical floor added to Â Âᵀ by the Moore-Penrose law: keeps it finite at an exact
#: singularity (where it then stalls) and changes nothing measurable elsewhere (det ≥ 1e-6).
MP_FLOOR = 1e-12
#: the laws a scene may name (``[cmg] steering``)
STEERING_LAWS = ("mp", "sr", "odsr")
#: o-DSR dither phases (Wie 2005) [rad]
DITHER_PHASES = (0.0, math.pi / 2, math.pi)


def singularity_measure(A_hat):
    """``sqrt(det(Â Âᵀ))`` of the normalised Jacobian (casadi).

    Parameters
    ----------
    A_hat : casadi SX, shape (3, n_gimbals)  ``∂h/∂δ / h_rotor`` [1/rad].

    Returns
    -------
    casadi SX scalar  Dimensionless, 0 at a singular configuration.
    """
    return ca.sqrt(ca.fmax(ca.det(ca.mtimes(A_hat, A_hat.T)), 0.0))


def steer(law: str, A_hat, hdot_hat, t, lambda0, mu, eps0, omega):
    """Gimbal rates for a requested momentum rate, by ``law`` (casadi).

    Parameters
    ----------
    law : str  One of :data:`STEERING_LAWS`.
    A_hat : casadi SX, shape (3, n_gimbals)  Normalised Jacobian ``∂h/∂δ / h_rotor`` [1/rad].
    hdot_hat : casadi SX, shape (3, 1)  Requested ``ḣ / h_rotor``, B components [1/s].
    t : casadi SX  Time [s] (the o-DSR dither).
    lambda0, mu : casadi SX  SR gain scale [-] and its decay with ``det(Â Âᵀ)`` [-].
    eps0, omega : casadi SX  o-DSR dither amplitude [-] and frequency [rad/s].

    Returns
    -------
    casadi SX, shape (n_gimbals, 1)  Gimbal rates [rad/s].
    """
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
    """Scale ``rates`` down together so that ``max|rate| ≤ max_rate`` (casadi).

    Parameters
    ----------
    rates : casadi SX, shape (n, 1)  Gimbal rates [rad/s].
    max_rate : casadi SX  Largest allowed rate of any gimbal [rad/s].

    Returns
    -------
    rates : casadi SX, shape (n, 1)  The scaled rates [rad/s] (direction kept).
    limited : casadi SX  1 if they were scaled, else 0.
    """
    peak = ca.mmax(ca.fabs(rates))
    # = fmin(1, max_rate / peak), with an exact derivative (1) inside the limit, zero rates
    # included (stationbed.analysis differentiates the actuation)
    scale = ca.if_else(peak > max_rate, max_rate / peak, 1.0)
    return rates * scale, ca.if_else(scale < 1.0, 1.0, 0.0)
