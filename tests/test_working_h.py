"""What a person sees of the CMG cluster's momentum after a unit stops working mid-run (a
scheduled ``gimbal_stuck``: its rotor spins on, held at the angles it stuck at): the dashboard's
"|h| / capacity" panel, its saturation-vs-rate-limit ticks, the recording's limit events and the
Monte Carlo's ``h_fraction`` envelope all draw the working units' |h| over the capacity of the
units left at that row (stationbed/run/working_h.py), the series whose largest value is the
summary's ``max_h_fraction``.

Truths, none from the library's momentum or capacity code:

* each unit's rotor momentum from the rows' gimbal angles by the unit geometry written in the
  tests (the DGCMG's in tests/test_fault_momentum.py ``dgcmg_unit_momenta``, Wie's pyramid in
  tests/test_faults.py ``pyramid_h``);
* capacities: the DGCMG's ``n h_rotor`` (a spherical envelope; with a rotor at a fraction r of
  h_rotor, that unit counts r: ``(n - 1 + r) h_rotor``), the pyramid's by brute force
  (tests/test_fault_momentum.py ``pyramid_envelope``);
* a failed unit spinning down (``cmg_failed``, ``spin_down_s`` > 0) or stuck after its rotor
  dropped is out: the others' momenta from the gimbal angles (its rotor's is not needed);
* the saturation ticks: a flagged row whose working |h| (or the row before's) reaches
  ``saturation_fraction`` of that row's capacity, else a gimbal-rate limit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.analysis import dashboard as dash
from stationbed.output.rerun.events import Events
from stationbed.scene import scene_from_dict
from stationbed.studies.montecarlo.dispersions import draw
from stationbed.studies.montecarlo.samples import run_sample
from test_fault_momentum import SCENE, STUCK_UNIT, T_STUCK_S, TORQUE_Z_NM, dgcmg_unit_momenta, pyramid_envelope, stuck_scene
from test_faults import box, pyramid_h

#: the working momentum from the rows against the library's: the same sums in another order
#: (|h| ~ 5e3 N m s; the CSV's %.17g round trip is exact)
H_ROUNDOFF_REL = 1e-12
#: the pyramid's brute-force envelope (tests/test_fault_momentum.py ENVELOPE_REL: sampled every 2π/20000)
ENVELOPE_REL = 2e-8
STUCK_PYR_S = 4.0  # s: the pyramid's unit 1 sticks (no [fdir])


def _write_run(tr, folder):
    """A run folder as ``stationbed run --out`` leaves it: the rows and summary.json's summary."""
    folder.mkdir(parents=True, exist_ok=True)
    tr.to_csv(folder / "trajectory.csv")
    (folder / "summary.json").write_text(json.dumps({"scene": "stuck", "summary": tr.meta["summary"]}))
    return folder


def _drawn_lines(monkeypatch, folder) -> dict:
    """The dashboard's lines by panel title: label -> (x, y), the limit ticks by label."""
    got = {}
    real = dash.save_png

    def spy(plt, fig, path, **kw):
        got.update({ax.get_title(): {ln.get_label(): (ln.get_xdata(), ln.get_ydata()) for ln in ax.get_lines()}
                    for ax in fig.axes if ax.get_title()})
        real(plt, fig, path, **kw)

    monkeypatch.setattr(dash, "save_png", spy)
    dash.dashboard(folder)
    return got


# -- the DGCMG scene: unit 2 stuck at 5 s ---------------------------------------------------------
@pytest.fixture(scope="module")
def dgcmg_stuck():
    s = stuck_scene()
    return s, simulate(s, fused=True)


