"""Thrusters and CMG thruster assist (issue 21), each against an independent truth:

* a pure couple: Σ F_i ĝ_i = 0 and Σ F_i (r_i - c) × ĝ_i = L (hand-built arms, not the library's);
* the mapping never returns a negative force and is exact where the request is feasible; the LP
  meets its bounds and needs no more propellant than the closed form;
* the Schmitt trigger's on-times match a hand-worked sequence exactly;
* the split step: integrating ẋ = u[0:3] across the pulse edges gives Σ T_j t_on,j (the impulse);
* the propellant ledger equals Σ F_i t_on,i / (Isp_i g0) from the logged on-times;
* the dump law's request equals ΔH / dump_time by hand;
* the momentum balance ΔH_N = Σ impulses of the couples (every executor, edges inside ticks);
* the per-tick and fused executors agree to round-off.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from stationbed import simulate
from stationbed.integrators import RK4
from stationbed.loop.actuator import pulse_pieces, split_step
from stationbed.loop.thrusters import (G0_M_S2, ThrusterCluster, map_lp, map_min_norm_shift, mapping_matrices,
                                       opposed_pairs, supports, torque_arms)
from stationbed.scene.thrusters import AUTHORITY_ROUNDOFF_REL, missing_torque, torque_authority
from stationbed.scene import SceneError, scene_from_dict

PERIOD_S = 0.1  # s
ARM_M = 20.0  # m, pods at the ends of the x and y axes
F_N = 100.0  # N per thruster
ISP_S = 280.0  # s
J_SPHERE = 1.0e6  # kg m²
#: mapping residual: a 16 x 6 pseudo-inverse on arms of 20 m, round-off of ~1e-15 relative
MAP_REL = 1e-10
#: round-off of ~200 RK4 steps on momenta of ~100 N m s (as test_closed_loop_balance.py)
BALANCE_ABS = 1e-9  # N m s
#: thruster-only control cycles in pulses of the minimum impulse: a couple of 2 x 100 N x 20 m
#: for 0.02 s is 80 N m s, 8e-5 rad/s on 1e6 kg m²; the PD (0.05 rad/s) turns it round within
#: ~ 1/0.05 s: ~1e-3 rad ~ 0.05 deg is the scale of the cycle (measured 0.013 deg)
LIMIT_CYCLE_DEG = 0.05
#: fused vs per tick: the same expressions, evaluated in another order (C vs casadi VM)
EXEC_ABS = 1e-9


def pods(min_on=0.02):
    """16 thrusters: pods at ±x fire ±y and ±z, pods at ±y fire ±x and ±z (ĝ = force on the station)."""
    th = []
    for ax, others in ((0, (1, 2)), (1, (0, 2))):
        for sgn in (1, -1):
            pos = [0.0, 0.0, 0.0]
            pos[ax] = sgn * ARM_M
            for o in others:
                for ds in (1, -1):
                    d = [0.0, 0.0, 0.0]
                    d[o] = ds
                    th.append({"name": f"t{len(th)}", "position_B": pos, "direction_B": d, "force_N": F_N,
                               "isp_s": ISP_S, "min_on_s": min_on, "group": f"pod{ax}{'p' if sgn > 0 else 'm'}"})
    return th


def x_couples(min_on=0.023):
    """Four thrusters whose torques are all about body x: two couples, +x and -x."""
    def t(name, y, fz):
        return {"name": name, "position_B": [0.0, y, 0.0], "direction_B": [0.0, 0.0, fz], "force_N": F_N,
                "isp_s": ISP_S, "min_on_s": min_on}
    return [t("a", ARM_M, 1.0), t("b", -ARM_M, -1.0), t("c", ARM_M, -1.0), t("d", -ARM_M, 1.0)]


def sphere(thrusters, duration=20.0, integrator="rk4", **opts):
    d = {
        "name": "thr_sphere",
        "simulation": {"duration": duration, "integrator": integrator, "output_dt": 1.0, "rtol": 1e-12,
                       "atol": 1e-14},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 1.0e3, "inertia": [[J_SPHERE, 0, 0], [0, J_SPHERE, 0], [0, 0, J_SPHERE]]},
        "cmg": {"kind": "ideal", "max_momentum": 100.0, "h0_B": [90.0, 0.0, 0.0]},
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}},
        "thruster": thrusters,
        "thrusters": {"dump_time_s": 10.0, "max_dump_torque_Nm": 20.0, **opts},
    }
    if integrator != "dop853":
        d["simulation"]["step"] = PERIOD_S
    return scene_from_dict(d)


@pytest.fixture(scope="module")
def pod_geometry():
    s = sphere(pods())
    D, G = torque_arms(s)
    pairs = opposed_pairs([t.position_B for t in s.thruster], [t.unit_B for t in s.thruster])
    assert pairs is not None and len(pairs) == 8
    M, v, pure = mapping_matrices(D, G, pairs)
    return s, D, G, M, v, pure


def hand_arms(entries):
    """(r × ĝ) and ĝ per thruster, written out here (the sphere's mass centre is the origin)."""
    D = np.array([np.cross(e["position_B"], e["direction_B"]) for e in entries]).T
    G = np.array([e["direction_B"] for e in entries], dtype=float).T
    return D, G


torque = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(u=torque)
def test_pure_couple_delivers_request(pod_geometry, u):
    """Feasible requests (|L| ≤ 1000 N m) come out exact, non-negative, with no net force."""
    _, _, _, M, v, pure = pod_geometry
    D, G = hand_arms(pods())
    L = 1000.0 * u
    F = map_min_norm_shift(M, v, np.full(16, F_N), L)
    assert pure
    assert (F >= 0.0).all()
    assert_allclose(D @ F, L, rtol=0, atol=MAP_REL * ARM_M * F_N * 16)
    assert_allclose(G @ F, 0.0, rtol=0, atol=MAP_REL * F_N * 16)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(u=torque, scale=st.floats(0.0, 1e6))
def test_mapping_never_negative_nor_above_max(pod_geometry, u, scale):
    """Any request, however large: 0 <= F <= F_max, and the torque keeps the request's direction."""
    _, _, _, M, v, _ = pod_geometry
    D, _ = hand_arms(pods())
    L = scale * u
    F = map_min_norm_shift(M, v, np.full(16, F_N), L)
    assert (F >= 0.0).all() and (F <= F_N * (1 + 1e-12)).all()
    got = D @ F
    assert np.linalg.norm(np.cross(got, L)) <= MAP_REL * 1e3 * max(np.linalg.norm(L), 1.0) * np.linalg.norm(got) + 1e-9
    assert got @ L >= 0.0


def test_mapping_compiled_equals_numpy(pod_geometry):
    """The casadi mapping (what the loops run) and the numpy one agree."""
    _, _, _, M, v, _ = pod_geometry
    Ls = ca.SX.sym("L", 3)
    f = ca.Function("m", [Ls], [map_min_norm_shift(ca.DM(M), ca.DM(v), np.full(16, F_N), Ls, supports(v))])
    for L in ([300.0, -200.0, 50.0], [0.0, 0.0, 0.0], [5e4, 0.0, 0.0]):
        assert_allclose(ca.DM(f(L)).full().ravel(), map_min_norm_shift(M, v, np.full(16, F_N), np.array(L)), rtol=1e-12, atol=1e-12)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(u=torque)
def test_pair_shift_spends_what_the_lp_spends(pod_geometry, u):
    """On a set of opposed pairs the closed form (shift per pair) needs the LP's least Σ F:
    the minimum-norm solution is antisymmetric in each pair, and the shift fires one side."""
    _, _, _, M, v, _ = pod_geometry
    D, G = hand_arms(pods())
    L = 1000.0 * u
    F = map_min_norm_shift(M, v, np.full(16, F_N), L)
    lp = map_lp(D, G, np.full(16, F_N), L, np.full(16, 1.0 / ISP_S), True)
    assert_allclose(F.sum(), lp.sum(), rtol=1e-9, atol=1e-9)


def test_unpaired_set_shifts_along_one_null_vector():
    """15 of the 16 (one partner removed): no pairing, one positive null vector found by HiGHS;
    still exact, non-negative and a pure couple."""
    entries = pods()[1:]
    s = sphere(entries)
    D, G = torque_arms(s)
    assert opposed_pairs([t.position_B for t in s.thruster], [t.unit_B for t in s.thruster]) is None
    M, V, pure = mapping_matrices(D, G, None)
    assert pure and V.shape == (15, 1) and (V > 0).all()
    Dh, Gh = hand_arms(entries)
    L = np.array([300.0, -150.0, 80.0])
    F = map_min_norm_shift(M, V, np.full(15, F_N), L)
    assert (F >= 0).all()
    assert_allclose(Dh @ F, L, atol=MAP_REL * ARM_M * F_N * 16)
    assert_allclose(Gh @ F, 0.0, atol=MAP_REL * F_N * 16)


def test_lp_bounds_and_least_propellant(pod_geometry):
    """HiGHS: exact torque, no net force, forces in bounds, Σ F no more than the closed form's."""
    _, _, _, M, v, _ = pod_geometry
    D, G = hand_arms(pods())
    L = np.array([1500.0, -800.0, 300.0])
    F = map_lp(D, G, np.full(16, F_N), L, np.full(16, 1.0 / ISP_S), True)
    assert F is not None and (F >= -1e-9).all() and (F <= F_N + 1e-9).all()
    assert_allclose(D @ F, L, atol=1e-6)
    assert_allclose(G @ F, 0.0, atol=1e-6)
    assert F.sum() <= map_min_norm_shift(M, v, np.full(16, F_N), L).sum() + 1e-9


def fire_sequence(forces, remainder, min_on=0.04):
    """On-times of one thruster of a 4-thruster set given its force each tick (the others 0)."""
    s = sphere(x_couples(min_on=min_on), remainder=remainder)
    c = ThrusterCluster(s, s, 100.0)
    _, fire = c.lp_functions()
    x = c.x0.copy()
    aux = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # thruster-only, not dumping, not inhibited
    out = []
    for f in forces:
        xn, _, on, _, _ = fire(0.0, PERIOD_S, x, np.zeros(3), c.params, [f, 0.0, 0.0, 0.0], aux)
        x = ca.DM(xn).full().ravel()
        out.append(float(ca.DM(on).full().ravel()[0]))
    return out


def test_schmitt_hand_worked():
    """level = (F / F_max h) / min_on; on at >= 0.75, off at <= 0.25, hold in between; above min_on
    the request itself, at most the period (min_on = 0.04 s, h = 0.1 s, F_max = 100 N)."""
    forces = [10.0, 20.0, 35.0, 20.0, 5.0, 60.0, 150.0, 20.0, 25.0]
    #          .25 off  .5 hold(0) .875 on  .5 hold(on) .125 off  want .06  cut at h  .5 hold(on) .625 hold(on)
    expect = [0.0, 0.0, 0.04, 0.04, 0.0, 60.0 / F_N * PERIOD_S, PERIOD_S, 0.04, 0.04]
    assert fire_sequence(forces, remainder=False) == expect


def test_schmitt_remainder_hand_worked():
    """With the remainder: 10 N each tick asks 0.01 s; it accumulates 0.01, 0.02, 0.03 (level
    0.75: fire 0.04, carry -0.01), then 0.0, ...: one min_on pulse every 4 ticks, 0.01 s per tick."""
    got = fire_sequence([10.0] * 8, remainder=True)
    assert got == [0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.04, 0.0]


def test_pulse_pieces_cover_each_on_time():
    """Each channel is on over pieces whose lengths add up to its on-time, exactly."""
    on = np.array([0.03, 0.1, 0.0, 0.057, 0.03])
    pieces = pulse_pieces(on, 0.1)
    for j, t_on in enumerate(on):
        assert math.fsum(b - a for a, b, m in pieces if m[j]) == pytest.approx(t_on, abs=1e-17)
    assert pieces[0][0] == 0.0 and pieces[-1][1] == 0.1


def test_split_step_impulse_is_torque_times_on_time():
    """RK4 split at the edges on ẋ = u[0:3]: x(h) = Σ_j T_j t_on,j (no averaging), compiled as the
    fused tick compiles it."""
    t, x, h, u, p = ca.SX.sym("t"), ca.SX.sym("x", 3), ca.SX.sym("h"), ca.SX.sym("u", 3), ca.SX.sym("p", 0)
    rhs = ca.Function("rhs", [t, x, u, p], [u])
    on, tq = ca.SX.sym("on", 3), ca.SX.sym("tq", 3, 3)
    f = ca.Function("s", [x, h, on, tq], [split_step(RK4.explicit_step, rhs, 0.0, x, h, ca.SX.zeros(3), p, on, tq)])
    T = np.array([[2000.0, -1.0, 3.0], [0.0, 2000.0, 7.0], [5.0, 0.0, -2000.0]])  # N m, columns = channels
    t_on = np.array([0.023, 0.1, 0.061])
    got = ca.DM(f(np.zeros(3), 0.1, t_on, T)).full().ravel()
    assert_allclose(got, T @ t_on, rtol=1e-15, atol=1e-13)


def test_dump_request_by_hand():
    """Assist: |h| = 90 of 100 (>= assist_on 0.8): ΔH = -(90 - 30)/90 h; torque ΔH / 10 s."""
    s = sphere(x_couples(), max_dump_torque_Nm=1e3)
    c = ThrusterCluster(s, s, 100.0)
    request, _ = c.lp_functions()
    h_B = np.array([54.0, 0.0, -72.0])  # |h| = 90 N m s
    req, aux = request(0.0, PERIOD_S, c.x0, h_B, np.zeros(3), c.params)
    dH = -(90.0 - 30.0) / 90.0 * h_B
    assert_allclose(ca.DM(req).full().ravel(), dH / 10.0, rtol=1e-14)
    assert ca.DM(aux).full().ravel()[1] == 1.0  # dumping


#: executor -> (scene integrator, simulate's integrator override, fused)
class RK4Generic(RK4):
    fusable = False


EXECUTORS = {"generic_rk4": ("rk4", RK4Generic, False), "per_tick": ("rk4", None, False),
             "fused": ("rk4", None, True), "dop853": ("dop853", None, False)}


@pytest.mark.parametrize("executor", list(EXECUTORS))
def test_momentum_balance_with_pulse_edges_inside_ticks(executor):
    """Two couples about body x (a spherical body turns about x only): at every row the total
    momentum has changed by Σ_i (r_i × F_i ĝ_i)_x t_on,i (the logged on-times), along N's x;
    the pulses (min_on 0.023 s, remainder) end between ticks."""
    integrator, override, fused = EXECUTORS[executor]
    s = sphere(x_couples(), integrator=integrator, dump_time_s=0.5, max_dump_torque_Nm=1e3)
    tr = simulate(s, integrator=override, fused=fused)
    assert tr.meta["summary"]["fused"] == fused
    assert tr.meta["summary"]["thruster_firings"] > 0
    D, _ = hand_arms(x_couples())
    on = tr.data[:, [tr.columns.index(f"thr_on_s_{n}") for n in "abcd"]]
    assert (np.abs(on / PERIOD_S - np.round(on / PERIOD_S)) > 1e-3).any()  # edges off the grid
    dH = tr.H_O_N - tr.H_O_N[0]
    assert_allclose(dH[:, 0], on @ (D[0] * F_N), rtol=0, atol=BALANCE_ABS)
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=BALANCE_ABS)


