"""Python per Monte Carlo sample (issue 25, item 4): the controllers' entry points, read from every
installed distribution's metadata (~4 ms), are scanned once per ``sys.path``, not once per sample.

Truth: the number of metadata scans counted at ``importlib.metadata.entry_points`` itself.
And the knowledge scene of a sample (a validated deep copy) is built once per sample, not at each
of the three places that ask for it: counted at ``knowledge_changes``, with the memo and without.
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

from stationbed.run import controller as ctl


def _counting(monkeypatch):
    calls = []
    real = importlib.metadata.entry_points

    def counted(**kw):
        calls.append(kw)
        return real(**kw)

    monkeypatch.setattr(importlib.metadata, "entry_points", counted)
    ctl._ENTRY_POINTS.clear()
    return calls


def test_entry_points_scanned_once_for_many_samples(monkeypatch):
    calls = _counting(monkeypatch)
    classes = {ctl.get_controller("pd") for _ in range(20)}
    assert len(calls) == 1 and len(classes) == 1


def test_a_new_path_is_scanned_again(monkeypatch, tmp_path):
    """A folder put on ``sys.path`` may bring a package with its own laws: scanned anew."""
    calls = _counting(monkeypatch)
    ctl.get_controller("pd")
    monkeypatch.syspath_prepend(str(tmp_path))
    ctl.get_controller("pd")
    assert len(calls) == 2


# ---------------------------------------------------------------------------------------------
# the knowledge scene (what flight software believes) is built once per sample scene
# ---------------------------------------------------------------------------------------------
MC_SCENE = Path(__file__).resolve().parents[1] / "scenarios" / "iss_lvlh_hold_montecarlo.toml"


def test_knowledge_scene_built_once_per_monte_carlo_sample(monkeypatch):
    """A sample asks three times (its draw's record of what the law was told, the controller's
    plant, the scene's own check): one validated deep copy, not three (~1-2 ms each)."""
    from stationbed import load_scene
    from stationbed.scene import knowledge as kn
    from stationbed.studies.montecarlo.engine import envelope_times, study_scene
    from stationbed.studies.montecarlo.samples import run_sample

    from stationbed.run.rate_auto import scene_choice

    scene = study_scene(load_scene(MC_SCENE).replace({"simulation.duration": 2.0, "montecarlo.settle_s": 1.0}), 10)
    scene_choice(scene)  # the study's one environment-rate probe (run/rate_auto.py), before counting
    builds = []
    real_changes = kn.knowledge_changes
    monkeypatch.setattr(kn, "knowledge_changes", lambda s: builds.append(1) or real_changes(s))
    monkeypatch.setattr(kn, "_KNOWN", {})
    for k in range(3):
        run_sample(scene, k, envelope_times(scene))
    n_asked = len(builds)
    monkeypatch.setattr(kn, "_KNOWN", type("Miss", (dict,), {"get": lambda self, key, d=None: None})())
    builds.clear()
    for k in range(3):
        run_sample(scene, k, envelope_times(scene))
    asked = len(builds)
    assert (n_asked, asked) == (3, 9)  # one build per sample; three when every call builds anew


def test_an_equal_scene_gets_its_own_knowledge_scene():
    """The answer is kept per scene object: an equal but other scene (a later replace) is asked anew."""
    from stationbed import load_scene
    from stationbed.scene.knowledge import knowledge_scene

    a = load_scene(MC_SCENE)
    b = a.replace({})
    assert knowledge_scene(a) is knowledge_scene(a) and knowledge_scene(b) is not knowledge_scene(a)


def test_knowledge_scene_built_once_per_sample_of_a_chunk(monkeypatch):
    """A chunk draws all its samples before it runs the first (run_batch): each sample's
    knowledge scene is still built once (the memo keeps it while the sample scene lives; it
    once held the last 8 scenes only, and a chunk of more samples built each one twice)."""
    from stationbed import load_scene
    from stationbed.scene import knowledge as kn
    from stationbed.studies.montecarlo.engine import envelope_times, study_scene
    from stationbed.studies.montecarlo.samples import run_chunk
    from stationbed.run.rate_auto import scene_choice

    n = 12
    scene = study_scene(load_scene(MC_SCENE).replace({"simulation.duration": 2.0, "montecarlo.settle_s": 1.0}), n)
    scene_choice(scene)
    builds = []
    real_changes = kn.knowledge_changes
    monkeypatch.setattr(kn, "knowledge_changes", lambda s: builds.append(1) or real_changes(s))
    res = run_chunk(scene, 0, n, envelope_times(scene))
    assert [r["status"] for r in res["rows"]] == ["ok"] * n
    assert len(builds) == n


def test_knowledge_memo_lets_go_of_a_scene():
    """An entry leaves the memo with its scene (no limit, so none may outlive it)."""
    import gc

    from stationbed import load_scene
    from stationbed.scene import knowledge as kn

    a = load_scene(MC_SCENE).replace({})
    kn.knowledge_scene(a)
    key = id(a)
    assert kn._KNOWN[key][0]() is a
    del a
    gc.collect()
    assert key not in kn._KNOWN


def test_samples_run_one_after_another_take_over_the_buffers_with_their_own_numbers(monkeypatch):
    """A sample run on its own (fused) hands its compiled-call buffers to the next sample of the
    chunk instead of each making its own (~0.6 ms): no buffers are made after the first sample,
    and each sample's rows and summary are its single run's (``simulate``), bit for bit, in
    either order (nothing of one sample's run stays in the next one's)."""
    import numpy as np

    from stationbed import load_scene, simulate
    from stationbed.core.compile import FastCall
    from stationbed.run.lockstep import run_lockstep
    from stationbed.run.rate_auto import scene_choice
    from stationbed.studies.montecarlo.engine import study_scene
    from stationbed.studies.montecarlo.replay import sample_scene

    scene = study_scene(load_scene(MC_SCENE).replace({"simulation.duration": 2.0, "montecarlo.settle_s": 1.0}), 10)
    scene_choice(scene)
    samples = [sample_scene(scene, k) for k in range(3)]
    run_lockstep(samples[:1])  # the process's own shared calls made
    made = []
    real = FastCall.__init__
    monkeypatch.setattr(FastCall, "__init__", lambda self, f: made.append(f) or real(self, f))
    run_lockstep(samples[:1])
    one = len(made)
    made.clear()
    forward = run_lockstep(samples, keep=True)
    assert one > 0 and len(made) == one
    backward = run_lockstep(samples[::-1], keep=True)[::-1]
    for s, (kind, a), (_, b) in zip(samples, forward, backward):
        single = simulate(s)
        assert kind == "fused"
        for tr in (a, b):
            assert np.array_equal(tr.data, single.data, equal_nan=True)
            assert tr.meta["summary"] == single.meta["summary"]
