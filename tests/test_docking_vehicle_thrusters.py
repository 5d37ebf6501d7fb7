"""A visiting vehicle's own thrusters (issue 35, ``[[vehicle.thruster]]``): declared once in the
vehicle's axes V (positions from its docking interface), flown by the station's thruster block
while the vehicle is docked, never while it is away, in one compiled loop through the events.

Independent truths, written out here from the scene's numbers (no library code):

* where a docked vehicle's thruster is: ``r_B = r_port + C_BV r_V``, ``ĝ_B = C_BV ĝ_V``, with the
  port's ``q_VB`` a half turn about z, so ``C_BV = diag(-1, -1, 1)`` by hand;
* the composite mass centre ``c = m_v (r_port + C_BV cm_V) / (m_s + m_v)`` while docked (the
  body's at the origin), the origin while the vehicle is away;
* the momentum balance ``H_N(t_j) - H_N(t_0) = Σ_ticks Σ_i (r_i - c) × F_i ĝ_i Δt_on,i`` from the
  logged on-times, on a body too stiff to turn (``C_NB = E``), through a berth and an undock (the
  row intervals holding the two events left out: the capture's and the springs' own momentum are
  proven in tests/test_docking.py); with no station thruster, nothing changes ``H_N`` while the
  vehicle is away;
* the vehicle's on-times do not grow while it is away, although flight software, told of the undock
  only ``update_after_s`` later, still asks them for torque (the valves are the truth's);
* the per-vehicle propellant ``Σ F t_on / (Isp g0)`` from the logged on-times, ``g0`` = 9.80665 m/s²
  (CGPM 1901).

The per-tick, fused and lockstep executors give the same rows (the events are numbers of the same
compiled loop).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import simulate
from stationbed.run.lockstep import run_lockstep
from stationbed.scene import SceneError, scene_from_dict

from rrd_helpers import entity_rows
from scenes import EXECUTORS, fly_on

PERIOD_S = 0.1  # s
T_BERTH_S = 2.0  # s, a whole number of ticks
T_UNDOCK_S = 6.0  # s
UPDATE_AFTER_S = 1.0  # s: flight software is told of each change one second late
DURATION_S = 9.0  # s
M_S = 1.0e4  # kg, the station (its mass centre at the origin)
J_STIFF = 1.0e12  # kg m²: the body does not turn (C_NB = E to ~1e-9 rad)
M_V = 5.0e3  # kg, the vehicle
J_V = np.diag([1.0e3, 3.0e3, 3.5e3])  # kg m², about its own mass centre, V axes
R_PORT = np.array([-6.0, 0.5, 1.0])  # m
Q_VB = [0.0, 0.0, 0.0, 1.0]  # the vehicle's axes: half a turn about z from B's
C_BV = np.diag([-1.0, -1.0, 1.0])  # that half turn, by hand
CM_V = np.array([-2.5, 0.0, 0.0])  # m, from its interface, V axes
ARM_M = 10.0  # m, the vehicle's pods from its mass centre
F_N = 100.0  # N per thruster
ISP_S = 300.0  # s
G0 = 9.80665  # m/s², standard gravity (exact)
H0_B = [6000.0, 5000.0, -4000.0]  # N m s, the CMGs at 88 % of capacity: dumping from the start
H_MAX_NMS = 1.0e4

#: ΔH_N against Σ (r - c) × F t_on: on ~1e3 N m s of impulse the 1e12 kg m² body, held by the PD
#: law, turns by < 1e-9 rad (C_NB = E to that; the springs' kick included), as
#: tests/test_docking_thrusters.py (there measured <= 3.3e-7 N m s); the arms about the origin
#: instead of the composite mass centre are ~1e2 N m s off here
BALANCE_ABS = 1e-5  # N m s
#: the executors against each other (the same expressions in another order; test_executor_matrix)
EXEC_REL = 1e-8
#: propellant summed two ways from the same on-times (round-off of ~20 terms of ~1e-3 kg)
PROP_REL = 1e-12


def vehicle_thrusters() -> list[dict]:
    """Eight thrusters in V axes, all pushing along +x, +y or +z of V (pods at ±x of the vehicle's
    mass centre fire +y and +z, pods at ±y fire +x and +z): torque both ways about every axis."""
    th = []
    for off, dirs in (([ARM_M, 0.0, 0.0], "yz"), ([-ARM_M, 0.0, 0.0], "yz"), ([0.0, ARM_M, 0.0], "xz"),
                      ([0.0, -ARM_M, 0.0], "xz")):
        for d in dirs:
            g = [0.0, 0.0, 0.0]
            g["xyz".index(d)] = 1.0
            th.append({"name": f"r{len(th)}", "position_V": (CM_V + off).tolist(), "direction_V": g, "force_N": F_N,
                       "isp_s": ISP_S})
    return th


def station_thrusters() -> list[dict]:
    """Six station thrusters in three opposed pairs: at (0, 0, 12) m firing ±x (torque about y) and
    ±y (about x), at (12, 0, 0) firing ±y (about z). Alone, three shift vectors (one per pair);
    with the vehicle's one-way set, one (a positive null vector of all 14): the compiled mapping has
    three columns, the docked configuration's two of them zero, and zero entries for the vehicle's
    thrusters while it is away."""
    out = []
    for k, (pos, g) in enumerate((([0, 0, 12], [1, 0, 0]), ([0, 0, 12], [-1, 0, 0]), ([0, 0, 12], [0, 1, 0]),
                                  ([0, 0, 12], [0, -1, 0]), ([12, 0, 0], [0, 1, 0]), ([12, 0, 0], [0, -1, 0]))):
        out.append({"name": f"s{k}", "position_B": pos, "direction_B": g, "force_N": F_N, "isp_s": ISP_S})
    return out


BERTH = {"kind": "berth", "t": T_BERTH_S, "vehicle": "v", "port": "aft", "update_after_s": UPDATE_AFTER_S}
UNDOCK = {"kind": "undock", "t": T_UNDOCK_S, "vehicle": "v", "delta_v": 0.05, "update_after_s": UPDATE_AFTER_S}


def station(with_own: bool, vthr=None, events=(BERTH, UNDOCK)) -> dict:
    return {
        "name": "vehicle_thrusters",
        "simulation": {"duration": DURATION_S, "formulation": "momentum", "integrator": "rk4", "step": PERIOD_S,
                       "output_dt": PERIOD_S},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": M_S, "inertia": (J_STIFF * np.eye(3)).tolist()},
        "cmg": {"kind": "ideal", "max_momentum": H_MAX_NMS, "h0_B": H0_B},
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}},
        "port": [{"name": "aft", "position": R_PORT.tolist(), "axis": [-1.0, 0.0, 0.0], "q_VB": Q_VB}],
        "vehicle": [{"name": "v", "mass": M_V, "inertia": J_V.tolist(), "cm": CM_V.tolist(),
                     "thruster": vehicle_thrusters() if vthr is None else vthr}],
        "event": list(events),
        "thruster": station_thrusters() if with_own else [],
        "thrusters": {"assist_on": 0.3, "dump_stop": 0.15, "h_min": 0.1, "dump_time_s": 20.0,
                      "max_dump_torque_Nm": 1.0e4},
    }


def _all_thrusters(with_own: bool) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(column name, r_B, F_B) of every thruster flown, by hand: the station's, then the vehicle's at
    its port (named ``v_<name>``: one port in the run)."""
    out = [(t["name"], np.array(t["position_B"], float), F_N * np.array(t["direction_B"], float))
           for t in (station_thrusters() if with_own else [])]
    out += [(f"v_{t['name']}", R_PORT + C_BV @ np.array(t["position_V"]), F_N * (C_BV @ np.array(t["direction_V"])))
            for t in vehicle_thrusters()]
    return out


