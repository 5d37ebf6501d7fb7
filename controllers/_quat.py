"""Quaternion helpers on plain Python floats (scalar first, stationbed's conventions).

A controller runs every tick (55 536 times per orbit at 10 Hz): numpy's per-call overhead on
3- and 4-vectors would cost more than the dynamics, so the shipped laws use these.
``dcm(a ⊗ b) = dcm(b) @ dcm(a)`` (passive DCMs), so ``q_RN = q_ON ⊗ q_RO`` and the error of B
relative to R is ``q_BR = conj(q_RN) ⊗ q_BN``.
"""

from __future__ import annotations

import math


def qmul(p, q):
    """Hamilton product ``p ⊗ q``."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def lvlh_rate_varies(plant) -> bool:
    """Whether the LVLH frame turns at a varying rate (a two-body orbit, ``[orbit] r_N``/``elements``).

    On a circular orbit LVLH turns at the constant ``(0, -n, 0)``, which a law may compute once;
    on any other orbit it reads the measured ``meas.omega_ON_O`` every tick (``(0, -h/r², 0)``,
    plus the node's drift with J2).
    """
    orbit = getattr(plant.scene, "orbit", None)
    return bool(orbit is not None and getattr(orbit, "kepler", False))


def qconj(q):
    return (q[0], -q[1], -q[2], -q[3])


def rotate(q, v):
    """``dcm(q) @ v``: components in the rotated frame of a vector given in the reference frame."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 (q_v × v); C v = v - w t + q_v × t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx - w * tx + (y * tz - z * ty),
        vy - w * ty + (z * tx - x * tz),
        vz - w * tz + (x * ty - y * tx),
    )


def matvec(M, v):
    return (
        M[0][0] * v[0] + M[0][1] * v[1] + M[0][2] * v[2],
        M[1][0] * v[0] + M[1][1] * v[1] + M[1][2] * v[2],
        M[2][0] * v[0] + M[2][1] * v[1] + M[2][2] * v[2],
    )


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def error_angle(q_err) -> float:
    """Principal angle [rad] of an error quaternion."""
    s = math.sqrt(q_err[1] ** 2 + q_err[2] ** 2 + q_err[3] ** 2)
    return 2.0 * math.atan2(s, abs(q_err[0]))


def lvlh_error(q_BN, omega_BN_B, q_RN, w_RN_R):
    """``(theta, domega)`` of the design model from a measurement, on floats (runs every tick).

    ``q_BR = conj(q_RN) ⊗ q_BN`` with its scalar part made ≥ 0 (the short way round),
    ``theta = 2 vec(q_BR)`` [rad], ``domega = omega_BN_B - C_BR omega_RN_R`` [rad/s].
    """
    qw, qx, qy, qz = q_BN
    rw, rx, ry, rz = q_RN
    ew = rw * qw + rx * qx + ry * qy + rz * qz
    ex = rw * qx - rx * qw - ry * qz + rz * qy
    ey = rw * qy + rx * qz - ry * qw - rz * qx
    ez = rw * qz - rx * qy + ry * qx - rz * qw
    if ew < 0.0:
        ew, ex, ey, ez = -ew, -ex, -ey, -ez
    vx, vy, vz = w_RN_R
    # C_BR v = v - w t + e × t, t = 2 e × v (controllers/_quat.rotate, inlined)
    tx = 2.0 * (ey * vz - ez * vy)
    ty = 2.0 * (ez * vx - ex * vz)
    tz = 2.0 * (ex * vy - ey * vx)
    wx, wy, wz = omega_BN_B
    return (
        2.0 * ex,
        2.0 * ey,
        2.0 * ez,
        wx - (vx - ew * tx + (ey * tz - ez * ty)),
        wy - (vy - ew * ty + (ez * tx - ex * tz)),
        wz - (vz - ew * tz + (ex * ty - ey * tx)),
    )
