"""The closed loop (issue 3, DESIGN §7): integer tick clock, zero-order hold, the three ways a
period is integrated, sensor noise and delay (a controller that misbehaves, bad names and
controller files: test_controller_faults.py).

The loop can advance a period three ways, and all must give the same numbers:

* the *fused loop* (``stationbed.run.fused``): a controller with a symbolic form, RK4 with one step
  per period, no discontinuity, no sensor delay: many ticks in one compiled call;
* the *per-tick fused tick*: a Python controller, RK4 with one step per period: actuation, one
  RK4 step and the next measurement in one compiled call per tick;
* the *generic path*: any integrator, one ``Integrator.advance`` per period, split at the
  scene's discontinuities inside it (forced here by an RK4 subclass declared not ``fusable``,
  or by an adaptive integrator).

Closed forms: a body with a spherical inertia ``J E`` has no gyroscopic torque
(``ω × Jω = 0``), so under a held body torque its rate is exactly
``ω(t) = ω0 + ∫ τ dt / J`` in B components, whatever the attitude does.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.studies.check import compare
from stationbed.run.controller import Controller
from stationbed.integrators import RK4
from stationbed.scene import scene_from_dict

PERIOD_S = 0.1  # s, 10 Hz as the shipped scenes
J_SPHERE = 500.0  # kg m², spherical inertia: no gyroscopic coupling
W0 = [0.01, -0.02, 0.005]  # rad/s
#: round-off of a few hundred additions of ~1e-4 rad/s increments [rad/s]
ZOH_TOL_RAD_S = 1e-14


def loop_scene(**over) -> dict:
    """A spherical rigid body in deep space, 10 Hz controller, RK4 at one step per period."""
    d = {
        "name": "loop",
        "simulation": {"duration": 20.0, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"omega_BN_B": list(W0)},
        "body": {"mass": 100.0, "inertia": [[J_SPHERE, 0, 0], [0, J_SPHERE, 0], [0, 0, J_SPHERE]]},
        "controller": {"name": "recorder", "period": PERIOD_S},
    }
    for path, value in over.items():
        node = d
        keys = path.split(".")
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    return d


def torque_sequence(k: int) -> tuple[float, float, float]:
    """A known, non-smooth torque for tick k [N m] (the same function of k, not of t)."""
    return (0.3 * math.sin(0.7 * k), -0.2 * math.cos(0.3 * k), 0.1 * ((k % 5) - 2))


class Recorder(Controller):
    """Open loop: returns ``torque_sequence(k)`` at its k-th call; records what it was given."""

    name = "recorder"

    def _reset(self, plant):
        self.t, self.q, self.w = [], [], []

    def _update(self, t, meas):
        k = len(self.t)
        self.t.append(t)
        self.q.append(meas.q_BN.copy())
        self.w.append(meas.omega_BN_B.copy())
        return torque_sequence(k)


class RK4Generic(RK4):
    """RK4 declared not fusable: the loop takes the generic per-period path."""

    fusable = False


# ---------------------------------------------------------------------------------------
# the tick clock
# ---------------------------------------------------------------------------------------


def test_tick_clock_has_no_drift_after_1e5_ticks():
    """10⁵ ticks of 0.1 s: the controller runs at exactly t = k * 0.1 (the product, not a running
    sum), duration / period + 1 times, and the last tick is at the duration itself."""
    duration = 1.0e4  # s
    n = 100_000
    ctrl = Recorder()
    tr = simulate(scene_from_dict(loop_scene(**{"simulation.duration": duration, "simulation.output_dt": 100.0})),
                  controller=ctrl)
    ts = np.array(ctrl.t)
    assert len(ts) == n + 1 == ctrl.n_updates
    assert np.array_equal(ts, np.arange(n + 1) * PERIOD_S)
    assert ts[-1] == duration
    assert tr.meta["summary"]["ticks"] == n and tr.meta["summary"]["controller_updates"] == n + 1
    # what the integer clock avoids: a running sum of 0.1 s has drifted by ~2e-8 s by now
    acc = 0.0
    for _ in range(n):
        acc += PERIOD_S
    assert abs(acc - duration) > 1e-9


def test_tick_clock_with_a_short_last_period():
    """A duration that is not a whole number of periods: ticks at k * period, then one at the
    duration (the last period is shortened, not skipped or overrun)."""
    ctrl = Recorder()
    tr = simulate(scene_from_dict(loop_scene(**{"simulation.duration": 1.05, "simulation.output_dt": 0.5})),
                  controller=ctrl)
    assert ctrl.t == [k * PERIOD_S for k in range(11)] + [1.05]
    assert tr.t[-1] == 1.05


# ---------------------------------------------------------------------------------------
# zero-order hold
# ---------------------------------------------------------------------------------------


def held_rate(n_rows: int) -> np.ndarray:
    """ω at t_k = k period: ω0 + Σ_{i<k} τ_i period / J (each τ_i held over [t_i, t_i+1))."""
    taus = np.array([torque_sequence(k) for k in range(n_rows)])
    steps = np.vstack([np.zeros(3), np.cumsum(taus[:-1], axis=0) * PERIOD_S / J_SPHERE])
    return np.array(W0) + steps


@pytest.mark.parametrize("integrator", ["rk4", RK4Generic, "dop853"], ids=["fused_tick", "generic_rk4", "dop853"])
def test_zero_order_hold_closed_form(integrator):
    """Each command is held over exactly its own period: the body rate is the running integral of
    the held torque over J (RK4 and DOP853 integrate a constant derivative exactly); the
    ``tau_cmd`` columns log the command of each row's tick."""
    ctrl = Recorder()
    tr = simulate(scene_from_dict(loop_scene()), controller=ctrl, integrator=integrator)
    assert_allclose(tr.omega_BN_B, held_rate(len(tr)), rtol=0, atol=ZOH_TOL_RAD_S)
    taus = np.array([torque_sequence(k) for k in range(len(tr))])
    assert np.array_equal(tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z"), taus)


def test_torque_window_edge_inside_a_period():
    """A scene torque that switches on and off inside control periods is applied exactly from
    its edges (the loop splits those periods there), on top of the held command."""
    start, stop = 1.05, 3.37  # s, both inside a period
    window = np.array([0.05, 0.0, -0.08])  # N m
    d = loop_scene(torque=[{"kind": "constant", "torque_B": window.tolist(), "start": start, "stop": stop}])
    tr = simulate(scene_from_dict(d), controller=Recorder())
    on = np.clip(tr.t, start, stop) - start  # s of window before each row
    expected = held_rate(len(tr)) + np.outer(on, window) / J_SPHERE
    assert_allclose(tr.omega_BN_B, expected, rtol=0, atol=ZOH_TOL_RAD_S)


# ---------------------------------------------------------------------------------------
# three paths, one answer
# ---------------------------------------------------------------------------------------

#: round-off: the same arithmetic compiled as different C functions (common subexpressions
#: differ), amplified by the closed loop over 3000 ticks; measured ~3e-13 of each column's range
PATH_RTOL = 1e-9


@pytest.fixture(scope="module")
def iss_three_paths():
    """300 s of iss_lvlh_hold (PD, DGCMGs with SR steering, tracking arrays, gravity gradient,
    aero torque) by the fused loop, the per-tick fused tick and the generic path; every stage
    (the paths' contract: the per-tick loops evaluate the environment at every stage, the default
    rate is checked against that in tests/test_effect_rates.py)."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace({"simulation.environment_rate": 0})
    kw = dict(duration=300.0, output_dt=1.0)
    return {
        "fused_loop": simulate(scene, **kw),
        "fused_tick": simulate(scene, fused=False, **kw),
        "generic": simulate(scene, integrator=RK4Generic, **kw),
    }


@pytest.mark.parametrize("path", ["fused_tick", "generic"])
def test_paths_give_the_same_trajectory(iss_three_paths, path):
    """Every column (state, momentum, CMG gimbals and rates, commands, tracking errors) agrees
    with the fused loop to round-off."""
    ref, other = iss_three_paths["fused_loop"], iss_three_paths[path]
    assert ref.meta["summary"]["fused"] is True and other.meta["summary"]["fused"] is False
    assert ref.columns == other.columns and np.array_equal(ref.t, other.t)
    scale = np.maximum(np.abs(ref.data).max(axis=0), 1e-300)
    rel = np.abs(other.data - ref.data) / scale
    worst = int(np.argmax(rel.max(axis=0)))
    assert rel.max() <= PATH_RTOL, f"column {ref.columns[worst]} differs by {rel.max():.2e} of its range"
    for key in ("ticks", "controller_updates", "rate_limited_ticks", "momentum_saturated_ticks"):
        assert ref.meta["summary"][key] == other.meta["summary"][key], key


# ---------------------------------------------------------------------------------------
# DOP853 against RK4 in the closed loop
# ---------------------------------------------------------------------------------------

#: A fast small spacecraft (ω ~ 0.4 rad/s, PD at 0.5 rad/s) so that RK4's truncation error at
#: 0.1 s is well above round-off and its convergence can be seen; the station scenes are so slow
#: that RK4 at 10 Hz agrees with DOP853 to round-off (~1e-15 rad), which proves nothing.
TUMBLER = {
    "name": "tumbler",
    "simulation": {"duration": 30.0, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S,
                   "rtol": 1e-12, "atol": 1e-14},
    "initial": {"omega_BN_B": [0.3, -0.2, 0.4]},
    "body": {"mass": 100.0, "inertia": [[100.0, 5.0, -3.0], [5.0, 200.0, 2.0], [-3.0, 2.0, 250.0]]},
    "controller": {"name": "pd", "period": PERIOD_S,
                   "params": {"reference": "inertial", "bandwidth": 0.5, "damping": 0.7, "max_slew_rate": 1.0}},
}


def test_dop853_and_rk4_closed_loops_agree_to_rk4_truncation():
    """Both integrate the same held commands; DOP853 at rtol 1e-12 is the reference. RK4's error
    is then its truncation error: it falls 16x when its step halves (4th order, measured 15.5x)
    and its size is what Richardson extrapolation predicts from the two RK4 runs,
    ``|rk4(h) - rk4(h/2)| * 16/15`` (so the tolerance is not a guess but RK4's own estimate)."""
    scene = scene_from_dict(copy.deepcopy(TUMBLER))
    dp = simulate(scene, integrator="dop853")
    rk_h = simulate(scene)  # one step per period (fused)
    rk_h2 = simulate(scene, step=PERIOD_S / 2)  # two steps per period (generic)
    err_h = np.array(compare(rk_h, dp))  # attitude [rad], rate [rad/s], H [N m s]
    err_h2 = np.array(compare(rk_h2, dp))
    richardson = np.array(compare(rk_h, rk_h2)) * 16 / 15
    ratio = err_h / err_h2
    assert np.all((ratio > 12) & (ratio < 20)), f"convergence ratios {ratio}"
    assert np.all(err_h <= 1.5 * richardson) and np.all(err_h >= richardson / 1.5), (err_h, richardson)
    assert err_h[0] < 1e-8  # rad: even on this tumbler RK4 at 10 Hz is that close (measured 3.8e-9)


# ---------------------------------------------------------------------------------------
# sensor noise and delay
# ---------------------------------------------------------------------------------------

NOISE_ATT_RAD = 1e-3  # rad, 1 sigma per axis
NOISE_RATE_RAD_S = 1e-5  # rad/s, 1 sigma per axis


def _noisy_pd(seed):
    d = copy.deepcopy(TUMBLER)
    d["simulation"]["duration"] = 5.0
    d["controller"]["sensor"] = {"attitude_noise": NOISE_ATT_RAD, "rate_noise": NOISE_RATE_RAD_S, "seed": seed}
    return scene_from_dict(d)


def test_noise_is_seeded():
    """Same seed: identical runs, bit for bit; another seed: a different run."""
    a, b, c = simulate(_noisy_pd(7)), simulate(_noisy_pd(7)), simulate(_noisy_pd(8))
    assert np.array_equal(a.data, b.data)
    assert np.abs(a.data[1:] - c.data[1:]).max() > 0


def _seen(sensor, integrator="rk4", duration=100.0):
    """What an open-loop recorder sees (its commands do not depend on it: the truth is shared)."""
    ctrl = Recorder()
    d = loop_scene(**{"simulation.duration": duration, "simulation.output_dt": 1.0, "controller.sensor": sensor})
    d["body"]["inertia"] = [[100.0, 5.0, -3.0], [5.0, 200.0, 2.0], [-3.0, 2.0, 250.0]]  # kg m², asymmetric
    simulate(scene_from_dict(d), controller=ctrl, integrator=integrator)
    return np.array(ctrl.q), np.array(ctrl.w)


@pytest.mark.parametrize("integrator", ["rk4", "dop853"])
def test_delay_shows_the_measurement_from_d_ticks_before(integrator):
    """``delay = 3 periods``: at tick k the controller sees the true state of tick k - 3 (and the
    first measurement until then), exactly."""
    d = 3
    q_true, w_true = _seen({}, integrator)
    q, w = _seen({"delay": d * PERIOD_S}, integrator)
    assert np.array_equal(q[d:], q_true[:-d]) and np.array_equal(w[d:], w_true[:-d])
    assert np.array_equal(q[:d], np.tile(q_true[0], (d, 1)))
    assert np.abs(w_true[d:] - w_true[:-d]).max() > 1e-6  # rad/s: the delay is visible


#: two-sided level of each chi-squared check of the noise's covariance (8 checks: ~1 % in all
#: for a correct noise; a sigma off by 10 % moves the 3000-dof statistic ~7 of its sd)
CHI2_ALPHA = 1e-3


def _small_rotation(q, q_true):
    """Per row the rotation vector δθ of ``q = q_true ⊗ δq`` (``δθ = 2 atan2(|v|, w) v/|v|`` of
    ``δq = q_true* ⊗ q``), scalar-first quaternions, written out here."""
    w0, v0 = q_true[:, :1], -q_true[:, 1:]
    w1, v1 = q[:, :1], q[:, 1:]
    w = w0 * w1 - np.sum(v0 * v1, axis=1, keepdims=True)
    v = w0 * v1 + w1 * v0 + np.cross(v0, v1)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return 2.0 * np.arctan2(n, w) * v / n


def test_noise_covariance_is_in_its_chi_squared_band():
    """Attitude noise is a small rotation δθ with N(0, σ² E) per tick, rate noise N(0, σ² E),
    zero mean, independent ticks: over N = 1001 ticks ``Σ δθ_i² / σ²`` is χ²(N) per axis and
    ``Σ |δθ|² / σ²`` χ²(3N); each off-diagonal ``Σ δθ_i δθ_j / σ²`` has mean 0 and variance N
    (normal by the central limit theorem). Every one in its band at :data:`CHI2_ALPHA`."""
    q_true, w_true = _seen({})
    q, w = _seen({"attitude_noise": NOISE_ATT_RAD, "rate_noise": NOISE_RATE_RAD_S, "seed": 3})
    for e in (_small_rotation(q, q_true) / NOISE_ATT_RAD, (w - w_true) / NOISE_RATE_RAD_S):
        n = len(e)
        S = e.T @ e  # N times the sample covariance (the mean is known: zero), in units of σ²
        lo, hi = stats.chi2.ppf([CHI2_ALPHA / 2, 1 - CHI2_ALPHA / 2], n)
        assert np.all((np.diag(S) > lo) & (np.diag(S) < hi)), (np.diag(S), lo, hi)
        lo3, hi3 = stats.chi2.ppf([CHI2_ALPHA / 2, 1 - CHI2_ALPHA / 2], 3 * n)
        assert lo3 < np.trace(S) < hi3
        z = stats.norm.ppf(1 - CHI2_ALPHA / 2)
        assert np.all(np.abs(S[np.triu_indices(3, 1)]) < z * math.sqrt(n)), S
        assert np.all(np.abs(e.mean(axis=0)) < z / math.sqrt(n))
    # and a wrong sigma is seen: the same draws read as 10 % larger fall out of the band
    e = (w - w_true) / (1.1 * NOISE_RATE_RAD_S)
    assert not lo3 < np.sum(e**2) < hi3


class LvlhRecorder(Recorder):
    """Records the LVLH fields of the measurement (deep space: their documented constants)."""

    name = "lvlh_recorder"

    def _reset(self, plant):
        super()._reset(plant)
        self.fields = []

    def _update(self, t, meas):
        self.fields.append(np.concatenate([meas.C_ON.ravel(), meas.q_ON, meas.omega_ON_O, meas.sun_N, meas.r_N]))
        return super()._update(t, meas)


@pytest.mark.parametrize("integrator", [RK4, RK4Generic], ids=["fused_tick", "generic"])
def test_deep_space_measurement_has_its_documented_lvlh_fields(integrator):
    """Without an orbit the measurement's LVLH outputs are structural constants (C_ON = E,
    q_ON = (1, 0, 0, 0), ω_ON_O = 0, sun_N = 0, r_N = 0): casadi stores them sparse, and a buffer
    reads only nonzeros, so before the dense FastCall a law read C_ON = [1, 1, 1, 0, ...] and q_ON
    shifted. The values are exact constants: compared exactly."""
    rec = LvlhRecorder(period=PERIOD_S)
    simulate(scene_from_dict(loop_scene(**{"simulation.duration": 1.0})), integrator=integrator, controller=rec)
    expect = np.concatenate([np.eye(3).ravel(), [1.0, 0.0, 0.0, 0.0], np.zeros(9)])
    assert len(rec.fields) >= 10
    for f in rec.fields:
        assert np.array_equal(f, expect)