C_DOCKED = M_V * (R_PORT + C_BV @ CM_V) / (M_S + M_V)  # m, the docked composite's mass centre


def _c(t) -> np.ndarray:
    """The mass centre flown over the tick starting at ``t``."""
    return C_DOCKED if T_BERTH_S - 1e-9 <= t < T_UNDOCK_S - 1e-9 else np.zeros(3)


CASES = {"vehicle_only": False, "with_station_set": True}




@pytest.fixture(scope="module")
def runs():
    return {case: {ex: fly_on(scene_from_dict(station(own)), ex) for ex in EXECUTORS} for case, own in CASES.items()}


def _pulses(tr, names) -> np.ndarray:
    """Each tick's on-times (ticks, n) [s] from the logged totals (rows one tick apart)."""
    return np.diff(tr.data[:, [tr.columns.index(f"thr_on_s_{n}") for n in names]], axis=0)


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize("case", list(CASES))
def test_momentum_balance_through_a_berth_and_an_undock(runs, case, executor):
    """ΔH_N over every tick is Σ_i (r_i - c) × F_i ĝ_i Δt_on,i with the vehicle's thrusters where
    its port puts them and c the mass centre of the configuration flown (the event ticks left out)."""
    tr = runs[case][executor]
    thr = _all_thrusters(CASES[case])
    pulses = _pulses(tr, [n for n, _, _ in thr])
    t0 = tr.t[:-1]
    expect = np.array([sum(p[i] * np.cross(r - _c(t), F) for i, (_, r, F) in enumerate(thr)) for p, t in zip(pulses, t0)])
    got = np.diff(tr.H_O_N, axis=0)
    keep = ~(np.isclose(tr.t[1:], T_BERTH_S, rtol=0, atol=1e-9) | np.isclose(tr.t[1:], T_UNDOCK_S, rtol=0, atol=1e-9))
    assert_allclose(np.cumsum(got[keep], axis=0), np.cumsum(expect[keep], axis=0), rtol=0, atol=BALANCE_ABS)
    vehicle = pulses[:, -len(vehicle_thrusters()):]
    assert vehicle.sum() > 1.0  # s: the vehicle's thrusters dumped while docked
    if not CASES[case]:  # nothing else acts on the body: H_N still while the vehicle is away
        away = (t0 < T_BERTH_S - 1e-9) | (t0 >= T_UNDOCK_S - 1e-9)
        assert_allclose(got[away & keep], 0.0, rtol=0, atol=BALANCE_ABS)


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize("case", list(CASES))
def test_vehicle_thrusters_fire_only_while_docked(runs, case, executor):
    """The vehicle's on-times grow only over ticks it is docked; flight software is told of the berth
    at 3 s (none fire before, though the truth could) and of the undock at 7 s (it still asks them
    over [6, 7) s: the valves, the truth's, do not fire)."""
    tr = runs[case][executor]
    names = [f"v_{t['name']}" for t in vehicle_thrusters()]
    pulses = _pulses(tr, names).sum(axis=1)
    t0 = tr.t[:-1]
    told = (t0 >= T_BERTH_S + UPDATE_AFTER_S - 1e-9) & (t0 < T_UNDOCK_S - 1e-9)
    assert (pulses[~told] == 0.0).all(), t0[~told][pulses[~told] != 0.0]
    assert (pulses[told] > 0.0).all()  # the dump keeps them firing while told and docked