def _dgcmg_truth(tr, s):
    """|h_work| / capacity per row: all four units over 4 h_rotor before the stuck time, the three
    left over 3 h_rotor from it; and the whole cluster's |h| over 4 h_rotor (what is not drawn)."""
    g = tr.data[:, [tr.columns.index(c) for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]]
    hu = dgcmg_unit_momenta(g, s.cmg.h_rotor)
    out = tr.t >= T_STUCK_S
    hw = np.where(out[:, None], hu.sum(axis=1) - hu[:, STUCK_UNIT - 1], hu.sum(axis=1))
    whole = np.linalg.norm(hu.sum(axis=1), axis=1) / (4.0 * s.cmg.h_rotor)
    return np.linalg.norm(hw, axis=1) / (np.where(out, 3.0, 4.0) * s.cmg.h_rotor), whole


def test_dashboard_draws_the_working_units_over_their_capacity(dgcmg_stuck, tmp_path, monkeypatch):
    """The panel's series is |h_work| over each row's capacity: the stuck rotor's 4760 N m s out
    of |h| and its unit out of the capacity from 5 s (the whole cluster's |h| over 4 h_rotor,
    drawn before, is near 0 there: the three others cancel the stuck rotor); its largest value
    is the summary's max_h_fraction."""
    s, tr = dgcmg_stuck
    lines = _drawn_lines(monkeypatch, _write_run(tr, tmp_path / "run"))
    _, y = lines["CMG momentum |h| / capacity"]["|h| / capacity"]
    want, whole = _dgcmg_truth(tr, s)
    after = tr.t >= T_STUCK_S
    # the units left hold about a third of their capacity (the dump brings it down), the cluster ~0
    assert after.any() and want[after].min() > 0.25 and whole[after].max() < 0.05
    np.testing.assert_allclose(y, want, rtol=H_ROUNDOFF_REL, atol=0)
    assert float(np.max(y)) == tr.meta["summary"]["max_h_fraction"]


def test_montecarlo_envelope_is_the_working_units_over_their_capacity(dgcmg_stuck):
    """A sample of the stuck scene with an envelope at every row: its h_fraction series is the
    truth's, and its largest value the sample's max_h_fraction (the table's column)."""
    s, _ = dgcmg_stuck
    mc = s.replace({"montecarlo": {"n": 1, "seed": 7, "envelope_dt": s.simulation.output_dt}})
    n_t = int(round(s.simulation.duration / s.simulation.output_dt)) + 1
    row, env = run_sample(mc, 0, env_times=n_t)
    assert row["status"] == "ok"
    drawn_scene = draw(mc, 0)[0]  # the sample's scene: its run again, with the rows kept
    tr = simulate(drawn_scene, fused=True)
    assert len(tr.t) == n_t
    np.testing.assert_allclose(env[:, 1], _dgcmg_truth(tr, drawn_scene)[0], rtol=H_ROUNDOFF_REL, atol=0)
    assert float(np.nanmax(env[:, 1])) == row["max_h_fraction"]


# -- the pyramid box: unit 1 stuck at 4 s, a torque that saturates the units left ------------------
@pytest.fixture(scope="module")
def pyramid_stuck():
    d = box([{"kind": "gimbal_stuck", "unit": 1, "t": STUCK_PYR_S}], duration=20.0, w0=(0.0, 0.0, 0.0))
    d["simulation"]["output_dt"] = 0.1
    d["controller"]["params"]["bandwidth"] = 0.3  # 1/s: the law holds attitude, the CMGs take the torque
    d["torque"] = [{"kind": "constant", "torque_B": [0.0, 0.0, TORQUE_Z_NM]}]
    s = scene_from_dict(d)
    return s, simulate(s, fused=True)


def _pyramid_saturated_rows(tr, s):
    """The flagged rows at which the working units' |h| (or the row before's) reached
    saturation_fraction of their capacity (units 2-4 from the stuck time), and the flagged rows."""
    g = tr.data[:, [tr.columns.index(f"gimbal_{i}") for i in range(1, 5)]]
    out = tr.t >= STUCK_PYR_S
    hw = np.array([np.linalg.norm(pyramid_h(gi, [0.0 if o else 1.0, 1.0, 1.0, 1.0])) for gi, o in zip(g, out)])
    thr = s.cmg.saturation_fraction * np.where(out, pyramid_envelope([2, 3, 4]), pyramid_envelope([1, 2, 3, 4]))
    assert np.abs(hw - thr).min() / thr.min() > 2 * ENVELOPE_REL  # the sampled envelope decides no row
    at = hw >= thr
    flag = tr["cmg_saturated"] >= 0.5
    return flag & (at | np.r_[False, at[:-1]]), flag


