"""A solar-array wing pair declared once (issue 32): ``appendage.wing`` derives the inertia, the
``[[surface]]`` plate, the bending beams and the drawing; an explicit inertia and a plate on the
same appendage must face the same way.

Truths used: the inertia of a cloud of point masses laid out over the two wings and summed here
(``Σ m (|r|² E - r rᵀ)``, no library code); the sun-tracking normal of the array frame, +z of P
(``C_PB s_B = ẑ``, stationbed/model/appendages.py), and the beta gimbal's axis, x of P
(``C_PB = Ax(β) Ay(α)`` leaves P x fixed under β); the cantilever integrals of an explicit ``beam``
(core/beam.py, tested against closed forms in tests/test_flexible.py).
"""

from __future__ import annotations

import glob
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import load_scene
from stationbed.core.beam import axis_vector, beam_mode
from stationbed.core.massprops import wing_pair_inertia
from stationbed.output.rerun.geometry import StationGeometry
from stationbed.scene import SceneError, scene_from_dict
from stationbed.scene.wing import PLATE_NORMAL_TOL_DEG

from env_helpers import base_scene
from scenes import ROOT

#: points per metre of the cloud; its inertia converges as h² (midpoint rule): 1e-4 relative at 20/m
CLOUD_PER_M = 20
CLOUD_REL = 2e-4
#: the ISS scenes' wing pair (the scenes' own numbers)
ISS_MASS_KG, ISS_SPAN_M, ISS_CHORD_M, ISS_OFFSET_M = 2200.0, 35.0, 24.0, 2.0
#: the scenes that fly the ISS's arrays (each declares its wings once)
ISS_SCENES = sorted(p for p in glob.glob(str(ROOT / "scenarios" / "*.toml")) if "wing = {" in open(p).read())


def cloud_inertia(mass, span, chord, offset, e_along, e_normal):
    """Σ m (|r|² E - r rᵀ) over a midpoint grid of both wings, about their mass centre."""
    e_l, e_n = np.asarray(e_along, float), np.asarray(e_normal, float)
    e_c = np.cross(e_n, e_l)
    nl, nc = int(span * CLOUD_PER_M), int(chord * CLOUD_PER_M)
    s = offset + (np.arange(nl) + 0.5) * span / nl
    c = (np.arange(nc) - (nc - 1) / 2) * chord / nc
    S, C = np.meshgrid(np.concatenate([s, -s]), c, indexing="ij")
    r = S.reshape(-1, 1) * e_l + C.reshape(-1, 1) * e_c
    r = r - r.mean(axis=0)
    dm = mass / len(r)
    return dm * (np.sum(r * r) * np.eye(3) - r.T @ r)


@pytest.mark.parametrize(
    "span, chord, offset, along, normal",
    [(35.0, 24.0, 2.0, "x", "+z"), (20.0, 6.0, 0.0, "y", "+z"), (12.0, 3.0, 5.0, "z", "-x")],
    ids=["iss_x_along_z_normal", "no_offset_y_along", "z_along_minus_x_normal"],
)
def test_wing_inertia_is_the_point_cloud_of_its_wings(span, chord, offset, along, normal):
    m = 1000.0  # kg
    J = wing_pair_inertia(m, span, chord, offset, np.abs(axis_vector(along)), axis_vector(normal))
    assert_allclose(J, cloud_inertia(m, span, chord, offset, np.abs(axis_vector(along)), axis_vector(normal)),
                    rtol=CLOUD_REL, atol=CLOUD_REL * np.max(J))


def _iss_like(**wing):
    arr = {"name": "stbd_pair", "mass": ISS_MASS_KG, "cm": [0.0, 38.0, 0.0],
           "wing": {"span": ISS_SPAN_M, "chord": ISS_CHORD_M, "offset": ISS_OFFSET_M, **wing}}
    return base_scene(torque=[{"kind": "aero"}], appendage=[arr])


def test_wing_plate_faces_its_largest_moment_and_has_its_area():
    scene = scene_from_dict(_iss_like())
    (plate,) = [s for s in scene.surfaces if s.on == "stbd_pair"]
    moments, axes = np.linalg.eigh(scene.appendage[0].inertia_P)
    assert abs(axes[:, 2] @ np.asarray(plate.normal)) == pytest.approx(1.0, abs=1e-12)
    assert plate.area == pytest.approx(2 * ISS_SPAN_M * ISS_CHORD_M)  # 1680 m², the scenes' former value
    assert moments[2] == pytest.approx(moments[0] + moments[1], rel=1e-12)  # a thin plate


