"""Scene keys of the environment torques (issue 14): one-line errors naming the field, the
defaults derived from a scene without [[surface]], and the night-glider array drive.

Truths used: the uniform box's inertia (``J_xx = m (b² + c²) / 12``) and the uniform thin plate's
(``J_xx = m b² / 12``), inverted by hand for the default surfaces; for the glider, the geometry
of the flow (array normal perpendicular to the air-relative velocity) computed in the test from
the orbit of DESIGN §5, and the drive's rate limit.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose

from stationbed import load_scene, simulate
from stationbed.model.atmosphere import EXPONENTIAL_TABLE, msis_table
from stationbed.model.surfaces import scene_plates
from stationbed.scene import SceneError, scene_from_dict

from env_helpers import base_scene, circular_state, v_rel_N
from scenes import C_PB, ROOT


@pytest.mark.parametrize(
    "change, pattern",
    [
        ({"surface": [{"area": 2.0}]}, r"surface\[0\]\.normal: a plate needs both 'area' and 'normal'$"),
        ({"surface": [{"size": [1.0, 1.0, 1.0], "area": 3.0, "normal": [1, 0, 0]}]}, r"give a plate .* or a box"),
        ({"surface": [{"area": 2.0, "normal": [1, 0, 0], "on": "stbd_pari"}]}, r"surface\[0\]\.on: no appendage named 'stbd_pari'; did you mean 'stbd_pair'\?$"),
        ({"surface": [{"area": 2.0, "normal": [1, 0, 0], "specular": 0.4}]}, r"give two of 'absorbed', 'specular', 'diffuse'"),
        ({"surface": [{"area": 2.0, "normal": [1, 0, 0], "absorbed": 0.5, "specular": 0.4, "diffuse": 0.4}]}, r"must be 1, got 1\.3$"),
        ({"surface": [{"area": 2.0, "normal": [1, 0, 0], "drag": 2.0}]}, r"surface\[0\]\.drag: unknown key"),
        ({"atmosphere": {"model": "msis"}}, r"atmosphere\.model: 'msis' needs \[sun\] epoch"),
        ({"atmosphere": {"density_scal": 2.0}}, r"atmosphere\.density_scal: unknown key; did you mean 'density_scale'\?$"),
        ({"torque": [{"kind": "srp"}]}, r"torque: kind 'srp' needs a \[sun\] table$"),
        ({"torque": [{"kind": "aero"}, {"kind": "aero"}]}, r"torque: kind 'aero' given 2 times"),
        ({"sun": {"epoch": "2024-13-01T00:00:00Z"}}, r"sun\.epoch: .*is not an ISO 8601 date"),
        ({"sun": {"beta": 0.1, "epoch": "2024-03-01T00:00:00Z"}}, r"give exactly one of 'beta'"),
        ({"appendage[0].alpha": {"track": "sun", "night": "glider"}, "sun": {"beta": 0.1}}, r"appendage\.stbd_pair\.alpha\.night: 'glider' needs \[sun\] eclipse"),
    ],
    ids=["plate_without_normal", "plate_and_box", "unknown_appendage", "one_fraction", "fractions_sum", "typo_key",
         "msis_without_epoch", "atmosphere_typo", "srp_without_sun", "aero_twice", "bad_epoch", "two_sun_forms", "glider_without_eclipse"],
)
def test_bad_environment_keys_are_one_line_errors(change, pattern):
    d = base_scene(torque=[{"kind": "aero"}], appendage=[_array("stbd_pair", 20.0)])
    for key, value in change.items():
        if key.startswith("appendage[0]."):
            d["appendage"][0][key.split(".")[1]] = value
        else:
            d[key] = value
    with pytest.raises(SceneError, match=pattern) as err:
        scene_from_dict(d)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(importlib.util.find_spec("pymsis") is not None, reason="pymsis installed: no error to see")
def test_msis_without_pymsis_is_a_one_line_error():
    d = base_scene(torque=[{"kind": "aero"}], atmosphere={"model": "msis"}, sun={"epoch": "2024-03-20T00:00:00Z"})
    with pytest.raises(ValueError, match=r"^atmosphere\.model: 'msis' needs the optional package pymsis") as err:
        simulate(scene_from_dict(d))
    assert "\n" not in str(err.value)


@pytest.mark.skipif(importlib.util.find_spec("pymsis") is None, reason="optional extra stationbed[msis] not installed")
def test_msis_table_falls_with_altitude_near_the_exponential_model():
    table = msis_table("2024-03-20T00:00:00Z", 150.0, 150.0, 15.0)
    assert np.all(np.diff(table[:, 1]) < 0)
    # at 400 km NRLMSIS at F10.7 = 150 lies within a factor 3 of the static mean table
    assert 1 / 3 < table[20, 1] / EXPONENTIAL_TABLE[20, 1] < 3


def _array(name, y, alpha=None):
    return {"name": name, "mass": 2000.0, "inertia": [[3e5, 0, 0], [0, 1.2e5, 0], [0, 0, 4e5]], "cm": [0.0, y, 0.0],
            "alpha": alpha or {"a0": 0.0}}


def test_default_surfaces_come_from_the_inertia():
    d = base_scene(torque=[{"kind": "aero"}], appendage=[_array("wing", 20.0)])
    plates = scene_plates(scene_from_dict(d))
    m, (Jx, Jy, Jz) = 1.0e5, (1e7, 2e7, 2.5e7)
    a2 = {0: 12 * Jx / m, 1: 12 * Jy / m, 2: 12 * Jz / m}  # b² + c² etc. of the uniform box
    edges = [math.sqrt((a2[1] + a2[2] - a2[0]) / 2), math.sqrt((a2[0] + a2[2] - a2[1]) / 2),
             math.sqrt((a2[0] + a2[1] - a2[2]) / 2)]
    body = [p for p in plates if p[0] == -1]
    assert len(body) == 6
    areas = sorted(p[1] for p in body)
    want = sorted([edges[1] * edges[2]] * 2 + [edges[0] * edges[2]] * 2 + [edges[0] * edges[1]] * 2)
    assert_allclose(areas, want, rtol=1e-12)
    (wing,) = [p for p in plates if p[0] == 0]
    # thin plate in P's x-y plane: J_xx = m b²/12, J_yy = m a²/12 -> area a b
    assert_allclose(wing[1], math.sqrt(12 * 3e5 / 2000.0) * math.sqrt(12 * 1.2e5 / 2000.0), rtol=1e-12)
    assert wing[11] == 1.0  # two-sided


#: the drive's rate limit may be exceeded by the rate loop's first-order lag only by round-off [rad/s]
RATE_SLACK = 1e-9
#: edge-on after the drive has settled: its angle loop (gain 0.05 1/s) with no rate feed-forward on
#: a flow fixed in LVLH leaves only the attitude's own drift (the free body turns ~1e-4 rad) [rad]
EDGE_ON_RAD = 2e-3


def test_night_glider_turns_the_array_edge_on_in_eclipse():
    alpha = {"track": "sun", "max_rate": 0.002, "max_acc": 2e-5, "night": "glider"}
    d = base_scene(appendage=[_array("wing", 20.0, alpha)])
    d["simulation"] = {"duration": 3600.0, "output_dt": 10.0}
    d["initial"] = {"frame": "lvlh", "omega_BN_B": [0.0, 0.0, 0.0]}
    d["orbit"] = {"altitude": 420e3, "inclination": 0.0, "u0": 0.0, "gravity_gradient": False}
    d["sun"] = {"direction_N": [1.0, 0.0, 0.0], "eclipse": "cylindrical"}  # shadow for u in ~(110, 250) deg
    tr = simulate(scene_from_dict(d))
    df = pd.DataFrame(tr.data, columns=tr.columns)
    scene = scene_from_dict(d)
    # shadow centre u = π at t = π/n; the slew (up to π/2 at 0.002 rad/s, 100 s to reach that rate)
    # ends within 900 s of entry: from then on the array must be edge-on
    o = scene.orbit
    n = o.mean_motion
    R = o.radius_m
    half = math.acos(math.sqrt(1 - (6378137.0 / R) ** 2))
    t_in, t_out = (math.pi - half) / n, (math.pi + half) / n
    rates = np.gradient(df["alpha_wing"].to_numpy(), df["t"].to_numpy())
    assert np.max(np.abs(rates)) < 0.002 + RATE_SLACK + 1e-6  # finite differences of a 10 s grid
    checked = 0
    for _, row in df[(df.t > t_in + 900.0) & (df.t < t_out)].iterrows():
        q = row[["qw", "qx", "qy", "qz"]].to_numpy()
        w, x, y, z = q
        C_NB = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        r, v, _ = circular_state(scene, row.t)
        v_B = C_NB.T @ v_rel_N(r, v)
        n_B = C_PB(row.alpha_wing, row.beta_wing).T @ [0.0, 0.0, 1.0]
        assert abs(math.asin(n_B @ v_B / np.linalg.norm(v_B))) < EDGE_ON_RAD
        checked += 1
    assert checked > 10
    # and in daylight before the eclipse (after the drive's start-up from rest) it tracked the sun
    lit = df[(df.t > 600.0) & (df.t < t_in - 100.0)]
    assert np.max(np.abs(lit[[c for c in df.columns if c.startswith("track_err_deg")]].to_numpy())) < 0.5


@pytest.mark.slow
def test_night_glider_scene_lowers_drag_but_grows_more_pitch_momentum():
    """scenarios/iss_night_glider.toml and its documented override (night = "track" by --set):
    parking the arrays edge-on in eclipse lowers the mean pitch drag torque, but the orbit-mean
    growth of the CMG pitch momentum is larger (README: 3697 vs 3077 N m s per orbit). Tracking,
    a wing's products of inertia in B, ``(J_along - J_normal) sin α cos α``, average out over the
    orbit; parked edge-on (sin 2α = 0) in eclipse they leave the day side's, whose gravity-gradient
    pitch torque adds to the drag's for arrays whose face is their largest moment (issue 32: with
    the face and the mass 90 deg apart it subtracted, and the glider grew 885 against 3101)."""
    glider = load_scene(ROOT / "scenarios" / "iss_night_glider.toml")
    track = glider.replace({"appendage.stbd_pair.alpha.night": "track", "appendage.port_pair.alpha.night": "track"})
    growth, aero = {}, {}
    for name, scene in (("glider", glider), ("track", track)):
        tr = simulate(scene)
        T = 2 * math.pi / scene.orbit.mean_motion
        hy = tr["hy"]
        first, last = hy[tr.t < T].mean(), hy[tr.t >= 2 * T].mean()
        growth[name] = (last - first) / 2  # N m s per orbit
        aero[name] = tr["tau_aero_y"].mean()
        assert tr.meta["summary"]["momentum_saturated_ticks"] == 0
    assert aero["glider"] < 0.8 * aero["track"]  # the eclipse is ~36 % of the orbit
    assert growth["glider"] > 1.1 * growth["track"]  # measured 1.20: the parked arrays' gravity gradient


def test_plates_do_not_depend_on_the_mass_properties():
    # a Monte Carlo disperses masses and mass centres: one compiled system must serve every
    # sample, so no plate constant (part of the structure's key) may follow them; the torque
    # still does, through the parameters (the lever arms are taken from the composite centre)
    from stationbed.model.station import StationModel
    from stationbed.model.structure import Structure

    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").replace(
        {"simulation.duration": 1.0, "simulation.output_dt": 1.0})
    moved = scene.replace({"body.cm": [0.3, -0.2, 0.5], "appendage.stbd_pair.mass": 2600.0,
                           "appendage.port_pair.cm": [0.0, -37.0, 0.4]})
    assert Structure.of(moved).key == Structure.of(scene).key
    p0, p1 = StationModel(Structure.of(scene)).params(scene), StationModel(Structure.of(moved)).params(moved)
    L = StationModel(Structure.of(scene)).layout
    assert not np.array_equal(p0[L["surf_O"]], p1[L["surf_O"]])
    tau = [simulate(s, formulation="momentum").cols("tau_aero_x", "tau_aero_y", "tau_aero_z")[0] for s in (scene, moved)]
    assert np.abs(tau[1] - tau[0]).max() > 1e-3 * np.abs(tau[0]).max()
