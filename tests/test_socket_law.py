"""A law in another process, over a socket (issue 36; docs/socket_law.md).

The shipped example clients (clients/socket_law/pd_client.py, standard library only, and
pd_client.c, built here by the system compiler with ``-ffp-contract=off``) each serve ``pd``.

Truths:

* the in-process ``pd`` called every tick (``fused=False``): the measurement crosses the socket
  as little-endian float64 and the command comes back so, both clients compute pd.py's
  operations in the same order on the same doubles, and the loop takes the same path: every
  column of every row is equal, **bit for bit** (any wrong field offset, sign, a tick of delay
  or a rounding difference would show), truth-fed and with sensor noise and a delay;
* a client that dies, answers late, or sends a frame of the wrong size or version stops the run
  at that tick: one line naming the tick and its time, the rows before it the reference's;
* a READY that lacks a field of the command frame is refused at connect, naming the field;
* under ``--realtime`` with ``--hold-late`` a late reply holds the last command, counted, and
  the run goes on; the rows before the late tick are the reference's.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stationbed import simulate
from stationbed.run.pacing import Pacer
from stationbed.run.simulation import SimulationError
from stationbed.run.socket_law import SocketController, SocketSetupError
from stationbed.scene import scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
CLIENTS = ROOT / "clients" / "socket_law"
PERIOD_S = 0.5  # s
DURATION_S = 30.0  # s: 60 ticks, the 5-deg roll error taken out
PD_PARAMS = {"bandwidth": 0.05, "damping": 0.7}  # rad/s, -
FAULT_TICK = 20  # the tick a faulty client misbehaves at
FAULT_T_S = FAULT_TICK * PERIOD_S  # s
#: how long a test waits for a client's "listening on" line [s]
START_S = 10.0


def pd_scene(controller: dict, sensor: dict | None = None) -> dict:
    """A small station in a 400 km orbit held in LVLH by pd from a 5-deg roll error, no CMG."""
    c = {"period": PERIOD_S, **controller}
    if sensor:
        c["sensor"] = sensor
    return scene_from_dict({
        "name": "socket_pd",
        "simulation": {"duration": DURATION_S, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"frame": "lvlh", "q_BN": [math.cos(0.5 * math.radians(5.0)), math.sin(0.5 * math.radians(5.0)), 0.0, 0.0],
                    "omega_BN_B": [0.0, 1.0e-4, 0.0]},  # rad/s
        "body": {"mass": 1.0e5, "inertia": [[1.2e6, 5.0e4, -3.0e4], [5.0e4, 0.9e6, 2.0e4], [-3.0e4, 2.0e4, 1.5e6]]},
        "orbit": {"altitude": 400.0e3, "inclination": 0.9},  # m, rad
        "controller": c,
    })


def start(cmd: list[str]) -> tuple[subprocess.Popen, int]:
    """A client process and the port it listens on (its first stdout line)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()  # bounded: the client prints it first thing, or exits
        if not line.startswith("listening on "):
            raise RuntimeError(f"client {cmd} did not start: {line!r} {proc.stderr.read()}")
        return proc, int(line.rsplit(":", 1)[1])
    except BaseException:
        proc.kill()
        proc.wait()
        raise


def stop(proc: subprocess.Popen) -> None:
    proc.kill()
    proc.wait(timeout=START_S)
    proc.stdout.close()
    proc.stderr.close()


@pytest.fixture(scope="module")
def c_client(tmp_path_factory):
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler (cc) to build clients/socket_law/pd_client.c")
    exe = tmp_path_factory.mktemp("c_client") / "pd_client"
    subprocess.run([cc, "-O2", "-ffp-contract=off", "-o", str(exe), str(CLIENTS / "pd_client.c"), "-lm"], check=True,
                   timeout=120)
    return exe


def client_command(kind: str, c_exe=None, fault: str | None = None, late_s: float | None = None) -> list[str]:
    if kind == "c":
        return [str(c_exe), "0"]
    cmd = [sys.executable, str(CLIENTS / "pd_client.py"), "--port", "0"]
    if fault:
        cmd += ["--fault", fault]
    if late_s is not None:
        cmd += ["--late-s", str(late_s)]
    return cmd


@pytest.fixture(scope="module")
def reference():
    """The in-process pd called every tick, truth-fed and with sensor errors."""
    cache = {}

    def get(sensor=None):
        key = repr(sensor)
        if key not in cache:
            cache[key] = simulate(pd_scene({"name": "pd", "params": PD_PARAMS}, sensor), fused=False)
        return cache[key]

    return get


SENSOR = {"attitude_noise": 1.0e-4, "rate_noise": 1.0e-6, "delay": PERIOD_S, "seed": 3}  # rad, rad/s, s


