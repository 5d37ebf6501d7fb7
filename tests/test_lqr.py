"""The ``lqr`` law (controllers/lqr.py): its design model, its poles, margins and settling time,
each checked against a truth that does not come from the design code."""

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from controllers.lqr import LQR
from stationbed import simulate
from stationbed.run.controller import ControllerError, Plant
from stationbed.model.environment import C_ON
from stationbed.core.rotation import dcm, quat_from_dcm
from stationbed.scene import scene_from_dict

#: JEOD ISS inertia, products of inertia included [kg m²] (scenarios/iss_lvlh_gravity_gradient.toml)
JEOD_I = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]
#: its principal part [kg m²]
JEOD_DIAG = [1.02e8, 0.91e8, 1.64e8]
N_400KM = math.sqrt(3.986004418e14 / 6778137.0**3)  # rad/s, mean motion at 400 km
PERIOD_S = 0.1  # s, the controller period (10 Hz)

#: A is exact AD of the model; the textbook coefficients are products of 1e8-size inertias:
#: float64 rounding only.
JAC_RTOL = 1e-12
#: Central differences of the simulation with ε = 1e-4 rad / 1e-7 rad/s: the truncation error is
#: O(ε²) of the quadratic terms, ~1e-8 relative; RK4 at 0.1 s adds ~(|s| T)⁴ ≈ 1e-13 (measured
#: agreement 4e-10).
FD_RTOL = 1e-6
#: Settling: 4/|Re s_slow| is when the slowest mode has decayed to e⁻⁴ = 1.8 % of its initial
#: amplitude, so the band is 2 % of the initial error. The margin of 25 % is for the share of the
#: initial error that the slowest mode carries (the three oscillatory pairs are coupled by gravity
#: gradient and gyroscopic terms, so it is not 1; measured worst: 1.15 t_s, about yaw).
SETTLE_BAND = 0.02
SETTLE_MARGIN = 1.25


def lqr_scene(theta0=(0.0, 0.0, 0.0), domega0=(0.0, 0.0, 0.0), duration=100.0, output_dt=10.0, params=None,
              inertia=JEOD_I, orbit=True):
    """The rigid JEOD station, gravity gradient, the lqr law as an ideal torquer (no CMG)."""
    e = [0.5 * v for v in theta0]
    q_BO = [math.sqrt(1.0 - sum(v * v for v in e)), *e]
    d = {
        "name": "lqr_test",
        "simulation": {"duration": duration, "integrator": "rk4", "step": PERIOD_S, "output_dt": output_dt},
        "initial": {"frame": "lvlh", "q_BN": q_BO, "omega_BN_B": list(domega0)},
        "body": {"mass": 4.0e5, "inertia": inertia, "cm": [0.0, 0.0, 0.0]},
        "orbit": {"altitude": 400000.0, "inclination": 0.9006, "u0": 0.3, "gravity_gradient": True},
        "controller": {"name": "lqr", "period": PERIOD_S, "params": params or {}},
    }
    if not orbit:
        del d["orbit"]
        d["initial"]["frame"] = "inertial"
    return scene_from_dict(d)


def designed(inertia=JEOD_I, **params) -> LQR:
    c = LQR(period=PERIOD_S, **params)
    c.reset(Plant(scene=None, inertia_O_B=np.array(inertia, float), mean_motion=N_400KM, period=PERIOD_S))
    return c


def lvlh_state(tr, scene) -> np.ndarray:
    """``(θ, δω)`` relative to LVLH at the last row, from the trajectory (independent of the law)."""
    o = scene.orbit
    C_BO = dcm(tr.q_BN[-1]) @ C_ON(o.u0 + o.mean_motion * tr.t[-1], o.inclination).T
    q = quat_from_dcm(C_BO)
    q = q if q[0] >= 0 else -q
    dw = tr.omega_BN_B[-1] - C_BO @ np.array([0.0, -o.mean_motion, 0.0])
    return np.r_[2.0 * q[1:], dw]


def match(a, b):
    """``b`` reordered to pair each of ``a`` with its nearest (poles, small sets)."""
    b = list(b)
    out = []
    for s in a:
        j = int(np.argmin([abs(s - x) for x in b]))
        out.append(b.pop(j))
    return np.array(out)


