"""Knowledge is not truth (issue 20 item 2): the law designs on what flight software believes
(``[knowledge]``, the nominal scene in a Monte Carlo), never on the truth being flown.

Truths:
- in a Monte Carlo with dispersed inertia, ``lqr``'s designed gain is the same in every sample
  (bit for bit) and equals the design on the nominal inertia given by hand (a :class:`Plant`
  built here), while the drawn truths differ;
- a dispersion marked ``known`` reaches the law: each sample's gain is the design on that
  sample's drawn inertia (read back from the row), and the gains differ;
- ``pd``'s first command ``τ = -k J e`` (zero rate, inertial reference, no rate limit) uses the
  composite inertia computed by hand from the ``[knowledge]`` mass properties (parallel-axis
  theorem about the composite mass centre, numpy only), not the truth's;
- nothing reachable from the Plant is the flown scene or one of its tables, and no number of the
  flown truth's dispersed inertia appears anywhere in it;
- a failed CMG unit is unknown to the law (capacity of all units) unless ``failed_units`` says so,
  while the run's own capacity is the truth's working units';
- each Monte Carlo row records the truth drawn and, ``told.``, the nominal (or, known, the drawn)
  value the law was told;
- bad ``[knowledge]`` input: one-line errors naming the key.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from pydantic import BaseModel

from controllers.lqr import LQR
from controllers.pd import PD
from stationbed import load_scene, montecarlo, simulate
from stationbed.run.closed_loop import plant_facts
from stationbed.run.controller import Plant
from stationbed.run.prepare import prepare
from stationbed.scene import SceneError, knowledge_scene, scene_from_dict
from stationbed.studies.montecarlo.dispersions import check_keys
from stationbed.studies.montecarlo.replay import sample_scene

#: JEOD ISS principal inertia [kg m²] (scenarios/iss_lvlh_hold.toml)
NOMINAL_I = [[1.02e8, 0.0, 0.0], [0.0, 0.91e8, 0.0], [0.0, 0.0, 1.64e8]]
PERIOD_S = 0.1  # s, the controller period (10 Hz)
#: the knowledge's composite inertia is formed by the compiled model from the same numbers the
#: hand computation uses: float64 rounding of 1e8-size sums only
INERTIA_RTOL = 1e-13
#: a command is -k J e with the hand inertia: a few roundings of products of 1e8-size numbers
TAU_RTOL = 1e-12
# lqr's reset also computes its loop margins (~1.5 s on this machine): two samples per study
# (the truth differs between them; every sample's gain is compared)

#: the smallest relative difference between truth and knowledge that the tests rely on (the
#: 5 % dispersion or the 10-30 % [knowledge] offsets make it far larger)
DIFFERS = 1e-3


def lqr_study(known: bool = False, n: int = 2, more=()):
    """A rigid station on a 400 km orbit flown by lqr, its inertia dispersed 5 % (one tick)."""
    d = {
        "name": "knowledge_lqr",
        "simulation": {"duration": PERIOD_S, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"frame": "lvlh", "q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 4.0e5, "inertia": NOMINAL_I, "cm": [0.0, 0.0, 0.0]},
        "orbit": {"altitude": 400000.0, "inclination": 0.9006, "u0": 0.3, "gravity_gradient": True},
        "controller": {"name": "lqr", "period": PERIOD_S, "params": {"max_torque": 20.0}},
        "montecarlo": {"n": n, "seed": 11, "envelope_dt": None, "disperse": [
            {"key": "body.inertia", "kind": "inertia", "sigma": 0.05, "sigma_products": 0.005, "known": known},
            *more]},
    }
    return scene_from_dict(d)


def flown_gain(scene, k):
    """Sample k drawn and flown as the Monte Carlo flies it; the lqr law's designed gain."""
    s = sample_scene(scene, k)
    law = LQR(period=PERIOD_S)
    simulate(s, controller=law, keep=False)
    return s, law.K


def hand_design(inertia, mean_motion):
    """lqr designed on a Plant built here by hand (the inertia given, nothing else)."""
    law = LQR(period=PERIOD_S)
    law.reset(Plant(scene=None, inertia_O_B=np.array(inertia, float), mean_motion=mean_motion, period=PERIOD_S))
    return law.K


