"""Sensor plug-ins of stationbed/loop/ (issue 20) against independent truths.

Truths used (none calls the library's sensor code to make its expectation):

* the continuous Farrenkopf model's cluster averages, whose covariance is written here in
  closed form (white part σ_v²/τ δ_ij; Brownian bias averaged over clusters i <= j:
  σ_u² (a_i + τ/2) for i < j, σ_u² (a_i + τ/3) for i = j, a_i = i τ): its Allan variance must be
  ``σ_v²/τ + σ_u² τ/3`` (checked), and the estimator's exact mean and variance (a Gaussian
  quadratic form) give the equivalent degrees of freedom of its chi-squared band
  (Satterthwaite: edf = 2 mean²/var);
* chi-squared and normal quantiles (scipy.stats) for the star tracker's error covariance;
* the error rotation recovered with ``scipy.spatial.transform.Rotation`` (not the library's
  quaternion code); the boresight and the Sun, Moon and Earth-limb angles by numpy geometry;
* plain sums for the quantiser (a counter keeps the total within half a count) and ``np.clip``
  for saturation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation
from scipy.stats import chi2, norm

from stationbed.core.constants import R_EARTH_M
from stationbed.loop import SENSORS, TRUTH, Layout, build_sensors, get_sensor, noise_rng
from stationbed.scene import SceneError, sensing_from_dict

# -- tolerances and confidence levels (each with its reason) ----------------------------------
#: float64 round-off of a few dozen operations on O(1) numbers
ROUNDOFF = 1e-12
#: per-τ two-sided miss probability of the Allan band: 13 τ per record, so the family-wise
#: chance that a correct gyro fails is <= 13 x 1e-3 (Bonferroni)
ALLAN_ALPHA = 1e-3
#: per-statistic two-sided miss probability of the star-tracker checks (3 variances, 3 means,
#: 3 correlations, 1 total: family-wise <= 1 %)
ST_ALPHA = 1e-3
#: samples kept away from an exclusion edge [rad], so that round-off cannot decide them
EDGE_MARGIN_RAD = 1e-9

ORBIT_RADIUS_M = 6.778e6  # m, ISS-like


def _gyro(**kw):
    d = dict(kind="gyro", name="g", period=1.0, sigma_v=1e-4, sigma_u=1e-6)
    return {**d, **kw}


def _head(**kw):
    d = dict(kind="star_tracker", name="st", period=1.0, boresight_B=[0.3, -0.5, -0.8], roll=0.4,
             nea_cross=1e-4, nea_about=8e-4)
    return {**d, **kw}


def _one(entry):
    return build_sensors(sensing_from_dict({"sensor": [entry]}).sensor)[0]


def _q_wxyz(rot: Rotation) -> np.ndarray:
    """q_BN (w, x, y, z) of the rotation whose matrix is C_NB (DESIGN §3)."""
    x, y, z, w = rot.as_quat().T
    return np.stack([w, x, y, z], axis=-1)


def _truth(n, q_BN=None, theta_B=None, R_N=None, sun_N=None, moon_N=None) -> np.ndarray:
    rows = np.zeros((n, TRUTH.size))
    rows[:, TRUTH.slice("q_BN")] = [1.0, 0.0, 0.0, 0.0] if q_BN is None else q_BN
    for name, v in (("theta_B", theta_B), ("R_N", R_N), ("sun_N", sun_N), ("moon_N", moon_N)):
        if v is not None:
            rows[:, TRUTH.slice(name)] = v
    if R_N is None:
        rows[:, TRUTH.slice("R_N")] = [ORBIT_RADIUS_M, 0.0, 0.0]
    return rows


# -- layouts -----------------------------------------------------------------------------------
def test_layout_reads_the_same_numbers_in_numpy_and_casadi():
    L = Layout(q_BN=4, bias_B=3, P=(2, 3))
    v = np.arange(L.size, dtype=float)
    X = ca.SX.sym("x", L.size)
    for name in L.names:
        sym = ca.Function("f", [X], [L.get(X, name)])(v)
        assert_array_equal(np.asarray(sym).reshape(L.shape(name), order="F"), np.atleast_2d(L.get(v, name).T).T
                           if L.shape(name)[1] == 1 else L.get(v, name))
    assert_array_equal(L.pack(L.split(v)), v)
    table = np.vstack([v, 2 * v])
    assert_array_equal(L.get(table, "P")[1], 2 * L.get(v, "P"))


def test_layout_refuses_missing_and_unknown_fields():
    L = Layout(a=1, b=3)
    with pytest.raises(ValueError, match="missing fields \\['b'\\]"):
        L.pack(a=1.0)
    with pytest.raises(ValueError, match="unknown fields \\['c'\\]"):
        L.pack(a=1.0, b=[1, 2, 3], c=0.0)
    with pytest.raises(ValueError, match="3 numbers, expected"):
        L.pack(a=[1.0, 2.0, 3.0], b=[1, 2, 3])


def test_layout_columns_name_axes():
    assert Layout(q_BN=4, bias_B=3, valid=1).columns("st1_") == [
        "st1_q_BN_w", "st1_q_BN_x", "st1_q_BN_y", "st1_q_BN_z", "st1_bias_B_x", "st1_bias_B_y", "st1_bias_B_z",
        "st1_valid"]


# -- the contract, for every registered kind --------------------------------------------------
#: one valid table per registered kind: a new kind without an example fails the contract test
EXAMPLES = {"gyro": _gyro(quantum=1e-6, max_rate=0.1), "star_tracker": _head(latency=2.0, sun_exclusion=0.5)}


@pytest.mark.parametrize("kind", sorted(SENSORS))
def test_registered_kind_has_an_example_and_a_scene_table(kind):
    assert kind in EXAMPLES, f"add a valid [[sensor]] table of kind {kind!r} to EXAMPLES"
    cls = SENSORS[kind]
    assert cls.kind == kind and cls.scene_model is not None
    assert get_sensor(kind) is cls


@pytest.mark.parametrize("kind", sorted(SENSORS))
def test_step_reads_only_the_declared_truth(kind):
    """Rule 3: the expression depends on no truth field outside ``reads`` (and on each it declares)."""
    s = _one(EXAMPLES[kind])
    f = s.function()
    args = [ca.SX.sym(n, f.size1_in(i)) for i, n in enumerate(f.name_in())]
    outs = ca.vertcat(*f(*args))
    truth = args[2]
    for name in TRUTH.names:
        depends = ca.depends_on(outs, truth[TRUTH.slice(name)])
        assert depends == (name in s.reads), f"{kind}: depends on truth.{name} = {depends}, declared {s.reads}"


@pytest.mark.parametrize("kind", sorted(SENSORS))
def test_step_is_pure_and_record_equals_steps(kind, rng):
    """Rule 6: no hidden state; the one-call record (mapaccum) is the same function step by step."""
    s = _one(EXAMPLES[kind])
    n = 7
    q = _q_wxyz(Rotation.random(n, random_state=1))
    truth = _truth(n, q_BN=q, theta_B=np.cumsum(rng.normal(0, 1e-3, (n, 3)), axis=0), sun_N=[0, 0, 1], moon_N=[0, 1, 0])
    w = s.noise(rng, n)
    t = s.period * np.arange(1, n + 1)
    xs, ys = s.record(t, truth, w)
    x = s.x0
    for k in range(n):
        x1, y1 = s.step(t[k], x, truth[k], w[k])
        x1b, y1b = s.step(t[k], x, truth[k], w[k])
        assert_array_equal(x1, x1b)
        assert_array_equal(y1, y1b)
        assert_allclose(x1, xs[k], rtol=0, atol=ROUNDOFF)
        assert_allclose(y1, ys[k], rtol=0, atol=ROUNDOFF)
        x = x1


def test_unknown_sensor_kind_lists_the_valid_ones():
    with pytest.raises(ValueError, match="valid kinds: gyro, star_tracker"):
        get_sensor("sun_sensor")


def test_noise_streams_are_reproducible_in_pieces_and_independent():
    whole = noise_rng(42, 3).standard_normal((30, 6))
    r = noise_rng(42, 3)
    pieces = np.vstack([r.standard_normal((10, 6)), r.standard_normal((20, 6))])
    assert_array_equal(whole, pieces)
    assert not np.allclose(whole, noise_rng(42, 4).standard_normal((30, 6)))
    assert not np.allclose(whole, noise_rng(43, 3).standard_normal((30, 6)))


# -- rate gyro ----------------------------------------------------------------------------------
def test_gyro_without_noise_reports_scaled_rate_plus_bias():
    """(E + M) Δθ/Δt + β, the rate integrated over each sample (not the rate at its end)."""
    M = [[0.0, 2e-4, -1e-4], [3e-4, 0.0, 5e-5], [-2e-4, 1e-4, 0.0]]
    s = _one(_gyro(period=0.5, sigma_v=0.0, sigma_u=0.0, bias0=[1e-5, -2e-5, 3e-5], scale_factor=[1e-3, -2e-3, 5e-4],
                   misalignment=M))
    t = 0.5 * np.arange(1, 41)
    theta = np.stack([0.01 * np.sin(0.3 * t), 0.002 * t**2, -0.004 * t], axis=1)  # rad, any smooth path
    _, y = s.record(t, _truth(40, theta_B=theta), np.zeros((40, 6)))
    d_theta = np.diff(np.vstack([np.zeros(3), theta]), axis=0)
    expected = (d_theta / 0.5) @ (np.eye(3) + np.diag([1e-3, -2e-3, 5e-4]) + np.array(M)).T + [1e-5, -2e-5, 3e-5]
    assert_allclose(y, expected, rtol=0, atol=ROUNDOFF)


def _allan_truth(sigma_v, sigma_u, tau, K):
    """Mean and variance of the non-overlapping Allan variance of K clusters of length τ, from
    the continuous model's cluster-average covariance (see the module docstring).

    The cluster differences d_i = ȳ_i+1 - ȳ_i are stationary with lag covariances c(h); with the
    covariance written for the first clusters, c(h >= 2) = 0 (an MA(1)), so for K clusters
    ``E = c0/2`` and ``Var = 2 tr(C_d²)/(2(K-1))² = ((K-1) c0² + 2 (K-2) c1²)/(2 (K-1)²)``."""
    k = 6  # first clusters: enough for lags 0..3
    a = tau * np.arange(k)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    lo = np.minimum(i, j)
    C = sigma_u**2 * np.where(i == j, a[lo] + tau / 3, a[lo] + tau / 2) + np.eye(k) * sigma_v**2 / tau
    D = np.diff(np.eye(k), axis=0)
    Cd = D @ C @ D.T
    c0, c1 = Cd[0, 0], Cd[0, 1]
    assert_allclose(Cd[0, 2:], 0.0, atol=ROUNDOFF * c0)  # MA(1): differences two apart are independent
    assert_allclose(np.diag(Cd), c0, rtol=ROUNDOFF)  # stationary
    return c0 / 2, ((K - 1) * c0**2 + 2 * (K - 2) * c1**2) / (2 * (K - 1) ** 2)


@pytest.mark.parametrize("dt, n_log2", [(1.0, 16), (0.1, 16)], ids=["dt_1s", "dt_0.1s"])
def test_gyro_allan_variance_inside_its_chi_squared_band(dt, n_log2):
    """σ²(τ) = σ_v²/τ + σ_u² τ/3 for τ from one sample to 1/16 of the record, at two sample
    periods (the discrete model is exact for any step); crossover at τ = √3 σ_v/σ_u = 173 s."""
    sigma_v, sigma_u = 1e-4, 1e-6  # rad/s^0.5, rad/s^1.5
    n = 2**n_log2
    s = _one(_gyro(period=dt, sigma_v=sigma_v, sigma_u=sigma_u, bias0=[1e-3, -1e-3, 2e-3]))
    t = dt * np.arange(1, n + 1)
    rate = np.array([1e-3, -2e-3, 5e-4])  # rad/s, a constant true rate (Allan variance ignores it)
    _, y = s.record(t, _truth(n, theta_B=t[:, None] * rate), s.noise(noise_rng(7, 0), n))
    for j in range(n_log2 - 3):
        m = 2**j
        tau, K = m * dt, n // m
        clusters = y[: K * m].reshape(K, m, 3).mean(axis=1)
        avar = 0.5 * np.mean(np.diff(clusters, axis=0) ** 2)  # three axes: 3 independent copies
        mean, var = _allan_truth(sigma_v, sigma_u, tau, K)
        assert_allclose(mean, sigma_v**2 / tau + sigma_u**2 * tau / 3, rtol=1e-12)
        edf = 3 * 2 * mean**2 / var
        lo, hi = chi2.ppf([ALLAN_ALPHA / 2, 1 - ALLAN_ALPHA / 2], edf) / edf * mean
        assert lo <= avar <= hi, f"τ = {tau:g} s: Allan variance {avar:.4g} outside [{lo:.4g}, {hi:.4g}] (edf {edf:.0f})"


def test_gyro_quantiser_keeps_the_total_angle_within_half_a_count():
    quantum = 1e-5  # rad per count
    raw = _one(_gyro(period=0.1, sigma_v=1e-5, sigma_u=1e-7))
    counted = _one(_gyro(period=0.1, sigma_v=1e-5, sigma_u=1e-7, quantum=quantum))
    n = 5000
    t = 0.1 * np.arange(1, n + 1)
    truth = _truth(n, theta_B=t[:, None] * [1e-3, -3e-4, 7e-5])
    w = raw.noise(noise_rng(3, 0), n)
    _, y_raw = raw.record(t, truth, w)
    _, y_q = counted.record(t, truth, w)
    counts = y_q * 0.1 / quantum
    assert_allclose(counts, np.round(counts), rtol=0, atol=1e-6)  # whole counts (to round-off of the division)
    gap = np.abs(np.cumsum(y_q - y_raw, axis=0) * 0.1)
    assert gap.max() <= quantum / 2 * (1 + 1e-9)
    assert np.abs(y_q - y_raw).max() > 0.1 * quantum / 0.1  # the quantiser did act


def test_gyro_saturates_each_axis():
    s = _one(_gyro(sigma_v=0.0, sigma_u=0.0, max_rate=0.02))
    t = np.arange(1.0, 5.0)
    rate = np.array([0.05, -0.01, -0.03])  # rad/s
    _, y = s.record(t, _truth(4, theta_B=t[:, None] * rate), np.zeros((4, 6)))
    assert_allclose(y, np.tile(np.clip(rate, -0.02, 0.02), (4, 1)), rtol=0, atol=ROUNDOFF)


# -- star tracker ------------------------------------------------------------------------------
def test_star_tracker_reports_its_mounted_frame_without_noise():
    """q_SN with C_SN = C_SB C_BN; boresight_B is S's z axis and roll turns x about it."""
    e = _head(nea_cross=0.0, nea_about=0.0, roll=0.4)
    s = _one(e)
    rots = Rotation.random(20, random_state=5)  # C_NB
    _, y = s.record(np.arange(1.0, 21.0), _truth(20, q_BN=_q_wxyz(rots)), np.zeros((20, 3)))
    C_SB = sensing_from_dict({"sensor": [e]}).sensor[0]
    q_SB = C_SB.mounting()
    R_SB = Rotation.from_quat([*q_SB[1:], q_SB[0]]).as_matrix().T  # C_SB
    b = np.asarray(e["boresight_B"]) / np.linalg.norm(e["boresight_B"])
    assert_allclose(R_SB[2], b, rtol=0, atol=ROUNDOFF)
    x_ref = np.array([1.0, 0, 0]) - b[0] * b  # the roll's reference axis (|b_x| < 0.9)
    x_ref /= np.linalg.norm(x_ref)
    assert_allclose(R_SB[0] @ x_ref, np.cos(0.4), rtol=0, atol=ROUNDOFF)
    for k in range(20):
        C_SN = R_SB @ rots[k].as_matrix().T
        C_meas = Rotation.from_quat([*y[k, 1:4], y[k, 0]]).as_matrix().T
        assert_allclose(C_meas, C_SN, rtol=0, atol=ROUNDOFF)
    assert_array_equal(y[:, 4], 1.0)


