"""The multiplicative EKF of stationbed/loop/mekf.py against independent truths.

Truths used:

* the truth attitude in closed form: a constant body rate about a fixed axis,
  ``C_NB(t) = C_NB(0) R(ω t)`` built with ``scipy.spatial.transform.Rotation`` (so the rate
  integrated over any sample is ω Δt and ``theta_B = ω t``);
* the error-state transition matrix as the matrix exponential of the continuous error dynamics
  ``[[-[ω×], -E], [0, 0]]`` (scipy.linalg.expm), and the discrete process noise as the integral
  ``∫ Φ(s) G Qc Gᵀ Φ(s)ᵀ ds`` (scipy quadrature) for a resting body;
* consistency over an ensemble of independent runs (the gyro and the heads drawn by their own
  plug-ins, the filter told only their tables): the ensemble-mean NEES inside the two-sided 95 %
  chi-squared band for 6 x runs degrees of freedom, the errors inside 3σ (Bar-Shalom, Li &
  Kirubarajan, *Estimation with Applications to Tracking and Navigation*, §5.4);
* noise-free sensors: the estimate converges to the truth, attitude and bias, to round-off.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad_vec
from scipy.linalg import expm
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from stationbed.loop import TRUTH, Mekf, build_sensors, noise_rng
from stationbed.loop.mekf import SERIES_BELOW, propagate
from stationbed.scene import sensing_from_dict

import casadi as ca

# -- the set-up: ISS-like sensors (docs/loop.md gives the sources) --------------------------------
GYRO_DT_S = 0.2  # s, gyro sample period = filter step
HEAD_DT_S = 1.0  # s, star-tracker update period
SIGMA_V = 1.454e-6  # rad/s^0.5 = 0.005 deg/sqrt(h), angle random walk
SIGMA_U = 3.162e-10  # rad/s^1.5 = sqrt(10) 1e-10, rate random walk
NEA_CROSS = 9.7e-6  # rad = 2 arcsec, 1 sigma
NEA_ABOUT = 7.3e-5  # rad = 15 arcsec, 1 sigma
SIGMA_ATT0 = 1e-4  # rad, initial attitude error, 1 sigma per axis
SIGMA_BIAS0 = 1e-5  # rad/s (2 deg/h), initial bias, 1 sigma per axis
OMEGA_B = np.array([2e-4, -1.13e-3, 3e-4])  # rad/s: about the LVLH-hold orbit rate, off-axis parts added

N_RUNS = 50
DURATION_S = 600.0

# -- tolerances (each with its reason) ------------------------------------------------------
#: float64 round-off of a 6x6 product chain of O(1) entries
ROUNDOFF = 1e-13
#: the two-sided confidence of the NEES band (issue 20)
NEES_CONFIDENCE = 0.95
#: per-state two-sided miss probability at the end (6 states: family-wise <= 6 %)
STATE_ALPHA = 0.01
#: bias error RMS after DURATION_S, as a fraction of the initial σ (the filter's 3σ then is 0.018)
BIAS_END_FRACTION = 0.02
#: an error inside its 3σ bound at least this often (Gaussian: 99.73 %)
INSIDE_3SIGMA_MIN = 0.99
#: noise-free sensors: the attitude error after convergence [rad] (measured 2.4e-16 after 600 s:
#: the round-off floor of a unit quaternion, 2 |δq| ~ 1e-16; 40x margin)
CONVERGED_ATT_RAD = 1e-14
#: noise-free: bias error after convergence [rad/s] (measured 4e-17: the attitude's round-off
#: over the heads' 1 s period; 20x margin)
CONVERGED_BIAS_RAD_S = 1e-15


def _sensing(nea=(NEA_CROSS, NEA_ABOUT), estimator=None, latency=0.0):
    heads = [dict(kind="star_tracker", name=f"st{i}", period=HEAD_DT_S, boresight_B=b, nea_cross=nea[0],
                  nea_about=nea[1], latency=latency) for i, b in enumerate(([0.0, -0.5, -0.866], [0.0, 0.5, -0.866]))]
    gyro = dict(kind="gyro", name="rga", period=GYRO_DT_S, sigma_v=SIGMA_V, sigma_u=SIGMA_U)
    return sensing_from_dict({"sensor": [gyro, *heads], "estimator": {"kind": "mekf", "sigma_attitude0": SIGMA_ATT0,
                                                                       "sigma_bias0": SIGMA_BIAS0, **(estimator or {})}})


def _q_wxyz(rot):
    x, y, z, w = rot.as_quat().T
    return np.stack([w, x, y, z], axis=-1)


def _fly(mekf, sensors, seed, gyro_params=None, head_params=None, bias0=None, att0=None):
    """One run: truth, sensor records, the filter's states. Returns (xf, q_true, bias_true)."""
    gyro, heads = sensors[0], sensors[1:]
    gen = np.random.default_rng(seed)
    n = int(round(DURATION_S / GYRO_DT_S))
    t = GYRO_DT_S * np.arange(1, n + 1)
    R0 = Rotation.random(random_state=gen)
    rots = R0 * Rotation.from_rotvec(t[:, None] * OMEGA_B)  # C_NB(t) = C_NB(0) R(ω t)
    q_true = _q_wxyz(rots)
    truth = np.zeros((n, TRUTH.size))
    truth[:, TRUTH.slice("q_BN")] = q_true
    truth[:, TRUTH.slice("theta_B")] = t[:, None] * OMEGA_B
    truth[:, TRUTH.slice("R_N")] = [6.778e6, 0.0, 0.0]
    b0 = gen.normal(0.0, SIGMA_BIAS0, 3) if bias0 is None else bias0
    x0 = gyro.x0.copy()
    x0[gyro.state.slice("bias_B")] = b0
    xg, yg = gyro.record(t, truth, gyro.noise(noise_rng(seed, 0), n), x0=x0, params=gyro_params)
    z = np.zeros((n, mekf.inputs.size))
    z[:, mekf.inputs.slice("omega_B")] = yg
    every = int(round(HEAD_DT_S / GYRO_DT_S))
    at = np.arange(every - 1, n, every)  # ticks with a head sample
    for i, h in enumerate(heads):
        _, yh = h.record(t[at], truth[at], h.noise(noise_rng(seed, 1 + i), at.size),
                         params=None if head_params is None else head_params[i])
        z[at, mekf.inputs.slice(f"q_SN_{i}")] = yh[:, 0:4]
        z[at, mekf.inputs.slice(f"valid_{i}")] = yh[:, 4:5]
        z[at, mekf.inputs.slice(f"fresh_{i}")] = 1.0
    R_hat0 = R0 * Rotation.from_rotvec(-np.asarray(gen.normal(0.0, SIGMA_ATT0, 3) if att0 is None else att0))
    xf, _ = mekf.record(mekf.initial(_q_wxyz(R_hat0)), z)
    return xf, q_true, xg[:, gyro.state.slice("bias_B")]