def test_dashboard_and_recording_name_the_saturation_of_the_units_left(pyramid_stuck, tmp_path, monkeypatch):
    """After unit 1 sticks the units left saturate at 0.9 of their own envelope (the whole
    cluster's |h|, the stuck rotor's included, stays under 0.9 of the four units'): the
    dashboard's red ticks and the recording's "CMG momentum saturation" are those rows, the
    other flagged rows gimbal-rate limits."""
    s, tr = pyramid_stuck
    sat, flag = _pyramid_saturated_rows(tr, s)
    sm = tr.meta["summary"]
    assert sat.any() and (flag & ~sat).any(), "the run must have both kinds of limit"
    assert sm["rate_limited_ticks"] > 0 and sm["momentum_saturated_ticks"] > 0
    lines = _drawn_lines(monkeypatch, _write_run(tr, tmp_path / "run"))
    ticks = lines["CMG momentum |h| / capacity"]
    np.testing.assert_array_equal(ticks["CMG momentum saturation"][0], tr.t[sat])
    np.testing.assert_array_equal(ticks["CMG gimbal-rate limit"][0], tr.t[flag & ~sat])
    # the recording's events: a "begins" at each row where a run of saturated rows starts
    said = [t for t, _, text in Events.of(s, tr.columns).changes(tr) if text == "CMG momentum saturation begins"]
    starts = tr.t[sat & ~np.r_[False, sat[:-1]]]
    np.testing.assert_array_equal(said, starts)


# -- a rotor at a fraction: a wheel_speed_drop, a failed unit spinning down (the DGCMG) -------------
T_ROTOR_S = 5.0  # s, on the tick grid: unit 2's rotor drops, or the unit fails and spins down
DROP_FRACTION = 0.5  # of unit 2's rotor lost: it runs on at 0.5 h_rotor, a working unit
SPIN_DOWN_S = 10.0  # s, the failed rotor's time constant: a step every 0.5 s (5 ticks), exp(-1.5) = 0.22 of it left at 20 s


T_DROP_FIRST_S = 3.0  # s: in "drop_then_stuck", unit 2's rotor drops here, its gimbals stick at T_ROTOR_S


def _rotor_scene(kind):
    s = load_scene(SCENE)
    f = dict(s.fault[0].model_dump(exclude_unset=True), t=T_ROTOR_S, unit=STUCK_UNIT)
    if kind == "wheel_speed_drop":
        faults = [dict(f, kind=kind, fraction=DROP_FRACTION)]
    elif kind == "cmg_failed":
        faults = [dict(f, kind=kind, spin_down_s=SPIN_DOWN_S)]
    else:  # the stuck unit holds the momentum its dropped rotor has
        faults = [dict(f, name="drop", kind="wheel_speed_drop", t=T_DROP_FIRST_S, fraction=DROP_FRACTION),
                  dict(f, name="stuck", kind="gimbal_stuck")]
    return s.replace({"simulation.duration": 20.0, "simulation.output_dt": 0.1, "fault": faults})


def hw_vec(tr, s):
    """The three units other than unit 2: their summed momentum per row, B [N m s]."""
    g = tr.data[:, [tr.columns.index(c) for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]]
    hu = dgcmg_unit_momenta(g, s.cmg.h_rotor)
    return hu.sum(axis=1) - hu[:, STUCK_UNIT - 1]