@pytest.mark.parametrize("sensor", [None, SENSOR], ids=["truth_fed", "noisy_delayed"])
@pytest.mark.parametrize("kind", ["python", "c"])
def test_a_socket_client_flies_pd_bit_for_bit(kind, sensor, c_client, reference):
    proc, port = start(client_command(kind, c_client))
    try:
        tr = simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS}, sensor))
    finally:
        stop(proc)
    ref = reference(sensor)
    assert tr.columns == ref.columns
    np.testing.assert_array_equal(tr.data, ref.data)
    s = tr.meta["summary"]
    assert not s["fused"] and s["socket_law"] == f"127.0.0.1:{port}" and "socket law" in s["executor_per_tick_because"]
    assert s["controller_updates"] == round(DURATION_S / PERIOD_S) + 1
    assert np.ptp(ref["tau_cmd_x"]) > 10.0  # N m: the law worked (the roll error was taken out)


@pytest.mark.parametrize("fault, words", [
    ("die", "the law process closed the connection"),
    ("size", "a COMMAND frame of 48 bytes, expected 80"),  # 24-byte header + 3 (not 3 + 4) float64
    ("version", "a frame of version 99, expected 1"),
], ids=["killed", "wrong_size", "wrong_version"])
def test_a_faulty_client_stops_the_run_at_its_tick_with_the_rows_kept(fault, words, reference):
    proc, port = start(client_command("python", fault=f"{fault}@{FAULT_TICK}"))
    try:
        with pytest.raises(SimulationError) as exc:
            simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS}))
    finally:
        stop(proc)
    e = exc.value
    msg = str(e)
    assert "\n" not in msg and e.t == FAULT_T_S
    assert f"tick {FAULT_TICK} (t = {FAULT_T_S:g} s)" in msg and words in msg
    tr = e.trajectory
    assert tr.meta["status"] == "failed" and tr.t[-1] == FAULT_T_S - PERIOD_S
    np.testing.assert_array_equal(tr.data, reference().data[: len(tr.t)])


def test_a_late_client_stops_the_run_after_the_timeout(reference):
    proc, port = start(client_command("python", fault=f"late@{FAULT_TICK}", late_s=3.0))
    try:
        with pytest.raises(SimulationError) as exc:
            simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS, "timeout": 0.5}))
    finally:
        stop(proc)
    msg = str(exc.value)
    assert f"tick {FAULT_TICK} (t = {FAULT_T_S:g} s): no command within 0.5 s (the law process is late)" in msg
    np.testing.assert_array_equal(exc.value.trajectory.data, reference().data[: FAULT_TICK])


def test_a_late_reply_under_realtime_holds_the_last_command(reference):
    """x20: a tick is due every 25 ms (a round trip takes ~0.05 ms); the client sleeps 0.2 s at
    tick 20: held, counted, and the run ends normally; its rows before tick 20 are the reference's."""
    proc, port = start(client_command("python", fault=f"late@{FAULT_TICK}", late_s=0.2))
    try:
        law = SocketController(f"127.0.0.1:{port}", period=PERIOD_S, params=PD_PARAMS)
        tr = simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS}), controller=law,
                      pace=Pacer(20.0, hold_late=True))
    finally:
        stop(proc)
    s = tr.meta["summary"]
    assert tr.meta["status"] == "ok" and FAULT_TICK in law.late_ticks and s["socket_late_ticks"] == law.n_late
    first = min(law.late_ticks)  # FAULT_TICK, unless the loaded machine made an earlier tick late too
    np.testing.assert_array_equal(tr.data[:first], reference().data[:first])
    assert not np.array_equal(tr.data, reference().data)  # the held command changed the flight


def test_a_ready_without_a_command_field_is_refused_naming_it():
    proc, port = start(client_command("python", fault="noref"))
    try:
        with pytest.raises(SocketSetupError, match=r"READY lacks the field 'command q_ref_BN 4'"):
            simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS}))
    finally:
        stop(proc)


def test_the_client_refuses_a_parameter_it_does_not_know():
    """The HELLO carries [controller.params]; the client answers ERROR with its own words."""
    proc, port = start(client_command("python"))
    try:
        with pytest.raises(SocketSetupError, match=r"refused the run: pd: unknown parameter 'bandwith'"):
            simulate(pd_scene({"port": f"127.0.0.1:{port}", "params": {"bandwith": 0.05}}))
    finally:
        stop(proc)


def test_no_law_process_is_one_line_naming_the_address():
    import socket

    with socket.socket() as s:  # a port nobody listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        with pytest.raises(SocketSetupError, match=rf"no law process listening at 127.0.0.1:{port} within 0.2 s"):
            simulate(pd_scene({"port": str(port), "params": PD_PARAMS, "timeout": 0.2}))


MC_TABLE = {
    "n": 4,
    "seed": 7,
    "disperse": [
        {"key": "initial.q_BN", "kind": "attitude_normal", "sigma": 0.02},  # rad
        {"key": "controller.params.bandwidth", "kind": "scale_uniform", "low": -0.2, "high": 0.2},
    ],
}
#: the fused pd (casadi C) against the per-tick law: tests/test_controller_contract.py FUSED_RTOL
FUSED_RTOL = 1e-9


