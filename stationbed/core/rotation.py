"""Rotation math: quaternions, direction cosine matrices, cross-product matrices, Ax/Ay/Ap.

Pure functions, no state. Every function works on numpy arrays *and* on casadi SX/MX
expressions (the formulations build their equations from the same code), so only
operations both support are used here.

Conventions (DESIGN §3)
-----------------------
* ``C_XY`` maps Y components into X components: ``v_X = C_XY @ v_Y``.
* ``q_BN = (w, x, y, z)``, scalar first. ``C_BN = dcm(q_BN)`` and ``C_NB = C_BN.T`` is what
  ``scipy.spatial.transform.Rotation.from_quat([x, y, z, w]).as_matrix()`` returns.
* Kinematics: ``q_dot = 0.5 * q ⊗ (0, omega_BN_B)`` (Hamilton product).
* ``Ay(a)`` and ``Ax(b)`` are the TP-2511 Eq. 35-38 frame rotations, ``Ap = C_PB = Ax(beta) Ay(alpha)``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .linalg import row_norms
from .rotation_batch import dcm_batch, quat_mult_batch
from .symbolic import is_symbolic, matrix, trig, vector

__all__ = [
    "skew",
    "quat_mult",
    "quat_conj",
    "dcm",
    "quat_from_dcm",
    "quat_kinematics",
    "Ax",
    "Ay",
    "Ap",
    "omega_PB_P",
    "omega_PB_P_dot",
    "rotation_angle",
    "rotation_vector",
    "rotation_angle_vector",
    "euler_321",
]


def skew(v):
    """Cross-product matrix: ``skew(a) @ b == a x b``.

    Quinn's tilde (seed 000, Eq. 8b) is the transpose of this matrix.
    """
    return matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], v)


def quat_mult(p, q):
    """Hamilton product ``p ⊗ q`` of scalar-first quaternions (component-first (4, n) arrays:
    n products at once, :mod:`.rotation_batch`)."""
    if (p.__class__ is np.ndarray and q.__class__ is np.ndarray and p.ndim == q.ndim == 2
            and p.dtype == q.dtype == float):
        return quat_mult_batch(p, q)
    pw, px, py, pz = p[0], p[1], p[2], p[3]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    return vector(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        p if is_symbolic(p) else q,
    )


def quat_conj(q):
    """Conjugate ``(w, -x, -y, -z)`` of a scalar-first quaternion (numpy or casadi); for a unit
    quaternion its inverse."""
    return vector([q[0], -q[1], -q[2], -q[3]], q)


def dcm(q_BN):
    """Direction cosine matrix ``C_BN`` of the Euler parameters ``q_BN = (w, x, y, z)``.

    The quaternion need not be normalised: the result is divided by ``|q|²`` so that a
    slightly off-norm integrator state still yields an orthogonal matrix. A (4, n) array gives
    (3, 3, n) (:mod:`.rotation_batch`).
    """
    if q_BN.__class__ is np.ndarray and q_BN.ndim == 2 and q_BN.dtype == float:
        return dcm_batch(q_BN)
    w, x, y, z = q_BN[0], q_BN[1], q_BN[2], q_BN[3]
    n2 = w * w + x * x + y * y + z * z
    s = 2.0 / n2
    # C_NB (body -> inertial), the usual Hamilton rotation matrix; return its transpose.
    return matrix(
        [
            [1 - s * (y * y + z * z), s * (x * y + w * z), s * (x * z - w * y)],
            [s * (x * y - w * z), 1 - s * (x * x + z * z), s * (y * z + w * x)],
            [s * (x * z + w * y), s * (y * z - w * x), 1 - s * (x * x + y * y)],
        ],
        q_BN,
    )


def quat_from_dcm(C_BN: np.ndarray) -> np.ndarray:
    """Scalar-first ``q_BN`` with ``w >= 0`` from ``C_BN`` (Shepperd's method, numpy only)."""
    C = np.asarray(C_BN, dtype=float).T  # C_NB, the active rotation matrix
    tr = np.trace(C)
    cand = np.array([tr, C[0, 0], C[1, 1], C[2, 2]])
    i = int(np.argmax(cand))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = [w, (C[2, 1] - C[1, 2]) / (4 * w), (C[0, 2] - C[2, 0]) / (4 * w), (C[1, 0] - C[0, 1]) / (4 * w)]
    elif i == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * C[0, 0] - tr)
        q = [(C[2, 1] - C[1, 2]) / (4 * x), x, (C[0, 1] + C[1, 0]) / (4 * x), (C[0, 2] + C[2, 0]) / (4 * x)]
    elif i == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * C[1, 1] - tr)
        q = [(C[0, 2] - C[2, 0]) / (4 * y), (C[0, 1] + C[1, 0]) / (4 * y), y, (C[1, 2] + C[2, 1]) / (4 * y)]
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * C[2, 2] - tr)
        q = [(C[1, 0] - C[0, 1]) / (4 * z), (C[0, 2] + C[2, 0]) / (4 * z), (C[1, 2] + C[2, 1]) / (4 * z), z]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def quat_kinematics(q_BN, omega_BN_B):
    """``q_dot = 0.5 * q ⊗ (0, omega)`` for scalar-first ``q_BN`` and body rates."""
    w, x, y, z = q_BN[0], q_BN[1], q_BN[2], q_BN[3]
    p, r, s = omega_BN_B[0], omega_BN_B[1], omega_BN_B[2]
    return vector(
        [
            0.5 * (-x * p - y * r - z * s),
            0.5 * (w * p + y * s - z * r),
            0.5 * (w * r - x * s + z * p),
            0.5 * (w * s + x * r - y * p),
        ],
        q_BN if is_symbolic(q_BN) else omega_BN_B,
    )