def test_ledger_equals_logged_on_times():
    """propellant = Σ F_i t_on,i / (Isp_i g0) and impulse = Σ F_i t_on,i from the on-time columns."""
    tr = simulate(sphere(pods()), fused=False)
    on = tr.data[:, [tr.columns.index(f"thr_on_s_t{i}") for i in range(16)]]
    prop = tr.data[:, tr.columns.index("thr_propellant_kg")]
    assert on[-1].sum() > 0
    assert_allclose(prop, on @ np.full(16, F_N / (ISP_S * 9.80665)), rtol=1e-13, atol=0)
    assert_allclose(tr.data[:, tr.columns.index("thr_impulse_Ns")], on.sum(axis=1) * F_N, rtol=1e-13)
    assert tr.meta["summary"]["propellant_kg"] == pytest.approx(prop[-1], rel=1e-12)
    assert G0_M_S2 == 9.80665


@pytest.mark.parametrize("extra", [{}, {"simulation.duration": 20.05},
                                   {"torque": [{"kind": "constant", "torque_B": [3.0, -2.0, 1.0], "start": 4.0, "stop": 9.0}]},
                                   {"cmg.h0_B": [99.0, 0.0, 0.0]}, {"thrusters.mode": "thruster_only"}],
                         ids=["plain", "short_last_tick", "torque_window_on_grid", "handover", "thruster_only"])