#: star-tracker latencies of the ensembles [s]: none, and two head periods in flight (the filter
#: compares a late measurement with its estimate carried back by its own turn since the sample)
LATENCIES_S = (0.0, 2.0)


@pytest.fixture(scope="module", params=LATENCIES_S, ids=[f"latency_{x:g}s" for x in LATENCIES_S])
def ensemble(request):
    sensing = _sensing(latency=request.param)
    sensors = build_sensors(sensing.sensor)
    mekf = Mekf.from_sensors(sensing.estimator, sensors)
    errs, sig3, nees = [], [], []
    for r in range(N_RUNS):
        xf, q, b = _fly(mekf, sensors, seed=1000 + r)
        e_att, s3, ne = mekf.report(xf, q, b)
        errs.append(np.hstack([e_att, b - mekf.state.get(xf, "bias_B")]))
        sig3.append(s3)
        nees.append(ne)
    return np.array(errs), np.array(sig3), np.array(nees)


# -- the closed forms -----------------------------------------------------------------------------
@pytest.mark.parametrize("omega_dt", [0.0, 0.5 * SERIES_BELOW, 2 * SERIES_BELOW, 1.3],
                         ids=["rest", "series", "closed_form", "large_step"])
def test_transition_matrix_is_the_exponential_of_the_error_dynamics(omega_dt):
    dt = 0.5  # s
    axis = np.array([0.36, -0.48, 0.8])  # unit
    omega = axis * omega_dt / dt
    q, b, P, w = ca.SX.sym("q", 4), ca.SX.sym("b", 3), ca.SX.sym("P", 6, 6), ca.SX.sym("w", 3)
    _, _, P1 = propagate(q, b, P, w, dt, 0.0, 0.0)
    f = ca.Function("f", [q, b, P, w], [P1])
    F = np.zeros((6, 6))
    F[:3, :3] = -np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    F[:3, 3:] = -np.eye(3)
    Phi = expm(F * dt)
    P0 = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]) + 0.1 * np.ones((6, 6))  # symmetric positive definite
    got = np.asarray(f([1, 0, 0, 0], 0, P0, omega))
    assert_allclose(got, Phi @ P0 @ Phi.T, rtol=0, atol=ROUNDOFF * 100)


