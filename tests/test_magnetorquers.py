"""Magnetic torquers (issue 33 item 6: stationbed/loop/magnetorquers.py, the worked example of a
new actuator), each claim against an independent truth:

* the dipole field against its closed form: ``|B| = B0 (R/r)³`` pointing north over the
  equator, ``2 B0 (R/r)³`` pointing down over the north pole, ``B0 (R/r)³ √(1 + 3 sin² λ)`` at
  latitude λ;
* one tick against ``m × B`` worked by hand for a known field and attitude (B along the body's y
  axis: the rods make the request's x and z parts, the y part is left to the chain), a rod at
  its limit, and the torque made in the *true* field while the dipole is chosen in the known one;
* the momentum balance over a run: ``ΔH_N = Σ_ticks C_NB (m × B_B) h`` with the dipoles from
  the logged ``mtq_m_*`` columns and the field computed here at the orbit's position (a sphere on
  a momentum store: the rods' torque is the only external one), per tick and fused; with the
  ideal torquer at the chain's end, the rods plus what they leave are exactly the law's request;
* the full flight loop plus the rods (the shipped scenario): fused = per tick = lockstep to
  round-off, the chain in order (rods, thrusters, then the CMGs), and its momentum balance with
  the environment torques' columns and the rods' impulses summed here.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from balance_helpers import C_NB, logged_torques_B, torque_integral_N
from stationbed import load_scene, simulate
from stationbed.loop.actuator import chain_kinds
from stationbed.loop.magnetorquers import B0_T, R_REF_M, Magnetorquers
from stationbed.scene import SceneError, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenarios" / "iss_full_flight_loop_magnetorquers.toml"
PERIOD_S = 0.1  # s
R_ORBIT_M = R_REF_M + 400.0e3  # m
M_MAX_AM2 = 1000.0  # A m², each rod (the sphere's)
#: the field's closed form against its casadi evaluation: a few float64 roundings
FIELD_REL = 1e-14
#: one tick's torque by hand against the compiled tick: cross products of ~1e-5 T and ~1e3 A m²
TORQUE_ABS = 1e-15  # N m
#: a dipole by hand against the compiled tick: cos(45 deg) rounded puts ~1e-16 of b off the y
#: axis, ~1e-16 x 1e3 / 1e-4 relative in the dipole's other components
DIPOLE_ABS = 1e-9  # A m²
#: the balance on the sphere: the held B-frame torque summed with C_NB at the tick's start while
#: the sphere turns (< 1e-3 rad/s; 6e-4 seen): < |τ| ω h² / 2 = 0.03 x 1e-3 x 0.01 / 2 = 1.5e-7 N m s per tick,
#: 600 ticks: 1e-4 (measured 1.1e-5); the rods' impulse over the run is 0.63 N m s (checked to be seen)
SPHERE_BALANCE_ABS = 2e-4  # N m s
#: the sphere at rest with the thrusters (rates < 1e-5 rad/s): a 2000 N m pulse held in B while
#: it turns, 2000 x 1e-5 x 0.01 / 2 = 1e-7 N m s per tick at most (measured 2.6e-8 in all)
THR_BALANCE_ABS = 1e-6  # N m s
#: the balance of the full loop with the rods (20 s, rows every tick): the rods' torque held in B
#: while LVLH turns at orbital rate, < |τ| ω h² / 2 = 0.12 N m x 1.1e-3 rad/s x 0.01 s² / 2 per
#: tick over 200 ticks = 1.3e-4 N m s (measured 1.1e-4), plus the trapezoids of the smooth
#: torques' 91 N m s (~1e-8); the rods' impulse is 2.4 N m s
FULL_BALANCE_ABS = 5e-4  # N m s
#: fused (generated C) against per tick (each block compiled on its own): the same expressions in
#: another order; measured 2e-11 on 20 s of the full loop (the NEES, a ratio of small numbers)
EXEC_REL = 1e-8


def _dipole_hand(r_N) -> np.ndarray:
    """The axial dipole (moment along -z_N) written here: B0 (R/r)³ (3 (m̂·r̂) r̂ - m̂)."""
    r = np.asarray(r_N, dtype=float)
    rn = np.linalg.norm(r)
    m_hat = np.array([0.0, 0.0, -1.0])
    return B0_T * (R_REF_M / rn) ** 3 * (3.0 * m_hat.dot(r / rn) * r / rn - m_hat)


def _field(r_N) -> np.ndarray:
    import casadi as ca

    from stationbed.loop.magnetorquers import dipole_field_N

    r = ca.SX.sym("r", 3)
    return np.asarray(ca.Function("B", [r], [dipole_field_N(r, B0_T, R_REF_M)])(r_N)).ravel()


@pytest.mark.parametrize("lat_deg, expect_dir", [(0.0, (0.0, 0.0, 1.0)), (90.0, (0.0, 0.0, -1.0)), (45.0, None)],
                         ids=["equator", "north_pole", "lat45"])
def test_dipole_field_closed_form(lat_deg, expect_dir):
    """|B| = B0 (R/r)³ √(1 + 3 sin² λ): B0 (R/r)³ north over the equator, twice that down over the pole."""
    lat = math.radians(lat_deg)
    r_N = R_ORBIT_M * np.array([math.cos(lat) * math.cos(0.3), math.cos(lat) * math.sin(0.3), math.sin(lat)])
    B = _field(r_N)
    scale = B0_T * (R_REF_M / R_ORBIT_M) ** 3  # T
    assert_allclose(np.linalg.norm(B), scale * math.sqrt(1.0 + 3.0 * math.sin(lat) ** 2), rtol=FIELD_REL)
    if expect_dir is not None:
        assert_allclose(B / np.linalg.norm(B), expect_dir, rtol=0, atol=FIELD_REL)


def _tick(q_known, q_true, tau_B):
    """One tick of 1000 A m² rods on the equator (B_N = b ẑ_N), the field known at ``q_known``,
    felt at ``q_true``."""
    act = Magnetorquers([M_MAX_AM2] * 3)
    r_N = [R_ORBIT_M, 0.0, 0.0]
    r = np.concatenate([q_known, r_N, q_true, r_N])  # READS: q_BN, r_N, q_BN_true, r_N_true
    x1, rest, on_s, torque, out = act.command(0.0, PERIOD_S, act.x0, r, np.asarray(tau_B, dtype=float))
    return x1, rest, on_s, torque[:, 0], act


Q_X90 = [math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0]  # B turned +90 deg about x: ẑ_N = ŷ_B
B_EQ_T = B0_T * (R_REF_M / R_ORBIT_M) ** 3  # T, over the equator


def test_tick_is_m_cross_b_by_hand():
    """B_B = (0, b, 0): m = B × τ / b² = (τz/b, 0, -τx/b), m × B = (τx, 0, τz); the rest (0, τy, 0)."""
    tau = np.array([0.01, 0.02, 0.02])  # N m
    x1, rest, on_s, torque, act = _tick(Q_X90, Q_X90, tau)
    b = B_EQ_T
    m = np.array([tau[2] / b, 0.0, -tau[0] / b])  # A m², inside the rods' 1000
    assert np.abs(m).max() < M_MAX_AM2
    assert_allclose(act.state.get(x1, "m_B"), m, rtol=0, atol=DIPOLE_ABS)
    assert_allclose(torque, [tau[0], 0.0, tau[2]], rtol=0, atol=TORQUE_ABS)
    assert_allclose(rest, [0.0, tau[1], 0.0], rtol=0, atol=TORQUE_ABS)
    assert_allclose(on_s, [PERIOD_S], rtol=0)  # one channel, the whole tick
    assert_allclose(act.state.get(x1, "dipole_Am2s"), np.abs(m).sum() * PERIOD_S, rtol=1e-12)


def test_a_rod_at_its_limit_makes_less_and_leaves_the_rest():
    """τx = 0.2 N m needs m_z = -τx/b ~ -8200 A m²: clipped to -1000, torque_x = 1000 b."""
    tau = np.array([0.2, 0.0, 0.01])  # N m
    x1, rest, _, torque, act = _tick(Q_X90, Q_X90, tau)
    b = B_EQ_T
    assert_allclose(act.state.get(x1, "m_B"), [tau[2] / b, 0.0, -M_MAX_AM2], rtol=0, atol=DIPOLE_ABS)
    assert_allclose(torque, [M_MAX_AM2 * b, 0.0, tau[2]], rtol=0, atol=TORQUE_ABS)
    assert_allclose(rest, tau - torque, rtol=0, atol=TORQUE_ABS)
    assert act.state.get(x1, "clipped_s")[0] == PERIOD_S


def test_dipole_chosen_in_the_known_field_torque_made_in_the_true_one():
    """Flight software thinks B ∥ ŷ_B (attitude 90 deg about x), the station sits at identity
    (B ∥ ẑ_B): the torque is m × (0, 0, b) = (0, -m_x b, 0); the rest is what flight software
    believes is left, (0, τy, 0)."""
    tau = np.array([0.01, 0.02, 0.02])  # N m
    _, rest, _, torque, _ = _tick(Q_X90, [1.0, 0.0, 0.0, 0.0], tau)
    m_x = tau[2] / B_EQ_T
    assert_allclose(torque, [0.0, -m_x * B_EQ_T, 0.0], rtol=0, atol=TORQUE_ABS)
    assert_allclose(rest, [0.0, tau[1], 0.0], rtol=0, atol=TORQUE_ABS)


#: four thrusters at y = ±20 m firing ±z: two couples about body x (100 N: ±2000 N m)
X_COUPLES = [{"name": n, "position_B": [0.0, y, 0.0], "direction_B": [0.0, 0.0, z], "force_N": 100.0, "isp_s": 280.0} for n, y, z in (("a", 20.0, 1.0), ("b", 20.0, -1.0), ("c", -20.0, 1.0), ("d", -20.0, -1.0))]


def sphere(cmg: bool = True, duration: float = 60.0, thrusters: bool = False):
    """A 1e4 kg m² sphere in a 400 km orbit (no gravity gradient: a sphere has none) holding an
    inertial attitude with pd, 1000 A m² rods first in the chain, a momentum store (or the ideal
    torquer) at its end; with ``thrusters``, :data:`X_COUPLES` between them dumping the store's
    90 N m s about x from t = 0 (the sphere at rest: the held torques do not turn with it)."""
    d = {
        "name": "mtq_sphere",
        "simulation": {"duration": duration, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"q_BN": [0.9998054810811952, 0.01, -0.015, 0.008], "omega_BN_B": [2e-4, -1e-4, 3e-4]},
        "body": {"mass": 1.0e3, "inertia": [[1.0e4, 0, 0], [0, 1.0e4, 0], [0, 0, 1.0e4]]},
        "orbit": {"altitude": 400.0e3, "inclination": 0.9, "u0": 0.3, "gravity_gradient": False},
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}},
        "magnetorquers": {"max_dipole_Am2": [M_MAX_AM2] * 3},
    }
    if cmg:
        d["cmg"] = {"kind": "ideal", "max_momentum": 100.0}
    if thrusters:
        d["initial"] = {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]}
        d["cmg"]["h0_B"] = [90.0, 0.0, 0.0]
        d["thruster"] = X_COUPLES
        d["thrusters"] = {"dump_time_s": 1.0, "max_dump_torque_Nm": 1000.0}
    return scene_from_dict(d)


def _r_N(scene, t) -> np.ndarray:
    """The circular orbit's position: radius (cos u, sin u cos i, sin u sin i), u = u0 + n t."""
    o = scene.orbit
    u = o.u0 + o.mean_motion * np.asarray(t)
    ci, si = math.cos(o.inclination), math.sin(o.inclination)
    return o.radius_m * np.stack([np.cos(u), np.sin(u) * ci, np.sin(u) * si], axis=-1)


