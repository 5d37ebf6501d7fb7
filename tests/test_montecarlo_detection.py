"""Fault detection statistics of a Monte Carlo study (issue 34 item 4,
stationbed/studies/montecarlo/detection.py).

Truths (none from the module's code):
* the binomial intervals against scipy's ``binomtest`` (exact Clopper-Pearson, Wilson; the
  one-sided upper bound) and the order-statistic interval of a median against the textbook
  ranks (n = 100: x(40), x(61) at 95 %; n = 6: the extremes, 1 - 2/2^6 = 0.969; n = 5: none,
  1 - 2/2^5 = 0.9375 < 0.95);
* a small study of scenarios/iss_cmg_failure_fdir_montecarlo.toml (40 s, the fault at 10-20 s
  with probability 0.5): the per-sample columns against each sample's drawn truth (read from the
  table's drawn columns, the declaration from the run's metrics), and the summary's counts
  against the columns counted here.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binomtest

from stationbed import montecarlo
from stationbed.scene import scene_from_dict
from stationbed.studies.montecarlo.detection import (binomial_upper, clopper_pearson, quantile_interval,
                                                     wilson)
from stationbed.studies.montecarlo.report import table_text

SCENE = Path(__file__).resolve().parents[1] / "scenarios" / "iss_cmg_failure_fdir_montecarlo.toml"
#: scipy's and ours both come from beta / normal quantiles: agreement to round-off
INTERVAL_REL = 1e-9
#: the CMG detector's persistence latency in the scene: (N - 1) ticks of 0.1 s (docs/faults.md)
LATENCY_S = 1.9
#: round-off of a time difference at ~20 s
TIME_ABS = 1e-9


@pytest.mark.parametrize("k,n", [(0, 10), (3, 10), (10, 10), (48, 50), (156, 156), (7, 200)])
def test_binomial_intervals_against_scipy(k, n):
    ref = binomtest(k, n)
    for ours, method in ((clopper_pearson(k, n), "exact"), (wilson(k, n), "wilson")):
        ci = ref.proportion_ci(confidence_level=0.95, method=method)
        assert ours == pytest.approx((ci.low, ci.high), rel=INTERVAL_REL, abs=1e-15), method
    up = binomtest(k, n, alternative="less").proportion_ci(confidence_level=0.95, method="exact").high
    assert binomial_upper(k, n) == pytest.approx(up, rel=INTERVAL_REL)


def test_upper_bound_with_no_alarm_is_one_minus_alpha_to_the_one_over_n():
    assert binomial_upper(0, 44) == pytest.approx(1.0 - 0.05 ** (1.0 / 44), rel=INTERVAL_REL)


def test_order_statistic_interval_of_the_median():
    x = np.arange(1.0, 101.0)[::-1]  # x(i) = i, given unsorted
    assert quantile_interval(x, 50.0) == (40.0, 61.0)
    assert quantile_interval(np.arange(1.0, 7.0), 50.0) == (1.0, 6.0)
    assert quantile_interval(np.arange(1.0, 6.0), 50.0) is None


def test_small_study_columns_and_counts_match_each_samples_truth():
    d = tomllib.loads(SCENE.read_text())
    d["simulation"]["duration"] = 40.0
    d["fault"][0].update(t=15.0, probability=0.5)
    d["montecarlo"].update(n=6, settle_s=0.0, envelope_dt=None)
    d["montecarlo"]["disperse"][0].update(low=-5.0, high=5.0)  # 10-20 s
    scene = scene_from_dict(d)
    res = montecarlo(scene, workers=0, charts=False)
    df = res.df
    assert (df["status"] == "ok").all()
    occ = df["fault.cmg2.occurred"].to_numpy() > 0.5
    assert occ.any() and not occ.all(), "seed 34 draws both kinds of sample"
    for i, r in df.iterrows():
        if occ[i]:
            assert r["detect.fault_occurred"] == 1.0 and r["detect.declared"] == 1.0
            assert r["detect.fault_t_s"] == r["fault.cmg2.t"] and r["detect.fault_unit"] == r["fault.cmg2.unit"]
            assert r["detect.t_s"] == r["fdir_detect_s"] and r["detect.unit"] == r["fdir_unit"]
            assert abs(r["detect.latency_s"] - (r["fdir_detect_s"] - r["fault.cmg2.t"])) <= TIME_ABS
            assert abs(r["detect.latency_s"] - LATENCY_S) <= TIME_ABS
            assert r["detect.unit_right"] == float(r["fdir_unit"] == r["fault.cmg2.unit"]) == 1.0
        else:  # nominal flight: nothing declared, nothing to compare
            assert r["fdir_detect_s"] == -1.0 and r["detect.declared"] == 0.0
            assert math.isnan(r["detect.latency_s"]) and math.isnan(r["detect.unit_right"])
        assert r["detect.false_alarm"] == 0.0
    s = res.summary["fault_detection"]
    k = int(occ.sum())
    assert (s["detection"]["k"], s["detection"]["n"]) == (k, k)
    assert s["detection"]["clopper_pearson"] == pytest.approx(list(clopper_pearson(k, k)))
    assert (s["isolation"]["k"], s["false_alarms"]["k"], s["false_alarms"]["n"]) == (k, 0, len(df) - k)
    assert s["latency_s"]["count"] == k and s["latency_s"]["p50"] == pytest.approx(LATENCY_S)
    assert s["false_alarms"]["consistent"]
    assert [r["n"] for r in s["requirements_faulted"]] == [k] * len(scene.montecarlo.requirement)
    assert "fault detection: declared" in table_text(res.summary)


def test_a_fault_the_sample_did_not_draw_is_no_truth_for_the_run_summary():
    """A sample without its fault (``enabled = false``) that declares one: a false alarm in the
    run's summary too (it was counted against the disabled fault's time before)."""
    from stationbed.run.fdir_run import detections_vs_truth
    from stationbed.scene.faults import Fault

    off = Fault(t=5.0, kind="cmg_failed", unit=2, enabled=False)
    got = detections_vs_truth([off], True, 10.0, 2)
    assert got["fdir_cmg_false_alarm"] and "fdir_cmg_latency_s" not in got and "fault_cmg_t_s" not in got
    on = detections_vs_truth([Fault(t=5.0, kind="cmg_failed", unit=2)], True, 10.0, 2)
    assert not on["fdir_cmg_false_alarm"] and on["fdir_cmg_latency_s"] == 5.0


@pytest.mark.parametrize("upper", [math.nan, None])  # (None: the summary read back from its JSON)
def test_the_text_of_a_study_whose_every_sample_drew_its_fault(upper):
    """No sample without a fault: the false-alarm line says there is nothing to bound (it raised
    TypeError formatting the missing bound before)."""
    from stationbed.studies.montecarlo.detection import detection_text

    rate = {"k": 4, "n": 4, "clopper_pearson": list(clopper_pearson(4, 4))}
    d = {"confidence": 0.95, "detection": rate, "isolation": rate,
         "latency_s": {"count": 4, "max": 1.9, **{f"p{p:g}": None for p in (50, 90, 99)},
                       **{f"p{p:g}_interval": None for p in (50, 90, 99)}},
         "false_alarms": {"k": 0, "n": 0, "rate": None, "upper": upper, "stated_per_run": 1e-6, "run_hours": 1.5,
                          "consistent": True, "early_in_faulted": 0},
         "requirements_faulted": [], "requirements_no_fault": []}
    lines = detection_text(d)
    assert lines[0].startswith("fault detection: declared 4 of 4")
    assert any(ln.startswith("false alarms: no sample without a fault") for ln in lines), lines