def test_fused_equals_per_tick(extra):
    """16 thrusters in assist: the fused loop's rows equal the per-tick loop's to round-off (also
    with a short last period and a torque window whose edges the fused loop cuts on the grid, and
    through handover and in thruster-only control, where ticks that fire nothing give the CMGs a
    rest other than the law's request: the fused tick's branch that actuates the rest)."""
    s = sphere(pods()).replace(extra)
    a, b = simulate(s, fused=False), simulate(s, fused=True)
    assert b.meta["summary"]["fused"] and not a.meta["summary"]["fused"]
    assert_allclose(b.data, a.data, rtol=0, atol=EXEC_ABS)
    assert a.meta["summary"]["thruster_firings"] == b.meta["summary"]["thruster_firings"] > 0


def test_lp_mapping_runs_per_tick_and_says_why():
    s = sphere(pods(), mapping="lp")
    tr = simulate(s, fused=True)
    sm = tr.meta["summary"]
    assert not sm["fused"] and "lp" in sm["thrusters_not_fused"]
    assert sm["thruster_firings"] > 0


def test_handover_to_thruster_only_and_back():
    """|h| at 99 % of capacity (>= handover 0.97): the law's torque goes to the thrusters and the
    dump brings |h| below handback, when the CMGs take attitude control back."""
    s = sphere(pods()).replace({"cmg.h0_B": [99.0, 0.0, 0.0]})
    tr = simulate(s, fused=False)
    mode = tr.data[:, tr.columns.index("thr_mode")]
    assert mode.max() == 1.0 and mode[-1] == 0.0
    assert tr.meta["summary"]["thruster_control_s"] > 0