def test_process_noise_is_the_integral_of_the_gyro_noise_at_rest():
    dt, sv, su = 0.7, 2e-3, 5e-4  # s, rad/s^0.5, rad/s^1.5 (large, so Q is far above round-off)
    q, b, P, w = ca.SX.sym("q", 4), ca.SX.sym("b", 3), ca.SX.sym("P", 6, 6), ca.SX.sym("w", 3)
    _, _, P1 = propagate(q, b, P, w, dt, sv, su)
    Q = np.asarray(ca.Function("f", [q, b, P, w], [P1])([1, 0, 0, 0], 0, np.zeros((6, 6)), [0, 0, 0]))
    F = np.zeros((6, 6))
    F[:3, 3:] = -np.eye(3)
    G = np.block([[-np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3)]])
    Qc = np.diag([sv**2] * 3 + [su**2] * 3)
    Phi = expm  # at rest F is nilpotent (F² = 0): expm(F s) = E + F s, checked here once
    assert_allclose(Phi(F * dt), np.eye(6) + F * dt, rtol=0, atol=ROUNDOFF)
    exact, _ = quad_vec(lambda s: (np.eye(6) + F * s) @ G @ Qc @ G.T @ (np.eye(6) + F * s).T, 0.0, dt,
                        epsabs=1e-16, epsrel=1e-12)
    assert_allclose(Q, exact, rtol=1e-10, atol=1e-20)


# -- the ensemble ------------------------------------------------------------------------------------
def test_ensemble_nees_inside_the_chi_squared_band(ensemble):
    """Mean NEES over the runs: at the last step (independent runs: exactly χ²(6 N)/N) and over
    the whole record (a time average of such means has a smaller spread, so the band is wide)."""
    _, _, nees = ensemble
    dof = 6 * N_RUNS
    lo, hi = chi2.ppf([(1 - NEES_CONFIDENCE) / 2, (1 + NEES_CONFIDENCE) / 2], dof) / N_RUNS
    final = nees[:, -1].mean()
    whole = nees.mean()
    assert lo <= final <= hi, f"mean NEES at the end {final:.2f} outside [{lo:.2f}, {hi:.2f}]"
    assert lo <= whole <= hi, f"mean NEES over the runs and time {whole:.2f} outside [{lo:.2f}, {hi:.2f}]"


def test_errors_inside_three_sigma(ensemble):
    errs, sig3, _ = ensemble
    inside = np.abs(errs) <= sig3
    assert inside.mean() >= INSIDE_3SIGMA_MIN, f"inside 3σ {inside.mean():.4f} of the time"


