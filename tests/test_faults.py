"""Scheduled faults (issue 34 item 1; stationbed/run/schedule.py, run/faults.py) against truths
the executors do not share.

* **The split run.** A fault at t_e is a step of the truth's numbers at a control tick: the run
  with the fault equals a run to t_e without it, re-seeded from its last state (attitude, rate,
  gimbal angles) with the fault at t = 0 and run on. The scene is time-invariant (deep space, a
  stateless inertial law, SR steering), so the re-seeded run's clock does not matter. Held on the
  fused loop, the per-tick loop (the law in Python) and the lockstep batch.
* **The momentum balance.** Deep space, no external torque: the system's angular momentum
  (body + CMG rotors, the ``HN*`` columns) is constant across every CMG fault, including the
  rotor stopped or slowed at t (its momentum goes to the body: the state jumps). A leaking
  thruster about body x of a spherical body: ``ΔH_N = F L (t - t_on)`` exactly, its propellant
  ``F t / (Isp g0)``.
* **What the hardware does**, from the columns: a stuck gimbal's angle does not move until the
  window ends (and ``max_h`` leaves its held rotor out, as a failed unit's: Wie's sum of the others); a degraded gimbal's rate stays within its limit; after a wheel-speed drop the
  cluster's momentum is Wie's pyramid sum with that rotor at its fraction, written here.
* **Load errors**: a misspelt kind, unit or parameter, a time off the tick grid: one line.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import simulate
from stationbed.model.cmg import CmgGeometry
from stationbed.run.controller import Controller, ControllerParams
from stationbed.run.lockstep import run_lockstep
from stationbed.run.metrics import trajectory_metrics
from stationbed.scene import SceneError, scene_from_dict

PERIOD_S = 0.1  # s, control period and RK4 step
T_FAULT_S = 4.0  # s, on the tick grid and on an output row
DURATION_S = 10.0  # s
H_ROTOR_NMS = 1000.0  # N m s per unit
BETA_RAD = math.atan2(4.0, 3.0)  # pyramid skew (cos = 0.6)
#: the split run and the executors agree to round-off: states ~1e3 N m s and 1e-2 rad/s after ~100
#: RK4 ticks (measured < 3e-12 abs; a tick late or early would be ~1e-1 N m s)
SPLIT_ABS = 1e-9
#: RK4 at 0.1 s over 10 s of a tumbling box (ω state) keeps H to ~3e-8 N m s (measured); a rotor's
#: momentum lost instead of handed to the body would be 1e3 N m s
H_DRIFT_NMS = 1e-6
J_BOX = np.diag([1.0e5, 1.2e5, 1.5e5])  # kg m², the box's inertia
#: g0 for the propellant's truth [m/s²] (CGPM 1901, exact)
G0 = 9.80665

CMG_FAULTS = {
    "cmg_failed": {"kind": "cmg_failed", "unit": 2},
    "gimbal_stuck": {"kind": "gimbal_stuck", "unit": 1, "until": 7.0},
    "gimbal_rate_limit": {"kind": "gimbal_rate_limit", "unit": 3, "limit": 0.002},
    "wheel_speed_drop": {"kind": "wheel_speed_drop", "unit": 4, "fraction": 0.35},
}


def box(faults=(), *, formulation="dalembert", duration=DURATION_S, q0=(1.0, 0.0, 0.0, 0.0),
        w0=(0.01, -0.005, 0.002), gimbal0=None) -> dict:
    """A tumbling box in deep space; a 4-SGCMG pyramid steered by SR; ``pd`` holding inertial."""
    cmg = {"kind": "sgcmg_pyramid", "h_rotor": H_ROTOR_NMS, "skew": BETA_RAD, "max_gimbal_rate": 1.0}
    if gimbal0 is not None:
        cmg["gimbal0"] = list(gimbal0)
    return {
        "name": "fault_box",
        "simulation": {"duration": duration, "integrator": "rk4", "step": PERIOD_S, "output_dt": 0.5,
                       "formulation": formulation},
        "initial": {"q_BN": list(q0), "omega_BN_B": list(w0)},
        "body": {"mass": 1.0e3, "inertia": [[1.0e5, 0, 0], [0, 1.2e5, 0], [0, 0, 1.5e5]]},  # kg m²
        "cmg": cmg,
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.1, "damping": 0.9}},
        "fault": [dict(f, t=T_FAULT_S if "t" not in f else f["t"]) for f in faults],
    }


class PyHold(Controller):
    """A law in Python only (no symbolic form: the per-tick loop calls ``_update`` every tick):
    ``τ = -J (k q_v + c ω)``, stateless, inertial hold."""

    name = "py_hold"
    command = "torque"

    class Params(ControllerParams):
        k: float = 0.02  # 1/s²
        c: float = 0.2  # 1/s

    def _update(self, t, meas):
        q, w, P = meas.q_BN, meas.omega_BN_B, self.params
        s = 1.0 if q[0] >= 0.0 else -1.0
        return tuple(-J_BOX[i, i] * (P.k * s * q[i + 1] + P.c * w[i]) for i in range(3))


def run(d: dict, executor: str):
    """The run of scene dict ``d`` on ``executor``, asserting it ran there."""
    scene = scene_from_dict(d)
    if executor == "python_law":
        tr = simulate(scene, controller=PyHold(period=PERIOD_S))
        assert not tr.meta["summary"]["fused"]
        return tr
    if executor == "lockstep":  # the batch: a second sample (nominal) beside it
        (kind, tr), _ = run_lockstep([scene, scene_from_dict(dict(d, fault=[]))], fused=False, keep=True)
        assert kind == "batch"
        return tr
    tr = simulate(scene, fused=executor == "fused")
    assert tr.meta["summary"]["fused"] == (executor == "fused"), tr.meta["summary"].get("not_fused")
    return tr


#: fault -> the CMG unit's numbers after it (model/cmg/base.py UNIT_TAIL), set in the re-seeded
#: run's parameters from the start (no scheduled step there)
AFTER = {
    "cmg_failed": {"rate_cap": 0.0, "rotor": 0.0},
    "gimbal_stuck": {"rate_cap": 0.0},
    "gimbal_rate_limit": {"rate_cap": CMG_FAULTS["gimbal_rate_limit"]["limit"]},
    "wheel_speed_drop": {"rotor": 1.0 - CMG_FAULTS["wheel_speed_drop"]["fraction"]},
}


@pytest.mark.parametrize("executor", ["fused", "per_tick", "python_law", "lockstep"])
@pytest.mark.parametrize("name", list(CMG_FAULTS))
def test_fault_equals_the_split_run(name, executor, monkeypatch):
    f = dict(CMG_FAULTS[name])
    f.pop("until", None)  # (a window's end: test_stuck_gimbal_holds_its_angle_until_the_window_ends)
    full = run(box([f]), executor)
    before = run(box(duration=T_FAULT_S), executor)
    c = before.columns
    last = before.data[-1]
    q0 = last[[c.index(k) for k in ("qw", "qx", "qy", "qz")]]
    w0 = last[[c.index(k) for k in ("wx", "wy", "wz")]]
    g0 = last[[c.index(f"gimbal_{i}") for i in range(1, 5)]]
    # the rotor momentum the fault takes goes to the body: ω jumps by J⁻¹ Δh (a rigid box)
    rotor = np.ones(4)
    rotor[f["unit"] - 1] = AFTER[name].get("rotor", 1.0)
    w0 = w0 + np.linalg.solve(J_BOX, pyramid_h(g0, np.ones(4)) - pyramid_h(g0, rotor))
    params = CmgGeometry.params

    def after_fault(self, cfg):
        p = params(self, cfg).copy()
        for key, v in AFTER[name].items():
            p[self.unit_index(key, f["unit"])] = v
        return p

    monkeypatch.setattr(CmgGeometry, "params", after_fault)
    # (the fault kept but disabled: a scene with [[fault]] compiles the cluster that reads the
    # units' numbers; one without leaves them out, Structure.cmg's unit_faults)
    after = run(box([dict(f, enabled=False)], duration=DURATION_S - T_FAULT_S, q0=q0, w0=w0, gimbal0=g0), executor)
    i0 = int(np.searchsorted(full.t, T_FAULT_S))
    assert full.t[i0] == T_FAULT_S
    assert_allclose(full.t[i0:] - T_FAULT_S, after.t, rtol=0, atol=1e-12)
    # every column but time and faults_active: the state, h, the gimbals and their held rates, the command
    assert_allclose(full.data[i0:, 1:-1], after.data[:, 1:-1], rtol=0, atol=SPLIT_ABS)
    assert full.meta["summary"]["faults"] == [dict(fault=0, kind=f["kind"], unit=f["unit"], t=T_FAULT_S)]


@pytest.mark.parametrize("formulation", ["dalembert", "momentum"])
@pytest.mark.parametrize("name", list(CMG_FAULTS))
def test_system_momentum_is_kept_across_cmg_faults(name, formulation):
    tr = run(box([CMG_FAULTS[name]], formulation=formulation), "fused")
    H = tr.H_O_N
    assert_allclose(H, np.broadcast_to(H[0], H.shape), rtol=0, atol=H_DRIFT_NMS)


def _col(tr, name):
    return tr.data[:, tr.columns.index(name)]


def test_stuck_gimbal_holds_its_angle_until_the_window_ends():
    tr = run(box([CMG_FAULTS["gimbal_stuck"]]), "fused")
    g, t = _col(tr, "gimbal_1"), tr.t
    held = (t >= T_FAULT_S) & (t <= 7.0)
    assert np.all(g[held] == g[held][0])  # exactly: its rate is 0
    assert np.ptp(g[t >= 7.0]) > 1e-6  # free again after the window (rad)
    assert np.all(_col(tr, "gimbal_1_rate")[(t >= T_FAULT_S) & (t < 7.0)] == 0.0)
    assert list(_col(tr, "faults_active")) == [float(T_FAULT_S <= v < 7.0) for v in t]


def test_degraded_gimbal_keeps_within_its_limit():
    f = CMG_FAULTS["gimbal_rate_limit"]
    nominal, tr = run(box(), "fused"), run(box([f]), "fused")
    after = tr.t >= T_FAULT_S
    assert np.max(np.abs(_col(nominal, "gimbal_3_rate")[after])) > 2 * f["limit"]  # the limit bites
    assert np.max(np.abs(_col(tr, "gimbal_3_rate")[after])) <= f["limit"]


def pyramid_h(delta, rotor) -> np.ndarray:
    """Wie's pyramid (JGCD 28(5) 2005, eq. 2) with each rotor at its fraction ``rotor``."""
    cb, sb = math.cos(BETA_RAD), math.sin(BETA_RAD)
    c, s = np.cos(delta), np.sin(delta)
    spins = np.array([[-cb * s[0], c[0], sb * s[0]], [-c[1], -cb * s[1], sb * s[1]],
                      [cb * s[2], -c[2], sb * s[2]], [c[3], cb * s[3], sb * s[3]]])
    return H_ROTOR_NMS * (np.asarray(rotor)[:, None] * spins).sum(axis=0)


