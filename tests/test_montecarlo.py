"""The Monte Carlo study (stationbed/studies/montecarlo/) without Dask: dispersions, replay,
refused draws, failures, resume, statistics and recording.

Truths:
- the drawn values are applied: the run's own first row (attitude, rate, angular momentum
  H_N = C_NB I ω of a rigid body) equals what the recorded draw implies, computed here with
  scipy's Rotation, independently of the library's quaternion code;
- ``--sample K`` (the scene file written for sample K, loaded back and run alone) gives the
  metrics of row K bit for bit;
- the binomial verdict against hand-computed cases: 0 failures need p**n <= 1 - c (n = 852 for
  0.9973 / 0.9, 22 for 0.9 / 0.9), 1 failure needs p**n + n (1-p) p**(n-1) <= 1 - c, and the
  Clopper-Pearson lower bound with 0 failures is (1 - c)**(1/n);
- refused draws: every accepted inertia is positive definite and meets the triangle inequality
  (checked here with numpy's eigvalsh), and a sample out of redraws is a row with its reason;
- a failing sample (a torque of 1e300 N m) is a row with status failed and the others run;
- resume: a deleted chunk is run again and the table is identical.
"""

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
from numpy.testing import assert_allclose
from rerun import chunk as rerun_chunk
from scipy.spatial.transform import Rotation

from scenes import RIGID
from stationbed import load_scene, montecarlo, simulate
from stationbed.run.metrics import METRICS
from stationbed.scene import SceneError, scene_from_dict
from stationbed.studies.montecarlo import stats
from stationbed.studies.montecarlo.replay import sample_scene
from stationbed.studies.montecarlo.report import ENVELOPE_PERCENTILES, recorded_percentiles

MC_SCENE = "scenarios/iss_lvlh_hold_montecarlo.toml"
#: the H of the first row is computed by the compiled model from q, ω and I: a few roundings
H_RTOL = 1e-12
#: the first row's attitude is the drawn one up to the normalisation of the row
Q_ATOL = 1e-14


def short_study(**changes):
    """The scenario cut to 60 s (600 ticks of the 10 Hz loop), envelopes every 20 s."""
    base = {"simulation.duration": 60.0, "montecarlo.envelope_dt": 20.0, "montecarlo.settle_s": 20.0}
    return load_scene(MC_SCENE).replace({**base, **changes})


def rigid_study(disperse, n=4, max_redraws=100):
    data = {**RIGID, "simulation": {**RIGID["simulation"], "duration": 2.0}}
    data["initial"] = {"q_BN": [0.9, 0.3, -0.2, 0.2478], "omega_BN_B": [0.01, -0.02, 0.015]}
    data["montecarlo"] = {"n": n, "seed": 7, "max_redraws": max_redraws, "envelope_dt": None, "disperse": disperse}
    q = np.array(data["initial"]["q_BN"])
    data["initial"]["q_BN"] = (q / np.linalg.norm(q)).tolist()
    return scene_from_dict(data)


RIGID_DISPERSE = [
    {"key": "body.inertia", "kind": "inertia", "sigma": 0.05, "sigma_products": 0.02},
    {"key": "initial.q_BN", "kind": "attitude_normal", "sigma": 0.2},
    {"key": "initial.omega_BN_B", "kind": "normal", "sigma": 0.005},
]


@pytest.fixture(scope="module")
def rigid():
    scene = rigid_study(RIGID_DISPERSE)
    return scene, montecarlo(scene)


