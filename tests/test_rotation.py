"""Rotation math against scipy (an independent implementation) and finite differences."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed.core.rotation import (
    Ap,
    Ax,
    Ay,
    dcm,
    omega_PB_P,
    omega_PB_P_dot,
    quat_from_dcm,
    quat_kinematics,
    quat_mult,
    rotation_angle,
    rotation_angle_vector,
    rotation_vector,
    skew,
)

ROUND_OFF = 1e-14  # float64 on O(1) quantities, a few operations
FD_TOL = 1e-8  # central differences with h = 1e-5: truncation ~h², round-off ~eps/h ≈ 1e-11


def random_quats(rng, n=50):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_dcm_is_transpose_of_scipy_matrix(rng):
    for q in random_quats(rng):
        C_NB = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        assert_allclose(dcm(q), C_NB.T, atol=ROUND_OFF)


def test_dcm_quaternion_round_trip(rng):
    for q in random_quats(rng):
        q2 = quat_from_dcm(dcm(q))
        assert_allclose(q2, q * np.sign(q[0]), atol=ROUND_OFF)


def test_quat_mult_composes_dcms(rng):
    """q_CN = q_BN ⊗ q_CB  <=>  C_CN = C_CB C_BN (frame-rotation composition)."""
    qs = random_quats(rng, 40)
    for q_BN, q_CB in zip(qs[:20], qs[20:]):
        assert_allclose(dcm(quat_mult(q_BN, q_CB)), dcm(q_CB) @ dcm(q_BN), atol=ROUND_OFF)


def test_quaternion_kinematics_matches_dcm_kinematics(rng):
    """d/dt C_BN = -skew(ω) C_BN  (Poisson) from q_dot = ½ q ⊗ (0, ω)."""
    q = random_quats(rng, 1)[0]
    w = rng.normal(size=3)
    h = 1e-6
    qd = quat_kinematics(q, w)
    Cdot = (dcm(q + h * qd) - dcm(q - h * qd)) / (2 * h)
    assert_allclose(Cdot, -skew(w) @ dcm(q), atol=FD_TOL)


def test_skew_is_cross_product(rng):
    a, b = rng.normal(size=(2, 3))
    assert_allclose(skew(a) @ b, np.cross(a, b), atol=ROUND_OFF)


def test_Ap_is_Ax_times_Ay_and_orthonormal(rng):
    for a, b in rng.uniform(-3, 3, size=(20, 2)):
        C = Ap(a, b)
        assert_allclose(C, Ax(b) @ Ay(a), atol=ROUND_OFF)
        assert_allclose(C @ C.T, np.eye(3), atol=ROUND_OFF)
        assert np.linalg.det(C) == pytest.approx(1.0, abs=ROUND_OFF)


def test_Ay_Ax_are_frame_rotations_about_y_and_x():
    """Ay(a) is scipy's passive rotation about +y by a (C_PB of a frame turned by +a about y)."""
    a = 0.37
    assert_allclose(Ay(a), Rotation.from_rotvec([0, a, 0]).as_matrix().T, atol=ROUND_OFF)
    assert_allclose(Ax(a), Rotation.from_rotvec([a, 0, 0]).as_matrix().T, atol=ROUND_OFF)


@pytest.mark.parametrize("case", range(10))
def test_relative_rate_matches_dcm_derivative(rng, case):
    """skew(ω_PB_P) = -Ċ_PB C_PBᵀ (TP Eq. 40 with the sign the scan lost)."""
    a, b, ad, bd = rng.uniform(-2, 2, size=4)
    h = 1e-5
    Cdot = (Ap(a + h * ad, b + h * bd) - Ap(a - h * ad, b - h * bd)) / (2 * h)
    W = -Cdot @ Ap(a, b).T
    assert_allclose(W, -W.T, atol=FD_TOL)  # skew-symmetric
    assert_allclose([W[2, 1], W[0, 2], W[1, 0]], omega_PB_P(a, b, ad, bd), atol=FD_TOL)