def test_max_h_leaves_a_stuck_unit_out_as_a_failed_one():
    """While unit 1's gimbal is stuck ([4, 7) s) its rotor's momentum is held, as a failed unit's:
    ``max_h_Nms`` is the largest |h| of the working units, Wie's sum with rotor 1 left out there
    (all four before and after); the summary's record of the held momentum gives the same
    number from the rows again (``trajectory_metrics``, as ``compare`` reads a run)."""
    f = CMG_FAULTS["gimbal_stuck"]
    tr = run(box([f]), "fused")
    g = tr.data[:, [tr.columns.index(f"gimbal_{i}") for i in range(1, 5)]]
    working = [pyramid_h(gi, [0.0 if T_FAULT_S <= t < f["until"] else 1.0, 1.0, 1.0, 1.0]) for t, gi in zip(tr.t, g)]
    sm = tr.meta["summary"]
    assert sm["max_h_Nms"] == pytest.approx(max(np.linalg.norm(w) for w in working), rel=0, abs=1e-9 * H_ROTOR_NMS)
    assert trajectory_metrics(tr)["max_h_Nms"] == sm["max_h_Nms"]


def test_wheel_speed_drop_scales_that_rotor():
    f = CMG_FAULTS["wheel_speed_drop"]
    tr = run(box([f]), "fused")
    g = tr.data[:, [tr.columns.index(f"gimbal_{i}") for i in range(1, 5)]]
    h = tr.data[:, [tr.columns.index(k) for k in ("hx", "hy", "hz")]]
    for t, gi, hi in zip(tr.t, g, h):
        rotor = [1.0, 1.0, 1.0, 1.0 - f["fraction"] if t >= T_FAULT_S else 1.0]
        assert_allclose(hi, pyramid_h(gi, rotor), rtol=0, atol=1e-9 * H_ROTOR_NMS)


