"""A law's own state carried by the compiled loops (stationbed/run/law_state.py, issue 22).

Truths, none of them the compiled loop's code:

* the held command, summed by hand (test_closed_loop_balance's ``held_command_impulse``): a law
  whose state is its tick count commands ``τ(k T)`` at tick k; with no cluster the momentum at
  every row is ``Σ τ_k Δt_k`` plus the windows' impulse, on every executor (a state carried one
  tick late, or not masked in a chunk's tail, shifts the hold by a tick: >= 0.35 N m s);
* the law's Python ``_update`` called every tick (the per-tick loop): ``momentum_manager`` fused
  flies the same rows to round-off, and hands back the same state (its integral ``z``, the TEA it
  found), so its summary is the per-tick run's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.run.controller import Controller, ControllerError
from stationbed.run.lockstep import run_lockstep
from stationbed.scene import scene_from_dict
from test_closed_loop_balance import (CLOSED, CLOSED_FORM_ABS, PERIOD_S, held_command_impulse,
                                      sphere_scene, tau_x, window_impulse_x)

#: the same float operations compiled as two programs (the fused loop's C vs CPython and the
#: per-tick compiled tick): the law's own arithmetic is the same sequence (no FMA at gcc -O2
#: without -march), the RK4 step is grouped differently (one mapaccum vs one call per tick);
#: measured 4e-12 over 6000 s, a stable loop does not amplify it
FUSED_RTOL = 1e-9
MM_SCENE = ROOT / "scenarios" / "iss_tea_momentum_management.toml"
#: past the first orbit's end (5553.6 s): the TEA average is taken once
MM_DURATION_S = 6000.0


class CountedSine(Controller):
    """``τ_x = TAU_AMP sin(TAU_W k T)`` at tick k, where k is the law's own state (ticks so far),
    in Python and in casadi (``symbolic_state``)."""

    name = "counted_sine"
    command = "torque"

    def _reset(self, plant):
        self.k = 0.0

    def _update(self, t, meas):
        tau = tau_x(self.k * self.period)
        self.k += 1.0
        return (tau, 0.0, 0.0)

    def symbolic_params(self):
        return [self.period]

    def symbolic_state(self):
        return [self.k]

    def set_symbolic_state(self, s):
        self.k = float(s[0])

    def symbolic(self, t, y, cp, s):
        import casadi as ca

        return ca.vertcat(tau_x(s[0] * cp[0]), 0.0, 0.0), ca.DM([1.0, 0.0, 0.0, 0.0]), s[0] + 1.0


@pytest.mark.parametrize("executor", list(CLOSED))
@pytest.mark.parametrize("windows", [[], [(5.0, 12.0)], [(5.03, 12.07)]], ids=["none", "on_grid", "off_grid"])
def test_a_carried_state_acts_over_its_own_tick(executor, windows):
    """No cluster: ΔH_N at every row is the hand-summed hold of τ(k T) plus the windows; the last
    period is short (10.05 s); the fused loop's chunks (5 ticks a row) are split at the edges (a tick
    holding one off the grid a piece of its own).
    The law's count at the end is the ticks updated (K + 1), on every executor."""
    integrator, override, fused = CLOSED[executor]
    duration = 10.05
    d = sphere_scene(windows, integrator=integrator, cmg=False, duration=duration)
    d["controller"] = {"name": "counted_sine", "period": PERIOD_S}
    d["simulation"]["output_dt"] = 0.5
    law = CountedSine(period=PERIOD_S)
    tr = simulate(scene_from_dict(d), integrator=override, controller=law, fused=fused)
    assert tr.meta["summary"]["fused"] == (executor == "fused")  # (an edge between ticks: the edge tick's case)
    dH = tr.H_O_N - tr.H_O_N[0]
    expect = held_command_impulse(tr.t, duration) + window_impulse_x(windows, tr.t)
    assert_allclose(dH[:, 0], expect, rtol=0, atol=CLOSED_FORM_ABS)
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)
    assert law.k == math.ceil(duration / PERIOD_S - 1e-9) + 1 == law.n_updates


def _mm_runs(scene):
    laws = [build(scene) for _ in range(2)]
    return [simulate(scene, fused=f, controller=c) for f, c in zip((True, False), laws)], laws


def build(scene):
    from stationbed.run.laws import build_controller  # noqa: PLC0415

    return build_controller(scene.controller)


