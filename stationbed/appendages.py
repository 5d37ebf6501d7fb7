"""Articulated arrays: angle profiles, ``Ap(alpha, beta) = C_PB``, relative rates.

A profile is ``a0 + rate t + amp sin(freq t + phase)`` [rad]; its first and second derivatives
are analytic. Functions accept numpy or casadi ``t`` and coefficient vectors, so the same code
builds the equations of motion and evaluates the trajectory's angle columns.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .rotation import Ap, omega_PB_P, omega_PB_P_dot

__all__ = ["profile", "joint_kinematics"]


def profile(t, c):
    """Angle, rate and acceleration of ``c = (a0, rate, amp, freq, phase)`` at time ``t``."""
    a0, rate, amp, freq, phase = c[0], c[1], c[2], c[3], c[4]
    arg = freq * t + phase
    if isinstance(t, (ca.SX, ca.MX)) or isinstance(c, (ca.SX, ca.MX)):
        s, co = ca.sin(arg), ca.cos(arg)
    else:
        s, co = np.sin(arg), np.cos(arg)
    return (a0 + rate * t + amp * s, rate + amp * freq * co, -amp * freq * freq * s)


def joint_kinematics(t, c_alpha, c_beta):
    """``C_PB``, ``omega_PB_P`` and its derivative for profiled gimbal angles at time ``t``.

    Returns
    -------
    C_PB : (3,3)  DCM from B to the array frame P.
    omega_PB_P : (3,)  Rate of P relative to B, P components [rad/s].
    omega_PB_P_dot : (3,)  Its time derivative [rad/s²] (same in P or, rotated, in B).
    angles : tuple (alpha, beta) [rad]
    """
    a, ad, add = profile(t, c_alpha)
    b, bd, bdd = profile(t, c_beta)
    return (
        Ap(a, b),
        omega_PB_P(a, b, ad, bd),
        omega_PB_P_dot(a, b, ad, bd, add, bdd),
        (a, b),
    )
