"""The working units' momentum after a CMG unit stops working mid-run (a scheduled
``gimbal_stuck``: its rotor spins on at the angles it stuck at): what the thrusters' dump law
acts on once ``[fdir]`` has declared the unit, the run's ``max_h_fraction`` and the per-tick
saturation flag (``momentum_saturated_ticks``).

Truths, none from the library's momentum or capacity code:

* each unit's rotor momentum from the CSV's gimbal angles, by the unit geometry written here
  (the DGCMG's default layout: outer axes +x, +y, -x, -y, spins at zero angles +z, +x, -z, -x)
  or in tests/test_faults.py (Wie's pyramid sum, ``pyramid_h``);
* capacities: the DGCMG's ``n h_rotor`` (a spherical envelope); the pyramid's, for the units
  left, by brute force: along each body axis the sum over the units of the largest component
  their spin reaches over a full turn of the gimbal (sampled), the least of the three axes;
* the dump law's Schmitt trigger (``[thrusters] assist_on``, ``dump_stop``) replayed row by row
  from those momenta, with the mode and the declaration the rows report.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.run.lockstep import run_lockstep
from stationbed.run.metrics import trajectory_metrics
from stationbed.scene import scene_from_dict
from test_faults import BETA_RAD, H_ROTOR_NMS, box, pyramid_h, run

SCENE = Path(__file__).resolve().parents[1] / "scenarios" / "iss_cmg_failure_fdir.toml"
T_STUCK_S = 5.0  # s, on the tick grid: unit 2's gimbals stick (its rotor spins on)
STUCK_UNIT = 2
#: the momenta from the rows against the run's: the same sums in another order, |h| ~ 5e3 N m s
H_ROUNDOFF_REL = 1e-12
#: the pyramid's brute-force envelope: the reach max_δ s(δ)·e sampled every 2π/N rad falls short
#: of the true maximum by at most 1 - cos(π/N) of it (N = 20000: 1.2e-8)
REACH_SAMPLES = 20000
ENVELOPE_REL = 2e-8


def dgcmg_unit_momenta(gimbals, h_rotor):
    """Each DGCMG unit's rotor momentum, B [N m s], (n_rows, 4, 3), from the rows' outer and
    inner gimbal angles (n_rows, 8) in the CSV's order: the spin ``e3`` turned about the outer
    axis ``e1`` by δ_o, then about the inner axis by δ_i: ``sin δ_i e1 + cos δ_i (cos δ_o e3 -
    sin δ_o e2)``, ``e2 = e3 × e1`` (the default layout, written out)."""
    e1 = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    e3 = np.array([[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]], float)
    e2 = np.cross(e3, e1)
    d_o, d_i = gimbals[:, 0::2, None], gimbals[:, 1::2, None]
    return h_rotor * (np.sin(d_i) * e1 + np.cos(d_i) * (np.cos(d_o) * e3 - np.sin(d_o) * e2))


def pyramid_envelope(units) -> float:
    """The capacity of the pyramid's ``units`` (1-based) by brute force [N m s]: along each body
    axis e the sum of max over δ of ``s_i(δ)·e`` (the unit's spin over a sampled full turn), the
    least over the three axes."""
    d = np.linspace(0.0, 2.0 * math.pi, REACH_SAMPLES, endpoint=False)
    reach = np.zeros(3)
    for u in units:
        rotor = [1.0 if i + 1 == u else 0.0 for i in range(4)]
        s = np.array([pyramid_h(np.full(4, di), rotor) for di in d]) / H_ROTOR_NMS  # (N, 3): unit u's spin
        reach += s.max(axis=0)
    return H_ROTOR_NMS * float(reach.min())


# -- the DGCMG scene with [fdir]: a stuck gimbal declared, the dump law ----------------------------
def stuck_scene():
    """iss_cmg_failure_fdir for 20 s at one row per tick, unit 2's gimbals stuck at 5 s (its rotor's
    4760 N m s held where the three others cancel it: they carry a third of their capacity, the
    cluster's total near 0) and a dump time of 20 s (the dump shows within the run)."""
    s = load_scene(SCENE)
    f = dict(s.fault[0].model_dump(exclude_unset=True), kind="gimbal_stuck", t=T_STUCK_S, unit=STUCK_UNIT)
    return s.replace({"simulation.duration": 20.0, "simulation.output_dt": 0.1, "fault": [f],
                      "thrusters.dump_time_s": 20.0})


def fly(scene, executor):
    if executor == "lockstep":  # the batch: a second sample (nominal) beside it
        (kind, tr), _ = run_lockstep([scene, scene.replace({"fault.cmg2.enabled": False})], fused=False, keep=True)
        assert kind == "batch"
        return tr
    tr = simulate(scene, fused=executor == "fused")
    assert tr.meta["summary"]["fused"] == (executor == "fused")
    return tr


@pytest.fixture(scope="module")
def stuck_runs():
    s = stuck_scene()
    return s, {e: fly(s, e) for e in ("fused", "per_tick", "lockstep")}


def _units(tr, scene):
    g = tr.data[:, [tr.columns.index(c) for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]]
    return dgcmg_unit_momenta(g, scene.cmg.h_rotor)


def test_rows_momentum_is_the_sum_of_the_units_written_here(stuck_runs):
    """(The unit geometry written here is the one flown: its sum is the rows' h.)"""
    s, runs = stuck_runs
    tr = runs["fused"]
    h = tr.data[:, [tr.columns.index(c) for c in ("hx", "hy", "hz")]]
    np.testing.assert_allclose(_units(tr, s).sum(axis=1), h, rtol=0, atol=H_ROUNDOFF_REL * 4 * s.cmg.h_rotor)


@pytest.mark.parametrize("executor", ["fused", "per_tick", "lockstep"])
def test_dump_acts_on_the_working_units_once_the_stuck_unit_is_declared(stuck_runs, executor):
    """Tick by tick, ``thr_dumping`` is the Schmitt trigger on |h_work| / capacity: before the
    declaration all four units (flight software does not know), after it the three left and
    their capacity 3 h_rotor; in hold mode nothing dumps. The stuck rotor's momentum is not the
    working units' to dump: they hold -h_stuck (a third of their capacity, over assist_on), which
    the dump must bring down though the cluster's total is small."""
    s, runs = stuck_runs
    tr = runs[executor]
    hu = _units(tr, s)
    th, hr = s.thrusters, s.cmg.h_rotor
    declared = tr["fdir_t_cmg_s"] >= 0.0  # the memory before the row's tick: what the tick's thrusters read
    assert tr.meta["summary"]["fdir_cmg_unit"] == STUCK_UNIT and declared.any()
    work = [i for i in range(4) if i + 1 != STUCK_UNIT]
    want, dumping = [], False
    for j in range(len(tr.t) - 1):  # the row after tick j reports its decision
        if declared[j]:
            f = np.linalg.norm(hu[j, work].sum(axis=0)) / (3 * hr)
        else:
            f = np.linalg.norm(hu[j].sum(axis=0)) / (4 * hr)
        dumping = tr["fdir_mode"][j] >= 0.5 and (f > th.dump_stop if dumping else f >= th.assist_on)
        want.append(float(dumping))
    assert any(want), "the scene must make the dump law act"
    assert tr["thr_dumping"][1:].tolist() == want


def test_max_h_fraction_is_over_each_rows_working_capacity(stuck_runs):
    """From the fault's time the stuck unit is out of the working units (the truth's schedule,
    as ``max_h_Nms`` leaves its rotor out): each row's |h_work| over that row's capacity, 4 h_rotor
    before, 3 h_rotor after; the summary's record gives the same number from the rows again."""
    s, runs = stuck_runs
    tr = runs["fused"]
    hu = _units(tr, s)
    out = tr.t >= T_STUCK_S
    hw = np.where(out[:, None], hu.sum(axis=1) - hu[:, STUCK_UNIT - 1], hu.sum(axis=1))
    frac = np.linalg.norm(hw, axis=1) / np.where(out, 3.0, 4.0) / s.cmg.h_rotor
    sm = tr.meta["summary"]
    assert sm["max_h_fraction"] == pytest.approx(frac.max(), rel=H_ROUNDOFF_REL)
    assert trajectory_metrics(tr)["max_h_fraction"] == sm["max_h_fraction"]


# -- the pyramid box: the saturation flag -------------------------------------------------------------
#: a constant torque along body z [N m] builds the momentum the three units left must hold
TORQUE_Z_NM = 200.0
STUCK_PYR_S = 4.0  # s: unit 1 sticks (no [fdir]: it stays in the steering law)


@pytest.mark.parametrize("executor", ["fused", "per_tick", "lockstep"])
def test_saturated_ticks_count_the_units_that_move_against_their_envelope(executor):
    """A tick is momentum saturated when the momentum of the units whose gimbals move reaches
    saturation_fraction of their capacity: from the stuck time, units 2-4 against their
    envelope (brute force); before, all four against 3.2 h_rotor. One row per tick: the count
    over the ticks flown (every row but the last) is the summary's."""
    d = box([{"kind": "gimbal_stuck", "unit": 1, "t": STUCK_PYR_S}], duration=20.0, w0=(0.0, 0.0, 0.0))
    d["simulation"]["output_dt"] = 0.1
    d["controller"]["params"]["bandwidth"] = 0.3  # 1/s: the law holds attitude, the CMGs take the torque
    d["torque"] = [{"kind": "constant", "torque_B": [0.0, 0.0, TORQUE_Z_NM]}]
    tr = run(d, executor)
    g = tr.data[:, [tr.columns.index(f"gimbal_{i}") for i in range(1, 5)]]
    out = tr.t >= STUCK_PYR_S
    hw = np.array([np.linalg.norm(pyramid_h(gi, [0.0 if o else 1.0, 1.0, 1.0, 1.0])) for gi, o in zip(g, out)])
    cap_all, cap_left = pyramid_envelope([1, 2, 3, 4]), pyramid_envelope([2, 3, 4])
    assert cap_all == pytest.approx(H_ROTOR_NMS * 4 * math.sin(BETA_RAD), rel=ENVELOPE_REL)  # (the closed form at 53.13 deg)
    frac = scene_from_dict(d).cmg.saturation_fraction
    thr = frac * np.where(out, cap_left, cap_all)
    margin = np.abs(hw - thr)[:-1].min() / thr.min()
    assert margin > 2 * ENVELOPE_REL  # no tick so near the threshold that the sampled envelope could decide it
    want = int(np.sum(hw[:-1] >= thr[:-1]))
    assert want > 0, "the scene must saturate the units left"
    assert tr.meta["summary"]["momentum_saturated_ticks"] == want
