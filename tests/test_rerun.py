"""Rerun recordings (issue 4): read the files back and check what a viewer would show.

Recordings are read with ``rerun.chunk.RrdReader`` (rerun-sdk 0.41): the recording store and the
blueprint store are two stores in the same ``.rrd`` file.
"""

import copy
import io
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from scenes import RIGID, ROOT, one_error_line
from stationbed import Trajectory, load_scene, simulate
from stationbed.cli import main as cli_main
from stationbed.model.cmg import cluster_functions
from stationbed.model.environment import C_ON
from stationbed.core.massprops import composite_cm
from stationbed.output.rerun.geometry import box_half_sizes
from stationbed.output.rerun.recording import write_recording
from stationbed.output.rerun.sink import RrdSink, TeeSink
from stationbed.core.rotation import Ap, dcm, euler_321
from stationbed.scene import scene_from_dict
from stationbed.run.closed_loop import ROW_BATCH
from stationbed.run.rows import trajectory_columns
from stationbed.output.csv import CsvSink
from stationbed.run.trajectory import base_columns

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
#: Arrows3D vectors are float32 (relative eps 6e-8); rebuilding h [N m s] from four unit arrows
#: of 4760 N m s each (normalised, then summed): ~4 x 4760 x 2e-7 = 4e-3 N m s.
CMG_F32_TOL_NMS = 1e-2
#: Angle between two float32-built unit vectors (two f32 quaternions and an f32 arrow, a few
#: 1e-7 rad each): ~1e-5 deg; atan2 of |cross| and dot keeps small angles well conditioned.
ANGLE_F32_TOL_DEG = 1e-4

ISS = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
HOLD = ROOT / "scenarios" / "iss_lvlh_hold.toml"  # 4 DGCMGs, 10 Hz PD, sun-tracking arrays
HOLD_DURATION_S = 200.0  # s: 21 rows at output_dt = 10 s, the arrays still slewing to the sun
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


def blueprint_views(path) -> list[dict]:
    """Views of the blueprint store: class ("3D", "TimeSeries"), origin, name and the entity
    query expressions they show (``$origin/**`` unless the view lists its contents)."""
    reader = rerun_chunk.RrdReader(path)
    (bp,) = reader.blueprints()
    views, contents = {}, {}
    for c in reader.stream(store=bp).to_chunks():
        rb = c.to_record_batch()
        ent = c.entity_path.lstrip("/")
        if "ViewBlueprint:class_identifier" in rb.schema.names:
            views[ent] = {
                "class": rb.column("ViewBlueprint:class_identifier").to_pylist()[0][0],
                "origin": rb.column("ViewBlueprint:space_origin").to_pylist()[0][0],
                "name": rb.column("ViewBlueprint:display_name").to_pylist()[0][0],
            }
        if "ViewContents:query" in rb.schema.names:
            contents[ent.rsplit("/", 1)[0]] = rb.column("ViewContents:query").to_pylist()[0]
    for ent, v in views.items():
        v["contents"] = contents.get(ent, ["$origin/**"])
    return list(views.values())


def shown_by(view, entities) -> set[str]:
    """The entities of ``entities`` a view shows (its ``$origin/**`` or exact ``/path`` queries)."""
    out = set()
    for q in view["contents"]:
        q = q.replace("$origin", view["origin"]).lstrip("+ ").lstrip("/")
        if q.endswith("/**"):
            root = q[:-3]
            out |= {e for e in entities if e == root or e.startswith(root + "/")}
        else:
            out |= {q} & set(entities)
    return out


def verify(path) -> subprocess.CompletedProcess:
    return subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True)


# -- fixtures ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def iss_run(tmp_path_factory):
    """The ISS scene (orbit, two arrays), 3000 s, streamed through an RrdSink batch by batch."""
    scene = load_scene(ISS)
    path = tmp_path_factory.mktemp("rrd") / "iss.rrd"
    with RrdSink(scene, path, trajectory_columns(scene)) as sink:  # base columns and tau_gg (issue 32)
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
        "telemetry/environment/tau_gg_B",
    }
    assert temporal <= set(data)
    static = {
        "world/station/body",
        "world/station/truss",
        "world/station/axes_B",
        "world/station/stbd_pair/surfaces/stbd_pair_wing",  # a wing is drawn as its plate (issue 32)
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
        ("telemetry/environment/tau_gg_B", ["tau_gg_x", "tau_gg_y", "tau_gg_z"]),
    ],
    ids=["omega", "T", "array_angles", "gravity_gradient"],
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
    _, _, path, data = iss_run
    reader = rerun_chunk.RrdReader(path)
    (rec,) = reader.recordings()
    (bp,) = reader.blueprints()
    assert rec.application_id == bp.application_id == "stationbed"
    views = {v["origin"]: v["class"] for v in blueprint_views(path)}
    assert views["world"] == "3D"
    for origin in ("telemetry/omega_BN_B", "telemetry/euler_lvlh_deg", "telemetry/H_O_N", "telemetry/T", "telemetry/arrays"):
        assert views[origin] == "TimeSeries", origin


def test_rrd_verify_passes(iss_run):
    res = verify(iss_run[2])
    assert res.returncode == 0, res.stderr


