"""``stationbed run --realtime [FACTOR]`` and ``--live`` (issue 36; run/pacing.py, output/rerun/live.py).

Truths:

* pacing only sleeps: the CSV of a paced run is the unpaced run's, byte for byte, on every
  executor (the fused loop, the per-tick loop, the open loop);
* a paced run cannot run ahead of the wall clock: its wall time is at least the simulated time
  over the factor, so the achieved factor is at most the one asked (a lower bound: how close it
  comes is the benchmark's, benchmarks/bench_socket.py);
* deadlines are absolute: after a late tick the next deadline is still ``wall0 + t / factor``;
* ``--live``: the recording streamed to a rerun gRPC server (``rerun --serve-grpc --save``,
  headless, on localhost) holds what the ``--rrd`` file holds, entity by entity.
"""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stationbed.cli import main
from stationbed.run.pacing import MISS_S, Pacer
from stationbed.scene import scene_from_dict
from stationbed.studies.montecarlo.replay import scene_toml

FACTOR = 50.0  # simulated seconds per wall second in the tests
DURATION_S = 20.0  # s: 0.4 s of wall time at FACTOR
PERIOD_S = 0.5  # s


def scene_dict(controller: dict | None) -> dict:
    d = {
        "name": "paced",
        "simulation": {"duration": DURATION_S, "integrator": "rk4", "step": PERIOD_S, "output_dt": 1.0},
        "initial": {"frame": "lvlh", "q_BN": [math.cos(0.5 * math.radians(5.0)), math.sin(0.5 * math.radians(5.0)), 0.0, 0.0],
                    "omega_BN_B": [0.0, 1.0e-4, 0.0]},  # rad/s
        "body": {"mass": 1.0e5, "inertia": [[1.2e6, 5.0e4, -3.0e4], [5.0e4, 0.9e6, 2.0e4], [-3.0e4, 2.0e4, 1.5e6]]},
        "orbit": {"altitude": 400.0e3, "inclination": 0.9},  # m, rad
    }
    if controller is not None:
        d["controller"] = {"period": PERIOD_S, "name": "pd", "params": {"bandwidth": 0.05, "damping": 0.7}, **controller}
    return d


#: executor -> the scene's controller: pd fuses; a law in Python (with sensor noise and delay) runs
#: per tick; none: open loop
EXECUTORS = {
    "fused": {},
    "per_tick": {"name": "example_hold", "params": {"reference": "lvlh"},
                 "sensor": {"attitude_noise": 1.0e-4, "delay": PERIOD_S, "seed": 2}},
    "open_loop": None,
}


def write_scene(folder: Path, controller) -> Path:
    path = folder / "scene.toml"
    path.write_text(scene_toml(scene_from_dict(scene_dict(controller))))
    return path


@pytest.mark.parametrize("executor", list(EXECUTORS))
def test_a_paced_run_writes_the_unpaced_csv_byte_for_byte(tmp_path, executor):
    import json

    scene = write_scene(tmp_path, EXECUTORS[executor])
    assert main(["run", str(scene), "--out", str(tmp_path / "free"), "-q"]) == 0
    t0 = time.perf_counter()
    assert main(["run", str(scene), "--out", str(tmp_path / "paced"), "--realtime", str(FACTOR), "-q"]) == 0
    wall = time.perf_counter() - t0
    free, paced = ((tmp_path / d / "trajectory.csv").read_bytes() for d in ("free", "paced"))
    assert paced == free
    assert wall >= DURATION_S / FACTOR  # it cannot run ahead of the clock
    summary = json.loads((tmp_path / "paced" / "summary.json").read_text())
    rt = summary["summary"] if "summary" in summary else summary["realtime"]
    assert rt["realtime_factor"] == FACTOR and rt["realtime_achieved_factor"] <= FACTOR * (1 + 1e-9)
    assert rt["realtime_paced_at"] == ("tick" if executor == "per_tick" else "row")
    if executor != "open_loop":
        assert summary["summary"]["fused"] == (executor == "fused")


def test_deadlines_are_absolute_after_a_late_tick():
    """Work of 3 periods at one tick is a miss; the next deadline is still wall0 + t / factor
    (a clock that slept a period from each wake-up would drift by the lateness)."""
    p = Pacer(factor=100.0)  # a tick of 0.5 s every 5 ms
    p.wait(0.0)
    wall0 = p.wall0
    time.sleep(3 * PERIOD_S / 100.0)
    p.wait(PERIOD_S)
    assert p.misses == 1 and p.worst_late_s >= 2 * PERIOD_S / 100.0 - MISS_S
    assert p.deadline(4 * PERIOD_S) == wall0 + 4 * PERIOD_S / 100.0
    p.wait(4 * PERIOD_S)
    assert time.perf_counter() >= wall0 + 4 * PERIOD_S / 100.0
    p.wait(2 * PERIOD_S)  # a time already passed returns at once, uncounted
    assert p.n == 3


def test_a_factor_that_is_not_positive_is_refused(tmp_path, capsys):
    scene = write_scene(tmp_path, {})
    assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--realtime", "0"]) == 2
    assert "--realtime: the factor must be a positive number, got 0.0" in capsys.readouterr().err


# -- --live: the recording streamed to a rerun gRPC server ------------------------------------------

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rerun_exe() -> str:
    exe = Path(sys.executable).parent / "rerun"
    if not exe.is_file():
        pytest.skip("the rerun CLI (rerun-sdk) is not installed in this environment")
    return str(exe)


