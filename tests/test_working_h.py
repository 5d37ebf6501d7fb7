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
* capacities: the DGCMG's ``n h_rotor`` (a spherical envelope), the pyramid's by brute force
  (tests/test_fault_momentum.py ``pyramid_envelope``);
* the saturation ticks: a flagged row whose working |h| (or the row before's) reaches
  ``saturation_fraction`` of that row's capacity, else a gimbal-rate limit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from stationbed import simulate
from stationbed.analysis import dashboard as dash
from stationbed.output.rerun.events import Events
from stationbed.scene import scene_from_dict
from stationbed.studies.montecarlo.dispersions import draw
from stationbed.studies.montecarlo.samples import run_sample
from test_fault_momentum import STUCK_UNIT, T_STUCK_S, TORQUE_Z_NM, dgcmg_unit_momenta, pyramid_envelope, stuck_scene
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
