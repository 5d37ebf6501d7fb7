"""Docking and undocking (issue 35): mass properties, the capture jump, the separation impulse.

Independent truths, worked here without the library's docking code:

* the composite's mass centre and inertia: the parallel-axis theorem by hand for a body and a
  vehicle at a port (numbers in the comments), with the port turned 90 deg about z;
* a capture keeps the angular momentum of the two bodies about their common mass centre: the
  sum over the bodies of spin + ``m (r_i - r_c) × (v_i - v_c)``, from each body's state
  (station: ``I_s ω + Σ I_p ω_p + h`` about its own mass centre, moving at the orbit's velocity;
  vehicle: its inertia, its rate, its mass centre's position and velocity), equals the momentum
  of the state after the jump (round-off);
* an undocking spring's angular impulse on a station at rest: ``r × F`` worked by hand;
* a massless vehicle changes nothing, bit for bit (parameters and state).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from scenes import RIGID
from stationbed import FORMULATIONS
from stationbed.model import StationModel, Structure
from stationbed.model.docking import event_jump, event_terms
from stationbed.scene import SceneError, configuration_changes, scene_from_dict

#: mass properties are sums of a few products of numbers ~1e2..1e4: 1e-12 relative is round-off
MASS_RTOL = 1e-12
#: angular momentum after a jump: a few 3x3 products and one inverse of an inertia ~1e6 kg m²
#: with condition ~3: round-off, 1e-12 of |H| ~ 1e3..1e4 N m s
H_RTOL = 1e-12
H_ATOL = 1e-9  # N m s


def _q_z(angle):
    """Euler parameters (scalar first) of a turn by ``angle`` about z."""
    return [float(np.cos(angle / 2)), 0.0, 0.0, float(np.sin(angle / 2))]


def docking_dict(vehicle_mass=50.0, q_VB=(1.0, 0.0, 0.0, 0.0), docked=False, events=()):
    """RIGID's station (100 kg here) with one port at (3, 0, 0), axis +x, and one vehicle."""
    d = {**RIGID, "body": {"mass": 100.0, "inertia": [[10.0, 0, 0], [0, 20.0, 0], [0, 0, 30.0]], "cm": [0, 0, 0]}}
    d["port"] = [{"name": "aft", "position": [3.0, 0.0, 0.0], "axis": [1.0, 0.0, 0.0], "q_VB": list(q_VB)}]
    inertia = [[2.0, 0, 0], [0, 5.0, 0], [0, 0, 6.0]] if vehicle_mass else [[0.0] * 3] * 3
    d["vehicle"] = [{"name": "v", "mass": vehicle_mass, "inertia": inertia, "cm": [1.0, 0.0, 0.0],
                     "port": "aft" if docked else ""}]
    d["event"] = list(events)
    return d


def _I0(scene):
    model = StationModel(Structure.of(scene))
    return model.params(scene)[model.layout["I0"]].reshape(3, 3)


# ---------------------------------------------------------------------------------------
# mass properties
# ---------------------------------------------------------------------------------------


def test_composite_inertia_is_the_parallel_axis_sum_by_hand():
    # vehicle mass centre at 3 + 1 = 4 m on x; composite at 50 * 4 / 150 = 4/3 m.
    # body: 100 kg at 4/3 m -> + 100 (16/9) = 177.78 on yy, zz; vehicle: 50 kg at 8/3 m -> + 355.56
    I0 = _I0(scene_from_dict(docking_dict(docked=True)))
    d_b, d_v = 4.0 / 3.0, 8.0 / 3.0  # m
    by_hand = np.diag([10.0 + 2.0, 20.0 + 5.0 + 100 * d_b**2 + 50 * d_v**2, 30.0 + 6.0 + 100 * d_b**2 + 50 * d_v**2])
    assert_allclose(I0, by_hand, rtol=MASS_RTOL, atol=0)


def test_turned_port_turns_the_vehicle():
    # q_VB a quarter turn about z: V's x is B's y, so the vehicle's mass centre is at (3, 1, 0)
    # and its inertia diag(2, 5, 6) in V is diag(5, 2, 6) in B. Composite at (1, 1/3, 0) m;
    # body at -(1, 1/3, 0), vehicle at (2, 2/3, 0) from it: products -m x y.
    I0 = _I0(scene_from_dict(docking_dict(q_VB=_q_z(np.pi / 2), docked=True)))
    rb, rv = np.array([-1.0, -1.0 / 3.0, 0.0]), np.array([2.0, 2.0 / 3.0, 0.0])
    by_hand = np.diag([10.0, 20.0, 30.0]) + np.diag([5.0, 2.0, 6.0])
    for m, r in ((100.0, rb), (50.0, rv)):
        x, y = r[0], r[1]
        by_hand += m * np.array([[y * y, -x * y, 0.0], [-x * y, x * x, 0.0], [0.0, 0.0, x * x + y * y]])
    assert_allclose(I0, by_hand, rtol=MASS_RTOL, atol=1e-12)


