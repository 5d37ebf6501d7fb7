"""Sensor noise in the closed loop: the corruption plug-in (stationbed/loop/corruption.py,
issue 20) inlined in the fused tick (stationbed/run/fused.py) and called compiled by the
per-tick loop (inside its composed parts; ``ControlLoop.corrupt`` on its generic path). Truths, independent of the plug-in:

* the corruption: a hand-written numpy corruption (:func:`_numpy_corrupt`, here in the test:
  ``q ⊗ [1, δ/2]`` renormalised, ``ω + δω``) of random measurements and draws;
* the random stream: numpy's own ``rng.normal(0, σ, 3)`` called tick by tick, attitude then
  rate, gives the numbers the executors draw in blocks;
* the trajectory: the per-tick loop on its generic path with the numpy corruption in place of
  the plug-in (and the controller's Python ``update``) flies the same noisy run as the fused loop and the per-tick
  loop with the plug-in;
* the seed: the same seed gives the same run bit for bit, another seed another run.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.loop import Corruption
from stationbed.loop.block import delay_block
from stationbed.run import closed_loop
from stationbed.run.closed_loop import ControlLoop
from stationbed.run.controller import Controller
from stationbed.run.lockstep import run_lockstep
from stationbed.run.measurement import measurement_fields
from stationbed.scene import scene_from_dict

ATT_RAD = 1e-3  # rad, 1 sigma per axis: 10x the Monte Carlo scene's, so the noise shows
RATE_RAD_S = 1e-5  # rad/s, 1 sigma per axis
#: round-off: the same arithmetic compiled as two programs (the fused chunk vs the per-tick calls;
#: common subexpressions and the summation order differ), amplified by the closed loop over 3000
#: ticks; measured 7e-13 of a column's range
PATH_RTOL = 1e-9
#: one corruption, plug-in vs numpy: a few ulps of the unit quaternion's entries (the division by
#: the norm and its square root each round once; numpy's norm sums in another order)
ONE_ATOL = 1e-15


def _numpy_corrupt(y, nz, att, rate, layout):
    """The independent reference: ``q ⊗ [1, δ/2]`` renormalised (δ the attitude draws), then
    ``ω + δω`` (the rate draws), written in numpy from the quaternion product."""
    y = np.array(y, dtype=float)
    i = 0
    if att:
        q = y[layout.slice("q_BN")]
        dq = np.concatenate([[1.0], 0.5 * nz[i : i + 3]])
        w0, v0, w1, v1 = q[0], q[1:], dq[0], dq[1:]
        qn = np.concatenate([[w0 * w1 - v0 @ v1], w0 * v1 + w1 * v0 + np.cross(v0, v1)])
        y[layout.slice("q_BN")] = qn / np.linalg.norm(qn)
        i += 3
    if rate:
        y[layout.slice("omega_BN_B")] += nz[i : i + 3]
    return y


@pytest.mark.parametrize("att,rate", [(ATT_RAD, RATE_RAD_S), (ATT_RAD, 0.0), (0.0, RATE_RAD_S)])
def test_plugin_corrupts_as_the_quaternion_product(att, rate):
    """The plug-in compiled (the per-tick loop's call) on random measurements and draws equals the
    numpy reference to round-off; the fields it does not corrupt pass bit for bit."""
    layout = measurement_fields(4, 2)
    c = Corruption(att, rate, layout)
    fc = c.compiled()
    rng = np.random.default_rng(5)
    for _ in range(50):
        y = rng.normal(size=layout.size)
        q = rng.normal(size=4)
        y[layout.slice("q_BN")] = q / np.linalg.norm(q)
        nz = c.noise(rng).rows(0, 1)[0]
        fc.args[0][:], fc.args[1][:] = y, nz
        fc()
        ref = _numpy_corrupt(y, nz, att, rate, layout)
        np.testing.assert_allclose(fc.res[0], ref, rtol=0, atol=ONE_ATOL)
        touched = np.zeros(layout.size, dtype=bool)
        for f, on in (("q_BN", att), ("omega_BN_B", rate)):
            touched[layout.slice(f)] = on > 0
        assert np.array_equal(fc.res[0][~touched], y[~touched])
        assert np.all(fc.res[0][touched] != y[touched])


@pytest.mark.parametrize("end", [None, 1000], ids=["open", "run_end"])
@pytest.mark.parametrize("att,rate", [(ATT_RAD, RATE_RAD_S), (ATT_RAD, 0.0), (0.0, RATE_RAD_S)])
def test_block_draws_equal_the_per_tick_calls(att, rate, end, monkeypatch):
    """The corruption's stream (``Corruption.noise``: rows of a block of ticks, as the suite's;
    its last block cut at the run's end or not) asked in blocks of uneven sizes (as the rows cut
    a run) gives, bit for bit, the numbers of ``rng.normal(0, σ_att, 3)`` then
    ``rng.normal(0, σ_rate, 3)`` called once per tick from tick 0; after a ``restore`` the same
    again."""
    from stationbed.loop import flight

    monkeypatch.setattr(flight, "NOISE_BLOCK", 64)  # small blocks: the stream draws again inside the run
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
    stream = Corruption(att, rate, measurement_fields(0, 0)).noise(np.random.default_rng(seed), end)
    sizes = [1, 100, 37, 100, 1, 761]  # sums to 1000
    starts = np.cumsum([0] + sizes[:-1])
    blocks = []
    for k0, n in zip(starts, sizes):
        if k0 == 238:  # put back before a block, asked again: the same numbers
            st = stream.state()
            stream.rows(k0, n)
            stream.restore(st)
        blocks.append(stream.rows(k0, n))
    assert np.array_equal(np.vstack(blocks), np.array(per_tick))


def _reference_sense(self, k, t, y):
    """``ControlLoop._after_sense`` (the generic path's sense blocks: here the noise block alone)
    with the numpy reference in place of the plug-in (no delay, no sensors), its draws
    ``rng.normal`` per tick from its own generator of the run's seed."""
    comp = self.comp
    s = comp.sensor
    if k == 0:
        self.reference_rng = np.random.default_rng(s.seed)
    rng = self.reference_rng
    att, rate = s.attitude_noise > 0, s.rate_noise > 0
    nz = np.concatenate([rng.normal(0.0, s.attitude_noise, 3) if att else [],
                         rng.normal(0.0, s.rate_noise, 3) if rate else []])
    self.seen[:] = _numpy_corrupt(y, nz, att, rate, comp.meas_layout)


def _iss(sensor, duration, monkeypatch):
    # every stage: the per-tick loop's (the default rate's own test: tests/test_effect_rates.py)
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace(
        {"controller.sensor": sensor, "simulation.environment_rate": 0})
    kw = dict(duration=duration, output_dt=1.0)
    runs = simulate(scene, **kw), simulate(scene, fused=False, **kw)
    with monkeypatch.context() as m:  # the generic path, its sensing in Python, tick by tick
        m.setattr(ControlLoop, "_after_sense", _reference_sense)
        m.setattr(closed_loop, "parts_ok", lambda comp: "the reference flies the generic path")
        return runs + (simulate(scene, fused=False, **kw),)


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
def test_noisy_fused_loop_flies_the_per_tick_run(sensor, duration, monkeypatch):
    """The PD LVLH hold of iss_lvlh_hold (DGCMGs, SR steering, tracking arrays, aero) with
    sensor noise: the fused loop is taken, and it and the per-tick loop (both with the plug-in)
    agree in every column to round-off with the per-tick loop whose corruption is the numpy
    reference; the summary counts are equal."""
    fused, per_tick, reference = _iss(sensor, duration, monkeypatch)
    assert fused.meta["summary"]["fused"] is True and per_tick.meta["summary"]["fused"] is False
    for run in (fused, per_tick):
        assert run.columns == reference.columns and np.array_equal(run.t, reference.t)
        rel = _rel(run, reference)
        worst = run.columns[int(np.argmax(rel.max(axis=0)))]
        assert rel.max() <= PATH_RTOL, f"column {worst} differs by {rel.max():.2e} of its range"
        for key in ("ticks", "controller_updates", "rate_limited_ticks", "momentum_saturated_ticks"):
            assert run.meta["summary"][key] == reference.meta["summary"][key], key


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


@pytest.mark.parametrize("delay", [1, 3])
def test_delay_block_passes_on_the_measurement_of_delay_ticks_before(delay):
    """The delay block (loop/block.py ``delay_block``), stepped tick by tick from a zero memory as
    the executors start it, on its step (the per-tick parts) and on its plain step where it
    says it may (the fused loop's plain ticks): at tick k the measurement of tick ``k - delay``,
    tick 0's before that (a hand-written index), bit for bit (a -0.0 keeps its sign)."""
    n, ny = 12, 5
    ys = np.random.default_rng(4).normal(size=(n, ny))
    ys[0, 1] = ys[5, 2] = -0.0
    b = delay_block(delay, ny)
    expect = ys[[max(k - delay, 0) for k in range(n)]]
    for plain in (False, True):
        x, seen = np.zeros(b.state.size), []
        for k in range(n):
            f = b.plain if plain and b.is_plain(float(k)) else b.step
            x, out = (np.asarray(v, dtype=float).ravel() for v in f(k, 0.1 * k, 0.1, x, ys[k], [], []))
            seen.append(out)
        assert np.array(seen).tobytes() == expect.tobytes(), f"plain={plain}"


W_B = measurement_fields(0, 0).slice("omega_BN_B")
ECHO_GAIN = 2.0  # N m per rad/s: the command echoes what the law sees


class EchoRate(Controller):
    """``τ = -ECHO_GAIN ω_seen``: the logged command shows, exactly, the rate the law was given."""

    name = "echo_rate"
    command = "torque"

    def symbolic_params(self):
        return []

    def symbolic(self, t, y, cp):
        import casadi as ca

        return -ECHO_GAIN * y[W_B], ca.DM([1.0, 0.0, 0.0, 0.0])


DELAY_TICKS = 3


def _echo_tumbler(seed: int):
    """The tumbler (an ideal torquer: the command acts as given) flown by :class:`EchoRate` with a
    delay of :data:`DELAY_TICKS` and rate noise, a row per tick."""
    return scene_from_dict({
        "name": "tumbler",
        "simulation": {"duration": 3.0, "integrator": "rk4", "step": 0.1, "output_dt": 0.1},
        "initial": {"omega_BN_B": [0.3, -0.2, 0.4]},
        "body": {"mass": 100.0, "inertia": [[100.0, 5.0, -3.0], [5.0, 200.0, 2.0], [-3.0, 2.0, 250.0]]},
        "controller": {"name": "test_fused_noise:EchoRate", "period": 0.1,
                       "sensor": {"rate_noise": RATE_RAD_S, "delay": DELAY_TICKS * 0.1, "seed": seed}},
    })


@pytest.mark.parametrize("executor", ["fused", "per_tick", "lockstep"])
def test_delayed_noisy_rate_is_the_rate_of_delay_ticks_before_plus_the_ticks_draw(executor):
    """With a delay and rate noise, at tick k the law sees ``ω(k - d) + z_k`` (``ω(0)`` before
    tick d; ``z_k`` = ``rng.normal(0, σ, 3)`` of tick k from the run's seed, drawn here): the
    logged command is ``-ECHO_GAIN`` times that, bit for bit, against the logged true rate. The
    delay flies fused (it was the per-tick loop's ring buffer), and in the lockstep batch."""
    seeds = (5, 6)
    if executor == "lockstep":
        runs = run_lockstep([_echo_tumbler(s) for s in seeds], keep=True, fused=False)
        assert [k for k, _ in runs] == ["batch", "batch"]
        runs = [tr for _, tr in runs]
    else:
        runs = [simulate(_echo_tumbler(s), fused=executor == "fused") for s in seeds]
    for seed, tr in zip(seeds, runs):
        assert tr.meta["summary"]["fused"] is (executor == "fused"), tr.meta["summary"].get("not_fused")
        assert tr.meta["summary"]["controller_updates"] == len(tr.t)
        w, cmd = tr.cols("wx", "wy", "wz"), tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")
        rng = np.random.default_rng(seed)
        z = np.array([rng.normal(0.0, RATE_RAD_S, 3) for _ in range(len(w))])
        seen = w[[max(k - DELAY_TICKS, 0) for k in range(len(w))]] + z
        assert np.array_equal(cmd, -ECHO_GAIN * seen)


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
