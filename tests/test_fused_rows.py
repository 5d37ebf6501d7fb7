"""Many output rows of the fused loop per compiled call (issue 25; stationbed/run/fused_rows.py).

Claims:

* the fused loop with its rows in bulk gives the row-by-row fused loop's trajectory bit for bit,
  and the same counts of ticks, rate-limited and saturated ticks, on a stretch of
  ``iss_lvlh_hold`` where the CMGs' gimbal-rate limit switches on and off between rows (the
  flags a row carries from the ticks after the previous row), with the environment at every
  stage and held over blocks (its carry passed from call to call), and with sensor noise (the
  draws of many rows taken in one call: the same stream);
* the bulk path ran (the test would otherwise compare the row-by-row loop with itself);
* a run that ends in a non-finite state inside a bulk call stops where the row-by-row loop
  stops: the same time, the same rows handed over before it.

The independent truths of the loop itself (balance, closed forms) are in
tests/test_closed_loop_balance.py and tests/test_control_loop.py, which run the bulk path too.
"""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.run import composed as composed_mod
from stationbed.run.controller import Controller
from stationbed.run.simulation import SimulationError
from stationbed.scene import scene_from_dict
from test_control_loop import loop_scene

ROOT = Path(__file__).resolve().parents[1]
#: an initial attitude error that drives the gimbals into their rate limit on and off in the
#: 200 s (measured: 1431 rate-limited ticks at 3.5 deg; 2.5 deg gave 223 until issue 32's wing
#: inertia, and none since)
SLEW_DEG = 3.5
DURATION_S = 200.0


def _row_by_row(monkeypatch):
    """The fused loop without its bulk rows (the composed build offers no ``cl_rows_R``;
    run/composed.py, issue 33)."""
    monkeypatch.setattr(composed_mod, "rows_functions", lambda *a, **k: [])
    monkeypatch.setattr(composed_mod, "_CHUNKS", {})


def spy_first(monkeypatch, module, name: str) -> list:
    """``module.name`` wrapped: a list it appends the first value of each call's result to (a
    bulk-rows runner's rows run in bulk, per run; also tests/test_flight_rows.py's)."""
    seen = []
    real = getattr(module, name)

    def spy(*a, **k):
        out = real(*a, **k)
        seen.append(out[0])
        return out

    monkeypatch.setattr(module, name, spy)
    return seen


def _spy(monkeypatch) -> list:
    """Rows run in bulk, per run (a list the wrapped :func:`run_rows` appends to)."""
    return spy_first(monkeypatch, composed_mod, "run_rows")


#: sensor noise of the noisy case: attitude [rad], rate [rad/s] (the MC scenario's order)
NOISE = {"attitude_noise": 1.0e-4, "rate_noise": 1.0e-6, "seed": 7}


def _slew_scene(rate: int, noisy: bool):
    a = math.radians(SLEW_DEG) / 2
    s = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    return s.replace(
        {"initial.q_BN": [math.cos(a), math.sin(a), 0.0, 0.0], "simulation.output_dt": 1.0,
         "simulation.environment_rate": rate, "controller.sensor": NOISE if noisy else {}})


@pytest.mark.parametrize("rate, noisy", [(0, False), (20, False), (20, True)],
                         ids=["every_stage", "environment_20", "environment_20_noise"])
def test_bulk_rows_give_the_row_by_row_loops_bits(monkeypatch, rate, noisy):
    scene = _slew_scene(rate, noisy)
    seen = _spy(monkeypatch)
    bulk = simulate(scene, duration=DURATION_S)
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = simulate(scene, duration=DURATION_S)
    assert seen[0] >= 192 and seen[1] == 0  # 3 x 64 + 1 x 8 of 200 rows in bulk; none without
    s_bulk, s_one = bulk.meta["summary"], one.meta["summary"]
    assert s_bulk["rate_limited_ticks"] > 0 and s_bulk["fused"] is True
    for key in ("ticks", "controller_updates", "rate_limited_ticks", "momentum_saturated_ticks"):
        assert s_bulk[key] == s_one[key], key
    assert bulk.columns == one.columns
    assert np.array_equal(bulk.data, one.data, equal_nan=True)