TAU_S = 2.0  # s, the spin-down's time constant: a step every tick (τ / 20 = 0.1 s)


@pytest.mark.parametrize("formulation", ["dalembert", "momentum"])
def test_spin_down_follows_the_exponential_and_keeps_momentum(formulation):
    """``spin_down_s = τ``: at every step tick the rotor holds exp(-(t - t_f) / τ) of its momentum
    (Wie's pyramid sum, written here), the rest handed to the body (H_N constant)."""
    tr = run(box([{"kind": "cmg_failed", "unit": 2, "spin_down_s": TAU_S}], formulation=formulation), "fused")
    g = tr.data[:, [tr.columns.index(f"gimbal_{i}") for i in range(1, 5)]]
    h = tr.data[:, [tr.columns.index(k) for k in ("hx", "hy", "hz")]]
    for t, gi, hi in zip(tr.t, g, h):
        rotor = [1.0, math.exp(-(t - T_FAULT_S) / TAU_S) if t >= T_FAULT_S else 1.0, 1.0, 1.0]
        assert_allclose(hi, pyramid_h(gi, rotor), rtol=0, atol=1e-9 * H_ROTOR_NMS)
    assert_allclose(tr.H_O_N, np.broadcast_to(tr.H_O_N[0], tr.H_O_N.shape), rtol=0, atol=H_DRIFT_NMS)
    assert tr.meta["summary"]["faults"] == [dict(fault=0, kind="cmg_failed", unit=2, t=T_FAULT_S)]


