"""Noise-free sensors against the truth fed (issue 20, item 5): exactly what differs, and a bound.

The ideal measurement hands the law the true rate at tick k, ``ω_k``. A rate gyro, even a perfect
one, reports the rate *integrated over its sample* (Farrenkopf's model; docs/loop.md): with the
truth's ``theta_B`` the trapezoid integral of the true rate over each tick, the noise-free gyro's
sample at tick k is ``(θ_k − θ_{k−1})/h = (ω_{k−1} + ω_k)/2``, and the MEKF hands the law

    ω̂_k = (ω_{k−1} + ω_k)/2 − β̂_k,   so   ω̂_k − ω_k = (ω_{k−1} − ω_k)/2 − β̂_k ≈ −(h/2) ω̇_k

(half a tick late; the noise-free filter's bias estimate β̂ stays below 1e-9 rad/s: it absorbs
the tiny difference between its own propagation ``q̂ ⊗ exp(ω̂ h)`` and the RK4 truth), while
``q̂_k`` is the truth's ``q_k``. Truths used: the identity above,
tick by tick, against the true rates of the run's own rows (one row per tick), recorded beside
what the law received; and the closed-loop consequence bounded from it: the law's torque differs
by at most ``c J (h/2) max|ω̇|`` (pd's rate gain ``c``, the largest principal inertia; the
gyroscopic term's change is far below it), so the angular momentum of the two runs differs by at
most ``T`` times that over a run of ``T`` seconds, and it does (the attitude follows).
"""

from __future__ import annotations

import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.controllers.pd import PD

SCENARIO = "scenarios/iss_lvlh_hold_estimated.toml"
DURATION_S = 30.0  # s: 300 ticks, 30 star-tracker updates
PERIOD_S = 0.1
#: ω̂_k against (ω_{k−1} + ω_k)/2 − β̂_k: round-off of θ (|θ| < 1e-1 rad over the run: its last bit
#: over h is ~1e-16 rad/s) and of the rates (~1e-3 rad/s: 2e-19); the difference the docs state,
#: (h/2)|ω̇|, is ~1e-8 rad/s here
RATE_IDENTITY_RAD_S = 1e-12
#: the noise-free filter's bias estimate: what it takes the difference between its exp(ω̂ h)
#: propagation of the trapezoid-mean rate and the RK4 truth to be (~1e-10 rad per head period)
BIAS_RAD_S = 1e-9
#: q̂ against the truth: the noise-free estimate's floor measured in test_loop_flown (1.1e-10 deg)
ATTITUDE_RAD = 1e-9
#: the largest lag against the largest half-difference of the true rates: they differ by b̂ at
#: most (max|b̂| 8e-11 rad/s against a 1e-7 rad/s lag here: 1e-3); measured 1.1e-12 relative
LAG_RTOL = 1e-6


def noise_free(scene):
    over = {"simulation.duration": DURATION_S, "simulation.output_dt": PERIOD_S, "estimator.sigma_v": 1.454e-6,
            "estimator.sigma_u": 3.162e-10, "estimator.sigma_attitude0": 1e-12}
    for name in ("rga1", "rga2"):
        over.update({f"sensor.{name}.sigma_v": 0.0, f"sensor.{name}.sigma_u": 0.0, f"sensor.{name}.bias0": [0.0] * 3})
    for name in ("st1", "st2"):
        over.update({f"sensor.{name}.nea_cross": 1e-12, f"sensor.{name}.nea_about": 1e-12})
    return scene.replace(over)


@pytest.fixture(scope="module")
def runs():
    seen = []
    tick_update = PD.tick_update

    def recording_tick_update(self):  # what the per-tick loop calls every tick (pd's compiled form)
        update, counted = tick_update(self)

        def recording(t, meas):
            seen.append((t, *meas.q_BN, *meas.omega_BN_B))
            return update(t, meas)
        return recording, counted

    mp = pytest.MonkeyPatch()
    mp.setattr(PD, "tick_update", recording_tick_update)
    try:
        est = simulate(noise_free(load_scene(SCENARIO)), fused=False)
    finally:
        mp.undo()
    truth_scene = load_scene(SCENARIO).replace({"sensor": [], "estimator": None, "simulation.duration": DURATION_S,
                                                "simulation.output_dt": PERIOD_S})
    return est, simulate(truth_scene, fused=False), np.array(seen)


def test_the_law_receives_the_rate_averaged_over_the_tick(runs):
    est, _, seen = runs
    t, w = est.cols("t").ravel(), est.omega_BN_B
    assert np.array_equal(seen[:, 0], t)  # one row per tick, the law called at each
    w_hat, b_hat = seen[1:, 5:8], est.cols("est_bias_x", "est_bias_y", "est_bias_z")[1:]
    assert np.abs(w_hat - (0.5 * (w[:-1] + w[1:]) - b_hat)).max() < RATE_IDENTITY_RAD_S
    assert np.abs(b_hat).max() < BIAS_RAD_S
    lag = np.abs(w_hat - w[1:]).max()  # the difference the docs state: (h/2)|ω̇|, not round-off
    assert lag > 1e3 * RATE_IDENTITY_RAD_S
    np.testing.assert_allclose(lag, np.abs(0.5 * np.diff(w, axis=0)).max(), rtol=LAG_RTOL)
    q_hat, q = seen[:, 1:5], est.q_BN
    assert np.abs(q_hat - q * np.sign(np.sum(q_hat * q, axis=1))[:, None]).max() < ATTITUDE_RAD


def test_the_trajectory_differs_from_the_truth_fed_run_within_its_bound(runs):
    """The law's rate input differs by at most δ = (h/2) max|ω̇|, so its torque by at most
    ``Δτ = J_max (c + 2 max|ω|) δ`` (pd's rate gain c plus the gyroscopic term's derivative,
    ``|∂(ω × Jω)/∂ω| <= 2 J_max |ω|``); the CMG momentum integrates the torque, and the loop
    feeds the difference back through gains of at most ``c + ω_n`` per second (Gronwall), so
    ``|Δh(t)| <= Δτ t exp((c + ω_n) t)``."""
    est, fed, _ = runs
    scene = load_scene(SCENARIO)
    t, w = fed.cols("t").ravel(), fed.omega_BN_B
    delta = PERIOD_S / 2 * np.abs(np.diff(w, axis=0)).max() / PERIOD_S
    P = scene.controller.params
    c, wn = 2.0 * P["damping"] * P["bandwidth"], P["bandwidth"]
    J = np.max(np.linalg.eigvalsh(np.asarray(scene.body.inertia)))
    J += sum(a.mass * np.dot(a.cm, a.cm) + np.max(np.diag(a.inertia_P)) for a in scene.appendage)  # arrays' share
    d_tau = J * (c + 2 * np.linalg.norm(w, axis=1).max()) * delta
    dh = np.linalg.norm(est.cols("hx", "hy", "hz") - fed.cols("hx", "hy", "hz"), axis=1)
    bound = d_tau * t * np.exp((c + wn) * t)
    assert np.all(dh <= bound)
    assert dh[-1] > 1e-3 * bound[-1]  # the bound is not vacuous: the runs differ by that order
