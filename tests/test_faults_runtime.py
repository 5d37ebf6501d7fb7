"""Runtime faults (issue 12, items 10-12): rows reach the disk steadily for every integrator (a
killed run keeps all but the last batch), a long run streams with bounded memory, and a full
disk never leaves a torn row and names the file and the last complete time."""

from __future__ import annotations

import copy
import io
import json
import os
import resource
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import stationbed.run.simulation as simulation
from scenes import RIGID, ROOT
from stationbed import INTEGRATORS, load_scene, simulate
from stationbed.output import csv as csv_module
from stationbed.output.csv import CsvSink
from stationbed.run.rows import ROW_BATCH, SinkError, trajectory_columns
from stationbed.run.segments import OutputTimes, output_times
from stationbed.scene import scene_from_dict

#: A rigid body tumbling under a torque window (three smooth segments), small output step: the
#: adaptive steps span many output times, the windows cut inside steps and segments.
TUMBLING = copy.deepcopy(RIGID)
TUMBLING["initial"]["omega_BN_B"] = [0.1, 0.02, -0.05]
TUMBLING["simulation"].update(duration=30.0, output_dt=0.05, rtol=1e-10, atol=1e-12, integrator="rk4", step=0.01)
TUMBLING["torque"] = [{"kind": "constant", "torque_B": [0.5, -0.2, 0.1], "start": 10.0, "stop": 20.0}]

#: Long enough that a run is still going when it is killed, and that its millions of output times
#: are never all in memory at once (the 0.01 s step stays above the scene's 1e-9 x duration floor).
KILL_DURATION_S = 5.0e6
#: Rows on disk before the process is killed: a few batches.
KILL_AFTER_ROWS = 3 * ROW_BATCH
#: Wall-time limit [s] for a run to reach a state (never reached when fine).
WAIT_S = 60.0

#: Rows of the bounded-memory run (one per millisecond for 1500 s), and its peak-memory bound.
#: Measured peaks for these 1.5 million rows: 598 MiB before rows streamed (every row, the
#: segment's states), 382 MiB keeping the rows, 104 MiB with ``keep=False`` (the imports and
#: compiled code take ~100 MiB); one ISS orbit at 1 ms (5.5 million rows of 18 columns, CSV):
#: 4.6 GiB before, 108 MiB.
LONG_RUN_S, LONG_RUN_DT = 1500.0, 1e-3
PEAK_RSS_MIB = 300

