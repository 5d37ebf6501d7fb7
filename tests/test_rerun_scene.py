"""The replay shows the station the scene describes (issue 24), read back from the recording:
every ``[[surface]]`` at its size and place, the array plates turning with their joints, the events
on the time line, the optional star-tracker and estimate parts, the blueprint's groups, the Monte
Carlo recording, and the screenshot path (its PNG only where a browser is installed)."""

import math
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose

from stationbed import load_scene, simulate
from stationbed.core.rotation import Ap
from stationbed.output.rerun.events import GHOST_MAGNIFY
from stationbed.output.rerun.recording import write_recording
from stationbed.output.rerun.screenshot import find_browser
from stationbed.run.trajectory import Trajectory
from stationbed.scene.sensors import StarTrackerSensor

rerun_chunk = pytest.importorskip("rerun.chunk")
from rrd_helpers import entity_rows  # noqa: E402
from test_rerun_blueprint import TABS, blueprint_tree  # noqa: E402  (same folder: pytest puts it on sys.path)

ROOT = Path(__file__).resolve().parents[1]
HOLD = ROOT / "scenarios" / "iss_lvlh_hold.toml"
STATIONBED = Path(sys.executable).with_name("stationbed")
#: rerun stores sizes, positions and quaternions as float32 (~6e-8 relative)
F32_REL = 1e-6
#: a quaternion read back from float32 components, turned into an angle [rad]
F32_ANGLE = 1e-3


def static_components(path) -> dict[str, dict[str, list]]:
    """entity -> {component column: its python list} of the static chunks."""
    out = {}
    for c in rerun_chunk.RrdReader(path).stream().to_chunks():
        if not c.is_static:
            continue
        rb = c.to_record_batch()
        d = out.setdefault(c.entity_path.lstrip("/"), {})
        for name in rb.schema.names:
            if ":" in name:
                d[name] = rb.column(name).to_pylist()[0]
    return out


def temporal_rows(path, entity) -> list[tuple[float, dict]]:
    """(t [s], {component: value}) of every temporal row of ``entity``, time-sorted."""
    rows = [(t, {n: v[0] if isinstance(v, list) and len(v) == 1 else v for n, v in comp.items()})
            for t, comp in entity_rows(path, entity)[1]]
    return sorted(rows, key=lambda r: r[0])


