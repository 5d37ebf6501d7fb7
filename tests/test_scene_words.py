"""Scene errors name the key the user wrote (issue 32, item 8).

Claims:

* an array entry that has a name is named in an error as ``--set`` names it (``sensor.st1.period``,
  ``surface.truss.on``), both for a value pydantic refuses and for a check of the whole scene that
  names its field with an index; an entry without a name keeps its index (``torque[1]``). The
  truth is the file itself: the name is the one the TOML gives the entry at that index (read here
  with tomllib, not through the scene);
* a misspelt kind (sensor, torque, CMG, dispersion) and a misspelt law name or class say the
  nearest valid one; a word near nothing lists the valid ones without a guess.
"""

import tomllib

import pytest

from scenes import ROOT
from stationbed import load_scene
from stationbed.run.controller import ControllerError, get_controller
from stationbed.scene import SceneError

ESTIMATED = ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml"
MC = ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml"


def _file(path):
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _error(path, changes) -> str:
    with pytest.raises(SceneError) as e:
        load_scene(path).replace(changes)
    return str(e.value)


@pytest.mark.parametrize(
    "table, i, changes, rest",
    [("sensor", 2, {"sensor[2].period": "fast"}, ".period: must be a number"),
     ("sensor", 2, {"sensor[2].period": 0.123}, ".period: 0.123 s is not a whole number of controller periods"),
     ("surface", 0, {"surface[0].on": "stbd_pari"}, ".on: no appendage named 'stbd_pari'; did you mean 'stbd_pair'?")],
    ids=["value_refused", "scene_check", "named_surface"])
def test_a_named_entry_is_named_as_the_user_wrote_it(table, i, changes, rest):
    name = _file(ESTIMATED)[table][i]["name"]
    assert f"scene 'iss_lvlh_hold_estimated': {table}.{name}{rest}" in _error(ESTIMATED, changes)


def test_an_entry_without_a_name_keeps_its_index():
    assert "name" not in _file(ESTIMATED)["torque"][1]
    assert ": torque[1].kind: unknown kind 'srpp'; did you mean 'srp'?" in _error(ESTIMATED, {"torque[1].kind": "srpp"})


@pytest.mark.parametrize(
    "path, changes, message",
    [(ESTIMATED, {"sensor[2].kind": "star_traker"},
      "sensor.st1.kind: unknown kind 'star_traker'; did you mean 'star_tracker'? (valid: gyro, star_tracker)"),
     (ESTIMATED, {"cmg.kind": "sgcmg_pyramd"},
      "cmg.kind: must be 'ideal', 'dgcmg' or 'sgcmg_pyramid', got \"sgcmg_pyramd\"; did you mean 'sgcmg_pyramid'?"),
     (MC, {"montecarlo.disperse[0].kind": "scale_normall"}, "; did you mean 'scale_normal'?"),
     (ESTIMATED, {"torque[1].kind": "magnetic"}, "torque[1].kind: unknown kind 'magnetic' (valid: constant, "
                                                 "orbital_harmonic, aero, srp)")],
    ids=["sensor", "cmg", "dispersion", "far_from_any"])
def test_a_misspelt_kind_says_the_nearest(path, changes, message):
    err = _error(path, changes)
    assert message in err
    assert err.count("did you mean") == message.count("did you mean")


@pytest.mark.parametrize(
    "name, message",
    [("pdd", "unknown controller 'pdd'; valid: "),
     ("stationbed.controllers.pd:PDD", "no class 'PDD' in 'stationbed.controllers.pd'; did you mean 'PD'?")],
    ids=["registry_name", "class_name"])
def test_a_misspelt_law_says_the_nearest(name, message):
    with pytest.raises(ControllerError) as e:
        get_controller(name)
    assert message in str(e.value)
    assert str(e.value).endswith("did you mean 'pd'?" if ":" not in name else "did you mean 'PD'?")