@pytest.mark.parametrize("change, field", [
    ({"thruster[0].forse_N": 3.0}, "did you mean 'force_N'"),
    ({"thruster[0].direction_B": [0.0, 0.0, 0.0]}, "thruster.t0.direction_B"),
    ({"thruster[0].min_on_s": 0.5}, "thruster.t0.min_on_s"),
    ({"thrusters.level_off": 0.9}, "thrusters.level_off"),
    ({"thrusters.mode": "sometimes"}, "thrusters.mode"),
    ({"cmg.max_momentum": None}, "thrusters.mode"),
], ids=["typo", "zero_direction", "min_on_above_period", "levels", "mode", "assist_without_capacity"])
def test_bad_scene_one_line(change, field):
    with pytest.raises(SceneError) as e:
        sphere(pods()).replace(change)
    assert field in str(e.value) and "\n" not in str(e.value)


def test_dump_events_on_the_time_line():
    """The rerun recording's events: a dump that begins and ends is logged at its rows."""
    from stationbed.output.rerun.events import Events

    tr = simulate(sphere(pods()), fused=False)
    d = tr.data[:, tr.columns.index("thr_dumping")]
    texts = [e[2] for e in Events(tr.columns).changes(tr)]
    assert d.max() == 1.0 and d[-1] == 0.0
    assert "thruster momentum dump begins" in texts and "thruster momentum dump ends" in texts


