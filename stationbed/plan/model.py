"""The rotational model a plan is optimised on (casadi expressions, numpy too).

A rigid station (the scene's composite inertia about its mass centre at t = 0: the arrays frozen),
a CMG momentum store ``h`` and the point-mass gravity gradient, flown by the ISS-style law
(Bhatt 2007; PSOPT ``examples/zpm``) that tracks a commanded attitude ``C``:

    τ_B = -J (kp ε + kd ω̃),   ε = 2 vec(conj(q_CR) ⊗ q_BR),   ω̃ = ω_BN_B - C_CR ω_RN_R

(ε is the attitude error of B relative to C; ω̃ compares the body rate with the commanded frame's
rate, in their own components, as the ISS law does), with R the reference frame (LVLH, turning at
``ω_ON_O = (0, -n, 0)`` on a circular orbit, or N). The equations, stationbed's conventions
(DESIGN §3-4; the same as the simulator's momentum form with an ideal cluster):

    q̇_BR = ½ q_BR ⊗ (0, ω_BN_B - C_BR ω_RN_R)
    J ω̇ = L + τ - ω × J ω,   L = L_gg + L_B,   L_gg = 3 n² r̂_B × J r̂_B,  r̂_B = C_BR r̂_R
    ḣ = -τ - ω × h                      (the store delivers exactly τ to the body: the total
                                          H = J ω + h obeys Ḣ|_B = L - ω × H)

with ``L_B`` the scene's other torques known as functions of time (constant windows, orbital
harmonics: PSOPT's aerodynamic model is one).

PSOPT's ``dae`` writes the same with ``u = -τ`` (its ``hdot = u - ω × h``, ``J ω̇ = τ_d - ω × Jω - u``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..core.rotation import dcm, quat_conj, quat_mult

__all__ = ["Rotational", "rates", "law_torque"]


@dataclass(frozen=True)
class Rotational:
    """The numbers of the model.

    J : (3, 3)  Inertia about the mass centre, B axes [kg m²].
    w_RN_R : (3,)  Angular velocity of the reference frame R relative to N, R components [rad/s].
    n2 : float  ``mu / R³`` [rad²/s²] (0: no gravity gradient).
    kp : float [1/s²] ; kd : float [1/s]  Gains of the law.
    """

    J: np.ndarray
    w_RN_R: np.ndarray
    n2: float
    kp: float
    kd: float


def _cross(a, b):
    return ca.cross(a, b) if isinstance(a, (ca.SX, ca.MX)) or isinstance(b, (ca.SX, ca.MX)) else np.cross(a, b)


def _mv(M, v):
    return ca.mtimes(M, v) if isinstance(v, (ca.SX, ca.MX)) or isinstance(M, (ca.SX, ca.MX)) else M @ v


def law_torque(q_BR, omega_BN_B, q_CR, m: Rotational):
    """``τ_B = -J (kp ε + kd ω̃)`` [N m], B components (see the module docstring). ``q_BR`` is
    normalised first: off-unit quaternions (the collocation's band) do not change the law."""
    norm = ca.norm_2(q_BR) if isinstance(q_BR, (ca.SX, ca.MX)) else np.linalg.norm(q_BR)
    e = quat_mult(quat_conj(q_CR), q_BR / norm)
    eps = 2.0 * e[1:4]
    w_tilde = omega_BN_B - _mv(dcm(q_CR), m.w_RN_R)
    return -_mv(m.J, m.kp * eps + m.kd * w_tilde)


def rates(q_BR, omega_BN_B, h_B, q_CR, r_hat_R, m: Rotational, L_B=None):
    """``(q̇_BR, ω̇_BN_B, ḣ_B, τ_B)`` of the model.

    Parameters
    ----------
    q_BR : (4,)  Attitude of B relative to R, scalar first.
    omega_BN_B : (3,)  Body rate relative to N, B components [rad/s].
    h_B : (3,)  CMG momentum, B components [N m s].
    q_CR : (4,)  Commanded attitude relative to R.
    r_hat_R : (3,)  Unit vector to (or from) the Earth's centre, R components.
    m : Rotational
    L_B : (3,), optional  Other external torque (known in time: the scene's constant and
        orbital-harmonic torques), B components [N m].
    """
    C_BR = dcm(q_BR)
    w_BR_B = omega_BN_B - _mv(C_BR, m.w_RN_R)
    zero = 0.0 * w_BR_B[0]
    q_dot = 0.5 * quat_mult(q_BR, _vec4(zero, w_BR_B))
    tau = law_torque(q_BR, omega_BN_B, q_CR, m)
    r_B = _mv(C_BR, r_hat_R)
    L_gg = 3.0 * m.n2 * _cross(r_B, _mv(m.J, r_B))
    L = L_gg if L_B is None else L_gg + L_B
    w_dot = _mv(np.linalg.inv(m.J), L + tau - _cross(omega_BN_B, _mv(m.J, omega_BN_B)))
    h_dot = -tau - _cross(omega_BN_B, h_B)
    return q_dot, w_dot, h_dot, tau


def _vec4(s, v):
    if isinstance(v, (ca.SX, ca.MX)):
        return ca.vertcat(s, v)
    return np.concatenate([[s], v])
