"""The run metrics (stationbed/run/metrics.py) against values computed by hand on small tables.

Truths:
- a 4-row table whose maxima, minima, RMS and norms are written out below by hand (3-4-5 and
  1-2-2 triangles so the norms are exact integers);
- batch independence: the same rows in one batch or in batches of one give the same values;
- a real closed-loop run's summary equals the metrics recomputed from its own rows by
  :func:`trajectory_metrics` (same reduction over the same rows, so bit for bit).
"""

import math

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose

from stationbed.run.metrics import METRICS, RunMetrics, trajectory_metrics

COLS = ["t", "hx", "hy", "hz", "cmg_singularity", "tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg"]
# t, h (3), singularity, tau (3), err
TABLE = np.array(
    [
        [0.0, 3.0, 4.0, 0.0, 0.9, 1.0, 2.0, 2.0, 2.0],  # |h| 5, |tau| 3
        [10.0, 0.0, 0.0, 12.0, 0.4, 0.0, 0.0, 0.0, np.nan],  # |h| 12, err ignored
        [20.0, 6.0, 8.0, 0.0, 0.7, 2.0, 4.0, 4.0, 1.0],  # |h| 10, |tau| 6
        [30.0, 0.0, 0.0, 1.0, 0.8, 0.0, 3.0, 4.0, 3.0],  # |h| 1, |tau| 5
    ]
)
EXACT_RTOL = 1e-15  # the hand values are exact in binary floating point except sqrt: one rounding


def _metrics(batches, settle_s=None, cap=24.0):
    m = RunMetrics(COLS, settle_s=settle_s, h_capacity_Nms=cap)
    for b in batches:
        m.update(b)
    m.count_ticks(7, 2)
    return m.values()


@pytest.mark.parametrize("split", [1, 2, 4], ids=["one_batch", "two_batches", "row_by_row"])
def test_hand_computed_table(split):
    v = _metrics(np.array_split(TABLE, split))
    assert v["max_att_err_deg"] == 3.0
    assert v["final_att_err_deg"] == 3.0
    assert_allclose(v["rms_att_err_deg"], math.sqrt((4 + 1 + 9) / 3), rtol=EXACT_RTOL)  # NaN row skipped
    assert v["max_h_Nms"] == 12.0
    assert v["max_h_fraction"] == 0.5  # 12 / 24
    assert v["min_singularity"] == 0.4
    assert v["max_torque_cmd_Nm"] == 6.0  # |(2, 4, 4)|
    assert (v["rate_limited_ticks"], v["momentum_saturated_ticks"]) == (7, 2)
    assert set(v) <= set(METRICS)


def test_rms_after_settling_time():
    v = _metrics([TABLE], settle_s=15.0)  # rows at t = 20, 30: errors 1 and 3
    assert_allclose(v["rms_att_err_deg"], math.sqrt((1 + 9) / 2), rtol=EXACT_RTOL)
    assert v["max_att_err_deg"] == 3.0  # the max is over every row, settled or not


def test_absent_columns_give_absent_metrics():
    m = RunMetrics(["t", "att_err_deg"])
    m.update(np.array([[0.0, np.nan], [1.0, np.nan]]))
    assert m.values() == {}  # no reference, no CMG, no torque: nothing made up
    m = RunMetrics(COLS, h_capacity_Nms=math.inf)
    m.update(TABLE)
    assert "max_h_fraction" not in m.values() and m.values()["max_h_Nms"] == 12.0


def test_trajectory_metrics_of_a_dataframe_uses_summary_counts_and_capacity():
    df = pd.DataFrame(TABLE, columns=COLS)
    v = trajectory_metrics(df, {"rate_limited_ticks": 7, "momentum_saturated_ticks": 2, "h_capacity_Nms": 24.0})
    assert v == _metrics([TABLE])