# -- streaming, failure, extras ---------------------------------------------------------------
def test_readable_after_every_batch_without_close(tmp_path, rigid_scene_dict):
    """With ``flush_interval_s = 0`` each write is sent and flushed: a copy taken before close
    (as a killed process would leave it) has every row so far and is well formed apart from the
    footer (the chunk manifest that ``close`` writes); ``rerun rrd optimize`` adds the footer
    back. After close the file verifies fully."""
    scene = scene_from_dict(rigid_scene_dict)
    traj = simulate(scene, duration=20.0)
    live = tmp_path / "live.rrd"
    sink = RrdSink(scene, live, traj.columns, flush_interval_s=0.0)
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


def test_rows_wait_for_the_interval_and_all_reach_the_file_on_close(tmp_path, rigid_scene_dict):
    """Rows are sent at most every ``flush_interval_s``: with an infinite interval nothing but
    the static parts is in the file before close, and every row is after it."""
    scene = scene_from_dict(rigid_scene_dict)
    traj = simulate(scene, duration=20.0)
    live = tmp_path / "live.rrd"
    sink = RrdSink(scene, live, traj.columns, flush_interval_s=math.inf)
    for k in range(0, len(traj), 5):
        sink.write(traj.data[k : k + 5])
    sink.rec.flush()  # whatever the sink has sent is now in the file
    snap = tmp_path / "snap.rrd"
    shutil.copyfile(live, snap)
    with pytest.warns(Warning, match="no footer"):
        assert read_temporal(snap) == {}
    sink.close()
    assert verify(live).returncode == 0
    assert len(read_temporal(live)["telemetry/omega_BN_B"]["t"]) == len(traj) == sink.n_rows


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
    rrd = tmp_path / "o" / "recording.partial.rrd"  # a failed run's recording keeps the partial name
    assert res.returncode == 1 and str(rrd) in one_error_line(res.stderr)
    assert verify(rrd).returncode == 0
    csv = Trajectory.from_csv(tmp_path / "o" / "trajectory.partial.csv")
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


# -- command line: the recording process (stationbed/output/rerun/child.py) -------------------
#: Long enough that the run is still going when it is killed (3 orbits take ~1 s; this ~60x).
KILL_DURATION_S = 1.0e6
#: Rows in the CSV before the parent is killed: a few batches, while the child may still import.
KILL_AFTER_ROWS = 3 * ROW_BATCH
#: Wall-time limits [s] for a run to reach a state or a child to finish (never reached when fine).
WAIT_S = 60.0
needs_proc = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="finds the child in /proc (Linux)")
RIGID_TOML = FAILING.split("[[torque]]")[0].replace("duration = 100.0", "duration = 20.0") + "[initial]\nomega_BN_B = [0.1, 0.02, -0.05]\n"


def _csv_rows(path) -> int:
    try:
        with open(path) as fh:
            return max(sum(1 for _ in fh) - 1, 0)
    except FileNotFoundError:
        return 0