def test_massless_vehicle_changes_no_parameter():
    free = scene_from_dict(RIGID | {"body": docking_dict()["body"]})
    docked = scene_from_dict(docking_dict(vehicle_mass=0.0, docked=True))
    m1, m2 = StationModel(Structure.of(free)), StationModel(Structure.of(docked))
    assert_array_equal(m1.params(free), m2.params(docked))


# ---------------------------------------------------------------------------------------
# the capture: angular momentum of the two bodies about their common mass centre
# ---------------------------------------------------------------------------------------

OMEGA_BN_B = np.array([0.01, -0.02, 0.015])  # rad/s, the station's rate at contact
RATE_VB_B = np.array([0.002, 0.001, -0.003])  # rad/s, the vehicle's rate relative to it
CLOSING = 0.1  # m/s
LATERAL_B = [0.0, 0.02, -0.01]  # m/s


def _two_body_momentum(m_s, r_s, H_s, m_v, r_v, I_v, omega_v, v_rel):
    """Σ spin + m (r_i - r_c) × (v_i - v_c) about the common mass centre (station at rest in
    the frame moving with its mass centre: v_s = 0, v_v = v_rel)."""
    r_c = (m_s * r_s + m_v * r_v) / (m_s + m_v)
    v_c = m_v * v_rel / (m_s + m_v)
    return H_s + I_v @ omega_v + m_s * np.cross(r_s - r_c, -v_c) + m_v * np.cross(r_v - r_c, v_rel - v_c)


@pytest.mark.parametrize("form", sorted(FORMULATIONS), ids=str)
def test_capture_keeps_the_two_bodies_momentum(form):
    event = {"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft", "closing_velocity": CLOSING,
             "rate_VB_B": list(RATE_VB_B), "lateral_velocity_B": LATERAL_B}
    before = scene_from_dict(docking_dict(q_VB=_q_z(0.3), events=[event]))
    after = before.replace(configuration_changes(before, 1))
    model = StationModel(Structure.of(before))
    assert Structure.of(after) == model.structure  # one compiled system through the event
    f = FORMULATIONS[form](model)
    p_b, p_a = model.params(before), model.params(after)
    x = np.array(ca.evalf(f.state(0.0, ca.DM([1, 0, 0, 0]), ca.DM(OMEGA_BN_B), ca.DM.zeros(0), ca.DM(p_b)))).ravel()
    K, c = event_terms(before, after, before.event[0])
    x_after = np.array(ca.evalf(event_jump(f, 10.0, ca.DM(x), ca.DM(p_b), ca.DM(p_a), ca.DM(K), ca.DM(c)))).ravel()
    H_after = np.array(ca.evalf(f.H_O_B(10.0, ca.DM(x_after), ca.DM(p_a)))).ravel()
    # by hand: the station (100 kg at 0, diag(10, 20, 30)); the vehicle's mass centre at
    # (3, 0, 0) + C_BV (1, 0, 0), C_BV a turn of 0.3 rad about z; its velocity relative to the
    # station's mass centre ω × r_v + (-0.1, 0.02, -0.01) (the lateral part is off the x axis)
    ct, st = np.cos(0.3), np.sin(0.3)
    C_BV = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
    r_v = np.array([3.0, 0.0, 0.0]) + C_BV @ np.array([1.0, 0.0, 0.0])
    I_v = C_BV @ np.diag([2.0, 5.0, 6.0]) @ C_BV.T
    v_rel = np.cross(OMEGA_BN_B, r_v) + np.array([-CLOSING, 0.02, -0.01])
    H_s = np.diag([10.0, 20.0, 30.0]) @ OMEGA_BN_B
    truth = _two_body_momentum(100.0, np.zeros(3), H_s, 50.0, r_v, I_v, OMEGA_BN_B + RATE_VB_B, v_rel)
    assert_allclose(H_after, truth, rtol=H_RTOL, atol=H_ATOL)