def test_a_monte_carlo_flies_one_connection_per_sample(c_client):
    """One client serves every sample (a connection each, at once: the C client forks per
    connection), serially and on 2 Dask workers: the same table, and the in-process pd's
    (fused: to round-off)."""
    import pandas as pd

    from stationbed import montecarlo

    base = pd_scene({"name": "pd", "params": PD_PARAMS}).model_dump(exclude_unset=True)
    ref = montecarlo(scene_from_dict({**base, "montecarlo": MC_TABLE}), chunk=1).df
    proc, port = start(client_command("c", c_client))
    try:
        d = {**base, "montecarlo": MC_TABLE,
             "controller": {"port": f"127.0.0.1:{port}", "period": PERIOD_S, "params": PD_PARAMS}}
        serial = montecarlo(scene_from_dict(d), chunk=1).df
        workers = montecarlo(scene_from_dict(d), workers=2, chunk=1).df
    finally:
        stop(proc)
    assert (serial["status"] == "ok").all(), serial["reason"].tolist()
    pd.testing.assert_frame_equal(workers, serial)
    np.testing.assert_allclose(serial["final_att_err_deg"], ref["final_att_err_deg"], rtol=FUSED_RTOL, atol=0.0)
    assert serial["final_att_err_deg"].nunique() == len(serial)  # the samples differ


# -- waiting for the reply: spin or block, whichever flew faster (socket_law.WaitChoice) -------------

def _fly_epoch(choice, now: float, tick_s: float, misses_from: int | None = None) -> tuple[float, list[bool]]:
    """One epoch of ticks ``tick_s`` apart on a made-up clock; from tick ``misses_from`` on, every
    spin misses the reply."""
    from stationbed.run.socket_law import EPOCH_TICKS

    spins = []
    for i in range(EPOCH_TICKS):
        spins.append(choice.tick(now))
        if misses_from is not None and i >= misses_from and spins[-1]:
            choice.missed()
        now += tick_s
    return now, spins


FAST_S, SLOW_S = 15e-6, 60e-6  # s per tick: a spinning and a blocking tick on an idle machine, or the reverse


@pytest.mark.parametrize("spin_s, block_s, misses_from, spins", [
    (FAST_S, SLOW_S, None, True),
    (SLOW_S, FAST_S, None, False),
    (FAST_S, SLOW_S, 3, False),  # spins that missed the reply: the epoch stopped spinning, not timed so
], ids=["spin_faster", "block_faster", "spin_faster_but_missed"])
def test_the_wait_spins_when_spinning_flew_faster(spin_s, block_s, misses_from, spins):
    """A cycle times one epoch spinning, one blocking, then flies the faster way EXPLOIT_EPOCHS
    epochs; then it times both again."""
    from stationbed.run.socket_law import EXPLOIT_EPOCHS, SPINS_MISSED, WaitChoice

    w = WaitChoice()
    now, first = _fly_epoch(w, 0.0, spin_s, misses_from)
    n_spun = len(first) if misses_from is None else misses_from + SPINS_MISSED + 1
    assert all(first[:n_spun]) and not any(first[n_spun:])  # spinning until too many missed
    now, second = _fly_epoch(w, now, block_s)
    assert not any(second)
    for _ in range(EXPLOIT_EPOCHS):
        now, flown = _fly_epoch(w, now, FAST_S)
        assert set(flown) == {spins}
    now, again = _fly_epoch(w, now, FAST_S)
    assert all(again)  # timed again: the load may have changed


def test_a_flown_epoch_whose_spins_miss_blocks_until_the_next_cycle():
    """A few missed spins are the epoch's time (each costs SPIN_S); more than SPINS_MISSED stop
    spinning until the next cycle times it again."""
    from stationbed.run.socket_law import EPOCH_TICKS, EXPLOIT_EPOCHS, SPINS_MISSED, WaitChoice

    w = WaitChoice()
    now, _ = _fly_epoch(w, 0.0, FAST_S)
    now, _ = _fly_epoch(w, now, SLOW_S)
    now, flown = _fly_epoch(w, now, FAST_S, misses_from=EPOCH_TICKS - SPINS_MISSED)  # as many as tolerated
    assert all(flown)
    half = EPOCH_TICKS // 2
    now, flown = _fly_epoch(w, now, FAST_S, misses_from=half)
    assert all(flown[: half + SPINS_MISSED + 1]) and not any(flown[half + SPINS_MISSED + 1:])
    for _ in range(EXPLOIT_EPOCHS - 2):
        now, flown = _fly_epoch(w, now, FAST_S)
        assert not any(flown)
    now, again = _fly_epoch(w, now, FAST_S)
    assert all(again)