def _children(pid) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _alive(pid) -> bool:
    """Running (a zombie left unreaped by an orphan's new parent counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        return False


def _wait_for(cond, what):
    deadline = time.monotonic() + WAIT_S
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


@needs_proc
def test_killed_run_leaves_the_child_to_finish_the_recording(tmp_path):
    """SIGKILL the parent mid-run: the recording process reads to the end of the pipe and closes
    the file, so it verifies in full (footer included) and holds, exactly, every row handed over
    before the kill: at least the CSV's rows when the kill was sent, but the batch being written
    (the CSV gets each batch first), and no row the CSV does not have."""
    out = tmp_path / "o"
    rrd = out / "recording.rrd"
    proc = subprocess.Popen(
        [str(STATIONBED), "run", str(HOLD), "--out", str(out), "--duration", str(KILL_DURATION_S), "--rrd", str(rrd)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    child = None
    try:
        _wait_for(lambda: _children(proc.pid), "the recording process")
        (child,) = _children(proc.pid)
        _wait_for(lambda: _csv_rows(out / "trajectory.partial.csv") >= KILL_AFTER_ROWS or proc.poll() is not None, "rows")
        assert proc.poll() is None, "the run ended before it was killed"
        n_seen = _csv_rows(out / "trajectory.partial.csv")
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        _wait_for(lambda: not _alive(child), "the recording process to finish")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if child is not None and _alive(child):
            os.kill(child, signal.SIGKILL)
    rrd = out / "recording.partial.rrd"  # killed: the run never ended, its outputs keep the partial names
    res = verify(rrd)
    assert res.returncode == 0, res.stderr
    csv = Trajectory.from_csv(out / "trajectory.partial.csv", torn_tail=True)  # killed mid-write: may end mid-row
    w = read_temporal(rrd)["telemetry/omega_BN_B"]
    n = len(w["t"])
    assert n_seen - ROW_BATCH <= n <= len(csv)
    assert_allclose(w["t"], csv.t[:n], rtol=0, atol=TIME_TOL_S)
    assert_allclose(w["Scalars:scalars"], csv.omega_BN_B[:n], rtol=0, atol=SCALAR_TOL)


@needs_proc
def test_recording_process_killed_mid_run_keeps_the_run_and_its_csv(tmp_path):
    """The recording process dies while the run goes on: the run still completes, every row
    (t = 0..duration at output_dt) is in the CSV, and the CLI says in one line that the recording
    failed and why, exit 1."""
    scene = load_scene(HOLD)
    out = tmp_path / "o"
    rrd = out / "recording.rrd"
    proc = subprocess.Popen(
        [str(STATIONBED), "run", str(HOLD), "--out", str(out), "--rrd", str(rrd)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        _wait_for(lambda: _children(proc.pid), "the recording process")
        (child,) = _children(proc.pid)
        _wait_for(lambda: _csv_rows(out / "trajectory.partial.csv") > 0 or proc.poll() is not None, "the first rows")
        os.kill(child, signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=WAIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 1
    partial_rrd = out / "recording.partial.rrd"
    err = one_error_line(stderr)
    assert f"recording {partial_rrd} failed" in err and "killed by signal 9" in err
    csv = Trajectory.from_csv(out / "trajectory.csv")
    sim = scene.simulation
    assert len(csv) == math.floor(sim.duration / sim.output_dt) + 1 + (sim.duration % sim.output_dt > 0)
    assert csv.t[-1] == pytest.approx(sim.duration, abs=TIME_TOL_S)
    assert f"{len(csv)} rows" in stdout


def test_recording_process_that_cannot_start_keeps_the_run(tmp_path, monkeypatch, capsys):
    """No Python to start the recording process with: the run and its CSV are complete, one line
    names the failure, exit 1, no recording."""
    scene = tmp_path / "rigid.toml"
    scene.write_text(RIGID_TOML)
    monkeypatch.setattr(sys, "executable", str(tmp_path / "no-such-python"))
    rrd = tmp_path / "o" / "recording.rrd"
    assert cli_main(["run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd)]) == 1
    err = capsys.readouterr().err
    assert "cannot start the recording process" in one_error_line(err)
    csv = Trajectory.from_csv(tmp_path / "o" / "trajectory.csv")
    assert len(csv) == 21 and csv.t[-1] == 20.0  # duration 20 s at output_dt = 1 s
    assert not rrd.exists()


def test_recording_process_that_cannot_write_reports_why(tmp_path, capsys):
    """The recording's folder is a file: the child fails at once with the reason, the run goes
    on to a complete CSV, exit 1 with that reason in one line."""
    scene = tmp_path / "rigid.toml"
    scene.write_text(RIGID_TOML)
    (tmp_path / "afile").write_text("")
    rrd = tmp_path / "afile" / "recording.rrd"
    assert cli_main(["run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd)]) == 1
    err = capsys.readouterr().err
    line = one_error_line(err)
    assert "exit status 1" in line and "afile" in line
    assert len(Trajectory.from_csv(tmp_path / "o" / "trajectory.csv")) == 21


def test_bad_scene_stops_the_recording_process_and_writes_nothing(tmp_path, monkeypatch, capsys):
    """A scene that does not load: exit 2 as without --rrd, the recording process (already
    started) is stopped and no file is made."""
    from stationbed.output.rerun import child

    started = []
    start = child.RecordingChild.start
    monkeypatch.setattr(child.RecordingChild, "start", classmethod(lambda cls, *a: started.append(start(*a)) or started[-1]))
    scene = tmp_path / "bad.toml"
    scene.write_text("name = 'bad'\n[body]\nmass = -1.0\n")
    rrd = tmp_path / "o" / "recording.rrd"
    assert cli_main(["run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd)]) == 2
    one_error_line(capsys.readouterr().err)
    (rec,) = started
    assert rec.proc.poll() is not None
    assert not rrd.exists()


# -- closed loop: CMG cluster, controller, sun-tracking arrays (issue 3 columns) ------------------
@pytest.fixture(scope="module")
def hold_run(tmp_path_factory):
    """``stationbed run iss_lvlh_hold.toml --duration 200 --rrd``: the command-line path (CSV teed
    with the recording); the CSV (%.17g, exact) is the trajectory the recording must match."""
    out = tmp_path_factory.mktemp("hold")
    rrd = out / "recording.rrd"
    res = subprocess.run(
        [str(STATIONBED), "run", str(HOLD), "--out", str(out), "--duration", str(HOLD_DURATION_S), "--rrd", str(rrd)],
        capture_output=True, text=True,
    )
    assert res.returncode == 0, res.stderr
    return load_scene(HOLD), Trajectory.from_csv(out / "trajectory.csv"), rrd, read_temporal(rrd)


HOLD_SERIES = [
    ("telemetry/cmg/h_B", ["hx", "hy", "hz"]),
    ("telemetry/cmg/gimbal/angle", [f"gimbal_{i}_{w}" for i in range(1, 5) for w in ("outer", "inner")]),
    ("telemetry/cmg/gimbal/rate", [f"gimbal_{i}_{w}_rate" for i in range(1, 5) for w in ("outer", "inner")]),
    ("telemetry/cmg/singularity", ["cmg_singularity"]),
    ("telemetry/cmg/saturated", ["cmg_saturated"]),
    ("telemetry/control/tau_cmd_B", ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z"]),
    ("telemetry/control/att_err_deg", ["att_err_deg"]),
    ("telemetry/control/att_err_axes_deg", ["att_err_x_deg", "att_err_y_deg", "att_err_z_deg"]),
    ("telemetry/arrays/stbd_pair/track_err_deg", ["track_err_deg_stbd_pair"]),
    ("telemetry/arrays/port_pair/track_err_deg", ["track_err_deg_port_pair"]),
]


def test_hold_records_cmg_control_and_sun_entities(hold_run):
    """Every issue-3 column has its place in the station's tree; none is left under extra/."""
    _, traj, path, data = hold_run
    assert traj.columns == trajectory_columns(load_scene(HOLD))
    expected = {e for e, _ in HOLD_SERIES} | {"world/station/cmg/units", "world/station/cmg/h_B"}
    assert expected <= set(data)
    assert not [e for e in data if e.startswith("telemetry/extra")]
    assert {"world/sun", "world/station/cmg/units", "world/station/cmg/h_B"} <= static_entities(path)