def _rotor_truth(tr, s, kind):
    """|h_work| and its capacity per row. A dropped rotor's unit works: all four units' momenta
    from the gimbal angles, unit 2's times 1 - fraction from the drop, over (3 + 1 - fraction)
    h_rotor (the DGCMG's spherical envelope: each unit reaches its own rotor's momentum along any
    axis). A failed or stuck unit is out from its fault whatever its rotor holds: the three
    others' momenta over 3 h_rotor (nothing of the spin-down staircase or the drop needed)."""
    g = tr.data[:, [tr.columns.index(c) for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]]
    hu = dgcmg_unit_momenta(g, s.cmg.h_rotor)
    r2 = np.ones(len(tr.t))
    if kind == "wheel_speed_drop":
        r2[tr.t >= T_ROTOR_S] = 1.0 - DROP_FRACTION
    else:
        r2[tr.t >= T_DROP_FIRST_S] = 1.0 - DROP_FRACTION if kind == "drop_then_stuck" else 1.0
        r2[tr.t >= T_ROTOR_S] = 0.0
    hu[:, STUCK_UNIT - 1] *= r2[:, None]
    return np.linalg.norm(hu.sum(axis=1), axis=1), (3.0 + r2) * s.cmg.h_rotor


@pytest.fixture(scope="module", params=["wheel_speed_drop", "cmg_failed", "drop_then_stuck"])
def rotor_run(request):
    s = _rotor_scene(request.param)
    return request.param, s, simulate(s, fused=True)


def test_summary_and_dashboard_weigh_a_rotor_at_its_fraction(rotor_run, tmp_path, monkeypatch):
    """After a wheel_speed_drop the working capacity counts the unit's rotor at its fraction;
    after a cmg_failed with a spin-down the unit's decaying rotor (up to 4760 N m s) is out of
    |h_work| and the unit out of the capacity. The summary's max_h_Nms and max_h_fraction are
    the truth's largest values, the dashboard draws the truth's series."""
    kind, s, tr = rotor_run
    hw, cap = _rotor_truth(tr, s, kind)
    sm = tr.meta["summary"]
    after = tr.t >= T_ROTOR_S
    if kind == "wheel_speed_drop":  # the rows' h is the truth's |h_work| (the dropped rotor in it)
        h = tr.data[:, [tr.columns.index(c) for c in ("hx", "hy", "hz")]]
        np.testing.assert_allclose(np.linalg.norm(h, axis=1), hw, rtol=H_ROUNDOFF_REL, atol=0)
    else:  # the held rotor (the rows' h less the three others'): a fifth of h_rotor at the end, or half
        h = tr.data[:, [tr.columns.index(c) for c in ("hx", "hy", "hz")]]
        assert np.linalg.norm(h[-1] - hw_vec(tr, s)[-1]) > 0.2 * s.cmg.h_rotor
    assert (hw[after] / cap[after]).max() > 0.0
    np.testing.assert_allclose(sm["max_h_Nms"], hw.max(), rtol=H_ROUNDOFF_REL)
    np.testing.assert_allclose(sm["max_h_fraction"], (hw / cap).max(), rtol=H_ROUNDOFF_REL)
    lines = _drawn_lines(monkeypatch, _write_run(tr, tmp_path / "run"))
    _, y = lines["CMG momentum |h| / capacity"]["|h| / capacity"]
    np.testing.assert_allclose(y, hw / cap, rtol=H_ROUNDOFF_REL, atol=0)


def test_montecarlo_envelope_weighs_a_rotor_at_its_fraction(rotor_run):
    """The Monte Carlo's h_fraction envelope of the same scene at every row is the truth's series."""
    kind, s, _ = rotor_run
    mc = s.replace({"montecarlo": {"n": 1, "seed": 7, "envelope_dt": s.simulation.output_dt}})
    n_t = int(round(s.simulation.duration / s.simulation.output_dt)) + 1
    row, env = run_sample(mc, 0, env_times=n_t)
    assert row["status"] == "ok"
    drawn_scene = draw(mc, 0)[0]
    tr = simulate(drawn_scene, fused=True)
    hw, cap = _rotor_truth(tr, drawn_scene, kind)
    np.testing.assert_allclose(env[:, 1], hw / cap, rtol=H_ROUNDOFF_REL, atol=0)
    assert float(np.nanmax(env[:, 1])) == row["max_h_fraction"]