def test_each_state_variance_at_the_end_inside_its_band(ensemble):
    """Per error state, at the last step (runs independent): Σ_runs (e/σ)² ~ χ²(runs). A time
    fraction per state would not do: a bias error stays on one side for minutes, so 50 runs
    hold few independent bias samples over time."""
    errs, sig3, _ = ensemble
    white = errs[:, -1] / (sig3[:, -1] / 3)
    lo, hi = chi2.ppf([STATE_ALPHA / 2, 1 - STATE_ALPHA / 2], N_RUNS)
    for i in range(6):
        ss = np.sum(white[:, i] ** 2)
        assert lo <= ss <= hi, f"state {i}: Σ(e/σ)² = {ss:.1f} outside [{lo:.1f}, {hi:.1f}]"


def test_bias_estimate_converges_to_the_simulated_bias(ensemble):
    errs, sig3, _ = ensemble
    start = np.sqrt(np.mean(errs[:, 0, 3:] ** 2))
    end = np.sqrt(np.mean(errs[:, -1, 3:] ** 2))
    assert start > 0.5 * SIGMA_BIAS0  # it started uncertain
    # the filter's own 1σ after 600 s is 6e-8 rad/s = 0.006 σ_bias0: the RMS stays within ~3σ of it
    assert end < BIAS_END_FRACTION * SIGMA_BIAS0, f"bias error RMS {end:.3g} rad/s after {DURATION_S:g} s"
    assert np.all(sig3[:, -1, 3:] < BIAS_END_FRACTION * SIGMA_BIAS0)  # and the filter knows it


# -- noise-free sensors ----------------------------------------------------------------------
@pytest.mark.parametrize("latency", LATENCIES_S, ids=[f"latency_{x:g}s" for x in LATENCIES_S])
def test_noise_free_sensors_converge_to_truth_to_round_off(latency):
    """Sensors without noise (their parameters zeroed; the filter still assumes its tables') and
    a constant bias: the estimate reaches the truth, attitude and bias, to round-off."""
    sensing = _sensing(estimator={"sigma_u": 1e-7}, latency=latency)  # a faster bias loop: converges in the run
    sensors = build_sensors(sensing.sensor)
    mekf = Mekf.from_sensors(sensing.estimator, sensors)
    g = sensors[0]
    gp = g.params.copy()
    gp[g.param_layout.slice("white")] = 0.0  # the gyro's noise levels (σ_v, σ_u per sample)
    gp[g.param_layout.slice("bias_step")] = 0.0
    hps = []
    for h in sensors[1:]:
        hp = h.params.copy()
        hp[h.param_layout.slice("nea_cross")] = 0.0
        hp[h.param_layout.slice("nea_about")] = 0.0
        hps.append(hp)
    bias = np.array([1e-5, -2e-5, 5e-6])  # rad/s
    xf, q, b = _fly(mekf, sensors, seed=7, gyro_params=gp, head_params=hps, bias0=bias, att0=[1e-4, -2e-4, 1e-4])
    assert_allclose(b, np.tile(bias, (len(b), 1)), rtol=0, atol=0)  # the truth's bias is constant
    e_att, _, _ = mekf.report(xf, q, b)
    assert np.abs(e_att[0]).max() > 1e-5  # it started off
    assert np.abs(e_att[-1]).max() < CONVERGED_ATT_RAD
    assert np.abs(mekf.state.get(xf[-1], "bias_B") - bias).max() < CONVERGED_BIAS_RAD_S


def test_compiled_filter_gives_the_same_numbers_as_its_expression():
    sensing = _sensing()
    sensors = build_sensors(sensing.sensor)
    mekf = Mekf.from_sensors(sensing.estimator, sensors)
    gen = np.random.default_rng(3)
    xf0 = mekf.initial(_q_wxyz(Rotation.random(random_state=gen)))
    z = np.zeros((40, mekf.inputs.size))
    z[:, mekf.inputs.slice("omega_B")] = OMEGA_B + gen.normal(0, 1e-5, (40, 3))
    for i in range(2):
        z[::5, mekf.inputs.slice(f"q_SN_{i}")] = _q_wxyz(Rotation.random(8, random_state=gen))
        z[::5, mekf.inputs.slice(f"valid_{i}")] = 1.0
        z[::5, mekf.inputs.slice(f"fresh_{i}")] = 1.0
    a, wa = mekf.record(xf0, z, mekf.function())
    c, wc = mekf.record(xf0, z)
    assert_allclose(c, a, rtol=0, atol=ROUNDOFF)
    assert_allclose(wc, wa, rtol=0, atol=ROUNDOFF)