def _magnetic_impulse_N(scene, tr) -> np.ndarray:
    """Σ over ticks of C_NB(t_i) (m_i × C_BN(t_i) B_N(r_N(t_i))) h, cumulative per row (rows are
    ticks): ``m_i`` the dipole of the tick [t_i, t_i+1], logged at row i+1 (the memory before a
    row's tick)."""
    m = tr.cols("mtq_m_x", "mtq_m_y", "mtq_m_z")[1:]
    r = _r_N(scene, tr.t[:-1])
    C = np.array([C_NB(q) for q in tr.q_BN[:-1]])
    B_B = np.einsum("nji,nj->ni", C, np.array([_dipole_hand(ri) for ri in r]))  # C_BN = C_NB.T
    imp = np.einsum("nij,nj->ni", C, np.cross(m, B_B)) * np.diff(tr.t)[:, None]
    return np.vstack([np.zeros(3), np.cumsum(imp, axis=0)])


@pytest.fixture(scope="module")
def sphere_runs():
    s = sphere()
    return s, {"per_tick": simulate(s, fused=False), "fused": simulate(s, fused=True)}


@pytest.mark.parametrize("which", ["per_tick", "fused"])
def test_momentum_balance_with_the_rods(sphere_runs, which):
    """ΔH_N (body and store) = the rods' impulses summed here: the only external torque."""
    s, runs = sphere_runs
    tr = runs[which]
    assert tr.meta["summary"]["fused"] == (which == "fused")
    imp = _magnetic_impulse_N(s, tr)
    assert np.abs(imp[-1]).max() > 100 * SPHERE_BALANCE_ABS  # the rods' share is seen
    assert_allclose(tr.H_O_N - tr.H_O_N[0], imp, rtol=0, atol=SPHERE_BALANCE_ABS)