def test_hold_row_counts_and_times_match_trajectory(hold_run):
    _, traj, _, data = hold_run
    assert len(traj) == int(HOLD_DURATION_S / 10.0) + 1
    for ent, cols in data.items():
        if ent in ("events", "world/sun"):  # logged when something changes (issue 24), not per row
            continue
        assert len(cols["t"]) == len(traj), ent
        assert_allclose(cols["t"], traj.t, rtol=0, atol=TIME_TOL_S, err_msg=ent)


@pytest.mark.parametrize("entity, columns", HOLD_SERIES, ids=[e.split("telemetry/")[1] for e, _ in HOLD_SERIES])
def test_hold_logged_series_equal_trajectory(hold_run, entity, columns):
    _, traj, _, data = hold_run
    logged = data[entity]["Scalars:scalars"]
    assert_allclose(logged[:, : len(columns)], traj.cols(*columns), rtol=0, atol=SCALAR_TOL)


def test_hold_logged_h_norm_is_the_cluster_momentum_magnitude(hold_run):
    _, traj, _, data = hold_run
    h = data["telemetry/cmg/h_B"]["Scalars:scalars"]
    assert_allclose(h[:, 3], np.linalg.norm(traj.cols("hx", "hy", "hz"), axis=1), rtol=1e-15, atol=0)
    assert h[-1, 3] > 0.1 * 4 * 4760.0  # N m s: the PD law is working the cluster (the arrows below move)


def _dgcmg_unit_momenta(h_rotor, outer, inner):
    """Rotor momenta of the default ISS-style layout, written out here from the DGCMG geometry
    (outer axes +x, +y, -x, -y; spins +z, +x, -z, -x at zero angles; e2 = e3 x e1; spin
    sin(inner) e1 + cos(inner) (cos(outer) e3 - sin(outer) e2)), shape (n, 4, 3)."""
    e1 = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    e3 = np.array([[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]], float)
    e2 = np.cross(e3, e1)
    so, co, si, ci = (f(a)[..., None] for f, a in ((np.sin, outer), (np.cos, outer), (np.sin, inner), (np.cos, inner)))
    return h_rotor * (si * e1 + ci * (co * e3 - so * e2))


def test_hold_cmg_arrows_are_the_rotor_momenta(hold_run):
    """One arrow per unit: all four as long as one rotor's momentum, pointing along that unit's
    spin axis from its gimbal angles, summing to the trajectory's h (the dynamics' own model);
    the total arrow is h at the same scale."""
    scene, traj, _, data = hold_run
    h_rotor = scene.cmg.h_rotor
    units = data["world/station/cmg/units"]["Arrows3D:vectors"].reshape(len(traj), 4, 3)
    length = np.linalg.norm(units, axis=2)
    assert_allclose(length, length[0, 0], rtol=1e-6)  # float32 lengths of ~20 m
    scale = length[0, 0] / h_rotor  # [m per N m s]
    outer = traj.cols(*[f"gimbal_{i}_outer" for i in range(1, 5)])
    inner = traj.cols(*[f"gimbal_{i}_inner" for i in range(1, 5)])
    assert_allclose(units / scale, _dgcmg_unit_momenta(h_rotor, outer, inner), rtol=0, atol=CMG_F32_TOL_NMS)
    h = traj.cols("hx", "hy", "hz")
    assert_allclose(units.sum(axis=1) / scale, h, rtol=0, atol=CMG_F32_TOL_NMS)
    assert_allclose(data["world/station/cmg/h_B"]["Arrows3D:vectors"] / scale, h, rtol=0, atol=CMG_F32_TOL_NMS)


