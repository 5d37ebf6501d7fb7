"""Monte Carlo batches (stationbed.run.batch): a mapped batch is the same physics as single runs.

Truths: each batch sample against an individual ``stationbed.simulate`` run of the same initial
conditions and settings (the single-run path has its own C step driver, so this checks the
vectorised step control against it); the dispersion's statistics against scipy's rotation
algebra (an independent implementation of quaternion composition and the rotation vector).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

import stationbed
from stationbed.run.batch import disperse_initial, simulate_batch
from stationbed.core.rotation import rotation_angle

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
GG = SCENARIOS / "iss_lvlh_gravity_gradient.toml"

#: The batch takes the same steps as the single run (checked: equal step counts), so they differ
#: only by floating-point operation order (dense variant of the step, interpolant in numpy):
#: measured <= 6e-14 rad over one orbit; 1e-11 rad is 1e-2 x the scene's rtol (1e-9), far below
#: any integration error yet 100x above the round-off seen.
BATCH_ATT_TOL_RAD = 1e-11
BATCH_REL_TOL = 1e-11  # rate, H_O_N, T relative to their largest magnitude: same argument
DURATION_S = 1500.0  # ~1/4 orbit: ~10 DOP853 steps with dense output, a few hundred ms
N_SAMPLES = 8
ATT_SIGMA_RAD = math.radians(1.0)  # 1 deg 1-sigma per axis about LVLH
RATE_SIGMA_RAD_S = 1e-5  # rad/s 1-sigma per axis


@pytest.fixture(scope="module")
def gg_scene():
    return stationbed.load_scene(GG)


@pytest.fixture(scope="module")
def gg_batch(gg_scene):
    q0s, w0s = disperse_initial(
        gg_scene, N_SAMPLES, attitude_sigma_rad=ATT_SIGMA_RAD, rate_sigma_rad_s=RATE_SIGMA_RAD_S, seed=5
    )
    return q0s, w0s, simulate_batch(gg_scene, q0s, w0s, duration=DURATION_S)


def _single(scene, q0, w0, **kw):
    s = scene.replace(**{"initial.q_BN": list(q0), "initial.omega_BN_B": list(w0)})
    return stationbed.simulate(s, integrator="dop853", **kw)


def _assert_same_run(traj, batch, i):
    assert np.array_equal(traj.t, batch.t)
    assert batch.status[i] == 0
    assert np.max(rotation_angle(traj.q_BN, batch.q_BN[i])) <= BATCH_ATT_TOL_RAD
    for got, want in ((batch.omega_BN_B[i], traj.omega_BN_B), (batch.H_O_N[i], traj.H_O_N), (batch.T[i], traj["T"])):
        scale = np.max(np.abs(want))
        assert_allclose(got, want, rtol=0, atol=BATCH_REL_TOL * scale)


@pytest.mark.parametrize("i", [0, 3, 7])
def test_batch_sample_equals_its_single_run(gg_scene, gg_batch, i):
    """Sample i of a mapped batch is the single DOP853 run from the same initial state."""
    q0s, w0s, batch = gg_batch
    traj = _single(gg_scene, q0s[i], w0s[i], duration=DURATION_S)
    _assert_same_run(traj, batch, i)
    assert batch.meta["n_steps"][i] == traj.meta["n_steps"]  # the same step sequence


def test_batch_initial_state_is_the_lvlh_conversion(gg_scene, gg_batch):
    """q0s/w0s are relative to LVLH for an lvlh scene: row 0 is the single run's row 0."""
    q0s, w0s, batch = gg_batch
    traj = _single(gg_scene, q0s[1], w0s[1], duration=DURATION_S)
    assert rotation_angle(traj.q_BN[:1], batch.q_BN[1, :1])[0] < 1e-15
    assert_allclose(batch.omega0_BN_B[1], traj.omega_BN_B[0], rtol=0, atol=1e-18)


@pytest.mark.parametrize(
    "scene_file, formulation",
    [("torque_window.toml", "momentum"), ("array_rate_step.toml", "dalembert")],
    ids=["torque-window-segments", "rate-step-jump-omega-form"],
)
def test_batch_handles_discontinuities_like_simulate(scene_file, formulation):
    """Torque-window edges cut segments, and an array rate step re-initialises ω (ω-state
    form): the batch does both exactly as the single run."""
    scene = stationbed.load_scene(SCENARIOS / scene_file)
    q0s, w0s = disperse_initial(scene, 3, attitude_sigma_rad=0.01, rate_sigma_rad_s=1e-5, seed=2)
    duration = min(scene.simulation.duration, 3000.0)
    batch = simulate_batch(scene, q0s, w0s, formulation=formulation, duration=duration)
    for i in range(3):
        _assert_same_run(_single(scene, q0s[i], w0s[i], formulation=formulation, duration=duration), batch, i)


def test_parameter_dispersion_uses_each_samples_scene(gg_scene):
    """``scenes=``: sample k runs with its own inertia (body inertia scaled by 1 + 0.05 k)."""
    J = np.array(gg_scene.body.inertia)
    scenes = [gg_scene.replace(**{"body.inertia": (J * (1 + 0.05 * k)).tolist()}) for k in range(3)]
    q0s = np.tile(gg_scene.initial.q_BN, (3, 1))
    w0s = np.tile([0.0, 2e-5, 0.0], (3, 1))  # rad/s relative to LVLH
    batch = simulate_batch(gg_scene, q0s, w0s, scenes=scenes, duration=DURATION_S)
    for k in range(3):
        _assert_same_run(_single(scenes[k], q0s[k], w0s[k], duration=DURATION_S), batch, k)
    # and the inertia matters: the samples differ by far more than the tolerance
    assert np.max(rotation_angle(batch.q_BN[0], batch.q_BN[2])) > 1e3 * BATCH_ATT_TOL_RAD