#: a tick's delivered torque against the request (as tests/test_docking_thrusters.py: the mapping's
#: pseudo-inverse ~1e-15 relative on ~4e2 N m, on-times differenced from totals of ~1 s; there
#: measured <= 2e-12 N m); a shift along a zero entry (a thruster that cannot fire) gives no finite
#: forces at all, and the mapping on the wrong thrusters is ~1e2 N m off
DUMP_ABS_NM = 1e-8
H_MIN, DUMP_TIME_S = 0.1, 20.0


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize("case", list(CASES))
def test_dump_delivered_where_flight_software_knows_the_thrusters(runs, case, executor):
    """With ``min_on_s = 0`` every tick's thruster torque (logged on-times, true arms) is the dump
    request on the logged CMG momentum plus ``(c_known - c_true) × Σ F_i ĝ_i`` wherever the thrusters
    flight software maps on are those that fire: the station's alone before the berth is told (3 s)
    and after the undock is (7 s), both sets in between; over [6, 7) s it still asks the departed
    vehicle's (left out). Without a station set, from the told berth to the undock."""
    tr = runs[case][executor]
    thr = _all_thrusters(CASES[case])
    pulses = _pulses(tr, [n for n, _, _ in thr])
    assert (pulses < PERIOD_S).all()  # no thruster saturated: no request scaled down
    h = tr.cols("hx", "hy", "hz")[:-1]
    hn = np.linalg.norm(h, axis=1)[:, None]
    request = -(hn - H_MIN * H_MAX_NMS) / hn * h / DUMP_TIME_S
    checked = 0
    for k, t in enumerate(tr.t[:-1]):
        told_docked = T_BERTH_S + UPDATE_AFTER_S - 1e-9 <= t < T_UNDOCK_S - 1e-9
        if not (told_docked or (CASES[case] and not T_UNDOCK_S - 1e-9 <= t < T_UNDOCK_S + UPDATE_AFTER_S - 1e-9)):
            continue
        c_known = C_DOCKED if told_docked else np.zeros(3)
        made = sum(pulses[k, i] * np.cross(r - _c(t), F) for i, (_, r, F) in enumerate(thr)) / PERIOD_S
        force = sum(pulses[k, i] * F for i, (_, _, F) in enumerate(thr)) / PERIOD_S
        assert_allclose(made, request[k] + np.cross(c_known - _c(t), force), rtol=0, atol=DUMP_ABS_NM,
                        err_msg=f"tick at {t:g} s")
        checked += 1
    assert checked == (80 if CASES[case] else 30)


