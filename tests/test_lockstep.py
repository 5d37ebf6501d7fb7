"""The lockstep batch executor (stationbed/run/lockstep.py, issue 22) and the batch law interface
(``Controller.update_batch``).

Truth, independent of the batch code: each sample's single run, ``simulate(scene_k,
fused=False)`` (the per-tick loop, the law's ``_update``, or its compiled ``symbolic`` form,
called on each tick). The batch runs the same compiled tick (casadi's map calls the very machine
code once per sample), the sensor of each sample from its own generator, and laws whose
``update_batch`` does ``_update``'s operations element by element (or the law's compiled form
mapped: pd, lqr, momentum_manager): each sample's rows equal its single run's bit for bit
(``np.array_equal``), its summary (ticks, updates, saturation counts, metrics) too. Where a law's
vectorised form cannot promise that, the bound and its reason are stated next to the test.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.controllers.pd import PD
from stationbed.run.controller import Controller
from stationbed.run.lockstep import _Lockstep, _Sample, executor, run_lockstep, vectorised
from stationbed.run.simulation import SimulationError
from stationbed.scene import scene_from_dict

DURATION_S = 5.0  # s: 50 ticks of 10 Hz, 6 rows (enough for every path, a few seconds per law)
NOISE = {"attitude_noise": 1e-3, "rate_noise": 1e-5}  # rad, rad/s: 10x the Monte Carlo scene's, so it shows
N_SAMPLES = 3


def _samples(params: dict, name: str, sensor: dict | None = None, **extra) -> list:
    """Three samples of iss_lvlh_hold (DGCMGs, SR steering, tracking arrays, aero, SRP) that
    differ as Monte Carlo samples do: inertia, initial attitude, rate and sensor seed."""
    base = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    inertia = np.array(base.body.inertia)
    out = []
    for k in range(N_SAMPLES):
        ch = {"simulation.duration": DURATION_S, "simulation.output_dt": 1.0, "controller.name": name,
              "controller.params": params, "body.inertia": (inertia * (1.0 + 0.03 * k)).tolist(),
              "initial.omega_BN_B": [1e-5 * k, -2e-5, 1e-5], **extra}
        if sensor is not None:
            ch["controller.sensor"] = {**sensor, "seed": 100 + k}
        out.append(base.replace(ch))
    return out


def _same(batch, single):
    assert not isinstance(batch, BaseException), batch
    assert batch.columns == single.columns
    assert np.array_equal(batch.data, single.data, equal_nan=True), \
        f"max diff {np.nanmax(np.abs(batch.data - single.data)):.3g}"
    a, b = batch.meta["summary"], single.meta["summary"]
    assert {k: v for k, v in a.items()} == {k: v for k, v in b.items()}


LAWS = [
    ("pd", {"reference": "lvlh", "bandwidth": 0.01}),
    ("lqr", {}),
    ("momentum_manager", {}),
    ("example_hold", {"reference": "lvlh"}),
    ("torque_command", {"torque_B": [5.0, -3.0, 1.0], "start": 1.0, "stop": 3.05}),
]


@pytest.mark.parametrize("name,params", LAWS, ids=[n for n, _ in LAWS])
def test_batch_row_k_is_the_single_run_k_bit_for_bit(name, params):
    """Every shipped law (vectorised update_batch or compiled form), with sensor noise: batch row k == single run
    k, bit for bit, summary included; the executor says ``batch``."""
    scenes = _samples(params, name, NOISE)
    res = run_lockstep(scenes, keep=True, fused=False)
    for s, (kind, tr) in zip(scenes, res):
        assert kind == "batch"
        _same(tr, simulate(s, fused=False))


def test_samples_with_different_corruptions_are_their_single_runs():
    """Samples that corrupt different fields (both, attitude only, rate only, a delay alone, a
    delay and noise, none), two of each, mixed: the ideal measurement's delay and noise are
    blocks of the mapped parts, so each kind is a batch of its own (its structure), and row k is
    single run k bit for bit."""
    base = _samples({"reference": "lvlh", "bandwidth": 0.01}, "pd")[0]
    sensors = [dict(NOISE), {"attitude_noise": 1e-3}, {"rate_noise": 1e-5}, {"delay": 0.2}, {**NOISE, "delay": 0.3}, {}]
    scenes = [base.replace({"controller.sensor": {**x, "seed": 3 + k}}) for k, x in enumerate(sensors + sensors)]
    res = run_lockstep(scenes, keep=True, fused=False)
    for s, (kind, tr) in zip(scenes, res):
        assert kind == "batch"
        _same(tr, simulate(s, fused=False))


def test_the_default_update_batch_loops_and_gives_the_same_numbers():
    """A law without update_batch (a subclass of example_hold that only has _update): the base
    class's default calls each sample's update; same numbers, delay and noise included."""
    scenes = _samples({"reference": "lvlh"}, "example_hold", {**NOISE, "delay": 0.3})

    class OnlyUpdate(type(_law(scenes[0]))):
        update_batch = Controller.update_batch

    assert not vectorised(OnlyUpdate())
    res = _run_with(scenes, OnlyUpdate)
    for s, tr in zip(scenes, res):
        _same(tr, simulate(s, fused=False, controller=OnlyUpdate(period=0.1, reference="lvlh")))


def _law(scene):
    from stationbed.run.laws import build_controller  # noqa: PLC0415

    return build_controller(scene.controller)


def _run_with(scenes, cls):
    """The lockstep batch itself on ``scenes`` with the law replaced by ``cls`` (a module-less
    class: patched into the registry's lookup), whichever executor :func:`executor` would choose
    for it (a law without a vectorised update_batch is sent per tick: the batch's own paths are
    tested here)."""
    import stationbed.run.closed_loop as cl  # noqa: PLC0415

    orig = cl.build_controller
    cl.build_controller = lambda spec, base_dir=None: cls(period=spec.period, **spec.params)
    try:
        samples = [_Sample(s, None, True, False) for s in scenes]
    finally:
        cl.build_controller = orig
    return _Lockstep(samples).run(SimulationError)


class FailsOne(Controller):
    """A PD-like law whose sample with gain ``bad`` returns NaN from t = 1.5 s (or raises)."""

    name = "fails_one"
    from stationbed.run.controller import ControllerParams as _P

    class Params(_P):
        k: float = 1.0e3
        bad: float = -1.0
        how: str = "nan"

    def _update(self, t, meas):
        if self.params.k == self.params.bad and t >= 1.5:
            if self.params.how == "raise":
                raise RuntimeError("gain went bad")
            return (float("nan"), 0.0, 0.0)
        return tuple(-self.params.k * w for w in meas.omega_BN_B.tolist())


@pytest.mark.parametrize("how", ["nan", "raise"])
def test_a_failing_sample_fails_alone_with_its_single_runs_reason(how):
    """One sample's law returns NaN (or raises) at 1.5 s: that sample fails with the reason and
    time of its single run (same partial rows); the other samples finish, bit for bit."""
    scenes = [s.replace({"controller.params": {"k": 1e3 * (k + 1), "bad": 2e3, "how": how}})
              for k, s in enumerate(_samples({}, "pd"))]
    res = _run_with(scenes, FailsOne)
    for k, (s, tr) in enumerate(zip(scenes, res)):
        law = FailsOne(period=0.1, k=1e3 * (k + 1), bad=2e3, how=how)
        if k == 1:
            with pytest.raises(SimulationError) as err:
                simulate(s, fused=False, controller=law)
            assert isinstance(tr, SimulationError)
            assert (tr.t, tr.reason) == (err.value.t, err.value.reason)
            assert np.array_equal(tr.trajectory.data, err.value.trajectory.data, equal_nan=True)
        else:
            _same(tr, simulate(s, fused=False, controller=law))


def test_executor_choice_by_capability():
    """pd with its symbolic form: fused (where the fused loop applies); a law without one but
    with a vectorised update_batch: batch; the same law with the default (looping) update_batch:
    per-tick; a non-fusable integrator: per-tick. run_lockstep says which ran each sample."""
    pd_scenes = _samples({"reference": "lvlh"}, "pd")
    res = run_lockstep(pd_scenes[:2], keep=True)
    assert [k for k, _ in res] == ["fused", "fused"]
    for s, (_, tr) in zip(pd_scenes, res):  # the sample's own loop, fused, as simulate runs it
        _same(tr, simulate(s))
    eh = _samples({"reference": "lvlh"}, "example_hold")
    assert [k for k, _ in run_lockstep(eh[:2])] == ["batch", "batch"]
    import stationbed.run.closed_loop as cl  # noqa: PLC0415

    class OnlyUpdate(type(_law(eh[0]))):  # the same law without its vectorised update_batch
        update_batch = Controller.update_batch

    orig = cl.build_controller
    cl.build_controller = lambda spec, base_dir=None: OnlyUpdate(period=spec.period, **spec.params)
    try:  # per tick: the default update_batch loops each member's update, the law's Python per sample either way
        res = run_lockstep(eh[:2], keep=True)
    finally:
        cl.build_controller = orig
    assert [k for k, _ in res] == ["per-tick", "per-tick"]
    for s, (_, tr) in zip(eh, res):
        _same(tr, simulate(s, fused=False, controller=OnlyUpdate(period=0.1, reference="lvlh")))
    dop = [s.replace({"simulation.integrator": "dop853", "simulation.step": None}) for s in eh[:2]]
    kinds = [k for k, _ in run_lockstep(dop)]
    assert kinds == ["per-tick", "per-tick"]


def test_window_edges_on_and_off_the_tick_grid_stay_in_the_batch():
    """Torque windows with edges on (1.0 s) and off (2.05 s) the tick grid, different per
    sample: a sample with an edge between ticks stays in the batch (that tick the edge tick's
    case, its act part mapped for the samples in one), its rows its single run's, bit for bit.
    Edges on the grid, different per sample, stay in the batch too (each sample its own pieces)."""
    base = _samples({"reference": "lvlh"}, "example_hold")
    kinds = [t.model_dump(exclude_unset=True) for t in base[0].torque]
    scenes = [s.replace({"torque": kinds + [{"kind": "constant", "torque_B": [20.0, -5.0, 3.0], "start": 1.0 + 0.05 * k,
                                     "stop": 2.05 + 0.1 * k}]}) for k, s in enumerate(base)]
    res = run_lockstep(scenes, keep=True, fused=False)
    for s, (kind, tr) in zip(scenes, res):
        assert kind == "batch"
        _same(tr, simulate(s, fused=False))
    on_grid = [s.replace({"torque": kinds + [{"kind": "constant", "torque_B": [20.0, -5.0, 3.0], "start": 1.0 + 0.5 * k,
                                              "stop": 2.5 + 0.5 * k}]}) for k, s in enumerate(base)]
    for s, (kind, tr) in zip(on_grid, run_lockstep(on_grid, keep=True, fused=False)):
        assert kind == "batch"
        _same(tr, simulate(s, fused=False))


def test_the_monte_carlo_runs_a_python_law_in_lockstep_with_the_single_runs_numbers():
    """The Monte Carlo scene (every dispersion, sensor noise, a failed CMG unit now and then)
    with example_hold: the chunk runs in lockstep (executor column "batch", counted in the
    summary), and every row equals run_sample's (its single run through simulate)."""
    from stationbed import montecarlo  # noqa: PLC0415
    from stationbed.studies.montecarlo.samples import run_sample  # noqa: PLC0415

    s = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml")
    disperse = [d.model_dump(exclude_unset=True) for d in s.montecarlo.disperse
                if not d.key.startswith("controller.params")]
    s = s.replace({"simulation.duration": 3.0, "montecarlo.settle_s": 1.0, "montecarlo.envelope_dt": 1.0,
                   "simulation.output_dt": 1.0, "controller.name": "example_hold",
                   "controller.params": {"reference": "lvlh"}, "montecarlo.disperse": disperse})
    res = montecarlo(s, n=4, chunk=4)
    assert (res.df["executor"] == "batch").all() and res.summary["executors"] == {"batch": 4}
    for k in range(4):
        row, env = run_sample(s.replace({"montecarlo.n": 4}), k, len(res.envelope_t))
        got = res.df.iloc[k]
        for name in res.df.columns:  # the table's columns: those the scene reports (samples.scene_metrics)
            if name == "executor":
                continue
            v = row[name]
            assert got[name] == v or (isinstance(v, float) and np.isnan(v) and np.isnan(got[name])), name
        assert np.array_equal(res.envelope[k], env, equal_nan=True)


def test_the_readmes_update_batch_gives_the_guides_numbers(tmp_path):
    """The README's update_batch, added to the guide's LvlhHold as printed: two samples in
    lockstep equal their single runs (through the guide's _update) bit for bit."""
    import re  # noqa: PLC0415

    from test_readme_guide import guide_blocks  # noqa: PLC0415

    section = (ROOT / "docs" / "controllers" / "batch.md").read_text()  # the README's section, now a page
    method = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    py, _ = guide_blocks()
    law = tmp_path / "lvlh_hold.py"
    law.write_text(py + "\n" + method)
    scenes = [s.replace({"controller.name": f"{law}:LvlhHold", "controller.params": {"kd": 0.012 + 0.001 * k}})
              for k, s in enumerate(_samples({}, "pd", NOISE)[:2])]
    res = run_lockstep(scenes, keep=True, fused=False)
    assert [k for k, _ in res] == ["batch", "batch"]
    for s, (_, tr) in zip(scenes, res):
        _same(tr, simulate(s, fused=False))


def test_a_loop_with_sensors_runs_in_lockstep_bit_for_bit():
    """A scene that flies [[sensor]] tables and an [estimator] (issue 20's gyro, star trackers,
    MEKF; each sample its own seed, so its own noise): a Python law runs batch, its flight tick
    mapped over the samples (inside the composed parts, run/parts.py), each sample's rows (the estimation columns
    included) and summary its single per-tick run's, bit for bit; a law with a symbolic form
    runs fused (the flight inlined), as its single run."""
    base = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace(
        {"simulation.duration": 5.0, "simulation.output_dt": 1.0})
    for name, params, kind in (("example_hold", {"reference": "lvlh"}, "batch"),
                               ("pd", {"reference": "lvlh"}, "fused")):
        scenes = [base.replace({"controller.name": name, "controller.params": params,
                                "controller.sensor": {"seed": 7 + k}}) for k in range(N_SAMPLES)]
        res = run_lockstep(scenes, keep=True)
        assert [k for k, _ in res] == [kind] * N_SAMPLES
        for s, (_, tr) in zip(scenes, res):
            _same(tr, simulate(s, fused=kind == "fused"))
        if kind == "batch":  # the estimate flown, each sample with its own noise
            j = res[0][1].columns.index("est_err_x_deg")
            errs = [r.data[1:, j] for _, r in res]
            assert np.isfinite(errs[0]).all() and not np.array_equal(errs[0], errs[1])


def test_sensors_without_an_estimator_and_the_ideal_sensors_noise_as_single_runs():
    """[[sensor]] tables without an [estimator] (the truth-fed run: the sensors flown and recorded)
    and the [controller.sensor] noise on the law's ideal path: the per-tick loop flies the sensors,
    then corrupts what the law sees; in lockstep each sample is its single run, bit for bit (a
    batch that flew the sensors and dropped the noise would give the law the truth)."""
    base = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace(
        {"simulation.duration": DURATION_S, "simulation.output_dt": 1.0, "estimator": None,
         "controller.name": "example_hold", "controller.params": {"reference": "lvlh"}})
    scenes = [base.replace({"controller.sensor": {**NOISE, "delay": 0.2, "seed": 7 + k}}) for k in range(N_SAMPLES)]
    assert scenes[0].estimator is None and scenes[0].sensor
    res = run_lockstep(scenes, keep=True)
    assert [k for k, _ in res] == ["batch"] * N_SAMPLES
    for s, (_, tr) in zip(scenes, res):
        _same(tr, simulate(s, fused=False))


class RefTransposed(PD):
    """pd whose update_batch sets q_ref_BN transposed, (4, n) (a user's slip)."""

    def update_batch(self, t, meas):
        out = super().update_batch(t, meas)
        self.q_ref_BN = np.zeros((4, self.n_samples))
        return out


def test_a_batch_reference_of_the_wrong_shape_is_reported_with_its_shape():
    """update_batch setting q_ref_BN (4, 3) instead of (3, 4) (issue 32): every sample fails at the
    first tick with the shape set and the shape expected, not a sample's row's."""
    scenes = _samples({"reference": "lvlh", "bandwidth": 0.01}, "pd")
    res = _run_with(scenes, RefTransposed)
    for tr in res:
        assert isinstance(tr, SimulationError) and tr.t == 0.0
        assert "update_batch set q_ref_BN to an array of shape (4, 3), expected (3, 4)" in tr.reason, tr.reason
