"""The Monte Carlo on Dask: the same table serially, on 1 and 2 local workers, and on a real
``dask scheduler`` with two ``dask worker`` processes started here, one of which is killed
(SIGKILL) mid-run.

Truth: the serial table (one process, no Dask). Every distributed table must equal it exactly
(``assert_frame_equal`` with no tolerance): each sample draws from its own seed and a chunk
is a pure function of its range, so where it ran cannot change a number.

The processes started here are bounded: every wait has a timeout and every process is killed
in a ``finally``; ports are chosen free at test time.
"""

import os
import signal
import socket
import subprocess
import sys
import time

import pandas as pd
import pytest

from stationbed import load_scene, montecarlo
from stationbed.cli import main

MC_SCENE = "scenarios/iss_lvlh_hold_montecarlo.toml"
#: the longest wait for the scheduler or the workers to come up [s]
START_TIMEOUT_S = 60.0
#: the longest wait for the study through the scheduler [s]
RUN_TIMEOUT_S = 120.0


def scene(n):
    return load_scene(MC_SCENE).replace({"simulation.duration": 120.0, "montecarlo.envelope_dt": 20.0,
                                         "montecarlo.settle_s": 20.0, "montecarlo.n": n})


@pytest.fixture(scope="module")
def serial():
    return montecarlo(scene(6), chunk=1).df


@pytest.mark.parametrize("workers", [1, 2], ids=["1_worker", "2_workers"])
def test_local_workers_give_the_serial_table(serial, workers):
    got = montecarlo(scene(6), workers=workers, chunk=1).df
    pd.testing.assert_frame_equal(got, serial)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, proc, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"the dask scheduler exited with {proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise TimeoutError(f"no dask scheduler on port {port} after {timeout} s")


def _wait_workers(address: str, n: int, timeout: float) -> None:
    from distributed import Client

    with Client(address, timeout=f"{timeout}s") as c:
        c.wait_for_workers(n, timeout=timeout)


def test_real_scheduler_and_a_killed_worker_give_the_serial_table(serial, tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    log = open(tmp_path / "dask.log", "w")
    procs = []
    try:
        sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--dashboard-address", ":0", "--no-show"],
                                 stdout=log, stderr=subprocess.STDOUT, env=env)
        procs.append(sched)
        _wait_port(port, sched, START_TIMEOUT_S)
        for i in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                           "--nthreads", "1", "--nworkers", "1", "--no-nanny", "--name", f"w{i}",
                                           "--dashboard-address", ":0"],
                                          stdout=log, stderr=subprocess.STDOUT, env=env))
        _wait_workers(address, 2, START_TIMEOUT_S)
        out = tmp_path / "out"
        cmd = [sys.executable, "-c", "import sys; from stationbed.cli import main; sys.exit(main(sys.argv[1:]))",
               "montecarlo", str(tmp_path / "scene.toml"), "--scheduler", address, "--out", str(out),
               "--chunk", "1", "--no-charts", "-q", "--exit-zero"]
        (tmp_path / "scene.toml").write_text(
            open(MC_SCENE).read().replace("duration = 5553.6", "duration = 120.0")
            .replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0")
            .replace("n = 1000", "n = 6"))
        study = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
        procs.append(study)
        end = time.monotonic() + RUN_TIMEOUT_S
        chunks = out / "chunks"
        while time.monotonic() < end and study.poll() is None:  # the first chunk is back: kill a worker
            if chunks.is_dir() and any(chunks.glob("chunk_*.parquet")):
                break
            time.sleep(0.05)
        killed_mid_run = study.poll() is None
        procs[1].send_signal(signal.SIGKILL)
        assert study.wait(timeout=RUN_TIMEOUT_S) == 0, (tmp_path / "dask.log").read_text()[-2000:]
        assert killed_mid_run
        got = pd.read_parquet(out / "samples.parquet")
        pd.testing.assert_frame_equal(got, serial)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.kill()
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
        log.close()


def test_cli_serial_option_matches(serial, tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(open(MC_SCENE).read().replace("duration = 5553.6", "duration = 120.0")
                    .replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0"))
    assert main(["montecarlo", str(path), "--n", "6", "--serial", "--chunk", "2", "--out", str(tmp_path / "o"),
                 "--no-charts", "-q", "--exit-zero"]) == 0
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "o" / "samples.parquet"), serial)


#: the interrupted study: long enough (~2 s of fused samples) that Ctrl-C lands before its end
INTERRUPTED_N, INTERRUPTED_DURATION_S = 40, 2000.0


def test_ctrl_c_keeps_finished_chunks_and_resume_completes(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(open(MC_SCENE).read().replace("duration = 5553.6", f"duration = {INTERRUPTED_DURATION_S}")
                    .replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0"))
    out = tmp_path / "o"
    n = INTERRUPTED_N
    args = ["montecarlo", str(path), "--n", str(n), "--serial", "--chunk", "1", "--out", str(out), "--no-charts", "-q"]
    # Ctrl-C as in a terminal: Python's SIGINT handler, unblocked (seen in the full suite: the
    # child of a pytest-xdist worker could inherit SIGINT ignored or blocked and never stop)
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT]); "
            "from stationbed.cli import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + RUN_TIMEOUT_S
        while time.monotonic() < end and proc.poll() is None and not any((out / "chunks").glob("chunk_*.parquet")):
            time.sleep(0.05)
        assert proc.poll() is None, "the study ended before it could be interrupted"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=RUN_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == 1 and "interrupted" in err and "--resume" in err
    kept = sorted((out / "chunks").glob("chunk_*.parquet"))
    assert 1 <= len(kept) < n and not (out / "samples.parquet").exists()
    assert main([*args, "--resume", "--exit-zero"]) == 0
    serial = montecarlo(load_scene(path).replace({"montecarlo.n": n}), chunk=1).df
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), serial)


def test_forked_workers_start_quiet_and_the_driver_keeps_its_progress():
    """Local workers forked from a driver whose command line set progress up (plain lines, a
    task open) start as a spawned worker does: quiet, no task of the driver's; the driver
    keeps its mode; Dask's periodic work is off or slowed in them (cluster.QUIET) and the
    driver's own Dask config is back as it was once the cluster closed."""
    import dask
    import distributed  # noqa: F401 - its config's defaults

    from stationbed.core import progress
    from stationbed.studies.montecarlo.cluster import QUIET, local_cluster

    before = {k: dask.config.get(k) for k in QUIET}
    progress.configure("plain", heartbeat=False)
    try:
        with progress.task("a study", total=1), local_cluster(2) as client:
            assert set(client.run(progress.mode).values()) == {"quiet"}
            assert set(client.run(lambda: len(progress._S.open_tasks)).values()) == {0}
            assert progress.mode() == "plain"
            # Dask's periodic work off or slowed in the workers (cluster.QUIET), the driver's own config as it was
            seen = client.run(lambda: {k: dask.config.get(k) for k in QUIET})
            assert len(seen) == 2 and all(v == QUIET for v in seen.values())
        assert {k: dask.config.get(k) for k in QUIET} == before
    finally:
        progress.reset()