@pytest.mark.parametrize("path", ISS_SCENES, ids=lambda p: p.rsplit("/", 1)[-1].removesuffix(".toml"))
def test_iss_arrays_face_the_sun_tracked_normal_and_turn_about_their_mast(path):
    """The face (largest moment) is P z, the normal sun tracking points at the sun; the wings run
    along P x, the beta axis (smallest moment), so the BGA turns them about their length."""
    scene = load_scene(path)
    assert len(scene.appendage) == 2
    for a in scene.appendage:
        moments, axes = np.linalg.eigh(a.inertia_P)
        assert abs(axes[:, 2][2]) == pytest.approx(1.0, abs=1e-12), a.name
        assert abs(axes[:, 0][0]) == pytest.approx(1.0, abs=1e-12), a.name
        assert_allclose(a.inertia_P, wing_pair_inertia(ISS_MASS_KG, ISS_SPAN_M, ISS_CHORD_M, ISS_OFFSET_M,
                                                       [1, 0, 0], [0, 0, 1]))
        plates = [s for s in scene.surfaces if s.on == a.name]
        assert all(abs(s.normal[2]) == 1.0 for s in plates)


def test_wing_is_drawn_as_a_sheet_facing_its_normal():
    """The rerun drawing's box of the array is thinnest along P z (the face), longest along P x."""
    geom = StationGeometry(scene_from_dict(_iss_like()))
    _, _, half, C_PA = geom.arrays[0]
    thin, long = C_PA[:, int(np.argmin(half))], C_PA[:, int(np.argmax(half))]
    assert abs(thin[2]) == pytest.approx(1.0, abs=1e-9) and abs(long[0]) == pytest.approx(1.0, abs=1e-9)
    assert 2 * half.max() == pytest.approx(math.sqrt(12 * ((ISS_OFFSET_M + ISS_SPAN_M) ** 3 - ISS_OFFSET_M ** 3)
                                                     / (3 * ISS_SPAN_M)), rel=1e-9)


def test_wing_beam_is_the_explicit_beam_of_that_wing():
    d = _iss_like()
    d["appendage"][0]["mode"] = [{"frequency_hz": 0.1, "wing": {"side": "-", "deflection": "normal"}},
                                 {"frequency_hz": 0.25, "wing": {"side": "+", "deflection": "chord", "n": 2}}]
    modes = scene_from_dict(d).appendage[0].mode
    want = [beam_mode(1, ISS_SPAN_M, ISS_MASS_KG / 2, [-ISS_OFFSET_M, 0, 0], "-x", "z"),
            beam_mode(2, ISS_SPAN_M, ISS_MASS_KG / 2, [ISS_OFFSET_M, 0, 0], "+x", "y")]
    for mode, (phi, H, M) in zip(modes, want):
        got = mode.integrals(ISS_MASS_KG)
        assert_allclose(got[0], phi, atol=1e-12)
        assert_allclose(got[1], H, atol=1e-9)
        assert got[2] == pytest.approx(M, rel=1e-14)


def test_wing_scene_round_trips_and_mass_moves_its_inertia():
    scene = scene_from_dict(_iss_like())
    again = scene_from_dict(scene.model_dump())
    assert_allclose(again.appendage[0].inertia_P, scene.appendage[0].inertia_P)
    heavier = scene.replace({"appendage.stbd_pair.mass": 2 * ISS_MASS_KG})
    assert_allclose(heavier.appendage[0].inertia_P, 2 * scene.appendage[0].inertia_P)


#: the drifted ISS declaration (before issue 32): a plate facing P x by its inertia, P z by its surface
DRIFTED = [[1.0e6, 0.0, 0.0], [0.0, 9.8e5, 0.0], [0.0, 0.0, 3.0e4]]  # kg m², P axes