# -- thrusters -------------------------------------------------------------------------------------

F_N = 100.0  # N, the leaking thruster's force
ARM_M = 10.0  # m, its lever arm about body x
ISP_S = 300.0  # s


def sphere_with_thrusters(faults, mode="off", w0=(0.0, 0.0, 0.0)) -> dict:
    """A spherical body holding inertial with an ideal CMG; six thrusters, one per torque direction
    (``xp``: +x torque F L, ``xm``: -x, ...), in ``mode`` ("off": they fire only by a leak)."""
    d = box(faults, w0=w0)
    d["body"]["inertia"] = [[1.0e6, 0, 0], [0, 1.0e6, 0], [0, 0, 1.0e6]]  # kg m²
    d["cmg"] = {"kind": "ideal"}
    L = ARM_M
    places = {"x": ([0.0, L, 0.0], [0.0, 0.0, 1.0]), "y": ([0.0, 0.0, L], [1.0, 0.0, 0.0]), "z": ([L, 0.0, 0.0], [0.0, 1.0, 0.0])}
    d["thruster"] = [{"name": f"{a}{s}", "position_B": r, "direction_B": [sign * v for v in g], "force_N": F_N,
                      "isp_s": ISP_S} for a, (r, g) in places.items() for s, sign in (("p", 1.0), ("m", -1.0))]
    d["thrusters"] = {"mode": mode}
    return d


@pytest.mark.parametrize("executor", ["fused", "per_tick"])
def test_leak_torque_and_propellant(executor):
    t_on, t_off = 2.0, 6.0  # s, the leak's window
    tr = run(sphere_with_thrusters([{"t": t_on, "until": t_off, "kind": "thruster_stuck_on", "unit": "xp"}]), executor)
    t = tr.t
    lit = np.clip(np.minimum(t, t_off) - t_on, 0.0, None)  # s the valve was open in [0, t]
    dH = tr.H_O_N - tr.H_O_N[0]
    assert_allclose(dH[:, 0], F_N * ARM_M * lit, rtol=0, atol=1e-9)  # N m s
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=1e-9)
    assert_allclose(_col(tr, "thr_propellant_kg"), F_N * lit / (ISP_S * G0), rtol=1e-12, atol=1e-15)
    assert_allclose(_col(tr, "thr_on_s_xp"), lit, rtol=0, atol=1e-12)
    for name in ("xm", "yp", "ym", "zp", "zm"):
        assert np.all(_col(tr, f"thr_on_s_{name}") == 0.0)


def test_stuck_off_thruster_never_fires_again():
    """Thruster-only control of a tumbling sphere: every thruster fires; one stuck off at t_e
    keeps its on-time from then on (the others take what they can)."""
    def scene(faults):
        return sphere_with_thrusters(faults, mode="thruster_only", w0=(0.002, -0.002, 0.001))
    nominal = run(scene([]), "fused")
    tr = run(scene([{"kind": "thruster_stuck_off", "unit": "xm"}]), "fused")
    after = tr.t >= T_FAULT_S
    assert np.ptp(_col(nominal, "thr_on_s_xm")[after]) > 0.1  # s: it fires after t_e when healthy
    on = _col(tr, "thr_on_s_xm")
    assert np.all(on[after] == on[after][0]) and on[after][0] > 0.0


# -- load errors -----------------------------------------------------------------------------------