def test_pyramid_capacity_weighs_a_dropped_rotor_by_its_envelope():
    """The pyramid's capacity after unit 1's rotor drops to half, then with unit 3 stuck too: by
    brute force, along each body axis the sum of each unit's sampled reach (Wie's pyramid) times
    its rotor's fraction (0: out), the least of the three axes."""
    from stationbed.model.cmg import cmg_geometry
    from stationbed.run.faults import capacity_steps
    from test_fault_momentum import REACH_SAMPLES
    from test_faults import H_ROTOR_NMS

    s = scene_from_dict(box([{"kind": "wheel_speed_drop", "unit": 1, "t": 2.0, "fraction": DROP_FRACTION},
                             {"kind": "gimbal_stuck", "unit": 3, "t": 4.0}], duration=6.0))
    d = np.linspace(0.0, 2.0 * np.pi, REACH_SAMPLES, endpoint=False)
    reach = [np.array([pyramid_h(np.full(4, di), [float(i == u) for i in range(4)]) for di in d]).max(axis=0)
             for u in range(4)]  # (3,) each: unit u's largest momentum along x, y, z at h_rotor

    def brute(rotors):
        return float(sum(r * reach[u] for u, r in enumerate(rotors)).min())

    steps = capacity_steps(s, cmg_geometry(s.cmg))
    assert [t for t, _ in steps] == [2.0, 4.0]
    want = [brute([1.0 - DROP_FRACTION, 1.0, 1.0, 1.0]), brute([1.0 - DROP_FRACTION, 1.0, 0.0, 1.0])]
    # the full pyramid's 3.2 h_rotor is what the drop takes from (the brute force's scale)
    assert abs(brute([1.0] * 4) / H_ROTOR_NMS - 3.2) < ENVELOPE_REL * 3.2
    np.testing.assert_allclose([c for _, c in steps], want, rtol=ENVELOPE_REL)


def test_a_dropped_rotor_spins_down_from_what_it_has():
    """A wheel_speed_drop (half lost at 3 s) then a cmg_failed spinning down (τ = 10 s from 5 s)
    of the same unit: the failed rotor's momentum (the rows' h less the three others', from their
    gimbal angles) is the dropped half times exp(-(t_j - 5 s)/τ) at each staircase step t_j, never
    more than the half it had (the staircase of the nominal rotor spun it back up to 0.95)."""
    s = load_scene(SCENE)
    f = dict(s.fault[0].model_dump(exclude_unset=True), unit=STUCK_UNIT)
    faults = [dict(f, name="drop", kind="wheel_speed_drop", t=T_DROP_FIRST_S, fraction=DROP_FRACTION),
              dict(f, name="fail", kind="cmg_failed", t=T_ROTOR_S, spin_down_s=SPIN_DOWN_S)]
    s = s.replace({"simulation.duration": 20.0, "simulation.output_dt": 0.1, "fault": faults})
    tr = simulate(s, fused=True)
    h = tr.data[:, [tr.columns.index(c) for c in ("hx", "hy", "hz")]]
    h2 = np.linalg.norm(h - hw_vec(tr, s), axis=1) / s.cmg.h_rotor  # unit 2's rotor, of h_rotor
    step_s = SPIN_DOWN_S / 20  # the staircase's step (SPIN_DOWN_STEPS_PER_TAU = 20 per τ)
    for k in (0, 1, 5, 20):  # rows just after staircase steps t_j = 5 s + (k + 1) step_s
        t_j = T_ROTOR_S + (k + 1) * step_s
        row = int(np.searchsorted(tr.t, t_j + 1e-9))
        want = (1.0 - DROP_FRACTION) * np.exp(-(t_j - T_ROTOR_S) / SPIN_DOWN_S)
        np.testing.assert_allclose(h2[row], want, rtol=1e-9)  # (the rows' %.17g; sums of ~5e3 N m s)
    assert h2[tr.t >= T_DROP_FIRST_S + 0.05].max() <= (1.0 - DROP_FRACTION) * (1.0 + 1e-9)
