"""Articulated arrays: angle profiles, ``Ap(alpha, beta) = C_PB``, relative rates, sun tracking.

A profile is ``a0 + rate t + amp sin(freq t + phase) + Σ_k delta_k max(0, t - t_k)`` [rad]: the
last terms are instantaneous rate steps (impulses). Its first and second derivatives are
analytic. Functions accept numpy or casadi ``t`` and coefficient vectors, so the same code
builds the equations of motion and evaluates the trajectory's angle columns.

Sun tracking: the array's sun-facing normal is ``+z`` of P. With the sun ``s_B`` in B and
``C_PB = Ax(β) Ay(α)``, the normal points at the sun (``C_PB s_B = ẑ``) for
``α* = atan2(s_x, s_z)``, ``β* = atan2(-v_y, v_z)``, ``v = Ay(α) s_B`` (with ``α = α*``,
``β* = -asin(s_y)``). A SARJ/BGA drive follows the target with a rate loop that bounds the rate
and the acceleration (:func:`drive_acceleration`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.symbolic import is_symbolic
from ..core.rotation import Ap, Ay, omega_PB_P, omega_PB_P_dot

__all__ = [
    "profile",
    "joint_kinematics",
    "sun_targets",
    "drive_acceleration",
    "wrap_angle",
    "tracking_error",
    "drive_from_error",
    "glider_error",
]


def profile(t, c, n_steps: int = 0, t_switch=None):
    """Angle, rate and acceleration of a joint-angle profile at ``t``.

    ``n_steps`` rate steps ``(t_k, d_k)`` follow the five profile coefficients. The new rate
    holds where ``t_switch >= t_k`` (``t_switch`` defaults to ``t``: right-continuous). The
    integrators pass the time of the segment being integrated, so every stage of a step that
    ends (or starts) on ``t_k`` sees one side only.

    Parameters
    ----------
    t : float, ndarray or casadi SX  Time [s].
    c : sequence or casadi SX, shape (5 + 2 n_steps,)  ``(a0 [rad], rate [rad/s], amp [rad],
        freq [rad/s], phase [rad], t_1 [s], d_1 [rad/s], ...)``.
    n_steps : int  Number of rate steps.
    t_switch : float or casadi SX, optional  The time that decides the side of each step [s].

    Returns
    -------
    angle, rate, acceleration : [rad], [rad/s], [rad/s²] (same type as ``t``)
    """
    a0, rate, amp, freq, phase = c[0], c[1], c[2], c[3], c[4]
    arg = freq * t + phase
    sym = is_symbolic(t, c)
    if sym:
        s, co = ca.sin(arg), ca.cos(arg)
    else:
        s, co = np.sin(arg), np.cos(arg)
    angle = a0 + rate * t + amp * s
    rate_t = rate + amp * freq * co
    ts = t if t_switch is None else t_switch
    for k in range(n_steps):
        tk, dk = c[5 + 2 * k], c[6 + 2 * k]
        if sym or is_symbolic(ts):
            after = ca.if_else(ts >= tk, 1.0, 0.0)
            # angle continuous; its slope is the side's rate (so d(angle)/dt = rate in a segment)
            angle = angle + dk * ca.if_else(ts >= tk, t - tk, 0.0)
            rate_t = rate_t + dk * after
        else:
            after = np.asarray(ts) >= tk
            angle = angle + dk * np.where(after, t - tk, 0.0)
            rate_t = rate_t + dk * after
    return (angle, rate_t, -amp * freq * freq * s)


def wrap_angle(a):
    """Angle wrapped to (-π, π].

    Parameters
    ----------
    a : float, ndarray or casadi SX  Angle [rad].

    Returns
    -------
    Same type as ``a`` [rad].
    """
    if is_symbolic(a):
        return ca.atan2(ca.sin(a), ca.cos(a))
    return np.arctan2(np.sin(a), np.cos(a))


def sun_targets(s_B, alpha):
    """Target angles pointing the array normal (+z of P) at the sun.

    ``β*`` is computed for the actual ``alpha`` (best normal for the SARJ where it is).

    Parameters
    ----------
    s_B : ndarray or casadi SX, shape (3,)  Unit vector to the sun, B components.
    alpha : float or casadi SX  The SARJ angle α [rad].

    Returns
    -------
    a_star, b_star : targets α*, β* [rad]
    """
    atan2 = ca.atan2 if is_symbolic(s_B, alpha) else np.arctan2
    a_star = atan2(s_B[0], s_B[2])
    v = Ay(alpha) @ s_B if not is_symbolic(s_B, alpha) else ca.mtimes(Ay(alpha), s_B)
    return a_star, atan2(-v[1], v[2])


def drive_acceleration(theta, theta_dot, target, target_rate, drive):
    """SARJ/BGA drive law: joint acceleration [rad/s²] (casadi).

    Parameters
    ----------
    theta, theta_dot : casadi SX  Joint angle [rad] and rate [rad/s].
    target : casadi SX or tuple (Y, X)  Target angle θ* [rad] (see below).
    target_rate : casadi SX  θ̇* [rad/s].
    drive : casadi SX, shape (4,)  ``(max_rate [rad/s], max_acc [rad/s²], gain [1/s], rate_tau [s])``.

    Notes
    -----
    ``rate_cmd = clip(gain wrap(θ* - θ) + θ̇*, ±max_rate)``;
    ``θ̈ = clip((rate_cmd - θ̇) / rate_tau, ±max_acc)``. ``drive = (max_rate, max_acc, gain,
    rate_tau)``. ``target`` is the target angle θ*, or the pair ``(Y, X)`` with θ* = atan2(Y, X):
    then the wrapped error is one ``atan2(Y cos θ - X sin θ, X cos θ + Y sin θ)`` (cos θ, sin θ
    are shared with C_PB), instead of atan2, sin, cos and atan2 again - the drives' trigonometry
    is a large part of a right-hand side's cost.
    """
    if isinstance(target, tuple):
        Y, X = target
        c, s = ca.cos(theta), ca.sin(theta)
        err = ca.atan2(Y * c - X * s, X * c + Y * s)
    else:
        err = wrap_angle(target - theta)
    return drive_from_error(err, theta_dot, target_rate, drive)


def drive_from_error(err, theta_dot, target_rate, drive):
    """The drive law of :func:`drive_acceleration` from the wrapped angle error ``err`` [rad]."""
    max_rate, max_acc, gain, tau = drive[0], drive[1], drive[2], drive[3]
    rate_cmd = ca.fmin(ca.fmax(gain * err + target_rate, -max_rate), max_rate)
    return ca.fmin(ca.fmax((rate_cmd - theta_dot) / tau, -max_acc), max_acc)


def glider_error(theta, v, joint: int):
    """Angle error [rad] to the nearer edge-on angle of a joint (night glider), in (-π/2, π/2].

    Parameters
    ----------
    theta : casadi SX  The joint angle [rad].
    v : casadi SX, shape (3, 1)  The air-relative velocity in the joint's base frame: B for the
        SARJ (``joint = 0``, turning about y), ``Ay(alpha) v_B`` for the BGA (``joint = 1``,
        turning about x).
    joint : int  0 (alpha) or 1 (beta).

    Notes
    -----
    The array normal (+z of P) is perpendicular to the flow at ``θ* = atan2(Y, X)`` with
    ``(Y, X) = (v_z, -v_x)`` (alpha) or ``(v_z, v_y)`` (beta): the sun targets' formulas turned by
    90 deg. Either side of the plate is edge-on, so the error is taken modulo π:
    ``½ atan2(2 S C, C² - S²)`` with ``(S, C)`` the (unnormalised) sine and cosine of the error.
    """
    Y, X = (v[2], -v[0]) if joint == 0 else (v[2], v[1])
    c, s = ca.cos(theta), ca.sin(theta)
    S, C = Y * c - X * s, X * c + Y * s
    return 0.5 * ca.atan2(2 * S * C, C * C - S * S)


def tracking_error(C_PB, s_B):
    """Angle between the array normal (+z of P) and the sun (numpy).

    Parameters
    ----------
    C_PB : ndarray, shape (..., 3, 3)  DCM from B to the array frame P.
    s_B : ndarray, shape (..., 3)  Unit vector to the sun, B components.

    Returns
    -------
    ndarray, shape (...)  [rad].
    """
    n_B = np.asarray(C_PB)[..., 2, :]  # third row of C_PB: P's z axis in B components
    c = np.sum(n_B * s_B, axis=-1)
    s = np.linalg.norm(np.cross(n_B, s_B), axis=-1)
    return np.arctan2(s, c)


def joint_kinematics(t, c_alpha, c_beta, n_steps=(0, 0), states=(None, None), t_switch=None):
    """``C_PB``, ``omega_PB_P`` and its derivative at time ``t``.

    Each joint follows its profile coefficients (``c_alpha``/``c_beta`` with ``n_steps`` rate
    steps), unless ``states`` gives it an ``(angle, rate, acceleration)`` triple (a driven joint;
    the acceleration may be None when not needed, then ``omega_PB_P_dot`` is None).

    Parameters
    ----------
    t : float or casadi SX  Time [s].
    c_alpha, c_beta : casadi SX  Profile coefficients of each joint (see :func:`profile`).
    n_steps : tuple of int  Rate steps of each profile.
    states : tuple  Per joint None (profile) or ``(angle [rad], rate [rad/s], accel [rad/s²] or None)``.
    t_switch : casadi SX, optional  The time that decides the side of a rate step [s].

    Returns
    -------
    C_PB : (3, 3)  DCM from B to the array frame P.
    omega_PB_P : (3,)  Rate of P relative to B, P components [rad/s].
    omega_PB_P_dot : (3,) or None  Its time derivative [rad/s²] (same in P or, rotated, in B).
    angles : tuple (alpha, beta) [rad]
    """
    a, ad, add = states[0] if states[0] is not None else profile(t, c_alpha, n_steps[0], t_switch)
    b, bd, bdd = states[1] if states[1] is not None else profile(t, c_beta, n_steps[1], t_switch)
    wd = None if (add is None or bdd is None) else omega_PB_P_dot(a, b, ad, bd, add, bdd)
    return (Ap(a, b), omega_PB_P(a, b, ad, bd), wd, (a, b))
