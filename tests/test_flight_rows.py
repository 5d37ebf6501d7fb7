"""Many output rows of the fused flight loop per compiled call (issue 20; stationbed/run/flight_rows.py).

Claims:

* the fused loop flown on two gyros, two star-tracker heads and the MEKF with its rows in bulk
  gives the row-by-row fused flight loop's trajectory bit for bit (the filter's report columns:
  error, 3σ, bias estimate, NEES, each head's valid flag), and the same summary (ticks, counts
  of rate-limited and saturated ticks, the estimation metrics), on a slew of
  ``iss_lvlh_hold_estimated`` that drives the gimbals into their rate limit between rows (the
  flags a row carries from the ticks after the previous row);
* the bulk path ran (the test would otherwise compare the row-by-row loop with itself);
* a loop whose rows hold other columns falls back to row by row with the same sensor noise
  (the stream put back after the bulk call drew it);
* at the default ``environment_rate = "auto"`` the flight loop runs held at the bound's choice,
  20 ticks (aero and solar pressure held over blocks of ticks, stationbed/run/flight_rates.py;
  its summary says so, with the bound), in bulk and row by row bit for bit, and moves the
  attitude from the every-stage flight loop (the same noise stream) by no more than the stated
  bound (run/rate_auto.py: the MEKF is kinematic, so the law on the estimate moves the truth
  through the same PD loop; docs/design.md "Effects at their own rate"), and no more than the
  hold moves the truth-fed loop of the same scene (independent truth: the truth-fed pair,
  run/env_block.py, whose hold tests/test_effect_rates.py bounds) times :data:`HOLD_SAME_DRAWS`;
  a noise row reaching the wrong tick of a held block would move it by the noise's effect
  (~1e-7 rad), four orders above the hold's;
* a run whose state turns non-finite inside a bulk call stops where the row-by-row loop stops:
  the same time and reason, the same rows handed over.

The loop's own truths (fused == per tick to round-off, the MEKF's NEES bands, the gyro's Allan
variance) are in tests/test_loop_flown.py, tests/test_mekf.py and tests/test_loop_sensors.py,
which run the bulk path too.
"""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.core.rotation import rotation_angle
from stationbed.run import composed as composed_mod
from stationbed.run.controller import Controller
from stationbed.run.rate_auto import TARGET_RAD
from stationbed.run.simulation import SimulationError
from test_fused_rows import spy_first

ROOT = Path(__file__).resolve().parents[1]
#: an initial attitude error that drives the gimbals into their rate limit in the first ~20 s
#: (3.5 deg: 728 limited ticks in 100 s; 2.5 deg did until issue 32's wing inertia, now 0)
SLEW_DEG = 3.5
#: 80 rows of 10 s (the scenario's output): one call of 64 rows and two of 8 in bulk
DURATION_S = 800.0
#: the held flight pair's attitude difference against the held truth-fed pair's (the filter's
#: estimate feeds the hold's torque error through the law as the truth does: the same order)
HOLD_SAME_DRAWS = 10.0


def _scene():
    a = math.radians(SLEW_DEG) / 2
    s = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml")
    return s.replace({"initial.q_BN": [math.cos(a), math.sin(a), 0.0, 0.0]})


def _spy(monkeypatch) -> list:
    """Rows run in bulk, per run."""
    return spy_first(monkeypatch, composed_mod, "run_rows")


def _row_by_row(monkeypatch):
    """The fused flight loop without its bulk rows (no row run in bulk; same compiled build;
    the composed loop's, run/composed.py, issue 33)."""
    monkeypatch.setattr(composed_mod, "run_rows", lambda *a, **k: (0, 0, 0, None))


def _bulk_and_row_by_row(monkeypatch, scene) -> tuple:
    """``(rows run in bulk per run, the run with bulk rows, the run row by row)`` of ``scene``."""
    with monkeypatch.context() as m:
        seen = _spy(m)
        bulk = simulate(scene, duration=DURATION_S, fused=True)
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = simulate(scene, duration=DURATION_S, fused=True)
    return seen, bulk, one