def test_star_tracker_error_covariance_inside_its_chi_squared_band():
    """ν = (nea_cross N₁, nea_cross N₂, nea_about N₃) in S: per-axis variances, means,
    correlations and the whitened total inside their bands."""
    nea = np.array([1e-4, 1e-4, 8e-4])  # rad
    s = _one(_head(nea_cross=nea[0], nea_about=nea[2]))
    n = 4000
    rots = Rotation.random(n, random_state=11)
    _, y = s.record(np.arange(1.0, n + 1), _truth(n, q_BN=_q_wxyz(rots)), s.noise(noise_rng(11, 0), n))
    q_SB = s.entry.mounting()
    R_SB = Rotation.from_quat([*q_SB[1:], q_SB[0]]).as_matrix().T
    C_true = R_SB[None] @ rots.as_matrix().transpose(0, 2, 1)
    C_meas = Rotation.from_quat(np.column_stack([y[:, 1:4], y[:, 0]])).as_matrix().transpose(0, 2, 1)
    # C_meas = (E - [ν×]) C_true: the active rotation C_meas C_trueᵀ turns by -ν
    nu = -Rotation.from_matrix(C_meas @ C_true.transpose(0, 2, 1)).as_rotvec()
    white = nu / nea
    lo, hi = chi2.ppf([ST_ALPHA / 2, 1 - ST_ALPHA / 2], n)
    for i in range(3):
        ss = np.sum(white[:, i] ** 2)
        assert lo <= ss <= hi, f"axis {i}: Σ(ν/σ)² = {ss:.1f} outside [{lo:.1f}, {hi:.1f}]"
        assert abs(white[:, i].mean()) <= norm.ppf(1 - ST_ALPHA / 2) / np.sqrt(n)
    lo3, hi3 = chi2.ppf([ST_ALPHA / 2, 1 - ST_ALPHA / 2], 3 * n)
    assert lo3 <= np.sum(white**2) <= hi3
    r = np.corrcoef(white.T)
    z_max = norm.ppf(1 - ST_ALPHA / 2) / np.sqrt(n - 3)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        assert abs(np.arctanh(r[i, j])) <= z_max, f"axes {i}, {j} correlated: r = {r[i, j]:.3f}"