def _explicit(normal, area=1680.0, inertia=DRIFTED):
    arr = {"name": "stbd_pair", "mass": ISS_MASS_KG, "cm": [0.0, 38.0, 0.0], "inertia": inertia}
    return base_scene(torque=[{"kind": "aero"}], appendage=[arr],
                      surface=[{"name": "box", "size": [1.0, 1.0, 1.0]},
                               {"on": "stbd_pair", "area": area, "normal": normal, "two_sided": True}])


@pytest.mark.parametrize(
    "change, pattern",
    [
        (lambda d: d["appendage"][0].update(inertia=DRIFTED), r"appendage\.stbd_pair\.wing: give 'inertia' .* not both$"),
        (lambda d: d["appendage"][0]["wing"].update(normal="x"), r"appendage\.stbd_pair\.wing\.normal: 'x' lies along the wings"),
        (lambda d: d["appendage"][0]["wing"].update(specular=0.7, diffuse=0.6), r"sum to 1\.3 > 1$"),
        (lambda d: d["appendage"][0].update(mode=[{"frequency_hz": 0.1, "wing": {"side": "+", "deflection": "normal"},
                                                   "beam": {"length": 3.0, "span": "x", "deflection": "z"}}]),
         r"appendage\.stbd_pair\.mode\[0\]: give a mode one of 'beam', 'wing'"),
        (lambda d: d.update(surface=[{"on": "stbd_pair", "area": 1680.0, "normal": [0, 0, 1]}]),
         r"surface\[0\]\.on: appendage 'stbd_pair' declares a wing, which is its plate"),
    ],
    ids=["wing_and_inertia", "normal_along_wings", "fractions", "mode_wing_and_beam", "plate_on_a_wing"],
)
def test_bad_wing_declarations_are_one_line_errors(change, pattern):
    d = _iss_like()
    change(d)
    with pytest.raises(SceneError, match=pattern) as err:
        scene_from_dict(d)
    assert "\n" not in str(err.value)


def test_mode_wing_needs_a_wing():
    d = _explicit([1, 0, 0])
    d["appendage"][0]["mode"] = [{"frequency_hz": 0.1, "wing": {"side": "+", "deflection": "normal"}}]
    with pytest.raises(SceneError, match=r"appendage\.stbd_pair\.mode\[0\]\.wing: bends a wing: 'stbd_pair' declares none"):
        scene_from_dict(d)


def test_explicit_inertia_and_plate_facing_apart_are_refused():
    """The drifted ISS declaration: 90 deg between the inertia's face (P x) and the plate (P z)."""
    with pytest.raises(SceneError, match=r"surface\[1\]\.normal: faces 90 deg away from appendage\.stbd_pair\.inertia's "
                                         r"plate normal \(its largest moment's axis, P \[1, 0, 0\]"):
        scene_from_dict(_explicit([0, 0, 1]))


@pytest.mark.parametrize(
    "normal, area",
    [([1, 0, 0], 1680.0), ([-1, 0, 0], 1680.0), ([math.cos(math.radians(PLATE_NORMAL_TOL_DEG) - 1e-3), 0,
                                                   math.sin(math.radians(PLATE_NORMAL_TOL_DEG) - 1e-3)], 1680.0),
     ([0, 0, 1], 10.0)],
    ids=["same_face", "other_side", "inside_tolerance", "small_part_any_way"],
)
def test_explicit_inertia_and_plate_that_agree_are_accepted(normal, area):
    scene_from_dict(_explicit(normal, area))


def test_a_body_without_a_face_takes_any_plate():
    """A cube's inertia names no face: nothing to compare."""
    scene_from_dict(_explicit([0, 0, 1], inertia=[[1.0e5, 0, 0], [0, 1.0e5, 0], [0, 0, 1.0e5]]))


def test_wing_plate_is_drawn_at_its_span_and_chord():
    """The replay draws the wing's plate 2 span x chord, along P x and P y, facing P z."""
    from stationbed.output.rerun.surfaces import drawn_surfaces

    scene = scene_from_dict(_iss_like())
    (d,) = [d for d in drawn_surfaces(scene, StationGeometry(scene)) if d.on == "stbd_pair"]
    assert_allclose(2 * d.half_sizes[:2], [2 * ISS_SPAN_M, ISS_CHORD_M])
    assert_allclose(np.abs(d.C), np.eye(3), atol=1e-15)  # box axes: P x (along), P y (chord), P z (normal)
