"""Sensor noise in the fused closed loop (stationbed/run/fused.py, issue 13).

The fused loop draws each tick's sensor noise in numpy before a compiled call and corrupts the
measurement inside the compiled tick; the per-tick loop (``ControlLoop._corrupt``) draws and
corrupts in Python, tick by tick. Truths, independent of the fused code:

* the random stream: numpy's own ``rng.normal(0, σ, 3)`` called tick by tick, attitude then
  rate, exactly as the per-tick loop calls it, gives the numbers the fused loop draws in blocks;
* the trajectory: the per-tick loop (``simulate(..., fused=False)``: the controller's Python
  ``update`` and the noise applied in numpy) flies the same noisy run as the fused loop;
* the seed: the same seed gives the same run bit for bit, another seed another run.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.run.fused import _draw
from stationbed.scene import scene_from_dict

ATT_RAD = 1e-3  # rad, 1 sigma per axis: 10x the Monte Carlo scene's, so the noise shows
RATE_RAD_S = 1e-5  # rad/s, 1 sigma per axis
#: round-off: the same arithmetic compiled as two programs (the fused chunk vs the per-tick calls
#: with the noise applied in numpy; common subexpressions and the quaternion norm's summation
#: order differ), amplified by the closed loop over 3000 ticks; measured 7e-13 of a column's range
PATH_RTOL = 1e-9


class _Loop:
    """What :func:`_draw` reads of a ControlLoop: the sensor table and the generator."""

    def __init__(self, att, rate, seed):
        self.sensor = type("S", (), {"attitude_noise": att, "rate_noise": rate})()
        self.rng = np.random.default_rng(seed)


@pytest.mark.parametrize("att,rate", [(ATT_RAD, RATE_RAD_S), (ATT_RAD, 0.0), (0.0, RATE_RAD_S)])
def test_block_draws_equal_the_per_tick_calls(att, rate):
    """Blocks of uneven sizes (as the rows cut a run) give, bit for bit, the numbers of
    ``rng.normal(0, σ_att, 3)`` then ``rng.normal(0, σ_rate, 3)`` called once per tick."""
    n_ticks, seed = 1000, 42
    ref = np.random.default_rng(seed)
    per_tick = []
    for _ in range(n_ticks):
        row = []
        if att > 0:
            row += list(ref.normal(0.0, att, 3))
        if rate > 0:
            row += list(ref.normal(0.0, rate, 3))
        per_tick.append(row)
    loop = _Loop(att, rate, seed)
    flags = (att > 0, rate > 0)
    sizes = [1, 100, 37, 100, 1, 761]  # sums to 1000
    blocks = np.vstack([_draw(loop, k, flags) for k in sizes])
    assert np.array_equal(blocks, np.array(per_tick))


def _iss(sensor, duration):
    # every stage: the per-tick loop's (the default rate's own test: tests/test_effect_rates.py)
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace(
        {"controller.sensor": sensor, "simulation.environment_rate": 0})
    kw = dict(duration=duration, output_dt=1.0)
    return simulate(scene, **kw), simulate(scene, fused=False, **kw)


def _rel(a, b):
    scale = np.maximum(np.nanmax(np.abs(a.data), axis=0), 1e-300)
    assert np.array_equal(np.isnan(a.data), np.isnan(b.data))
    return np.nan_to_num(np.abs(a.data - b.data), nan=0.0) / scale


@pytest.mark.parametrize(
    "sensor,duration",
    [
        ({"attitude_noise": ATT_RAD, "rate_noise": RATE_RAD_S, "seed": 11}, 300.0),
        ({"attitude_noise": ATT_RAD, "seed": 2}, 30.05),  # a short last period: a one-tick call
        ({"rate_noise": RATE_RAD_S, "seed": 2}, 30.0),
    ],
    ids=["both_300s", "attitude_short_last", "rate"],
)
def test_noisy_fused_loop_flies_the_per_tick_run(sensor, duration):
    """The PD LVLH hold of iss_lvlh_hold (DGCMGs, SR steering, tracking arrays, aero) with
    sensor noise: the fused loop is taken and every column agrees with the per-tick loop to
    round-off; the summary counts are equal."""
    fused, per_tick = _iss(sensor, duration)
    assert fused.meta["summary"]["fused"] is True and per_tick.meta["summary"]["fused"] is False
    assert fused.columns == per_tick.columns and np.array_equal(fused.t, per_tick.t)
    rel = _rel(fused, per_tick)
    worst = fused.columns[int(np.argmax(rel.max(axis=0)))]
    assert rel.max() <= PATH_RTOL, f"column {worst} differs by {rel.max():.2e} of its range"
    for key in ("ticks", "controller_updates", "rate_limited_ticks", "momentum_saturated_ticks"):
        assert fused.meta["summary"][key] == per_tick.meta["summary"][key], key


def test_noisy_fused_run_is_seeded_and_the_noise_shows():
    """Same seed: the same fused run bit for bit; another seed, or no noise: a run that differs
    by far more than round-off (the commanded torque follows the noisy measurement)."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    sensor = {"attitude_noise": ATT_RAD, "rate_noise": RATE_RAD_S}
    runs = [simulate(scene.replace({"controller.sensor": dict(sensor, seed=s)}), duration=20.0) for s in (5, 5, 6)]
    clean = simulate(scene, duration=20.0)
    assert all(r.meta["summary"]["fused"] for r in runs + [clean])
    assert np.array_equal(runs[0].data, runs[1].data, equal_nan=True)
    assert _rel(runs[0], runs[2]).max() > 1e3 * PATH_RTOL
    assert _rel(runs[0], clean).max() > 1e3 * PATH_RTOL


def test_delay_keeps_the_per_tick_loop():
    """A sensor delay is not fused (its history of measurements is kept in Python): the run
    falls back to the per-tick loop, with the same numbers as forcing it."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace(
        {"controller.sensor": {"attitude_noise": ATT_RAD, "delay": 0.3, "seed": 1}}
    )
    a, b = simulate(scene, duration=5.0), simulate(scene, duration=5.0, fused=False)
    assert a.meta["summary"]["fused"] is False
    assert np.array_equal(a.data, b.data, equal_nan=True)


def test_noisy_fused_loop_without_a_cluster():
    """An ideal torquer (no [cmg]: the command acts directly) on a fast small spacecraft, where
    the noisy measurement drives large commands: fused and per-tick agree to round-off."""
    d = {
        "name": "tumbler",
        "simulation": {"duration": 5.0, "integrator": "rk4", "step": 0.1, "output_dt": 0.1},
        "initial": {"omega_BN_B": [0.3, -0.2, 0.4]},
        "body": {"mass": 100.0, "inertia": [[100.0, 5.0, -3.0], [5.0, 200.0, 2.0], [-3.0, 2.0, 250.0]]},
        "controller": {"name": "pd", "period": 0.1,
                       "params": {"reference": "inertial", "bandwidth": 0.5, "damping": 0.7, "max_slew_rate": 1.0},
                       "sensor": {"attitude_noise": ATT_RAD, "rate_noise": RATE_RAD_S, "seed": 7}},
    }
    scene = scene_from_dict(d)
    fused, per_tick = simulate(scene), simulate(scene, fused=False)
    assert fused.meta["summary"]["fused"] is True and per_tick.meta["summary"]["fused"] is False
    assert _rel(fused, per_tick).max() <= PATH_RTOL
