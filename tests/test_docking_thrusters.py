"""Thrusters on a station that docks and undocks (issues 21 and 35): each thruster's torque is
``(r_i - c) × F_i ĝ_i`` about the composite mass centre c *of the configuration flown*, the
vehicles docked included, and flight software's mapping uses the c it was told of.

Independent truths, written out here from the scene's numbers (no library code):

* the composite mass centre of body and docked vehicle, ``c = m_v r_v / (m_s + m_v)`` (the
  body's mass centre at the origin), with ``r_v`` the port plus the vehicle's ``cm``;
* the momentum balance ``H_N(t_j) - H_N(t_0) = Σ_ticks Σ_i (r_i - c) × F_i ĝ_i Δt_on,i`` from the
  logged on-times, on a body too stiff to turn (``C_NB = E``), across a dock and an undock (the
  row interval holding the event left out: the capture's own momentum is proven in
  tests/test_docking.py);
* with ``min_on_s = 0`` every tick's pulses deliver the mapping's forces exactly, so the torque
  the thrusters make over a tick (from the logged on-times and the true arms) is the dump request
  ``-(|h| - h_min) ĥ / dump_time`` (from the logged CMG momentum) once flight software knows the
  configuration, and differs from it by exactly ``(c_known - c_true) × Σ F_i ĝ_i`` while it
  does not (the set below pushes one way: its forces never cancel, so the error shows);
* the load-time authority check: thrusters whose lines of action all pass through the docked
  station's mass centre make no torque there, whatever they make about the body's.

The per-tick, fused and lockstep executors give the same rows (the event's step is numbers in
the same compiled loop).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import simulate
from stationbed.scene import SceneError, scene_from_dict

from scenes import EXECUTORS, fly_on

PERIOD_S = 0.1  # s
T_EVENT_S = 4.0  # s, a whole number of ticks
UPDATE_AFTER_S = 2.0  # s: flight software told of the new configuration at 6 s
DURATION_S = 9.0  # s
M_S = 1.0e4  # kg, the station (its mass centre at the origin)
J_STIFF = 1.0e12  # kg m²: the body does not turn (C_NB = E to ~1e-9 rad)
M_V = 5.0e3  # kg, the vehicle
J_V = np.diag([1.0e3, 3.0e3, 3.5e3])  # kg m², about its own mass centre
R_PORT = np.array([-6.0, 0.5, 1.0])  # m
CM_V = np.array([-2.5, 0.0, 0.0])  # m, from its interface (its axes are B's)
ARM_M = 20.0  # m
F_N = 100.0  # N per thruster
ISP_S = 280.0  # s
#: the dump: CMG momentum [N m s] at 88 % of a 1e4 N m s capacity, dumped towards 10 % over 20 s
#: (~390 N m, forces of a few tens of N: no thruster saturates, so no request is scaled down)
H0_B = [6000.0, 5000.0, -4000.0]
H_MAX_NMS = 1.0e4
H_MIN = 0.1
DUMP_TIME_S = 20.0

#: ΔH_N against Σ (r - c) × F t_on: on ~2e3 N m s of impulse the 1e12 kg m² body, held by the PD
#: law, turns by < 1e-9 rad (C_NB = E to that; the undock's spring kick included): measured
#: <= 3.3e-7 N m s; the arms about a wrong c (2.8 m off) are ~6e2 N m s off
BALANCE_ABS = 1e-5  # N m s
#: a tick's delivered torque against the request: the mapping's pseudo-inverse (~1e-15 relative
#: on ~4e2 N m) and on-times differenced from totals of ~1 s (~2e-16 s, x 2e3 N m / 0.1 s):
#: measured <= 2e-12 N m; the mapping on a wrong c is ~7e1 N m off
DUMP_ABS_NM = 1e-8
#: the executors against each other (the same expressions in another order; test_executor_matrix)
EXEC_REL = 1e-8


def one_way():
    """Eight thrusters that all push along +x, +y or +z (pods at ±x fire +y and +z, pods at ±y
    fire +x and +z): torque both ways about every axis, never a pure couple."""
    th = []
    for pos, dirs in (([ARM_M, 0.0, 0.0], "yz"), ([-ARM_M, 0.0, 0.0], "yz"), ([0.0, ARM_M, 0.0], "xz"),
                      ([0.0, -ARM_M, 0.0], "xz")):
        for d in dirs:
            g = [0.0, 0.0, 0.0]
            g["xyz".index(d)] = 1.0
            th.append({"name": f"t{len(th)}", "position_B": pos, "direction_B": g, "force_N": F_N, "isp_s": ISP_S,
                       "min_on_s": 0.0})
    return th


def c_docked(port=R_PORT) -> np.ndarray:
    """The docked station's mass centre [m], by hand."""
    return M_V * (np.asarray(port) + CM_V) / (M_S + M_V)


