"""Orbit, LVLH and gravity gradient against first principles."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed.model.environment import C_ON, gravity_gradient_torque, omega_ON_O, orbit_position_N
from stationbed.core.rotation import skew


@pytest.mark.parametrize("u, inc", [(0.0, 0.0), (0.7, 0.9006), (2.5, 1.7), (-1.0, 0.4974)])
def test_lvlh_axes(u, inc):
    C = C_ON(u, inc)
    assert_allclose(C @ C.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(C) == pytest.approx(1.0)
    R = orbit_position_N(u, 1.0, inc)
    h = 1e-6
    V = (orbit_position_N(u + h, 1.0, inc) - orbit_position_N(u - h, 1.0, inc)) / (2 * h)
    assert_allclose(C[2], -R, atol=1e-14)  # z to nadir
    assert_allclose(C[0], V / np.linalg.norm(V), atol=1e-9)  # x along velocity
    assert_allclose(C[1], -np.cross(R, V) / np.linalg.norm(np.cross(R, V)), atol=1e-9)  # y = -orbit normal


def test_lvlh_rate():
    """d/dt C_ON = -skew(ω_ON_O) C_ON with ω_ON_O = (0, -n, 0)."""
    n, inc, u = 1.1e-3, 0.9, 0.3
    h = 1e-3
    Cdot = (C_ON(u + n * h, inc) - C_ON(u - n * h, inc)) / (2 * h)
    assert_allclose(Cdot, -skew(omega_ON_O(n)) @ C_ON(u, inc), atol=1e-12)


def test_gravity_gradient_matches_point_mass_dumbbell():
    """Exact inverse-square torque on a cloud about its CM -> 3 n² R̂ × I R̂ as the cloud shrinks."""
    rng = np.random.default_rng(3)
    mu, R = 3.986004418e14, 6.778e6  # m³/s², m
    m = rng.uniform(1, 3, size=40)  # kg
    r = rng.normal(size=(40, 3)) * [30.0, 10.0, 5.0]  # m
    r -= m @ r / m.sum()
    I = sum(mi * (ri @ ri * np.eye(3) - np.outer(ri, ri)) for mi, ri in zip(m, r))
    Rv = np.array([0.3, -0.5, 0.8])
    Rv = R * Rv / np.linalg.norm(Rv)
    exact = sum(np.cross(ri, -mu * mi * (Rv + ri) / np.linalg.norm(Rv + ri) ** 3) for mi, ri in zip(m, r))
    approx = gravity_gradient_torque(Rv / R, I, mu / R**3)
    # first-order theory: relative error O(|r|/R) ≈ 1e-5
    assert_allclose(approx, exact, rtol=5e-5 * 10, atol=1e-5 * np.abs(exact).max())