def quat_rotate(xyzw, v):
    """``v`` rotated by the quaternion (x, y, z, w) (the child's components in the parent)."""
    x, y, z, w = np.ravel(xyzw)
    u = np.array([x, y, z])
    v = np.asarray(v, float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


@pytest.fixture(scope="module")
def hold(tmp_path_factory):
    scene = load_scene(HOLD)
    traj = simulate(scene, duration=200.0)
    path = write_recording(traj, scene, tmp_path_factory.mktemp("scene") / "hold.rrd")
    return scene, traj, path, static_components(path)


# -- the station the scene describes ------------------------------------------------------------
def test_every_surface_is_drawn_at_its_size_and_place(hold):
    scene, _, _, static = hold
    masses = [scene.body.mass] + [a.mass for a in scene.appendage]
    r_cm = sum(m * np.asarray(c, float) for m, c in zip(masses, [scene.body.cm] + [a.cm for a in scene.appendage])) / sum(masses)
    assert scene.surfaces  # iss_lvlh_hold names its truss and modules; its wings bring their plates
    for s in scene.surfaces:
        ent = f"world/station/surfaces/{s.name}" if s.on == "body" else f"world/station/{s.on}/surfaces/{s.name}"
        box = static[ent]
        half = np.array(box["Boxes3D:half_sizes"][0])
        if s.size is not None:  # a box: its edges, its centre about the composite mass centre
            assert_allclose(2.0 * half, s.size, rtol=F32_REL)
            assert_allclose(box["Boxes3D:centers"][0], np.asarray(s.centre) - r_cm, rtol=F32_REL, atol=1e-4)
        else:  # a plate: its area, normal to its normal (the box's third axis), thin
            assert 4.0 * half[0] * half[1] == pytest.approx(s.area, rel=F32_REL * 10)
            assert half[2] < 0.05 * min(half[0], half[1])
            n_drawn = quat_rotate(box["Boxes3D:quaternions"][0], [0.0, 0.0, 1.0])
            assert_allclose(n_drawn, np.asarray(s.normal) / np.linalg.norm(s.normal), atol=1e-6)
    # the equivalent boxes of the mass properties are not drawn over the named surfaces
    assert "world/station/body" not in static and "world/station/truss" not in static
    assert not any("Boxes3D:half_sizes" in static.get(f"world/station/{a}", {}) for a in scene.appendage_names)


def test_array_plates_turn_with_their_joints(hold):
    """The plate's normal in B, from the logged array transform, is C_BP n = Ap(alpha, beta)^T n
    (core.rotation), and it turns over the run (sun tracking)."""
    scene, traj, path, static = hold
    s = next(s for s in scene.surfaces if s.on != "body")
    n_P = quat_rotate(static[f"world/station/{s.on}/surfaces/{s.name}"]["Boxes3D:quaternions"][0], [0, 0, 1])
    rows = temporal_rows(path, f"world/station/{s.on}")
    assert len(rows) == len(traj)
    normals = []
    for i, (t, comp) in enumerate(rows):
        n_B = quat_rotate(comp["Transform3D:quaternion"], n_P)
        C_PB = np.asarray(Ap(traj[f"alpha_{s.on}"][i], traj[f"beta_{s.on}"][i]), float)
        assert_allclose(n_B, C_PB.T @ n_P, atol=F32_ANGLE)
        normals.append(n_B)
    turned = math.acos(np.clip(normals[0] @ normals[-1], -1.0, 1.0))
    assert turned > 10 * F32_ANGLE  # the joints moved the plate


def test_labels_show_on_hover_only_except_the_directions(hold):
    *_, static = hold
    for ent in ("world/station/axes_B", "world/lvlh/axes", "world/station/cmg/units", "world/station/surfaces/truss"):
        shown = [v for k, v in static[ent].items() if k.endswith(":show_labels")]
        assert shown and shown[0] is False or shown == [[False]], ent
    for ent in ("world/sun", "world/lvlh/earth", "world/lvlh/ram"):
        assert static[ent]["Arrows3D:labels"] and not any(k.endswith(":show_labels") for k in static[ent])
    assert_allclose(static["world/lvlh/ram"]["Arrows3D:vectors"][0][1:], [0.0, 0.0])  # along x_O
    assert static["world/lvlh/ram"]["Arrows3D:vectors"][0][0] > 0.0


def test_scene_without_surfaces_keeps_its_mass_property_boxes(tmp_path):
    scene = load_scene(ROOT / "scenarios" / "power_tower_free_drift.toml")
    assert not scene.surface
    static = static_components(write_recording(simulate(scene, duration=20.0), scene, tmp_path / "t.rrd"))
    assert "world/station/body" in static and "world/station/truss" in static
    assert not any("/surfaces/" in e for e in static)


# -- events, sensors and the estimate (synthetic columns) ---------------------------------------
#: flag changes put into a real run's rows: (column, row index, value from that row on)
SAT_ON, SAT_OFF, SHADOW_IN, SHADOW_OUT, BLIND, SEE = 5, 9, 3, 12, 7, 11


def _synthetic(scene, traj):
    """The run's rows with flags that change at known rows, a star tracker's valid flag and an
    estimation error (the columns issue 20's flight loop writes)."""
    n = len(traj)
    cols = dict(zip(traj.columns, traj.data.T))
    sat = np.zeros(n)
    sat[SAT_ON:SAT_OFF] = 1.0
    ecl = np.ones(n)
    ecl[SHADOW_IN:SHADOW_OUT] = 0.0
    ecl[SHADOW_IN] = 0.4  # penumbra: already in the shadow
    valid = np.ones(n)
    valid[BLIND:SEE] = 0.0
    cols.update(cmg_saturated=sat, eclipse=ecl, st_valid_st1=valid)
    err = np.outer(np.linspace(0.0, 1.0, n), [1e-3, -2e-3, 5e-4])  # deg
    for j, a in enumerate("xyz"):  # the columns of issue 20's flight_columns
        cols[f"est_err_{a}_deg"] = err[:, j]
        cols[f"est_3sigma_{a}_deg"] = np.full(n, 3e-3)
        cols[f"est_bias_{a}"] = np.zeros(n)
    cols["nees"] = np.full(n, 6.0)
    head = StarTrackerSensor(kind="star_tracker", name="st1", period=0.5, boresight_B=[0.0, -0.6, -0.8],
                             nea_cross=1e-5, nea_about=7e-5, sun_exclusion=0.5)
    return _WithSensors(scene, [head]), Trajectory(list(cols), np.column_stack(list(cols.values()))), err


class _WithSensors:
    """The scene with a ``sensor`` list (as issue 20's Scene has one), everything else delegated."""

    def __init__(self, scene, sensor):
        self._scene, self.sensor = scene, sensor

    def __getattr__(self, name):
        return getattr(self._scene, name)


@pytest.fixture(scope="module")
def synthetic(hold, tmp_path_factory):
    scene, traj, _, _ = hold
    s, tr, err = _synthetic(scene, traj)
    path = write_recording(tr, s, tmp_path_factory.mktemp("syn") / "syn.rrd")
    return tr, err, path


def test_events_are_logged_when_the_flags_change(synthetic):
    tr, _, path = synthetic
    got = [(t, c["TextLog:text"], c["TextLog:level"]) for t, c in temporal_rows(path, "events")]
    t = tr.t
    # the hold's |h| stays far below 0.9 of the capacity: the flag is the gimbal-rate limit (issue 32)
    expected = sorted([(t[SAT_ON], "CMG gimbal-rate limit begins", "WARN"), (t[SAT_OFF], "CMG gimbal-rate limit ends", "INFO"),
                       (t[SHADOW_IN], "eclipse entry", "INFO"), (t[SHADOW_OUT], "eclipse exit", "INFO"),
                       (t[BLIND], "star tracker st1 dropout", "WARN"), (t[SEE], "star tracker st1 valid again", "INFO")])
    assert [(e[1], e[2]) for e in got] == [(e[1], e[2]) for e in expected]
    assert_allclose([e[0] for e in got], [e[0] for e in expected], atol=1e-9)


def test_events_do_not_depend_on_how_the_rows_were_batched(hold):
    """A streamed run hands rows in batches: the flags' last values carry over."""
    from stationbed.output.rerun.events import Events

    scene, traj, _, _ = hold
    _, tr, _ = _synthetic(scene, traj)
    whole = Events(tr.columns).changes(tr)
    ev = Events(tr.columns)
    pieces = [ev.changes(Trajectory(tr.columns, tr.data[i:i + 3])) for i in range(0, len(tr), 3)]
    assert [e for p in pieces for e in p] == whole


def test_star_tracker_boresight_cone_and_blinding_colour(synthetic):
    tr, _, path = synthetic
    static = static_components(path)
    b = np.array(static["world/station/sensors/st1/boresight"]["Arrows3D:vectors"][0])
    assert_allclose(b / np.linalg.norm(b), np.array([0.0, -0.6, -0.8]), atol=1e-6)  # the mounting's z axis in B
    rim = np.array(static["world/station/sensors/st1/exclusion"]["LineStrips3D:strips"][0])
    half_angles = np.arccos(rim @ b / (np.linalg.norm(rim, axis=1) * np.linalg.norm(b)))
    assert_allclose(half_angles, 0.5, atol=1e-5)  # the sun exclusion [rad]
    for ent in ("world/station/sensors/st1/boresight", "world/station/sensors/st1/exclusion"):
        colours = [(t, c[next(k for k in c if k.endswith(":colors"))]) for t, c in temporal_rows(path, ent)]
        red = [t for t, col in colours if (col >> 24) & 0xFF > 200 and (col >> 16) & 0xFF < 100]
        assert [t for t, _ in colours] == pytest.approx([tr.t[0], tr.t[BLIND], tr.t[SEE]])
        assert red == pytest.approx([tr.t[BLIND]])


def test_estimated_attitude_ghost_is_the_error_magnified(synthetic):
    tr, err, path = synthetic
    rows = temporal_rows(path, "world/station/estimate")
    assert len(rows) == len(tr)
    for (t, c), e in zip(rows, err):
        x, y, z, w = c["Transform3D:quaternion"]
        angle = 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))
        assert angle == pytest.approx(GHOST_MAGNIFY * math.radians(np.linalg.norm(e)), abs=F32_ANGLE)
        if np.linalg.norm(e) > 0:  # about -err: the estimate is the body turned back by the error
            assert_allclose(np.array([x, y, z]) * np.sign(w) / np.linalg.norm([x, y, z]), -e / np.linalg.norm(e), atol=1e-4)