def _angle_deg(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...i,...i", a, b)))


def test_hold_sun_vector_is_where_the_arrays_point(hold_run):
    """The drawn sun is the one the arrays track: the angle between each array's normal (+z_P,
    turned into N by the logged C_NB and C_BP) and the drawn sun vector is the logged tracking
    error, row by row (it rises to ~0.4 deg as the station starts turning, then decays)."""
    scene, traj, path, data = hold_run
    sun = [c for c in rerun_chunk.RrdReader(path).stream().to_chunks() if c.is_static and c.entity_path.lstrip("/") == "world/sun"]
    s_N = np.asarray(sun[0].to_record_batch().column("Arrows3D:vectors").to_pylist()[0][0], float)
    C_NB = Rotation.from_quat(data["world/station"]["Transform3D:quaternion"]).as_matrix()
    for a in scene.appendage:
        C_BP = Rotation.from_quat(data[f"world/station/{a.name}"]["Transform3D:quaternion"]).as_matrix()
        n_N = np.einsum("nij,njk,k->ni", C_NB, C_BP, [0.0, 0.0, 1.0])
        err = traj[f"track_err_deg_{a.name}"]
        assert_allclose(_angle_deg(n_N, s_N), err, rtol=0, atol=ANGLE_F32_TOL_DEG, err_msg=a.name)
        assert err.max() > 0.1  # deg: a real variation, resolved to ANGLE_F32_TOL_DEG


def test_hold_sun_vector_has_the_scene_beta_and_noon(hold_run):
    """The sun sits beta above the orbit plane (the angle to the logged y_O = -orbit normal is
    90 deg + beta) and its in-plane part points at the station's position at u = u_noon
    (DESIGN §5: R_N = (cos u, sin u cos i, sin u sin i))."""
    scene, _, path, data = hold_run
    sun = [c for c in rerun_chunk.RrdReader(path).stream().to_chunks() if c.is_static and c.entity_path.lstrip("/") == "world/sun"]
    s_N = np.asarray(sun[0].to_record_batch().column("Arrows3D:vectors").to_pylist()[0][0], float)
    y_O_N = Rotation.from_quat(data["world/lvlh"]["Transform3D:quaternion"][0]).as_matrix()[:, 1]
    beta, u, i = scene.sun.beta, scene.sun.u_noon, scene.orbit.inclination
    assert _angle_deg(s_N, y_O_N) == pytest.approx(90.0 + math.degrees(beta), abs=ANGLE_F32_TOL_DEG)
    in_plane = s_N - np.dot(s_N, y_O_N) * y_O_N  # y_O is a unit vector: remove the normal part
    R_noon = np.array([math.cos(u), math.sin(u) * math.cos(i), math.sin(u) * math.sin(i)])
    assert _angle_deg(in_plane, R_noon) == pytest.approx(0.0, abs=ANGLE_F32_TOL_DEG)


def assert_every_panel_and_series_shown(views, telemetry):
    """Every time-series panel shows at least one logged series, and every series is in a panel."""
    shown = set()
    for v in (v for v in views if v["class"] == "TimeSeries"):
        s = shown_by(v, telemetry)
        assert s, v
        shown |= s
    assert shown == set(telemetry)


def test_hold_blueprint_shows_every_series_in_some_panel(hold_run):
    """3-D view plus time-series panels; every panel shows at least one logged series and every
    logged telemetry entity is in a panel (the control column holds the issue-3 series)."""
    _, _, path, data = hold_run
    views = blueprint_views(path)
    assert [v["origin"] for v in views if v["class"] == "3D"] == ["world"]
    telemetry = [e for e in data if e.startswith("telemetry/")]
    assert_every_panel_and_series_shown(views, telemetry)
    # the angle panel shows the angles only, the tracking errors (deg) have their own
    (angles,) = [v for v in views if v["name"] == "array angles [rad]"]
    assert shown_by(angles, telemetry) == {"telemetry/arrays/stbd_pair", "telemetry/arrays/port_pair"}


def test_hold_recording_verifies(hold_run):
    res = verify(hold_run[2])
    assert res.returncode == 0, res.stderr


CMG_KINDS = {
    "dgcmg_user_axes": {"kind": "dgcmg", "count": 3, "h_rotor": 100.0,
                         "outer_axes_B": [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.0, -1.0, 1.0]]},
    "sgcmg_pyramid": {"kind": "sgcmg_pyramid", "h_rotor": 100.0},
    "ideal": {"kind": "ideal", "max_momentum": 300.0},
}


@pytest.mark.parametrize("cmg", CMG_KINDS.values(), ids=CMG_KINDS.keys())
def test_cmg_arrows_sum_to_the_model_momentum(tmp_path, rng, cmg):
    """For every cluster kind, at random gimbal angles: the unit arrows have one rotor's length
    and sum to h of the dynamics' own model (``cluster_functions(cfg)["h"]``); the total arrow
    is h; an ideal cluster has no units, only the total."""
    d = copy.deepcopy(RIGID)
    d["cmg"] = cmg
    scene = scene_from_dict(d)
    cols = trajectory_columns(scene)
    n = 7
    data = np.zeros((n, len(cols)))
    j = {c: k for k, c in enumerate(cols)}
    data[:, j["t"]] = np.arange(n) * 1.0
    data[:, j["qw"]] = 1.0
    h_of = cluster_functions(scene.cmg)["h"]
    gimbals = [c for c in cols if c.startswith("gimbal_") and not c.endswith("_rate")]
    for row in data:
        if gimbals:
            row[[j[c] for c in gimbals]] = rng.uniform(-math.pi, math.pi, len(gimbals))
            row[[j["hx"], j["hy"], j["hz"]]] = np.asarray(h_of(row[[j[c] for c in gimbals]])).ravel()
        else:
            row[[j["hx"], j["hy"], j["hz"]]] = rng.uniform(-170.0, 170.0, 3)  # N m s, inside 300
    traj = Trajectory(cols, data)
    rec = read_temporal(write_recording(traj, scene, tmp_path / "cmg.rrd"))
    h = traj.cols("hx", "hy", "hz")
    total = rec["world/station/cmg/h_B"]["Arrows3D:vectors"]
    if scene.cmg.kind == "ideal":
        assert "world/station/cmg/units" not in rec
        scale = np.linalg.norm(total[0]) / np.linalg.norm(h[0])
    else:
        units = rec["world/station/cmg/units"]["Arrows3D:vectors"].reshape(n, scene.cmg.n_units, 3)
        length = np.linalg.norm(units, axis=2)
        assert_allclose(length, length[0, 0], rtol=1e-6)
        scale = length[0, 0] / scene.cmg.h_rotor
        assert_allclose(units.sum(axis=1) / scale, h, rtol=0, atol=1e-4)  # 100 N m s rotors in float32
    assert_allclose(total / scale, h, rtol=0, atol=1e-4)


