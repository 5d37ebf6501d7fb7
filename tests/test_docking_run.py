"""A docking inside a run (issue 35): one compiled loop on every executor, equal to the split run.

Independent truth: the *split run*. Fly the station alone to the event (the scene without its
events, stopped at t_e); from that run's last row (attitude, body rate, CMG momentum), work the
capture by hand here (the two bodies' angular momentum about their common mass centre, the
composite inertia by the parallel-axis theorem: no library code); fly the docked scene from that
state. The run with the ``[[event]]`` must give the same rows after t_e, on the fused, per-tick
and lockstep executors (the law told at once, so both halves design on what they fly).

The scene is deep space with an ideal CMG cluster and a PD law holding an inertial attitude: it
has no clock of its own (no orbit, no sun), so the second half may start at t = 0.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from stationbed import simulate
from stationbed.scene import scene_from_dict

from rrd_helpers import entity_rows
from scenes import fly_on

T_EVENT_S = 10.0  # s
DURATION_S = 20.0  # s
M_S, M_V = 1.0e4, 2.0e3  # kg
J_S = np.diag([4.0e4, 5.0e4, 6.0e4])  # kg m², the station about its mass centre (at 0)
J_V = np.diag([1.0e3, 3.0e3, 3.5e3])  # kg m², the vehicle about its own
R_PORT = np.array([-6.0, 0.5, 1.0])  # m
CM_V = np.array([-2.5, 0.0, 0.0])  # m, from the interface along the port's axis (-x)
CLOSING = 0.08  # m/s
RATE_VB_B = np.array([0.0, 0.001, -0.0005])  # rad/s
#: the two halves start from states equal to round-off (the hand-worked capture ~1e-16 relative
#: of |ω| ~ 1e-3 rad/s); 100 RK4 ticks of a damped closed loop keep that far below 1e-10
RTOL = 1e-10
ATOL = 1e-13  # rad/s, N m s and quaternion units alike (|ω| ~ 1e-3, |h| ~ 10)

#: the fused and per-tick loops on this scene: 1.3e-13 apart without any edge (measured), a held
#: torque wrong by 0.1 N m for one 0.1 s tick would be ~1e-6 N m s of h
LOOPS_RTOL = 1e-11
LOOPS_ATOL = 1e-11

BASE = {
    "name": "dock_split",
    "simulation": {"duration": DURATION_S, "formulation": "momentum", "integrator": "rk4", "step": 0.1,
                   "output_dt": 1.0},
    "initial": {"q_BN": (np.array([0.999, 0.02, -0.03, 0.01]) / np.linalg.norm([0.999, 0.02, -0.03, 0.01])).tolist(),
                "omega_BN_B": [0.002, -0.001, 0.0015]},
    "body": {"mass": M_S, "inertia": J_S.tolist()},
    "cmg": {"kind": "ideal", "max_torque": 50.0, "max_momentum": 500.0},
    "controller": {"name": "pd", "period": 0.1, "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.8}},
    "port": [{"name": "aft", "position": R_PORT.tolist(), "axis": [-1.0, 0.0, 0.0]}],
    "vehicle": [{"name": "v", "mass": M_V, "inertia": J_V.tolist(), "cm": CM_V.tolist()}],
}
EVENT = {"kind": "dock", "t": T_EVENT_S, "vehicle": "v", "port": "aft", "closing_velocity": CLOSING,
         "rate_VB_B": RATE_VB_B.tolist()}




def _captured(row):
    """The state just after the capture, by hand from the station's state just before."""
    w, h = row[0:3], row[3:6]
    r_v = R_PORT + CM_V  # m, the vehicle's mass centre (its axes are B's)
    r_c = M_V * r_v / (M_S + M_V)  # the composite's
    v_v = np.cross(w, r_v) + np.array([CLOSING, 0.0, 0.0])  # closing along -axis = +x
    v_c = M_V * v_v / (M_S + M_V)
    H = (J_S @ w + h + J_V @ (w + RATE_VB_B) + M_S * np.cross(-r_c, -v_c) + M_V * np.cross(r_v - r_c, v_v - v_c))
    I_c = J_S + J_V
    for m, r in ((M_S, -r_c), (M_V, r_v - r_c)):
        I_c = I_c + m * (r @ r * np.eye(3) - np.outer(r, r))
    return np.linalg.solve(I_c, H - h), h


@pytest.fixture(scope="module")
def split():
    """The split run's rows from t_e on (times shifted back by t_e)."""
    first = simulate(scene_from_dict({**BASE, "simulation": {**BASE["simulation"], "duration": T_EVENT_S}}),
                     fused=False)
    end = first.data[-1]
    q = first.cols("qw", "qx", "qy", "qz")[-1]
    w, h = _captured(np.concatenate([first.cols("wx", "wy", "wz")[-1], first.cols("hx", "hy", "hz")[-1]]))
    d = {**BASE, "initial": {"q_BN": q.tolist(), "omega_BN_B": w.tolist()},
         "simulation": {**BASE["simulation"], "duration": DURATION_S - T_EVENT_S},
         "cmg": {**BASE["cmg"], "h0_B": h.tolist()}}
    d["vehicle"] = [{**BASE["vehicle"][0], "port": "aft"}]
    assert end[0] == T_EVENT_S
    return simulate(scene_from_dict(d), fused=False)


