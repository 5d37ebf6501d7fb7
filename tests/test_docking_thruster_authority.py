"""What a station's thrusters can turn it about, per configuration the run flies (issues 32 and
35): the run summary's ``thruster_no_torque_about`` is the starting configuration's, and each
docking event's entry of ``events`` says it of the configuration after it (the arms about the
new composite mass centre, with the thrusters that can fire there).

Independent truths, written out here from the scene's numbers (no library code):

* the composite mass centre of body and berthed vehicle, ``c = m_v r_v / (m_s + m_v)`` (the
  body's at the origin), ``r_v = r_port + C_BV cm_V`` with the port's half turn about z,
  ``C_BV = diag(-1, -1, 1)`` by hand: ``c = (-7/6, 0, 1)`` m;
* each thruster's torque per newton ``(r - c) × ĝ`` by hand, and from it the torque authority
  (the largest torque about ``±e_k`` with none about the other two axes, forces in ``[0, F]``):
  before the berth (c = 0) the pairs give ``F h`` about ±y, ``F h`` about ±x, ``F a`` about ±z
  alone; after it the ±x pair's line passes through c (nothing), no thruster has a y arm (so no
  torque about ±y), the ±y pair at the top gives ``F (7/6)`` about ±z alone, and the ±y pair at
  ``x = a`` gives ``F (1, 0, a + 7/6)``, whose z the top pair cancels at most: ``F (7/6) / (a + 7/6)``
  about ±x;
* a vehicle's thrusters fire only while it is docked: a station set with no z arm (about the
  origin) lacks ±z until the vehicle's set (torque both ways about every axis,
  tests/test_docking_vehicle_thrusters.py) is docked, and again after it leaves.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import simulate
from stationbed.loop.thrusters import ThrusterCluster
from stationbed.scene import scene_from_dict
from stationbed.scene.docking import configuration_ports, mass_centre_B
from stationbed.scene.thrusters import torque_arms, torque_authority

from scenes import EXECUTORS, fly_on

PERIOD_S = 0.1  # s
T_BERTH_S = 2.0  # s, a whole number of ticks
T_UNDOCK_S = 5.0  # s
DURATION_S = 6.0  # s
M_S = 1.0e4  # kg, the station (its mass centre at the origin)
M_V = 5.0e3  # kg, the vehicle
R_PORT = np.array([-6.0, 0.0, 3.0])  # m
CM_V = np.array([-2.5, 0.0, 0.0])  # m, from its interface, V axes
C_BV = np.diag([-1.0, -1.0, 1.0])  # the port's half turn about z, by hand
H_M = 1.0  # m, height of the top pairs
A_M = 12.0  # m, the ±y pair's x
F_N = 100.0  # N per thruster
C_AFTER_M = np.array([-7.0 / 6.0, 0.0, 1.0])  # m, M_V (R_PORT + C_BV CM_V) / (M_S + M_V) by hand
#: the LP's authority against the hand-worked one (HiGHS's feasibility tolerance 1e-7 on rows of ~1e3)
AUTH_ABS = 1e-6  # N m

#: the hand-worked authority (3, 2) [N m], about -e_k and +e_k, before and after the berth
AUTH_BEFORE = F_N * np.array([[H_M, H_M], [H_M, H_M], [A_M, A_M]])
_X_AFTER = F_N * (7.0 / 6.0) / (A_M + 7.0 / 6.0)
AUTH_AFTER = np.array([[_X_AFTER, _X_AFTER], [0.0, 0.0], [F_N * 7.0 / 6.0, F_N * 7.0 / 6.0]])


def pairs(z_pair: bool = True) -> list[dict]:
    """Opposed pairs: at (0, 0, h) firing ±x and ±y, and (with ``z_pair``) at (a, 0, 0) firing ±y."""
    spots = [([0, 0, H_M], [1, 0, 0]), ([0, 0, H_M], [-1, 0, 0]), ([0, 0, H_M], [0, 1, 0]), ([0, 0, H_M], [0, -1, 0])]
    spots += [([A_M, 0, 0], [0, 1, 0]), ([A_M, 0, 0], [0, -1, 0])] if z_pair else []
    return [{"name": f"s{k}", "position_B": p, "direction_B": g, "force_N": F_N, "isp_s": 300.0}
            for k, (p, g) in enumerate(spots)]


def vehicle_set() -> list[dict]:
    """Eight thrusters in V axes pushing +x, +y or +z of V from pods at ±10 m of its mass centre
    (as tests/test_docking_vehicle_thrusters.py): torque both ways about every axis."""
    out = []
    for off, dirs in (([10, 0, 0], "yz"), ([-10, 0, 0], "yz"), ([0, 10, 0], "xz"), ([0, -10, 0], "xz")):
        for d in dirs:
            g = [0.0, 0.0, 0.0]
            g["xyz".index(d)] = 1.0
            out.append({"name": f"r{len(out)}", "position_V": (CM_V + off).tolist(), "direction_V": g,
                        "force_N": F_N, "isp_s": 300.0})
    return out


def station(own: list[dict], vthr: list[dict]) -> dict:
    return {
        "name": "thruster_authority",
        "simulation": {"duration": DURATION_S, "formulation": "momentum", "integrator": "rk4", "step": PERIOD_S,
                       "output_dt": PERIOD_S},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": M_S, "inertia": (1.0e9 * np.eye(3)).tolist()},
        "cmg": {"kind": "ideal", "max_momentum": 1.0e4, "h0_B": [6000.0, 5000.0, -4000.0]},
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}},
        "port": [{"name": "aft", "position": R_PORT.tolist(), "axis": [-1.0, 0.0, 0.0], "q_VB": [0.0, 0.0, 0.0, 1.0]}],
        "vehicle": [{"name": "v", "mass": M_V, "inertia": np.diag([1.0e3, 3.0e3, 3.5e3]).tolist(), "cm": CM_V.tolist(),
                     "thruster": vthr}],
        "event": [{"kind": "berth", "t": T_BERTH_S, "vehicle": "v", "port": "aft", "update_after_s": "never"},
                  {"kind": "undock", "t": T_UNDOCK_S, "vehicle": "v", "delta_v": 0.05, "update_after_s": "never"}],
        "thruster": own,
        "thrusters": {"assist_on": 0.3, "dump_stop": 0.15, "h_min": 0.1, "dump_time_s": 20.0},
    }


def _missing(auth: np.ndarray) -> str:
    """The directions of a hand-worked authority with none."""
    return ", ".join(f"{'-+'[col]}{'xyz'[k]}" for k in range(3) for col in range(2) if auth[k, col] == 0.0)


def test_hand_authority_before_and_after_the_berth():
    """The library's arms and LP agree with the hand-worked authority in both configurations
    (the summary below is checked against the hand one through :func:`_missing`)."""
    s = scene_from_dict(station(pairs(), []))
    after = configuration_ports(s)[1]
    assert_allclose(mass_centre_B(s, after), C_AFTER_M, rtol=0, atol=1e-12)  # m, round-off of 1e4 kg sums
    for c, auth in ((np.zeros(3), AUTH_BEFORE), (C_AFTER_M, AUTH_AFTER)):
        assert_allclose(torque_authority(torque_arms(s, c)[0], np.full(6, F_N)), auth, rtol=0, atol=AUTH_ABS)


@pytest.mark.parametrize("executor", EXECUTORS)
def test_summary_says_an_axis_lost_at_a_berth(executor):
    """No torque about ±y only while the vehicle is berthed: the start's key absent (every axis),
    the berth's entry the hand-worked ``-y, +y``, the undock's every axis again; the run line
    says so after the events (on every executor: the events' summary is the schedule's)."""
    tr = fly_on(scene_from_dict(station(pairs(), [])), executor)
    s = tr.meta["summary"]
    assert _missing(AUTH_BEFORE) == "" and "thruster_no_torque_about" not in s
    said = [(e["event"], e["t"], e["thruster_no_torque_about"]) for e in s["events"]]
    assert said == [(0, T_BERTH_S, _missing(AUTH_AFTER)), (1, T_UNDOCK_S, _missing(AUTH_BEFORE))]
    assert _missing(AUTH_AFTER) == "-y, +y"
    line = "; ".join(ThrusterCluster.summary_parts(s))
    assert "thruster torque after event[0] at 2 s: none about -y, +y; event[1] at 5 s: every axis" in line


def test_summary_says_an_axis_gained_while_a_vehicle_is_docked():
    """A station set with no z arm lacks ±z as it starts (the existing key), has every axis while
    the vehicle's set is berthed, and lacks ±z again once it has left."""
    s = simulate(scene_from_dict(station(pairs(z_pair=False), vehicle_set())), fused=False).meta["summary"]
    assert s["thruster_no_torque_about"] == "-z, +z"
    assert [e["thruster_no_torque_about"] for e in s["events"]] == ["", "-z, +z"]
    line = "; ".join(ThrusterCluster.summary_parts(s))
    assert line.count("thrusters make no torque about -z, +z") == 1 and "event[0] at 2 s: every axis" in line


@pytest.mark.parametrize("fused", [False, True], ids=["per_tick", "fused"])
def test_no_event_entry_without_thrusters_mode(fused):
    """``mode = "off"``: nothing is said of any configuration (the thrusters are not flown)."""
    d = station(pairs(), [])
    d["thrusters"] = {"mode": "off"}
    s = simulate(scene_from_dict(d), fused=fused).meta["summary"]
    assert all("thruster_no_torque_about" not in e for e in s["events"]) and "thruster_no_torque_about" not in s