def test_dropped_measurements_leave_the_filter_to_the_gyro():
    """Every head sample invalid (excluded): no update, and at rest the attitude variance grows
    as the closed form of the random walks, P₁₁(t) = P₁₁(0) + P₂₂(0) t² + σ_v² t + σ_u² t³/3."""
    sensing = _sensing()
    mekf = Mekf.from_sensors(sensing.estimator, build_sensors(sensing.sensor))
    n = 500
    z = np.zeros((n, mekf.inputs.size))
    for i in range(2):
        z[4::5, mekf.inputs.slice(f"q_SN_{i}")] = [0.0, 1.0, 0.0, 0.0]  # far off: would move the estimate
        z[4::5, mekf.inputs.slice(f"fresh_{i}")] = 1.0  # new, but not valid
    xf, _ = mekf.record(mekf.initial([1.0, 0.0, 0.0, 0.0]), z)
    t = GYRO_DT_S * np.arange(1, n + 1)
    P = mekf.state.get(xf, "P")
    expected = SIGMA_ATT0**2 + SIGMA_BIAS0**2 * t**2 + SIGMA_V**2 * t + SIGMA_U**2 * t**3 / 3
    for i in range(3):
        assert_allclose(P[:, i, i], expected, rtol=1e-12)
    assert_allclose(mekf.state.get(xf, "q_BN"), np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), rtol=0, atol=0)


@pytest.mark.parametrize("latency", [0.0, 2.0], ids=["no_latency", "latency_2s"])
def test_short_covariance_update_equals_the_joseph_form(latency):
    """With the optimal gain (correlated noise included) ``P − K (P Hᵀ + M)ᵀ`` is the Joseph form's
    value: the two agree to round-off on a random covariance, mounting and carried-back turn."""
    from stationbed.loop.mekf import update

    gen = np.random.default_rng(5)
    A = gen.normal(size=(6, 6))
    P0 = A @ A.T * 1e-8 + np.diag([1e-6] * 3 + [1e-10] * 3)  # rad², rad²/s: SPD, correlated
    q, b, P = ca.SX.sym("q", 4), ca.SX.sym("b", 3), ca.SX.sym("P", 6, 6)
    z, qsb, D = ca.SX.sym("z", 4), ca.SX.sym("qsb", 4), ca.SX.sym("D", 4)
    r = np.array([NEA_CROSS, NEA_CROSS, NEA_ABOUT])
    extra = dict(D=D, latency=latency, q_latency=SIGMA_V**2 * latency) if latency else {}
    outs = [ca.Function(f"u{j}", [q, b, P, z, qsb, D], list(update(q, b, P, z, 1.0, qsb, r, joseph=j, **extra)))
            for j in (False, True)]
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    args = (unit(gen.normal(size=4)), gen.normal(0, 1e-5, 3), P0, unit(gen.normal(size=4)), unit(gen.normal(size=4)),
            unit([1.0, 1e-3, -2e-3, 5e-4]))
    short, joseph = (f(*args) for f in outs)
    P_s, P_j = np.asarray(short[2]), np.asarray(joseph[2])
    assert np.array_equal(P_s, P_s.T)
    assert_allclose(P_s, P_j, rtol=0, atol=ROUNDOFF * np.abs(P0).max())
    assert np.all(np.linalg.eigvalsh(P_s) > 0)
    for a, c in zip(short[:2], joseph[:2]):
        assert np.array_equal(np.asarray(a), np.asarray(c))  # the state update is the same expression