# -- flexible arrays (issue 6): modal coordinates and the arrays' elastic lines -------------------
#: power_tower_free_drift with two beam modes per array (a 30 m array bending out of its plane
#: at 0.1 Hz and in its plane at 0.25 Hz), 60 s at 1 s: both modes resolved (>= 4 rows a period).
FLEX_TOML = """
name = "rrd_flex_case"
[simulation]
duration = 60.0  # s
output_dt = 1.0  # s
rtol = 1e-9
atol = 1e-12
[initial]
frame = "lvlh"
[body]
mass = 2.2e5  # kg
inertia = [[9.1e7, -1.5e6, -2.0e6], [-1.5e6, 8.7e7, 4.0e5], [-2.0e6, 4.0e5, 7.5e6]]  # kg m²
cm = [0.0, 0.0, 10.0]  # m
[[appendage]]
name = "stbd"
mass = 3000.0  # kg
inertia = [[2.25e5, 0.0, 0.0], [0.0, 3.6e4, 0.0], [0.0, 0.0, 2.61e5]]  # kg m²
cm = [0.0, 25.0, -60.0]  # m
alpha = { a0 = 0.0, rate = -0.0011313 }  # rad, rad/s
beta = { a0 = 0.25 }  # rad
[[appendage.mode]]
frequency_hz = 0.1
beam = { length = 30.0, root = [0.0, -15.0, 0.0], span = "y", deflection = "z", n = 1 }
eta0 = 0.05  # m
[[appendage.mode]]
frequency_hz = 0.25
beam = { length = 30.0, root = [0.0, -15.0, 0.0], span = "y", deflection = "x", n = 1 }
eta_rate0 = 0.01  # m/s
[[appendage]]
name = "port"
mass = 3000.0
inertia = [[2.25e5, 0.0, 0.0], [0.0, 3.6e4, 0.0], [0.0, 0.0, 2.61e5]]
cm = [0.0, -25.0, -60.0]
alpha = { a0 = 0.0, rate = -0.0011313 }
beta = { a0 = -0.25 }
[[appendage.mode]]
frequency_hz = 0.1
damping = 0.02
beam = { length = 30.0, root = [0.0, 15.0, 0.0], span = "-y", deflection = "z", n = 1 }
eta_rate0 = -0.02  # m/s
[[appendage.mode]]
frequency_hz = 0.25
beam = { length = 30.0, root = [0.0, 15.0, 0.0], span = "-y", deflection = "x", n = 1 }
[orbit]
altitude = 400000.0  # m
inclination = 0.4974  # rad
gravity_gradient = true
"""
FLEX_BEAM_M = 30.0  # m, both arrays' beams
#: Largest free-vibration tip amplitude sum(sqrt(eta² + (etadot/omega)²)) of one array at t = 0
#: [m]: stbd's 0.05 m plus 0.01 m/s at 0.25 Hz (port: 0.02 m/s at 0.1 Hz, 0.0318 m, is less).
FLEX_AMP0_M = 0.05 + 0.01 / (2.0 * math.pi * 0.25)
#: Strip points are float32 (~1e-7 relative) on a ~15 m lever: ~1e-5 m; divided by the
#: exaggeration (~100), a drawn deflection reads back to ~1e-7 m of the modal coordinate.
ELASTIC_F32_TOL_M = 1e-6
MODE_COLUMNS = {
    f"telemetry/modes/{a}/{w}": [f"{w}_{a}_{k}" for k in (1, 2)] for a in ("stbd", "port") for w in ("eta", "etadot")
}
MODE_COLUMNS["telemetry/modes/U_strain"] = ["U_strain"]