@pytest.mark.parametrize("k", [0, 3])
def test_dispersions_are_applied_to_the_physics(rigid, k):
    scene, res = rigid
    row = res.df.iloc[k]
    tr = simulate(sample_scene(scene, k))
    I = np.zeros((3, 3))
    for i in range(3):
        for j in range(i, 3):
            I[i, j] = I[j, i] = row[f"body.inertia[{i}][{j}]"]
    w = np.array([row[f"initial.omega_BN_B[{i}]"] for i in range(3)])
    rv = np.array([row[f"initial.q_BN.rotvec[{i}]"] for i in range(3)])
    q0 = np.array(scene.initial.q_BN)  # scalar first
    # q ⊗ dq: the draw turns the body about its own axis rv (scipy: xyzw, a * b applies b first)
    r = Rotation.from_quat(np.roll(q0, -1)) * Rotation.from_rotvec(rv)
    q_expect = np.roll(r.as_quat(canonical=False), 1)
    q_run = tr.q_BN[0]
    assert_allclose(q_run * np.sign(q_run[0] * q_expect[0]), q_expect, atol=Q_ATOL)
    assert_allclose(tr.omega_BN_B[0], w, rtol=1e-15, atol=0)
    C_NB = r.as_matrix()  # body to inertial
    assert_allclose(tr.H_O_N[0], C_NB @ I @ w, rtol=H_RTOL)
    nominal = np.array(scene.body.inertia)
    assert np.abs(I - nominal).max() > 1e-3 * nominal.max()  # the draw moved it (5 % sigma)


def test_same_sample_alone_or_in_a_batch(rigid):
    scene, res = rigid
    alone = montecarlo(scene.replace({"montecarlo.n": 4}), chunk=1).df
    pd.testing.assert_frame_equal(alone, res.df)


def test_sample_scene_file_gives_row_k_bit_for_bit(tmp_path):
    from stationbed.cli import main

    scene = short_study(**{"montecarlo.n": 3})
    res = montecarlo(scene, chunk=2)
    assert (res.df["status"] == "ok").all()
    path = tmp_path / "scene.toml"
    text = open(MC_SCENE).read().replace("duration = 5553.6", "duration = 60.0")
    text = text.replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0")
    path.write_text(text.replace("n = 1000", "n = 3"))
    assert main(["montecarlo", str(path), "--sample", "2", "--out", str(tmp_path / "s2"), "-q"]) == 0
    got = json.loads((tmp_path / "s2" / "summary.json").read_text())["metrics"]
    row = res.df.iloc[2]
    assert set(got) >= {"max_att_err_deg", "rms_att_err_deg", "max_h_fraction", "max_torque_cmd_Nm"}
    for name, v in got.items():
        assert v == row[name], name  # bit for bit (JSON keeps a double's repr exactly)


@pytest.mark.parametrize("known", [False, True], ids=["unknown_to_the_law", "known"])
def test_a_failed_cmg_unit_is_recorded_as_the_units_flown(known, tmp_path):
    """Issue 32: ``cmg.failed`` was recorded as the float index of the choice (``cmg.failed.choice``
    = 2.0); the row must name the units, as the scene does: the truth is the ``[cmg] failed`` of
    the sample's own scene (``sample_scene``), and what the law was told that of its knowledge."""
    choice = {"key": "cmg.failed", "kind": "choice", "choices": [[], [1], [2], [3], [4]], "known": known}
    scene = short_study(**{"simulation.duration": 1.0, "montecarlo.envelope_dt": None, "montecarlo.settle_s": None,
                           "montecarlo.disperse": [choice], "montecarlo.n": 6})
    res = montecarlo(scene, out=tmp_path, charts=False)
    df = pd.read_parquet(tmp_path / "samples.parquet")
    assert "cmg.failed.choice" not in df
    flown = [sample_scene(scene, k).cmg.failed for k in range(6)]
    assert [json.loads(v) for v in df["cmg.failed"]] == flown
    assert len({tuple(f) for f in flown}) > 1  # the draws differ
    assert [json.loads(v) for v in df["told.cmg.failed"]] == (flown if known else [[]] * 6)
    pd.testing.assert_frame_equal(df, res.df)


def test_refused_draws_are_redrawn_and_counted():
    wide = [{"key": "body.inertia", "kind": "inertia", "sigma": 0.6, "sigma_products": 0.3}]
    res = montecarlo(rigid_study(wide, n=12))
    df = res.df
    assert df["redraws"].sum() > 0 and (df["status"] == "ok").all()
    for _, row in df.iterrows():
        I = np.array([[row[f"body.inertia[{min(i, j)}][{max(i, j)}]"] for j in range(3)] for i in range(3)])
        ev = np.linalg.eigvalsh(I)
        assert ev.min() > 0 and 2 * ev.max() <= ev.sum() * (1 + 1e-12)  # triangle inequality
    assert res.summary["counts"]["redraws"] == int(df["redraws"].sum())