def station(docked: bool, events=(), thrusters=None, mode="assist", port=R_PORT) -> dict:
    return {
        "name": "dock_thrusters",
        "simulation": {"duration": DURATION_S, "formulation": "momentum", "integrator": "rk4", "step": PERIOD_S,
                       "output_dt": PERIOD_S},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": M_S, "inertia": (J_STIFF * np.eye(3)).tolist()},
        "cmg": {"kind": "ideal", "max_momentum": H_MAX_NMS, "h0_B": H0_B},
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}},
        "port": [{"name": "aft", "position": list(port), "axis": [-1.0, 0.0, 0.0]}],
        "vehicle": [{"name": "v", "mass": M_V, "inertia": J_V.tolist(), "cm": CM_V.tolist(),
                     "port": "aft" if docked else ""}],
        "event": list(events),
        "thruster": one_way() if thrusters is None else thrusters,
        "thrusters": {"mode": mode, "assist_on": 0.3, "dump_stop": 0.15, "h_min": H_MIN, "dump_time_s": DUMP_TIME_S,
                      "max_dump_torque_Nm": 1.0e4},
    }


BERTH = {"kind": "berth", "t": T_EVENT_S, "vehicle": "v", "port": "aft", "update_after_s": UPDATE_AFTER_S}
UNDOCK = {"kind": "undock", "t": T_EVENT_S, "vehicle": "v", "delta_v": 0.05, "update_after_s": UPDATE_AFTER_S}
#: case -> (docked at t = 0, events, c before the event, c after it)
CASES = {"starts_docked": (True, [], c_docked(), c_docked()),
         "berth": (False, [BERTH], np.zeros(3), c_docked()),
         "undock": (True, [UNDOCK], c_docked(), np.zeros(3))}




@pytest.fixture(scope="module")
def runs():
    out = {}
    for case, (docked, events, _, _) in CASES.items():
        scene = scene_from_dict(station(docked, events))
        out[case] = {ex: fly_on(scene, ex) for ex in EXECUTORS}
    return out


def _arms(c) -> np.ndarray:
    """(n, 3): ``(r_i - c) × F_i ĝ_i`` [N m] of :func:`one_way`, written out."""
    return np.array([np.cross(np.subtract(t["position_B"], c), t["direction_B"]) * t["force_N"] for t in one_way()])


def _pulses(tr) -> np.ndarray:
    """Each tick's on-times (ticks, n) [s] from the logged totals (rows one tick apart)."""
    on = tr.data[:, [tr.columns.index(f"thr_on_s_{t['name']}") for t in one_way()]]
    return np.diff(on, axis=0)


def _true_c(case, t) -> np.ndarray:
    """The mass centre flown over the tick starting at ``t``."""
    _, events, before, after = CASES[case]
    return after if events and t >= T_EVENT_S - 1e-9 else before


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize("case", list(CASES))
def test_momentum_balance_about_the_configurations_mass_centre(runs, case, executor):
    """ΔH_N over every tick is Σ_i (r_i - c) × F_i ĝ_i Δt_on,i with c the mass centre of the
    configuration flown (vehicle docked or not), the tick holding the event left out."""
    tr = runs[case][executor]
    pulses = _pulses(tr)
    assert pulses.sum() > 1.0  # s: the dump fired throughout
    t0 = tr.t[:-1]
    expect = np.array([p @ _arms(_true_c(case, t)) for p, t in zip(pulses, t0)])
    got = np.diff(tr.H_O_N, axis=0)
    keep = ~np.isclose(tr.t[1:], T_EVENT_S, rtol=0, atol=1e-9) if CASES[case][1] else np.ones(len(t0), bool)
    assert_allclose(np.cumsum(got[keep], axis=0), np.cumsum(expect[keep], axis=0), rtol=0, atol=BALANCE_ABS)


def _known_c(case, t) -> np.ndarray:
    """The mass centre flight software believes over the tick starting at ``t``."""
    _, events, before, after = CASES[case]
    return after if events and t >= T_EVENT_S + UPDATE_AFTER_S - 1e-9 else before


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize("case", list(CASES))
def test_dump_delivered_once_the_configuration_is_known(runs, case, executor):
    """Every tick's thruster torque (logged on-times, true arms) is the dump request on the logged
    CMG momentum plus ``(c_known - c_true) × Σ F_i ĝ_i``: the request exactly where flight software
    knows the configuration (from t = 0 when the run starts docked; after ``update_after_s``)."""
    tr = runs[case][executor]
    pulses = _pulses(tr)
    assert (pulses < PERIOD_S).all()  # no thruster saturated: no request scaled down
    h = tr.cols("hx", "hy", "hz")[:-1]
    hn = np.linalg.norm(h, axis=1)[:, None]
    request = -(hn - H_MIN * H_MAX_NMS) / hn * h / DUMP_TIME_S
    G = np.array([t["direction_B"] for t in one_way()]) * F_N
    for k, t in enumerate(tr.t[:-1]):
        c_true, c_known = _true_c(case, t), _known_c(case, t)
        made = pulses[k] @ _arms(c_true) / PERIOD_S
        force = pulses[k] @ G / PERIOD_S
        assert_allclose(made, request[k] + np.cross(c_known - c_true, force), rtol=0, atol=DUMP_ABS_NM,
                        err_msg=f"tick at {t:g} s")