#: RLIMIT_FSIZE values [bytes] for the disk-full run: inside the header, and after a few batches.
HEADER_BYTES = len(",".join(trajectory_columns(scene_from_dict(TUMBLING)))) + 1
FILE_LIMITS = {"in_the_header": HEADER_BYTES // 2, "after_some_rows": 20_000}

_RUN = """
from stationbed.scene import scene_from_dict
from stationbed.run.simulation import simulate
from stationbed.run.rows import trajectory_columns
from stationbed.output.csv import CsvSink
scene = scene_from_dict({scene!r})
"""


def _python(code: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, **kw)


def _read_rows(path, ncol, torn_tail_ok=False):
    """The CSV's data rows, checking that every line is whole (ends with a newline and has
    ``ncol`` fields); ``torn_tail_ok``: the text after the last newline is left out (a SIGKILL
    may stop the kernel part-way through writing a batch)."""
    text = open(path).read()
    if torn_tail_ok:
        text = text[: text.rfind("\n") + 1]
    assert text == "" or text.endswith("\n"), f"torn last line: {text[-80:]!r}"
    lines = text.splitlines()[1:]
    assert all(line.count(",") == ncol - 1 for line in lines), "a line with the wrong field count"
    return np.array([[float(v) for v in line.split(",")] for line in lines]).reshape(-1, ncol)


def _csv_rows(path) -> int:
    """Whole data rows in the file so far."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


# -- item 10: rows reach the sink window by window; windows never change the numbers -----------
class BatchSink:
    """Keeps every batch handed over."""

    def __init__(self):
        self.batches = []

    def write(self, rows):
        self.batches.append(np.array(rows))


@pytest.fixture(scope="module")
def tumbling():
    return scene_from_dict(TUMBLING)


def _one_window_per_segment(monkeypatch, scene, integrator):
    """The run as before windows: each smooth segment integrated in one call."""
    with monkeypatch.context() as m:
        m.setattr(simulation, "ROW_BATCH", 10**9)
        m.setattr(simulation, "FLUSH_S", 1e9)
        return simulate(scene, integrator=integrator)


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_open_loop_hands_rows_over_in_bounded_batches(tumbling, integrator):
    """Every batch the sink gets has at most ROW_BATCH rows, whatever the integrator (a segment
    of 200 output times is never one batch)."""
    sink = BatchSink()
    simulate(tumbling, integrator=integrator, sink=sink)
    assert max(len(b) for b in sink.batches) <= ROW_BATCH


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_windows_do_not_change_the_numbers(tumbling, monkeypatch, integrator):
    """The run cut into windows of ROW_BATCH output times equals, bit for bit, each segment in one
    integrator call (the adaptive steps run on across windows, never landing on a window's end;
    the scipy interpolants are read one time at a time)."""
    whole = _one_window_per_segment(monkeypatch, tumbling, integrator)
    windowed = simulate(tumbling, integrator=integrator)
    assert np.array_equal(windowed.data, whole.data)
    assert (windowed.meta["n_rhs"], windowed.meta["n_steps"]) == (whole.meta["n_rhs"], whole.meta["n_steps"])


def test_dop853_c_driver_matches_its_python_loop_across_windows(tumbling, monkeypatch):
    """The no-compiler fallback runs the C driver's windows: the same rows (to rounding of its
    matrix-product interpolant) and the same RHS count."""
    a = simulate(tumbling)
    monkeypatch.setattr(INTEGRATORS["dop853"], "force_python", True)
    b = simulate(tumbling)
    assert a.meta["n_rhs"] == b.meta["n_rhs"]
    np.testing.assert_allclose(a.data, b.data, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("duration, dt", [(16661.0, 10.0), (5553.7, 1e-3), (1.0, 0.1), (0.35, 0.1), (7.0, 3.0)])
def test_output_times_without_the_array_are_the_array(duration, dt):
    clock = OutputTimes(duration, dt)
    ts = output_times(duration, dt)
    assert np.array_equal(clock.times(0, len(clock)), ts)
    probes = np.concatenate([ts[:3], ts[-3:], np.linspace(0.0, duration, 37)])
    assert [clock.first_after(t) for t in probes] == list(np.searchsorted(ts, probes, side="right"))


@pytest.mark.parametrize("integrator", ["rk4", "dop853", "scipy_dop853"])
def test_killed_open_loop_run_keeps_all_rows_but_the_last_batch(tmp_path, integrator):
    """SIGKILL a long open-loop run: rows were on disk while it ran (before, a smooth segment's
    rows came at its end: a killed 100-orbit rk4 run left only the t = 0 row), the file holds
    whole rows t = 0, 1, 2 ..., at least those seen before the kill (but for the tail of a batch
    the kernel was writing when the kill came)."""
    scene = copy.deepcopy(TUMBLING)
    scene.pop("torque")
    scene["simulation"].update(duration=KILL_DURATION_S, output_dt=1.0, integrator=integrator)
    if INTEGRATORS[integrator].adaptive:  # a step is for fixed-step integrators (refused otherwise)
        scene["simulation"].pop("step")
    path = tmp_path / "trajectory.csv"
    code = _RUN.format(scene=scene) + textwrap.dedent(
        f"""
        with open({str(path)!r}, "w", newline="") as fh:
            simulate(scene, sink=CsvSink(fh, trajectory_columns(scene)))
        """
    )
    proc = _python(code, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + WAIT_S
        while _csv_rows(path) < KILL_AFTER_ROWS and proc.poll() is None:
            assert time.monotonic() < deadline, f"{_csv_rows(path)} rows on disk after {WAIT_S} s"
            time.sleep(0.01)
        assert proc.poll() is None, proc.stderr.read().decode()
        n_seen = _csv_rows(path)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rows = _read_rows(path, len(trajectory_columns(scene_from_dict(scene))), torn_tail_ok=True)
    assert len(rows) >= n_seen
    assert np.array_equal(rows[:, 0], np.arange(len(rows)))


# -- item 12: bounded memory, the summary without the rows -------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the peak memory in /proc (Linux)")
def test_long_run_streams_with_bounded_memory():
    """A run of 1.5 million rows handed to a sink with keep=False peaks under PEAK_RSS_MIB (before:
    every row and the segment's states in memory, 598 MiB)."""
    scene = copy.deepcopy(TUMBLING)
    scene.pop("torque")
    scene["simulation"].update(duration=LONG_RUN_S, output_dt=LONG_RUN_DT)
    code = _RUN.format(scene=scene) + textwrap.dedent(
        """
        import json
        class Count:
            n, last = 0, None
            def write(self, rows):
                self.n += len(rows)
                self.last = rows[-1].tolist()
        sink = Count()
        traj = simulate(scene, sink=sink, keep=False)
        # VmHWM: this process's peak (ru_maxrss would include the parent's, inherited at exec)
        with open("/proc/self/status") as fh:
            peak_kib = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
        print(json.dumps({"rss_mib": peak_kib / 1024, "n": sink.n,
                          "n_rows": traj.meta["n_rows"], "kept": traj.data.tolist(), "last": sink.last}))
        """
    )
    out, err = _python(code, stdout=subprocess.PIPE, stderr=subprocess.PIPE).communicate(timeout=300)
    assert out, err.decode()
    res = json.loads(out)
    n = round(LONG_RUN_S / LONG_RUN_DT) + 1
    assert (res["n"], res["n_rows"]) == (n, n)
    assert res["kept"] == [res["last"]]  # the trajectory keeps the last row only
    assert res["rss_mib"] < PEAK_RSS_MIB


@pytest.fixture(scope="module", params=[True, False], ids=["fused", "per_tick"])
def cmg_runs(request):
    """A CMG slew with a reference attitude, kept and not kept (the fused loop and the per-tick one)."""
    scene = load_scene(ROOT / "scenarios" / "eigenaxis_slew.toml")
    kw = dict(duration=60.0, fused=request.param)
    return simulate(scene, **kw), simulate(scene, keep=False, **kw)


def test_closed_loop_summary_needs_no_kept_rows(cmg_runs):
    """The summary (max |h|, min singularity, attitude errors) is reduced as rows are emitted:
    the same whether the rows are kept or not."""
    kept, streamed = cmg_runs
    assert streamed.meta["summary"] == kept.meta["summary"]
    assert {"max_h_Nms", "min_singularity", "final_att_err_deg", "max_att_err_deg"} <= set(kept.meta["summary"])


def test_summary_reductions_are_those_of_the_rows(cmg_runs):
    kept, _ = cmg_runs
    s = kept.meta["summary"]
    h = np.linalg.norm(kept.cols("hx", "hy", "hz"), axis=1)
    err = kept["att_err_deg"]
    assert (s["max_h_Nms"], s["min_singularity"]) == (h.max(), kept["cmg_singularity"].min())
    assert (s["final_att_err_deg"], s["max_att_err_deg"]) == (err[-1], np.nanmax(err))


def test_run_without_kept_rows_returns_its_last_row(cmg_runs):
    kept, streamed = cmg_runs
    assert streamed.meta["n_rows"] == len(kept)
    assert np.array_equal(streamed.data, kept.data[-1:])


# -- item 11: a write that fails leaves whole rows and names the file ---------------------------
def _run_with_file_limit(path, limit):
    """Run TUMBLING into a CsvSink at ``path`` in a process whose files may not grow past
    ``limit`` bytes (SIGXFSZ ignored: the write fails with EFBIG, as on a full disk)."""

    def limit_size():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    code = _RUN.format(scene=TUMBLING) + textwrap.dedent(
        f"""
        try:
            with open({str(path)!r}, "w", newline="") as fh:
                simulate(scene, sink=CsvSink(fh, trajectory_columns(scene)))
        except OSError as e:  # SinkError is one
            print(e)
        """
    )
    out, err = _python(code, stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=limit_size).communicate(
        timeout=120
    )
    return out.decode().strip(), err.decode()


@pytest.mark.parametrize("limit", list(FILE_LIMITS.values()), ids=list(FILE_LIMITS))
def test_full_disk_leaves_whole_rows(tmp_path, limit):
    path = tmp_path / "trajectory.csv"
    _run_with_file_limit(path, limit)
    _read_rows(path, len(trajectory_columns(scene_from_dict(TUMBLING))))


def test_full_disk_error_names_the_file_and_the_last_complete_time(tmp_path):
    path = tmp_path / "trajectory.csv"
    msg, err = _run_with_file_limit(path, FILE_LIMITS["after_some_rows"])
    rows = _read_rows(path, len(trajectory_columns(scene_from_dict(TUMBLING))))
    assert len(rows) > 0, err
    assert msg == f"cannot write {path}: File too large; it holds the rows up to t = {rows[-1, 0]:.10g} s"


def test_full_disk_in_the_header_says_the_file_holds_nothing(tmp_path):
    path = tmp_path / "trajectory.csv"
    msg, err = _run_with_file_limit(path, FILE_LIMITS["in_the_header"])
    assert path.read_bytes() == b""
    assert msg == f"cannot write {path}: File too large; it holds nothing (the header did not fit)", err


def test_interrupt_in_the_middle_of_a_write_leaves_whole_rows(tmp_path, monkeypatch):
    """Ctrl-C after part of a batch reached the file: the part is cut off again."""
    path = tmp_path / "t.csv"
    cols = ["t", "a", "b"]
    sink = CsvSink(path, cols)
    sink.write(np.array([[0.0, 1.0, 2.0]]))
    calls = []

    def write_half_then_interrupt(fd, data):
        calls.append(len(data))
        if len(calls) > 1:
            raise KeyboardInterrupt
        return os.write(fd, bytes(data[: len(data) // 2]))

    monkeypatch.setattr(csv_module.os, "write", write_half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        sink.write(np.array([[1.0, 3.0, 4.0], [2.0, 5.0, 6.0]]))
    monkeypatch.undo()
    sink.close()
    assert np.array_equal(_read_rows(path, 3), [[0.0, 1.0, 2.0]])


def test_sink_error_is_one_line_and_survives_pickling():
    import pickle

    e = SinkError("out/x/trajectory.csv", 12.5, OSError(28, "No space left on device"))
    again = pickle.loads(pickle.dumps(e))
    assert isinstance(again, OSError) and again.errno == 28
    assert str(again) == str(e) == "cannot write out/x/trajectory.csv: No space left on device; it holds the rows up to t = 12.5 s"


def test_csv_lines_are_numpy_savetxt_lines():
    """The sink formats a batch in one operation: the lines np.savetxt writes with CSV_FORMAT."""
    from stationbed.run.trajectory import CSV_FORMAT

    rng = np.random.default_rng(0)
    rows = rng.normal(size=(20, 5)) * 10.0 ** rng.integers(-300, 300, size=(20, 5))
    rows[0, :] = [np.nan, np.inf, -np.inf, -0.0, 5e-324]
    got, want = io.StringIO(), io.StringIO()
    CsvSink(got, list("abcde")).write(rows)
    want.write("a,b,c,d,e\n")
    np.savetxt(want, rows, delimiter=",", fmt=CSV_FORMAT)
    assert got.getvalue() == want.getvalue()