COLS = ("qw", "qx", "qy", "qz", "wx", "wy", "wz", "hx", "hy", "hz")


@pytest.mark.parametrize("executor", ["fused", "per_tick", "lockstep"])
def test_docking_run_equals_the_split_run(split, executor):
    tr = fly_on(scene_from_dict({**BASE, "event": [EVENT]}), executor)
    after = tr.t >= T_EVENT_S
    assert_allclose(tr.t[after] - T_EVENT_S, split.t, rtol=0, atol=1e-12)
    assert_allclose(tr.cols(*COLS)[after], split.cols(*COLS), rtol=RTOL, atol=ATOL)
    assert tr.meta["summary"]["fused"] == (executor == "fused")
    assert [e["t"] for e in tr.meta["summary"]["events"]] == [T_EVENT_S, T_EVENT_S]  # the dock, the law told
    assert_array_equal(tr["config"], (tr.t >= T_EVENT_S).astype(float))


@pytest.mark.parametrize("executor", ["fused", "per_tick", "lockstep"])
def test_massless_vehicle_changes_no_row(executor):
    """A vehicle of zero mass and no surfaces docking changes nothing, bit for bit."""
    plain = fly_on(scene_from_dict(BASE), executor)
    d = {**BASE, "event": [EVENT], "vehicle": [{"name": "v", "mass": 0.0, "inertia": [[0.0] * 3] * 3}]}
    tr = fly_on(scene_from_dict(d), executor)
    assert_array_equal(tr.data[:, : len(plain.columns)], plain.data)


def test_rows_keep_their_parameters_through_another_run_of_the_system():
    """Rows made after another run of the same compiled system (the environment rate's probe
    runs one inside a run) use their own run's parameters: a docked vehicle's inertia changes
    the body rate recovered from the momentum state, so rows made with the other run's numbers
    differ (they did, before the rows kept their own copy)."""
    from stationbed.model import StationModel, Structure  # noqa: PLC0415
    from stationbed.run.rows import Rows  # noqa: PLC0415
    from stationbed.run.system import build_system  # noqa: PLC0415

    free = scene_from_dict(BASE)
    docked = scene_from_dict({**BASE, "vehicle": [{**BASE["vehicle"][0], "port": "aft"}]})
    system = build_system(Structure.of(free), "momentum", "rk4")
    model = StationModel(Structure.of(free))
    xs = np.zeros((2, system.formulation.nx))
    xs[:, 0], xs[:, 4:7] = 1.0, [[100.0, -50.0, 80.0]] * 2  # q = 1, H_O_B [N m s]
    rows = Rows(free, system, model.params(free), None)
    before = rows.make([0.0, 1.0], xs)
    simulate(docked)  # another run of the same system, with other numbers
    assert_array_equal(rows.make([0.0, 1.0], xs), before)


def test_momentum_manager_told_the_docking_designs_on_the_docked_station():
    """The law's numbers after the update are those of the same law designed from the start on
    what flight software believes of the docked station; its TEA target moves (the vehicle's
    offset makes products of inertia: ~2 deg in pitch and yaw for the Progress)."""
    from scenes import ROOT  # noqa: PLC0415
    from stationbed.model import Structure  # noqa: PLC0415
    from stationbed.run.closed_loop import plant_facts  # noqa: PLC0415
    from stationbed.run.docking import configurations, law_numbers_after  # noqa: PLC0415
    from stationbed.run.laws import build_controller  # noqa: PLC0415
    from stationbed.run.system import build_system  # noqa: PLC0415
    from stationbed.scene import knowledge_scene, load_scene  # noqa: PLC0415

    scene = load_scene(ROOT / "scenarios" / "iss_progress_docking.toml").replace(
        {"controller.name": "momentum_manager", "controller.params": {}})
    before, after = configurations(scene)
    system = build_system(Structure.of(scene), "momentum", "rk4")
    law = build_controller(scene.controller)
    law.reset(plant_facts(before, system, 0.1))
    fresh = build_controller(scene.controller)
    fresh.reset(plant_facts(after, system, 0.1))
    told = law_numbers_after(law, system, 0.1, knowledge_scene(after))
    assert_array_equal(told, np.asarray(fresh.symbolic_params(), float))
    assert np.degrees(np.abs(np.asarray(fresh.tea_design) - np.asarray(law.tea_design))).max() > 1.0