@pytest.mark.parametrize("case", list(CASES))
def test_executors_agree_through_the_events(runs, case):
    a = runs[case]["per_tick"]
    for ex in ("fused", "lockstep"):
        b = runs[case][ex]
        assert a.columns == b.columns
        rel = np.nanmax(np.abs(a.data - b.data) / np.maximum(np.abs(a.data), 1.0))
        assert rel < EXEC_REL, (ex, rel)


@pytest.mark.parametrize("case", list(CASES))
def test_propellant_per_vehicle(runs, case):
    """The summary's propellant of the vehicle is Σ F t_on / (Isp g0) over its thrusters' logged
    on-time totals; the run's total counts the station's too."""
    tr = runs[case]["fused"]
    s = tr.meta["summary"]
    on = tr.data[-1, [tr.columns.index(f"thr_on_s_{n}") for n, _, _ in _all_thrusters(CASES[case])]]
    per = on * F_N / (ISP_S * G0)
    n_v = len(vehicle_thrusters())
    assert_allclose(s["propellant_kg_by_vehicle"]["v"], per[-n_v:].sum(), rtol=PROP_REL)
    assert_allclose(s["propellant_kg"], per.sum(), rtol=PROP_REL)


def test_two_ports_name_their_columns():
    """A vehicle that uses two ports in the run has a channel at each: ``v_<port>_<name>``."""
    d = station(False, events=[BERTH, UNDOCK, dict(BERTH, t=7.0, port="fwd")])
    d["port"].append({"name": "fwd", "position": [6.0, 0.0, 0.0], "axis": [1.0, 0.0, 0.0]})
    tr = simulate(scene_from_dict(d), fused=True)
    names = [c.removeprefix("thr_on_s_") for c in tr.columns if c.startswith("thr_on_s_")]
    assert names == [f"v_{p}_{t['name']}" for p in ("aft", "fwd") for t in vehicle_thrusters()]


@pytest.mark.parametrize("change, where", [
    ({"positon_V": [1.0, 0.0, 0.0]}, "vehicle.v.thruster.r0.positon_V"),
    ({"direction_V": [0.0, 0.0, 0.0]}, "vehicle.v.thruster.r0.direction_V"),
    ({"force_N": -1.0}, "vehicle.v.thruster.r0.force_N"),
])
def test_bad_vehicle_thruster_is_one_line_naming_the_field(change, where):
    th = vehicle_thrusters()
    th[0] = {**th[0], **change}
    with pytest.raises(SceneError) as e:
        scene_from_dict(station(False, vthr=th))
    msg = str(e.value)
    assert "\n" not in msg and where in msg, msg


def test_vehicle_thruster_name_clash_is_refused():
    """A station thruster named as a vehicle's channel (``v_r0``) would share its CSV column."""
    d = station(True)
    d["thruster"][0]["name"] = "v_r0"
    with pytest.raises(SceneError, match=r"names must be unique.*'v_r0'"):
        scene_from_dict(d)