def _stopped(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"  # a zombie has exited
    except FileNotFoundError:
        return True


def _stop_server(pid: int, wait=None) -> None:
    """Stop a rerun gRPC server (SIGINT: it writes what it received, then exits)."""
    time.sleep(0.5)  # let it write what it received
    os.kill(pid, signal.SIGINT)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not (wait() is not None if wait else _stopped(pid)):
        time.sleep(0.05)
    if not (wait() is not None if wait else _stopped(pid)):
        os.kill(pid, signal.SIGKILL)


def _assert_received_what_the_file_holds(received: Path, rrd: Path) -> None:
    from test_rerun import read_temporal, static_entities  # the recording read back, entity by entity

    assert static_entities(received) == static_entities(rrd)  # the station drawn as in a replay
    live, file = read_temporal(received), read_temporal(rrd)
    assert sorted(live) == sorted(file) and len(file) > 10
    for entity, cols in file.items():
        assert sorted(live[entity]) == sorted(cols), entity
        for name, values in cols.items():
            np.testing.assert_array_equal(live[entity][name], values, err_msg=f"{entity} {name}")
    assert max(cols["t"][-1] for cols in live.values()) == DURATION_S  # every row streamed, to the last


def test_live_streams_the_recording_the_file_holds(tmp_path):
    pytest.importorskip("rerun")
    port = _free_port()
    received = tmp_path / "received.rrd"
    server = subprocess.Popen([_rerun_exe(), "--serve-grpc", "--port", str(port), "--save", str(received)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:  # until it listens
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        scene = write_scene(tmp_path, {})
        rrd = tmp_path / "file.rrd"
        assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd), "--live", str(port),
                     "--realtime", str(4 * FACTOR), "-q"]) == 0
    finally:
        _stop_server(server.pid, server.poll)
        if server.poll() is None:
            server.wait()
        server.stderr.close()
    _assert_received_what_the_file_holds(received, rrd)


#: the viewer --live starts when given no URL, stood in for: rerun's headless gRPC server on the
#: port the viewer is given, saving what it receives (the test has no display for a window)
STAND_IN = """#!{python}
import os, sys
port = next(a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--port="))
with open({said!r}, "w") as f:
    f.write(str(os.getpid()) + "\\n" + " ".join(sys.argv[1:]))
os.execv({real!r}, [{real!r}, "--serve-grpc", "--port", port, "--save", {save!r}])
"""


def test_live_without_a_url_starts_a_viewer_and_streams_to_it(tmp_path, monkeypatch):
    """``--live`` alone starts the viewer ``stationbed replay`` starts (``$STATIONBED_RERUN``,
    here the stand-in) on rerun's port, and streams to it what the ``--rrd`` file holds. (Before,
    rerun looked for ``rerun`` on PATH alone: a venv not activated had none.)"""
    pytest.importorskip("rerun")
    from stationbed.output.rerun.live import SPAWN_PORT
    from stationbed.output.rerun.viewer import RERUN_BINARY_ENV, rerun_binary

    real = rerun_binary()
    if real is None:
        pytest.skip("no rerun binary (rerun-sdk) to stand in for the viewer")
    with socket.socket() as s:
        if s.connect_ex(("127.0.0.1", SPAWN_PORT)) == 0:
            pytest.skip(f"a viewer already listens on {SPAWN_PORT}: --live would stream to it")
    said, received = tmp_path / "viewer_said", tmp_path / "received.rrd"
    stand_in = tmp_path / "viewer"
    stand_in.write_text(STAND_IN.format(python=sys.executable, said=str(said), real=real, save=str(received)))
    stand_in.chmod(0o755)
    monkeypatch.setenv(RERUN_BINARY_ENV, str(stand_in))
    monkeypatch.setenv("DISPLAY", ":0")  # (has_display: the stand-in needs none)
    scene, rrd = write_scene(tmp_path, {}), tmp_path / "file.rrd"
    try:
        assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--rrd", str(rrd), "--live",
                     "--realtime", str(4 * FACTOR), "-q"]) == 0
    finally:
        if said.exists():
            _stop_server(int(said.read_text().split()[0]))
    assert f"--port={SPAWN_PORT}" in said.read_text().split("\n", 1)[1].split()
    _assert_received_what_the_file_holds(received, rrd)


def test_live_to_a_viewer_that_is_not_there_stops_before_the_run(tmp_path, capsys):
    """Nobody listening at the URL: one line naming it, exit 2, no output written (rerun would
    otherwise take the stream and drop it silently at the end)."""
    scene = write_scene(tmp_path, {})
    port = _free_port()
    assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--live", str(port)]) == 2
    assert f"--live {port}: no rerun viewer or gRPC server listening at 127.0.0.1:{port}" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_hold_late_needs_realtime(tmp_path, capsys):
    scene = write_scene(tmp_path, {})
    assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--hold-late"]) == 2
    assert "--hold-late: holds a socket law's late command under --realtime" in capsys.readouterr().err


def test_a_sleep_that_wakes_late_is_a_miss(monkeypatch):
    """A deadline the work kept but the sleep before it overshot by more than MISS_S is a miss
    too (it was counted only when the work itself overran: a 10-minute run reported 0 misses
    with a 32 ms worst lateness)."""
    import stationbed.run.pacing as pacing

    real_sleep = time.sleep
    monkeypatch.setattr(pacing.time, "sleep", lambda s: real_sleep(s + 3 * MISS_S))  # a wake-up 3 ms late
    p = Pacer(factor=100.0)
    p.wait(0.0)
    p.wait(PERIOD_S)  # due 5 ms after the first: the work took nothing, the sleep woke late
    assert p.misses == 1 and p.worst_late_s >= 3 * MISS_S
