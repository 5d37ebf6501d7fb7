"""Bad input refused with one ``stationbed: error:`` line naming the key or option, exit 2, before
any output (issue 19, item 16): times that are not times (``linearize --t nan``), a sun epoch
outside the range the sun model is stated for, surfaces that no torque uses."""

import subprocess
import sys
from pathlib import Path

import pytest

from stationbed.scene import SceneError, scene_from_dict
from stationbed.scene.environment import SUN_EPOCH_RANGE

from env_helpers import base_scene

ROOT = Path(__file__).resolve().parents[1]
STATIONBED = Path(sys.executable).parent / "stationbed"
HOLD = ROOT / "scenarios" / "iss_lvlh_hold.toml"
PLATE = {"area": 2.0, "normal": [1.0, 0.0, 0.0]}  # m², a flat plate facing +x


def one_error(res) -> str:
    assert res.returncode == 2, res.stderr
    assert res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("stationbed: error: ")
    return res.stderr


@pytest.mark.parametrize("argv, option", [
    (["linearize", HOLD, "--t", "nan"], "--t"),
    (["linearize", HOLD, "--t", "inf"], "--t"),
    (["linearize", HOLD, "--t", "-1"], "--t"),
    (["linearize", HOLD, "--dt", "0"], "--dt"),
    (["linearize", HOLD, "--dt", "nan"], "--dt"),
    (["margins", HOLD, "--t", "nan"], "--t"),
    (["compare", "somewhere", "--settle", "nan"], "--settle"),
], ids=["t_nan", "t_inf", "t_negative", "dt_zero", "dt_nan", "margins_t_nan", "settle_nan"])
def test_time_options_that_are_not_times(tmp_path, argv, option):
    res = subprocess.run([str(STATIONBED), *map(str, argv), *(["--out", str(tmp_path / "o")] if argv[0] != "compare" else [])],
                         capture_output=True, text=True)
    err = one_error(res)
    assert f"argument {option}:" in err and "finite" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("epoch, ok", [
    ("1949-12-31T23:59:59Z", False),
    ("1950-01-01T00:00:00Z", True),
    ("2050-12-31T23:59:59Z", True),
    ("2051-01-01T00:00:00Z", False),
    ("2051-01-01T00:30:00+01:00", True),  # 2050-12-31T23:30Z: the zone is applied
    ("1776-07-04T12:00:00", False),
], ids=["before", "first", "last", "after", "zone", "no_zone_before"])
def test_sun_epoch_outside_the_model_range(epoch, ok):
    d = base_scene(sun={"epoch": epoch})
    if ok:
        assert scene_from_dict(d).sun.epoch == epoch
        return
    with pytest.raises(SceneError, match=r"sun\.epoch: .* is outside 1950-2050, the range the sun model is stated for") as e:
        scene_from_dict(d)
    assert "\n" not in str(e.value)


def test_sun_epoch_range_is_the_stated_one():
    """The Astronomical Almanac states its low-precision solar coordinates for 1950-2050."""
    first, end = SUN_EPOCH_RANGE
    assert (first.year, first.month, first.day) == (1950, 1, 1) and (end.year, end.month, end.day) == (2051, 1, 1)


@pytest.mark.parametrize("torque, ok", [([], False), ([{"kind": "constant", "torque_B": [1.0, 0.0, 0.0]}], False),
                                        ([{"kind": "aero"}], True)], ids=["none", "constant_only", "aero"])
def test_surfaces_that_no_torque_uses(torque, ok):
    d = base_scene(surface=[PLATE], torque=torque)
    if ok:
        assert len(scene_from_dict(d).surface) == 1
        return
    with pytest.raises(SceneError, match=r"surface: 1 surface\(s\) but no \[\[torque\]\] uses them.*'aero' or 'srp'") as e:
        scene_from_dict(d)
    assert "\n" not in str(e.value)


def test_replacing_a_scene_torques_keeps_no_silent_surfaces(tmp_path):
    """``--set torque=[...]`` on a scene with surfaces: refused (the plates would do nothing), with
    the option that removes them; nothing written."""
    res = subprocess.run([str(STATIONBED), "run", str(HOLD), "--out", str(tmp_path / "o"), "--set",
                          'torque=[{kind="constant", torque_B=[0.0, -20.0, 0.0]}]'], capture_output=True, text=True)
    err = one_error(res)
    # truss and modules: the arrays' plates come with their wing declarations (issue 32), which
    # need no torque (a wing's plate only matters to aero and srp)
    assert "surface: 2 surface(s) but no [[torque]] uses them" in err and "--set surface=[]" in err
    assert not (tmp_path / "o").exists()
