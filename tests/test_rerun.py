"""Rerun recordings (issue 4): read the files back and check what a viewer would show.

Recordings are read with ``rerun.chunk.RrdReader`` (rerun-sdk 0.41): the recording store and the
blueprint store are two stores in the same ``.rrd`` file.
"""

import io
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from scenes import ROOT
from stationbed import Trajectory, load_scene, simulate
from stationbed.environment import C_ON
from stationbed.massprops import composite_cm
from stationbed.rerun_log import RrdSink, TeeSink, box_half_sizes, write_recording
from stationbed.rotation import Ap, dcm, euler_321
from stationbed.scene import scene_from_dict
from stationbed.trajectory import CsvSink, base_columns

rerun_chunk = pytest.importorskip("rerun.chunk")

#: Scalars are stored as float64, the same type as the trajectory: logged == computed exactly.
SCALAR_TOL = 0.0
#: sim_time is a duration timeline stored as integer nanoseconds.
TIME_TOL_S = 1e-9
#: Transform3D quaternions are stored as float32 (eps 1.2e-7); a DCM built from one is
#: correct to a few eps.
QUAT_F32_TOL = 1e-6
#: Euler angles are computed here (float64) and in the library by a different route (5-element
#: products vs full matrices): round-off of a few 1e-16 rad, ~1e-13 deg.
EULER_TOL_DEG = 1e-9

ISS = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
RERUN = Path(sys.executable).parent / "rerun"
STATIONBED = Path(sys.executable).parent / "stationbed"

FAILING = """
name = "rrd_fail_case"
[simulation]
duration = 100.0
output_dt = 1.0
[body]
mass = 10.0  # kg
inertia = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.5]]  # kg m²
[[torque]]
kind = "constant"
torque_B = [1e300, 1e300, 0.0]  # N m: blows the state up from t = 50 s
start = 50.0
"""


# -- reading helpers --------------------------------------------------------------------------
def read_temporal(path) -> dict[str, dict[str, np.ndarray]]:
    """Entity path -> {"t": [s], component: values (n, k)} of the recording store, time-sorted."""
    parts: dict[str, list] = {}
    for c in rerun_chunk.RrdReader(path).stream().to_chunks():
        if c.is_static or "sim_time" not in c.timeline_names:
            continue
        parts.setdefault(c.entity_path, []).append(c.to_record_batch())
    out = {}
    for ent, batches in parts.items():
        cols: dict[str, list] = {}
        for rb in batches:
            n = rb.num_rows
            cols.setdefault("t", []).append(rb.column("sim_time").cast(pa.int64()).to_numpy() * 1e-9)
            for name in rb.schema.names:
                if ":" not in name:
                    continue
                arr = rb.column(name).flatten()
                while pa.types.is_fixed_size_list(arr.type) or pa.types.is_list(arr.type):
                    arr = arr.flatten()
                cols.setdefault(name, []).append(np.asarray(arr.to_numpy(zero_copy_only=False)).reshape(n, -1))
        merged = {k: np.concatenate(v) for k, v in cols.items()}
        order = np.argsort(merged["t"], kind="stable")
        out[ent.lstrip("/")] = {k: v[order] for k, v in merged.items()}
    return out


def static_entities(path) -> set[str]:
    return {c.entity_path.lstrip("/") for c in rerun_chunk.RrdReader(path).stream().to_chunks() if c.is_static}


def verify(path) -> subprocess.CompletedProcess:
    return subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True)


# -- fixtures ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def iss_run(tmp_path_factory):
    """The ISS scene (orbit, two arrays), 3000 s, streamed through an RrdSink batch by batch."""
    scene = load_scene(ISS)
    path = tmp_path_factory.mktemp("rrd") / "iss.rrd"
    with RrdSink(scene, path, base_columns(scene.appendage_names)) as sink:
        traj = simulate(scene, duration=3000.0, sink=sink)
    return scene, traj, path, read_temporal(path)


# -- the run recording ------------------------------------------------------------------------
def test_entity_tree(iss_run):
    scene, _, path, data = iss_run
    temporal = {
        "world/station",
        "world/station/stbd_pair",
        "world/station/port_pair",
        "world/lvlh",
        "world/orbit/station",
        "world/H_O_N",
        "telemetry/omega_BN_B",
        "telemetry/euler_lvlh_deg",
        "telemetry/H_O_N",
        "telemetry/T",
        "telemetry/arrays/stbd_pair",
        "telemetry/arrays/port_pair",
    }
    assert temporal <= set(data)
    static = {
        "world/station/body",
        "world/station/truss",
        "world/station/axes_B",
        "world/station/stbd_pair",
        "world/lvlh/axes",
        "world/lvlh/earth",
        "world/orbit/track",
    }
    assert static <= static_entities(path)


def test_row_counts_and_times_match_trajectory(iss_run):
    _, traj, _, data = iss_run
    for ent, cols in data.items():
        assert len(cols["t"]) == len(traj), ent
        assert_allclose(cols["t"], traj.t, rtol=0, atol=TIME_TOL_S, err_msg=ent)


