"""Every direction in a scene (a vector that must point somewhere: a thruster's force, a plate's
normal, a port's axis, a star tracker's boresight, a dgcmg's outer-gimbal axes, the sun's
direction) is checked by one validator (``stationbed.scene.base.Direction``): the zero vector,
NaN and a wrong length are each refused with one line naming the field the user wrote.

Independent truth: the key path each message must start with is written here by hand, from the
scene files' own tables (``thruster.<name>.direction_B``), not taken from the library.
"""

from __future__ import annotations

import math
from functools import cache

import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import SceneError, load_scene
from stationbed.scene.base import DIRECTION_NORM_MIN

#: a normalised axis against its exact unit vector: a few ulps of 1 (one division per component)
UNIT_TOL = 1e-15
#: a plate added to the full flight loop's surfaces (it has boxes and wings only) [m², -]
PLATE = {"name": "radiator", "area": 10.0, "normal": [0.0, 0.0, 1.0]}


@cache
def _scene(stem: str):
    return load_scene(ROOT / "scenarios" / f"{stem}.toml")


def _with_plate(v):
    s = _scene("iss_full_flight_loop")
    return {"surface": [x.model_dump(exclude_unset=True) for x in s.surface] + [{**PLATE, "normal": v}]}


#: field -> (scene file, its changes given the direction v, the key path the message names)
FIELDS = {
    "thruster_direction_B": ("iss_full_flight_loop", lambda v: {"thruster[0].direction_B": v},
                             "thruster.aft_p_1.direction_B"),
    "star_tracker_boresight_B": ("iss_full_flight_loop", lambda v: {"sensor[2].boresight_B": v},
                                 "sensor.st1.boresight_B"),
    "cmg_outer_axes_B": ("iss_full_flight_loop",
                         lambda v: {"cmg.outer_axes_B": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], v, [0.0, 0.0, 1.0]]},
                         "cmg.outer_axes_B[2]"),
    "sun_direction_N": ("iss_full_flight_loop", lambda v: {"sun": {"direction_N": v, "eclipse": "conical"}},
                        "sun.direction_N"),
    "surface_normal": ("iss_full_flight_loop", _with_plate, "surface.radiator.normal"),
    "port_axis": ("iss_progress_docking", lambda v: {"port[0].axis": v}, "port.sm_aft.axis"),
    "vehicle_surface_normal": ("iss_progress_docking", lambda v: {"vehicle[0].surface[1].normal": v},
                               "vehicle.progress.surface.progress_arrays.normal"),
}

#: bad value -> (the vector, what the message says after the field's path)
BAD = {
    "zero": ([0.0, 0.0, 0.0], ": must be a non-zero vector"),
    "below_floor": ([0.5 * DIRECTION_NORM_MIN, 0.0, 0.0], ": must be a non-zero vector"),
    "nan": ([math.nan, 1.0, 0.0], "[0]: must be a finite number, not NaN or inf"),
    "wrong_length": ([1.0, 0.0], ": wrong length"),
}


@pytest.mark.parametrize("bad", list(BAD))
@pytest.mark.parametrize("field", list(FIELDS))
def test_a_direction_refuses_zero_nan_and_wrong_length_naming_the_field(field, bad):
    stem, change, path = FIELDS[field]
    value, says = BAD[bad]
    with pytest.raises(SceneError) as err:
        _scene(stem).replace(change(value), source="s.toml")
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"s.toml: {path}{says}"), msg


@pytest.mark.parametrize("field", list(FIELDS))
def test_a_direction_of_any_length_is_taken(field):
    """Not only unit vectors: a direction 1e6 times the floor, off the axes, loads."""
    stem, change, _ = FIELDS[field]
    _scene(stem).replace(change([1e6 * DIRECTION_NORM_MIN, 2e6 * DIRECTION_NORM_MIN, 0.0]))


def test_a_port_axis_is_stored_unit_length():
    axis = [0.0, -3.0, 4.0]  # m: length 5
    s = _scene("iss_progress_docking").replace({"port[0].axis": axis})
    assert_allclose(s.port[0].axis, [0.0, -0.6, 0.8], rtol=0.0, atol=UNIT_TOL)
