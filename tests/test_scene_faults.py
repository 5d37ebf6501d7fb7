"""Scene faults a user hits (issue 12, items 15 and 19): values of the wrong type, values a run
cannot honour, files the parser chokes on, and dotted-path changes (the command line's ``--set``).
Each bad input is one line naming the file (or option) and the field, as ``stationbed`` prints it
before exiting 2."""

import copy
import math

import numpy as np
import pytest

from scenes import RIGID
from stationbed.core.constants import R_EARTH_M
from stationbed.scene.environment import ALTITUDE_MIN_M
from stationbed.integrators.dop853 import StepControl
from stationbed.scene import (
    ATOL_MIN, MIN_TIME_S, RTOL_MIN, TIME_RESOLUTION, SceneError, load_scene, parse_assignment, parse_assignments,
    scene_from_dict,
)

#: the array's inertia about its mass centre [kg m²]: a 500 kg, 20 m wing along y
WING_INERTIA = [[3.0e4, 0.0, 0.0], [0.0, 1.0e3, 0.0], [0.0, 0.0, 3.0e4]]


def full_dict():
    """A scene with every table, so that each table's fields can be spoiled one at a time."""
    d = copy.deepcopy(RIGID)
    d["simulation"]["step"] = 0.01  # s
    d["simulation"]["max_step"] = 10.0  # s
    d["orbit"] = {"altitude": 4.0e5, "inclination": 0.9}  # m, rad
    d["sun"] = {"beta": 0.1}  # rad
    d["appendage"] = [{
        "name": "stbd", "mass": 500.0, "inertia": WING_INERTIA, "cm": [0.0, 10.0, 0.0], "alpha": {"rate": 0.001},
        "mode": [{"frequency_hz": 0.1, "beam": {"length": 20.0, "span": "y", "deflection": "z", "root": [0.0, -10.0, 0.0]}}],
    }]
    d["torque"] = [{"kind": "constant", "torque_B": [1.0, 0.0, 0.0], "start": 1.0, "stop": 2.0}]
    d["cmg"] = {"kind": "dgcmg", "count": 4}
    d["controller"] = {"name": "pd", "period": 0.1, "sensor": {"seed": 3}}
    return d


def spoilt(**changes):
    """``full_dict()`` with values put at slash-separated paths (``**{"body/mass": True}``)."""
    d = full_dict()
    for path, value in changes.items():
        node = d
        keys = path.split("/")
        for k in keys[:-1]:
            node = node[int(k) if k.isdigit() else k]
        last = keys[-1]
        node[int(last) if last.isdigit() else last] = value
    return d