def test_fused_equals_per_tick_with_sensor_noise():
    """With [controller.sensor] noise the fused loop draws the same numbers (fused.py's order)."""
    s = sphere(pods()).replace({"controller.sensor": {"attitude_noise": 1e-4, "rate_noise": 1e-6, "seed": 7}})
    a, b = simulate(s, fused=False), simulate(s, fused=True)
    assert b.meta["summary"]["fused"] and not a.meta["summary"]["fused"]
    assert_allclose(b.data, a.data, rtol=0, atol=EXEC_ABS)


def test_sensors_with_thrusters_fly_fused_as_per_tick():
    """[[sensor]] tables + an MEKF + thrusters (issue 33): the loop composed from its blocks flies
    them fused, the thrusters fire, and its rows are the per-tick loop's to round-off (before
    issue 33 this combination fell to the per-tick loop)."""
    gyro = {"kind": "gyro", "name": "g1", "period": PERIOD_S, "sigma_v": 1e-7, "sigma_u": 1e-10}
    st = {"kind": "star_tracker", "name": "s1", "period": 0.5, "boresight_B": [0.0, 0.0, 1.0],
          "nea_cross": 1e-5, "nea_about": 5e-5}
    s = sphere(pods()).replace({"sensor": [gyro, st], "estimator": {"kind": "mekf"}})
    a, b = simulate(s, fused=False), simulate(s, fused=True)
    sm = b.meta["summary"]
    assert sm["fused"] and "thrusters_not_fused" not in sm and not a.meta["summary"]["fused"]
    assert sm["thruster_firings"] > 0 and sm["thruster_firings"] == a.meta["summary"]["thruster_firings"]
    assert_allclose(b.data, a.data, rtol=0, atol=EXEC_ABS)


def test_lockstep_batch_never_drops_thrusters():
    """The Monte Carlo's lockstep executor flies thruster scenes in the batch (the composed parts
    mapped, the chain's pulses split the step), each sample its single per-tick run bit for bit."""
    from stationbed.run.lockstep import run_lockstep

    s = sphere(pods())
    res = run_lockstep([s, s], fused=False, keep=True)
    assert [kind for kind, _ in res] == ["batch", "batch"]
    single = simulate(s, fused=False)
    for _, tr in res:
        assert tr.meta["summary"]["thruster_firings"] == single.meta["summary"]["thruster_firings"] > 0
        assert np.array_equal(tr.data, single.data)


