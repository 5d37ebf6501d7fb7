"""Closed-form truths: torque-free axisymmetric precession, constant torque about a principal
axis, gravity-gradient pitch libration, and the torque window."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import simpson
from scipy.spatial.transform import Rotation

from stationbed import FORMULATIONS, load_scene, simulate
from stationbed.model.environment import C_ON
from stationbed.core.rotation import dcm, euler_321, rotation_angle
from stationbed.scene import scene_from_dict
from scenes import ROOT

FORMS = sorted(FORMULATIONS)
#: rtol 1e-12 over ≲ 10⁴ steps: global error ≲ 1e-10 rad; 1e-9 leaves a decade of margin.
ATT_TOL_RAD = 1e-9


@pytest.mark.parametrize("form", FORMS)
def test_torque_free_axisymmetric_precession(rigid_scene_dict, form):
    It, Ia = 200.0, 350.0  # kg m²
    w1, w3 = 0.02, 0.05  # rad/s
    d = rigid_scene_dict
    d["body"]["inertia"] = [[It, 0, 0], [0, It, 0], [0, 0, Ia]]
    d["initial"]["omega_BN_B"] = [w1, 0.0, w3]
    d["simulation"]["duration"] = 400.0
    tr = simulate(scene_from_dict(d), formulation=form)
    t = tr.t
    lam = (Ia - It) / It * w3
    assert_allclose(tr.omega_BN_B, np.c_[w1 * np.cos(lam * t), w1 * np.sin(lam * t), np.full_like(t, w3)], atol=1e-12)
    # attitude: precession of the body about H at |H|/It, plus spin about e3 at (It - Ia)/It w3
    H_B0 = np.array([It * w1, 0.0, Ia * w3])
    h_N = H_B0 / np.linalg.norm(H_B0)  # C_NB(0) = E
    Om = np.linalg.norm(H_B0) / It
    sig = (It - Ia) / It * w3
    R = Rotation.from_rotvec(np.outer(Om * t, h_N)) * Rotation.from_rotvec(np.outer(sig * t, [0, 0, 1]))
    xyzw = R.as_quat()
    q_exact = np.c_[xyzw[:, 3], xyzw[:, :3]]
    assert rotation_angle(tr.q_BN, q_exact).max() < ATT_TOL_RAD


@pytest.mark.parametrize("form", FORMS)
def test_constant_torque_about_principal_axis(rigid_scene_dict, form):
    d = rigid_scene_dict
    L, Iy = 5.0, 200.0  # N m, kg m²
    d["torque"] = [{"kind": "constant", "torque_B": [0.0, L, 0.0]}]
    tr = simulate(scene_from_dict(d), formulation=form)
    t = tr.t
    theta = 0.5 * L / Iy * t**2
    assert_allclose(tr["wy"], L / Iy * t, rtol=1e-12, atol=1e-14)
    q_exact = np.c_[np.cos(theta / 2), 0 * t, np.sin(theta / 2), 0 * t]
    assert rotation_angle(tr.q_BN, q_exact).max() < ATT_TOL_RAD


def pitch_scene(theta0):
    Ix, Iy, Iz = 3.0e7, 2.5e7, 1.0e7  # kg m², principal axes along LVLH
    return scene_from_dict(
        {
            "name": "pitch_libration",
            "simulation": {"duration": 11107.2, "rtol": 1e-11, "atol": 1e-14, "output_dt": 10.0},
            "initial": {
                "frame": "lvlh",
                "q_BN": [np.cos(theta0 / 2), 0.0, np.sin(theta0 / 2), 0.0],
                "omega_BN_B": [0.0, 0.0, 0.0],
            },
            "body": {"mass": 3e5, "inertia": [[Ix, 0, 0], [0, Iy, 0], [0, 0, Iz]]},
            "orbit": {"altitude": 400e3, "inclination": 0.9, "u0": 0.3},
        }
    ), (Ix, Iy, Iz)


@pytest.mark.parametrize("form", FORMS)
def test_gravity_gradient_pitch_libration_frequency(form):
    """Small pitch about LVLH y oscillates at n sqrt(3 (Ix - Iz) / Iy)."""
    theta0 = 1e-3  # rad: nonlinear frequency shift ~θ0²/8 ≈ 1e-7, negligible
    scene, (Ix, Iy, Iz) = pitch_scene(theta0)
    tr = simulate(scene, formulation=form)
    o = scene.orbit
    pitch = np.array(
        [euler_321(dcm(q) @ C_ON(o.u0 + o.mean_motion * t, o.inclination).T)[1] for t, q in zip(tr.t, tr.q_BN)]
    )
    w_lib = o.mean_motion * np.sqrt(3 * (Ix - Iz) / Iy)
    # 3 libration cycles: a 0.1 % frequency error would give a 0.019 θ0 mismatch; allow 1e-4 θ0
    assert_allclose(pitch, theta0 * np.cos(w_lib * tr.t), atol=1e-4 * theta0)
    # frequency by least squares, for a readable failure
    assert np.max(np.abs(pitch)) == pytest.approx(theta0, rel=1e-4)


@pytest.fixture(scope="module")
def torque_window():
    scene = load_scene(ROOT / "scenarios" / "torque_window.toml")
    return scene, simulate(scene)


def test_torque_window_rest_before_start(torque_window):
    scene, tr = torque_window
    before = tr.t <= 1000.0
    assert np.all(tr.omega_BN_B[before] == 0.0)  # exactly: no step straddles t = 1000 s


def test_torque_window_momentum_gain_is_integral_of_torque(torque_window):
    """ΔH_N = ∫ C_NB L_B dt over [1000, 2000), and H_N is constant afterwards."""
    scene, tr = torque_window
    L_B = np.array([10.0, 0.0, 0.0])  # N m
    win = (tr.t >= 1000.0) & (tr.t <= 2000.0)
    L_N = np.array([dcm(q).T @ L_B for q in tr.q_BN[win]])
    dH = simpson(L_N, x=tr.t[win], axis=0)  # 1 s grid, ω ~ 1e-4 rad/s: quadrature error ~1e-15
    i2000 = int(np.argmin(np.abs(tr.t - 2000.0)))
    assert_allclose(tr.H_O_N[i2000], dH, rtol=1e-8, atol=1e-8)
    after = tr.t >= 2000.0
    assert_allclose(tr.H_O_N[after], np.broadcast_to(tr.H_O_N[i2000], tr.H_O_N[after].shape), rtol=1e-10, atol=1e-9)


def test_torque_window_energy_equals_work(torque_window):
    """T(2000) = ∫ ω · L dt (work-energy theorem) and T is constant afterwards."""
    scene, tr = torque_window
    win = (tr.t >= 1000.0) & (tr.t <= 2000.0)
    work = simpson(tr["wx"][win] * 10.0, x=tr.t[win])
    i2000 = int(np.argmin(np.abs(tr.t - 2000.0)))
    assert tr["T"][i2000] == pytest.approx(work, rel=1e-8)
    assert_allclose(tr["T"][tr.t >= 2000.0], tr["T"][i2000], rtol=1e-10)


def test_torque_window_independent_of_output_grid(torque_window):
    """Edges that are not output times are still integrated across exactly."""
    scene, tr = torque_window
    coarse = simulate(scene, output_dt=700.0)  # outputs 0, 700, 1400, 2100, 2800, 3000
    fine = {t: i for i, t in enumerate(tr.t)}
    idx = [fine[t] for t in coarse.t]
    assert rotation_angle(coarse.q_BN, tr.q_BN[idx]).max() < 1e-9
    assert_allclose(coarse.omega_BN_B, tr.omega_BN_B[idx], atol=1e-13)