def test_bulk_flight_rows_give_the_row_by_row_loops_bits(monkeypatch):
    seen, bulk, one = _bulk_and_row_by_row(monkeypatch, _scene())
    # 64 + 8 + 8 rows (the row at the run's end: row by row); before it, the default rate's probe
    # (a truth-fed run, run/rate_auto.py) when not cached yet: the same executor since issue 33
    assert seen[-1] == 80 and len(seen) <= 2
    s_bulk, s_one = bulk.meta["summary"], one.meta["summary"]
    assert s_bulk["rate_limited_ticks"] > 0 and s_bulk["fused"] is True
    assert s_bulk == s_one
    assert "nees" in bulk.columns and bulk.columns == one.columns
    assert np.array_equal(bulk.data, one.data, equal_nan=True)


def test_a_flight_loop_whose_rows_hold_other_columns_runs_row_by_row_with_the_same_noise(monkeypatch):
    from stationbed.run import composition

    scene = _scene()
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = simulate(scene, duration=DURATION_S, fused=True)
    real = composition.RunState.held_row
    seen = _spy(monkeypatch)
    monkeypatch.setattr(composition.RunState, "held_row",
                        lambda self, f, t=0.0: (real(self, f, t)[0][:-1] + [0.5], real(self, f, t)[1]))
    other = simulate(scene, duration=DURATION_S, fused=True)
    assert seen == [0]
    cols = [i for i, c in enumerate(one.columns) if c != "st_valid_st2"]  # the planted column (the last held)
    assert np.array_equal(other.data[:, cols], one.data[:, cols], equal_nan=True)


def test_the_environment_at_its_own_rate_in_the_flight_loop(monkeypatch):
    scene = _scene()
    seen, held, held_one = _bulk_and_row_by_row(monkeypatch, scene)  # the default: "auto"
    summary = held.meta["summary"]
    assert seen == [80] and (summary["environment_rate_asked"], summary["environment_rate_ticks"]) == ("auto", 20)
    assert summary["environment_rate_why"] is None and 0.0 < summary["environment_rate_bound_rad"] <= TARGET_RAD
    assert np.array_equal(held.data, held_one.data, equal_nan=True) and held.meta["summary"] == held_one.meta["summary"]
    every = simulate(scene.replace({"simulation.environment_rate": 0}), duration=DURATION_S, fused=True)
    err = float(np.max(rotation_angle(every.q_BN, held.q_BN)))
    assert err <= summary["environment_rate_bound_rad"], f"{err:.3e} rad against the bound's {summary['environment_rate_bound_rad']:.3e}"
    truth = scene.replace({"sensor": [], "estimator": None, "simulation.environment_rate": 0})  # every stage
    truth_err = float(np.max(rotation_angle(simulate(truth, duration=DURATION_S).q_BN,
                                            simulate(truth.replace({"simulation.environment_rate": 20}),
                                                     duration=DURATION_S).q_BN)))
    assert 0.0 < err <= HOLD_SAME_DRAWS * truth_err, f"{err:.3e} rad against the truth-fed hold's {truth_err:.3e} rad"


#: the law's command becomes NaN after this time [s]: inside the 21st row (10 s rows) of the first
#: 64-row call
NAN_AFTER_S = 205.05


class NanAfter(Controller):
    """A tiny torque until :data:`NAN_AFTER_S`, NaN after it (casadi: the square root of a negative)."""

    name = "nan_after_flight"
    command = "torque"

    def _update(self, t, meas):
        return (1e-9 * math.sqrt(NAN_AFTER_S - t) if t <= NAN_AFTER_S else math.nan, 0.0, 0.0)

    def symbolic_params(self):
        return []

    def symbolic(self, t, y, cp):
        return ca.vertcat(1e-9 * ca.sqrt(NAN_AFTER_S - t), 0.0, 0.0), ca.DM([1.0, 0.0, 0.0, 0.0])


def _stopped(scene):
    with pytest.raises(SimulationError) as exc:
        simulate(scene, controller=NanAfter(), fused=True, duration=DURATION_S)
    return exc.value


def test_a_nan_inside_a_bulk_flight_call_stops_where_the_row_by_row_loop_stops(monkeypatch):
    # the ideal torquer (no [cmg]: a CMG's rate limit would clip the NaN request away)
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace({"cmg": None})
    with monkeypatch.context() as m:
        seen = _spy(m)
        bulk = _stopped(scene)
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = _stopped(scene)
    assert seen == [21]  # 20 rows, then the row (t = 200 s) whose stretch ends in NaN
    assert (bulk.t, bulk.reason) == (one.t, one.reason) and bulk.t == pytest.approx(210.0)
    assert np.array_equal(bulk.trajectory.data, one.trajectory.data, equal_nan=True)
