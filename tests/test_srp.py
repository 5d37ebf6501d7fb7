"""Solar radiation pressure torque on flat plates (the ``srp`` torque kind).

Truths used (written here, not calling the library's plate code):

* the textbook flat plate (Wertz 1978 Eq. 17-10; Montenbruck & Gill 2000 Eq. 3.72):
  ``F = -P A cos θ [(1 - ε_s) ŝ + 2 (ε_s cos θ + ε_d / 3) n̂]`` for cos θ = n̂·ŝ > 0, nothing on a
  one-sided plate's dark side, the lit face's normal for a two-sided plate; ``P = 4.56e-6 N/m²``
  at 1 AU, ``(1 AU / d)²`` at the epoch's distance d (the test's own AA formula);
* symmetry: a box centred on the mass centre has no SRP torque from any direction;
* the shadow: inside the Earth's cylinder behind it, no SRP at all.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed.model.environment import sun_direction_N
from stationbed.scene import scene_from_dict

from env_helpers import base_scene, outputs, quat_of_dcm

#: float64 round-off through a few dozen operations, relative to the torque
ROUNDOFF_REL = 1e-12
#: zero torque [N m] (test torques ~1e-5 N m)
ZERO_NM = 1e-18
P_1AU = 4.56e-6  # N/m², Wertz Eq. 17-8
AREA = 8.0  # m²
SUN_N = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


def _scene(surface, sun=None, eclipse="none"):
    sun = {"direction_N": SUN_N.tolist(), "eclipse": eclipse} if sun is None else sun
    return base_scene(torque=[{"kind": "srp"}], surface=surface, sun=sun)


def _textbook(n, s, spec, diff, centre, P=P_1AU):
    cos = n @ s
    if cos <= 0:
        return np.zeros(3)
    F = -P * AREA * cos * ((1 - spec) * s + 2 * (spec * cos + diff / 3) * n)
    return np.cross(centre, F)


ATTITUDE = Rotation.from_rotvec([-0.4, 0.25, 0.9])  # C_NB = ATTITUDE.as_matrix()


@pytest.mark.parametrize("spec, diff", [(0.0, 0.0), (0.6, 0.1), (0.1, 0.7)], ids=["absorber", "mirror", "diffuse"])
@pytest.mark.parametrize("tilt_deg", [0.0, 40.0, 80.0, 120.0], ids=lambda d: f"tilt{d:g}")
def test_flat_plate_against_textbook(spec, diff, tilt_deg):
    C_BN = ATTITUDE.as_matrix().T
    s_B = C_BN @ SUN_N
    k = np.cross(s_B, [1.0, 0.0, 0.0])
    n = Rotation.from_rotvec(math.radians(tilt_deg) * k / np.linalg.norm(k)).apply(s_B)
    centre = [2.0, -1.0, 4.0]
    surf = [{"area": AREA, "normal": n.tolist(), "centre": centre, "specular": spec, "diffuse": diff}]
    f, _, _ = outputs(_scene(surf))
    got = f(10.0, quat_of_dcm(C_BN))["tau_srp"]
    want = _textbook(n, s_B, spec, diff, np.array(centre))
    if tilt_deg > 90:
        assert np.all(np.abs(got) < ZERO_NM)
    else:
        assert_allclose(got, want, rtol=ROUNDOFF_REL, atol=ZERO_NM)


def test_two_sided_plate_uses_the_lit_face():
    C_BN = ATTITUDE.as_matrix().T
    s_B = C_BN @ SUN_N
    n = -Rotation.from_rotvec([0.3, 0.0, 0.0]).apply(s_B)  # facing away from the sun
    centre = np.array([1.0, 3.0, -2.0])
    surf = [{"area": AREA, "normal": n.tolist(), "centre": centre.tolist(), "two_sided": True,
             "specular": 0.5, "diffuse": 0.2}]
    f, _, _ = outputs(_scene(surf))
    got = f(10.0, quat_of_dcm(C_BN))["tau_srp"]
    assert_allclose(got, _textbook(-n, s_B, 0.5, 0.2, centre), rtol=ROUNDOFF_REL)


def test_centred_box_has_no_torque_and_offset_box_has_lever_torque():
    C_BN = ATTITUDE.as_matrix().T
    f, _, _ = outputs(_scene([{"size": [3.0, 5.0, 2.0], "centre": [0.0, 0.0, 0.0]}]))
    assert np.all(np.abs(f(0.0, quat_of_dcm(C_BN))["tau_srp"]) < ZERO_NM)
    # off the mass centre by c: the torque is c × (the box's force), the force summed over the
    # lit faces by the textbook formula (default fractions 0.8 / 0.1 / 0.1)
    c = np.array([0.0, 6.0, -1.0])
    f, _, _ = outputs(_scene([{"size": [2.0, 2.0, 2.0], "centre": c.tolist()}]))
    s_B = C_BN @ SUN_N
    F = np.zeros(3)
    for n in np.vstack([np.eye(3), -np.eye(3)]):
        cos = n @ s_B
        if cos > 0:
            F += -P_1AU * 4.0 * cos * (0.9 * s_B + 2 * (0.1 * cos + 0.1 / 3) * n)
    assert_allclose(f(0.0, quat_of_dcm(C_BN))["tau_srp"], np.cross(c, F), rtol=ROUNDOFF_REL)


def test_pressure_scales_with_the_epoch_distance():
    epoch = "2024-01-03T00:39:00Z"  # perihelion: 0.983307 AU (published)
    surf = [{"area": AREA, "normal": [0.0, 0.0, 1.0], "centre": [0.0, 5.0, 0.0], "specular": 0.0, "diffuse": 0.0}]
    f_epoch, _, _ = outputs(_scene(surf, sun={"epoch": epoch}))
    f_au, _, _ = outputs(_scene(surf, sun={"direction_N": [0.0, 0.0, 1.0]}))
    # the same plate facing the sun in each case (the epoch's sun from the library's ephemeris,
    # which test_eclipse.py checks): the torques' ratio is the pressures'
    s_N = sun_direction_N(scene_from_dict(_scene(surf, sun={"epoch": epoch})).sun)
    C_BN = Rotation.align_vectors([[0.0, 0.0, 1.0]], [s_N])[0].as_matrix()
    ratio = np.linalg.norm(f_epoch(0.0, quat_of_dcm(C_BN))["tau_srp"]) / np.linalg.norm(f_au(0.0, [1.0, 0, 0, 0])["tau_srp"])
    assert_allclose(ratio, 1.0 / 0.983307**2, rtol=1e-4)  # the AA distance series is good to ~3e-5 AU


def test_no_srp_in_the_shadow():
    # sun along +x of N; the station at u0 = π on an equatorial orbit is straight behind the Earth
    d = _scene([{"area": AREA, "normal": [-1.0, 0.0, 0.0], "centre": [0.0, 2.0, 0.0]}],
               sun={"direction_N": [1.0, 0.0, 0.0], "eclipse": "cylindrical"})
    d["orbit"] = {"altitude": 420e3, "inclination": 0.0, "u0": math.pi}
    f, _, _ = outputs(d)
    out = f(0.0, [1.0, 0.0, 0.0, 0.0])
    assert out["eclipse"][0] == 0.0 and np.all(out["tau_srp"] == 0.0)
    d["orbit"]["u0"] = 0.0  # sunlit side
    f, _, _ = outputs(d)
    out = f(0.0, [0.0, 0.0, 0.0, 1.0])  # turned 180 deg about z: the plate's -x normal faces the sun
    assert out["eclipse"][0] == 1.0 and np.linalg.norm(out["tau_srp"]) > 1e-6
