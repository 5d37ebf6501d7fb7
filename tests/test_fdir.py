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
  the failed unit blamed and taken out of the steering law; a second failure after the first
  is isolated declared the same way (the test re-armed on the units left, the first never
  blamed again);
* the working units' capacity flight software knows after a declaration: the DGCMG's
  ``n_working x h_rotor`` written by hand, what the mode manager's and the thrusters' momentum
  thresholds divide by (a momentum under a threshold of four units, over it of three).
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.stats import binom, chi2

from stationbed import simulate
from stationbed.loop.fdir import FdirSpec, false_alarms_per_hour, fdir_block
from stationbed.loop.thrusters import ThrusterCluster
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


def _spec(modes=(), capacity_of=None, cmg=None, **kw):
    more = ({} if capacity_of is None else {"capacity_of": capacity_of}) | ({} if cmg is None else {"cmg": cmg})
    return FdirSpec(Fdir(**kw), [ModeCommand(**m) for m in modes], N_UNITS, GPU, CAPACITY_NMS, **more)


def _working_capacity(declared):
    """A cluster of N_UNITS equal units: each unit a quarter of the capacity (as a DGCMG's n h_rotor)."""
    return CAPACITY_NMS * (N_UNITS - len(declared)) / N_UNITS


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


def test_a_second_failure_after_an_isolation_is_declared_and_the_first_not_again():
    """Unit 3 stops at tick 15 (residual until tick 24: declared at 17), the isolation works (the
    residual back to 0), then unit 4 stops at tick 40 (residual from 40: declared at 42). Unit 3's
    gimbals stay stopped: it ties with unit 4 as the least moved, and the lower number would win
    a tie, so only the rule "a declared unit is never blamed again" blames unit 4."""
    n = 60
    g = np.outer(np.arange(n), 1e-3 * np.arange(1, N_UNITS * GPU + 1))
    g[15:, 4:6] = g[14, 4:6]
    g[40:, 6:8] = g[39, 6:8]
    r = np.zeros((n, 3))
    r[15:25, 2] = 10.0  # N m
    r[40:, 0] = 10.0  # N m
    b, xs, _ = _fly(_spec(cmg_persistence=3), r, gimbal=g)
    S = b.state
    assert S.get(xs, "cmg_excluded")[-1].tolist() == [0.0, 0.0, 1.0, 1.0]
    assert_allclose(S.get(xs, "t_unit")[-1], [-1.0, -1.0, 17 * H_S, 42 * H_S], rtol=0, atol=1e-12)
    assert S.get(xs, "cmg_unit").ravel()[-1] == 3 and S.get(xs, "t_cmg").ravel()[-1] == pytest.approx(17 * H_S, abs=1e-12)


def test_a_residual_that_stays_after_the_isolation_blames_no_more_units():
    """The isolation did not bring the residual back under the gate: the test stays waiting (a
    residual that never comes back is not blamed on the working units one after the other)."""
    n = 80
    g = np.outer(np.arange(n), 1e-3 * np.arange(1, N_UNITS * GPU + 1))
    g[15:, 4:6] = g[14, 4:6]
    r = np.zeros((n, 3))
    r[15:, 2] = 10.0  # N m, for ever
    b, xs, _ = _fly(_spec(cmg_persistence=3), r, gimbal=g)
    assert b.state.get(xs, "cmg_excluded")[-1].tolist() == [0.0, 0.0, 1.0, 0.0]


def test_the_mode_manager_climbs_on_the_working_units_capacity():
    """|h| = 0.5 of the four units' capacity, under assist_at = 0.6 of it; unit 3 declared at tick
    17 (on_cmg_fault = hold: the base mode stays hold): from the next tick the threshold is 0.6
    of the three units' capacity (0.75 of it), which 0.5 exceeds (0.5 / 0.75 = 0.67): assist."""
    n = 30
    g = np.outer(np.arange(n), 1e-3 * np.arange(1, N_UNITS * GPU + 1))
    g[15:, 4:6] = g[14, 4:6]
    r = np.zeros((n, 3))
    r[15:, 2] = 10.0  # N m (|h| moves by 1 N m s per tick: 0.01 % of it)
    spec = _spec(cmg_persistence=3, initial_mode="hold", on_cmg_fault="hold", assist_at=0.6,
                 capacity_of=_working_capacity)
    b, xs, _ = _fly(spec, r, gimbal=g, h0_B=(0.5 * CAPACITY_NMS, 0.0, 0.0))
    S = b.state
    assert S.get(xs, "fdir_mode").ravel().tolist() == [0.0] * 18 + [1.0] * 12
    assert S.get(xs, "cmg_capacity").ravel()[-1] == 0.75 * CAPACITY_NMS