def test_sphere_fused_equals_per_tick(sphere_runs):
    _, runs = sphere_runs
    a, b = runs["per_tick"], runs["fused"]
    assert a.columns == b.columns
    assert np.nanmax(np.abs(a.data - b.data) / np.maximum(np.abs(a.data), 1.0)) < EXEC_REL


@pytest.mark.parametrize("fused", [False, True], ids=["per_tick", "fused"])
def test_with_the_ideal_torquer_rods_and_rest_are_the_request(fused):
    """No CMGs: the ideal torquer at the chain's end makes what the rods leave, so the station
    feels the law's whole request (the field known is the true one): ΔH_N = Σ C_NB τ_cmd h."""
    s = sphere(cmg=False, duration=20.0)
    tr = simulate(s, fused=fused)
    assert tr.meta["summary"]["fused"] == fused
    tau = tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")[:-1]
    C = np.array([C_NB(q) for q in tr.q_BN[:-1]])
    imp = np.vstack([np.zeros(3), np.cumsum(np.einsum("nij,nj->ni", C, tau) * np.diff(tr.t)[:, None], axis=0)])
    assert np.abs(tr.cols("mtq_m_x", "mtq_m_y", "mtq_m_z")).max() > 0  # the rods worked
    assert_allclose(tr.H_O_N - tr.H_O_N[0], imp, rtol=0, atol=SPHERE_BALANCE_ABS)