def _same_to_round_off(a, b):
    assert a.columns == b.columns
    assert np.array_equal(np.isnan(a.data), np.isnan(b.data))
    scale = np.maximum(np.abs(b.data).max(axis=0), 1e-300)
    rel = np.nan_to_num(np.abs(a.data - b.data), nan=0.0) / scale
    assert rel.max() <= FUSED_RTOL, f"{b.columns[int(np.argmax(rel.max(axis=0)))]}: {rel.max():.2e}"


def test_momentum_manager_fused_is_its_per_tick_run_and_summary():
    """iss_tea_momentum_management for 6000 s (past one orbit): momentum_manager runs fused, and
    its rows, integral state and TEA found are the per-tick run's to round-off; the summary has
    the same keys and the same counts."""
    scene = load_scene(MM_SCENE).replace({"simulation.duration": MM_DURATION_S})
    (fused, tick), (cf, ct) = _mm_runs(scene)
    assert fused.meta["summary"]["fused"] is True and tick.meta["summary"]["fused"] is False
    _same_to_round_off(fused, tick)
    sf, st = fused.meta["summary"], tick.meta["summary"]
    assert sf.keys() == st.keys() - {"not_fused"} and "mm_tea_found_deg" in sf  # (per tick: says why)
    assert_allclose(sf["mm_tea_found_deg"], st["mm_tea_found_deg"], rtol=FUSED_RTOL)
    assert_allclose(cf.z, ct.z, rtol=FUSED_RTOL)
    assert (cf._count, cf._next_orbit, cf.n_updates) == (ct._count, ct._next_orbit, ct.n_updates)