def test_a_sample_out_of_redraws_is_refused_with_its_reason():
    wide = [{"key": "body.inertia", "kind": "inertia", "sigma": 0.8, "sigma_products": 0.5}]
    df = montecarlo(rigid_study(wide, n=12, max_redraws=0)).df
    refused = df[df["status"] == "refused"]
    assert 0 < len(refused) < len(df)
    assert refused["reason"].str.contains("inertia").all()
    told = [c for c in df if c.startswith("told.")]  # what the law was told: nothing, it never flew
    assert told and refused[told].isna().all().all()


def test_a_failing_sample_is_recorded_and_the_study_goes_on():
    # an air density 1e300 times the table's: the drag torque overflows the state (non-finite)
    changes = {"montecarlo.disperse": [{"key": "atmosphere.density_scale", "kind": "choice",
                                        "choices": [1.0, 1e300], "weights": [0.6, 0.4]}],
               "montecarlo.n": 6}
    df = montecarlo(short_study(**changes), chunk=2).df
    bad = df["atmosphere.density_scale"] > 1.0
    assert bad.any() and (~bad).any()
    assert (df.loc[bad, "status"] == "failed").all() and (df.loc[~bad, "status"] == "ok").all()
    assert df.loc[bad, "reason"].str.contains("finite").all()


def test_resume_runs_only_missing_chunks_and_gives_the_same_table(tmp_path):
    scene = short_study(**{"montecarlo.n": 4})
    first = montecarlo(scene, out=tmp_path, chunk=2, charts=False)
    chunks = sorted((tmp_path / "chunks").glob("chunk_*.parquet"))
    assert len(chunks) == 2
    kept = chunks[0].stat().st_mtime_ns
    chunks[1].unlink()
    again = montecarlo(scene, out=tmp_path, chunk=2, resume=True, charts=False)
    assert chunks[0].stat().st_mtime_ns == kept and chunks[1].exists()
    pd.testing.assert_frame_equal(again.df, first.df)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "samples.parquet"), first.df)
    with pytest.raises(SceneError, match="another study"):
        montecarlo(scene.replace({"montecarlo.seed": 1}), out=tmp_path, chunk=2, resume=True, charts=False)


def test_recording_holds_the_envelope_percentiles(tmp_path):
    scene = short_study(**{"montecarlo.n": 3})
    res = montecarlo(scene, out=tmp_path, chunk=3)
    got = {}
    for c in rerun_chunk.RrdReader(tmp_path / "montecarlo.rrd").stream().to_chunks():
        if c.is_static or c.entity_path.lstrip("/") != "montecarlo/envelope/att_err_deg":
            continue
        rb = c.to_record_batch()
        name = next(n for n in rb.schema.names if n.endswith(":scalars"))
        arr = rb.column(name).flatten()
        while pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
            arr = arr.flatten()
        got["t"] = rb.column("sim_time").cast(pa.int64()).to_numpy() * 1e-9
        got["v"] = np.asarray(arr.to_numpy(zero_copy_only=False)).reshape(rb.num_rows, -1)
    y = res.envelope[:, :, 0]
    shown = [p for p in ENVELOPE_PERCENTILES if p in (50.0, 100.0)]  # 3 samples: p90 needs 10, p99.73 371
    assert recorded_percentiles(3) == shown
    expect = np.stack([np.nanpercentile(y, p, axis=0) for p in shown], axis=1)
    assert_allclose(got["t"], res.envelope_t, atol=1e-9)
    assert_allclose(got["v"], expect, rtol=0, atol=0)
    assert np.all(np.nanmax(y, axis=0) == expect[:, -1])  # p100 is the worst sample per time
    for f in ("envelope_att_err.png", "envelope_h.png", "hist_max_att_err_deg.png", "summary.json"):
        assert (tmp_path / f).stat().st_size > 0