# -- design model ------------------------------------------------------------------------
def test_design_model_matches_textbook_lvlh_equations():
    """With principal axes along LVLH the casadi Jacobians are Wie's linearised equations
    (Space Vehicle Dynamics and Control, 2nd ed., §7.2; x along velocity, z nadir, ω_O = (0,-n,0)):
    J1 θ̈1 - n(J1-J2+J3) θ̇3 + 4n²(J2-J3) θ1 = u1;  J2 θ̈2 + 3n²(J1-J3) θ2 = u2;
    J3 θ̈3 + n(J1-J2+J3) θ̇1 + n²(J2-J1) θ3 = u3."""
    J1, J2, J3 = JEOD_DIAG
    n = N_400KM
    c = designed(inertia=np.diag(JEOD_DIAG))
    A, B = c.A, c.B
    Jd = np.diag(JEOD_DIAG)
    stiff = -np.diag([4 * n**2 * (J2 - J3), 3 * n**2 * (J1 - J3), n**2 * (J2 - J1)])
    gyro = np.zeros((3, 3))
    gyro[0, 2] = n * (J1 - J2 + J3)
    gyro[2, 0] = -n * (J1 - J2 + J3)
    expected = np.block([[np.zeros((3, 3)), np.eye(3)], [np.linalg.solve(Jd, stiff), np.linalg.solve(Jd, gyro)]])
    assert_allclose(A, expected, rtol=JAC_RTOL, atol=JAC_RTOL * np.abs(expected).max())
    assert_allclose(B, np.vstack([np.zeros((3, 3)), np.linalg.inv(Jd)]), rtol=JAC_RTOL)


@pytest.mark.slow
def test_feedforward_holds_lvlh_with_products_of_inertia():
    """With the JEOD products of inertia LVLH needs a steady torque (gravity gradient + ω × Iω,
    written here in numpy); the law's feedforward u0 is that torque, and the station started in
    LVLH stays there to round-off."""
    n = N_400KM
    I = np.array(JEOD_I)
    w = np.array([0.0, -n, 0.0])
    r = np.array([0.0, 0.0, -1.0])  # zenith in LVLH = B at rest in LVLH
    u_needed = np.cross(w, I @ w) - 3 * n**2 * np.cross(r, I @ r)
    c = designed()
    assert_allclose(c.u0, u_needed, rtol=1e-12)
    sc = lqr_scene(duration=1000.0, output_dt=1000.0)
    assert np.max(np.abs(lvlh_state(simulate(sc), sc))) < 1e-12  # rad, rad/s: round-off


def ss_zoh(A, B, T: float):
    """Zero-order-hold discretisation over ``T`` [s]: ``(e^{AT}, ∫₀ᵀ e^{As} ds B)`` (Van Loan's block
    exponential, written here: independent of python-control's ``c2d``)."""
    from scipy.linalg import expm

    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * T)
    return E[:n, :n], E[:n, n:]


# -- poles -------------------------------------------------------------------------------
def test_reported_poles_are_eig_A_minus_BK():
    c = designed()
    assert_allclose(np.sort_complex(c.poles), np.sort_complex(np.linalg.eigvals(c.A - c.B @ c.K)), rtol=1e-12)
    assert_allclose(np.sort_complex(c.poles), np.sort_complex(c.lqr_poles), rtol=1e-9)
    s = c.summary()
    assert_allclose(s["lqr_settling_time_s"], 4.0 / np.min(np.abs(c.poles.real)))
    assert len(s["lqr_poles_rad_s"]) == 6 and all(p[0] < 0 for p in s["lqr_poles_rad_s"])
    json.dumps(s, allow_nan=False)  # strict JSON (summary.json): no inf/NaN, no complex