@pytest.mark.parametrize("form", sorted(FORMULATIONS), ids=str)
def test_massless_capture_leaves_the_state_bit_for_bit(form):
    event = {"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft", "closing_velocity": CLOSING}
    before = scene_from_dict(docking_dict(vehicle_mass=0.0, events=[event]))
    after = before.replace(configuration_changes(before, 1))
    model = StationModel(Structure.of(before))
    f = FORMULATIONS[form](model)
    p_b, p_a = model.params(before), model.params(after)
    x = ca.evalf(f.state(0.0, ca.DM([1, 0, 0, 0]), ca.DM(OMEGA_BN_B), ca.DM.zeros(0), ca.DM(p_b)))
    K, c = event_terms(before, after, before.event[0])
    x_after = ca.evalf(event_jump(f, 10.0, x, ca.DM(p_b), ca.DM(p_a), ca.DM(K), ca.DM(c)))
    assert_array_equal(np.array(x_after), np.array(x))


# ---------------------------------------------------------------------------------------
# undocking: the spring's angular impulse
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("form", sorted(FORMULATIONS), ids=str)
def test_undocking_impulse_is_r_cross_f_by_hand(form):
    # a port at (0, 10, 0) with axis +x, the vehicle's mass centre 1 m out along it; the
    # station (100 kg) at rest. The spring pushes the vehicle by J = μ Δv along +x and the
    # station by -J at the port: the station's momentum about its own mass centre (at 0, once
    # the vehicle has left) is (0, 10, 0) × (-J, 0, 0) = (0, 0, 10 J).
    d = docking_dict(docked=True)
    d["port"][0].update(position=[0.0, 10.0, 0.0])
    d["event"] = [{"kind": "undock", "t": 10.0, "vehicle": "v", "delta_v": 0.05}]
    before = scene_from_dict(d)
    after = before.replace(configuration_changes(before, 1))
    model = StationModel(Structure.of(before))
    f = FORMULATIONS[form](model)
    p_b, p_a = model.params(before), model.params(after)
    x = ca.evalf(f.state(0.0, ca.DM([1, 0, 0, 0]), ca.DM.zeros(3), ca.DM.zeros(0), ca.DM(p_b)))
    K, c = event_terms(before, after, before.event[0])
    x_after = event_jump(f, 10.0, x, ca.DM(p_b), ca.DM(p_a), ca.DM(K), ca.DM(c))
    H_after = np.array(ca.evalf(f.H_O_B(10.0, x_after, ca.DM(p_a)))).ravel()
    J = (100.0 * 50.0 / 150.0) * 0.05  # N s, reduced mass x separation speed
    assert_allclose(H_after, [0.0, 0.0, 10.0 * J], rtol=H_RTOL, atol=H_ATOL)


def test_spring_energy_gives_the_separation_speed():
    # E = ½ μ Δv²: 0.5 J into a pair of reduced mass 100/3 kg -> Δv = sqrt(3/100) m/s
    d = docking_dict(docked=True)
    d["event"] = [{"kind": "undock", "t": 10.0, "vehicle": "v", "spring_energy_J": 0.5}]
    d2 = docking_dict(docked=True)
    d2["event"] = [{"kind": "undock", "t": 10.0, "vehicle": "v", "delta_v": float(np.sqrt(3.0 / 100.0))}]
    s1, s2 = scene_from_dict(d), scene_from_dict(d2)
    K1, c1 = event_terms(s1, s1.replace(configuration_changes(s1, 1)), s1.event[0])
    K2, c2 = event_terms(s2, s2.replace(configuration_changes(s2, 1)), s2.event[0])
    assert_allclose(c1, c2, rtol=MASS_RTOL, atol=0)


# ---------------------------------------------------------------------------------------
# scene errors: one line naming the key
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("change, where", [
    ({"event": [{"kind": "dock", "t": 10.0, "vehicle": "w", "port": "aft"}]}, "event[0].vehicle: no vehicle named 'w'"),
    ({"event": [{"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aftt"}]}, "did you mean 'aft'"),
    ({"event": [{"kind": "undock", "t": 10.0, "vehicle": "v"}]}, "event[0].vehicle: 'v' is not docked"),
    ({"event": [{"kind": "dock", "t": 500.0, "vehicle": "v", "port": "aft"}]}, "event[0].t: 500 s is not inside"),
    ({"event": [{"kind": "berth", "t": 10.0, "vehicle": "v", "port": "aft", "closing_velocity": 0.1}]},
     "event[0].closing_velocity: a berth"),
    ({"event": [{"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft", "delta_v": 0.1}]}, "event[0].delta_v"),
    ({"event": [{"kind": "lunch", "t": 10.0, "vehicle": "v"}]}, "event[0].kind"),
], ids=["vehicle", "port-typo", "undock-free", "after-end", "berth-moving", "dock-spring", "kind"])
def test_bad_event_is_one_line_naming_the_key(change, where):
    with pytest.raises(SceneError) as err:
        scene_from_dict(docking_dict() | change)
    assert where in str(err.value) and "\n" not in str(err.value)


