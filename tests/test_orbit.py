"""Two-body orbits (issue 14): the orbit model (stationbed/model/orbit.py, core/kepler.py), the LVLH
frame on an eccentric orbit, and a rigid body librating on it.

Truths used (none calls the library's orbit code):

* an independent integration of the two-body ODE ``r̈ = -μ r / r³`` (scipy DOP853, rtol 1e-12),
  started from an inertial state written in the test (perifocal frame rotated by scipy's
  ``Rotation``);
* the conservation of the specific energy ``v²/2 - μ/r`` and of ``h = r × v`` (two-body laws);
* the closed-form first-order J2 secular rates (Vallado Eq. 9-41/9-42), written here with their
  own constants;
* the LVLH frame built here from r and v (z = -r̂, y = -ĥ, x = y × z) and its rate from finite
  differences of the model's ``C_ON``;
* THE KEY CHECK: an independent attitude + orbit model written here (quaternion, body rate,
  position and velocity integrated together by scipy DOP853 at rtol 1e-13, gravity gradient
  ``3 μ/r⁵ (C r) × (I C r)`` from the integrated position), compared with the scenario
  ``jeod_style_eccentric_libration`` run by stationbed with every formulation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

import stationbed
from stationbed.core.kepler import elements_from_rv, newton_steps, rv_from_elements, solve_kepler
from stationbed.model.orbit import orbit_numeric
from stationbed.run.initial import initial_state
from stationbed.scene import SceneError, load_scene, scene_from_dict
from scenes import ROOT

MU_M3_S2 = 3.986004415e14  # m³/s², the scenario's (JEOD's) Earth GM
#: ISS-like state at t = 0 (the scenario's numbers; e ≈ 0.0078, i ≈ 51.6 deg)
R0_N_M = np.array([-4315967.74, 960356.2, 5167269.53])
V0_N_M_S = np.array([129.091037, -7491.513855, 1452.515654])
#: an e = 0.3 orbit as elements: a [m], e, i, raan, argp, nu [rad]
ELEMENTS_E03 = {"a": 1.2e7, "e": 0.3, "i": 0.5, "raan": 2.0, "argp": -1.0 % (2 * math.pi), "nu": 2.5}
SCENARIO = ROOT / "scenarios" / "jeod_style_eccentric_libration.toml"
J2 = 1.08262668e-3  # EGM96 / WGS-84 second zonal harmonic
R_EQ_M = 6378137.0  # m, WGS-84 equatorial radius

# -- tolerances (each with its reason) ------------------------------------------------------
#: the truth integrates at rtol 1e-12: over 3 orbits its position error is ~1e-12 x 7e6 m x
#: (steps' growth) ~ 1e-4 m; Kepler's equation is solved to 1e-16 rad (~1e-9 m)
POS_TOL_M = 2e-3
VEL_TOL_M_S = 2e-6  # the same, times the orbital rate ~1e-3 /s
#: energy and h from r, v of ~1e7 m and ~1e4 m/s: float64 round-off of a few dozen operations
CONSERVE_REL = 1e-12
#: elements -> state -> elements: round-off of acos/atan2 on values of order 1
ROUND_TRIP_RAD = 1e-10
#: central difference with dt = 0.1 s: truncation ~ω³ dt²/6 ~ 2e-12 rad/s at ω ~ 1.2e-3 /s,
#: round-off ~1e-16 / dt
FD_DT_S = 0.1
FD_RATE_TOL = 5e-12
#: the same difference of r: truncation ~(ω dt)²/6 |v| ~ 1.4e-5 m/s at the e = 0.3 perigee
FD_VEL_TOL_M_S = 3e-5
#: THE KEY CHECK (issue 14): the attitude of a rigid body over 8 hours
ATT_TOL_RAD = 1e-9
#: the circular orbit written as e = 0 elements: the same numbers by other operations
CIRC_POS_REL = 1e-12
CIRC_ATT_TOL_RAD = 1e-11


# -- independent truths ---------------------------------------------------------------------
def two_body(t_eval, r0, v0, mu=MU_M3_S2, j2=0.0):
    """Position and velocity by integrating ``r̈ = -μ r / r³`` (plus J2 when given), shape (n, 3) each."""

    def f(t, y):
        r, v = y[:3], y[3:]
        rn = np.linalg.norm(r)
        acc = -mu * r / rn**3
        if j2:  # zonal J2 acceleration (Vallado Eq. 8-30)
            k = 1.5 * j2 * mu * R_EQ_M**2 / rn**5
            z2 = 5.0 * r[2] ** 2 / rn**2
            acc = acc - k * np.array([r[0] * (1 - z2), r[1] * (1 - z2), r[2] * (3 - z2)])
        return np.concatenate([v, acc])

    sol = solve_ivp(f, (0.0, t_eval[-1]), np.concatenate([r0, v0]), method="DOP853", t_eval=t_eval,
                    rtol=1e-12, atol=np.r_[np.full(3, 1e-6), np.full(3, 1e-9)])
    return sol.y[:3].T, sol.y[3:].T


def state_of_elements(a, e, i, raan, argp, nu, mu=MU_M3_S2):
    """Inertial state of elements: perifocal position/velocity rotated by R_z(Ω) R_x(i) R_z(ω)."""
    p = a * (1 - e * e)
    r_pf = p / (1 + e * math.cos(nu)) * np.array([math.cos(nu), math.sin(nu), 0.0])
    v_pf = math.sqrt(mu / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])
    R = Rotation.from_euler("ZXZ", [raan, i, argp]).as_matrix()
    return R @ r_pf, R @ v_pf


def lvlh_of(r, v):
    """C_ON rows (x, y, z) from the state: z = -r̂, y = -ĥ, x = y × z."""
    z = -r / np.linalg.norm(r)
    h = np.cross(r, v)
    y = -h / np.linalg.norm(h)
    return np.array([np.cross(y, z), y, z])


def orbit_scene(orbit: dict, **sim) -> object:
    return scene_from_dict({
        "name": "orbit_test",
        "simulation": {"duration": 6000.0, "rtol": 1e-12, "atol": 1e-14, "output_dt": 10.0, **sim},
        "body": {"mass": 1.0e4, "inertia": [[3.3e5, 0, 0], [0, 3.4e5, 0], [0, 0, 2.0e4]], "cm": [0, 0, 0]},
        "orbit": {"gravity_gradient": True, **orbit},
    })


RV_ORBIT = {"r_N": R0_N_M.tolist(), "v_N": V0_N_M_S.tolist(), "mu": MU_M3_S2}
E03_ORBIT = {"elements": ELEMENTS_E03, "mu": MU_M3_S2}
ORBITS = {"iss_e0.0078_rv": RV_ORBIT, "e0.3_elements": E03_ORBIT}


def initial_state_of(orbit: dict):
    if "r_N" in orbit:
        return R0_N_M, V0_N_M_S
    return state_of_elements(**orbit["elements"])


def period_s(r0, v0, mu=MU_M3_S2):
    a = -mu / (2 * (0.5 * v0 @ v0 - mu / np.linalg.norm(r0)))
    return 2 * math.pi * math.sqrt(a**3 / mu)


# -- the orbit model ------------------------------------------------------------------------
@pytest.mark.parametrize("e", [0.0, 0.0078, 0.1, 0.3, 0.6, 0.7], ids=lambda e: f"e{e}")
def test_proven_newton_steps_solve_keplers_equation(e):
    """After ``newton_steps(e)`` steps, E - e sin E = M to round-off, on a dense grid of M over
    two revolutions (the residual's slope is 1 - e cos E >= 1 - e, so E errs by at most 1/(1-e)
    times it); E increases with M (a continuous anomaly)."""
    M = np.linspace(-2 * math.pi, 2 * math.pi, 20001)
    E = solve_kepler(M, e, newton_steps(e))
    assert np.abs(E - e * np.sin(E) - M).max() <= 8 * np.finfo(float).eps * 2 * math.pi
    assert np.all(np.diff(E) > 0)


@pytest.mark.parametrize("name", ORBITS, ids=list(ORBITS))
def test_kepler_matches_two_body_integration(name):
    orbit = ORBITS[name]
    r0, v0 = initial_state_of(orbit)
    t = np.linspace(0.0, 3 * period_s(r0, v0), 601)
    r_true, v_true = two_body(t, r0, v0)
    o = orbit_numeric(orbit_scene(orbit).orbit, t)
    assert_allclose(o.r_N.T, r_true, rtol=0, atol=POS_TOL_M)
    assert_allclose(o.v_N.T, v_true, rtol=0, atol=VEL_TOL_M_S)


@pytest.mark.parametrize("name", ORBITS, ids=list(ORBITS))
def test_two_body_energy_and_angular_momentum_conserved(name):
    orbit = ORBITS[name]
    r0, v0 = initial_state_of(orbit)
    t = np.linspace(0.0, 5 * period_s(r0, v0), 2001)
    o = orbit_numeric(orbit_scene(orbit).orbit, t)
    r, v = o.r_N.T, o.v_N.T
    energy = 0.5 * np.sum(v * v, axis=1) - MU_M3_S2 / np.linalg.norm(r, axis=1)
    h = np.cross(r, v)
    e0 = 0.5 * v0 @ v0 - MU_M3_S2 / np.linalg.norm(r0)
    assert_allclose(energy, e0, rtol=CONSERVE_REL, atol=0)
    assert_allclose(h, np.tile(np.cross(r0, v0), (len(t), 1)), rtol=0, atol=CONSERVE_REL * np.linalg.norm(np.cross(r0, v0)))


def test_elements_state_round_trip():
    el = ELEMENTS_E03
    r, v = rv_from_elements(el["a"], el["e"], el["i"], el["raan"], el["argp"], el["nu"], MU_M3_S2)
    r_ref, v_ref = state_of_elements(**el)
    assert_allclose(r, r_ref, rtol=1e-13, atol=0)
    assert_allclose(v, v_ref, rtol=1e-13, atol=0)
    back = elements_from_rv(r, v, MU_M3_S2)
    assert_allclose(back[0], el["a"], rtol=1e-13)
    assert_allclose(back[1:], [el[k] for k in ("e", "i", "raan", "argp", "nu")], rtol=0, atol=ROUND_TRIP_RAD)


def test_state_form_equals_elements_form():
    el = ELEMENTS_E03
    r0, v0 = state_of_elements(**el)
    t = np.linspace(0.0, 2 * period_s(r0, v0), 301)
    a = orbit_numeric(orbit_scene(E03_ORBIT).orbit, t)
    b = orbit_numeric(orbit_scene({"r_N": r0.tolist(), "v_N": v0.tolist(), "mu": MU_M3_S2}).orbit, t)
    assert_allclose(a.r_N, b.r_N, rtol=0, atol=1e-6)  # m: elements recovered to ~1e-13 relative
    assert_allclose(a.C_ON, b.C_ON, rtol=0, atol=1e-12)


# -- J2 -------------------------------------------------------------------------------------
def node_of(C_ON):
    """RAAN [rad] of the orbit plane whose normal is -y_O (rows of C_ON, shape (3, 3, n))."""
    h = -C_ON[1]
    return np.unwrap(np.arctan2(h[0], -h[1]))


def test_j2_node_and_perigee_drift_closed_form():
    el = {"a": 8.0e6, "e": 0.1, "i": 0.9, "raan": 1.0, "argp": 0.5, "nu": 0.0}
    scene = orbit_scene({"elements": el, "mu": MU_M3_S2, "j2": True})
    day = 86400.0
    t = np.arange(0.0, day, 2.0)
    o = orbit_numeric(scene.orbit, t)
    n0 = math.sqrt(MU_M3_S2 / el["a"] ** 3)
    k = J2 * (R_EQ_M / (el["a"] * (1 - el["e"] ** 2))) ** 2
    raan_dot = -1.5 * n0 * k * math.cos(el["i"])
    argp_dot = 0.75 * n0 * k * (4 - 5 * math.sin(el["i"]) ** 2)
    node = node_of(o.C_ON)
    assert_allclose(node - node[0], raan_dot * t, rtol=0, atol=1e-12)  # rad: closed form, round-off
    # perigee: the argument of latitude at each minimum of r (parabola through the samples)
    r = np.linalg.norm(o.r_N, axis=0)
    i_min = np.nonzero((r[1:-1] < r[:-2]) & (r[1:-1] < r[2:]))[0] + 1
    u = np.unwrap(np.arctan2(o.sin_u, o.cos_u))
    frac = 0.5 * (r[i_min - 1] - r[i_min + 1]) / (r[i_min - 1] - 2 * r[i_min] + r[i_min + 1])
    t_p = t[i_min] + frac * 2.0
    u_p = np.interp(t_p, t, u)
    slope = np.polyfit(t_p, u_p - 2 * math.pi * np.arange(len(t_p)), 1)[0]
    assert len(t_p) > 10
    assert_allclose(slope, argp_dot, rtol=1e-4)  # the parabola's error on samples 2 s apart


def test_j2_node_drift_matches_integrated_j2_orbit():
    """The model's mean node rate against the osculating node of an integrated J2 orbit, fitted by
    a straight line over a day (the short-period terms average out to ~0.5 % of the drift)."""
    el = {"a": 6.78e6, "e": 0.001, "i": 0.9, "raan": 1.0, "argp": 0.5, "nu": 0.0}
    scene = orbit_scene({"elements": el, "mu": MU_M3_S2, "j2": True})
    t = np.linspace(0.0, 86400.0, 3001)
    r, v = two_body(t, *state_of_elements(**el), j2=J2)
    h = np.cross(r, v)
    node_true = np.unwrap(np.arctan2(h[:, 0], -h[:, 1]))
    node_model = node_of(orbit_numeric(scene.orbit, t).C_ON)
    rate_true = np.polyfit(t, node_true, 1)[0]
    rate_model = np.polyfit(t, node_model, 1)[0]
    assert_allclose(rate_model, rate_true, rtol=5e-3)


# -- LVLH on an eccentric orbit ---------------------------------------------------------------
@pytest.mark.parametrize("name", ORBITS, ids=list(ORBITS))
def test_lvlh_frame_and_rate_on_eccentric_orbit(name):
    orbit = ORBITS[name]
    r0, v0 = initial_state_of(orbit)
    t = np.linspace(0.0, period_s(r0, v0), 97)
    o = orbit_numeric(orbit_scene(orbit).orbit, t)
    r, v = o.r_N.T, o.v_N.T
    C = np.moveaxis(o.C_ON, 2, 0)  # (n, 3, 3)
    # orthonormal and equal to the frame built from r, v
    assert_allclose(C @ np.swapaxes(C, 1, 2), np.broadcast_to(np.eye(3), C.shape), rtol=0, atol=1e-14)
    assert_allclose(C, np.array([lvlh_of(a, b) for a, b in zip(r, v)]), rtol=0, atol=1e-13)
    # the rate: (0, -h/r², 0), h/r² from r and v
    nu_dot = np.linalg.norm(np.cross(r, v), axis=1) / np.sum(r * r, axis=1)
    assert_allclose(o.omega_ON_O.T, np.c_[0 * nu_dot, -nu_dot, 0 * nu_dot], rtol=1e-13, atol=0)
    # ... equals the finite difference of C_ON: skew(omega_ON_O) = -Ċ_ON C_ONᵀ; v = ṙ
    ap, am = orbit_numeric(orbit_scene(orbit).orbit, t + FD_DT_S), orbit_numeric(orbit_scene(orbit).orbit, t - FD_DT_S)
    C_dot = np.moveaxis((ap.C_ON - am.C_ON) / (2 * FD_DT_S), 2, 0)
    W = -C_dot @ np.swapaxes(C, 1, 2)
    w_fd = np.c_[W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]]
    assert_allclose(w_fd, o.omega_ON_O.T, rtol=0, atol=FD_RATE_TOL)
    assert_allclose((ap.r_N - am.r_N).T / (2 * FD_DT_S), v, rtol=0, atol=FD_VEL_TOL_M_S)
    # continuous quaternion with dcm(q_ON) = C_ON
    q = o.q_ON.T
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0.9)
    C_q = Rotation.from_quat(np.c_[q[:, 1:], q[:, 0]]).as_matrix()  # = C_NO
    assert_allclose(np.swapaxes(C_q, 1, 2), C, rtol=0, atol=1e-13)


def test_initial_lvlh_rate_on_eccentric_orbit():
    """``initial.frame = "lvlh"`` at rest relative to LVLH: ω_BN = C_BO (0, -h/r², 0)."""
    scene = load_scene(SCENARIO)
    q, w = initial_state(scene)
    C_ON = lvlh_of(R0_N_M, V0_N_M_S)
    C_BO = Rotation.from_quat(np.r_[scene.initial.q_BN[1:], scene.initial.q_BN[0]]).as_matrix().T
    C_BN = Rotation.from_quat(np.r_[q[1:], q[0]]).as_matrix().T
    assert_allclose(C_BN, C_BO @ C_ON, rtol=0, atol=1e-14)
    nu_dot = np.linalg.norm(np.cross(R0_N_M, V0_N_M_S)) / (R0_N_M @ R0_N_M)
    assert_allclose(w, C_BO @ np.array([0.0, -nu_dot, 0.0]), rtol=1e-13, atol=0)


# -- THE KEY CHECK: a rigid body on the eccentric orbit ---------------------------------------
def independent_libration(scene, t_eval):
    """Quaternion, body rate, position and velocity integrated together (scipy DOP853)."""
    I = np.array(scene.body.inertia)
    I_inv = np.linalg.inv(I)
    C_ON = lvlh_of(R0_N_M, V0_N_M_S)
    qi = scene.initial.q_BN
    C_BO = Rotation.from_quat([qi[1], qi[2], qi[3], qi[0]]).as_matrix().T
    C_BN = C_BO @ C_ON
    x, y, z, w = Rotation.from_matrix(C_BN.T).as_quat()
    nu_dot = np.linalg.norm(np.cross(R0_N_M, V0_N_M_S)) / (R0_N_M @ R0_N_M)
    w0 = C_BO @ np.array([0.0, -nu_dot, 0.0])  # at rest relative to LVLH

    def f(t, s):
        q, om, r, v = s[:4], s[4:7], s[7:10], s[10:13]
        qw, qx, qy, qz = q
        C = np.array([  # C_BN of q (Schaub & Junkins Eq. 3.98, written out here)
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qw * qz), 2 * (qx * qz - qw * qy)],
            [2 * (qx * qy - qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + qw * qx)],
            [2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy)],
        ])
        rn = np.linalg.norm(r)
        r_B = C @ r
        L = 3 * MU_M3_S2 / rn**5 * np.cross(r_B, I @ r_B)
        q_dot = 0.5 * np.array([-qx * om[0] - qy * om[1] - qz * om[2], qw * om[0] - qz * om[1] + qy * om[2],
                                qz * om[0] + qw * om[1] - qx * om[2], -qy * om[0] + qx * om[1] + qw * om[2]])
        return np.concatenate([q_dot, I_inv @ (L - np.cross(om, I @ om)), v, -MU_M3_S2 * r / rn**3])

    s0 = np.concatenate([[w, x, y, z], w0, R0_N_M, V0_N_M_S])
    atol = np.r_[np.full(4, 1e-16), np.full(3, 1e-19), np.full(3, 1e-7), np.full(3, 1e-10)]
    sol = solve_ivp(f, (0.0, t_eval[-1]), s0, method="DOP853", t_eval=t_eval, rtol=1e-13, atol=atol)
    assert sol.success
    return sol.y[:4].T


def angle_between(q1, q2):
    """Rotation angle [rad] between attitude quaternion rows (scalar first), sign-blind and exact
    when small: ``2 asin |vec(conj(q1) ⊗ q2)|`` (``1 - (q1·q2)²`` would lose it to round-off)."""
    w1, v1 = q1[:, 0], q1[:, 1:]
    w2, v2 = q2[:, 0], q2[:, 1:]
    vec = w1[:, None] * v2 - w2[:, None] * v1 - np.cross(v1, v2)
    norm = np.linalg.norm(q1, axis=1) * np.linalg.norm(q2, axis=1)
    return 2 * np.arcsin(np.clip(np.linalg.norm(vec, axis=1) / norm, 0, 1))


@pytest.fixture(scope="module")
def libration_truth():
    scene = load_scene(SCENARIO)
    t = np.arange(0.0, scene.simulation.duration + 1.0, 60.0)
    return scene, t, independent_libration(scene, t)


@pytest.mark.parametrize("formulation", ["momentum", "momentum27", "dalembert", "hamel"])
def test_rigid_body_on_eccentric_orbit_matches_independent_model(libration_truth, formulation):
    scene, t, q_true = libration_truth
    tr = stationbed.simulate(scene, formulation=formulation, output_dt=60.0)
    assert_allclose(tr.t, t, rtol=0, atol=1e-9)
    err = angle_between(tr.q_BN, q_true)
    assert err.max() < ATT_TOL_RAD, f"{formulation}: max attitude difference {err.max():.3g} rad"
    # the body librates about LVLH (built here from the integrated orbit): from 0.1 rad through 0
    r, v = two_body(t, R0_N_M, V0_N_M_S)
    C_NB = Rotation.from_quat(np.c_[tr.q_BN[:, 1:], tr.q_BN[:, 0]]).as_matrix()
    C_BO = np.swapaxes(C_NB, 1, 2) @ np.swapaxes(np.array([lvlh_of(a, b) for a, b in zip(r, v)]), 1, 2)
    off_lvlh = Rotation.from_matrix(C_BO).magnitude()
    assert off_lvlh.min() < 0.02 and off_lvlh.max() > 0.09


# -- the circular orbit as e = 0 elements -----------------------------------------------------
def test_circular_orbit_as_elements_agrees_with_circular_path():
    R, i, u0 = 6.9e6, 0.9, 0.4  # m, rad, rad
    circ = orbit_scene({"radius": R, "inclination": i, "u0": u0, "mu": MU_M3_S2})
    kep = orbit_scene({"elements": {"a": R, "e": 0.0, "i": i, "raan": 0.0, "argp": 0.0, "nu": u0}, "mu": MU_M3_S2})
    t = np.linspace(0.0, 6000.0, 301)
    a, b = orbit_numeric(circ.orbit, t), orbit_numeric(kep.orbit, t)
    assert_allclose(b.r_N, a.r_N, rtol=0, atol=CIRC_POS_REL * R)
    assert_allclose(b.C_ON, a.C_ON, rtol=0, atol=1e-12)
    assert_allclose(b.omega_ON_O, a.omega_ON_O, rtol=0, atol=1e-12 * circ.orbit.mean_motion)
    init = {"frame": "lvlh", "q_BN": [0.99875026039496628, 0.0, 0.049979169270678331, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]}
    runs = [stationbed.simulate(s.replace({"initial": init})) for s in (circ, kep)]
    assert_allclose(runs[1].t, runs[0].t, rtol=0, atol=0)
    assert angle_between(runs[0].q_BN, runs[1].q_BN).max() < CIRC_ATT_TOL_RAD


# -- scene validation -------------------------------------------------------------------------
BAD = {
    "two_forms": ({"radius": 7e6, "elements": ELEMENTS_E03}, r"orbit: give exactly one"),
    "r_without_v": ({"r_N": R0_N_M.tolist()}, r"orbit\.v_N: give both"),
    "hyperbolic": ({"r_N": R0_N_M.tolist(), "v_N": (2 * V0_N_M_S).tolist()}, r"orbit\.v_N: .*not a bound orbit"),
    "perigee_inside": ({"elements": {**ELEMENTS_E03, "a": 7.0e6}}, r"orbit\.elements\.e: perigee radius"),
    "e_one": ({"elements": {**ELEMENTS_E03, "e": 1.0}}, r"orbit\.elements\.e"),
    "e_unproven": ({"elements": {**ELEMENTS_E03, "a": 3.0e7, "e": 0.75}}, r"orbit\.elements\.e: eccentricity 0\.75 above 0\.7"),
    "j2_circular": ({"radius": 7e6, "j2": True}, r"orbit\.j2: needs a two-body orbit"),
    "u0_with_elements": ({"elements": ELEMENTS_E03, "u0": 0.3}, r"orbit\.u0: belongs to the circular form"),
    "elements_typo": ({"elements": {**ELEMENTS_E03, "argp_typo": 1.0}}, r"orbit\.elements\.argp_typo"),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_orbit_is_a_one_line_error_naming_the_field(case):
    orbit, pattern = BAD[case]
    with pytest.raises(SceneError, match=pattern) as err:
        orbit_scene(orbit)
    assert "\n" not in str(err.value)