def one_line_error(data, pattern=None):
    """The one-line message of the SceneError that ``data`` raises (checked against ``pattern``)."""
    with pytest.raises(SceneError, match=pattern) as err:
        scene_from_dict(data, source="s.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("s.toml: ")
    return msg


def test_full_dict_is_valid():
    scene_from_dict(full_dict())


# -- types: a number is a number, a bool a bool, a string a string ---------------------------------

WRONG_TYPES = {
    "mass_true": ("body/mass", True, r"body\.mass: must be a number, got true$"),
    "mass_text": ("body/mass", "100", r'body\.mass: must be a number, got "100"$'),
    "mass_huge_integer": ("body/mass", 10**400, r"body\.mass: must be a finite number, got an integer of 401 digits$"),
    "duration_text": ("simulation/duration", "100", r'simulation\.duration: must be a number, got "100"'),
    "rtol_false": ("simulation/rtol", False, r"simulation\.rtol: must be a number, got false"),
    "step_true": ("simulation/step", True, r"simulation\.step: must be a number, got true"),
    "impulse_jump_no": ("simulation/impulse_jump", "no", r'simulation\.impulse_jump: must be true or false, got "no"'),
    "impulse_jump_one": ("simulation/impulse_jump", 1, r"simulation\.impulse_jump: must be true or false, got 1"),
    "gravity_gradient_yes": ("orbit/gravity_gradient", "yes", r'orbit\.gravity_gradient: must be true or false, got "yes"'),
    "name_number": ("name", 3, r"name: must be a string, got 3"),
    "integrator_number": ("simulation/integrator", 4, r"simulation\.integrator: must be a string, got 4"),
    "description_bool": ("description", True, r"description: must be a string, got true"),
    "omega_element_true": ("initial/omega_BN_B/1", True, r"initial\.omega_BN_B\[1\]: must be a number, got true"),
    "quaternion_element_text": ("initial/q_BN/0", "1", r'initial\.q_BN\[0\]: must be a number, got "1"'),
    "frame_true": ("initial/frame", True, r"initial\.frame: must be 'inertial' or 'lvlh', got true"),
    "inertia_element_text": ("body/inertia/0/0", "100", r'body\.inertia\[0\]\[0\]: must be a number, got "100"'),
    "inertia_row_number": ("body/inertia/0", 1.0, r"body\.inertia\[0\]: must be an array, got 1\.0"),
    "appendage_rate_true": ("appendage/0/alpha/rate", True, r"appendage\.stbd\.alpha\.rate: must be a number, got true"),
    "appendage_name_number": ("appendage/0/name", 7, r"appendage\[0\]\.name: must be a string, got 7"),
    "beam_n_float": ("appendage/0/mode/0/beam/n", 1.0, r"appendage\.stbd\.mode\[0\]\.beam\.n: must be an integer, got 1\.0"),
    "beam_n_true": ("appendage/0/mode/0/beam/n", True, r"appendage\.stbd\.mode\[0\]\.beam\.n: must be an integer, got true"),
    "torque_element_text": ("torque/0/torque_B/0", "1", r'torque\[0\]\.torque_B\[0\]: must be a number, got "1"'),
    "torque_start_true": ("torque/0/start", True, r"torque\[0\]\.start: must be a number, got true"),
    "sun_beta_true": ("sun/beta", True, r"sun\.beta: must be a number, got true"),
    "orbit_mu_text": ("orbit/mu", "3.986e14", r'orbit\.mu: must be a number, got "3\.986e14"'),
    "cmg_count_float": ("cmg/count", 4.0, r"cmg\.count: must be an integer, got 4\.0"),
    "cmg_count_true": ("cmg/count", True, r"cmg\.count: must be an integer, got true"),
    "cmg_steering_number": ("cmg/steering", 1, r"cmg\.steering: must be 'mp', 'sr' or 'odsr', got 1"),
    "controller_name_true": ("controller/name", True, r"controller\.name: must be a string, got true"),
    "controller_period_text": ("controller/period", "0.1", r'controller\.period: must be a number, got "0\.1"'),
    "controller_params_number": ("controller/params", 3, r"controller\.params: must be a table, got 3"),
    "seed_float": ("controller/sensor/seed", 1.5, r"controller\.sensor\.seed: must be an integer, got 1\.5"),
    "seed_true": ("controller/sensor/seed", True, r"controller\.sensor\.seed: must be an integer, got true"),
    "seed_text": ("controller/sensor/seed", "3", r'controller\.sensor\.seed: must be an integer, got "3"'),
    "sensor_number": ("controller/sensor", 3, r"controller\.sensor: must be a table, got 3"),
}


@pytest.mark.parametrize("case", list(WRONG_TYPES), ids=list(WRONG_TYPES))
def test_value_of_the_wrong_type_is_refused_naming_field_and_value(case):
    path, value, pattern = WRONG_TYPES[case]
    one_line_error(spoilt(**{path: value}), pattern)


def test_an_integer_is_a_number():
    scene = scene_from_dict(spoilt(**{"body/mass": 1000, "simulation/duration": 100}))
    assert isinstance(scene.body.mass, float) and scene.body.mass == 1000.0


# -- bounds: values a run cannot honour ------------------------------------------------------------

OUT_OF_BOUNDS = {
    "rtol_below_floor": ({"simulation/rtol": 1e-15}, r"simulation\.rtol: must be at least 1e-14, got 1e-15 \(a double's roundoff"),
    "rtol_1e-300": ({"simulation/rtol": 1e-300}, r"simulation\.rtol: must be at least 1e-14, got 1e-300"),
    "atol_1e-300": ({"simulation/atol": 1e-300}, r"simulation\.atol: must be at least 1e-20, got 1e-300 \(a state at zero"),
    "duration_1e-300": ({"simulation/duration": 1e-300}, r"simulation\.duration: must be at least 1e-06 s, got 1e-300 \(shorter"),
    "duration_below_floor": ({"simulation/duration": 1e-7}, r"simulation\.duration: must be at least 1e-06 s, got 1e-07"),
    "output_dt_1e-300": ({"simulation/output_dt": 1e-300}, r"simulation\.output_dt: must be at least 1e-06 s"),
    "step_1e-300": ({"simulation/step": 1e-300}, r"simulation\.step: must be at least 1e-06 s"),
    "max_step_1e-300": ({"simulation/max_step": 1e-300}, r"simulation\.max_step: must be at least 1e-06 s"),
    "output_dt_unresolved": ({"simulation/duration": 1e12, "simulation/output_dt": 1.0},
                             r"simulation\.output_dt: 1 s is below 1e-09 of the duration"),
    "step_unresolved": ({"simulation/duration": 1e9, "simulation/step": 1e-4}, r"simulation\.step: 0\.0001 s is below 1e-09"),
    "max_step_unresolved": ({"simulation/duration": 1e9, "simulation/step": 10.0, "simulation/max_step": 1e-4,
                             "simulation/output_dt": 100.0},
                            r"simulation\.max_step: 0\.0001 s is below"),
    "period_1e-300": ({"controller/period": 1e-300}, r"controller\.period: must be at least 1e-06 s"),
    "period_unresolved": ({"simulation/duration": 1e9, "simulation/output_dt": 100.0, "simulation/step": 10.0},
                          r"controller\.period: 0\.1 s is below 1e-09 of the duration"),
    "radius_inside_earth": ({"orbit": {"radius": 6.0e6}}, r"orbit\.radius: 6000000 m is inside the Earth"),
    "radius_on_surface": ({"orbit": {"radius": R_EARTH_M}}, r"orbit\.radius: 6378137 m is inside the Earth"),
    # a length in km (issue 32): 400 km = 400000 m, 6778 km = 6778000 m, by hand
    "altitude_in_km": ({"orbit": {"altitude": 400.0}}, r"orbit\.altitude: 400 m is below the lowest orbit \(100000 m, "
                                                       r"100 km: the air brings it down\); did you mean 400 km = 400000 m\?$"),
    "radius_in_km": ({"orbit": {"radius": 6778.0}}, r"orbit\.radius: 6778 m is inside the Earth .*; did you mean 6778 km "
                                                    r"= 6778000 m\?$"),
    "radius_below_lowest_orbit": ({"orbit": {"radius": R_EARTH_M + 50e3}},
                                  r"orbit\.radius: 6428137 m is 50000 m above the Earth, below the lowest orbit"),
    "elements_a_in_km": ({"orbit": {"elements": {"a": 6778.0, "e": 0.0, "i": 0.9, "raan": 0.0, "argp": 0.0, "nu": 0.0}}},
                         r"orbit\.elements\.e: perigee radius 6778 m is inside the Earth .*did you mean elements\.a = "
                         r"6778 km = 6778000 m\?$"),
    "inclination_in_degrees": ({"orbit/inclination": 51.6}, r"orbit\.inclination: must be within \[0, pi\] rad"),
    "sun_beta_in_degrees": ({"sun/beta": 60.0}, r"sun\.beta: must be within \[-pi/2, pi/2\] rad"),
    "seed_negative": ({"controller/sensor/seed": -1}, r"controller\.sensor\.seed: must be greater than or equal to 0, got -1"),
    "output_dt_not_whole_periods": ({"controller/period": 0.3},
                                    r"^s\.toml: simulation\.output_dt: 1(\.0)? s is not a whole number of controller periods"),
    "delay_not_whole_periods": ({"controller/sensor/delay": 0.15},
                                r"^s\.toml: controller\.sensor\.delay: 0\.15 s is not a whole number of controller periods"),
}


@pytest.mark.parametrize("case", list(OUT_OF_BOUNDS), ids=list(OUT_OF_BOUNDS))
def test_value_a_run_cannot_honour_is_refused_naming_the_field(case):
    changes, pattern = OUT_OF_BOUNDS[case]
    one_line_error(spoilt(**changes), pattern)


def test_time_floors_sit_above_the_integrators_underflow():
    """The smallest duration or interval, and the finest fraction of the duration, stay three
    decades above the adaptive integrators' step-size underflow (``h <= 1e-12 max(1 s, t)``)."""
    assert MIN_TIME_S >= 1e3 * StepControl.UNDERFLOW_RTOL * 1.0  # s
    assert TIME_RESOLUTION >= 1e3 * StepControl.UNDERFLOW_RTOL


def test_floors_are_accepted():
    d = spoilt(**{"simulation/rtol": RTOL_MIN, "simulation/atol": ATOL_MIN, "orbit": {"radius": R_EARTH_M + ALTITUDE_MIN_M}})
    d["simulation"].update(duration=MIN_TIME_S, output_dt=MIN_TIME_S, step=MIN_TIME_S, max_step=MIN_TIME_S)
    d.pop("controller")
    scene = scene_from_dict(d)
    assert scene.simulation.rtol == RTOL_MIN and scene.orbit.radius_m > R_EARTH_M


# -- files the parser chokes on ----------------------------------------------------------------------

DEPTH = 100_000  # nesting levels
UNPARSABLE = {
    "nested_arrays": "a = " + "[" * DEPTH + "]" * DEPTH + "\n",
    "nested_inline_tables": "a = " + "{b = " * DEPTH + "1" + "}" * DEPTH + "\n",
    "integer_of_5000_digits": "[body]\nmass = " + "9" * 5000 + "\n",
}


@pytest.mark.parametrize("case", list(UNPARSABLE), ids=list(UNPARSABLE))
def test_unparsable_file_is_one_line_naming_it(tmp_path, case):
    path = tmp_path / "deep.toml"
    path.write_text(UNPARSABLE[case])
    with pytest.raises(SceneError, match=r"deep\.toml: malformed TOML") as err:
        load_scene(path)
    assert "\n" not in str(err.value)


def test_type_error_in_a_file_names_file_field_and_value(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\n[simulation]\nduration = 10.0\n[body]\nmass = true\n'
                    "inertia = [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]\n")
    with pytest.raises(SceneError, match=r"s\.toml: body\.mass: must be a number, got true$"):
        load_scene(path)


# -- dotted-path changes (Scene.replace, the command line's --set) ------------------------------------

@pytest.fixture(scope="module")
def scene():
    return scene_from_dict(full_dict(), source="s.toml")


SAME_AS_FILE = {
    "rtol_2": ("simulation.rtol", 2.0, ("simulation", "rtol")),
    "rtol_1e-300": ("simulation.rtol", 1e-300, ("simulation", "rtol")),
    "mass_true": ("body.mass", True, ("body", "mass")),
    "radius_inside_earth": ("orbit", {"radius": 6.0e6}, ("orbit",)),
    "seed_negative": ("controller.sensor.seed", -1, ("controller", "sensor", "seed")),
}


@pytest.mark.parametrize("case", list(SAME_AS_FILE), ids=list(SAME_AS_FILE))
def test_replace_refuses_a_value_with_the_files_message(scene, case):
    path, value, keys = SAME_AS_FILE[case]
    d = full_dict()
    node = d
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    file_msg = one_line_error(d).removeprefix("s.toml: ")
    with pytest.raises(SceneError) as err:
        scene.replace({path: value}, source="s.toml with --set")
    assert str(err.value) == f"s.toml with --set: {file_msg}"


APPLIED = {
    "simulation_rtol": ("simulation.rtol", 1e-10, lambda s: s.simulation.rtol),
    "by_index": ("appendage[0].alpha.rate", 0.002, lambda s: s.appendage[0].alpha.rate),
    "by_name": ("appendage.stbd.alpha.rate", 0.002, lambda s: s.appendage[0].alpha.rate),
    "vector_element": ("initial.omega_BN_B[1]", 0.001, lambda s: s.initial.omega_BN_B[1]),
    "mode_by_index": ("appendage.stbd.mode[0].damping", 0.01, lambda s: s.appendage[0].mode[0].damping),
    "whole_table": ("orbit", {"radius": 7.0e6}, lambda s: {"radius": s.orbit.radius}),
    "controller_param": ("controller.params.kp", 2.0, lambda s: s.controller.params["kp"]),
}


@pytest.mark.parametrize("case", list(APPLIED), ids=list(APPLIED))
def test_replace_sets_the_value_at_the_path(scene, case):
    path, value, read = APPLIED[case]
    assert read(scene.replace({path: value})) == value


def test_replace_takes_values_as_toml_gives_them_and_refuses_them_nested_too_deeply(scene):
    """A value built in Python (numpy numbers and arrays, tuples) is taken as TOML would give it,
    a copy (the new scene shares no list with the caller's value); one nested past Python's
    recursion is one line, as from a dict."""
    value = [np.float64(1.0), (2.0, np.int64(3))]
    got = scene.replace({"controller.params.kp": np.float64(2.5), "controller.params.v": value}).controller.params
    assert got["kp"] == 2.5 and type(got["kp"]) is float and got["v"] == [1.0, [2.0, 3]] and got["v"] is not value
    assert type(got["v"][1][1]) is int
    deep: list = []
    for _ in range(DEPTH):
        deep = [deep]
    with pytest.raises(SceneError, match=r"^s\.toml with --set: values nested too deeply$"):
        scene.replace({"controller.params.v": deep}, source="s.toml with --set")


def test_replace_creates_a_missing_table():
    rigid = scene_from_dict(RIGID)
    assert rigid.replace({"orbit.altitude": 4.0e5}).orbit.radius_m == R_EARTH_M + 4.0e5


def test_replace_validates_all_changes_together(scene):
    """A period that does not divide output_dt is refused alone, accepted with an output_dt it divides."""
    with pytest.raises(SceneError, match=r"simulation\.output_dt"):
        scene.replace({"controller.period": 0.3})
    both = scene.replace({"controller.period": 0.3, "simulation.output_dt": 0.9})
    assert (both.controller.period, both.simulation.output_dt) == (0.3, 0.9)


def test_replace_leaves_unset_defaults_unset(scene):
    """Only the file's own keys and the changes go back through validation: a joint switched to
    sun tracking does not inherit the profile's default keys."""
    tracked = scene.replace({"appendage.stbd.beta": {"track": "sun"}})
    assert tracked.appendage[0].beta.tracked


BAD_PATHS = {
    "typo_in_key": ("simulation.rtoll", 1e-9, r"^s\.toml: simulation\.rtoll: unknown key; did you mean 'rtol'\?$"),
    "typo_in_table": ("simulaton.rtol", 1e-9, r"^s\.toml: simulaton: unknown key; did you mean 'simulation'\?$"),
    "typo_in_name": ("appendage.stbdd.mass", 1.0, r"^s\.toml: appendage\.stbdd: no appendage named 'stbdd'; did you mean 'stbd'\?$"),
    "index_out_of_range": ("appendage[3].mass", 1.0, r"^s\.toml: appendage\[3\]: no such entry \(appendage has 1\)$"),
    "name_on_unnamed": ("torque.first.start", 1.0, r"^s\.toml: torque\.first: torque entries have no names; use torque\[i\]$"),
    "into_a_value": ("simulation.rtol.x", 1.0, r"^s\.toml: simulation\.rtol\.x: simulation\.rtol is a value, not a table$"),
    "index_a_table": ("simulation[0]", 1.0, r"^s\.toml: simulation\[0\]: simulation is a table, not an array$"),
    "empty_key": ("simulation..rtol", 1.0, r"^s\.toml: 'simulation\.\.rtol' is not a key path"),
    "nothing": ("", 1.0, r"^s\.toml: '' is not a key path"),
}


@pytest.mark.parametrize("case", list(BAD_PATHS), ids=list(BAD_PATHS))
def test_replace_bad_path_is_one_line_with_a_suggestion(scene, case):
    path, value, pattern = BAD_PATHS[case]
    with pytest.raises(SceneError, match=pattern):
        scene.replace({path: value}, source="s.toml")


# -- the command line's --set text ----------------------------------------------------------------

ASSIGNMENTS = {
    "number": ("simulation.rtol=1e-10", ("simulation.rtol", 1e-10)),
    "integer": ("simulation.duration=100", ("simulation.duration", 100)),
    "spaces": ("  body.mass = 3e5 ", ("body.mass", 3e5)),
    "bool": ("simulation.impulse_jump=false", ("simulation.impulse_jump", False)),
    "array": ("initial.omega_BN_B=[0.0, 1e-3, 0]", ("initial.omega_BN_B", [0.0, 1e-3, 0])),
    "text": ('simulation.integrator="rk4"', ("simulation.integrator", "rk4")),
    "inline_table": ("orbit={altitude = 4e5}", ("orbit", {"altitude": 4e5})),
    "indexed": ("appendage[0].alpha.rate=0.001", ("appendage[0].alpha.rate", 0.001)),
    "equals_in_text": ('description="a=b"', ("description", "a=b")),
    "inf": ("torque[0].stop=inf", ("torque[0].stop", math.inf)),
}


@pytest.mark.parametrize("case", list(ASSIGNMENTS), ids=list(ASSIGNMENTS))
def test_parse_assignment_reads_the_value_as_toml(case):
    text, expected = ASSIGNMENTS[case]
    assert parse_assignment(text) == expected


MALFORMED = {
    "no_equals": ("simulation.rtol", r"^--set 'simulation\.rtol': expected KEY\.PATH=VALUE$"),
    "no_value": ("simulation.rtol=", r"^--set 'simulation\.rtol=': '' is not a TOML value"),
    "bad_number": ("simulation.rtol=1e", r"^--set 'simulation\.rtol=1e': '1e' is not a TOML value"),
    "bare_word": ("simulation.integrator=rk4", r"""text needs quotes: --set 'simulation\.integrator="rk4"'$"""),
    "two_values": ("simulation.rtol=1\nx = 2", r"^--set 'simulation\.rtol=1\\nx = 2': .* is not one TOML value"),
    "no_key": ("=1", r"^--set '=1': '' is not a key path"),
    "bad_key": ("simulation rtol=1", r"^--set 'simulation rtol=1': 'simulation rtol' is not a key path"),
    "deeply_nested": ("a=" + "[" * DEPTH, r"^--set 'a=\[\[\[.*' is not a TOML value \(nested too deeply\)$"),
}


@pytest.mark.parametrize("case", list(MALFORMED), ids=list(MALFORMED))
def test_malformed_assignment_is_one_line_naming_the_option(case):
    text, pattern = MALFORMED[case]
    with pytest.raises(SceneError, match=pattern) as err:
        parse_assignment(text)
    assert "\n" not in str(err.value)


def test_parse_assignments_refuses_a_key_given_twice():
    with pytest.raises(SceneError, match=r"^--set: simulation\.rtol given twice$"):
        parse_assignments(["simulation.rtol=1e-9", "body.mass=1.0", "simulation.rtol=1e-10"])


def test_parse_assignments_keeps_the_order():
    assert list(parse_assignments(["b.x=1", "a.y=2"]).items()) == [("b.x", 1), ("a.y", 2)]


def test_numpy_and_tuples_from_python_are_arrays_and_numbers():
    """A scene built in Python may hold numpy values and tuples: taken as TOML arrays and numbers."""
    d = spoilt(**{"initial/omega_BN_B": np.array([0.0, 1e-3, 0.0]), "body/cm": (0.0, 0.0, 0.1),
                  "controller/sensor/seed": np.int64(5), "simulation/impulse_jump": np.bool_(False)})
    scene = scene_from_dict(d)
    assert (scene.initial.omega_BN_B, scene.body.cm, scene.controller.sensor.seed, scene.simulation.impulse_jump) == (
        [0.0, 1e-3, 0.0], [0.0, 0.0, 0.1], 5, False)


def test_replace_takes_the_mapping_as_keywords_too(scene):
    assert scene.replace(**{"simulation.rtol": 1e-10}) == scene.replace({"simulation.rtol": 1e-10})