def test_lqr_gain_is_the_nominal_design_in_every_sample():
    scene = lqr_study()
    flown = [flown_gain(scene, k) for k in range(2)]
    truths = [np.array(s.body.inertia) for s, _ in flown]
    for a in truths[1:]:
        assert np.max(np.abs(a - truths[0]) / np.abs(truths[0]).max()) > DIFFERS  # the truth differs
    K_nominal = hand_design(NOMINAL_I, scene.orbit.mean_motion)
    for _, K in flown:
        assert np.array_equal(K, flown[0][1])
        assert_allclose(K, K_nominal, rtol=0, atol=0)


def test_a_known_dispersion_reaches_the_law():
    scene = lqr_study(known=True)
    res = montecarlo(scene)
    gains = []
    for k in range(2):
        row = res.df.iloc[k]
        J = np.zeros((3, 3))
        for i in range(3):
            for j in range(i, 3):
                J[i, j] = J[j, i] = row[f"body.inertia[{i}][{j}]"]
                assert row[f"told.body.inertia[{i}][{j}]"] == J[i, j]  # what the law was told
        _, K = flown_gain(scene, k)
        assert_allclose(K, hand_design(J, scene.orbit.mean_motion), rtol=1e-12, atol=0)
        gains.append(K)
    assert np.max(np.abs(gains[1] - gains[0])) > DIFFERS * np.max(np.abs(gains[0]))


def test_monte_carlo_rows_record_the_truth_and_what_the_law_was_told():
    gain = {"key": "controller.params.max_torque", "kind": "scale_uniform", "low": -0.2, "high": 0.2}
    angle = {"key": "initial.q_BN", "kind": "attitude_normal", "sigma": 0.01}
    res = montecarlo(lqr_study(more=[gain, angle]))
    for k in range(2):
        row = res.df.iloc[k]
        for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
            assert row[f"told.body.inertia[{i}][{j}]"] == NOMINAL_I[i][j]
        assert abs(row["body.inertia[0][0]"] - NOMINAL_I[0][0]) > DIFFERS * NOMINAL_I[0][0]
        # the law's own setting is built with the drawn value: it is what the law was told
        assert row["told.controller.params.max_torque.scale"] == pytest.approx(row["controller.params.max_torque.scale"], rel=1e-15)
        assert row["initial.q_BN.angle"] > 0.0 and row["told.initial.q_BN.angle"] == 0.0


# -- pd on a [knowledge] inertia: an independent hand computation ---------------------------------

TRUTH_BODY = {"mass": 3.0e5, "inertia": [[9.0e7, 1.0e6, 0.0], [1.0e6, 8.0e7, 0.0], [0.0, 0.0, 1.5e8]],
              "cm": [1.0, 0.0, -0.5]}
KNOWN_BODY = {"mass": 3.3e5, "inertia": [[1.1e8, -2.0e6, 5.0e5], [-2.0e6, 7.0e7, 0.0], [5.0e5, 0.0, 1.6e8]],
              "cm": [0.0, 0.5, 0.0]}
ARRAY = {"name": "wing", "mass": 5000.0, "inertia": [[1.0e6, 0.0, 0.0], [0.0, 9.0e5, 0.0], [0.0, 0.0, 1.5e5]],
         "cm": [0.0, 40.0, 2.0]}  # alpha = beta = 0: its P axes are B's
THETA0_RAD = 0.01  # rad, initial rotation about (1, 2, 2)/3
BANDWIDTH = 0.005  # rad/s