@pytest.mark.parametrize(
    "entity, columns",
    [
        ("telemetry/omega_BN_B", ["wx", "wy", "wz"]),
        ("telemetry/T", ["T"]),
        ("telemetry/arrays/stbd_pair", ["alpha_stbd_pair", "beta_stbd_pair"]),
    ],
    ids=["omega", "T", "array_angles"],
)
def test_logged_series_equal_trajectory(iss_run, entity, columns):
    _, traj, _, data = iss_run
    assert_allclose(data[entity]["Scalars:scalars"], traj.cols(*columns), rtol=0, atol=SCALAR_TOL)


def test_logged_H_is_H_O_N_and_its_norm(iss_run):
    _, traj, _, data = iss_run
    H = data["telemetry/H_O_N"]["Scalars:scalars"]
    assert_allclose(H[:, :3], traj.H_O_N, rtol=0, atol=SCALAR_TOL)
    assert_allclose(H[:, 3], np.linalg.norm(traj.H_O_N, axis=1), rtol=1e-15, atol=0)


def test_station_rotation_is_C_NB(iss_run):
    """world/station maps B components into N: its quaternion's matrix is dcm(q_BN).T."""
    _, traj, _, data = iss_run
    C = Rotation.from_quat(data["world/station"]["Transform3D:quaternion"]).as_matrix()
    C_NB = np.array([dcm(q).T for q in traj.q_BN])
    assert_allclose(C, C_NB, rtol=0, atol=QUAT_F32_TOL)


def test_array_transform_is_C_BP_at_its_cm(iss_run):
    """world/station/<array> maps P into B: rotation Ap(alpha, beta).T, translation r_p - r_cm."""
    scene, traj, _, data = iss_run
    r_cm = composite_cm([scene.body.mass] + [a.mass for a in scene.appendage], [scene.body.cm] + [a.cm for a in scene.appendage])
    for a in scene.appendage:
        d = data[f"world/station/{a.name}"]
        C = Rotation.from_quat(d["Transform3D:quaternion"]).as_matrix()
        C_BP = np.array([Ap(al, be).T for al, be in zip(traj[f"alpha_{a.name}"], traj[f"beta_{a.name}"])])
        assert_allclose(C, C_BP, rtol=0, atol=QUAT_F32_TOL)
        assert_allclose(d["Transform3D:translation"], np.tile(np.array(a.cm) - r_cm, (len(traj), 1)), rtol=1e-6, atol=1e-5)


def test_lvlh_rotation_and_euler_angles(iss_run):
    """world/lvlh carries C_NO = C_ON.T; roll/pitch/yaw are euler_321(C_BN C_ON.T) in degrees."""
    scene, traj, _, data = iss_run
    o = scene.orbit
    u = o.u0 + o.mean_motion * traj.t
    C = Rotation.from_quat(data["world/lvlh"]["Transform3D:quaternion"]).as_matrix()
    assert_allclose(C, np.array([C_ON(uk, o.inclination).T for uk in u]), rtol=0, atol=QUAT_F32_TOL)
    expected = np.degrees([euler_321(dcm(q) @ C_ON(uk, o.inclination).T) for q, uk in zip(traj.q_BN, u)])
    assert_allclose(data["telemetry/euler_lvlh_deg"]["Scalars:scalars"], expected, rtol=0, atol=EULER_TOL_DEG)


def test_blueprint_is_a_second_store_in_the_file(iss_run):
    _, _, path, _ = iss_run
    reader = rerun_chunk.RrdReader(path)
    (rec,) = reader.recordings()
    (bp,) = reader.blueprints()
    assert rec.application_id == bp.application_id == "stationbed"
    views = {}
    for c in reader.stream(store=bp).to_chunks():
        rb = c.to_record_batch()
        if "ViewBlueprint:class_identifier" in rb.schema.names:
            views[rb.column("ViewBlueprint:space_origin").to_pylist()[0][0]] = rb.column(
                "ViewBlueprint:class_identifier"
            ).to_pylist()[0][0]
    assert views["world"] == "3D"
    for origin in ("telemetry/omega_BN_B", "telemetry/euler_lvlh_deg", "telemetry/H_O_N", "telemetry/T", "telemetry/arrays"):
        assert views[origin] == "TimeSeries", origin


def test_rrd_verify_passes(iss_run):
    res = verify(iss_run[2])
    assert res.returncode == 0, res.stderr


# -- streaming, failure, extras ---------------------------------------------------------------
def test_readable_after_every_batch_without_close(tmp_path, rigid_scene_dict):
    """Each write is flushed: a copy taken before close (as a killed process would leave it) has
    every row so far and is well formed apart from the footer (the chunk manifest that ``close``
    writes); ``rerun rrd optimize`` adds the footer back. After close the file verifies fully."""
    scene = scene_from_dict(rigid_scene_dict)
    traj = simulate(scene, duration=20.0)
    live = tmp_path / "live.rrd"
    sink = RrdSink(scene, live, traj.columns)
    try:
        n = 0
        for k, rows in enumerate((traj.data[:1], traj.data[1:11], traj.data[11:])):
            sink.write(rows)
            n += len(rows)
            snap = tmp_path / f"snap{k}.rrd"
            shutil.copyfile(live, snap)
            res = subprocess.run([str(RERUN), "rrd", "verify", "--check-footers", "false", str(snap)], capture_output=True, text=True)
            assert res.returncode == 0, res.stderr
            with pytest.warns(Warning, match="no footer"):
                assert len(read_temporal(snap)["telemetry/omega_BN_B"]["t"]) == n
        fixed = tmp_path / "fixed.rrd"
        subprocess.run([str(RERUN), "rrd", "optimize", str(snap), "-o", str(fixed)], capture_output=True, check=True)
        assert verify(fixed).returncode == 0
    finally:
        sink.close()
    assert verify(live).returncode == 0