def test_recording_draws_the_vehicle_at_its_port_while_docked(tmp_path):
    """Read back from the .rrd: the vehicle's box appears at the dock, at its port (centre
    r_port + cm = (-8.5, 0.5, 1) m from the mass centre, here at the origin), with the uniform
    box of its moments (edges² = 6 (I_j + I_k - I_i) / m: 16.5, 4.5, 1.5 m²), and is cleared at
    the undock."""
    pytest.importorskip("rerun.chunk")
    from stationbed.output.rerun.recording import write_recording  # noqa: PLC0415

    undock = {"kind": "undock", "t": 15.0, "vehicle": "v", "delta_v": 0.05}
    scene = scene_from_dict({**BASE, "event": [EVENT, undock]})
    path = write_recording(simulate(scene), scene, tmp_path / "dock.rrd")
    rows = sorted(entity_rows(path, "world/station/vehicle/v")[1], key=lambda r: r[0])
    assert_allclose([t for t, _ in rows], [T_EVENT_S, 15.0], rtol=0, atol=1e-9)  # (ns on the time line)
    box = rows[0][1]
    assert_allclose(box["Boxes3D:centers"][0], R_PORT + CM_V, rtol=1e-6)  # (float32 in the recording)
    assert_allclose(sorted(box["Boxes3D:half_sizes"][0]), sorted(0.5 * np.sqrt([16.5, 4.5, 1.5])), rtol=1e-6)
    assert rows[1][1].get("Clear:is_recursive") is not None  # the undock clears it


@pytest.mark.parametrize("events", [[], [EVENT]], ids=["window", "window+dock"])
def test_fused_rows_in_bulk_around_edges_equal_the_per_tick_loop(events):
    """The fused loop runs its rows in bulk before the first edge and after the last (a torque
    window's start, a docking): the same rows as the per-tick loop, to round-off (the
    composed loop and the per-tick loop differ by round-off on this scene without any edge)."""
    window = {"kind": "constant", "torque_B": [2.0, -1.0, 0.5], "start": 5.0}  # (held on to the end)
    scene = scene_from_dict({**BASE, "torque": [window], "event": events})
    fused, per_tick = simulate(scene, fused=True), simulate(scene, fused=False)
    assert fused.meta["summary"]["fused"] and not per_tick.meta["summary"]["fused"]
    assert_allclose(fused.data, per_tick.data, rtol=LOOPS_RTOL, atol=LOOPS_ATOL)


#: positions read back from a recording: float32 (~6e-8 relative) of ~2 m, and a rotation of float32
#: quaternion components
RRD_ABS = 1e-6  # m


def test_recording_origin_is_the_docked_mass_centre(tmp_path):
    """Read back from the .rrd: a station that starts with the vehicle docked is drawn about the
    composite mass centre of body and vehicle, c0 = m_v (r_port + cm) / (m_s + m_v) by hand (the
    body's box at -c0, the vehicle's at r_port + cm - c0), so it turns about the point the
    physics turns it about; after the undock the mass centre is the body's (the origin of B),
    and the station's frame is put at C_NB c0 (the body's centre at the world origin again)."""
    pytest.importorskip("rerun.chunk")
    from scipy.spatial.transform import Rotation  # noqa: PLC0415 (independent of the library's rotations)

    from stationbed.output.rerun.recording import write_recording  # noqa: PLC0415

    undock = {"kind": "undock", "t": T_EVENT_S, "vehicle": "v", "delta_v": 0.05}
    vehicle = [{**BASE["vehicle"][0], "port": "aft"}]
    scene = scene_from_dict({**BASE, "vehicle": vehicle, "event": [undock]})
    path = write_recording(simulate(scene), scene, tmp_path / "undock.rrd")
    c0 = M_V * (R_PORT + CM_V) / (M_S + M_V)  # m, the composite's (the vehicle's axes are B's)
    body, _ = entity_rows(path, "world/station/body")
    assert_allclose(body["Boxes3D:centers"][0], -c0, rtol=0, atol=RRD_ABS)
    box = sorted(entity_rows(path, "world/station/vehicle/v")[1], key=lambda r: r[0])[0]
    assert box[0] == 0.0
    assert_allclose(box[1]["Boxes3D:centers"][0], R_PORT + CM_V - c0, rtol=0, atol=RRD_ABS)
    frames = entity_rows(path, "world/station")[1]
    assert len(frames) == DURATION_S + 1  # a row a second
    for t, row in frames:
        C_NB = Rotation.from_quat(row["Transform3D:quaternion"][0]).as_matrix()
        origin_N = np.asarray(row.get("Transform3D:translation", [[0.0, 0.0, 0.0]])[0])
        body_N = origin_N + C_NB @ -c0  # where the body's mass centre is drawn
        assert_allclose(body_N, -C_NB @ c0 if t < T_EVENT_S else np.zeros(3), rtol=0, atol=RRD_ABS, err_msg=f"t = {t} s")
