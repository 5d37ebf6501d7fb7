"""The sensors and the MEKF as one composition on the tick clock (stationbed/loop/suite.py).

Truths used: the parts, each proved on its own (tests/test_loop_sensors.py, tests/test_mekf.py),
stepped by hand here on their own clocks (each sensor's ``record`` at its own sample times with
its own noise stream, the filter's ``record`` on inputs assembled here); the composition must
give exactly what they give. Sample-and-hold and the fresh flags are checked against the
integer arithmetic of the schedule (tick k samples a sensor of n ticks when k mod n = 0).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from stationbed.loop import TRUTH, Suite, SuiteNoise, noise_rng
from stationbed.scene import sensing_from_dict

TICK_S = 0.1  # s, the controller period
#: float64 round-off: the composition evaluates the same operations as the parts
ROUNDOFF = 1e-13
OMEGA_B = np.array([1e-4, -1.13e-3, 2e-4])  # rad/s, constant (closed-form truth)


def _sensing(gyro_period=0.2, head_period=1.0):
    return sensing_from_dict({"sensor": [
        dict(kind="gyro", name="rga", period=gyro_period, sigma_v=1.454e-6, sigma_u=3.162e-10, bias0=[1e-5, 0, -1e-5]),
        dict(kind="star_tracker", name="st1", period=head_period, boresight_B=[0.0, -0.5, -0.866], nea_cross=9.7e-6,
             nea_about=7.3e-5, sun_exclusion=0.5),
        dict(kind="star_tracker", name="st2", period=2 * head_period, boresight_B=[0.0, 0.5, -0.866],
             nea_cross=9.7e-6, nea_about=7.3e-5, latency=2 * head_period),
    ], "estimator": {"kind": "mekf"}})


def _truth(n, seed=0):
    t = TICK_S * np.arange(1, n + 1)
    rots = Rotation.random(random_state=seed) * Rotation.from_rotvec(t[:, None] * OMEGA_B)
    x, y, z, w = rots.as_quat().T
    rows = np.zeros((n, TRUTH.size))
    rows[:, TRUTH.slice("q_BN")] = np.stack([w, x, y, z], axis=1)
    rows[:, TRUTH.slice("theta_B")] = t[:, None] * OMEGA_B
    rows[:, TRUTH.slice("R_N")] = [6.778e6, 0.0, 0.0]
    rows[:, TRUTH.slice("sun_N")] = rots.apply([0.0, 0.0, -1.0])  # the Sun overhead in B: st1 blinded at times
    rows[:, TRUTH.slice("shadow")] = 1.0
    return rows


@pytest.fixture(scope="module")
def suite():
    return Suite(_sensing(), TICK_S)


def test_suite_gives_exactly_what_its_parts_give(suite):
    n, seed = 400, 9
    truth = _truth(n)
    q0 = [0.9, 0.1, -0.3, 0.3]
    X, Y = suite.record(suite.initial(q0 / np.linalg.norm(q0)), 1, truth, SuiteNoise(suite, seed).draw(n))
    gyro, st1, st2 = suite.sensors
    mekf = suite.mekf
    z = np.zeros((n, mekf.inputs.size))
    ticks = np.arange(1, n + 1)
    for i, s in enumerate(suite.sensors):
        at = np.flatnonzero(ticks % suite.every[s.name] == 0)
        _, ys = s.record(TICK_S * ticks[at], truth[at], s.noise(noise_rng(seed, i), at.size))
        assert_allclose(Y[at, suite.OUTPUTS.slice(s.name)], ys, rtol=0, atol=ROUNDOFF)
        if s is gyro:
            z_at, z_g = at, ys
        else:
            j = mekf.heads.index(s)
            held = np.zeros((n, 5))
            held[at] = ys
            z[:, mekf.inputs.slice(f"q_SN_{j}")] = held[:, :4]
            z[:, mekf.inputs.slice(f"valid_{j}")] = held[:, 4:]
            z[at, mekf.inputs.slice(f"fresh_{j}")] = 1.0
    xf, omega_hat = mekf.record(mekf.initial(q0 / np.linalg.norm(q0)), _with_rate(z[z_at], mekf, z_g))
    assert_allclose(Y[z_at, suite.OUTPUTS.slice("q_BN_hat")], mekf.state.get(xf, "q_BN"), rtol=0, atol=ROUNDOFF)
    assert_allclose(Y[z_at, suite.OUTPUTS.slice("bias_B_hat")], mekf.state.get(xf, "bias_B"), rtol=0, atol=ROUNDOFF)
    assert_allclose(Y[z_at, suite.OUTPUTS.slice("omega_hat_B")], omega_hat, rtol=0, atol=ROUNDOFF)
    assert 0 < Y[:, suite.OUTPUTS.slice("st1")][:, 4].sum() < n  # st1 was blinded part of the time


def _with_rate(z, mekf, rate):
    z = z.copy()
    z[:, mekf.inputs.slice("omega_B")] = rate
    return z


def test_outputs_hold_between_samples_and_fresh_marks_the_samples(suite):
    n = 120
    X, Y = suite.record(suite.initial(), 1, _truth(n), SuiteNoise(suite, 3).draw(n))
    ticks = np.arange(1, n + 1)
    for s in suite.sensors:
        due = ticks % suite.every[s.name] == 0
        assert_array_equal(Y[:, suite.OUTPUTS.slice(f"{s.name}.fresh")][:, 0], due.astype(float))
        y = Y[:, suite.OUTPUTS.slice(s.name)]
        changed = np.any(np.diff(y, axis=0) != 0, axis=1)
        assert not np.any(changed & ~due[1:]), f"{s.name}: output changed between samples"
    assert suite.every == {"rga": 2, "st1": 10, "st2": 20}
    # the filter steps only on the gyro's samples: its estimates held, bit for bit, between them
    est = np.hstack([Y[:, suite.OUTPUTS.slice(f)] for f in ("q_BN_hat", "bias_B_hat", "omega_hat_B")])
    gyro_due = ticks % suite.every["rga"] == 0
    assert_array_equal(est[1:][~gyro_due[1:]], est[:-1][~gyro_due[1:]])
    assert np.all(np.any(est[1:][gyro_due[1:]] != est[:-1][gyro_due[1:]], axis=1))


def test_a_run_in_chunks_is_the_run_at_once(suite):
    """Sample k is the same however the executor cuts the run (noise drawn chunk by chunk)."""
    n = 200
    truth = _truth(n, seed=4)
    whole_x, whole_y = suite.record(suite.initial(), 1, truth, SuiteNoise(suite, 21).draw(n))
    noise = SuiteNoise(suite, 21)
    x1, y1 = suite.record(suite.initial(), 1, truth[:70], noise.draw(70))
    x2, y2 = suite.record(x1[-1], 71, truth[70:], noise.draw(130))
    assert_array_equal(np.vstack([y1, y2]), whole_y)
    assert_array_equal(np.vstack([x1, x2]), whole_x)


def test_tick_reads_only_what_its_sensors_read(suite):
    f = suite.function()
    args = [ca.SX.sym(n, f.size1_in(i)) for i, n in enumerate(f.name_in())]
    outs = ca.vertcat(*f(*args))
    read = {r for s in suite.sensors for r in s.reads}
    for name in TRUTH.names:
        assert ca.depends_on(outs, args[3][TRUTH.slice(name)]) == (name in read), name


def test_period_not_a_whole_number_of_ticks_is_refused():
    with pytest.raises(ValueError, match="sensor 'rga': period 0.25 s is not a whole number of ticks \\(0.1 s\\)"):
        Suite(_sensing(gyro_period=0.25, head_period=1.0), TICK_S)


def test_a_sensor_named_as_an_estimator_output_is_refused():
    data = _sensing().model_dump()
    data["sensor"][0]["name"] = "mekf"
    data["estimator"]["gyro"] = "mekf"
    with pytest.raises(ValueError, match="sensor 'mekf': the name is taken"):
        Suite(sensing_from_dict(data), TICK_S)


def test_tick_noise_rows_are_one_whole_draw_however_they_are_asked(suite, monkeypatch):
    """The executors ask :class:`TickNoise` for rows tick by tick, a row's ticks, or many rows'
    at once (run/composed_rows.py, straight into a compiled call's buffer: ``rows_into``), across
    its block boundaries and after a :meth:`restore`: every pattern, the two ways mixed, gives
    the numbers of one whole draw (tick 0 a zero row; a buffer full of NaN is overwritten
    everywhere); the draw places each sensor's samples on its own ticks (gyro every 2nd tick,
    heads every 10th and 20th)."""
    from stationbed.loop import flight

    monkeypatch.setattr(flight, "NOISE_BLOCK", 16)  # small blocks: every path through rows() is taken
    n = 400
    whole = np.vstack([np.zeros((1, suite.NOISE.size)), SuiteNoise(suite, 5).draw(n - 1)])
    tn = flight.TickNoise(SuiteNoise(suite, 5))
    got, k = [], 0

    def into(k, m):
        buf = np.full((m, suite.NOISE.size), np.nan)
        tn.rows_into(k, m, buf)
        return buf

    for j, m in enumerate((5, 3, 16, 12, 36, 7, 100, 1, 1, 30, 60, 129)):  # (the first from tick 0, drawn straight)
        ask = (lambda k, m: tn.rows(k, m).copy()) if j % 3 == 1 else into
        saved = tn.state()
        first = ask(k, m)
        tn.restore(saved)  # put the stream back: the same rows again
        got.append(ask(k, m))
        assert_array_equal(got[-1], first)
        k += m
    assert k == n
    assert_array_equal(np.vstack(got), whole)
    gyro = suite.NOISE.slice("rga")
    assert np.all(whole[1::2, gyro] == 0.0) and np.all(whole[2::2, gyro] != 0.0)
    st2 = suite.NOISE.slice("st2")
    assert np.all(whole[np.arange(n) % 20 != 0][:, st2] == 0.0) and np.all(whole[20::20, st2] != 0.0)
