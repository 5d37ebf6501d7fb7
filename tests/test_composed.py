"""The loop composed once from its blocks (issue 33: loop/block.py, loop/compose.py, run/composed.py).

Independent truths:

* the composer knows no block: a toy plant ``ẋ = -a x + u`` with a toy law ``cmd = -k x``
  held over the tick (zero-order hold) composed into one tick is RK4 on an affine system,
  whose step is the closed form ``R(z) x + h u (1 + z/2 + z²/6 + z³/24)``, ``z = -a h``,
  ``R(z) = 1 + z + z²/2 + z³/6 + z⁴/24``, ``u = -k x``, written here;
* the full flight loop (``scenarios/iss_full_flight_loop.toml``: sensors, MEKF,
  ``momentum_manager`` with its state, 16 assist thrusters, the CMG cluster) flown fused is the
  per-tick loop's run (the law in Python, each block compiled on its own) to round-off, and
  keeps the momentum balance ``ΔH_N = ∫ C_NB L dt`` with the thrusters' impulses summed here
  from their logged on-times and the scene's geometry (``r × F ĝ``);
* the composed loop replaced the hand-composed fused loops (fused.py's, fused_flight.py,
  thrust_fused.py) after giving their rows bit for bit on every combination they flew (the
  test that showed it went with them: docs/design.md "One loop, built once"); every shipped
  scenario's CSV is byte-identical to before.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from balance_helpers import C_NB, logged_torques_B, torque_integral_N
from stationbed import load_scene, simulate
from stationbed.core.layout import Layout
from stationbed.integrators import RK4
from stationbed.loop.block import Block
from stationbed.loop.compose import Plant, compose

ROOT = Path(__file__).resolve().parents[1]
FULL = ROOT / "scenarios" / "iss_full_flight_loop.toml"
#: fused (generated C, the law's symbolic form) vs per tick (the law in Python, each block's own
#: compiled call): the same expressions in another order; 2000 ticks. Measured 1e-10 (the NEES,
#: a ratio of small numbers), relative to max(|value|, 1)
EXEC_REL = 1e-8
#: the thrusters' impulses summed with the attitude at the start of their tick: the station turns
#: ~1e-4 rad in a tick (orbital rate 1.1e-3 rad/s), a pulse of 130 N x 40 m x 0.1 s is 520 N m s:
#: < 0.06 N m s per pulse, ~10 pulses; a pulse lost or misplaced is >= 130 N x 2.2 m x 0.03 s = 8.6 N m s
BALANCE_ABS = 2.0  # N m s
#: the closed form of one RK4 step against its evaluation: a few float64 roundings
CLOSED_FORM_REL = 1e-14


def _toy(k_gain: float):
    """A plant ``ẋ = -a x + u`` (3 states, u = u_ext, a = p), a law ``cmd = -k x`` (the truth row: x itself),
    an end that holds the command as ``u_ext``: blocks the composer has never seen."""
    x, u, p, t = ca.SX.sym("x", 3), ca.SX.sym("u", 3), ca.SX.sym("p", 1), ca.SX.sym("t")
    rhs = ca.Function("rhs", [t, x, u, p], [-p * x + u])
    meas = ca.Function("meas", [t, x, p], [x])
    M = Layout(q_BN=3)
    plant = Plant(meas, rhs, RK4.explicit_step, 3, 1, M, Layout(u_ext=3), ("toy",))
    k, h = ca.SX.sym("k"), ca.SX.sym("h")
    y, cp = ca.SX.sym("y", 3), ca.SX.sym("cp", 1)
    law = Block("law", "law", ca.Function("law", [k, t, h, ca.SX.sym("s", 0), y, ca.SX.sym("w", 0), cp],
                                          [ca.SX(0, 1), ca.vertcat(-cp * y, 1, 0, 0, 0)]),
                Layout(), Layout(cp=1), Layout(), Layout(y=3), Layout(cmd=3, q_ref=4), key=("toy_law",))
    ui = ca.SX.sym("u", 9)
    end = Block("end", "end", ca.Function("end", [k, t, h, ca.SX.sym("xe", 0), ui, ca.SX.sym("w", 0), p],
                                          [ca.SX(0, 1), ca.vertcat(ui[3:6] + ui[6:9], ca.SX.zeros(2))]),
                Layout(), Layout(p=1), Layout(), Layout(x=3, tau=3, u_ext=3), Layout(act=0, u=3, sat=2), key=("toy_end",))
    return compose(plant, [end, law])


def test_composer_knows_no_block_rk4_closed_form():
    """A toy plant and law composed into one tick: the closed form of RK4 on ``ẋ = -a x - k x0``."""
    k_gain, h, a = 0.7, 0.1, 2.0
    cm = _toy(k_gain)
    C, P = cm.carry, cm.par
    c0 = C.pack(i=0.0, x=[1.0, -2.0, 0.5], counts=[0.0, 0.0], law=np.zeros(0))
    par = P.pack(t0=0.0, h=h, n_act=1.0, k0=0.0, u_ext=np.zeros(3), p=[a], law=[k_gain])
    c1 = np.asarray(cm.tick()(c0, par, np.zeros(0))).ravel()
    z = -a * h
    x0 = np.array([1.0, -2.0, 0.5])
    expect = (1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) * x0 + h * (-k_gain * x0) * (1 + z / 2 + z**2 / 6 + z**3 / 24)
    assert_allclose(C.get(c1, "x"), expect, rtol=CLOSED_FORM_REL)
    assert C.get(c1, "i")[0] == 1.0
    c_hold = np.asarray(cm.tick()(c0, P.pack(t0=0.0, h=h, n_act=0.0, k0=0.0, u_ext=np.zeros(3), p=[0.0], law=[k_gain]),
                                  np.zeros(0))).ravel()
    assert_allclose(C.get(c_hold, "x"), [1.0, -2.0, 0.5], rtol=0)  # past the active ticks: held


def test_block_contract_refuses_a_step_of_another_shape():
    """A block whose step does not read (k, t, h, x, u, w, p) of its layouts' sizes is refused,
    naming it."""
    a = ca.SX.sym("a")
    f = ca.Function("f", [a], [a])
    with pytest.raises(ValueError, match="block 'bad'"):
        Block("bad", "law", f, Layout(), Layout(), Layout(), Layout(y=3), Layout(cmd=3, q_ref=4))


def test_a_block_that_is_not_symbolic_cannot_be_composed():
    """A Python law is a block with ``symbolic = False``: the composer names it and its reason
    when asked for the whole tick; the parts around it (what the per-tick loop calls) compose."""
    cm = _toy(1.0)
    law = cm.law_block
    py = Block("law", "law", law.step, law.state, law.params, law.noise, law.inputs, law.outputs, symbolic=False,
               why="a Python law")
    c = compose(cm.plant, [py, cm.end])
    assert c.blocker is py
    for whole in (c.tick, c.row):
        with pytest.raises(ValueError, match="block 'law' is not symbolic \\(a Python law\\)"):
            whole()
    assert c.sense_part().n_out() == 3 and c.act_part().n_out() == 5


def _short(path, duration, **over):
    s = load_scene(path).replace({"simulation.duration": duration, **over})
    return s


def _rel(a, b):
    return np.nanmax(np.abs(a - b) / np.maximum(np.abs(a), 1.0))


@pytest.fixture(scope="module")
def full_runs():
    s = _short(FULL, 200.0, **{"simulation.output_dt": 0.1})
    return s, simulate(s, fused=False), simulate(s, fused=True)


def test_full_flight_loop_flies_fused_as_per_tick(full_runs):
    """Sensors + MEKF + momentum_manager + thrusters + CMGs: fused (the summary says so), the
    thrusters fire, and every column is the per-tick loop's to round-off."""
    _, a, b = full_runs
    sm = b.meta["summary"]
    assert sm["fused"] and not a.meta["summary"]["fused"] and "thrusters_not_fused" not in sm
    assert sm["thruster_firings"] > 0 and sm["thruster_firings"] == a.meta["summary"]["thruster_firings"]
    assert a.columns == b.columns and np.array_equal(np.isnan(a.data), np.isnan(b.data))
    assert _rel(a.data, b.data) < EXEC_REL