# -- statistics -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "p, c, n_zero",
    [(0.9973, 0.9, 852), (0.9, 0.9, 22), (0.99, 0.95, 299)],
    ids=["3sigma_90", "p90_c90", "p99_c95"],
)
def test_samples_needed_for_zero_failures(p, c, n_zero):
    # by hand: p**n <= 1 - c first at n_zero (0.9**22 = 0.0985, 0.9**21 = 0.109; 0.99**299 = 0.0495)
    assert p**n_zero <= 1 - c < p ** (n_zero - 1)
    assert stats.n_needed(p, c) == n_zero
    assert stats.verdict(n_zero, 0, p, c) and not stats.verdict(n_zero - 1, 0, p, c)


def test_one_failure_verdict_by_hand():
    p, c = 0.9, 0.9
    cdf = lambda n: p**n + n * (1 - p) * p ** (n - 1)  # noqa: E731  P(X <= 1), X ~ B(n, 1 - p)
    n1 = next(n for n in range(2, 200) if cdf(n) <= 1 - c)  # 38 (cdf 0.0988; 37: 0.1087)
    assert n1 == 38
    assert stats.n_needed(p, c, failures=1) == n1
    assert stats.verdict(n1, 1, p, c) and not stats.verdict(n1 - 1, 1, p, c)
    assert not stats.verdict(1000, 200, p, c)  # 20 % failures cannot show 90 % coverage


def test_clopper_pearson_bound_with_zero_failures():
    for n in (10, 852):
        assert_allclose(stats.success_lower_bound(n, 0, 0.9), 0.1 ** (1 / n), rtol=1e-12)


def test_requirement_counts_failed_runs_as_failures():
    from stationbed.scene import Requirement

    df = pd.DataFrame({"index": [0, 1, 2, 3], "status": ["ok", "ok", "failed", "ok"],
                       "max_att_err_deg": [0.5, 1.5, np.nan, 0.9]})
    (v,) = stats.requirement_verdicts(df, [Requirement(metric="max_att_err_deg", max=1.0)])
    assert (v["failures"], v["not_run"], v["n"], v["pass"]) == (2, 1, 4, False)
    s = stats.metric_stats(df, ["max_att_err_deg"])["max_att_err_deg"]
    assert (s["count"], s["max"], s["max_index"], s["min_index"]) == (3, 1.5, 1, 0)
    assert_allclose(s["std"], np.std([0.5, 1.5, 0.9], ddof=1), rtol=1e-15)


#: coverage 95 %, confidence 95 %: 0 failures need n >= ln(0.05) / ln(0.95) = 58.4, so 59
#: (0.95**59 = 0.0485 <= 0.05; 0.95**58 = 0.0510 is not); with 200 samples one failure is shown
#: too: 0.95**200 + 200 * 0.05 * 0.95**199 = 4.0e-4 <= 0.05
@pytest.mark.parametrize(
    "n, failed, word",
    [(20, 0, "NOT SHOWN"), (58, 0, "NOT SHOWN"), (59, 0, "PASS"), (200, 1, "PASS"), (20, 1, "FAIL"), (59, 1, "FAIL")],
    ids=["20_none_failed", "58_none_failed", "59_none_failed", "200_one_failed", "20_one_failed", "59_one_failed"])
def test_a_requirement_is_fail_only_when_a_sample_failed_it(n, failed, word):
    from stationbed.scene import Requirement

    err = np.full(n, 0.5)  # deg
    err[:failed] = 2.0  # deg, above the 1-deg limit
    df = pd.DataFrame({"index": np.arange(n), "status": ["ok"] * n, "max_att_err_deg": err})
    (v,) = stats.requirement_verdicts(df, [Requirement(metric="max_att_err_deg", max=1.0, coverage=0.95,
                                                       confidence=0.95)])
    assert (v["verdict"], v["pass"], v["failures"]) == (word, word == "PASS", failed)
    if word == "NOT SHOWN":
        assert v["note"] == f"0 of {n} failed; needs >= 59 samples for 95 % confidence that at most 5 % fail"