def test_inhibit_window_fires_nothing_inside():
    """Dumping from t = 0 but inhibited over [0, 5) s: no on-time before 5 s, firings after."""
    tr = simulate(sphere(pods(), inhibit=[[0.0, 5.0]]), fused=False)
    on = tr.data[:, [tr.columns.index(f"thr_on_s_t{i}") for i in range(16)]].sum(axis=1)
    assert (on[tr.t <= 5.0] == 0.0).all() and on[-1] > 0.0


def test_mode_off_is_the_run_without_thrusters():
    """``mode = "off"``: every state and shared column equal, bit for bit, to the same scene with
    no [[thruster]] on the same (generic per-tick) path: the request passes to the CMGs whole."""
    s = sphere(pods(), mode="off")
    bare = s.replace({"thruster": [], "thrusters": None})
    a, b = simulate(s, integrator=RK4Generic), simulate(bare, integrator=RK4Generic)
    shared = [c for c in b.columns]
    assert np.array_equal(a.data[:, [a.columns.index(c) for c in shared]], b.data)
    assert a.meta["summary"]["thruster_firings"] == 0


def test_thruster_only_mode_holds_attitude_on_thrusters():
    """``mode = "thruster_only"``: the law's torque goes to the thrusters for the whole run (its
    time counted), and the attitude stays held (the CMGs only take the dump torque)."""
    s = sphere(pods(), mode="thruster_only")
    tr = simulate(s, fused=False)
    sm = tr.meta["summary"]
    assert sm["thruster_control_s"] == pytest.approx(s.simulation.duration, rel=1e-12)
    assert (tr.data[1:, tr.columns.index("thr_mode")] == 1.0).all()
    assert sm["max_att_err_deg"] < LIMIT_CYCLE_DEG


#: the law holds a body of 1e12 kg m² (the CMGs absorb each pulse within its tick): the attitude
#: error stays near 1e-10 rad (measured 7.6e-9 deg), so C_NB = E to that; on ~3e3 N m s of impulse
#: ΔH_N differs from Σ T_i t_on,i by at most ~3e-7 N m s (measured 9e-9)
STIFF_BALANCE_ABS = 1e-6  # N m s


@pytest.mark.parametrize("executor", list(EXECUTORS))
def test_vector_impulse_of_sixteen_thrusters(executor):
    """All 16 thrusters, a dump along a general direction (pulses of different lengths, edges
    inside ticks, torques about every axis): ΔH_N = Σ_i (r_i × F_i ĝ_i) t_on,i, the arms written
    here, on a body too stiff to turn (C_NB = E)."""
    integrator, override, fused = EXECUTORS[executor]
    s = sphere(pods(min_on=0.017), integrator=integrator).replace({
        "body.inertia": [[1e12, 0, 0], [0, 1e12, 0], [0, 0, 1e12]],
        "cmg": {"kind": "ideal", "max_momentum": 1e4, "h0_B": [6000.0, 5000.0, -4000.0]},
        "thrusters.dump_time_s": 20.0, "thrusters.max_dump_torque_Nm": 1e4})
    tr = simulate(s, integrator=override, fused=fused)
    D, _ = hand_arms(pods())
    on = tr.data[:, [tr.columns.index(f"thr_on_s_t{i}") for i in range(16)]]
    assert len({round(v, 12) for v in on[-1]}) > 2  # the thrusters fired for different times
    dH = tr.H_O_N - tr.H_O_N[0]
    assert np.abs(dH[-1]).min() > 1.0  # every axis took an impulse
    assert_allclose(dH, on @ (D * F_N).T, rtol=0, atol=STIFF_BALANCE_ABS)


def test_dump_request_on_the_working_units():
    """A failed unit flight software knows of holds 4760 N m s: the dump law acts on h minus it."""
    s = sphere(x_couples(), max_dump_torque_Nm=1e3)
    held = np.array([4760.0, 0.0, 0.0])  # N m s
    c = ThrusterCluster(s, s, 100.0, held)
    request, _ = c.lp_functions()
    h_work = np.array([54.0, 0.0, -72.0])  # |h| = 90 N m s of the working units
    req, _ = request(0.0, PERIOD_S, c.x0, h_work + held, np.zeros(3), c.params)
    assert_allclose(ca.DM(req).full().ravel(), -(90.0 - 30.0) / 90.0 * h_work / 10.0, rtol=1e-12)