# ---------------------------------------------------------------------------------------
# the vehicle's surfaces: on while it is docked, where its port puts them
# ---------------------------------------------------------------------------------------

#: the same plate sums in a different order: round-off of torques ~1e-5 N m
SRP_RTOL = 1e-12
SRP_ATOL = 1e-20  # N m


def _srp_scene(**more):
    from env_helpers import base_scene  # noqa: PLC0415

    return base_scene(**{"torque": [{"kind": "srp"}], "sun": {"direction_N": [0.3, -0.5, 0.8]},
                         "surface": [{"size": [4.0, 4.0, 4.0]}], **more})


def _tau_srp(d):
    from env_helpers import outputs  # noqa: PLC0415

    f, _, _ = outputs(d)
    return f(10.0, np.array(_q_z(0.4)))["tau_srp"]


def test_vehicle_plates_are_on_while_docked_where_the_port_puts_them():
    # a massless vehicle (the mass centre stays at 0) with a 10 m² plate, normal +z of V, 2 m
    # out along V x from its interface; docked at a port at (5, 1, 0) turned a quarter about z:
    # the plate's normal is +z of B and its centre (5, 1, 0) + (0, 2, 0) = (5, 3, 0) by hand
    plate = {"area": 10.0, "normal": [0.0, 0.0, 1.0], "centre": [2.0, 0.0, 0.0]}
    port = [{"name": "p", "position": [5.0, 1.0, 0.0], "axis": [1.0, 0.0, 0.0], "q_VB": _q_z(np.pi / 2)}]
    vehicle = {"name": "v", "mass": 0.0, "inertia": [[0.0] * 3] * 3, "surface": [plate]}
    docked = _srp_scene(port=port, vehicle=[vehicle | {"port": "p"}])
    free = _srp_scene(port=port, vehicle=[vehicle])
    by_hand = _srp_scene(surface=[{"size": [4.0, 4.0, 4.0]}, plate | {"centre": [5.0, 3.0, 0.0]}])
    alone = _srp_scene()
    assert_allclose(_tau_srp(docked), _tau_srp(by_hand), rtol=SRP_RTOL, atol=SRP_ATOL)
    assert_allclose(_tau_srp(free), _tau_srp(alone), rtol=SRP_RTOL, atol=SRP_ATOL)
    assert not np.allclose(_tau_srp(by_hand), _tau_srp(alone))  # the plate matters here
    assert Structure.of(scene_from_dict(docked)) == Structure.of(scene_from_dict(free))


def test_knowledge_of_every_configuration_names_the_same_events():
    """A Monte Carlo tells the law nominal values by key path (``[knowledge.values]``, event and
    vehicle keys among them): the knowledge of each configuration is built (past events stay,
    marked done, so ``event[0]`` still names one) and carries the nominal vehicle mass."""
    from stationbed.model.docking import docked_parts  # noqa: PLC0415
    from stationbed.scene import knowledge_scene  # noqa: PLC0415

    event = {"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft", "closing_velocity": CLOSING}
    truth = scene_from_dict(docking_dict(vehicle_mass=60.0, events=[event]) | {
        "knowledge": {"values": {"vehicle[0].mass": 50.0, "event[0].closing_velocity": 0.05}}})
    after = truth.replace(configuration_changes(truth, 1))
    assert [m for m, _, _ in docked_parts(after)] == [60.0]
    assert [m for m, _, _ in docked_parts(knowledge_scene(after))] == [50.0]  # kg: what the law is told


@pytest.mark.parametrize("which, n_docked", [("before", 0), ("after", 1), ("0", 1)])
def test_configuration_by_name(which, n_docked):
    from stationbed.model.docking import docked_parts  # noqa: PLC0415
    from stationbed.scene.docking import configuration_at  # noqa: PLC0415

    scene = scene_from_dict(docking_dict(events=[{"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft"}]))
    assert len(docked_parts(configuration_at(scene, which))) == n_docked


def test_unknown_configuration_names_the_option():
    from stationbed.scene.docking import configuration_at  # noqa: PLC0415

    scene = scene_from_dict(docking_dict(events=[{"kind": "dock", "t": 10.0, "vehicle": "v", "port": "aft"}]))
    with pytest.raises(ValueError, match=r"^--config: '1' is no configuration of 'test_rigid'; valid: before, after, 0\.\.0"):
        configuration_at(scene, "1")