def test_momentum_manager_fused_with_sensors_and_mekf():
    """The estimated scenario (gyro, star trackers, MEKF; run/composed.py) with
    momentum_manager, 60 s: fused and per tick fly the same rows and end in the same state."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace(
        {"simulation.duration": 60.0, "simulation.output_dt": 1.0, "controller.name": "momentum_manager",
         "controller.params": {}})
    (fused, tick), (cf, ct) = _mm_runs(scene)
    assert fused.meta["summary"]["fused"] is True and tick.meta["summary"]["fused"] is False
    _same_to_round_off(fused, tick)
    assert np.abs(ct.z).max() > 0
    assert_allclose(cf.z, ct.z, rtol=FUSED_RTOL)
    assert cf.n_updates == ct.n_updates


def test_lockstep_runs_momentum_manager_fused_with_its_single_runs_numbers():
    """run_lockstep picks ``fused`` for momentum_manager (it has a symbolic form now), and each
    sample is its single run, bit for bit (the same loop)."""
    base = load_scene(MM_SCENE).replace({"simulation.duration": 3.0, "simulation.output_dt": 1.0})
    inertia = np.array(base.body.inertia)
    scenes = [base.replace({"body.inertia": (inertia * (1.0 + 0.03 * k)).tolist()}) for k in range(2)]
    res = run_lockstep(scenes, keep=True)
    for s, (kind, tr) in zip(scenes, res):
        assert kind == "fused"
        single = simulate(s)
        assert np.array_equal(tr.data, single.data, equal_nan=True)
        assert tr.meta["summary"] == single.meta["summary"]


class NoSetter(CountedSine):
    name = "no_setter"
    set_symbolic_state = None


class BadState(CountedSine):
    name = "bad_state"

    def symbolic(self, t, y, cp, s):
        cmd, q, _ = super().symbolic(t, y, cp, s)
        return cmd, q, [s[0], s[0]]


@pytest.mark.parametrize("law,match", [
    (NoSetter, r"controller 'no_setter': has symbolic_state\(\) but no set_symbolic_state"),
    (BadState, r"controller 'bad_state': symbolic\(\) returned a state of 2 values, expected 1"),
], ids=["no_setter", "state_size"])
def test_a_broken_state_contract_names_the_controller(law, match):
    d = sphere_scene([], cmg=False, duration=1.0)
    d["controller"] = {"name": law.name, "period": PERIOD_S}
    with pytest.raises(ControllerError, match=match):
        simulate(scene_from_dict(d), controller=law(period=PERIOD_S), fused=True)


def test_the_readmes_law_with_a_state_flies_fused_as_per_tick(tmp_path):
    """The README's RateIntegral, as printed: fused (its state carried) and per tick give the
    same rows and the same final integral, on the rate-damped sphere of the balance tests."""
    import re  # noqa: PLC0415

    section = (ROOT / "docs" / "controllers" / "compile.md").read_text()  # the README's section, now a page
    (tmp_path / "rate_integral.py").write_text(re.search(r"```python\n(.*?)```", section, re.S).group(1))
    d = sphere_scene([(2.0, 6.0)], cmg=True, duration=20.0)
    d["initial"]["omega_BN_B"] = [2e-3, -1e-3, 5e-4]
    d["controller"] = {"name": f"{tmp_path / 'rate_integral.py'}:RateIntegral", "period": PERIOD_S}
    scene = scene_from_dict(d)
    laws = [build(scene) for _ in range(2)]
    fused, tick = (simulate(scene, fused=f, controller=c) for f, c in zip((True, False), laws))
    assert fused.meta["summary"]["fused"] is True and tick.meta["summary"]["fused"] is False
    _same_to_round_off(fused, tick)
    assert np.abs(laws[1].z).max() > 1e-4
    assert_allclose(laws[0].z, laws[1].z, rtol=FUSED_RTOL)


@pytest.mark.parametrize("fused", [True, False], ids=["fused", "batch"])
def test_a_carried_state_in_the_lockstep_executor(fused):
    """run_lockstep of three CountedSine samples (windows shifted per sample): fused (each
    sample's own fused loop, its state carried) or batch (the default update_batch: each
    member's _update keeps its state); every sample meets the hand-summed hold."""
    import stationbed.run.closed_loop as cl  # noqa: PLC0415

    duration = 10.05
    wins = [[((50 + k) * PERIOD_S, 12.0)] for k in range(3)]  # on the tick grid: the fused loop takes them
    scenes = []
    for w in wins:
        d = sphere_scene(w, cmg=False, duration=duration)
        d["controller"] = {"name": "counted_sine", "period": PERIOD_S}
        d["simulation"]["output_dt"] = 0.5
        scenes.append(scene_from_dict(d))
    orig = cl.build_controller
    cl.build_controller = lambda spec, base_dir=None: CountedSine(period=spec.period)
    try:
        if fused:
            res = run_lockstep(scenes, keep=True, fused=True)
        else:  # the batch itself: executor() sends a law with only _update per tick (run/lockstep.py)
            from stationbed.run.lockstep import _Lockstep, _Sample  # noqa: PLC0415
            from stationbed.run.simulation import SimulationError  # noqa: PLC0415

            res = [("batch", tr) for tr in _Lockstep([_Sample(s, None, True, False) for s in scenes]).run(SimulationError)]
    finally:
        cl.build_controller = orig
    for w, (kind, tr) in zip(wins, res):
        assert kind == ("fused" if fused else "batch")
        dH = tr.H_O_N - tr.H_O_N[0]
        expect = held_command_impulse(tr.t, duration) + window_impulse_x(w, tr.t)
        assert_allclose(dH[:, 0], expect, rtol=0, atol=CLOSED_FORM_ABS)
        assert tr.meta["summary"]["controller_updates"] == math.ceil(duration / PERIOD_S - 1e-9) + 1


def test_a_carried_state_through_the_held_environment_blocks():
    """The fused loop with the environment at its own rate (the composed loop's env block: blocks of 7 ticks,
    the law's state in the carry beside x): every row's commanded torque is τ(k T) of its own
    tick k, and the count at the end is K + 1 (a state lost or shifted at a block edge breaks
    both)."""
    from test_closed_loop_balance import kinds_scene  # noqa: PLC0415

    d = kinds_scene([])
    d["simulation"].update(duration=12.0, environment_rate=7, output_dt=2.0)  # rows of 20 ticks: blocks 7, 7, 6
    d["controller"] = {"name": "counted_sine", "period": PERIOD_S}
    law = CountedSine(period=PERIOD_S)
    tr = simulate(scene_from_dict(d), controller=law, fused=True)
    s = tr.meta["summary"]
    assert s["fused"] is True and s["environment_rate_ticks"] == 7
    k_rows = np.round(tr.t / PERIOD_S)
    assert_allclose(tr.data[:, tr.columns.index("tau_cmd_x")], [tau_x(k * PERIOD_S) for k in k_rows], rtol=0, atol=0)
    assert law.k == round(12.0 / PERIOD_S) + 1


def test_margins_refuse_a_law_with_a_state_naming_it():
    """The loop analysis closes a stateless law (u = -K x); momentum_manager's integral state is
    outside it: a one-line error naming the controller (its own design reports its margins)."""
    from stationbed.analysis.margins import loop_analysis  # noqa: PLC0415

    with pytest.raises(ValueError, match=r"^margins: controller 'momentum_manager' keeps a state between ticks"
                                         r" \(symbolic_state\)[^\n]*$"):
        loop_analysis(load_scene(MM_SCENE))
