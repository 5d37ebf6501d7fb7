"""Integrator contract: every registered integrator meets a closed form; C and Python DOP853
loops agree; RK4 converges at order 4."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stationbed import INTEGRATORS, simulate
from stationbed.integrators import DOP853, IntegrationError
from stationbed.core.rotation import rotation_angle
from stationbed.scene import scene_from_dict

It, Ia, W1, W3 = 200.0, 350.0, 0.02, 0.05  # kg m², rad/s


def precession_scene(rigid):
    rigid["body"]["inertia"] = [[It, 0, 0], [0, It, 0], [0, 0, Ia]]
    rigid["initial"]["omega_BN_B"] = [W1, 0.0, W3]
    rigid["simulation"]["duration"] = 200.0
    return scene_from_dict(rigid)


def exact_q(t):
    H = np.array([It * W1, 0.0, Ia * W3])
    R = Rotation.from_rotvec(np.outer(np.linalg.norm(H) / It * t, H / np.linalg.norm(H))) * Rotation.from_rotvec(
        np.outer((It - Ia) / It * W3 * t, [0, 0, 1])
    )
    xyzw = R.as_quat()
    return np.c_[xyzw[:, 3], xyzw[:, :3]]


#: per integrator: what accuracy its settings buy on a 200 s, 0.06 rad/s precession
SETTINGS = {
    "dop853": ({"rtol": 1e-11}, 1e-9),
    "rk4": ({"step": 0.5}, 1e-7),  # (0.06 rad/s * 0.5 s)^4 / 120 per step * 400 steps ≈ 3e-9
    "lie_rk4": ({"step": 0.5}, 1e-7),  # as rk4 (measured 2.1e-9)
    "lgvi": ({"step": 0.1}, 2e-4),  # 2nd order: (0.06 rad/s * 0.1 s)^2 phase error over 200 s (measured 5.0e-5)
    "radau": ({"step": 0.5}, 1e-9),  # order 5 (measured 1.1e-12)
    "scipy_dop853": ({"rtol": 1e-11}, 1e-9),
    "scipy_rk45": ({"rtol": 1e-10}, 1e-7),
    "scipy_radau": ({"rtol": 1e-10}, 1e-7),
    "scipy_bdf": ({"rtol": 1e-10}, 1e-5),
    "scipy_lsoda": ({"rtol": 1e-10}, 1e-6),
}


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_every_integrator_meets_closed_form(rigid_scene_dict, name):
    kw, tol = SETTINGS[name]
    tr = simulate(precession_scene(rigid_scene_dict), integrator=name, **kw)
    assert rotation_angle(tr.q_BN, exact_q(tr.t)).max() < tol
    assert tr.meta["n_rhs"] > 0


def test_c_driver_matches_python_loop(rigid_scene_dict, monkeypatch):
    from scenes import articulated_dict

    scene = scene_from_dict(articulated_dict())
    a = simulate(scene)
    monkeypatch.setattr(DOP853, "force_python", True)
    b = simulate(scene)
    assert a.meta["n_rhs"] == b.meta["n_rhs"]
    np.testing.assert_allclose(a.data, b.data, rtol=1e-12, atol=1e-12)


def test_rk4_order_four(rigid_scene_dict):
    scene = precession_scene(rigid_scene_dict)
    errs = []
    steps = [4.0, 2.0, 1.0]
    for h in steps:
        tr = simulate(scene, integrator="rk4", step=h, output_dt=20.0)
        errs.append(rotation_angle(tr.q_BN, exact_q(tr.t)).max())
    slopes = np.diff(np.log(errs)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 4.0) < 0.3), slopes


def test_unknown_integrator_lists_valid_names(rigid_scene_dict):
    with pytest.raises(ValueError, match="valid: dop853, lgvi, lie_rk4, radau, rk4"):
        simulate(scene_from_dict(rigid_scene_dict), integrator="euler")