def test_without_sensor_columns_there_are_no_sensor_parts(hold):
    *_, static = hold
    assert not any(e.startswith("world/station/sensors") or e.startswith("world/station/estimate") for e in static)


def test_blueprint_has_an_estimation_tab_when_the_columns_are_there(synthetic, hold):
    _, _, path = synthetic
    root, containers, views = blueprint_tree(path)
    (tabs,) = [c for c in containers.values() if c["kind"] == TABS]
    names = [containers[k]["name"] for k in tabs["contents"]]
    assert "estimation" in names
    est = containers[tabs["contents"][names.index("estimation")]]
    assert views[est["contents"][0]][1] == "estimation error vs 3 sigma [deg]"
    root, containers, views = blueprint_tree(hold[2])  # the plain run: no such tab
    (tabs,) = [c for c in containers.values() if c["kind"] == TABS]
    assert "estimation" not in [containers[k]["name"] for k in tabs["contents"]]


# -- the Monte Carlo recording -------------------------------------------------------------------
def test_montecarlo_recording_has_envelope_worst_replay_and_table(tmp_path):
    from stationbed.studies.montecarlo.recording import WORST_ROWS, write_recording as write_mc
    from stationbed.studies.montecarlo.report import recorded_percentiles

    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml")
    scene = scene.model_copy(update={"simulation": scene.simulation.model_copy(update={"duration": 30.0})})
    n = 12
    rng = np.random.default_rng(3)
    worst = 7
    max_err = rng.uniform(0.1, 1.0, n)
    max_err[worst] = 2.0
    df = pd.DataFrame({"index": np.arange(n), "seed": np.arange(n), "status": ["ok"] * n, "reason": [""] * n,
                       "redraws": 0, "stopped_at_s": np.nan, "body.inertia[0][0]": rng.uniform(1e8, 1.1e8, n),
                       "max_att_err_deg": max_err, "max_h_fraction": rng.uniform(0, 1, n)})
    t = np.linspace(0.0, 30.0, 4)
    env = np.stack([np.outer(max_err, np.ones(4)), np.outer(df["max_h_fraction"], np.ones(4))], axis=2)
    path = write_mc(tmp_path / "montecarlo.rrd", scene, t, env, df, percentiles=recorded_percentiles)
    static = static_components(path)
    text = static["montecarlo/worst_samples"]["TextDocument:text"][0]
    body = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| index")]
    assert len(body) == WORST_ROWS
    ranked = [int(line.split("|")[1]) for line in body]
    assert ranked == list(np.argsort(-max_err)[:WORST_ROWS])  # largest first
    assert "body.inertia[0][0]" in text  # the drawn values beside the metrics
    assert len(temporal_rows(path, "montecarlo/worst/att_err_deg")) == len(t)
    station = temporal_rows(path, "world/station")  # the worst sample, run again, in 3-D
    assert len(station) > 1 and station[-1][0] == pytest.approx(30.0)
    assert any("/surfaces/" in e for e in static)
    _, containers, views = blueprint_tree(path)
    kinds = {cls for cls, _ in views.values()}
    assert {"3D", "TimeSeries", "TextDocument", "TextLog"} <= kinds
    assert any(name == f"worst sample {worst} (N axes, CM at origin)" for _, name in views.values())


