"""Flight software's fault detection and mode manager (issue 34 items 2-3, stationbed/loop/fdir.py).

Truths (none made by the block's own code):

* the false-alarm rate: the block alone on synthetic nominal residuals (N(0, σ² E), written into
  the momentum stream by hand), its alarm onsets counted and held inside the binomial band of
  the stated per-tick probability ``(1 - α) α^N``; the per-tick exceedance inside the band of α
  (the chi-squared normalisation); the stated rate per hour is that probability times the ticks
  per hour;
* the detection latency: a residual ramp ``a (t - t_f)`` whose chi-squared crosses the gate at
  ``t_f + σ sqrt(γ)/a`` (γ from scipy's chi-squared quantile), so the fault is declared N - 1
  ticks after the first tick past that time;
* hand-worked mode sequences (commands, a momentum threshold, a detection), tick by tick;
* knowledge: a fault whose residual stays under the gate is never declared and the steering's
  view (``cmg_excluded``) and the mode stay as they were;
* closed loop (scenarios/iss_cmg_failure_fdir.toml, 120 s): no alarm in nominal flight, and a
  CMG failure at t declared at t + (N - 1) h (the rotor's momentum shows in the first tick),
  the failed unit blamed and taken out of the steering law.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.stats import binom, chi2

from stationbed import simulate
from stationbed.loop.fdir import FdirSpec, false_alarms_per_hour, fdir_block
from stationbed.output.rerun.events import Events
from stationbed.scene import load_scene
from stationbed.scene.fdir import Fdir, ModeCommand

H_S = 0.1  # s, tick
N_UNITS, GPU = 4, 2  # DGCMG cluster
CAPACITY_NMS = 1.0e4  # N m s
#: two-sided miss probability of each binomial band (a correct detector fails one with this chance)
BAND_ALPHA = 1e-3
#: a residual computed from a stream of momenta: round-off of (h_k - h_k-1)/h at |h| ~ 1e2 N m s
RESIDUAL_ROUNDOFF = 1e-9
SCENE = Path(__file__).resolve().parents[1] / "scenarios" / "iss_cmg_failure_fdir.toml"


def _spec(modes=(), **kw):
    return FdirSpec(Fdir(**kw), [ModeCommand(**m) for m in modes], N_UNITS, GPU, CAPACITY_NMS)


def _fly(spec, r_B, gimbal=None, h0_B=(100.0, 0.0, 0.0)):
    """The block alone over len(r_B) ticks whose residual is r_B[k] (rate zero, CMGs asked
    nothing, so r = (h_k - h_k-1)/h: the momentum stream written from it). Its memory after each tick."""
    b = fdir_block(spec)
    n = len(r_B)
    h_B = np.asarray(h0_B) + H_S * np.cumsum(r_B, axis=0)
    g = np.zeros((n, N_UNITS * GPU)) if gimbal is None else gimbal
    U = b.inputs
    u = np.hstack([h_B, np.zeros((n, 3)), g, np.zeros((n, 3))])
    assert u.shape[1] == U.size
    acc = b.step.mapaccum("acc", n, [3], [0])
    k = np.arange(n, dtype=float)
    xs, ys = acc(k, k * H_S, H_S, b.x0, u.T, ca.DM(0, n), np.tile(b.p0, (n, 1)).T)
    return b, np.asarray(xs).T, np.asarray(ys).T


def _band(count, n, p):
    lo, hi = binom.ppf(BAND_ALPHA / 2, n, p), binom.isf(BAND_ALPHA / 2, n, p)
    assert lo <= count <= hi, f"{count} outside [{lo}, {hi}] (n {n}, p {p:.3g})"


@pytest.mark.parametrize("alpha,n_persist", [(0.05, 2), (0.2, 3)], ids=["a0.05_N2", "a0.2_N3"])
def test_false_alarms_within_the_binomial_band_of_the_stated_probability(alpha, n_persist):
    sigma, n = 0.7, 40000
    spec = _spec(cmg_sigma_Nm=sigma, cmg_alpha=alpha, cmg_persistence=n_persist)
    r = np.random.default_rng(3).normal(0.0, sigma, (n, 3))
    r[0] = 0.0  # tick 0 has no previous tick (nothing compared)
    b, xs, _ = _fly(spec, r)
    S = b.state
    nis, count = S.get(xs, "nis").ravel(), S.get(xs, "count").ravel()
    _band(int(np.sum(nis[1:] > chi2.isf(alpha, 3))), n - 1, alpha)
    p_onset = (1 - alpha) * alpha**n_persist
    onsets = int(np.sum(count[n_persist + 1:] == n_persist))  # a run reaching N, preceded by a tick under
    _band(onsets, n - n_persist - 1, p_onset)
    assert false_alarms_per_hour(alpha, n_persist, 3600 / H_S) == pytest.approx(3600 / H_S * p_onset, rel=1e-15)


def test_detection_latency_is_the_analytic_threshold_crossing():
    sigma, alpha, n_persist, a = 0.5, 1e-3, 7, 0.37  # N m, -, ticks, N m/s
    t_f = 2.05  # s, between ticks
    n = 200
    t = np.arange(n) * H_S
    r = np.zeros((n, 3))
    r[:, 1] = np.where(t > t_f, a * (t - t_f), 0.0)
    b, xs, _ = _fly(_spec(cmg_sigma_Nm=sigma, cmg_alpha=alpha, cmg_persistence=n_persist), r)
    t_cross = t_f + sigma * np.sqrt(chi2.isf(alpha, 3)) / a  # the chi-squared reaches the gate
    k_first = int(np.floor(t_cross / H_S)) + 1
    assert abs(t_cross / H_S - round(t_cross / H_S)) > 1e-3  # (not on a tick: no tie to decide)
    S = b.state
    t_det = S.get(xs, "t_cmg").ravel()[-1]
    assert t_det == pytest.approx((k_first + n_persist - 1) * H_S, abs=1e-12)
    assert S.get(xs, "cmg_fault").ravel()[k_first + n_persist - 2] == 0.0  # not one tick earlier


def test_isolation_blames_the_unit_whose_gimbals_stopped():
    n = 30
    g = np.outer(np.arange(n), 1e-3 * np.arange(1, N_UNITS * GPU + 1))  # every gimbal turning ...
    g[15:, 4:6] = g[14, 4:6]  # ... unit 3 stops at tick 15, its residual with it
    r = np.zeros((n, 3))
    r[15:, 2] = 10.0  # N m
    b, xs, _ = _fly(_spec(cmg_persistence=3), r, gimbal=g)
    S = b.state
    assert S.get(xs, "cmg_unit").ravel()[-1] == 3
    assert S.get(xs, "cmg_excluded")[-1].tolist() == [0.0, 0.0, 1.0, 0.0]
    assert S.get(xs, "t_cmg").ravel()[-1] == pytest.approx(17 * H_S, abs=1e-12)


def test_mode_sequence_by_hand():
    """hold; |h| crosses assist_at x capacity at tick 5 -> assist; a command thruster_only over
    [1.0, 1.5) s (ticks 10-14) overrides; a detection at tick 20 (residual from tick 18, N = 3)
    raises the base to on_cmg_fault = drift; a command assist over [2.5, 2.7) overrides drift for
    ticks 25-26; in drift the CMGs are asked nothing."""
    n = 30
    r = np.zeros((n, 3))
    r[18:, 0] = 50.0  # N m
    r[5, 0] = 0.61 * CAPACITY_NMS / H_S  # a jump in |h| to 0.61 capacity at tick 5 (its residual too: one tick)
    spec = _spec([dict(mode="thruster_only", t=1.0, until=1.5), dict(mode="assist", t=2.5, until=2.7)],
                 cmg_persistence=3, initial_mode="hold", on_cmg_fault="drift", assist_at=0.6)
    b, xs, ys = _fly(spec, r, h0_B=(0.0, 0.0, 0.0))
    mode = b.state.get(xs, "fdir_mode").ravel()
    want = [0] * 5 + [1] * 5 + [2] * 5 + [1] * 5 + [3] * 5 + [1] * 2 + [3] * 3
    assert mode.tolist() == want
    assert b.state.get(xs, "t_cmg").ravel()[-1] == pytest.approx(20 * H_S, abs=1e-12)
    rest = b.outputs.get(ys, "tau_rest_B")
    assert np.all(rest[np.array(want) == 3] == 0.0)


def test_a_fault_under_the_gate_is_never_declared_and_knowledge_stays():
    sigma, alpha = 0.5, 1e-3
    r = np.zeros((500, 3))
    r[50:, 0] = 0.99 * sigma * np.sqrt(chi2.isf(alpha, 3))  # N m, just under the gate, for ever
    b, xs, _ = _fly(_spec(cmg_sigma_Nm=sigma, cmg_alpha=alpha, cmg_persistence=1, initial_mode="hold"), r)
    S = b.state
    assert S.get(xs, "count").max() == 0 and S.get(xs, "cmg_fault").max() == 0
    assert np.all(S.get(xs, "cmg_excluded") == 0) and np.all(S.get(xs, "fdir_mode") == 0)


# -- closed loop (one short compiled structure shared by the three runs) ------------------------
def _closed(**extra):
    s = load_scene(SCENE).replace({"simulation.duration": 120.0, "simulation.output_dt": 10.0, **extra})
    return simulate(s, fused=True)


def test_closed_loop_nominal_has_no_alarm():
    tr = _closed(**{"fault.cmg2.t": 120.0})  # the fault at the run's end: never flown
    sm = tr.meta["summary"]
    assert sm["fused"] and not sm["fdir_cmg_detected"] and sm["fdir_cmg_excluded"] == []
    assert np.all(tr["fdir_mode"] == 0)


def test_closed_loop_cmg_failure_declared_after_the_persistence():
    tr = _closed(**{"fault.cmg2.t": 60.0})
    sm = tr.meta["summary"]
    n_persist = load_scene(SCENE).fdir.cmg_persistence
    assert sm["fdir_cmg_detected"] and sm["fdir_cmg_unit_right"] and not sm["fdir_cmg_false_alarm"]
    assert sm["fdir_cmg_latency_s"] == pytest.approx((n_persist - 1) * 0.1, abs=1e-9)
    assert sm["fdir_cmg_excluded"] == [2]
    assert tr["fdir_mode"][-1] == 1  # assist after the detection
    assert sm["fdir_mode_changes"] == 1
    assert sm["fdir_mode_s"]["hold"] == pytest.approx(61.9, abs=1e-6)  # s: ticks 0..618 in hold
    assert sm["fdir_mode_s"]["hold"] + sm["fdir_mode_s"]["assist"] == pytest.approx(120.0, abs=1e-6)


def test_closed_loop_detection_is_an_event_of_the_recording():
    tr = _closed(**{"fault.cmg2.t": 60.0})
    texts = [(t, text) for t, _, text in Events(tr.columns).changes(tr)]
    assert (70.0, "flight software declares a CMG fault") in texts  # the first row after 61.9 s
    assert (70.0, "fdir_mode -> 1") in texts


def test_closed_loop_undetected_fault_leaves_knowledge_unchanged():
    tr = _closed(**{"fault.cmg2.t": 60.0, "fdir.cmg_sigma_Nm": 1.0e9})
    sm = tr.meta["summary"]
    assert not sm["fdir_cmg_detected"] and sm["fdir_cmg_excluded"] == []
    assert np.all(tr["fdir_mode"] == 0) and np.all(tr["fdir_cmg_unit"] == 0)


@pytest.mark.parametrize("edit,field", [
    (lambda d: d.pop("fdir"), "mode"),  # a [[mode]] command with no mode manager
    (lambda d: (d.pop("thruster"), d.pop("thrusters"), d["fdir"].update(on_cmg_fault="drift")), "fdir.initial_mode"),
    (lambda d: d["fdir"].update(initial_mode="thrusters_only"), "fdir.initial_mode"),
    (lambda d: d["mode"][0].update(until=10.0), "mode[0].until"),
], ids=["mode_without_fdir", "assist_without_thrusters", "misspelt_mode", "window_backwards"])
def test_bad_fdir_tables_are_one_line_errors_naming_the_field(edit, field):
    import tomllib  # noqa: PLC0415

    from stationbed.scene import SceneError, scene_from_dict  # noqa: PLC0415

    d = tomllib.loads(SCENE.read_text())
    d["fdir"]["initial_mode"] = "assist"
    d["mode"] = [{"mode": "drift", "t": 100.0, "until": 200.0}]
    edit(d)
    with pytest.raises(SceneError) as e:
        scene_from_dict(d)
    assert field in str(e.value) and "\n" not in str(e.value)