@pytest.mark.parametrize("fused", [False, True], ids=["per_tick", "fused"])
def test_rods_then_thrusters_keep_the_balance(fused):
    """Rods first, then four thrusters dumping the store's momentum (they fire while the rods act
    on every tick: the fused chain runs the thrusters' command where they are not idle):
    ΔH_N = the rods' impulses + Σ_j (r_j × F_j ĝ_j) t_on,j from the logged on-times, both summed here."""
    s = sphere(duration=20.0, thrusters=True)
    tr = simulate(s, fused=fused)
    assert tr.meta["summary"]["fused"] == fused and tr.meta["summary"]["thruster_firings"] > 0
    D = np.array([np.cross(t["position_B"], t["direction_B"]) * t["force_N"] for t in X_COUPLES])  # N m
    on = tr.data[:, [tr.columns.index(f"thr_on_s_{t['name']}") for t in X_COUPLES]]
    C = np.array([C_NB(q) for q in tr.q_BN[:-1]])
    thr = np.vstack([np.zeros(3), np.cumsum(np.einsum("nij,nj->ni", C, np.diff(on, axis=0) @ D), axis=0)])
    mag = _magnetic_impulse_N(s, tr)
    assert np.abs(mag[-1]).max() > 1e4 * THR_BALANCE_ABS and np.abs(thr[-1]).max() > 10.0  # N m s: both seen
    assert_allclose(tr.H_O_N - tr.H_O_N[0], thr + mag, rtol=0, atol=THR_BALANCE_ABS)


@pytest.fixture(scope="module")
def full_runs():
    s = load_scene(SCENE).replace({"simulation.duration": 20.0, "simulation.output_dt": PERIOD_S})
    return s, simulate(s, fused=False), simulate(s, fused=True)


def test_chain_in_order_rods_thrusters_then_cmgs(full_runs):
    """The scene's actuator tables in chain order (``ORDER``): the rods, the thrusters, then the
    end; the composer's blocks and the CSV columns in the same order."""
    from stationbed.run.blocks import run_blocks  # noqa: PLC0415
    from stationbed.run.closed_loop import ControlLoop  # noqa: PLC0415
    from stationbed.run.law_state import law_numbers  # noqa: PLC0415
    from stationbed.run.prepare import prepare  # noqa: PLC0415
    from stationbed.run.rows import Rows  # noqa: PLC0415
    from stationbed.run.segments import breakpoints  # noqa: PLC0415

    s, _, b = full_runs
    assert [k.kind for k in chain_kinds(s)] == ["magnetorquers", "thrusters"]
    run = prepare(s, s.simulation.formulation, s.simulation.integrator)
    bps, _ = breakpoints(s, 20.0)
    loop = ControlLoop(s, run.system, run.integrator, run.p, run.x0.copy(), Rows(s, run.system, run.p, None, True),
                       20.0, PERIOD_S, bps, lambda t, x: x, None, True)
    assert [a.kind for a in loop.comp.chain] == ["magnetorquers", "thrusters", "cmg_cluster"]
    cp = law_numbers(loop.comp.ctrl)
    assert [bl.name for bl in run_blocks(loop.comp, cp) if bl.role == "actuator"] == ["magnetorquers", "thrusters"]
    assert b.columns.index("mtq_m_x") < b.columns.index("thr_mode")


