"""``pd``'s one form (its ``symbolic`` law, compiled: what every executor calls) against Wie's
law computed here by hand from rotation matrices (scipy), not from the law's quaternion algebra:

    τ = -c J [ sat_ω_max((k / c) e) + ω_e ] + ω × J ω,   k = 2 ω_n², c = 2 ζ ω_n,

``e`` the vector part of ``q_BR`` (scalar part ≥ 0), ``ω_e = ω_BN_B - C_BR ω_RN_R``, R = the LVLH
frame turned by ``q_ref`` (``C_RN = C_RO C_ON``, ``ω_RN_R = C_RO (0, -n, 0)``) or N itself.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed.controllers.pd import PD
from stationbed.run.controller import Measurement, Plant, measurement_fields

N_RAD_S = 1.13e-3  # rad/s, a 400 km orbit's rate
INERTIA = np.array([[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]])  # kg m²
PARAMS = {"bandwidth": 0.02, "damping": 0.8, "max_slew_rate": 0.004}  # rad/s, -, rad/s
#: the same law by two routes (quaternions compiled vs matrices in numpy): round-off of |τ|
HAND_RTOL = 1e-9


def _C(q):
    """``C`` (components in the rotated frame from the reference frame's) of a scalar-first q."""
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix().T


def _reference(M, reference, q_ref):
    """``(C_RN, ω_RN_R)``."""
    C_RO = _C(q_ref)
    if reference == "lvlh":
        return C_RO @ _C(M.q_ON), C_RO @ [0.0, -N_RAD_S, 0.0]
    return C_RO, np.zeros(3)


def _hand(M, reference, q_ref, gyro=True):
    wn, z = PARAMS["bandwidth"], PARAMS["damping"]
    k, c = 2.0 * wn**2, 2.0 * z * wn
    C_RN, w_RN_R = _reference(M, reference, q_ref)
    C_BR = _C(M.q_BN) @ C_RN.T
    x, y, zq, w = Rotation.from_matrix(C_BR.T).as_quat()
    e = np.array([x, y, zq]) * (1.0 if w >= 0.0 else -1.0)
    r = k / c * e
    clip = np.linalg.norm(r) > PARAMS["max_slew_rate"]
    r = r * min(1.0, PARAMS["max_slew_rate"] / np.linalg.norm(r))
    w_B = np.array(M.omega_BN_B)
    tau = -c * INERTIA @ (r + w_B - C_BR @ w_RN_R)
    return tau + (np.cross(w_B, INERTIA @ w_B) if gyro else 0.0), C_RN, clip


@pytest.mark.parametrize("reference", ["lvlh", "inertial"])
@pytest.mark.parametrize("gyro", [True, False])
def test_the_command_is_wies_law(reference, gyro):
    """Small errors (the slew limit idle) and large ones (the rate command clipped to its length),
    either sign of the error quaternion; the reference attitude the law logs is R's."""
    q_ref = np.array([0.98, 0.1, -0.15, 0.08])
    q_ref /= np.linalg.norm(q_ref)
    plant = Plant(scene=SimpleNamespace(appendage=[], orbit=None), inertia_O_B=INERTIA, mean_motion=N_RAD_S,
                  period=0.1)
    c = PD(period=0.1, reference=reference, q_ref=q_ref.tolist(), gyro_compensation=gyro, **PARAMS)
    c.reset(plant)
    lay = measurement_fields(0, 0)
    M = Measurement(np.zeros(lay.size), lay)
    rng = np.random.default_rng(11)
    clipped = 0
    for scale in (1e-3, 1e-3, 1.0, 1.0, 1.0, 1.0):
        q_ON = rng.normal(size=4)
        M.q_ON[:] = q_ON / np.linalg.norm(q_ON)
        C_RN = _reference(M, reference, q_ref)[0]
        q_RN = Rotation.from_matrix(C_RN.T).as_quat()  # near R, or anywhere: (x, y, z, w)
        d = Rotation.from_rotvec(rng.normal(size=3) * scale)
        q = (d * Rotation.from_quat(q_RN)).as_quat() * rng.choice([-1.0, 1.0])
        M.q_BN[:] = [q[3], q[0], q[1], q[2]]
        M.omega_BN_B[:] = rng.normal(size=3) * 1e-3
        tau, C_RN, clip = _hand(M, reference, q_ref, gyro)
        got = c.update(0.0, M)
        assert_allclose(got, tau, rtol=0, atol=HAND_RTOL * np.linalg.norm(tau))
        assert_allclose(_C(c.q_ref_BN), C_RN, atol=1e-12)
        clipped += clip
    assert 0 < clipped < 6 and c.n_updates == 6  # (both branches of the limit)