# -- scene errors ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "changes, message",
    [
        ({"montecarlo.disperse": [{"key": "body.inertia", "kind": "inertia", "sigam": 0.1}]}, "did you mean 'sigma'"),
        ({"montecarlo.disperse": [{"key": "body.inertya", "kind": "normal", "sigma": 0.1}]},
         r"montecarlo.disperse\[0\].key: 'body.inertya'"),
        ({"montecarlo.disperse": [{"key": "body.mass", "kind": "normal"}]}, "needs 'sigma'"),
        ({"montecarlo.requirement": [{"metric": "max_att_err", "max": 1.0}]}, "did you mean 'max_att_err_deg'"),
        ({"cmg.failed": [5]}, "cmg.failed: must be distinct unit numbers 1..4"),
    ],
    ids=["typo_key", "unknown_path", "missing_sigma", "unknown_metric", "failed_unit_out_of_range"],
)
def test_bad_montecarlo_tables_are_one_line_errors(changes, message):
    with pytest.raises(SceneError, match=message):
        montecarlo(load_scene(MC_SCENE).replace(changes), n=1)


@pytest.mark.parametrize(
    "metric, needs",
    [("propellant_kg_per_orbit", r"\[\[thruster\]\] tables and an \[orbit\]"),
     ("max_est_err_deg", r"an \[estimator\]")],
    ids=["propellant_without_thrusters", "estimation_without_estimator"])
def test_a_requirement_on_a_metric_the_scene_cannot_report_is_refused_before_any_sample(metric, needs):
    """Issue 32: such a requirement was judged, every sample NaN, so FAIL; now a one-line error
    naming the requirement (exit 2, nothing run)."""
    reqs = [*load_scene(MC_SCENE).model_dump()["montecarlo"]["requirement"], {"metric": metric, "max": 1.0}]
    scene = load_scene(MC_SCENE).replace({"montecarlo.requirement": reqs})
    with pytest.raises(SceneError, match=rf"^montecarlo.requirement\[2\].metric: '{metric}' is not reported by a run "
                                         rf"of scene 'iss_lvlh_hold_montecarlo': it needs {needs}"):
        montecarlo(scene, n=1)


def test_the_table_has_the_metric_columns_a_run_of_the_scene_reports():
    """The truth: the summary of sample 0 run alone (``simulate``) reports exactly the metric
    columns of the table (before: every METRICS name, est_* and thruster ones all NaN here)."""
    scene = short_study(**{"simulation.duration": 20.0, "montecarlo.envelope_dt": None, "montecarlo.settle_s": None})
    df = montecarlo(scene, n=1).df
    reported = [m for m in METRICS if m in simulate(sample_scene(scene, 0), keep=False).meta["summary"]]
    assert [c for c in df.columns if c in METRICS] == reported
    assert not df[reported].isna().any().any()
    assert "max_est_err_deg" not in df and "propellant_kg" not in df


def test_typo_in_the_montecarlo_table_names_the_nearest_key():
    with pytest.raises(SceneError, match="montecarlo.sed: unknown key; did you mean 'seed'"):
        load_scene(MC_SCENE).replace({"montecarlo.sed": 3})


def test_sample_scene_keeps_a_relative_controller_file_reachable(tmp_path):
    from stationbed.studies.montecarlo.replay import write_sample_scene

    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "hold.py").write_text(open("controllers/example_hold.py").read())
    text = open(MC_SCENE).read().replace('name = "pd"', 'name = "laws/hold.py:ExampleHold"')
    text = text.replace("bandwidth = 0.005           # rad/s\ndamping = 0.8\nmax_slew_rate = 0.001       # rad/s\n",
                        "kp = 4.0e-5\n")
    text = text.replace('key = "controller.params.bandwidth"', 'key = "controller.params.kp"')
    (tmp_path / "scene.toml").write_text(text)
    scene = load_scene(tmp_path / "scene.toml")
    back = write_sample_scene(scene, 0, tmp_path / "elsewhere" / "s0.toml")
    module, _, cls = back.controller.name.rpartition(":")
    assert cls == "ExampleHold" and module == str((tmp_path / "laws" / "hold.py").resolve())
    tr = simulate(back.replace({"simulation.duration": 1.0}), keep=False)  # the file is found and runs
    assert tr.meta["summary"]["controller"] == "example_hold"
