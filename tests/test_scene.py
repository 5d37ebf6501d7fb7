"""Scene files: the contract keys, and bad input -> one clear line naming the field."""

import copy

import pytest
from numpy.testing import assert_allclose

from scenes import RIGID, SCENARIOS, scenario_ids
from stationbed import SceneError, load_scene
from stationbed.model.environment import C_ON
from stationbed.core.rotation import dcm
from stationbed.scene import scene_from_dict
from stationbed.run.initial import initial_state


@pytest.mark.parametrize("path", SCENARIOS, ids=scenario_ids())
def test_shipped_scenarios_load_and_say_what_they_show(path):
    scene = load_scene(path)
    first = path.read_text().splitlines()[0]
    assert first.startswith("# ") and path.stem in first
    assert scene.name == path.stem
    assert scene.description


def bad(mutate):
    d = copy.deepcopy(RIGID)
    mutate(d)
    return d


CASES = {
    "unknown_key": (lambda d: d["simulation"].update(rtoll=1e-9), r"simulation\.rtoll: unknown key; did you mean 'rtol'\?"),
    "unknown_top": (lambda d: d.update(orbitt={}), r"orbitt: unknown key; did you mean 'orbit'\?"),
    "missing_key": (lambda d: d["body"].pop("mass"), r"body\.mass: missing required key"),
    "missing_table": (lambda d: d.pop("simulation"), r"simulation: missing required key"),
    "nan": (lambda d: d["initial"].update(omega_BN_B=[0.0, float("nan"), 0.0]), r"initial\.omega_BN_B\[1\]: must be a finite number"),
    "inf": (lambda d: d["body"].update(mass=float("inf")), r"body\.mass: must be a finite number"),
    "negative_mass": (lambda d: d["body"].update(mass=-1.0), r"body\.mass: .*greater than 0"),
    "triangle": (lambda d: d["body"].update(inertia=[[1, 0, 0], [0, 1, 0], [0, 0, 3]]), r"body\.inertia: .*triangle inequality"),
    "indefinite": (lambda d: d["body"].update(inertia=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]), r"body\.inertia: not positive definite"),
    "asymmetric": (lambda d: d["body"].update(inertia=[[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]), r"body\.inertia: not symmetric"),
    "wrong_shape": (lambda d: d["body"].update(cm=[0.0, 0.0]), r"body\.cm: wrong length"),
    "non_unit_quat": (lambda d: d["initial"].update(q_BN=[1.0, 0.1, 0.0, 0.0]), r"initial\.q_BN: quaternion norm is 1\.00498756, not 1"),
    "zero_duration": (lambda d: d["simulation"].update(duration=0.0), r"simulation\.duration: must be at least 1e-06 s, got 0\.0"),
    "bad_profile_key": (
        lambda d: d.update(appendage=[{"name": "a", "mass": 1.0, "inertia": RIGID["body"]["inertia"], "alpha": {"ampl": 1.0}}]),
        r"appendage\.a\.alpha\.ampl: unknown key; did you mean 'amp'\?",
    ),
    "torque_kind": (lambda d: d.update(torque=[{"kind": "constnt", "torque_B": [1, 0, 0]}]), r"torque\[0\]"),
    "window_order": (lambda d: d.update(torque=[{"kind": "constant", "torque_B": [1, 0, 0], "start": 5.0, "stop": 1.0}]), r"torque\[0\]: stop"),
    "lvlh_no_orbit": (lambda d: d["initial"].update(frame="lvlh"), r"needs an \[orbit\] table"),
    "orbit_both_sizes": (lambda d: d.update(orbit={"radius": 7e6, "altitude": 4e5}), r"orbit: give exactly one"),
}


@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_bad_scene_gives_one_line_naming_the_field(case):
    mutate, pattern = CASES[case]
    with pytest.raises(SceneError, match=pattern) as err:
        scene_from_dict(bad(mutate), source="s.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("s.toml: ")


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "nope.toml")


def test_malformed_toml(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("name = 'x'\n[simulation\nduration = 1\n")
    with pytest.raises(SceneError, match="malformed TOML"):
        load_scene(p)


def test_binary_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_bytes(b"\xff\xfe\x00\x01")
    with pytest.raises(SceneError, match="not a UTF-8"):
        load_scene(p)


def test_unit_quaternion_rounding_is_normalised():
    d = bad(lambda d: d["initial"].update(q_BN=[1.0 + 1e-9, 0.0, 0.0, 0.0]))
    assert scene_from_dict(d).initial.q_BN == [1.0, 0.0, 0.0, 0.0]


def test_lvlh_initial_state_is_lvlh_at_rest():
    """frame = 'lvlh', identity, zero rate: C_BN = C_ON(u0) and ω_BN_B = (0, -n, 0)."""
    d = bad(lambda d: d.update(orbit={"altitude": 4e5, "inclination": 0.9, "u0": 0.7}))
    d["initial"]["frame"] = "lvlh"
    scene = scene_from_dict(d)
    q, w = initial_state(scene)
    assert_allclose(dcm(q), C_ON(0.7, 0.9), atol=1e-15)
    assert_allclose(w, [0.0, -scene.orbit.mean_motion, 0.0], atol=1e-18)
