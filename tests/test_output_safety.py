"""Where ``stationbed plan`` and ``run`` write, and a disk that fills while they write (issue 32).

Truths: the file system (a link at an output's path is replaced, its target untouched; files of an
earlier flight are gone; a default folder is under ``out/``), the command line's contract (one
``stationbed: error:`` line naming the file, exit 1 for a failed write, 2 for bad input, within a
bounded time: a full disk must never hang), and the scene's own bound (``plan.intervals`` <=
MAX_INTERVALS) holding for the options that override it.

A full disk is a file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored: writes fail with EFBIG as they
would with ENOSPC), set in the subprocess only; it is per file, so small outputs are written and
the large one fails.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenes import ROOT, one_error_line
from stationbed.cli import main
from stationbed.scene import scene_from_dict
from stationbed.scene.plan import MAX_INTERVALS
from stationbed.studies.montecarlo.replay import scene_toml
from stationbed.studies.plan_flight import FLIGHT_FILES
from test_plan import slew_scene

EXE = Path(sys.executable).parent / "stationbed"
#: a command on a small scene, compile cache warm, or one stopped by a full disk [s]
CMD_TIMEOUT_S = 180.0
#: the largest file the limited process may write [bytes]: above the run's CSV (600 s: 65 kB)
#: and the study's table (4 samples: 49 kB), below their recordings (0.4 MB, 0.19 MB)
FILE_LIMIT_B = 150_000


def _slew_file(folder: Path, name: str = "plan_slew", **plan) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    d = slew_scene(**plan)
    d["name"] = name
    path = folder / "slew.toml"
    path.write_text(scene_toml(scene_from_dict(d)))
    return path


def _limited(limit: int):
    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return preexec


def _stationbed(args, cwd: Path, limit: int | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([str(EXE), *map(str, args)], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=CMD_TIMEOUT_S, preexec_fn=None if limit is None else _limited(limit))


# ---------------------------------------------------------------------------------------------
# stationbed plan
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("option", ["--intervals", "--refine"])
def test_plan_options_keep_the_scenes_interval_bound(tmp_path, capsys, option):
    """``--intervals 1000000`` grew past 1.5 GiB in 9 s: the options have plan.intervals' bound."""
    scene = _slew_file(tmp_path)
    code = main(["plan", str(scene), "--out", str(tmp_path / "out"), option, str(MAX_INTERVALS + 1), "--no-fly"])
    line = one_error_line(capsys.readouterr().err)
    assert code == 2 and f"{option} must be between 2 and {MAX_INTERVALS}, got {MAX_INTERVALS + 1}" in line
    assert not (tmp_path / "out").exists()


def test_plan_scene_refuses_a_mesh_past_the_bound():
    from stationbed.plan import PlanError, plan_scene

    with pytest.raises(PlanError, match=rf"refine must be between 2 and {MAX_INTERVALS}"):
        plan_scene(scene_from_dict(slew_scene()), refine=1_000_000)


@pytest.mark.parametrize("name", ["../../x", "/abs/x"], ids=["dotdot", "absolute"])
def test_plans_default_folder_stays_under_out(tmp_path, monkeypatch, capsys, name):
    scene = _slew_file(tmp_path / "scenes", name=name, intervals=8)
    work = tmp_path / "work" / "here"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    assert main(["plan", str(scene), "--no-fly", "-q"]) == 0
    written = [p for p in tmp_path.rglob("plan.json")]
    assert len(written) == 1 and written[0].is_relative_to(work / "out"), written


def _link_to_a_victim(tmp_path: Path, name: str) -> tuple[Path, Path]:
    """``(out, victim)``: the folder ``out`` whose file ``name`` is a link to a file that must be
    kept as it is ("keep me")."""
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    (out / name).symlink_to(victim)
    return out, victim


def test_plan_replaces_a_link_instead_of_writing_through_it(tmp_path):
    out, victim = _link_to_a_victim(tmp_path, "plan.csv")
    assert main(["plan", str(_slew_file(tmp_path, intervals=8)), "--out", str(out), "--no-fly", "-q"]) == 0
    assert victim.read_text() == "keep me\n"
    assert not (out / "plan.csv").is_symlink() and (out / "plan.csv").read_text().startswith("t,")