def test_extra_columns_go_under_telemetry_extra(tmp_path, rigid_scene_dict):
    scene = scene_from_dict(rigid_scene_dict)
    traj = simulate(scene, duration=10.0)
    extra = np.column_stack([traj.t * 2.0, -traj.t])
    tr = Trajectory(traj.columns + ["h_cmg_x", "cmd_x"], np.hstack([traj.data, extra]))
    data = read_temporal(write_recording(tr, scene, tmp_path / "x.rrd"))
    assert_allclose(data["telemetry/extra/h_cmg_x"]["Scalars:scalars"][:, 0], extra[:, 0], rtol=0, atol=SCALAR_TOL)
    assert_allclose(data["telemetry/extra/cmd_x"]["Scalars:scalars"][:, 0], extra[:, 1], rtol=0, atol=SCALAR_TOL)
    assert "world/lvlh" not in data and "telemetry/euler_lvlh_deg" not in data  # no orbit, no LVLH


def test_tee_sink_feeds_csv_and_recording(tmp_path, rigid_scene_dict):
    scene = scene_from_dict(rigid_scene_dict)
    buf = io.StringIO()
    csv = CsvSink(buf, base_columns(scene.appendage_names))
    tee = TeeSink(csv, RrdSink(scene, tmp_path / "t.rrd", csv.columns))
    traj = simulate(scene, duration=10.0, sink=tee)
    tee.close()
    assert buf.getvalue().count("\n") == len(traj) + 1
    assert len(read_temporal(tmp_path / "t.rrd")["world/station"]["t"]) == len(traj)


def test_box_has_the_principal_moments():
    """A uniform 2 x 3 x 4 m box of 6 kg, turned: the drawn box is that box."""
    m, a, b, c = 6.0, 2.0, 3.0, 4.0  # kg, m
    J = m / 12.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    half, C_FA = box_half_sizes(m, R @ J @ R.T)
    assert_allclose(np.sort(half), [1.0, 1.5, 2.0], rtol=1e-12)
    assert_allclose(C_FA @ np.diag(m / 12.0 * (4 * np.roll(half, -1) ** 2 + 4 * np.roll(half, -2) ** 2)) @ C_FA.T, R @ J @ R.T, rtol=1e-12, atol=1e-12)
    assert np.linalg.det(C_FA) == pytest.approx(1.0)


# -- command line -----------------------------------------------------------------------------
def test_failed_run_leaves_partial_verifiable_recording(tmp_path):
    scene = tmp_path / "fail.toml"
    scene.write_text(FAILING)
    rrd = tmp_path / "o" / "recording.rrd"
    res = subprocess.run([str(STATIONBED), "run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd)], capture_output=True, text=True)
    assert res.returncode == 1 and str(rrd) in res.stderr and res.stderr.count("\n") == 1
    assert verify(rrd).returncode == 0
    csv = Trajectory.from_csv(tmp_path / "o" / "trajectory.csv")
    w = read_temporal(rrd)["telemetry/omega_BN_B"]
    assert 50.0 <= w["t"][-1] < 100.0
    assert_allclose(w["t"], csv.t, rtol=0, atol=TIME_TOL_S)
    assert_allclose(w["Scalars:scalars"], csv.omega_BN_B, rtol=0, atol=SCALAR_TOL)


def test_check_rrd_writes_formulations_and_diffs(tmp_path):
    scene = tmp_path / "rigid.toml"
    scene.write_text(FAILING.split("[[torque]]")[0].replace("duration = 100.0", "duration = 20.0") + "[initial]\nomega_BN_B = [0.1, 0.02, -0.05]\n")
    rrd = tmp_path / "check.rrd"
    res = subprocess.run([str(STATIONBED), "check", str(scene), "--rrd", str(rrd)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert verify(rrd).returncode == 0
    data = read_temporal(rrd)
    from stationbed import FORMULATIONS

    for f in FORMULATIONS:
        assert len(data[f"check/{f}/omega_BN_B"]["t"]) == 21
        assert data[f"check/{f}/q_BN"]["Scalars:scalars"].shape == (21, 4)
    names = list(FORMULATIONS)
    for a, b in [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, len(names))]:
        for what in ("attitude_rad", "rate", "H"):
            d = data[f"check/diff/{a}_vs_{b}/{what}"]["Scalars:scalars"]
            assert d.shape == (21, 1) and np.all(d >= 0.0)