def test_the_mode_manager_climbs_on_the_working_units_momentum():
    """Four DGCMGs at small gimbal angles (spins near +z, +x, -z, -x: the cluster's total |h| ~ 100 N m s,
    1 % of the capacity); unit 3 stops at tick 15 and is declared at 17 (on_cmg_fault = hold).
    From tick 18 the climb reads the three units left, near +z h_rotor (the -z rotor held is not
    theirs): |h_work| / (3 h_rotor) ~ 0.28 >= assist_at = 0.25, from the unit geometry written in
    tests/test_fault_momentum.py at the ticks' gimbal angles."""
    from stationbed.model.cmg import cmg_geometry  # noqa: PLC0415
    from stationbed.scene import Cmg  # noqa: PLC0415
    from test_fault_momentum import dgcmg_unit_momenta  # noqa: PLC0415

    n, h_rotor = 30, CAPACITY_NMS / N_UNITS  # N m s: a DGCMG's capacity is n h_rotor
    g = np.outer(np.arange(n), 1e-3 * np.arange(1, N_UNITS * GPU + 1))
    g[15:, 4:6] = g[14, 4:6]
    r = np.zeros((n, 3))
    r[15:, 2] = 10.0  # N m
    cfg = Cmg(kind="dgcmg", h_rotor=h_rotor)
    geo = cmg_geometry(cfg)
    spec = _spec(cmg_persistence=3, initial_mode="hold", on_cmg_fault="hold", assist_at=0.25,
                 capacity_of=_working_capacity, cmg=(geo, geo.params(cfg), np.zeros(3)))
    b, xs, _ = _fly(spec, r, gimbal=g)
    S = b.state
    assert S.get(xs, "t_unit")[-1].tolist() == [-1.0, -1.0, pytest.approx(17 * H_S, abs=1e-12), -1.0]
    left = np.linalg.norm(dgcmg_unit_momenta(g, h_rotor)[:, [0, 1, 3]].sum(axis=1), axis=1) / (3 * h_rotor)
    assert left[18] >= 0.25 * (1 + 0.01)  # (clear of the threshold at the first tick after the declaration)
    assert S.get(xs, "fdir_mode").ravel().tolist() == [0.0] * 18 + [1.0] * 12


def test_the_thrusters_dump_on_the_capacity_the_mode_manager_knows():
    """In assist, |h| = 0.17 of the four DGCMGs' capacity (4 h_rotor): under assist_on = 0.2 of
    it, over 0.2 of the three units' (3 h_rotor) the mode manager knows after a declaration."""
    s = load_scene(SCENE)
    h4, h3 = 4 * s.cmg.h_rotor, 3 * s.cmg.h_rotor  # N m s: the DGCMG cluster's n h_rotor
    assert s.thrusters.assist_on == 0.2
    c = ThrusterCluster(s, s, h4)
    dumping = []
    for cap in (h4, h3):
        r = c.reads.pack(h_B=[0.17 * h4, 0.0, 0.0], fdir_mode=1.0, cmg_capacity=cap,  # (no unit declared: h_B itself)
                         gimbal=np.zeros(8), t_unit=np.full(4, -1.0))
        x1 = c.command(0.0, H_S, c.x0, r, np.zeros(3))[0]
        dumping.append(c.state.get(x1, "dumping")[0])
    assert dumping == [0.0, 1.0]


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


def test_closed_loop_second_cmg_failure_declared_after_the_first_isolated():
    f = load_scene(SCENE).fault[0].model_dump(exclude_unset=True)
    tr = _closed(fault=[dict(f, t=60.0), dict(f, name="cmg4", unit=4, t=90.0)])
    sm = tr.meta["summary"]
    n_persist = load_scene(SCENE).fdir.cmg_persistence
    assert sm["fdir_cmg_excluded"] == [2, 4]
    assert [d["unit"] for d in sm["fdir_cmg_declared"]] == [2, 4]
    assert_allclose([d["t"] for d in sm["fdir_cmg_declared"]], [60.0 + (n_persist - 1) * 0.1, 90.0 + (n_persist - 1) * 0.1],
                    rtol=0, atol=1e-9)
    assert sm["fdir_cmg_unit"] == 2 and sm["fdir_cmg_t_s"] == pytest.approx(61.9, abs=1e-9)  # the first
    assert sm["fdir_cmg_capacity_Nms"] == 2 * load_scene(SCENE).cmg.h_rotor  # N m s: two DGCMGs left


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