def test_relative_rate_derivative_by_finite_difference(rng):
    a0, b0, ad0, bd0, add, bdd = rng.uniform(-1, 1, size=6)

    def state(t):
        a = a0 + ad0 * t + 0.5 * add * t * t
        b = b0 + bd0 * t + 0.5 * bdd * t * t
        return omega_PB_P(a, b, ad0 + add * t, bd0 + bdd * t)

    h = 1e-5
    fd = (state(h) - state(-h)) / (2 * h)
    assert_allclose(omega_PB_P_dot(a0, b0, ad0, bd0, add, bdd), fd, atol=FD_TOL)


def test_rotation_angle_small_and_large():
    q0 = np.array([1.0, 0, 0, 0])
    for ang in (1e-12, 1e-6, 0.5, 3.0):
        q1 = np.array([np.cos(ang / 2), 0, np.sin(ang / 2), 0])
        assert rotation_angle(q0, q1)[0] == pytest.approx(ang, rel=1e-12)
        assert rotation_angle(q0, -q1)[0] == pytest.approx(ang, rel=1e-12)  # q and -q: same attitude


def _error_rows_with_numpy(q_ref, q):
    """The output rows' attitude error as it was first written: ``np.linalg.norm`` and
    ``np.cross`` (numpy's own), the angle and the vector each from its own error quaternion."""
    q_ref = q_ref / np.linalg.norm(q_ref, axis=1, keepdims=True)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w = np.sum(q_ref * q, axis=1)
    v = q_ref[:, :1] * q[:, 1:] - q[:, :1] * q_ref[:, 1:] - np.cross(q_ref[:, 1:], q[:, 1:])
    angle = 2.0 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w))
    v = np.where((w < 0)[:, None], -v, v)
    s = np.linalg.norm(v, axis=1)
    scale = np.where(s > 1e-300, 2.0 * np.arctan2(s, np.abs(w)) / np.where(s > 1e-300, s, 1.0), 2.0)
    return angle, v * scale[:, None]


def test_rotation_angle_and_vector_against_scipy_and_bit_for_bit_against_numpy(rng):
    """The angle and rotation vector of ``conj(q_ref) ⊗ q`` (components in the frame of ``q``)
    against scipy's ``(R_ref⁻¹ R).as_rotvec()``; and, made once for both (issue 25), bit for bit
    the numbers of numpy's own norm and cross product (the output rows keep their values):
    unequal norms, q and -q, equal and nearly equal attitudes, a half turn."""
    q_ref = rng.normal(size=(400, 4)) * rng.uniform(0.5, 2.0, (400, 1))
    q = rng.normal(size=(400, 4))
    q[:50] = q_ref[:50]
    q[50:100] = -3.0 * q_ref[50:100]
    q[100:150] = q_ref[100:150] + 1e-9 * rng.normal(size=(50, 4))
    q[150] = quat_mult(q_ref[150], [0.0, 0.0, 1.0, 0.0])
    angle, vec = rotation_angle_vector(q_ref, q)
    want_angle, want_vec = _error_rows_with_numpy(q_ref, q)
    assert np.array_equal(angle, want_angle) and np.array_equal(vec, want_vec)
    assert np.array_equal(rotation_angle(q_ref, q), want_angle) and np.array_equal(rotation_vector(q_ref, q), want_vec)
    def sp(x):
        return Rotation.from_quat(np.roll(x, -1, axis=1))  # scipy: scalar last
    rotvec = (sp(q_ref).inv() * sp(q)).as_rotvec()
    far = slice(151, None)  # (a half turn's axis sign is a choice)
    assert_allclose(vec[far], rotvec[far], atol=ROUND_OFF)
    assert_allclose(angle, np.linalg.norm(vec, axis=1), rtol=ROUND_OFF, atol=ROUND_OFF)
    assert_allclose(angle[150], np.pi, rtol=ROUND_OFF)