def test_recording_draws_the_vehicle_thrusters_while_docked(runs, tmp_path):
    """Read back from the .rrd: the vehicle's arrows sit at ``r_port + C_BV r_V`` (from the mass
    centre of the scene as it starts: the origin, the vehicle away) with plumes along ``-C_BV ĝ_V``,
    transparent (alpha 0) before the berth and from the undock, opaque while docked."""
    pytest.importorskip("rerun.chunk")
    from stationbed.output.rerun.recording import write_recording  # noqa: PLC0415

    scene = scene_from_dict(station(False))
    tr = runs["vehicle_only"]["fused"]
    path = write_recording(tr, scene, tmp_path / "v.rrd")
    static, rows = entity_rows(path, "world/station/thrusters")
    colours = {round(t, 6): row["Arrows3D:colors"] for t, row in rows}
    thr = _all_thrusters(False)
    assert static["Arrows3D:labels"] == [n for n, _, _ in thr]
    assert_allclose(static["Arrows3D:origins"], [r for _, r, _ in thr], atol=1e-5)  # (float32)
    v = np.array(static["Arrows3D:vectors"])
    assert_allclose(v / np.linalg.norm(v, axis=1, keepdims=True), -np.array([F / F_N for _, _, F in thr]), atol=1e-6)
    times = sorted(colours)
    for t in tr.t:
        latest = colours[max(s for s in times if s <= t + 1e-9)]
        alpha = np.array([int(col) & 0xFF for col in latest])
        docked = T_BERTH_S - 1e-9 <= t < T_UNDOCK_S - 1e-9
        assert (alpha == (255 if docked else 0)).all(), (t, alpha)


#: the compiled shift against the numbers written out here: the same divisions and maxima in the
#: same order (round-off of one division and one add per column)
SHIFT_REL = 1e-14


def test_masked_shift_skips_zero_entries_and_zero_columns():
    """The shift whose supports are numbers (a vehicle's thrusters come and go): along each column
    of V the least ``s = max_{i: V_ik > 0} (-F_i / V_ik)`` (zero entries never chosen: a thruster
    that cannot fire), none along an all-zero column, then clipped at 0 and scaled so no force
    exceeds its F_max; written out here in numpy on draws with zero entries and a zero column."""
    import casadi as ca

    from stationbed.loop.thrusters import map_min_norm_shift

    rng = np.random.default_rng(35)
    n, m = 7, 3
    M_s, V_s, f_s, L_s = ca.SX.sym("M", n, 3), ca.SX.sym("V", n, m), ca.SX.sym("f", n), ca.SX.sym("L", 3)
    f = ca.Function("f", [M_s, V_s, f_s, L_s], [map_min_norm_shift(M_s, V_s, f_s, L_s, None)])
    for _ in range(50):
        M = rng.normal(size=(n, 3))
        V = np.abs(rng.normal(size=(n, m))) * (rng.random((n, m)) < 0.5)
        V[:, 2] = 0.0  # a padding column
        f_max = rng.uniform(50.0, 150.0, n)
        L = rng.normal(size=3) * 100.0
        F = M @ L
        for k in range(m):
            sup = V[:, k] > 0.0
            if sup.any():
                F = F + max(-F[sup] / V[sup, k]) * V[:, k]
        F = np.maximum(F, 0.0)
        F = F / max(1.0, max(F / f_max))
        assert_allclose(np.array(f(M, V, f_max, L)).ravel(), F, rtol=SHIFT_REL, atol=SHIFT_REL * np.abs(F).max())


def test_lp_mapping_with_vehicle_thrusters_is_refused():
    d = station(False)
    d["thrusters"]["mapping"] = "lp"
    with pytest.raises(SceneError, match=r"thrusters\.mapping: 'lp' is not flown with a vehicle's thrusters"):
        scene_from_dict(d)