@pytest.mark.parametrize("fault, words", [
    ({"t": 4.0, "kind": "cmg_faild", "unit": 2}, ["fault[0].kind", "did you mean 'cmg_failed'"]),
    ({"t": 4.0, "kind": "cmg_failed", "unit": 5}, ["fault[0].unit", "5", "1, 2, 3, 4"]),
    ({"t": 4.0, "kind": "wheel_speed_drop", "unit": 1, "fractoin": 0.3}, ["fractoin", "did you mean 'fraction'"]),
    ({"t": 4.0, "kind": "wheel_speed_drop", "unit": 1}, ["fraction", "needs"]),
    ({"t": 4.05, "kind": "gimbal_stuck", "unit": 1}, ["fault[0].t", "4 s", "4.1 s"]),
    ({"t": 4.0, "until": 3.0, "kind": "gimbal_stuck", "unit": 1}, ["until", "after t"]),
    ({"t": 4.0, "until": 6.0, "kind": "cmg_failed", "unit": 1}, ["until", "does not clear"]),
    ({"t": 4.0, "kind": "thruster_stuck_on", "unit": "xp"}, ["fault[0].unit", "[[thruster]] name"]),
])
def test_bad_fault_is_one_line(fault, words):
    with pytest.raises(SceneError) as e:
        scene_from_dict(box([fault]))
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


# -- the Monte Carlo (issue 34 item 4) --------------------------------------------------------------

P_OCCUR = 0.3  # the fault's probability of occurrence per sample
N_DRAWS = 400  # samples drawn (not run): the binomial band below
#: |count - n p| within 4.5 standard deviations sqrt(n p (1 - p)): a false failure ~7e-6 per run
BINOMIAL_SIGMAS = 4.5


def study(**fault) -> dict:
    d = box([dict({"name": "cmg", "kind": "cmg_failed", "unit": 2, "probability": P_OCCUR}, **fault)])
    d["montecarlo"] = {"n": N_DRAWS, "seed": 7, "envelope_dt": None, "disperse": [
        {"key": "fault.cmg.t", "kind": "uniform", "low": -3.0, "high": 3.0},  # s, about T_FAULT_S
        {"key": "fault.cmg.unit", "kind": "choice", "choices": [1, 2, 3, 4]}]}
    return d


def test_montecarlo_draws_faults_on_the_grid_with_their_probability():
    from stationbed.studies.montecarlo.dispersions import draw, drawn_columns

    scene = scene_from_dict(study())
    cols = drawn_columns(scene)
    assert "fault.cmg.occurred" in cols and not any(c.startswith("told.fault") for c in cols)
    occurred = 0
    for k in range(N_DRAWS):
        s, dr, _, why = draw(scene, k)
        assert why is None
        f = s.fault[0]
        assert f.enabled == bool(dr.values["fault.cmg.occurred"])
        assert s.knowledge is None or not any(p.startswith("fault") for p in s.knowledge.values)
        tick = f.t / PERIOD_S
        assert round(tick) * PERIOD_S == f.t and T_FAULT_S - 3.0 - PERIOD_S / 2 <= f.t <= T_FAULT_S + 3.0 + PERIOD_S / 2
        if f.enabled:
            occurred += 1
            assert (dr.values["fault.cmg.t"], dr.values["fault.cmg.unit"]) == (f.t, f.unit)
        else:
            assert math.isnan(dr.values["fault.cmg.t"]) and math.isnan(dr.values["fault.cmg.unit"])
    sd = math.sqrt(N_DRAWS * P_OCCUR * (1 - P_OCCUR))
    assert abs(occurred - N_DRAWS * P_OCCUR) <= BINOMIAL_SIGMAS * sd


def test_montecarlo_sample_flies_what_was_drawn():
    from stationbed.studies.montecarlo.dispersions import draw

    scene = scene_from_dict(study(probability=0.5))
    nominal = simulate(scene_from_dict(box()), fused=True)
    seen = set()
    for k in range(12):
        s, dr, _, _ = draw(scene, k)
        tr = simulate(s, fused=True)
        if s.fault[0].enabled:  # the drawn fault, at its drawn time
            assert tr.meta["summary"]["faults"] == [dict(fault="cmg", kind="cmg_failed", unit=s.fault[0].unit, t=s.fault[0].t)]
        else:  # a fault that did not occur changes nothing, bit for bit
            assert tr.meta["summary"]["faults"] == []
            assert np.array_equal(tr.data[:, :-1], nominal.data)
        seen.add(s.fault[0].enabled)
    assert seen == {True, False}


