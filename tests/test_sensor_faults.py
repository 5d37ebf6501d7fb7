"""Sensor faults as numbers of the sensors' steps (issue 34 item 1, stationbed/loop/sensor_faults.py).

Truths (none reads the fault code to make its expectation): the same sensor flown healthy on
the same noise and truth, and the fault written by hand on top of it: a bias step adds exactly
its vector from its first sample on; a frozen gyro repeats, sample for sample, the healthy
output of the sample before the window; a dropout reads zero; a silent head has ``valid = 0``
exactly on the samples inside its window. Outside every window the faulted output equals the
healthy one bit for bit (the state the fault does not touch evolves the same).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from stationbed.loop import TRUTH, build_sensors
from stationbed.loop.sensor_faults import apply_sensor_faults
from stationbed.scene import sensing_from_dict

N_SAMPLES = 40
PERIOD_S = 0.5  # s, sample period
RATE_RAD_S = np.array([1e-3, -2e-3, 5e-4])  # rad/s, a constant body rate
#: a bias step is added to a sum of O(1e-3) numbers: its round-off (the step is exact in the
#: difference only to the last bits of the healthy output)
BIAS_ROUNDOFF_RAD_S = 1e-17


def _fault(kind, unit, t, until=None, **params):
    return SimpleNamespace(kind=kind, unit=unit, t=t, until=until, param=lambda k: params[k])


def _sensor(entry):
    return build_sensors(sensing_from_dict({"sensor": [entry]}).sensor)[0]


def _gyro():
    return _sensor(dict(kind="gyro", name="g", period=PERIOD_S, sigma_v=1e-5, sigma_u=1e-7, bias0=[1e-5, 0, -2e-5]))


def _head():
    return _sensor(dict(kind="star_tracker", name="st", period=PERIOD_S, boresight_B=[0, 0, 1], nea_cross=1e-4,
                        nea_about=5e-4))


def _fly(s, faults):
    t = PERIOD_S * np.arange(1, N_SAMPLES + 1)
    truth = np.zeros((N_SAMPLES, TRUTH.size))
    truth[:, TRUTH.slice("q_BN")] = [1.0, 0.0, 0.0, 0.0]
    truth[:, TRUTH.slice("theta_B")] = t[:, None] * RATE_RAD_S
    w = np.random.default_rng(7).standard_normal((N_SAMPLES, s.n_noise))
    p = apply_sensor_faults([s], faults).get(s.name)
    _, y = s.record(t, truth, w, params=p)
    return t, y


def test_gyro_bias_step_adds_its_vector_from_its_first_sample():
    g = _gyro()
    step = np.array([2e-4, 0.0, -1e-4])  # rad/s
    t, healthy = _fly(g, [])
    _, y = _fly(g, [_fault("gyro_bias_step", "g", 5.0, bias_x=step[0], bias_y=step[1], bias_z=step[2])])
    on = t >= 5.0
    assert_array_equal(y[~on], healthy[~on])
    np.testing.assert_allclose(y[on] - healthy[on], np.tile(step, (on.sum(), 1)), rtol=0, atol=BIAS_ROUNDOFF_RAD_S)


@pytest.mark.parametrize("kind", ["gyro_frozen", "gyro_dropout"])
def test_gyro_window_holds_or_zeroes_then_heals(kind):
    g = _gyro()
    t, healthy = _fly(g, [])
    _, y = _fly(g, [_fault(kind, "g", 4.0, until=9.0)])
    inside = (t >= 4.0) & (t < 9.0)
    assert_array_equal(y[~inside], healthy[~inside])
    want = np.tile(healthy[np.flatnonzero(t < 4.0)[-1]], (inside.sum(), 1)) if kind == "gyro_frozen" else 0.0
    assert_array_equal(y[inside], want + 0 * y[inside])


@pytest.mark.parametrize("kind", ["st_blinded", "st_dropout"])
def test_head_is_invalid_exactly_inside_its_window(kind):
    h = _head()
    t, healthy = _fly(h, [])
    _, y = _fly(h, [_fault(kind, "st", 3.0, until=6.0)])
    inside = (t >= 3.0) & (t < 6.0)
    valid = h.outputs.slice("valid")
    assert_array_equal(y[:, valid].ravel(), np.where(inside, 0.0, 1.0))
    assert_array_equal(y[~inside], healthy[~inside])


def test_fault_on_a_sensor_of_the_wrong_kind_is_an_error():
    with pytest.raises(ValueError, match="not a gyro sensor"):
        apply_sensor_faults([_head()], [_fault("gyro_frozen", "st", 1.0)])