@pytest.fixture(scope="module")
def simulated_poles():
    """Poles of the *simulation* itself, linearised by central differences about LVLH.

    Each of the 6 state directions is perturbed (±ε) in the scene's initial condition and
    ``simulate`` runs N control periods (RK4, zero-order hold, the law in the loop); the columns
    of the N-period transition matrix Φ_N are the differences of the final (θ, δω). Its
    eigenvalues are exp(s N T).
    """
    c = designed()
    T = PERIOD_S
    N = int(round(1.5 / np.max(np.abs(c.poles)) / T))  # |s| N T ≈ 1.5 < π: log is unambiguous
    eps = np.r_[[1e-4] * 3, [1e-7] * 3]  # rad, rad/s
    Phi = np.zeros((6, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = eps[i]
        sc_p = lqr_scene(d[:3], d[3:], duration=N * T, output_dt=N * T)
        sc_m = lqr_scene(-d[:3], -d[3:], duration=N * T, output_dt=N * T)
        Phi[:, i] = (lvlh_state(simulate(sc_p), sc_p) - lvlh_state(simulate(sc_m), sc_m)) / (2 * eps[i])
    s_sim = np.log(np.linalg.eigvals(Phi).astype(complex)) / (N * T)
    return c, s_sim


@pytest.mark.slow
def test_simulation_poles_equal_zoh_discretised_design(simulated_poles):
    """The closed loop as simulated (nonlinear plant, 10 Hz zero-order hold) has exactly the poles
    of the design model discretised with the hold: eig(e^{AT} - ∫e^{As}ds B K)."""
    c, s_sim = simulated_poles
    Ad, Bd = ss_zoh(c.A, c.B, PERIOD_S)
    s_zoh = np.log(np.linalg.eigvals(Ad - Bd @ c.K).astype(complex)) / PERIOD_S
    assert_allclose(match(s_zoh, s_sim), s_zoh, rtol=FD_RTOL)


def test_simulation_poles_equal_designed_continuous_poles(simulated_poles):
    """... and the designed continuous poles eig(A - B K), to the hold's effect: the half-period
    delay of a zero-order hold moves a pole s by O(|s| T / 2) relative (|s|max T = 5e-4 here)."""
    c, s_sim = simulated_poles
    zoh_rtol = np.max(np.abs(c.poles)) * PERIOD_S
    assert_allclose(match(c.poles, s_sim), c.poles, rtol=zoh_rtol)


# -- margins -----------------------------------------------------------------------------
def _sweep_phase_margin_deg(A, B, K, i):
    """Phase margin of the loop broken at input i by a dense frequency sweep (no python-control)."""
    m = B.shape[1]
    others = [j for j in range(m) if j != i]
    Ai = A - B[:, others] @ K[others, :]
    w = np.logspace(-6, 1, 40001)
    L = np.array([K[i] @ np.linalg.solve(1j * wk * np.eye(A.shape[0]) - Ai, B[:, i]) for wk in w])
    mag = np.abs(L)
    k = np.nonzero(np.diff(np.sign(mag - 1.0)))[0]
    pms = []
    for j in k:  # linear interpolation in log-frequency of the crossing
        f = (1.0 - mag[j]) / (mag[j + 1] - mag[j])
        ph = np.angle(L[j]) + f * np.angle(L[j + 1] / L[j])
        pms.append(abs(180.0 - abs(math.degrees(ph))))
    return min(pms)


@pytest.mark.parametrize("i", [0, 1, 2], ids=["roll_input", "pitch_input", "yaw_input"])
def test_margins_match_frequency_sweep_and_lqr_guarantee(i):
    """Each channel's reported phase margin equals a dense sweep of L_i(jω), and meets the LQR
    guarantee (Kalman's return-difference inequality |1 + L| ≥ 1, diagonal R): phase margin
    ≥ 60 deg, gain margin from 1/2 to infinity."""
    c = designed()
    mg = c.margins[i]
    assert mg["phase_margin_deg"] == pytest.approx(_sweep_phase_margin_deg(c.A, c.B, c.K, i), abs=0.05)
    assert mg["phase_margin_deg"] >= 60.0
    assert mg["gain_margin_down"] <= 0.5
    assert mg["gain_margin_up"] == math.inf
    assert mg["stability_margin"] >= 1.0 - 1e-9  # the grid minimum tends to 1 as ω → ∞


# -- settling in the nonlinear simulation --------------------------------------------------
@pytest.mark.parametrize(
    "theta0",
    [(0.05, 0.0, 0.0), (0.0, 0.05, 0.0), (0.0, 0.0, 0.05), (0.02, -0.03, 0.04)],
    ids=["roll", "pitch", "yaw", "oblique"],
)
def test_nonlinear_run_settles_within_predicted_time(theta0):
    """From a 2.9-3.2 deg error the full simulation (nonlinear plant, products of inertia, 10 Hz
    hold) stays inside 2 % of the initial error after SETTLE_MARGIN x the predicted 4/|Re s|."""
    sc = lqr_scene(theta0, duration=4000.0)
    tr = simulate(sc)
    t_s = tr.meta["summary"]["lqr_settling_time_s"]
    err = tr["att_err_deg"]
    after = tr.t >= SETTLE_MARGIN * t_s
    assert tr.t[-1] > SETTLE_MARGIN * t_s and after.sum() > 10
    assert err[after].max() <= SETTLE_BAND * err[0]


# -- errors --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "params, word",
    [
        ({"max_torque": -1.0}, "max_torque"),
        ({"max_attitude": 0.0}, "max_attitude"),
        ({"max_rate": float("nan")}, "max_rate"),
        ({"q_ref": [1.0, 0.1, 0.0, 0.0]}, "q_ref"),
        ({"max_torq": 5.0}, "max_torq"),
    ],
    ids=["negative_torque", "zero_attitude", "nan_rate", "non_unit_q_ref", "unknown_key"],
)
def test_bad_parameters_name_the_parameter(params, word):
    with pytest.raises(ControllerError, match=word):
        simulate(lqr_scene(params=params, duration=1.0))


def test_design_too_fast_for_the_period_names_the_fix():
    """A design whose poles are too fast for a 10 Hz hold is refused, naming the knob."""
    with pytest.raises(ControllerError, match="max_torque"):
        simulate(lqr_scene(params={"max_torque": 1e7, "max_attitude": 1e-5, "max_rate": 1e-6}, duration=1.0))


def test_deep_space_scene_is_refused():
    with pytest.raises(ControllerError, match=r"\[orbit\]"):
        simulate(lqr_scene(duration=1.0, orbit=False))