def test_exclusion_cones_drop_exactly_the_samples_the_geometry_says():
    sun_ex, earth_ex, moon_ex = 0.6, 0.35, 0.25  # rad
    s = _one(_head(nea_cross=0.0, nea_about=0.0, sun_exclusion=sun_ex, earth_exclusion=earth_ex, moon_exclusion=moon_ex))
    n = 3000
    gen = np.random.default_rng(2026)

    def unit(k):
        v = gen.normal(size=(k, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    rots = Rotation.random(n, random_state=13)
    sun, moon = unit(n), unit(n)
    R = unit(n) * ORBIT_RADIUS_M * gen.uniform(1.0, 1.2, (n, 1))
    _, y = s.record(np.arange(1.0, n + 1), _truth(n, q_BN=_q_wxyz(rots), R_N=R, sun_N=sun, moon_N=moon),
                    np.zeros((n, 3)))
    q_SB = s.entry.mounting()
    b_B = Rotation.from_quat([*q_SB[1:], q_SB[0]]).as_matrix()[:, 2]  # S's z axis in B
    b_N = rots.apply(b_B)  # C_NB b_B

    def angle(u, v):
        return np.arccos(np.clip(np.sum(u * v, axis=1), -1.0, 1.0))

    margins = np.stack([angle(b_N, sun) - sun_ex, angle(b_N, moon) - moon_ex,
                        angle(b_N, -R / np.linalg.norm(R, axis=1, keepdims=True))
                        - np.arcsin(R_EARTH_M / np.linalg.norm(R, axis=1)) - earth_ex], axis=1)
    clear = np.all(np.abs(margins) > EDGE_MARGIN_RAD, axis=1)
    expected = np.all(margins > 0, axis=1).astype(float)
    assert clear.sum() > 0.99 * n
    assert_array_equal(y[clear, 4], expected[clear])
    for i, what in enumerate(("sun", "moon", "earth")):  # every cone did drop samples of its own
        assert np.sum((margins[:, i] < 0) & (np.delete(margins, i, axis=1) > 0).all(axis=1)) > 5, what
    assert expected.sum() > 0.3 * n


def test_absent_sun_moon_and_orbit_never_exclude():
    """Zero Sun and Moon vectors and a zero position (a run without them) leave every sample valid."""
    s = _one(_head(sun_exclusion=0.6, earth_exclusion=0.35, moon_exclusion=0.25))
    n = 50
    truth = _truth(n, q_BN=_q_wxyz(Rotation.random(n, random_state=23)), R_N=[0.0, 0.0, 0.0])
    _, y = s.record(np.arange(1.0, n + 1), truth, np.zeros((n, 3)))
    assert_array_equal(y[:, 4], 1.0)


def test_star_tracker_latency_delays_measurement_and_flag():
    e = _head(nea_cross=0.0, nea_about=0.0, sun_exclusion=0.5)
    now, late = _one(e), _one({**e, "latency": 3.0})
    n = 30
    rots = Rotation.random(n, random_state=17)
    q_SB = now.entry.mounting()
    b_N = rots.apply(Rotation.from_quat([*q_SB[1:], q_SB[0]]).as_matrix()[:, 2])  # the boresight in N
    sun = np.where((np.arange(n) % 3 == 0)[:, None], b_N, -b_N)  # the Sun in the cone every third sample
    truth = _truth(n, q_BN=_q_wxyz(rots), sun_N=sun)
    _, y_now = now.record(np.arange(1.0, n + 1), truth, np.zeros((n, 3)))
    _, y_late = late.record(np.arange(1.0, n + 1), truth, np.zeros((n, 3)))
    assert_array_equal(y_late[:3, 4], 0.0)  # nothing has come out yet
    assert_allclose(y_late[3:], y_now[:-3], rtol=0, atol=ROUNDOFF)
    assert 0 < y_now[:, 4].sum() < n  # the delayed flag is a real mix of valid and dropped


# -- the scene tables -------------------------------------------------------------------------
BAD = {
    "typo": ({"sensor": [_gyro(sigma_vv=1.0)]}, "sensor.g.sigma_vv: unknown key; did you mean 'sigma_v'?"),
    "unknown_kind": ({"sensor": [{"kind": "sun_sensor", "name": "c", "period": 1.0}]},
                     "sensor.c.kind: unknown kind 'sun_sensor' (valid: gyro, star_tracker)"),
    "negative_noise": ({"sensor": [_gyro(sigma_v=-1.0)]}, "sensor.g.sigma_v: must be greater than or equal to 0"),
    "misalignment_diagonal": ({"sensor": [_gyro(misalignment=[[1e-3, 0, 0], [0, 0, 0], [0, 0, 0]])]},
                              "sensor.g.misalignment: the diagonal must be zero"),
    "two_mountings": ({"sensor": [_head(q_SB=[1.0, 0, 0, 0])]}, "sensor.st.q_SB: give exactly one of"),
    "non_unit_mounting": ({"sensor": [{**_head(q_SB=[1.0, 0.1, 0, 0]), "boresight_B": None}]},
                          "sensor.st.q_SB: must be a unit quaternion"),
    "latency": ({"sensor": [_head(latency=0.3)]}, "sensor.st.latency: 0.3 s is not a whole number of periods"),
    "exclusion_angle": ({"sensor": [_head(sun_exclusion=4.0)]}, "sensor.st.sun_exclusion: must be an angle"),
    # units slips (issue 32), each hint's figure converted by hand: 0.005 deg/sqrt(h) x (pi/180) / 60
    # = 1.454e-6 rad/s^0.5 (the docstring's gyro), 15 arcsec x pi/648000 = 7.272e-5 rad, 0.01
    # deg/h/sqrt(h) x (pi/180) / 3600^1.5 = 8.08e-10 rad/s^1.5
    "arw_in_deg_per_sqrt_h": ({"sensor": [_gyro(sigma_v=0.005)]},
                              "sensor.g.sigma_v: 0.005 rad/s^0.5 is above 0.002 rad/s^0.5 (noisier than any rate gyro); "
                              "did you mean 0.005 deg/sqrt(h) = 1.454e-06 rad/s^0.5?"),
    "rrw_in_deg_per_h_sqrt_h": ({"sensor": [_gyro(sigma_u=0.01)]},
                                "sensor.g.sigma_u: 0.01 rad/s^1.5 is above 0.0001 rad/s^1.5 (a bias walking faster "
                                "than any rate gyro's); did you mean 0.01 deg/h/sqrt(h) = 8.08e-10 rad/s^1.5?"),
    "nea_in_arcsec": ({"sensor": [_head(nea_about=15.0)]},
                      "sensor.st.nea_about: 15 rad is above 0.005 rad (coarser than any star tracker); "
                      "did you mean 15 arcsec = 7.272e-05 rad?"),
    # a noise-free sensor the filter weighs (issue 32): the key that gives the filter its figure
    "noise_free_head_with_estimator": ({"sensor": [_gyro(), _head(nea_about=0.0)], "estimator": {"kind": "mekf"}},
                                       "sensor.st.nea_about: 0: the MEKF updates with head 'st' and weighs it by its "
                                       "noise-equivalent angles; give estimator.nea_about"),
    "noise_free_gyro_with_estimator": ({"sensor": [_gyro(sigma_v=0.0), _head()], "estimator": {"kind": "mekf"}},
                                       "sensor.g.sigma_v: 0: the MEKF propagates with gyro 'g' and weighs it by its "
                                       "noise; give estimator.sigma_v"),
    "estimator_arw_in_deg_per_sqrt_h": ({"sensor": [_gyro(), _head()], "estimator": {"kind": "mekf", "sigma_v": 0.005}},
                                        "estimator.sigma_v: 0.005 rad/s^0.5 is above 0.002 rad/s^0.5"),
    "duplicate": ({"sensor": [_gyro(), _gyro()]}, "sensor: names must be unique, repeated: ['g']"),
    "bad_name": ({"sensor": [_gyro(name="rga 1")]}, "sensor[0].name: "),
    "no_gyro": ({"sensor": [_head()], "estimator": {"kind": "mekf"}}, "estimator.gyro: name the gyro"),
    "head_period": ({"sensor": [_gyro(period=0.3), _head()], "estimator": {"kind": "mekf"}},
                    "estimator.star_trackers: head 'st': period 1 s is not a whole number of the gyro's (0.3 s)"),
    "unknown_head": ({"sensor": [_gyro(), _head()], "estimator": {"kind": "mekf", "star_trackers": ["st9"]}},
                     "estimator.star_trackers: must name one or more star trackers"),
}


def test_the_estimators_noise_figures_tune_the_filter_for_noise_free_sensors():
    """Noise-free gyro and head: the filter takes estimator.sigma_v, nea_cross and nea_about (the
    keys the refusal above names) as its own noise figures, per head (cross, cross, about)."""
    from stationbed.loop import Mekf  # noqa: PLC0415

    sensing = sensing_from_dict({"sensor": [_gyro(sigma_v=0.0), _head(nea_cross=0.0, nea_about=0.0)],
                                 "estimator": {"kind": "mekf", "sigma_v": 1e-6, "nea_cross": 2e-5, "nea_about": 1e-4}})
    f = Mekf.from_sensors(sensing.estimator, build_sensors(sensing.sensor))
    assert_array_equal(f.param_layout.get(f.params, "r_0"), [2e-5, 2e-5, 1e-4])  # rad
    assert f.param_layout.get(f.params, "sigma_v")[0] == 1e-6  # rad/s^0.5


@pytest.mark.parametrize("case", sorted(BAD), ids=sorted(BAD))
def test_bad_sensor_tables_fail_with_one_line_naming_the_field(case):
    data, message = BAD[case]
    data = {k: ([{kk: vv for kk, vv in e.items() if vv is not None} for e in v] if k == "sensor" else v)
            for k, v in data.items()}
    with pytest.raises(SceneError) as err:
        sensing_from_dict(data, source="s.toml")
    text = str(err.value)
    assert "\n" not in text and text.startswith("s.toml: ")
    assert message in text, text