def test_docked_from_the_start_flies_as_the_station_own_thrusters():
    """A vehicle docked at t = 0 with no event flies its thrusters as the same thrusters declared
    as the station's (``[[thruster]]`` at ``r_port + C_BV r_V`` along ``C_BV ĝ_V``, written out by
    hand, named as the vehicle's channels): the same rows bit for bit, the availability path
    (numbers) against the fixed supports' code: the same mapping numbers, the same divisions and
    maxima in the same order, the masks exact selects (``fmax(-1e300, x) = x``), ``avail`` = 1 an
    exact product."""
    d = station(False, events=[])
    d["vehicle"][0]["port"] = "aft"
    vehicle = simulate(scene_from_dict(d), fused=True)
    d["vehicle"][0]["thruster"] = []
    d["thruster"] = [{"name": n, "position_B": r.tolist(), "direction_B": (F / F_N).tolist(), "force_N": F_N,
                      "isp_s": ISP_S} for n, r, F in _all_thrusters(False)]
    own = simulate(scene_from_dict(d), fused=True)
    assert vehicle.columns == own.columns
    assert _pulses(own, [n for n, _, _ in _all_thrusters(False)]).sum() > 1.0  # s: they fired
    assert np.array_equal(vehicle.data, own.data, equal_nan=True)


def test_lockstep_samples_with_their_own_vehicle_and_update():
    """Two Monte Carlo-like samples in one lockstep batch (another vehicle mass: another mass centre
    and arms; another update delay: another tick for the mapping's step) each give the rows of
    their own per-tick run (measured bit for bit; the same compiled parts, per-sample numbers)."""
    a = scene_from_dict(station(True))
    b = a.replace({"vehicle[0].mass": 6000.0, "event[1].update_after_s": 2.0})
    [(k1, t1), (k2, t2)] = run_lockstep([a, b], keep=True, fused=False)
    assert k1 == k2 == "batch"
    for scene, tr in ((a, t1), (b, t2)):
        ref = simulate(scene, fused=False)
        rel = np.nanmax(np.abs(ref.data - tr.data) / np.maximum(np.abs(ref.data), 1.0))
        assert rel < EXEC_REL, rel
    assert not np.array_equal(t1.data, t2.data)


def test_vehicle_name_that_cannot_name_columns_is_refused():
    d = station(False)
    d["vehicle"][0]["name"] = "pro-gress"
    d["event"] = [dict(e, vehicle="pro-gress") for e in d["event"]]
    with pytest.raises(SceneError, match=r"vehicle\.pro-gress\.name: 'pro-gress' names its thrusters' columns"):
        scene_from_dict(d)


def test_thruster_only_with_the_vehicle_away_is_refused():
    """Thruster-only control needs thrusters that can fire in every configuration: before the
    berth the vehicle's cannot, and the station has none (assist flies there on the CMGs alone)."""
    d = station(False)
    d["thrusters"]["mode"] = "thruster_only"
    with pytest.raises(SceneError, match=r"about the composite mass centre \[0, 0, 0\] m\), and mode 'thruster_only'"
                                         r".*no thruster can fire"):
        scene_from_dict(d)


#: a tick's on-time differenced from totals of at most 4 s (round-off ~1e-15 s on 0.1 s)
LEAK_REL = 1e-12


def test_a_vehicle_thruster_stuck_on_leaks_only_while_docked():
    """``thruster_stuck_on`` on a vehicle's thruster (named as its column, ``v_r0``) from 1 s: it
    fires the whole of every tick it is on the station (a full period per tick from the berth to
    the undock) and nothing while the vehicle is away (a leak there pushes the vehicle, not the
    station); its propellant counted in the vehicle's."""
    d = station(False)
    d["fault"] = [{"t": 1.0, "kind": "thruster_stuck_on", "unit": "v_r0"}]
    tr = simulate(scene_from_dict(d), fused=True)
    p = _pulses(tr, ["v_r0"])[:, 0]
    t0 = tr.t[:-1]
    docked = (t0 >= T_BERTH_S - 1e-9) & (t0 < T_UNDOCK_S - 1e-9)
    assert_allclose(p[docked], PERIOD_S, rtol=LEAK_REL)
    assert (p[~docked] == 0.0).all()
    on = tr.data[-1, [tr.columns.index(f"thr_on_s_v_{t['name']}") for t in vehicle_thrusters()]]
    assert_allclose(tr.meta["summary"]["propellant_kg_by_vehicle"]["v"], on.sum() * F_N / (ISP_S * G0), rtol=PROP_REL)