# -- the screenshot path ---------------------------------------------------------------------------
def _shot(capsys, *argv):
    """``stationbed screenshot ARGV`` in this process: (status, stderr)."""
    from stationbed.cli import main

    code = main(["screenshot", *map(str, argv)])
    return code, capsys.readouterr().err


def test_screenshot_refuses_bad_input_in_one_line(tmp_path, capsys):
    code, err = _shot(capsys, tmp_path / "none.rrd", "--out", tmp_path / "x.png")
    assert code == 2 and err.startswith("stationbed: error: no recording at") and err.count("\n") == 1
    bad = tmp_path / "bad.rrd"
    bad.write_bytes(b"not a recording")
    code, err = _shot(capsys, bad, "--out", tmp_path / "x.png")
    assert code == 2 and "is not a rerun recording" in err and err.count("\n") == 1


def test_screenshot_without_a_browser_says_so(hold, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.setenv("STATIONBED_CHROMIUM", "")
    code, err = _shot(capsys, hold[2], "--out", tmp_path / "x.png")
    assert code == 1
    assert err.strip() == ("stationbed: error: no Chromium found, so no screenshot: install the 'chromium' "
                           "package (make screenshots does: apt-get install chromium) or set STATIONBED_CHROMIUM")
    assert not (tmp_path / "x.png").exists()


def _png_size_and_pixels(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", data[16:24])
    mpl_image = pytest.importorskip("matplotlib.image")
    return (w, h), mpl_image.imread(path)


@pytest.mark.slow
@pytest.mark.skipif(find_browser() is None, reason="no Chromium installed (apt-get install chromium; make screenshots)")
def test_screenshot_renders_the_station_and_the_plots(hold, tmp_path):
    out = tmp_path / "hold.png"
    res = subprocess.run([str(STATIONBED), "screenshot", str(hold[2]), "--out", str(out), "--width", "1280",
                          "--height", "800"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    (w, h), img = _png_size_and_pixels(out)
    assert (w, h) == (1280, 800)
    rgb = (img[..., :3] * 255).astype(int)
    left = rgb[:, : w // 2]  # the 3-D view: the arrays' blue plates are on the picture
    blue = (left[..., 2] > 150) & (left[..., 0] < 90) & (left[..., 1] < 130)
    assert blue.sum() > 500
    assert len(np.unique(rgb.reshape(-1, 3), axis=0)) > 200  # plots and text, not a blank or loading screen
