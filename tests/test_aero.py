"""Aerodynamic torque on flat plates (stationbed/model/surfaces.py, the ``aero`` torque kind).

Truths used (written in the tests, not calling the library's plate, density or orbit code):

* the closed-form free-molecular flat plate: ``F = -½ ρ |v|² A cd cos θ v̂`` on the windward side
  (cos θ = n̂·v̂ > 0), zero on the lee side of a one-sided plate, ``|cos θ|`` for a two-sided one;
  torque ``c × F`` about the mass centre; ``v = v_N - ω_E ẑ × r_N`` from the circular orbit of
  DESIGN §5; ρ from Vallado's Table 8-4 typed in tests/env_helpers.py;
* symmetry: a station symmetric about its x-z plane has zero aero torque for a flow along x;
* the array geometry of DESIGN §4: ``C_PB = Ay(α)`` turns the array normal to ``(sin α, 0, cos α)``;
* harmonics in LVLH hold: the co-rotating air's cross wind ``W = -ω_E R sin i cos u`` and along
  wind ``V = R n - ω_E R cos i`` make the torque of a body-fixed one-sided plate an exact series
  in 1, cos u, cos 2u with closed-form coefficients; on the iss_lvlh_hold scene the modules box
  gives an orbit-rate roll and a twice-orbit-rate pitch term whose sizes follow from the Fourier
  series of ``|cos u| cos u`` and ``|cos u|`` (slow test).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed import load_scene, simulate
from stationbed.model.atmosphere import EXPONENTIAL_TABLE, density
from stationbed.scene import scene_from_dict

from env_helpers import base_scene, circular_state, outputs, quat_of_dcm, v_rel_N, vallado_density, R_E
from scenes import C_PB, ROOT

#: float64 round-off through a few hundred operations, relative to the torque's size
ROUNDOFF_REL = 1e-10
#: torques below this are zero [N m] (the test torques are ~1e-4..1e-2 N m; round-off ~1e-18)
ZERO_NM = 1e-15
#: least-squares coefficients of an exact series: round-off times the basis' conditioning (~1)
FIT_REL = 1e-9
CD = 2.2  # the default drag coefficient
AREA = 12.0  # m²


def _plate_scene(normal, centre, two_sided=False, cd=CD):
    return base_scene(torque=[{"kind": "aero"}],
                      surface=[{"area": AREA, "normal": normal, "centre": centre, "two_sided": two_sided, "cd": cd}])


def _expected(scene, t, C_BN, normal, centre, two_sided=False, cd=CD):
    r, v, _ = circular_state(scene, t)
    v_B = C_BN @ v_rel_N(r, v)
    rho = vallado_density(np.linalg.norm(r) - R_E)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    cos = n @ v_B / np.linalg.norm(v_B)
    cos = abs(cos) if two_sided else max(cos, 0.0)
    F = -0.5 * rho * (v_B @ v_B) * AREA * cd * cos * v_B / np.linalg.norm(v_B)
    return np.cross(centre, F)


@pytest.mark.parametrize("two_sided", [False, True], ids=["one_sided", "two_sided"])
@pytest.mark.parametrize("side", [1.0, -1.0], ids=["windward", "leeward"])
def test_flat_plate_closed_form(two_sided, side):
    q = Rotation.from_rotvec([0.3, -0.2, 0.5])  # an attitude: C_NB = q.as_matrix()
    C_BN = q.as_matrix().T
    r, v, _ = circular_state(scene_from_dict(base_scene()), 40.0)
    v_B = C_BN @ v_rel_N(r, v)
    # a normal 35 deg from the flow (windward) or from the reverse flow (leeward)
    v_hat = side * v_B / np.linalg.norm(v_B)
    k = np.cross(v_hat, [0.0, 0.0, 1.0])
    normal = Rotation.from_rotvec(math.radians(35.0) * k / np.linalg.norm(k)).apply(v_hat)
    centre = [1.5, -2.0, 3.0]
    f, _, scene = outputs(_plate_scene(normal.tolist(), centre, two_sided))
    got = f(40.0, quat_of_dcm(C_BN))["tau_aero"]
    want = _expected(scene, 40.0, C_BN, normal, centre, two_sided)
    if side < 0 and not two_sided:
        assert np.all(np.abs(got) < ZERO_NM)
    else:
        assert np.linalg.norm(want) > 1e-4  # a real torque (N m) is compared
        assert_allclose(got, want, rtol=ROUNDOFF_REL, atol=0)


def _lvlh_quat(scene, t):
    """q_BN of B = LVLH (x along v, z to nadir), built from r and v."""
    r, v, _ = circular_state(scene, t)
    z = -r / np.linalg.norm(r)
    y = np.cross(z, v)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return quat_of_dcm(np.vstack([x, y, z]))


def _two_array_scene(alpha, inclination=0.0, centre_P=(0.0, 0.0, 0.0)):
    arrays = [{"name": n, "mass": 2000.0, "inertia": [[1e5, 0, 0], [0, 1e5, 0], [0, 0, 1e4]], "cm": [0.0, y, 0.0],
               "alpha": {"a0": alpha}} for n, y in (("stbd", 30.0), ("port", -30.0))]
    surf = [{"size": [20.0, 8.0, 6.0], "centre": [0.0, 0.0, 0.0]}]
    surf += [{"on": n, "area": 400.0, "normal": [0.0, 0.0, 1.0], "centre": list(centre_P), "two_sided": True}
             for n in ("stbd", "port")]
    d = base_scene(torque=[{"kind": "aero"}], surface=surf, appendage=arrays)
    d["orbit"] = {"altitude": 420e3, "inclination": inclination, "u0": 0.7}
    return d


@pytest.mark.parametrize("alpha", [0.0, 0.6], ids=["zero_incidence", "alpha0.6"])
def test_symmetric_station_has_no_aero_torque(alpha):
    f, _, scene = outputs(_two_array_scene(alpha))  # equatorial: the flow is along x in LVLH
    tau = f(100.0, _lvlh_quat(scene, 100.0))["tau_aero"]
    assert np.all(np.abs(tau) < ZERO_NM)


@pytest.mark.parametrize("alpha", [0.0, 0.3, 1.2, 2.0, -0.7], ids=lambda a: f"alpha{a}")
def test_torque_follows_array_angle(alpha):
    """One array of two (the port one carries no plate): the torque about O is the lever arm of its
    plate, turned by C_PB = Ay(α), crossed with the drag of a plate at incidence |sin α|."""
    d = _two_array_scene(alpha, centre_P=(0.0, 2.0, 1.0))
    d["surface"] = d["surface"][1:2]  # the starboard array plate only
    d["appendage"][1]["cm"] = [0.0, -10.0, 0.0]  # an asymmetric station: O is off the body's centre
    f, _, scene = outputs(d)
    t = 50.0
    got = f(t, _lvlh_quat(scene, t))["tau_aero"]
    r, v, _ = circular_state(scene, t)
    V = np.linalg.norm(v_rel_N(r, v))  # equatorial orbit: the relative flow is along x of LVLH
    rho = vallado_density(np.linalg.norm(r) - R_E)
    r_O = (2000.0 * np.array([0, 30.0, 0]) + 2000.0 * np.array([0, -10.0, 0])) / (1e5 + 4000.0)
    C_BP = C_PB(alpha, 0.0).T
    n_B = C_BP @ [0.0, 0.0, 1.0]
    assert_allclose(n_B, [math.sin(alpha), 0.0, math.cos(alpha)], atol=1e-15)
    lever = np.array([0.0, 30.0, 0.0]) - r_O + C_BP @ [0.0, 2.0, 1.0]
    F = np.array([-0.5 * rho * V * V * 400.0 * CD * abs(math.sin(alpha)), 0.0, 0.0])
    want = np.cross(lever, F)
    assert_allclose(got, want, rtol=ROUNDOFF_REL, atol=ZERO_NM)


def test_lvlh_hold_torque_has_orbit_and_twice_orbit_harmonics():
    gamma, z0 = 0.5, 4.0  # rad: the plate's normal in the x-y plane; m: its centre below O
    normal = [math.cos(gamma), math.sin(gamma), 0.0]
    d = _plate_scene(normal, [0.0, 0.0, z0])
    f, _, scene = outputs(d)
    o = scene.orbit
    R = R_E + o.altitude
    n = math.sqrt(3.986004418e14 / R**3)
    us = np.linspace(0.0, 2 * math.pi, 73)[:-1] + o.u0
    taus = np.array([f((u - o.u0) / n, _lvlh_quat(scene, (u - o.u0) / n))["tau_aero"] for u in us])
    basis = np.column_stack([np.ones_like(us), np.cos(us), np.sin(us), np.cos(2 * us), np.sin(2 * us)])
    coef, *_ = np.linalg.lstsq(basis, taus, rcond=None)
    assert np.max(np.abs(basis @ coef - taus)) < ROUNDOFF_REL * np.max(np.abs(taus))  # an exact 0/1/2u series
    # closed form: V along, W = -W0 cos u across the track; F = -k (n·v) v, k = ½ ρ cd A
    V = R * n - 7.292115e-5 * R * math.cos(o.inclination)
    W0 = 7.292115e-5 * R * math.sin(o.inclination)
    k = 0.5 * vallado_density(o.altitude) * CD * AREA
    cg, sg = math.cos(gamma), math.sin(gamma)
    roll = [k * z0 * sg * W0**2 / 2, -k * z0 * V * cg * W0, 0.0, k * z0 * sg * W0**2 / 2, 0.0]
    pitch = [-k * z0 * V * V * cg, k * z0 * V * sg * W0, 0.0, 0.0, 0.0]
    assert_allclose(coef[:, 0], roll, rtol=FIT_REL, atol=FIT_REL * abs(roll[1]))
    assert_allclose(coef[:, 1], pitch, rtol=FIT_REL, atol=FIT_REL * abs(pitch[0]))
    assert_allclose(coef[:, 2], 0.0, atol=ZERO_NM)


# -- density ----------------------------------------------------------------------------------
#: Vallado's Table 8-4 (h0 [km], ρ0 [kg/m³], H [km]) rows typed here for the check below
VALLADO_ROWS = [(0, 1.225, 7.249, 25), (100, 5.297e-7, 5.877, 10), (150, 2.070e-9, 22.523, 30),
                (300, 2.418e-11, 53.628, 50), (400, 3.725e-12, 58.515, 50), (700, 3.614e-14, 88.667, 100),
                (1000, 3.019e-15, 268.00, 100)]  # with the band's width [km]
#: the model's scale heights are the table's log-slopes; the table rounds H to 4-5 digits, which
#: moves the density at a band's top by up to 0.14 % (0-25 km band) and 0.002 % above 25 km
VALLADO_BAND_REL = 1.5e-3


@pytest.mark.parametrize("h0_km, rho0, H_km, width_km", VALLADO_ROWS, ids=[f"{r[0]}km" for r in VALLADO_ROWS])
def test_density_is_vallados_table(h0_km, rho0, H_km, width_km):


    assert_allclose(density(h0_km * 1e3), rho0, rtol=1e-12)  # the base densities exactly
    h = (h0_km + width_km * np.array([0.2, 0.5, 0.95])) * 1e3  # inside the band
    assert_allclose(density(h), rho0 * np.exp(-(h - h0_km * 1e3) / (H_km * 1e3)), rtol=VALLADO_BAND_REL)


def test_density_is_continuous_across_band_edges():


    for h0 in EXPONENTIAL_TABLE[1:, 0] * 1e3:
        below, above = density(h0 - 1e-6), density(h0)
        assert abs(above / below - 1) < 1e-9  # 1 µm below the edge: continuity, not a jump


#: the LVLH-holding scene flies within ~0.1 deg of LVLH after its start-up; the flow's out-of-plane
#: part this leaves moves the harmonics by < 1 % (measured 0.4 % roll, 0.8 % pitch)
SCENE_HARMONIC_REL = 0.03


@pytest.mark.slow
def test_iss_lvlh_hold_aero_torque_harmonics_of_the_corotating_air():
    """scenarios/iss_lvlh_hold.toml: the modules (a box, its drag through its centre c = (-5,
    1.5, 6) m) feel the air-relative flow ``(V, W, 0)`` in LVLH with the cross wind
    ``W = -W0 cos u`` of the co-rotating air. The box's drag is ``-½ρ cd (A_f V + A_s |W|) v``, so
    roll ``τ_x = -c_z F_y`` has an orbit-rate term ``-c_z ½ρ cd (A_f V W0 + A_s W0² 8/(3π)) cos u``
    and pitch ``τ_y = c_z F_x`` a twice-orbit-rate term ``-c_z ½ρ cd A_s W0 V (4/(3π)) cos 2u``
    (Fourier series of |cos u| cos u and |cos u|); truss and arrays lie on O's level."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    tr = simulate(scene)
    o = scene.orbit
    R, n = o.radius_m, o.mean_motion
    u = o.u0 + n * tr.t
    last = tr.t >= 2 * math.pi / n  # the last two orbits: the start-up transient is gone
    basis = np.column_stack([np.ones(last.sum())] + [f(k * u[last]) for k in (1, 2, 3, 4) for f in (np.cos, np.sin)])
    roll, *_ = np.linalg.lstsq(basis, tr["tau_aero_x"][last], rcond=None)
    pitch, *_ = np.linalg.lstsq(basis, tr["tau_aero_y"][last], rcond=None)
    V = R * n - 7.292115e-5 * R * math.cos(o.inclination)
    W0 = 7.292115e-5 * R * math.sin(o.inclination)
    half_rho_cd = 0.5 * 3.725e-12 * 2.2  # Vallado's 400 km base density, default cd
    A_f, A_s, c_z = 8.0 * 8.0, 50.0 * 8.0, 6.0  # m², m², m (the scene's modules box)
    roll_cos1 = -c_z * half_rho_cd * (A_f * V * W0 + A_s * W0**2 * 8 / (3 * math.pi))
    pitch_cos2 = -c_z * half_rho_cd * A_s * W0 * V * 4 / (3 * math.pi)
    assert_allclose(roll[1], roll_cos1, rtol=SCENE_HARMONIC_REL)
    assert_allclose(pitch[3], pitch_cos2, rtol=SCENE_HARMONIC_REL)
    assert abs(roll[2]) < SCENE_HARMONIC_REL * abs(roll[1])  # in phase with the cross wind (cos u)
