"""Fault detection's delay (issue 20): ``[knowledge] failure_detected_after_s``.

The truth's failed CMG unit (``[cmg] failed``, failed from t = 0) is unknown to the law until the
first tick at or after the stated delay; from that tick the law designs on the plant with the unit
failed (``run/detection.py::replan``: the law's ``_replan`` hook, else its ``_reset``). Truths:

* the law's plant per tick, recorded by the law itself: the four-unit capacity before the
  detection, after it the capacity of the plant a scene stating the failure as known from the
  start gives (``[knowledge] failed_units``, an independent path through the knowledge scene);
  ``replan`` called exactly once, at tick ``ceil(T / h)``;
* the rows before the detection are those of the run in which it never comes, bit for bit, and
  after it they are not (the test law's torque scales with the capacity it believes);
* a detection at t = 0 gives the law the failure from its first tick (the run of a scene that
  states it known); a detection after the run's end changes nothing and the fused loop runs;
* bad values are one-line errors naming the key.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.controllers.pd import PD
from stationbed.scene import SceneError

SCENARIO = "scenarios/iss_lvlh_hold.toml"
PERIOD_S = 0.1
DETECTED_S = 2.05  # s: between ticks 20 and 21, so the first tick after it is 21
FAILED = [2]


class CapacityAwarePD(PD):
    """pd whose torque is scaled by the capacity it believes (over a fixed H_REF: a replan shows
    in the trajectory), recording that belief at every tick."""

    H_REF = 2.0e4  # N m s

    def _reset(self, plant):
        super()._reset(plant)
        if not hasattr(self, "h0"):
            self.h0, self.seen, self.replans = plant.h_capacity, [], 0

    def _replan(self, plant):  # the hook: here, count and design again
        self.replans += 1
        self._reset(plant)

    def _update(self, t, meas):
        self.seen.append((t, self.plant.h_capacity))
        return tuple(self.plant.h_capacity / self.H_REF * v for v in self.compiled_law()(t, meas))  # pd, compiled


class CapacitySymbolicPD(PD):
    """pd written once (``symbolic``, no ``_update``: every executor evaluates it compiled), its
    torque scaled by the capacity it believes over H_REF: a number of its ``symbolic_params``
    that a redesign changes."""

    H_REF = 2.0e4  # N m s

    def _reset(self, plant):
        super()._reset(plant)
        self.scale = plant.h_capacity / self.H_REF

    def symbolic_params(self):
        return [*super().symbolic_params(), self.scale]

    def symbolic(self, t, y, cp):
        cmd, q_ref = super().symbolic(t, y, cp[:-1])
        return cmd * cp[-1], q_ref


def scene(**knowledge):
    s = load_scene(SCENARIO).replace({"simulation.duration": 4.0, "simulation.output_dt": PERIOD_S,
                                      "cmg.failed": FAILED})
    return s.replace({"knowledge": knowledge}) if knowledge else s


def fly(s, fused=False, law=None):
    law = (law or CapacityAwarePD)(s.controller.period, **s.controller.params)
    return simulate(s, controller=law, fused=fused), law


@pytest.fixture(scope="module")
def detected():
    return fly(scene(failure_detected_after_s=DETECTED_S))


def test_the_law_is_told_the_failure_at_the_first_tick_after_the_delay(detected):
    _, law = detected
    _, told = fly(scene(failed_units=FAILED))  # the failure known from the start: its plant's capacity
    t, cap = np.array(law.seen).T
    first = math.ceil(DETECTED_S / PERIOD_S)
    assert law.replans == 1
    assert np.all(cap[t < first * PERIOD_S - 1e-9] == law.h0)
    assert np.all(cap[t >= first * PERIOD_S - 1e-9] == told.h0) and told.h0 < law.h0


def test_rows_before_the_detection_are_the_undetected_run(detected):
    tr, _ = detected
    never, _ = fly(scene())
    t = tr.cols("t").ravel()
    before = t < math.ceil(DETECTED_S / PERIOD_S) * PERIOD_S - 1e-9  # (the detection tick's row has its command)
    assert not tr.meta["summary"]["fused"]
    np.testing.assert_array_equal(tr.data[before], never.data[before])
    assert np.abs(tr.data[~before] - never.data[~before]).max() > 0


def test_detected_at_once_is_known_from_the_first_tick():
    tr, law = fly(scene(failure_detected_after_s=0.0))
    known, _ = fly(scene(failed_units=FAILED))
    assert law.replans == 1 and all(c == law.plant.h_capacity for _, c in law.seen)
    cap = np.array(law.seen)[:, 1]
    np.testing.assert_array_equal(cap, np.full(cap.shape, cap[0]))
    assert cap[0] < law.h0
    np.testing.assert_array_equal(tr.data, known.data)


def test_a_detection_flies_fused_with_the_per_tick_numbers_and_a_fresh_design():
    """A symbolic law with a detection inside the run flies fused (the redesign a scheduled step:
    the law designs again in Python at the detection tick, its new numbers written into the fused
    loop's): its rows are the per-tick run's, bit for bit (the same compiled law, the same numbers),
    they differ from the run in which the failure is never detected after the detection tick, and
    the law's numbers after it are those of a law designed on the failure known from the start."""
    s = scene(failure_detected_after_s=DETECTED_S)
    fused, law = fly(s, fused=True, law=CapacitySymbolicPD)
    per_tick, _ = fly(s, law=CapacitySymbolicPD)
    never, _ = fly(scene(), fused=True, law=CapacitySymbolicPD)
    _, fresh = fly(scene(failed_units=FAILED), fused=True, law=CapacitySymbolicPD)
    assert fused.meta["summary"]["fused"] and not per_tick.meta["summary"]["fused"]
    np.testing.assert_array_equal(fused.data, per_tick.data)
    t = fused.cols("t").ravel()
    after = t >= math.ceil(DETECTED_S / PERIOD_S) * PERIOD_S - 1e-9
    np.testing.assert_array_equal(fused.data[~after], never.data[~after])
    assert np.abs(fused.data[after] - never.data[after]).max() > 0
    assert law.symbolic_params() == fresh.symbolic_params() and law.scale < never_scale(s)
    assert fused.meta["summary"]["controller_updates"] == per_tick.meta["summary"]["controller_updates"]


def never_scale(s) -> float:
    """The law's scale on the four-unit plant (the design before the detection)."""
    _, law = fly(s.replace({"knowledge": None}), fused=True, law=CapacitySymbolicPD)
    return law.scale


def test_a_detection_after_the_run_changes_nothing_and_the_loop_runs_fused():
    late = scene(failure_detected_after_s=100.0)
    tr, law = fly(late, fused=True)
    assert law.replans == 0 and tr.meta["summary"]["fused"]


@pytest.mark.parametrize("knowledge, cmg, message", [
    ({"failure_detected_after_s": -1.0}, True, "knowledge.failure_detected_after_s"),
    ({"failure_detected_after_s": 1.0}, False, "knowledge.failure_detected_after_s: needs a \\[cmg\\] table"),
])
def test_bad_detection_delay_is_refused_naming_the_key(knowledge, cmg, message):
    s = load_scene(SCENARIO)
    changes = {"knowledge": knowledge}
    if not cmg:
        changes.update({"cmg": None, "controller.name": "pd"})
    with pytest.raises(SceneError, match=message):
        s.replace(changes)


def test_a_law_without_the_hook_designs_again_with_its_reset():
    s = scene(failure_detected_after_s=DETECTED_S)
    law = PD(s.controller.period, **s.controller.params)
    simulate(s, controller=law, fused=True)
    _, told = fly(scene(failed_units=FAILED))
    assert law.plant.h_capacity == told.h0 and law.n_updates > 0



@pytest.mark.parametrize("law", [CapacityAwarePD, CapacitySymbolicPD], ids=["python", "symbolic"])
def test_lockstep_flies_a_detection_in_the_batch(monkeypatch, law):
    """run_lockstep (the Monte Carlo's executor) runs a sample with a detection inside it in the
    batch, its law designing again at the detection tick (a scheduled step: in Python for a law
    called per member, into the compiled batch law's row for a symbolic one): each sample's rows
    are its single per-tick run's, bit for bit, and differ from the run in which the failure is
    never detected."""
    import stationbed.run.closed_loop as cl
    from stationbed.run.lockstep import run_lockstep, vectorised

    monkeypatch.setattr(cl, "build_controller", lambda spec, base_dir=None: law(spec.period, **spec.params))
    inertia = np.array(load_scene(SCENARIO).body.inertia)
    scenes = [scene(failure_detected_after_s=DETECTED_S).replace({"body.inertia": (inertia * f).tolist()})
              for f in (1.0, 1.03)]
    if vectorised(law(0.1)):  # (a law with only _update: run_lockstep sends it per tick; the batch itself here)
        res = run_lockstep(scenes, keep=True, fused=False)
        assert [k for k, _ in res] == ["batch"] * 2
    else:
        from scenes import lockstep_batch

        res = [("batch", tr) for tr in lockstep_batch(scenes)]
    for s, (_, tr) in zip(scenes, res):
        np.testing.assert_array_equal(tr.data, fly(s, law=law)[0].data)
    never, _ = fly(scenes[0].replace({"knowledge": None}))
    assert np.abs(res[0][1].data - never.data).max() > 0


class FailsToReplan(CapacityAwarePD):
    """Its re-design raises (a bug in a user's hook)."""

    def _replan(self, plant):
        raise np.linalg.LinAlgError("Singular matrix")


def test_a_replan_that_raises_is_a_failed_run_naming_the_controller():
    """The law's ``_replan`` raising at the detection (issue 32): SimulationError naming the
    controller, the hook, the exception and the detection's tick time, the law's exception as its
    cause, the rows before it kept and the summary status 'failed'."""
    from stationbed.run.simulation import SimulationError  # noqa: PLC0415

    s = scene(failure_detected_after_s=DETECTED_S)
    with pytest.raises(SimulationError) as err:
        simulate(s, controller=FailsToReplan(s.controller.period, **s.controller.params), fused=False)
    e, t_detect = err.value, math.ceil(DETECTED_S / PERIOD_S) * PERIOD_S
    assert "controller 'pd' raised LinAlgError in _replan" in str(e) and "Singular matrix" in str(e)
    assert e.t == pytest.approx(t_detect, rel=1e-12) and isinstance(e.__cause__, np.linalg.LinAlgError)
    assert e.trajectory.meta["status"] == "failed" and e.trajectory.t[-1] < t_detect