def Ay(a):
    """TP-2511 frame rotation about y by ``a`` (Eq. 36): ``[[ca,0,-sa],[0,1,0],[sa,0,ca]]``."""
    c, s = trig(a)
    return matrix([[c, 0, -s], [0, 1, 0], [s, 0, c]], a)


def Ax(b):
    """TP-2511 frame rotation about x by ``b`` (Eq. 37): ``[[1,0,0],[0,cb,sb],[0,-sb,cb]]``."""
    c, s = trig(b)
    return matrix([[1, 0, 0], [0, c, s], [0, -s, c]], b)


def Ap(alpha, beta):
    """``C_PB = Ax(beta) @ Ay(alpha)`` (TP-2511 Eq. 35-38): alpha about B's y, then beta about x."""
    if is_symbolic(alpha, beta):
        return ca.mtimes(Ax(beta), Ay(alpha))
    return Ax(beta) @ Ay(alpha)


def omega_PB_P(alpha, beta, alpha_dot, beta_dot):
    """Rate of P relative to B in P components: ``[beta_dot, alpha_dot cos b, -alpha_dot sin b]``.

    (TP-2511 Eq. 40; the scan lost the minus sign. Proved against ``-Ċ_PB C_PBᵀ`` by a test.)
    """
    if is_symbolic(beta):
        cb, sb = ca.cos(beta), ca.sin(beta)
    else:
        cb, sb = np.cos(beta), np.sin(beta)
    return vector([beta_dot, alpha_dot * cb, -alpha_dot * sb], beta)


def omega_PB_P_dot(alpha, beta, alpha_dot, beta_dot, alpha_ddot, beta_ddot):
    """Time derivative (in P, hence also in B after rotation) of :func:`omega_PB_P`."""
    if is_symbolic(beta):
        cb, sb = ca.cos(beta), ca.sin(beta)
    else:
        cb, sb = np.cos(beta), np.sin(beta)
    return vector(
        [
            beta_ddot,
            alpha_ddot * cb - alpha_dot * beta_dot * sb,
            -alpha_ddot * sb - alpha_dot * beta_dot * cb,
        ],
        beta,
    )


def _unit_rows(q: np.ndarray) -> np.ndarray:
    """Rows of ``q`` (k, 4) divided by their norms (:func:`~.linalg.row_norms`: numpy's own)."""
    return q / row_norms(q, keepdims=True)


def _error_parts(q_a: np.ndarray, q_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(w, v)`` of ``conj(q_a) ⊗ q_b`` for unit rows: the scalar part, and the vector part
    ``w_a v_b - w_b v_a - v_a × v_b`` (the cross product written out in ``np.cross``'s order of
    operations: the same numbers)."""
    w = np.add.reduce(q_a * q_b, axis=1)
    a, b = q_a[:, 1:], q_b[:, 1:]
    c = np.empty_like(a)
    c[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    c[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    c[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return w, q_a[:, :1] * b - q_b[:, :1] * a - c


def rotation_angle(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Principal angle [rad] of the rotation between attitudes ``q_a`` and ``q_b`` (rows, numpy).

    Robust for small angles (uses the vector part of the error quaternion).
    """
    w, v = _error_parts(_unit_rows(np.atleast_2d(q_a)), _unit_rows(np.atleast_2d(q_b)))
    return 2.0 * np.arctan2(row_norms(v), np.abs(w))


def rotation_vector(q_ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The rotation vector [rad] that takes attitude ``q_ref`` to ``q`` (rows, numpy), components
    in the frame of ``q``: ``φ ê`` of ``q_e = conj(q_ref) ⊗ q`` taken the short way round, so its
    norm is :func:`rotation_angle` (≈ ``2 vec(q_e)``, the small rotation angles about the axes).

    Returns
    -------
    ndarray, shape (k, 3)
    """
    return rotation_angle_vector(q_ref, q)[1]


def rotation_angle_vector(q_ref: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rotation_angle` and :func:`rotation_vector` of the same rows at once, bit for bit
    the same numbers as each (the error quaternion is made once: the output rows' attitude
    error, issue 25).

    Returns
    -------
    (ndarray (k,), ndarray (k, 3))
    """
    w, v = _error_parts(_unit_rows(np.atleast_2d(q_ref)), _unit_rows(np.atleast_2d(q)))
    v = np.where((w < 0)[:, None], -v, v)  # the short way round (|-v| = |v|: the same angle)
    s = row_norms(v)
    angle = 2.0 * np.arctan2(s, np.abs(w))
    # φ/|v| → 2 as |v| → 0 (φ = 2 asin|v| ≈ 2|v|)
    scale = np.where(s > 1e-300, angle / np.where(s > 1e-300, s, 1.0), 2.0)
    return angle, v * scale[:, None]


def euler_321(C_BO: np.ndarray) -> np.ndarray:
    """Yaw-pitch-roll (3-2-1) angles [rad] ``(roll, pitch, yaw)`` of ``C_BO`` (numpy, (3,3))."""
    roll = np.arctan2(C_BO[1, 2], C_BO[2, 2])
    pitch = -np.arcsin(np.clip(C_BO[0, 2], -1.0, 1.0))
    yaw = np.arctan2(C_BO[0, 1], C_BO[0, 0])
    return np.array([roll, pitch, yaw])