def test_threads_do_not_change_the_numbers(gg_scene, gg_batch):
    q0s, w0s, batch = gg_batch
    serial = simulate_batch(gg_scene, q0s, w0s, duration=DURATION_S, threads=1)
    threaded = simulate_batch(gg_scene, q0s, w0s, duration=DURATION_S, threads=2)
    assert np.array_equal(serial.x, threaded.x)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # |ω0|² in the atol scale
def test_a_failing_sample_leaves_the_others_intact(gg_scene, gg_batch):
    """A sample whose state overflows is flagged and NaN; the other samples are unchanged."""
    q0s, w0s, batch = gg_batch
    w_bad = w0s.copy()
    w_bad[2] = [1e160, 0.0, 0.0]  # rad/s: ω × H overflows to inf within the first step
    bad = simulate_batch(gg_scene, q0s, w_bad, duration=DURATION_S)
    assert bad.status[2] != 0 and 2 in bad.meta["failures"]
    assert np.isnan(bad.x[2, -1]).all()
    others = [i for i in range(N_SAMPLES) if i != 2]
    assert np.all(bad.status[others] == 0)
    assert np.array_equal(bad.x[others], batch.x[others])


# -- the dispersion ---------------------------------------------------------------------


def test_dispersion_is_seeded(gg_scene):
    kw = dict(attitude_sigma_rad=ATT_SIGMA_RAD, rate_sigma_rad_s=RATE_SIGMA_RAD_S)
    a = disperse_initial(gg_scene, 16, seed=1, **kw)
    b = disperse_initial(gg_scene, 16, seed=1, **kw)
    c = disperse_initial(gg_scene, 16, seed=2, **kw)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


def test_dispersion_has_the_stated_statistics(gg_scene):
    """Rotation vectors of q_nom⁻¹ ⊗ q_i (scipy) and rate offsets are zero-mean with the stated
    1-sigma per axis, uncorrelated across axes."""
    n = 20000
    q, w = disperse_initial(gg_scene, n, attitude_sigma_rad=ATT_SIGMA_RAD, rate_sigma_rad_s=RATE_SIGMA_RAD_S, seed=3)
    assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    q_nom = np.array(gg_scene.initial.q_BN)
    R_nom = Rotation.from_quat(np.roll(q_nom, -1))
    theta = (R_nom.inv() * Rotation.from_quat(np.roll(q, -1, axis=1))).as_rotvec()
    dw = w - np.array(gg_scene.initial.omega_BN_B)
    # sampling error: mean ~ sigma/sqrt(n) (0.7 % of sigma), std ~ sigma/sqrt(2n) (0.5 %);
    # 5-sigma bounds: 3.5 % and 2.5 % of sigma, so a seeded run never flakes and a wrong
    # scale (e.g. sigma applied to the half-angle: a factor 2) fails by far
    for sample, sigma in ((theta, ATT_SIGMA_RAD), (dw, RATE_SIGMA_RAD_S)):
        assert np.all(np.abs(sample.mean(axis=0)) < 0.035 * sigma)
        assert_allclose(sample.std(axis=0), sigma, rtol=0.025)
        corr = np.corrcoef(sample.T)
        assert np.all(np.abs(corr[~np.eye(3, dtype=bool)]) < 0.035)


# -- bad inputs --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda q, w: (q[:, :3], w), r"q0s must have shape \(n, 4\)"),
        (lambda q, w: (q, w[:-1]), "w0s has 2 rows but q0s has 3"),
        (lambda q, w: (q, w[:, :2]), r"w0s must have shape \(n, 3\)"),
        (lambda q, w: (q * 1.01, w), r"q0s\[0\] has norm 1.01"),
        (lambda q, w: (q, np.where(np.arange(9).reshape(3, 3) == 4, np.nan, w)), r"w0s\[1\] is not finite"),
        (lambda q, w: (np.where(np.arange(12).reshape(3, 4) == 8, np.inf, q), w), r"q0s\[2\] is not finite"),
    ],
    ids=["q-shape", "row-mismatch", "w-shape", "non-unit-q", "nan-rate", "inf-q"],
)
def test_bad_initial_conditions_are_refused(gg_scene, change, match):
    q0s = np.tile(gg_scene.initial.q_BN, (3, 1))
    w0s = np.zeros((3, 3))
    q, w = change(q0s, w0s)
    with pytest.raises(ValueError, match=match):
        simulate_batch(gg_scene, q, w, duration=10.0)


def test_closed_loop_scene_is_refused():
    scene = stationbed.load_scene(SCENARIOS / "iss_lvlh_hold.toml")
    with pytest.raises(ValueError, match="open loop only"):
        simulate_batch(scene, [scene.initial.q_BN], [[0.0, 0.0, 0.0]], duration=10.0)


def test_scenes_of_another_structure_are_refused(gg_scene):
    other = stationbed.load_scene(SCENARIOS / "torque_window.toml")  # rigid, deep space
    with pytest.raises(ValueError, match=r"scenes\[1\].*different structure"):
        simulate_batch(gg_scene, np.tile(gg_scene.initial.q_BN, (2, 1)), np.zeros((2, 3)), scenes=[gg_scene, other])


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(attitude_sigma_rad=-1.0, rate_sigma_rad_s=0.0, seed=0), "attitude_sigma_rad must be finite and >= 0"),
        (dict(attitude_sigma_rad=0.0, rate_sigma_rad_s=math.nan, seed=0), "rate_sigma_rad_s must be finite"),
    ],
    ids=["negative-sigma", "nan-sigma"],
)
def test_bad_dispersion_is_refused(gg_scene, kw, match):
    with pytest.raises(ValueError, match=match):
        disperse_initial(gg_scene, 4, **kw)