def test_closed_loop_summary_is_the_metrics_of_its_rows():
    from stationbed import load_scene, simulate

    scene = load_scene("scenarios/iss_lvlh_hold.toml").replace({"simulation.duration": 600.0})
    tr = simulate(scene)
    s = tr.meta["summary"]
    v = trajectory_metrics(tr)
    assert {k: s[k] for k in v} == v
    assert {"max_att_err_deg", "rms_att_err_deg", "max_h_fraction", "max_torque_cmd_Nm"} <= set(v)
    df = pd.DataFrame(tr.data, columns=tr.columns)  # what a reader of the CSV gets
    assert trajectory_metrics(df, s) == v


def test_rms_is_bit_identical_however_the_rows_are_batched():
    # the closed loop flushes its rows on a timer as well as by count, so the batches a run's
    # summary sees depend on the machine's load; 1000 errors of mixed magnitude make a batched
    # floating-point sum differ in its last bits between groupings (checked below), the exact
    # accumulation must not
    rng = np.random.default_rng(7)
    err = rng.lognormal(0.0, 3.0, 1000)
    rows = np.full((len(err), len(COLS)), 1.0)
    rows[:, 0] = np.arange(len(err))
    rows[:, -1] = err
    splits = [[rows], np.array_split(rows, 7), np.array_split(rows, 333), list(rows[:, None, :])]
    grouped = {sum(float(np.dot(b[:, -1], b[:, -1])) for b in s) for s in splits}
    assert len(grouped) > 1  # the naive per-batch sum does depend on the grouping
    values = {_metrics(s)["rms_att_err_deg"] for s in splits}
    assert values == {math.sqrt(math.fsum(err * err) / len(err))}


def test_rms_is_bit_identical_when_a_long_run_is_folded(monkeypatch):
    """A long run's squared errors are folded into the exact partials of their sum
    (``_FOLD_AT``): the same correctly rounded total as one ``math.fsum`` over all of them."""
    from stationbed.run import metrics

    monkeypatch.setattr(metrics, "_FOLD_AT", 50)
    rng = np.random.default_rng(11)
    err = rng.lognormal(0.0, 3.0, 1000)
    rows = np.full((len(err), len(COLS)), 1.0)
    rows[:, 0] = np.arange(len(err))
    rows[:, -1] = err
    splits = [[rows], np.array_split(rows, 7), np.array_split(rows, 333)]
    values = {_metrics(s)["rms_att_err_deg"] for s in splits}
    assert values == {math.sqrt(math.fsum(err * err) / len(err))}


def test_estimation_sums_are_bit_identical_however_the_rows_are_batched(monkeypatch):
    # the fused flight loop hands its rows over in bulk, the row-by-row loop in timed batches:
    # rms_est_err_deg and mean_nees are the correctly rounded sums whatever the grouping, also
    # when a long run's values are folded into exact partials (here every 100 rows)
    from stationbed.run import metrics

    cols = ["t", "est_err_x_deg", "est_err_y_deg", "est_err_z_deg", "est_3sigma_x_deg", "est_3sigma_y_deg",
            "est_3sigma_z_deg", "nees"]
    rng = np.random.default_rng(11)
    n = 1000
    rows = np.column_stack([np.arange(n), rng.lognormal(0.0, 3.0, (n, 3)), np.ones((n, 3)), rng.lognormal(0.0, 3.0, n)])
    e2 = np.einsum("ij,ij->i", rows[:, 1:4], rows[:, 1:4])
    want = (math.sqrt(math.fsum(e2) / n), math.fsum(rows[:, -1]) / n)
    splits = [[rows], np.array_split(rows, 7), np.array_split(rows, 333)]
    assert len({sum(float(b[:, -1].sum()) for b in s) for s in splits}) > 1  # naive batched sums differ
    for fold_at in (metrics._FOLD_AT, 100):
        monkeypatch.setattr(metrics, "_FOLD_AT", fold_at)
        for s in splits:
            m = RunMetrics(cols)
            for b in s:
                m.update(b)
            v = m.values()
            assert (v["rms_est_err_deg"], v["mean_nees"]) == want