def test_plan_no_fly_removes_an_earlier_flight(tmp_path):
    """The flight files of an earlier plan in the folder described another plan: a new plan,
    flown or not, removes them."""
    scene = _slew_file(tmp_path, intervals=8)
    out = tmp_path / "out"
    assert main(["plan", str(scene), "--out", str(out), "-q"]) == 0
    assert all((out / f).exists() for f in FLIGHT_FILES)
    assert main(["plan", str(scene), "--out", str(out), "--no-fly", "-q"]) == 0
    assert [f for f in FLIGHT_FILES if (out / f).exists()] == []
    assert "flight" not in json.loads((out / "plan.json").read_text())


def test_schedule_plan_path_is_relative_to_the_scene_file(tmp_path, monkeypatch):
    """``params.plan = "plan.json"`` is the scene folder's plan (as ``controller.fmu`` and a
    controller file are), even when the working folder has a plan.json of its own."""
    from stationbed import load_scene, simulate

    scene_dir, work = tmp_path / "scene", tmp_path / "work"
    assert main(["plan", str(_slew_file(scene_dir, intervals=8)), "--out", str(scene_dir), "--no-fly", "-q"]) == 0
    work.mkdir()
    (work / "plan.json").write_text("not a plan")  # the working folder's: must not be read
    text = (scene_dir / "slew.toml").read_text().replace('name = "schedule"\n', 'name = "schedule"\nparams = { plan = "plan.json" }\n')
    (scene_dir / "flies.toml").write_text(text)
    monkeypatch.chdir(work)
    tr = simulate(load_scene(scene_dir / "flies.toml"), duration=1.0)
    assert tr.meta["status"] == "ok"


def test_a_sample_scene_written_elsewhere_still_finds_the_plan(tmp_path):
    """``montecarlo --sample K`` writes the sample's scene to another folder: schedule's relative
    ``params.plan`` (a declared ``file_params``) becomes absolute, as an FMU's path does."""
    from stationbed import load_scene, simulate
    from stationbed.studies.montecarlo.replay import write_sample_scene

    scene_dir = tmp_path / "scene"
    assert main(["plan", str(_slew_file(scene_dir, intervals=8)), "--out", str(scene_dir), "--no-fly", "-q"]) == 0
    d = slew_scene(intervals=8)
    d["controller"]["params"] = {"plan": "plan.json"}
    d["montecarlo"] = {"n": 2, "seed": 1, "disperse": [{"key": "initial.q_BN", "kind": "attitude_normal", "sigma": 1e-3}]}
    (scene_dir / "mc.toml").write_text(scene_toml(scene_from_dict(d)))
    back = write_sample_scene(load_scene(scene_dir / "mc.toml"), 1, tmp_path / "elsewhere" / "sample_1.toml")
    assert Path(back.controller.params["plan"]) == (scene_dir / "plan.json").resolve()
    assert simulate(back, duration=1.0).meta["status"] == "ok"


def test_plan_on_a_full_disk_is_one_line_naming_the_file(tmp_path):
    """A write that fails (the flight's recording, above the limit) ends the command with one
    line naming the file, exit 1; the plan's files written before it stay."""
    scene = _slew_file(tmp_path, intervals=8)
    res = _stationbed(["plan", scene, "--out", tmp_path / "out", "-q"], tmp_path, limit=20_000)
    assert res.returncode == 1, res.stderr
    line = one_error_line(res.stderr)
    assert f"cannot write {tmp_path / 'out'}/" in line and "File too large" in line
    assert (tmp_path / "out" / "plan.json").exists()


# ---------------------------------------------------------------------------------------------
# stationbed run and montecarlo
# ---------------------------------------------------------------------------------------------

def test_run_replaces_a_link_at_the_partial_csv(tmp_path):
    out, victim = _link_to_a_victim(tmp_path, "trajectory.partial.csv")
    scene = ROOT / "scenarios" / "iss_lvlh_hold.toml"
    assert main(["run", str(scene), "--out", str(out), "--duration", "10", "-q"]) == 0
    assert victim.read_text() == "keep me\n"
    assert (out / "trajectory.csv").read_text().startswith("t,")


def test_a_runs_recording_goes_to_a_folder_not_made_yet(tmp_path):
    """``--rrd`` into folders that do not exist yet: made, as the CSV's ``--out`` is (the file
    written by stationbed from rerun's stream must not lose what rerun's own sink did)."""
    rrd = tmp_path / "new" / "deeper" / "run.rrd"
    assert main(["run", str(ROOT / "scenarios" / "power_tower_free_drift.toml"), "--out", str(tmp_path / "out"),
                 "--duration", "20", "--rrd", str(rrd), "-q"]) == 0
    assert rrd.stat().st_size > 0