@pytest.mark.parametrize("t_fault", [20.0, 20.3], ids=["on_the_probe_grid", "off_the_probe_grid"])
def test_faults_with_the_environment_rate_probe(t_fault, tmp_path, monkeypatch):
    """``environment_rate = "auto"`` probes the scene with a nested run at a 1 s tick before the
    run flies: the probe flies without the faults (a fault at 20.3 s is off its grid), and the
    compiled calls' buffers it shares with the run keep the run's nominal numbers, so the fused
    and the per-tick run of the faulted scene agree (the probe fresh, run by the first)."""
    from stationbed.run import rate_auto
    from stationbed.scene import load_scene

    (tmp_path / "cache").mkdir()
    monkeypatch.setattr(rate_auto, "cache_dir", lambda: tmp_path / "cache")
    monkeypatch.setattr(rate_auto, "_CHOICES", type(rate_auto._CHOICES)())
    monkeypatch.setattr(rate_auto, "_BY_ID", type(rate_auto._BY_ID)())
    scene = load_scene("scenarios/iss_lvlh_hold.toml").replace(
        {"simulation.duration": 60.0, "fault": [{"t": t_fault, "kind": "cmg_failed", "unit": 2}]})
    fused = simulate(scene, fused=True)
    per_tick = simulate(scene, fused=False)
    assert fused.meta["summary"]["environment_rate_ticks"] > 0  # the probe ran and chose a held rate
    assert_allclose(fused.data, per_tick.data, rtol=1e-12, atol=1e-9)


def test_fault_events_on_the_rerun_time_line():
    """The recording's ``events`` log marks each change of ``faults_active`` at its row's time."""
    from stationbed.output.rerun.events import Events

    tr = run(box([CMG_FAULTS["gimbal_stuck"], dict(CMG_FAULTS["cmg_failed"], t=5.0)]), "fused")
    got = Events(tr.columns).changes(tr)
    assert [e for e in got if "fault" in e[2]] == [(T_FAULT_S, "WARN", "faults active: 1"), (5.0, "WARN", "faults active: 2"),
                                                 (7.0, "INFO", "faults active: 1")]


def test_every_truth_kind_has_an_effect_and_a_balance_test():
    """A CMG or thruster fault kind registered without its effect, or left out of the tests above
    (the momentum balance, the split run, the thrusters' ledger), fails here."""
    from stationbed.run.faults import FAULT_EFFECTS
    from stationbed.scene.faults import FAULT_KINDS

    truth = {n for n, k in FAULT_KINDS.items() if k.target in ("cmg", "thruster")}
    assert truth <= set(FAULT_EFFECTS)
    assert truth <= set(CMG_FAULTS) | {"thruster_stuck_on", "thruster_stuck_off"}


def test_run_line_names_the_faults():
    from stationbed.cli import _summary_line

    tr = run(box([CMG_FAULTS["gimbal_stuck"], dict(CMG_FAULTS["cmg_failed"], t=5.0)]), "fused")
    assert "faults: gimbal_stuck 1 at 4 s, cmg_failed 2 at 5 s, gimbal_stuck 1 at 7 s cleared" in _summary_line(tr.meta["summary"])


#: the executors on the flight loop (gyros, star trackers, MEKF): measured 9e-11 relative over
#: 120 s; a step missed or a tick late by one executor is of order 1 relative in h
FLIGHT_REL = 1e-8


def test_faults_on_the_flight_loop_every_executor():
    """With ``[[sensor]]`` tables and the MEKF (the estimator flies through the step, its own
    numbers untouched), the fused loop, the per-tick loop and the lockstep batch fly the same
    faulted run: the sensing block's memory and draws go on across the step on each."""
    from stationbed.scene import load_scene

    scene = load_scene("scenarios/iss_lvlh_hold_estimated.toml").replace({"simulation.duration": 60.0, "fault": [
        {"t": 20.0, "kind": "cmg_failed", "unit": 2}, {"t": 30.0, "until": 45.0, "kind": "gimbal_rate_limit", "unit": 1,
                                                        "limit": 0.001}]})
    fused, per_tick = simulate(scene, fused=True), simulate(scene, fused=False)
    (kind, batch), _ = run_lockstep([scene, scene], fused=False, keep=True)
    assert fused.meta["summary"]["fused"] and kind == "batch"
    for tr in (fused, batch):
        assert_allclose(tr.data, per_tick.data, rtol=FLIGHT_REL, atol=FLIGHT_REL)