def test_a_law_with_a_state_and_thrusters_flies_fused_as_per_tick():
    """A law that carries a state (run/law_state.py) with thrusters (issue 33): the composed loop
    carries the law's state beside the thrusters' memory, so the run flies fused, the thrusters
    fire, the rows are the per-tick loop's to round-off and the law's own count is every tick it
    was updated (nothing skipped), handed back at the end."""
    from test_law_state import CountedSine

    s = sphere(pods()).replace({"controller": {"name": "counted_sine", "period": PERIOD_S}})
    laws = [CountedSine(period=PERIOD_S), CountedSine(period=PERIOD_S)]
    a, b = (simulate(s, fused=f, controller=law) for f, law in zip((False, True), laws))
    sm = b.meta["summary"]
    assert sm["fused"] and "thrusters_not_fused" not in sm
    assert sm["thruster_firings"] > 0
    assert laws[1].k == laws[0].k == sm["ticks"] + 1
    # (the attitude error: from the reference the symbolic form returns; the Python law sets none)
    keep = [j for j, c in enumerate(a.columns) if not c.startswith("att_err")]
    assert_allclose(b.data[:, keep], a.data[:, keep], rtol=0, atol=EXEC_ABS)


# -- torque authority (issue 32): what the set can turn the station about -------------------------
#: pods(), by hand: +z from the four thrusters whose arm is along x or y and force along y or x
#: ((20, 0, 0) x (0, 1, 0) = (0, 0, 20) m, and three like it) at 100 N: 4 x 20 x 100 N m; +x and
#: +y from two each ((0, 20, 0) x (0, 0, 1) = (20, 0, 0) m, ...): 2 x 20 x 100 N m; the set is
#: symmetric, so the same the other way
POD_AUTHORITY_NM = [[4000.0, 4000.0], [4000.0, 4000.0], [8000.0, 8000.0]]
#: x_couples(), by hand: a and b make +x ((0, ±20, 0) x (0, 0, ±1) = (20, 0, 0) m), c and d -x
X_COUPLES_AUTHORITY_NM = [[4000.0, 4000.0], [0.0, 0.0], [0.0, 0.0]]
#: the LP's optimum is a vertex: its sums of a few products of 20 m and 100 N, to round-off
AUTHORITY_ABS_NM = 1e-6


def one_sided():
    """Three thrusters making +x, +y and +z only ((0, 20, 0) x +z, (0, 0, 20) x +x, (20, 0, 0) x +y)."""
    def t(name, pos, d):
        return {"name": name, "position_B": pos, "direction_B": d, "force_N": F_N, "isp_s": ISP_S}
    return [t("px", [0.0, ARM_M, 0.0], [0.0, 0.0, 1.0]), t("py", [0.0, 0.0, ARM_M], [1.0, 0.0, 0.0]),
            t("pz", [ARM_M, 0.0, 0.0], [0.0, 1.0, 0.0])]


@pytest.mark.parametrize("entries, expected", [(pods(), POD_AUTHORITY_NM), (x_couples(), X_COUPLES_AUTHORITY_NM)],
                         ids=["pods", "x_couples"])
def test_torque_authority_by_hand(entries, expected):
    D, _ = hand_arms(entries)
    assert_allclose(torque_authority(D, [e["force_N"] for e in entries]), expected, rtol=0, atol=AUTHORITY_ABS_NM)


def _at(entries, where):
    return [{**e, "position_B": list(where)} for e in entries]


@pytest.mark.parametrize("mode", ["assist", "thruster_only"])
@pytest.mark.parametrize("cm", [[0.0, 0.0, 0.0], [5.0, -1.0, 2.0]], ids=["origin", "offset_body_cm"])
def test_thrusters_through_the_mass_centre_are_refused_naming_them(mode, cm):
    """The issue's case: every thruster at the composite mass centre (with the body's mass centre
    off the origin too: positions typed from the mass centre, not from the origin) makes no
    torque; a run that asks for dumps or thruster-only control is refused, naming all six
    directions and the thrusters."""
    with pytest.raises(SceneError) as e:
        sphere(_at(pods(), cm), mode=mode) if cm == [0.0, 0.0, 0.0] else _sphere_cm(_at(pods(), cm), cm, mode=mode)
    msg = str(e.value)
    assert "\n" not in msg and "thruster: the set makes no torque about -x, +x, -y, +y, -z, +z of B" in msg
    assert f"mode '{mode}'" in msg and "t0, t1, t2, t3, t4, t5 and 10 more make no torque at all" in msg


