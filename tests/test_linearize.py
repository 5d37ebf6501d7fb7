"""stationbed.analysis: the linear plant of a scene and the loop analysis, each against a truth that
does not come from the linearisation code (the nonlinear simulation, closed-form libration and
free-hub frequencies, the shipped lqr's own design, a PD loop's phase margin worked by hand,
Van Loan's block exponential)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.linalg import expm

from stationbed import simulate
from stationbed.analysis import OperatingPoint, linearize, loop_analysis
from stationbed.core.rotation import dcm, quat_from_dcm
from stationbed.model.environment import C_ON
from stationbed.scene import scene_from_dict

#: JEOD ISS inertia with its products of inertia [kg m²] (scenarios/iss_lvlh_gravity_gradient.toml)
JEOD_I = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]
#: A pitch-stable station: Ix > Iz (the gravity gradient restores pitch) [kg m²]
STABLE_DIAG = [1.6e8, 1.1e8, 0.7e8]
#: float64 round-off on products of 1e8-size inertias and n² ~ 1e-6 (Jacobians are exact AD)
EIG_RTOL = 1e-9
#: O(ε²): when ε falls 10x the linearisation error falls 100x; the third-order terms (relative
#: size ε) and the integrator's own error (rtol 1e-12) leave it within 90..110.
RATIO_LO, RATIO_HI = 90.0, 110.0
#: The TEA as an equilibrium: Newton's residual (1e-10 n²) and the integrator (rtol 1e-12) over
#: 1500 s leave the simulated station within ~1e-11 rad of it; 1e-9 rad is far below any drift
#: a wrong TEA would show (n² t² Δθ ~ 3 Δθ).
EQUILIBRIUM_RAD = 1e-9
#: Two computations of the same closed-loop poles (the law's design; its symbolic form through
#: the scene's plant): round-off on 1e8-size inertias, amplified by the eigenproblem.
POLE_RTOL = 1e-8
#: python-control's crossover search (a polynomial root) against the closed form.
MARGIN_RTOL = 1e-6


def theta_q(th):
    """q for θ = 2 vec(q), scalar first (the plant's attitude coordinate)."""
    e = 0.5 * np.asarray(th, float)
    return np.r_[math.sqrt(1.0 - e @ e), e]


def orbit_scene(inertia, theta0=(0.0, 0.0, 0.0), domega0=(0.0, 0.0, 0.0), duration=10.0, controller=None):
    """A rigid station on a 400 km orbit with gravity gradient, started relative to LVLH."""
    d = {
        "name": "linear_test",
        "simulation": {"duration": duration, "rtol": 1e-12, "output_dt": duration},
        "initial": {"frame": "lvlh", "q_BN": theta_q(theta0).tolist(), "omega_BN_B": list(domega0)},
        "body": {"mass": 4.0e5, "inertia": np.asarray(inertia, float).tolist(), "cm": [0.0, 0.0, 0.0]},
        "orbit": {"altitude": 400000.0, "inclination": 0.9006, "u0": 0.3, "gravity_gradient": True},
    }
    if controller:
        d["controller"] = controller
        d["simulation"].update(integrator="rk4", step=controller["period"])
        del d["simulation"]["rtol"]
    return scene_from_dict(d)


#: the flexible array of the free-hub test: one mode, rotational participation Ĥ [kg m] about P z
H_HAT = [0.0, 0.0, 150.0]
MODAL_MASS = 1.0  # kg (η is then in √kg m units; only Ĥ²/M matters)
F_CLAMPED_HZ = 0.2
ARRAY_J = [[2.67e4, 0.0, 0.0], [0.0, 2.4e3, 0.0], [0.0, 0.0, 2.91e4]]  # kg m², P axes
HUB_J = [[3.0e5, 0.0, 0.0], [0.0, 2.0e5, 0.0], [0.0, 0.0, 4.0e5]]  # kg m²


def flexible_scene(theta0=(0.0, 0.0, 0.0), omega0=(0.0, 0.0, 0.0), eta0=0.0, eta_rate0=0.0, duration=10.0):
    """Deep space: a hub and one array (at the hub's mass centre, joints at zero) with one mode."""
    return scene_from_dict({
        "name": "flex_test",
        "simulation": {"duration": duration, "rtol": 1e-12, "output_dt": duration},
        "initial": {"q_BN": theta_q(theta0).tolist(), "omega_BN_B": list(omega0)},
        "body": {"mass": 2.0e4, "inertia": HUB_J, "cm": [0.0, 0.0, 0.0]},
        "appendage": [{
            "name": "wing", "mass": 800.0, "inertia": ARRAY_J, "cm": [0.0, 0.0, 0.0],
            "mode": [{"frequency_hz": F_CLAMPED_HZ, "rotation": H_HAT, "modal_mass": MODAL_MASS,
                      "eta0": eta0, "eta_rate0": eta_rate0}],
        }],
    })


def lvlh_z(tr, scene):
    """``(θ, δω)`` relative to LVLH at the last row, from the trajectory in numpy."""
    o = scene.orbit
    C_BO = dcm(tr.q_BN[-1]) @ C_ON(o.u0 + o.mean_motion * tr.t[-1], o.inclination).T
    q = quat_from_dcm(C_BO)
    q = q if q[0] >= 0 else -q
    return np.r_[2.0 * q[1:], tr.omega_BN_B[-1] - C_BO @ np.array([0.0, -o.mean_motion, 0.0])]


# -- the linear plant predicts the nonlinear simulation to O(ε²) ---------------------------------
def test_linear_response_is_nonlinear_to_second_order_about_the_tea():
    """From the TEA (found by the linearisation's Newton search, then simulated: it must stay put)
    offset by ε d, the nonlinear run after 1500 s differs from ``TEA + e^{AT} ε d`` by O(ε²)."""
    T = 1500.0
    sys = linearize(orbit_scene(JEOD_I), "tea")
    tea = sys.linearization.tea_theta
    d = np.r_[[1.0, -0.6, 0.8], [2e-4, -1e-4, 1.5e-4]]  # rad, rad/s per unit ε
    sc0 = orbit_scene(JEOD_I, tea, duration=T)
    assert np.abs(lvlh_z(simulate(sc0), sc0) - np.r_[tea, 0, 0, 0]).max() < EQUILIBRIUM_RAD  # an equilibrium
    errs = []
    for eps in (1e-2, 1e-3):
        z0 = eps * d
        sc = orbit_scene(JEOD_I, tea + z0[:3], z0[3:], duration=T)
        z_nl = lvlh_z(simulate(sc), sc) - np.r_[tea, 0, 0, 0]
        n = sc.orbit.mean_motion  # rates in units of n (rad per radian of orbit), like the angles
        errs.append(np.linalg.norm((z_nl - expm(sys.A * T) @ z0) / np.r_[[1.0] * 3, [n] * 3]))
    ratio = errs[0] / errs[1]
    assert RATIO_LO < ratio < RATIO_HI, (errs, ratio)


def test_linear_response_is_nonlinear_to_second_order_with_a_flexible_array():
    """Deep space, hub + flexible array: offsets of attitude, rate and the modal coordinate; the
    nonlinear run after 20 s against ``e^{AT} ε d`` (states θ, δω, η, η̇)."""
    T = 20.0
    sys = linearize(flexible_scene(), "lvlh")
    assert sys.state_labels == ["att_err_x", "att_err_y", "att_err_z", "rate_err_x", "rate_err_y", "rate_err_z",
                                "eta0_1", "eta0_1_rate"]
    d = np.r_[[0.5, -0.3, 0.4], [0.02, 0.01, -0.03], [0.05, 0.3]]
    errs = []
    for eps in (1e-1, 1e-2):
        z0 = eps * d
        sc = flexible_scene(z0[:3], z0[3:6], z0[6], z0[7], duration=T)
        tr = simulate(sc)
        q = tr.q_BN[-1] * np.sign(tr.q_BN[-1][0])
        z_nl = np.r_[2.0 * q[1:], tr.omega_BN_B[-1], tr["eta_wing_1"][-1], tr["etadot_wing_1"][-1]]
        errs.append(np.linalg.norm(z_nl - expm(sys.A * T) @ z0))
    ratio = errs[0] / errs[1]
    assert RATIO_LO < ratio < RATIO_HI, (errs, ratio)


# -- closed forms ----------------------------------------------------------------------------
def test_pitch_libration_pole():
    """Principal axes along LVLH (x along track, y minus orbit normal, z nadir): pitch is the
    gravity-gradient pendulum J_y θ̈ + 3n²(J_x - J_z) θ = 0, poles ±j n √(3(Ix - Iz)/Iy)."""
    sc = orbit_scene(np.diag(STABLE_DIAG))
    sys = linearize(sc, "lvlh")
    Ix, Iy, Iz = STABLE_DIAG
    w = sc.orbit.mean_motion * math.sqrt(3.0 * (Ix - Iz) / Iy)
    pitch = np.linalg.eigvals(sys.A[np.ix_([1, 4], [1, 4])])  # θ_y, δω_y: decoupled from roll/yaw
    assert_allclose(np.sort(pitch.imag), [-w, w], rtol=EIG_RTOL)
    assert_allclose(pitch.real, 0.0, atol=EIG_RTOL * w)
    assert np.min(np.abs(sys.poles() - 1j * w)) < EIG_RTOL * w
    # and the torque that holds a principal-axis LVLH attitude is zero
    assert np.abs(sys.linearization.trim_torque).max() < 1e-9


def test_flexible_mode_poles_sit_at_the_free_hub_frequency():
    """A mode of clamped frequency ω_c on a free hub: [I Δ; Δᵀ M] [ω̇; η̈] + [0; K η] = 0 gives
    ω_f² = K / (M - Δᵀ I⁻¹ Δ) (Δ = Ĥ: the array sits at the mass centre, P = B at zero joint
    angles, no translation participation); I the whole station's inertia. Undamped: ±j ω_f."""
    sys = linearize(flexible_scene(), "lvlh")
    I = np.array(HUB_J) + np.array(ARRAY_J)
    wc = 2 * math.pi * F_CLAMPED_HZ
    D = np.array(H_HAT)
    wf = wc * math.sqrt(MODAL_MASS / (MODAL_MASS - D @ np.linalg.solve(I, D)))
    p = sys.poles()
    osc = p[np.abs(p) > 1e-6]
    assert_allclose(np.sort(osc.imag), [-wf, wf], rtol=EIG_RTOL)
    assert wf > wc * 1.01  # the hub's freedom raises it measurably above the clamped one


def test_zoh_plant_is_van_loans_block_exponential():
    """``linearize(..., dt=T)`` = (e^{AT}, ∫₀ᵀ e^{As} ds B), computed here by Van Loan's block
    exponential, with the same signal names."""
    sc = orbit_scene(JEOD_I)
    c = linearize(sc, "lvlh")
    T = 10.0
    d = linearize(sc, "lvlh", dt=T)
    n, m = c.B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = c.A, c.B
    E = expm(M * T)
    assert_allclose(d.A, E[:n, :n], rtol=1e-12, atol=1e-15)
    assert_allclose(d.B, E[:n, n:], rtol=1e-10, atol=1e-18)
    assert d.dt == T and d.state_labels == c.state_labels and d.input_labels == c.input_labels


def test_explicit_operating_point_equals_lvlh_at_that_attitude():
    """An OperatingPoint at LVLH (q_BN = q_ON(t), ω = LVLH's rate) gives the plant of about='lvlh'."""
    from stationbed.model.environment import q_ON

    sc = orbit_scene(JEOD_I)
    o = sc.orbit
    t = 100.0
    q = np.asarray(q_ON(o.u0 + o.mean_motion * t, o.inclination), float).ravel()
    w = np.array([0.0, -o.mean_motion, 0.0])
    a = linearize(sc, OperatingPoint(q_BN=tuple(q), omega_BN_B=tuple(w), t=t))
    b = linearize(sc, "lvlh", t=t)
    assert_allclose(a.A, b.A, rtol=1e-9, atol=1e-18)
    assert_allclose(a.B, b.B, rtol=1e-9, atol=1e-18)


# -- loop analysis -----------------------------------------------------------------------------
def test_lqr_closed_loop_poles_from_margins_equal_the_designed_ones():
    """loop_analysis closes the loop through the law's symbolic form and the scene's own plant: the
    poles are lqr's eig(A - B K) from its design (rigid scene, ideal torquer)."""
    sc = orbit_scene(JEOD_I, controller={"name": "lqr", "period": 0.1, "params": {}})
    la = loop_analysis(sc)
    assert_allclose(np.sort_complex(la.poles), np.sort_complex(la.controller.poles), rtol=POLE_RTOL)
    assert_allclose(la.K, -la.controller.K, rtol=1e-9, atol=1e-9 * np.abs(la.controller.K).max())
    for c in la.channels:
        assert c["phase_margin_deg"] >= 60.0  # the LQR guarantee
        assert c["sensitivity_peak"] <= 1.0 + 1e-9  # |1 + L| >= 1: Kalman's return-difference inequality


def test_pd_phase_margin_matches_the_textbook_loop():
    """Deep space, diagonal inertia, pd with ω_n and ζ: every axis is L(s) = (ω_n² + 2ζω_n s)/s².
    By hand: |L(jω_c)| = 1 gives ω_c² = ω_n² (2ζ² + √(4ζ⁴ + 1)), and the phase margin is
    atan(2ζ ω_c / ω_n)."""
    wn, zeta = 0.02, 0.6
    sc = scene_from_dict({
        "name": "pd_axis", "simulation": {"duration": 1.0},
        "body": {"mass": 1.0e4, "inertia": np.diag([3.0e5, 2.0e5, 4.0e5]).tolist(), "cm": [0.0, 0.0, 0.0]},
        "controller": {"name": "pd", "period": 0.1, "params": {"reference": "inertial", "bandwidth": wn, "damping": zeta}},
    })
    la = loop_analysis(sc)
    wc = wn * math.sqrt(2 * zeta**2 + math.sqrt(4 * zeta**4 + 1))
    pm = math.degrees(math.atan(2 * zeta * wc / wn))
    for c in la.channels:
        assert c["phase_margin_deg"] == pytest.approx(pm, rel=MARGIN_RTOL)
        assert c["crossover_rad_s"] == pytest.approx(wc, rel=MARGIN_RTOL)
        assert c["gain_margin_up"] == math.inf
    # closed loop: s² + 2ζω_n s + ω_n² per axis
    s = -zeta * wn + 1j * wn * math.sqrt(1 - zeta**2)
    assert np.min(np.abs(la.poles - s)) < 1e-9 * wn


def test_att_err_axes_are_the_error_rotation_vector():
    """att_err_x/y/z_deg: the rotation vector from the law's reference to B (here LVLH), computed
    in numpy from q_BN and the orbit; its norm is att_err_deg."""
    sc = orbit_scene(JEOD_I, (0.03, -0.02, 0.05), duration=200.0,
                     controller={"name": "lqr", "period": 0.1, "params": {}})
    sc = sc.model_copy(update={"simulation": sc.simulation.model_copy(update={"output_dt": 50.0})})
    tr = simulate(sc)
    axes = tr.cols("att_err_x_deg", "att_err_y_deg", "att_err_z_deg")
    assert_allclose(np.linalg.norm(axes, axis=1), tr["att_err_deg"], rtol=1e-12, atol=1e-12)
    o = sc.orbit
    for i in range(len(tr)):
        C_BO = dcm(tr.q_BN[i]) @ C_ON(o.u0 + o.mean_motion * tr.t[i], o.inclination).T
        q = quat_from_dcm(C_BO)
        q = q if q[0] >= 0 else -q
        phi = 2 * math.atan2(np.linalg.norm(q[1:]), q[0])
        assert_allclose(axes[i], np.degrees(phi * q[1:] / np.linalg.norm(q[1:])), rtol=1e-9, atol=1e-12)


def test_to_pandas_keeps_columns_and_values():
    tr = simulate(orbit_scene(JEOD_I, duration=20.0))
    df = tr.to_pandas()
    assert list(df.columns) == tr.columns[1:] and df.index.name == "t"
    assert_allclose(df["wy"].to_numpy(), tr["wy"])


# -- the commands ------------------------------------------------------------------------------
def test_commands_write_their_files_and_tables(tmp_path, capsys):
    """linearize, margins, run, plot and compare on a small scene: files written, tables printed,
    the compare table's values are the run summary's (the one metric definition)."""
    import json

    from stationbed.cli import main

    scene = tmp_path / "small.toml"
    scene.write_text("""name = "small"
[simulation]
duration = 300.0
integrator = "rk4"
step = 0.5
output_dt = 10.0
[initial]
frame = "lvlh"
q_BN = [0.9999054955, 0.01, -0.005, 0.008]
[body]
mass = 4.0e5
inertia = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]
cm = [0.0, 0.0, 0.0]
[orbit]
altitude = 400000.0
[cmg]
kind = "ideal"
[controller]
name = "lqr"
period = 0.5
""")
    out = tmp_path / "lin"
    assert main(["linearize", str(scene), "--out", str(out), "--about", "tea", "--dt", "0.5"]) == 0
    z = np.load(out / "plant.npz")
    assert z["A"].shape == (9, 9) and list(z["states"][6:]) == ["hx", "hy", "hz"] and z["Ad"].shape == (9, 9)
    assert {"bode.png", "pole_zero.png", "poles_zeros.json"} <= {p.name for p in out.iterdir()}
    assert main(["margins", str(scene), "--out", str(tmp_path / "mg")]) == 0
    text = capsys.readouterr().out
    assert "tau_cmd_x" in text and "PM [deg]" in text
    assert (tmp_path / "mg" / "nichols.png").stat().st_size > 0
    for name, law in (("a", "pd"), ("b", "lqr")):
        assert main(["run", str(scene), "-q", "--out", str(tmp_path / name), "--set", f'controller.name="{law}"']) == 0
    assert main(["plot", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "dashboard.png").stat().st_size > 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    table = capsys.readouterr().out
    s = json.loads((tmp_path / "b" / "summary.json").read_text())["summary"]
    row = next(line for line in table.splitlines() if line.startswith("max_att_err_deg"))
    assert float(row.split()[-1]) == pytest.approx(s["max_att_err_deg"], rel=1e-3)  # the table's 4 digits
    assert main(["plot", str(tmp_path / "nowhere")]) == 2  # a one-line error, not a traceback


@pytest.mark.parametrize("bandwidth, flagged", [(0.05, False), (3.0, True)], ids=["below_mode", "above_mode"])
def test_structural_mode_inside_the_bandwidth_is_flagged(bandwidth, flagged):
    """The array mode (free-hub ω_f ≈ 1.29 rad/s) is flagged when the pd's bandwidth (≈ ω_n) lies
    above it, not when it lies 25x below; the flagged frequency is that mode's."""
    d = flexible_scene().model_dump()
    d["controller"] = {"name": "pd", "period": 0.01, "params": {"reference": "inertial", "bandwidth": bandwidth, "damping": 0.7}}
    d["simulation"].pop("step", None)
    la = loop_analysis(scene_from_dict(d))
    I = np.array(HUB_J) + np.array(ARRAY_J)
    D = np.array(H_HAT)
    wf = 2 * math.pi * F_CLAMPED_HZ * math.sqrt(MODAL_MASS / (MODAL_MASS - D @ np.linalg.solve(I, D)))
    assert bool(la.structural_in_band) == flagged
    if flagged:
        assert la.structural_in_band[0] == pytest.approx(wf, rel=1e-6)


@pytest.mark.parametrize("make", [lambda: orbit_scene(JEOD_I), flexible_scene], ids=["rigid_orbit", "flexible"])
def test_every_formulation_gives_the_same_plant(make):
    """θ, δω, η, η̇ are physical coordinates: the four formulations (momentum, ω or modal-momentum
    states, energy-derived hamel) must give the same A and B, to round-off (measured ≤ 4e-20
    relative)."""
    from stationbed import FORMULATIONS

    ref = None
    for f in FORMULATIONS:
        sc = make()
        sc = sc.model_copy(update={"simulation": sc.simulation.model_copy(update={"formulation": f})})
        s = linearize(sc, "lvlh")
        if ref is None:
            ref = s
            continue
        assert_allclose(s.A, ref.A, rtol=0, atol=1e-12 * np.abs(ref.A).max(), err_msg=f)
        assert_allclose(s.B, ref.B, rtol=0, atol=1e-12 * np.abs(ref.B).max(), err_msg=f)