def test_a_runs_recording_on_a_full_disk_is_one_line(tmp_path):
    """``run --rrd``: the recording fails past the limit (the CSV fits): exit 1, one line naming
    the recording; rerun's own file sink had reported success on a truncated file."""
    rrd = tmp_path / "run.rrd"
    res = _stationbed(["run", ROOT / "scenarios" / "iss_lvlh_hold.toml", "--out", tmp_path / "out", "--duration", "600",
                       "--rrd", rrd, "-q"], tmp_path, limit=FILE_LIMIT_B)
    assert res.returncode == 1, res.stderr
    line = one_error_line(res.stderr)
    assert f"cannot write {tmp_path / 'run.partial.rrd'}: File too large" in line
    assert (tmp_path / "out" / "trajectory.csv").exists()


def test_a_studys_recording_on_a_full_disk_is_one_line(tmp_path):
    """``montecarlo.rrd`` past the limit: rerun's file sink hung (its flush waited for a writer
    thread that had died); now exit 1 within the timeout, one line naming the file."""
    res = _stationbed(["montecarlo", ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml", "--n", "4", "--serial",
                       "--no-charts", "--out", tmp_path / "mc", "--set", "simulation.duration=600", "-q"],
                      tmp_path, limit=FILE_LIMIT_B)
    assert res.returncode == 1, res.stderr
    line = one_error_line(res.stderr)
    assert f"cannot write {tmp_path / 'mc' / 'montecarlo.rrd'}: File too large" in line


# ---------------------------------------------------------------------------------------------
# stationbed screenshot
# ---------------------------------------------------------------------------------------------

#: how long the screenshot's browser may take to start [s]
BROWSER_START_S = 60.0
#: how long the processes it started may take to end after SIGTERM [s] (the command stops each
#: group with SIGTERM, waits up to 10 s, then SIGKILL)
STOP_S = 30.0


def _descendants(pid: int) -> dict[int, str]:
    """Every process below ``pid`` (children in sessions of their own too): pid -> command name."""
    parent, name = {}, {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            rest = stat[stat.rindex(")") + 2:].split()
            if rest[0] != "Z":
                parent[int(d.name)], name[int(d.name)] = int(rest[1]), stat[stat.index("(") + 1: stat.rindex(")")]
    below, frontier = {}, [pid]
    while frontier:
        p = frontier.pop()
        for c, pp in parent.items():
            if pp == p and c not in below:
                below[c] = name[c]
                frontier.append(c)
    return below


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc")
def test_sigterm_stops_the_screenshots_viewer_and_browser(tmp_path):
    """SIGTERM while the browser renders: exit 1 ("interrupted"), and the viewer server and every
    browser process it started are gone (they had been left running)."""
    from stationbed.output.rerun.screenshot import find_browser

    if find_browser() is None:
        pytest.skip("no Chromium installed (apt-get install chromium; make screenshots)")
    from stationbed import load_scene, simulate
    from stationbed.output.rerun.recording import write_recording

    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    rrd = write_recording(simulate(scene, duration=20.0), scene, tmp_path / "hold.rrd")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.Popen([str(EXE), "screenshot", str(rrd), "--out", str(tmp_path / "hold.png")], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: dict[int, str] = {}
    try:
        deadline = time.monotonic() + BROWSER_START_S
        while time.monotonic() < deadline and proc.poll() is None:
            seen.update(_descendants(proc.pid))
            if any("chrom" in n for n in seen.values()) and len(seen) >= 3:
                break
            time.sleep(0.2)
        assert proc.poll() is None and any("chrom" in n for n in seen.values()), (seen, proc.poll())
        time.sleep(1.0)
        seen.update(_descendants(proc.pid))
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=STOP_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    deadline = time.monotonic() + STOP_S
    while time.monotonic() < deadline and any(_alive(p) for p in seen):
        time.sleep(0.2)
    left = {p: n for p, n in seen.items() if _alive(p)}
    for p in left:  # never leave them to the next test
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert left == {}, left
    assert proc.returncode == 1 and "interrupted" in one_error_line(err)