def _sphere_cm(entries, cm, **opts):
    d = sphere(pods()).model_dump(exclude_none=True)  # the sphere's tables, with the body's mass centre moved
    d["body"]["cm"] = cm
    d["thruster"] = entries
    d["thrusters"] = {**d["thrusters"], **opts}
    return scene_from_dict(d)


def test_one_sided_set_is_refused_for_thruster_only_control():
    with pytest.raises(SceneError, match=r": thruster: the set makes no torque about -x, -y, -z of B .*mode "
                                         r"'thruster_only' controls attitude about every axis$"):
        sphere(one_sided(), mode="thruster_only", max_dump_torque_Nm=1e3)


def test_mode_off_takes_any_set():
    assert sphere(_at(pods(), [0.0, 0.0, 0.0]), mode="off").thrusters.mode == "off"


def test_assist_set_about_one_axis_flies_and_its_summary_says_what_it_lacks():
    """x_couples dumps about x only: flown (the dump here is about x), and the summary and the
    run's line name the four directions it cannot turn the station about; pods() lacks none."""
    from stationbed.run.chain import chain_summary_parts as thruster_parts

    sm = simulate(sphere(x_couples(), duration=1.0), fused=False).meta["summary"]
    assert sm["thruster_no_torque_about"] == "-y, +y, -z, +z"
    assert any("no torque about -y, +y, -z, +z" in p for p in thruster_parts(sm))
    from stationbed.cli import _summary_line  # the run's line: the thrusters' parts through their plug-in

    assert f"thrusters {sm['thruster_firings']} firings" in _summary_line(sm)
    assert "thruster_no_torque_about" not in simulate(sphere(pods(), duration=1.0), fused=False).meta["summary"]


def _lp_missing(s):
    """The directions the LP alone (:func:`torque_authority`) finds no torque about: the truth
    the fast path must give (the same round-off threshold)."""
    D, _ = torque_arms(s)
    f = np.array([t.force_N for t in s.thruster])
    auth, scale = torque_authority(D, f), float(np.linalg.norm(D, axis=0) @ f)
    return [f"{'-+'[c]}{'xyz'[k]}" for k in range(3) for c in range(2) if auth[k, c] <= AUTHORITY_ROUNDOFF_REL * scale]


#: pods() moved off the origin by amounts no other test uses (sets the cache has not seen)
POD_SHIFT_M = [0.123, -0.456, 0.789]
NO_LP_SHIFT_M = [-0.321, 0.654, -0.987]


@pytest.mark.parametrize("entries", [pods(), x_couples(), one_sided(), _at(pods(), [0.0, 0.0, 0.0]),
                                     [{**e, "position_B": list(np.add(e["position_B"], POD_SHIFT_M))} for e in pods()]],
                         ids=["pods", "x_couples", "one_sided", "through_cm", "pods_shifted"])
def test_missing_directions_are_the_lps(entries):
    assert missing_torque(sphere(entries, mode="off")) == _lp_missing(sphere(entries, mode="off"))


axis_dir = st.sampled_from([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0],
                            [1.0, 1.0, 0], [0, -1.0, 2.0]])
position = st.lists(st.sampled_from([-20.0, -3.0, 0.0, 2.5, 20.0]), min_size=3, max_size=3)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.lists(st.tuples(position, axis_dir, st.sampled_from([50.0, 130.0])), min_size=1, max_size=9))
def test_missing_directions_of_any_set_are_the_lps(spec):
    """Sets of up to nine thrusters on a coarse grid (couples, one-sided sets, lines through the
    mass centre, parallel forces: what the firings of three cannot show is left to the LP)."""
    entries = [{"name": f"t{i}", "position_B": p, "direction_B": d, "force_N": f, "isp_s": ISP_S}
               for i, (p, d, f) in enumerate(spec)]
    s = sphere(entries, mode="off")
    assert missing_torque(s) == _lp_missing(s)


def test_a_set_with_torque_each_way_needs_no_lp(monkeypatch):
    """A set that turns the station both ways about every axis is shown so by three-thruster
    firings: no LP (6 of them were ~10 ms of each Monte Carlo sample, whose mass centre is drawn)."""
    import scipy.optimize

    def no_lp(*a, **k):
        raise AssertionError("linprog called")

    monkeypatch.setattr(scipy.optimize, "linprog", no_lp)
    shifted = [{**e, "position_B": list(np.add(e["position_B"], NO_LP_SHIFT_M))} for e in pods()]
    assert missing_torque(sphere(shifted, mode="thruster_only")) == []