@pytest.mark.parametrize("case", list(CASES))
def test_executors_agree_through_the_event(runs, case):
    a = runs[case]["per_tick"]
    for ex in ("fused", "lockstep"):
        b = runs[case][ex]
        assert a.columns == b.columns
        rel = np.nanmax(np.abs(a.data - b.data) / np.maximum(np.abs(a.data), 1.0))
        assert rel < EXEC_REL, (ex, rel)


#: a port on the body's x axis: the docked mass centre on it too (c_docked(R_AXIAL) = (-2.83, 0, 0) m)
R_AXIAL = [-6.0, 0.0, 0.0]  # m


def _through(point) -> list[dict]:
    """Six thrusters at ``point`` firing ±x, ±y, ±z: no torque about it; about the origin, with
    ``point`` on the x axis, torque both ways about y and z (``point × ĝ``)."""
    return [{"name": f"p{k}", "position_B": list(point), "direction_B": list(s * np.eye(3)[a]), "force_N": F_N,
             "isp_s": ISP_S} for k, (a, s) in enumerate((a, s) for a in range(3) for s in (1.0, -1.0))]


def test_assist_set_through_the_station_mass_centre_flies():
    """About the station's own mass centre (the origin) the set makes torque about y and z: an
    assist set, flown."""
    scene = scene_from_dict(station(False, thrusters=_through(c_docked(R_AXIAL)), port=R_AXIAL))
    assert scene.thrusters.mode == "assist"


@pytest.mark.parametrize("docked, events, where", [(True, [], ""), (False, [BERTH], " after event[0] (berth v)")],
                         ids=["starts_docked", "berth"])
def test_set_through_the_docked_mass_centre_is_refused(docked, events, where):
    """Docked, the same set's lines of action pass through the composite mass centre: no torque
    about any axis, refused at load naming the configuration and its mass centre."""
    with pytest.raises(SceneError) as e:
        scene_from_dict(station(docked, events, thrusters=_through(c_docked(R_AXIAL)), port=R_AXIAL))
    msg = str(e.value)
    c = ", ".join(f"{v:.6g}" for v in c_docked(R_AXIAL))
    assert "the set makes no torque about -x, +x, -y, +y, -z, +z of B" in msg
    assert f"(about the composite mass centre [{c}] m{where})" in msg, msg


#: the LP mapping (scipy HiGHS) meets its equality rows to its primal feasibility tolerance (1e-7
#: on rows scaled to F_max = 1, x 2e3 N m of arm times force: 2e-4 N m at worst; measured 1.3e-12,
#: HiGHS's vertex solved to round-off); the mapping on a wrong c is ~7e1 N m off
LP_ABS_NM = 1e-3


def test_lp_mapping_on_the_configuration_told():
    """``mapping = "lp"`` (per tick, in Python) maps on the mass centre flight software was told of
    too: the berth's dump, as :func:`test_dump_delivered_once_the_configuration_is_known`."""
    d = station(False, [BERTH])
    d["thrusters"]["mapping"] = "lp"
    tr = simulate(scene_from_dict(d), fused=False)
    pulses = _pulses(tr)
    h = tr.cols("hx", "hy", "hz")[:-1]
    hn = np.linalg.norm(h, axis=1)[:, None]
    request = -(hn - H_MIN * H_MAX_NMS) / hn * h / DUMP_TIME_S
    G = np.array([t["direction_B"] for t in one_way()]) * F_N
    for k, t in enumerate(tr.t[:-1]):
        c_true, c_known = _true_c("berth", t), _known_c("berth", t)
        made = pulses[k] @ _arms(c_true) / PERIOD_S
        assert_allclose(made, request[k] + np.cross(c_known - c_true, pulses[k] @ G / PERIOD_S), rtol=0, atol=LP_ABS_NM,
                        err_msg=f"tick at {t:g} s")


def test_mapping_whose_structure_would_change_cannot_be_told():
    """:func:`one_way`'s pods at ±x alone have no positive null vector about the station's mass
    centre (no shift: forces clipped) but one about the docked station's: the compiled mapping
    cannot become the other, so telling flight software is refused, naming the event's key."""
    few = one_way()[:4]
    scene = scene_from_dict(station(False, [BERTH], thrusters=few))
    with pytest.raises(ValueError, match=r"^event\[0\]\.update_after_s: thrusters: the mapping on the configuration"
                                         r".*\(use update_after_s = \"never\"\)$"):
        simulate(scene, fused=False)
    simulate(scene.replace({"event[0].update_after_s": "never"}), fused=False)