@pytest.fixture(scope="module")
def flex_run(tmp_path_factory):
    """``stationbed run FLEX --rrd``: the recording process and the CSV (%.17g, exact) side by side."""
    out = tmp_path_factory.mktemp("flex")
    scene = out / "flex.toml"
    scene.write_text(FLEX_TOML)
    rrd = out / "recording.rrd"
    res = subprocess.run([str(STATIONBED), "run", str(scene), "--out", str(out), "--rrd", str(rrd)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return load_scene(scene), Trajectory.from_csv(out / "trajectory.csv"), rrd, read_temporal(rrd)


def test_flex_rows_have_the_modal_columns(flex_run):
    scene, traj, _, data = flex_run
    assert traj.columns == trajectory_columns(scene) and traj.columns[-1] == "U_strain"
    assert len(traj) == 61
    for ent, cols in data.items():
        assert_allclose(cols["t"], traj.t, rtol=0, atol=TIME_TOL_S, err_msg=ent)
    assert not [e for e in data if e.startswith("telemetry/extra")]


@pytest.mark.parametrize("entity, columns", MODE_COLUMNS.items(), ids=[e.split("modes/")[1] for e in MODE_COLUMNS])
def test_flex_modal_series_equal_csv(flex_run, entity, columns):
    """eta, etadot per array and U_strain are the CSV's float64 values, exactly."""
    _, traj, _, data = flex_run
    assert_allclose(data[entity]["Scalars:scalars"], traj.cols(*columns), rtol=0, atol=SCALAR_TOL)
    assert np.ptp(traj.cols(*columns), axis=0).min() > 0.0  # every series moves: a real comparison


def test_flex_blueprint_has_a_modes_column_and_shows_every_series(flex_run):
    _, _, path, data = flex_run
    views = blueprint_views(path)
    telemetry = [e for e in data if e.startswith("telemetry/")]
    assert_every_panel_and_series_shown(views, telemetry)
    by_name = {v["name"]: shown_by(v, telemetry) for v in views}
    assert by_name["modal coordinates eta (beam modes: tip deflection [m])"] == {"telemetry/modes/stbd/eta", "telemetry/modes/port/eta"}
    assert by_name["modal rates etadot"] == {"telemetry/modes/stbd/etadot", "telemetry/modes/port/etadot"}
    assert by_name["strain energy U_strain [J]"] == {"telemetry/modes/U_strain"}


def _static_labels(path, entity):
    chunks = [c for c in rerun_chunk.RrdReader(path).stream().to_chunks() if c.is_static and c.entity_path.lstrip("/") == entity]
    rb = [c.to_record_batch() for c in chunks if "LineStrips3D:labels" in c.to_record_batch().schema.names]
    return rb[-1].column("LineStrips3D:labels").to_pylist()[0]


@pytest.mark.parametrize("array, root_y, span_y", [("stbd", -15.0, 1.0), ("port", 15.0, -1.0)], ids=["stbd", "port"])
def test_flex_elastic_line_is_the_tip_deflection(flex_run, array, root_y, span_y):
    """The drawn line of an array (P axes, child of its C_BP transform) runs from the beam's root,
    which does not move, to its tip, displaced by the exaggeration k times eta_1 z_P + eta_2 x_P
    (the shapes are tip-normalised, so eta is the tip deflection [m]); k is the same in every
    row, in the label, and makes the largest tip amplitude at t = 0 draw as 0.2 x the beam."""
    _, traj, path, data = flex_run
    pts = data[f"world/station/{array}/elastic_line"]["LineStrips3D:strips"].reshape(len(traj), -1, 3)
    assert_allclose(pts[:, 0], np.tile([0.0, root_y, 0.0], (len(traj), 1)), rtol=0, atol=1e-5)  # m
    tip_rigid = np.array([0.0, root_y + span_y * FLEX_BEAM_M, 0.0])
    k = 0.2 * FLEX_BEAM_M / FLEX_AMP0_M  # drawn m per m
    eta1, eta2 = traj[f"eta_{array}_1"], traj[f"eta_{array}_2"]
    expected = np.column_stack([eta2, np.zeros_like(eta1), eta1])
    assert_allclose((pts[:, -1] - tip_rigid) / k, expected, rtol=0, atol=ELASTIC_F32_TOL_M)
    label = _static_labels(path, f"world/station/{array}/elastic_line")
    assert label == [f"{array} deflection x{k:.3g}"]


def test_flex_exaggeration_is_fixed_at_the_first_motion(tmp_path, flex_run):
    """Rows streamed in two batches, the arrays at rest in the first: those lines are straight
    (no scale yet), and the scale is fixed by the first row that moves (stbd: eta_1 = 0.1 m at
    rest, amplitude 0.1 m -> drawn 0.2 x 30 m), then kept for later, larger motion."""
    scene = flex_run[0]
    cols = trajectory_columns(scene)
    j = {c: k for k, c in enumerate(cols)}
    data = np.zeros((6, len(cols)))
    data[:, j["t"]] = np.arange(6) * 1.0  # s
    data[:, j["qw"]] = 1.0
    data[3:, j["eta_stbd_1"]] = [0.1, 0.3, -0.2]  # m
    with RrdSink(scene, tmp_path / "k.rrd", cols, flush_interval_s=0.0) as sink:
        sink.write(data[:2])
        sink.write(data[2:])
    pts = read_temporal(tmp_path / "k.rrd")["world/station/stbd/elastic_line"]["LineStrips3D:strips"].reshape(6, -1, 3)
    k = 0.2 * FLEX_BEAM_M / 0.1  # drawn m per m
    assert_allclose(pts[:, -1, 2] / k, data[:, j["eta_stbd_1"]], rtol=0, atol=ELASTIC_F32_TOL_M)
    assert _static_labels(tmp_path / "k.rrd", "world/station/stbd/elastic_line") == [f"stbd deflection x{k:.3g}"]


def test_rigid_recording_has_no_elastic_parts(iss_run):
    """A rigid scene: no modes entities, no elastic lines, no modes panels (its recording is as
    before issue 6)."""
    _, _, path, data = iss_run
    everything = set(data) | static_entities(path)
    assert not [e for e in everything if e.startswith("telemetry/modes") or e.endswith("elastic_line")]
    assert not [v for v in blueprint_views(path) if v["origin"].startswith("telemetry/modes")]


def test_flex_recording_verifies(flex_run):
    res = verify(flex_run[2])
    assert res.returncode == 0, res.stderr


# -- stationbed replay ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_rrd(tmp_path_factory):
    scene = scene_from_dict(copy.deepcopy(RIGID))
    return write_recording(simulate(scene, duration=5.0), scene, tmp_path_factory.mktemp("replay") / "small.rrd")


def fake_viewer(tmp_path, status: int) -> Path:
    """A stand-in for the rerun binary: records its arguments, exits with ``status``."""
    exe = tmp_path / "fake_rerun"
    exe.write_text(f'#!/bin/sh\nprintf "%s\\n" "$@" > "{tmp_path}/argv.txt"\nexit {status}\n')
    exe.chmod(0o755)
    return exe


def test_replay_missing_file_is_a_one_line_error_exit_2(tmp_path):
    res = subprocess.run([str(STATIONBED), "replay", str(tmp_path / "nope.rrd")], capture_output=True, text=True)
    assert res.returncode == 2
    assert res.stderr == f"stationbed: error: no recording at {tmp_path / 'nope.rrd'}\n"


def test_replay_rejects_a_file_that_is_not_a_recording(tmp_path, capsys):
    (tmp_path / "scene.toml").write_text("name = 'x'\n")
    assert cli_main(["replay", str(tmp_path / "scene.toml")]) == 2
    assert "not a rerun recording" in capsys.readouterr().err


def _no_display(monkeypatch):
    for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(v, raising=False)


def test_replay_without_display_prints_the_commands_exit_0(tmp_path, small_rrd, monkeypatch, capsys):
    exe = fake_viewer(tmp_path, 0)
    monkeypatch.setenv("STATIONBED_RERUN", str(exe))
    _no_display(monkeypatch)
    assert cli_main(["replay", str(small_rrd)]) == 0
    out = capsys.readouterr().out
    assert "no display" in out
    assert f"{exe} {small_rrd}" in out and f"{exe} --web-viewer --bind 127.0.0.1 {small_rrd}" in out
    assert not (tmp_path / "argv.txt").exists()  # nothing was started


@pytest.mark.parametrize("web, argv", [(False, []), (True, ["--web-viewer", "--bind", "127.0.0.1"])], ids=["native", "web"])
def test_replay_starts_the_viewer_on_the_file(tmp_path, small_rrd, monkeypatch, web, argv):
    monkeypatch.setenv("STATIONBED_RERUN", str(fake_viewer(tmp_path, 0)))
    if web:
        _no_display(monkeypatch)  # the web viewer needs no display
    else:
        monkeypatch.setenv("DISPLAY", ":0")
    assert cli_main(["replay", str(small_rrd)] + (["--web"] if web else [])) == 0
    assert (tmp_path / "argv.txt").read_text().splitlines() == argv + [str(small_rrd)]


def test_replay_failing_viewer_prints_the_commands_exit_1(tmp_path, small_rrd, monkeypatch, capsys):
    exe = fake_viewer(tmp_path, 3)
    monkeypatch.setenv("STATIONBED_RERUN", str(exe))
    monkeypatch.setenv("DISPLAY", ":0")
    assert cli_main(["replay", str(small_rrd)]) == 1
    out, err = capsys.readouterr()
    assert "exited with status 3" in out and f"{exe} --web-viewer --bind 127.0.0.1 {small_rrd}" in out
    assert "status 3" in one_error_line(err)


def test_trajectory_csv_round_trip_is_exact(tmp_path):
    """Trajectory.to_csv writes 17 significant digits: from_csv reads every float64 back bit for bit."""
    scene = load_scene(ROOT / "scenarios" / "torque_window.toml")
    traj = simulate(scene, duration=50.0)
    traj.to_csv(tmp_path / "t.csv")
    back = Trajectory.from_csv(tmp_path / "t.csv")
    assert back.columns == traj.columns
    np.testing.assert_array_equal(back.data, traj.data)


@pytest.mark.parametrize("cut", [0, 1, 37], ids=["at_a_newline", "one_char_in", "mid_row"])
def test_trajectory_csv_torn_tail(tmp_path, cut):
    """A file cut ``cut`` characters after a row's newline (a writer killed mid-batch): with
    ``torn_tail`` the whole rows read bit for bit and the torn one is counted; without it, a torn
    row is the one-line error naming its line."""
    traj = Trajectory(["t", "a", "b"], np.array([[0.0, 1.0 / 3.0, -2.5e-300], [0.1, np.pi, 7.0], [0.2, -1.0, 1e300]]))
    traj.to_csv(tmp_path / "t.csv")
    text = (tmp_path / "t.csv").read_text()
    end = text.index("\n", text.index("\n") + 1) + 1 + cut  # the header, one row, then `cut` characters
    (tmp_path / "t.csv").write_text(text[:end])
    back = Trajectory.from_csv(tmp_path / "t.csv", torn_tail=True)
    np.testing.assert_array_equal(back.data, traj.data[:1])
    assert back.meta == {"torn_rows": int(cut > 0)}
    if cut:
        with pytest.raises(ValueError, match=r"line 3 has \d+ values, the header 3 columns"):
            Trajectory.from_csv(tmp_path / "t.csv")


def test_trajectory_csv_torn_header(tmp_path):
    """A header without its newline: with ``torn_tail`` no header (the run was killed writing
    it), one-line error; read strictly it is a header without rows."""
    (tmp_path / "t.csv").write_text("t,qw,q")
    with pytest.raises(ValueError, match="no header row"):
        Trajectory.from_csv(tmp_path / "t.csv", torn_tail=True)
    assert Trajectory.from_csv(tmp_path / "t.csv").columns == ["t", "qw", "q"]
