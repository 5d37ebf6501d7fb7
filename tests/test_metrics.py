"""The run metrics (stationbed/run/metrics.py) against values computed by hand on small tables.

Truths:
- a 4-row table whose maxima, minima, RMS and norms are written out below by hand (3-4-5 and
  1-2-2 triangles so the norms are exact integers); time means by the trapezoid rule written out
  by hand on an uneven grid (issue 32: a mean over time, not over rows);
- the estimation window and convergence time on a table whose error falls below a tenth of the
  first row's 3σ at a known row;
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
    # time mean by the trapezoid rule: only the interval 20..30 has a value at both ends (the
    # NaN row at t = 10 leaves 0..10 and 10..20 out): (1 + 9) / 2 over 10 s
    assert_allclose(v["rms_att_err_deg"], math.sqrt((1 + 9) / 2), rtol=EXACT_RTOL)
    assert v["max_h_Nms"] == 12.0
    assert v["max_h_fraction"] == 0.5  # 12 / 24
    assert v["min_singularity"] == 0.4
    assert v["max_torque_cmd_Nm"] == 6.0  # |(2, 4, 4)|
    assert (v["rate_limited_ticks"], v["momentum_saturated_ticks"]) == (7, 2)
    assert set(v) <= set(METRICS)


def test_rms_after_settling_time():
    v = _metrics([TABLE], settle_s=25.0)  # the row at t = 30 alone: a window of no length, its value
    assert_allclose(v["rms_att_err_deg"], 3.0, rtol=EXACT_RTOL)
    assert v["max_att_err_deg"] == 3.0  # the max is over every row, settled or not


@pytest.mark.parametrize("split", [1, 3], ids=["one_batch", "row_by_row"])
def test_rms_is_a_time_mean_on_an_uneven_grid(split):
    """err 1, 1, 3 deg at t = 0, 1, 10 s: ∫ err² dt = (1 + 1) / 2 * 1 + (1 + 9) / 2 * 9 = 46 deg² s
    over 10 s (a mean over the rows would be 11 / 3: the last row held for 9 s counts 9 times)."""
    rows = np.array([[0.0, 1.0], [1.0, 1.0], [10.0, 3.0]])
    m = RunMetrics(["t", "att_err_deg"])
    for b in np.array_split(rows, split):
        m.update(b)
    assert_allclose(m.values()["rms_att_err_deg"], math.sqrt(4.6), rtol=EXACT_RTOL)


EST_COLS = ["t", "est_err_x_deg", "est_err_y_deg", "est_err_z_deg", "est_3sigma_x_deg", "est_3sigma_y_deg",
            "est_3sigma_z_deg", "nees", "st_valid_st1", "st_valid_st2"]


def _est_table():
    """t = 0, 2, 3, 4, 8 s. 3σ (0.3, 0.4, 1.2) at t = 0: |3σ| 1.3, the threshold 0.13 deg. |err|
    0.6 (above), 0.2 (above), 0.1, 0.05, 0.12 (at or below): converged at t = 3 s. Head st1 invalid
    at t = 0 and 4, st2 at t = 0."""
    err = [[0.0, 0.6, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.1], [0.03, 0.04, 0.0], [0.0, 0.0, 0.12]]
    s3 = [[0.3, 0.4, 1.2], [0.05, 0.05, 0.05], [0.05, 0.05, 0.05], [0.05, 0.05, 0.05], [0.05, 0.05, 0.2]]
    nees = [9.0, 7.0, 6.0, 2.0, 4.0]
    valid = [[0, 0], [1, 1], [1, 1], [0, 1], [1, 1]]
    t = [0.0, 2.0, 3.0, 4.0, 8.0]
    return np.column_stack([t, err, s3, nees, valid]).astype(float)


@pytest.mark.parametrize("split", [1, 2, 5], ids=["one_batch", "two_batches", "row_by_row"])
def test_estimation_window_and_convergence_time(split):
    m = RunMetrics(EST_COLS)
    for b in np.array_split(_est_table(), split):
        m.update(b)
    v = m.values()
    assert v["est_converged_s"] == 3.0
    assert v["max_est_err_deg"] == 0.12  # over t >= 3 s: not the initial 0.6
    # over 3..8 s: |err|² 0.01, 0.0025, 0.0144 at t = 3, 4, 8 -> (0.0125 / 2) * 1 + (0.0169 / 2) * 4
    assert_allclose(v["rms_est_err_deg"], math.sqrt((0.0125 / 2 + 0.0169 * 2) / 5), rtol=1e-14)
    assert_allclose(v["mean_nees"], ((6 + 2) / 2 + (2 + 4) / 2 * 4) / 5, rtol=1e-14)
    # axes inside 3σ: 2/3 (z 0.1 > 0.05), 3/3, 3/3 at t = 3, 4, 8
    assert_allclose(v["est_inside_3sigma"], ((2 / 3 + 1) / 2 + 1 * 4) / 5, rtol=1e-14)
    # dropouts 0, 0, 0, 1, 0 at t = 0, 2, 3, 4, 8 (both heads invalid at t = 0 before their first
    # sample: not a dropout, loop.flight.st_dropouts; st1 invalid at 4 s after it): 1 / 2 * 1 + 1 / 2 * 4 [s]
    assert v["st_dropout_s"] == 2.5


def test_estimation_window_with_a_settling_time_and_a_filter_that_never_converges():
    tab = _est_table()
    v = trajectory_metrics(pd.DataFrame(tab, columns=EST_COLS), settle_s=4.0)
    assert v["est_converged_s"] == 3.0 and v["max_est_err_deg"] == 0.12  # t >= max(4, 3)
    assert_allclose(v["mean_nees"], 3.0, rtol=1e-14)  # (2 + 4) / 2 over 4..8
    tab[-1, 1:4] = [0.0, 0.0, 0.5]  # above the threshold at the last row: not converged
    v = trajectory_metrics(pd.DataFrame(tab, columns=EST_COLS), settle_s=4.0)
    assert v["est_converged_s"] == math.inf
    assert v["max_est_err_deg"] == 0.5  # the window is t >= settle_s alone


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
    assert values == {_trapezoid_rms(err)}


def _trapezoid_rms(err):
    """The RMS of ``err`` at t = 0, 1, 2, ... s by the trapezoid rule, its terms summed exactly."""
    e2 = err * err
    return math.sqrt(math.fsum(0.5 * (e2[:-1] + e2[1:])) / (len(err) - 1))


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
    assert values == {_trapezoid_rms(err)}


def test_estimation_sums_are_bit_identical_however_the_rows_are_batched(monkeypatch):
    # the fused flight loop hands its rows over in bulk, the row-by-row loop in timed batches:
    # rms_est_err_deg and mean_nees are the correctly rounded sums whatever the grouping, also
    # when a long run's values are folded into exact partials (here every 100 rows)
    from stationbed.run import metrics

    cols = ["t", "est_err_x_deg", "est_err_y_deg", "est_err_z_deg", "est_3sigma_x_deg", "est_3sigma_y_deg",
            "est_3sigma_z_deg", "nees"]
    rng = np.random.default_rng(11)
    n = 1000
    # a 3σ of 1e9 deg: every row converged (the window is the whole run)
    rows = np.column_stack([np.arange(n), rng.lognormal(0.0, 3.0, (n, 3)), np.full((n, 3), 1e9), rng.lognormal(0.0, 3.0, n)])
    e2 = np.einsum("ij,ij->i", rows[:, 1:4], rows[:, 1:4])
    nees = rows[:, -1]
    want = (math.sqrt(math.fsum(0.5 * (e2[:-1] + e2[1:])) / (n - 1)),
            math.fsum(0.5 * (nees[:-1] + nees[1:])) / (n - 1))
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