def test_full_loop_with_rods_flies_fused_as_per_tick(full_runs):
    """Sensors + MEKF + momentum_manager + rods + thrusters + CMGs: fused, equal to per tick."""
    _, a, b = full_runs
    assert b.meta["summary"]["fused"] and not a.meta["summary"]["fused"]
    assert b.meta["summary"]["magnetorquer_dipole_Am2s"] > 0
    assert a.columns == b.columns and np.array_equal(np.isnan(a.data), np.isnan(b.data))
    assert np.nanmax(np.abs(a.data - b.data) / np.maximum(np.abs(a.data), 1.0)) < EXEC_REL


@pytest.mark.parametrize("which", ["per_tick", "fused"])
def test_full_loop_with_rods_keeps_the_momentum_balance(full_runs, which):
    """ΔH_N = ∫ C_NB (L_gg + L_aero + L_srp) dt (trapezoids of the logged torque columns) + the
    rods' impulses summed here (:func:`_magnetic_impulse_N`, the true field at the true
    attitude; the dipoles were chosen on the MEKF's); no thruster fires in these 20 s."""
    s, a, b = full_runs
    tr = {"per_tick": a, "fused": b}[which]
    assert tr.meta["summary"]["thruster_firings"] == 0
    smooth = torque_integral_N(tr, logged_torques_B(tr))
    mag = _magnetic_impulse_N(s, tr)
    assert np.abs(mag[-1]).max() > 1000 * FULL_BALANCE_ABS  # the rods' share is seen
    assert_allclose(tr.H_O_N - tr.H_O_N[0], smooth + mag, rtol=0, atol=FULL_BALANCE_ABS)


def test_lockstep_flies_the_rods_as_simulate_does(full_runs):
    """The Monte Carlo's lockstep executor flies the rods' scene on the composed loop (fused) or
    in the batch (the composed parts mapped over the samples: every chain block, the rods and
    the thrusters), each the run simulate makes: the batch's samples are the per-tick run bit
    for bit (the same compiled parts), the fused run to round-off."""
    from stationbed.run.lockstep import run_lockstep  # noqa: PLC0415

    s, a, b = full_runs
    (k_f, tr_f), = run_lockstep([s], fused=True, keep=True)
    (k_1, tr_1), (k_2, tr_2) = run_lockstep([s, s], fused=False, keep=True)
    assert (k_f, k_1, k_2) == ("fused", "batch", "batch")
    assert np.array_equal(tr_f.data, b.data, equal_nan=True)
    for tr in (tr_1, tr_2):
        assert np.array_equal(tr.data, a.data, equal_nan=True)
        assert np.nanmax(np.abs(tr.data - b.data) / np.maximum(np.abs(b.data), 1.0)) < EXEC_REL


@pytest.mark.parametrize("change, field", [
    ({"magnetorquers.max_dipole_Am2": [1000.0, 0.0, 1000.0]}, "magnetorquers.max_dipole_Am2"),
    ({"magnetorquers.max_dipol_Am2": [1.0, 1.0, 1.0]}, "did you mean 'max_dipole_Am2'"),
    ({"orbit": None}, "magnetorquers: the Earth's field"),
], ids=["zero_rod", "typo", "no_orbit"])
def test_bad_scene_one_line(change, field):
    with pytest.raises(SceneError) as e:
        sphere().replace(change)
    assert field in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("path", ["stationbed/loop/magnetorquers.py", "stationbed/scene/magnetorquers.py"],
                         ids=["actuator", "scene_table"])
def test_the_worked_example_shows_the_whole_file(path):
    """docs/loop.md "Adding an actuator: a worked example" prints each file whole, as it is
    (tests/test_docs.py runs the blocks): a change to the file without the page fails here."""
    page = (ROOT / "docs" / "loop.md").read_text()
    section = page[page.index("## Adding an actuator: a worked example"):]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert (ROOT / path).read_text() in blocks