def _thruster_impulse_N(scene, tr) -> np.ndarray:
    """Σ over ticks of C_NB(tick start) Σ_j (r_j × F_j ĝ_j) Δt_on,j, cumulative per row (rows
    are ticks here): the on-times from the logged columns, the arms from the scene."""
    D = np.array([np.cross(t.position_B, np.asarray(t.direction_B) / np.linalg.norm(t.direction_B)) * t.force_N
                  for t in scene.thruster])  # (n, 3)
    on = tr.data[:, [tr.columns.index(f"thr_on_s_{t.name}") for t in scene.thruster]]
    d_on = np.diff(on, axis=0)  # the on-times of the tick starting at row i
    imp_B = d_on @ D
    imp_N = np.array([C_NB(q) @ v for q, v in zip(tr.q_BN[:-1], imp_B)])
    return np.vstack([np.zeros(3), np.cumsum(imp_N, axis=0)])


@pytest.mark.parametrize("which", ["per_tick", "fused"])
def test_full_flight_loop_keeps_the_momentum_balance(full_runs, which):
    """ΔH_N = ∫ C_NB (L_gg + L_aero + L_srp) dt (trapezoids over the 0.1 s rows, the logged torque
    columns, proved in test_gravity_gradient/test_aero/test_srp) + the thrusters' impulses summed
    here (:func:`_thruster_impulse_N`)."""
    scene, a, b = full_runs
    tr = {"per_tick": a, "fused": b}[which]
    smooth = torque_integral_N(tr, logged_torques_B(tr))
    thr = _thruster_impulse_N(scene, tr)
    assert np.abs(thr[-1]).max() > 10 * BALANCE_ABS  # the thrusters' share is seen
    assert_allclose(tr.H_O_N - tr.H_O_N[0], smooth + thr, rtol=0, atol=BALANCE_ABS)


def test_the_summary_names_the_one_block_off_the_fused_path():
    """A run that cannot fly fused says why in one place (``not_fused``, run/fused.py
    ``why_not_fused``), naming the block: the law without a symbolic form, the thrusters' LP
    mapping; a fused run has no such key; a run asked per tick says so."""
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    from test_thrusters import pods, sphere  # noqa: PLC0415

    s = _short(ROOT / "scenarios" / "iss_lvlh_hold.toml", 2.0)
    assert "not_fused" not in simulate(s).meta["summary"]
    assert simulate(s, fused=False).meta["summary"]["not_fused"] == "fused = False asked"
    py = s.replace({"controller.name": "example_hold", "controller.params": {"reference": "lvlh"}})
    assert simulate(py).meta["summary"]["not_fused"].startswith("law: controller 'example_hold' has no symbolic form")
    lp = sphere(pods(), duration=2.0, mapping="lp")
    sm = simulate(lp).meta["summary"]
    assert sm["not_fused"].startswith("thrusters: mapping = 'lp'") and "lp" in sm["thrusters_not_fused"]