def pd_scene(knowledge):
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    q0 = [math.cos(THETA0_RAD / 2), *(math.sin(THETA0_RAD / 2) * axis)]
    d = {
        "name": "knowledge_pd",
        "simulation": {"duration": PERIOD_S, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"q_BN": q0, "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": TRUTH_BODY,
        "appendage": [{**ARRAY, "alpha": {"a0": 0.0}, "beta": {"a0": 0.0}}],
        "controller": {"name": "pd", "period": PERIOD_S,
                       "params": {"reference": "inertial", "bandwidth": BANDWIDTH, "max_slew_rate": 1.0}},
    }
    if knowledge:
        d["knowledge"] = knowledge
    return scene_from_dict(d)


def hand_inertia(body, arr):
    """Composite inertia about the composite mass centre (parallel-axis theorem), numpy only."""
    m = [body["mass"], arr["mass"]]
    r = [np.array(body["cm"], float), np.array(arr["cm"], float)]
    c = (m[0] * r[0] + m[1] * r[1]) / (m[0] + m[1])
    J = np.array(body["inertia"], float) + np.array(arr["inertia"], float)
    for mk, rk in zip(m, r):
        d = rk - c
        J += mk * (d @ d * np.eye(3) - np.outer(d, d))
    return J


def first_command(scene):
    tr = simulate(scene)
    return np.array([tr[f"tau_cmd_{a}"][0] for a in "xyz"]), np.asarray(scene.initial.q_BN[1:])


def test_pd_designs_on_the_knowledge_inertia():
    tau, e = first_command(pd_scene({"mass": KNOWN_BODY["mass"], "inertia": KNOWN_BODY["inertia"],
                                     "cm": KNOWN_BODY["cm"]}))
    k = 2.0 * BANDWIDTH**2  # pd: k = 2 ω_n², τ = -c J (k/c) e = -k J e at zero rate
    J_known, J_truth = hand_inertia(KNOWN_BODY, ARRAY), hand_inertia(TRUTH_BODY, ARRAY)
    assert_allclose(tau, -k * J_known @ e, rtol=TAU_RTOL, atol=0)
    assert np.max(np.abs(tau + k * J_truth @ e)) > DIFFERS * np.max(np.abs(tau))


def test_without_knowledge_the_law_designs_on_the_scene():
    scene = pd_scene(None)
    prep = prepare(scene)
    plant = plant_facts(scene, prep.system, PERIOD_S)
    assert_allclose(plant.inertia_O_B, hand_inertia(TRUTH_BODY, ARRAY), rtol=INERTIA_RTOL, atol=0)
    tau, e = first_command(scene)
    assert_allclose(tau, -2.0 * BANDWIDTH**2 * hand_inertia(TRUTH_BODY, ARRAY) @ e, rtol=TAU_RTOL, atol=0)


# -- no attribute path from the Plant to the truth ----------------------------------------------

def reachable(obj, seen=None):
    """Every object reachable from ``obj`` through dataclass fields, pydantic fields, private
    attributes, dicts, lists and tuples (ids kept to stop at cycles)."""
    seen = {} if seen is None else seen
    if id(obj) in seen:
        return seen
    seen[id(obj)] = obj
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        children = [getattr(obj, f.name) for f in dataclasses.fields(obj)]
    elif isinstance(obj, BaseModel):
        children = [getattr(obj, name) for name in type(obj).model_fields]
        children += list((obj.__pydantic_private__ or {}).values())
    elif isinstance(obj, dict):
        children = list(obj.keys()) + list(obj.values())
    elif isinstance(obj, (list, tuple, set)):
        children = list(obj)
    else:
        children = []
    for ch in children:
        reachable(ch, seen)
    return seen


def numbers_in(objs):
    out = []
    for o in objs.values():
        if isinstance(o, float):
            out.append(o)
        elif isinstance(o, np.ndarray) and o.dtype.kind == "f":
            out += o.ravel().tolist()
    return out


def test_the_law_cannot_reach_the_flown_scene():
    scene = lqr_study()
    s = sample_scene(scene, 1)
    prep = prepare(s)
    plant = plant_facts(s, prep.system, PERIOD_S)
    truth_objects = {i for i, o in reachable(s).items() if isinstance(o, (BaseModel, list, dict))}
    from_plant = reachable(plant)
    assert not truth_objects & set(from_plant)
    drawn = {v for i, row in enumerate(s.body.inertia) for j, v in enumerate(row) if NOMINAL_I[i][j] != v}
    assert len(drawn) >= 3
    assert not drawn & set(numbers_in(from_plant))
    assert plant.scene.knowledge is None and plant.scene.montecarlo is None
    assert plant.scene.body.inertia == NOMINAL_I


SCENARIOS = sorted((Path(__file__).resolve().parents[1] / "scenarios").glob("*.toml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_no_table_of_a_shipped_scene_is_shared_with_its_knowledge_scene(path):
    """The knowledge scene is validated anew from the scene's values (no deep copy): no table,
    list or dict of the flown scene (a Monte Carlo sample's too) is reachable from it, tables
    left at their defaults (``initial``, ``controller.sensor``, the joints) included."""
    scene = load_scene(path)
    scenes = [scene] + ([sample_scene(scene, 1)] if scene.montecarlo is not None else [])
    for s in scenes:
        truth = {i for i, o in reachable(s).items() if isinstance(o, (BaseModel, list, dict))}
        assert not truth & set(reachable(knowledge_scene(s)))


# -- failed CMG units ---------------------------------------------------------------------------

def cmg_scene(knowledge=None):
    d = {
        "name": "knowledge_cmg",
        "simulation": {"duration": 1.0, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"frame": "lvlh"},
        "body": {"mass": 4.0e5, "inertia": NOMINAL_I},
        "orbit": {"altitude": 400000.0, "inclination": 0.9006},
        "cmg": {"kind": "dgcmg", "count": 4, "h_rotor": 4760.0, "failed": [2]},
        "controller": {"name": "pd", "period": PERIOD_S},
    }
    if knowledge:
        d["knowledge"] = knowledge
    return scene_from_dict(d)


H_ROTOR = 4760.0  # N m s per unit: a dgcmg cluster's capacity is units x h_rotor


@pytest.mark.parametrize("knowledge, units_believed", [(None, 4), ({"failed_units": [2]}, 3)],
                         ids=["failure-unknown", "failure-known"])
def test_a_failed_unit_is_known_only_when_listed(knowledge, units_believed):
    scene = cmg_scene(knowledge)
    prep = prepare(scene)
    plant = plant_facts(scene, prep.system, PERIOD_S)
    assert plant.h_capacity == units_believed * H_ROTOR
    summary = simulate(scene, keep=False).meta["summary"]
    assert summary["h_capacity_Nms"] == 3 * H_ROTOR  # the run's metrics: the truth's working units


def test_knowledge_cmg_limits_reach_the_law():
    scene = cmg_scene({"cmg": {"h_rotor": 4000.0, "max_gimbal_rate": 0.01}, "failed_units": []})
    plant = plant_facts(scene, prepare(scene).system, PERIOD_S)
    assert plant.h_capacity == 4 * 4000.0 and plant.h_rotor == 4000.0 and plant.max_gimbal_rate == 0.01
    assert knowledge_scene(scene).cmg.failed == []


# -- bad input ------------------------------------------------------------------------------------

@pytest.mark.parametrize("knowledge, message", [
    ({"inertia": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 3.0]]}, "knowledge.inertia: principal moments"),
    ({"mass": -1.0}, "knowledge.mass: must be greater than 0"),
    ({"failed_units": [5]}, "knowledge: the plant it believes is refused: cmg.failed: must be distinct unit numbers 1..4"),
    ({"values": {"body.inertai": 1.0}}, "did you mean 'inertia'"),
    ({"intertia": NOMINAL_I}, "knowledge.intertia: unknown key; did you mean 'inertia'?"),
], ids=["triangle", "mass", "failed-unit", "values-typo", "key-typo"])
def test_bad_knowledge_is_refused_naming_the_key(knowledge, message):
    with pytest.raises(SceneError, match=None) as err:
        cmg_scene(knowledge)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_failed_units_need_a_cluster():
    with pytest.raises(SceneError, match="knowledge.failed_units: needs a \\[cmg\\] table"):
        pd_scene({"failed_units": [1]})


def test_a_known_dispersion_cannot_contradict_a_stated_belief():
    scene = lqr_study(known=True).replace({"knowledge.inertia": NOMINAL_I})
    with pytest.raises(SceneError, match=r"montecarlo.disperse\[0\].known: 'body.inertia' is given by \[knowledge\] inertia"):
        check_keys(scene)


# -- the planner plans on knowledge -----------------------------------------------------------------

def test_the_planner_plans_on_knowledge():
    from stationbed import load_scene
    from stationbed.plan.scene_problem import scene_problem

    J_known = [[3.0e7, 0.0, 0.0], [0.0, 4.0e7, 0.0], [0.0, 0.0, 5.0e7]]  # kg m², not the scene's
    radius_m = 6.8e6  # m, the believed orbit (the scene's is 6714455 m)
    mu = 3.986004418e14  # m³/s², [orbit] mu's default
    scene = load_scene("scenarios/iss_zpm_2006.toml").replace({
        "knowledge.inertia": J_known, "knowledge.cmg.max_momentum": 12000.0,
        "knowledge.orbit": {"radius": radius_m, "inclination": 0.9006}})
    prob = scene_problem(scene)
    assert_allclose(prob.model.J, J_known, rtol=INERTIA_RTOL, atol=0)  # one body at its mass centre
    assert prob.h_max == 12000.0
    assert_allclose(prob.model.n2, mu / radius_m**3, rtol=1e-14, atol=0)


def test_the_command_line_refuses_bad_knowledge_with_exit_2(tmp_path, capsys):
    from stationbed.cli import main

    path = tmp_path / "bad_knowledge.toml"
    path.write_text('name = "k"\n[simulation]\nduration = 1.0\n[body]\nmass = 1.0\n'
                    'inertia = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.5]]\n'
                    '[knowledge]\nmass = 0.0\n')
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("stationbed: error: ") and "knowledge.mass: must be greater than 0" in err[0]