#: the command becomes NaN after this time [s] (a square root of a negative number)
NAN_AFTER_S = 7.05


class NanAfter(Controller):
    """Zero torque until ``NAN_AFTER_S``, NaN after it, in Python and in casadi."""

    name = "nan_after"
    command = "torque"

    def _update(self, t, meas):
        return (0.01 * math.sqrt(NAN_AFTER_S - t) if t <= NAN_AFTER_S else math.nan, 0.0, 0.0)

    def symbolic_params(self):
        return []

    def symbolic(self, t, y, cp):
        return ca.vertcat(0.01 * ca.sqrt(NAN_AFTER_S - t), 0.0, 0.0), ca.DM([1.0, 0.0, 0.0, 0.0])


def _stopped(scene):
    with pytest.raises(SimulationError) as exc:
        simulate(scene, controller=NanAfter(), fused=True)
    return exc.value


def test_a_nan_inside_a_bulk_call_stops_where_the_row_by_row_loop_stops(monkeypatch):
    scene = scene_from_dict(loop_scene())  # 200 rows of one tick each
    seen = _spy(monkeypatch)
    bulk = _stopped(scene)
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = _stopped(scene)
    assert seen[0] == 72  # 64 rows, then the second call up to the row (t = 7.1 s) whose stretch ends in NaN
    assert (bulk.t, bulk.reason) == (one.t, one.reason)
    assert bulk.t == pytest.approx(7.2)  # the tick after the first NaN command (t = 7.1 s)
    assert np.array_equal(bulk.trajectory.data, one.trajectory.data, equal_nan=True)


def test_a_loop_whose_rows_hold_other_columns_runs_row_by_row_with_the_same_draws(monkeypatch):
    """The bulk rows check the first row's held values against the executor's own
    (``RunState.held_row``); a loop whose rows hold something else (here: a planted extra column) falls
    back to row by row — after the bulk call drew its sensor noise, so the generator is put
    back: the run is the row-by-row run, draws included."""
    from stationbed.run import composition

    scene = _slew_scene(20, True)
    with monkeypatch.context() as m:
        _row_by_row(m)
        one = simulate(scene, duration=50.0)
    real = composition.RunState.held_row
    seen = _spy(monkeypatch)
    monkeypatch.setattr(composition.RunState, "held_row", lambda self, f, t=0.0: (real(self, f, t)[0][:-1] + [0.5], real(self, f, t)[1]))
    other = simulate(scene, duration=50.0)
    assert seen == [0]
    cols = [i for i, c in enumerate(one.columns) if c != "att_err_z_deg"]  # the planted column
    assert np.array_equal(other.data[:, cols], one.data[:, cols], equal_nan=True)


def _full_rows_one_by_one(period, duration, row_ks, n, K):
    """The leading full rows counted a row at a time (the first form of ``_full_rows``)."""
    j = 0
    while j + 1 < len(row_ks) and row_ks[j] < K and row_ks[j + 1] - row_ks[j] == n:
        if duration - (row_ks[j] + n - 1) * period < period * (1 - 1e-12):
            break
        j += 1
    return j


def test_leading_full_rows_counted_in_numpy_as_a_row_at_a_time():
    """Row ticks with gaps, a last row at K, a duration that cuts the last tick short or not, no
    rows and one row: the same count as one row at a time."""
    import types

    from stationbed.run.composed_rows import _full_rows

    rng = np.random.default_rng(4)
    for _ in range(300):
        n = int(rng.integers(1, 12))
        m = int(rng.integers(0, 40))
        steps = np.where(rng.uniform(size=m) < 0.9, n, rng.integers(1, 2 * n + 1, m))
        ks = np.concatenate([[0], np.cumsum(steps)])[: m].astype(int).tolist()
        K = int(ks[-1]) if ks and rng.uniform() < 0.5 else (int(ks[-1]) + n if ks else 0)
        period = float(rng.choice([0.1, 0.25, 1.0]))
        duration = (K + rng.choice([0.0, -0.5, 0.3])) * period
        comp = types.SimpleNamespace(period=period, duration=duration)
        assert _full_rows(comp, ks, n, K) == _full_rows_one_by_one(period, duration, ks, n, K)
