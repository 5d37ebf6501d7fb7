"""Progress of long commands (stationbed/core/progress.py): a bar on a terminal, rate-limited
``stationbed: `` lines in a log, nothing when quiet; the compile notice and warnings through the
same channel; the studies report through it.

The claims are about what a user reads on stderr, so the tests read the stream: plain mode is
driven by an injected clock (no sleeping), the heartbeat thread by a short real interval.
"""

from __future__ import annotations

import io
import logging
import subprocess
import sys
import time

import casadi as ca
import pytest

from scenes import ROOT
from stationbed.core import compile as compile_mod
from stationbed.core import progress

#: plain mode's defaults the tests check against [s]
DELAY_S = progress.DELAY_S
INTERVAL_S = progress.INTERVAL_S
#: the fake clock's step between updates [s]: finer than the interval, so the limit shows
UPDATE_EVERY_S = 0.5


class FakeClock:
    """A wall clock the test moves by hand."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class FakeTTY(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def _library_default():
    """Every test starts and ends in the library default (quiet, no handler)."""
    progress.reset()
    yield
    progress.reset()


@pytest.fixture
def plain():
    """Plain mode on a buffer with a fake clock and no heartbeat thread: ``(buffer, clock)``."""
    buf, clock = io.StringIO(), FakeClock()
    progress.configure("plain", stream=buf, clock=clock, heartbeat=False)
    return buf, clock


def _run_task(clock, seconds, total=5400.0):
    """A run of ``total`` simulated seconds that takes ``seconds`` of (fake) wall time,
    updating every UPDATE_EVERY_S."""
    steps = int(seconds / UPDATE_EVERY_S)
    with progress.task("run iss_lvlh_hold", total=total, unit="s") as t:
        for k in range(1, steps + 1):
            clock.now += UPDATE_EVERY_S
            t.update(total * k / steps)


def test_short_task_prints_nothing_in_plain_mode(plain):
    buf, clock = plain
    _run_task(clock, 0.9 * DELAY_S)
    assert buf.getvalue() == ""


def test_long_task_prints_prefixed_lines_at_most_every_interval(plain):
    buf, clock = plain
    seconds = 60.0
    _run_task(clock, seconds)
    lines = buf.getvalue().splitlines()
    assert all(line.startswith("stationbed: run iss_lvlh_hold: ") for line in lines), lines
    progress_lines = lines[:-1]
    elapsed = [int(line.rsplit(", ", 1)[1].split()[0]) for line in progress_lines]
    assert elapsed[0] >= DELAY_S
    assert all(b - a >= INTERVAL_S for a, b in zip(elapsed, elapsed[1:])), elapsed
    assert len(progress_lines) == 1 + int((seconds - DELAY_S) // INTERVAL_S)


def test_long_task_ends_with_a_done_line(plain):
    buf, clock = plain
    _run_task(clock, 60.0)
    assert buf.getvalue().splitlines()[-1] == "stationbed: run iss_lvlh_hold: done, 60 s"


def test_plain_line_gives_the_position_in_simulated_time(plain):
    buf, clock = plain
    _run_task(clock, 2 * DELAY_S)
    assert buf.getvalue().splitlines()[0].startswith("stationbed: run iss_lvlh_hold: 2700/5400 s (50 %), 2 s elapsed")


class StampedStream(io.StringIO):
    """A buffer that notes the (fake) wall time of every progress line written to it."""

    def __init__(self, clock):
        super().__init__()
        self.clock, self.times = clock, []

    def write(self, s):
        if "elapsed" in s:
            self.times.append(self.clock.now)
        return super().write(s)


def test_nested_tasks_share_one_rate_limit():
    """A study's task and the runs inside it: still at most one line per interval in all."""
    clock = FakeClock()
    buf = StampedStream(clock)
    progress.configure("plain", stream=buf, clock=clock, heartbeat=False)
    with progress.task("study stability", total=7, unit="cases") as study:
        for case in range(7):
            study.update(case, f"case {case + 1}/7 x")
            _run_task(clock, 10.0)
    gaps = [b - a for a, b in zip(buf.times, buf.times[1:])]
    assert len(buf.times) > 1 and min(gaps) >= INTERVAL_S, buf.times


def test_failed_task_claims_nothing_after_the_error(plain):
    """An exception closes the task without a done line: the CLI's error stays the last line."""
    buf, clock = plain
    with pytest.raises(RuntimeError):
        with progress.task("run x", total=100.0, unit="s") as t:
            clock.now += 3 * INTERVAL_S
            t.update(50.0)
            raise RuntimeError("boom")
    assert buf.getvalue().splitlines() == ["stationbed: run x: 50/100 s (50 %), 15 s elapsed"]


def test_quiet_prints_no_progress_and_no_notice():
    buf = io.StringIO()
    progress.configure("quiet", stream=buf)
    with progress.task("run x", total=10.0, unit="s") as t:
        t.update(5.0)
    logging.getLogger(progress.LOGGER).info("compiling x ...")
    assert buf.getvalue() == ""


def test_quiet_keeps_warnings():
    buf = io.StringIO()
    progress.configure("quiet", stream=buf)
    logging.getLogger(progress.LOGGER).warning("no C compiler found")
    assert buf.getvalue() == "stationbed: warning: no C compiler found\n"


def test_a_warning_of_several_lines_stays_one_prefixed_line():
    buf = io.StringIO()
    progress.configure("plain", stream=buf, heartbeat=False)
    logging.getLogger(progress.LOGGER).warning("cannot load x\n  casadi: assertion failed")
    assert buf.getvalue() == "stationbed: warning: cannot load x | casadi: assertion failed\n"


@pytest.mark.parametrize("stream, expected", [(FakeTTY(), "tty"), (io.StringIO(), "plain")], ids=["terminal", "pipe"])
def test_default_mode_follows_whether_the_stream_is_a_terminal(stream, expected):
    assert progress.configure(stream=stream) == expected


def test_terminal_mode_draws_a_tqdm_bar():
    tty = FakeTTY()
    progress.configure(stream=tty, delay_s=0.0, heartbeat=False)
    with progress.task("run x", total=100.0, unit="s") as t:
        t.update(100.0, "done soon")
        assert isinstance(t.bar, progress.tqdm)
    assert "\r" in tty.getvalue() and "100%|" in tty.getvalue() and "100/100 s" in tty.getvalue()


def test_terminal_bar_waits_for_the_delay():
    tty = FakeTTY()
    progress.configure(stream=tty, heartbeat=False)
    with progress.task("run x", total=100.0, unit="s") as t:
        t.update(100.0)
    assert tty.getvalue() == ""


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="valid: tty, plain, quiet"):
        progress.configure("loud")


def test_heartbeat_speaks_while_the_work_is_silent(monkeypatch):
    """A compile or one long run sends no update: the heartbeat repeats the line."""
    monkeypatch.setattr(progress, "TICK_S", 0.01)
    buf = io.StringIO()
    progress.configure("plain", stream=buf, delay_s=0.05, interval_s=0.1)
    with progress.task("compiling x", transient=True):
        time.sleep(0.6)  # > delay + 2 intervals, with room for a loaded machine
    lines = buf.getvalue().splitlines()
    assert len(lines) >= 3 and lines[0].startswith("stationbed: compiling x: ") and lines[-1].startswith(
        "stationbed: compiling x: done"), lines


def test_heartbeat_speaks_for_an_outer_task_while_short_inner_ones_churn(monkeypatch):
    """A study whose runs each end within the delay: the study's own line is repeated."""
    monkeypatch.setattr(progress, "TICK_S", 0.01)
    buf = io.StringIO()
    progress.configure("plain", stream=buf, delay_s=0.05, interval_s=0.1)
    with progress.task("study stability", total=7, unit="cases"):
        end = time.monotonic() + 0.6
        while time.monotonic() < end:
            with progress.task("run short"):
                time.sleep(0.005)
    lines = buf.getvalue().splitlines()
    assert sum(line.startswith("stationbed: study stability: 0/7 cases") for line in lines) >= 2, lines


def test_close_all_silences_the_heartbeat(monkeypatch):
    monkeypatch.setattr(progress, "TICK_S", 0.01)
    buf = io.StringIO()
    progress.configure("plain", stream=buf, delay_s=0.0, interval_s=0.01)
    progress.task("run x")
    time.sleep(0.05)
    progress.close_all()
    said = buf.getvalue()
    time.sleep(0.1)
    assert buf.getvalue() == said


def test_library_default_prints_nothing():
    """The Python API: no configure(), no progress (notebooks and tests are not spammed)."""
    code = ("from stationbed.core import progress\n"
            "assert progress.mode() == 'quiet'\n"
            "with progress.task('run x', total=10.0, unit='s') as t:\n"
            "    t.update(10.0)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0 and res.stderr == "" and res.stdout == ""


def _tiny_function(name):
    x = ca.SX.sym("x")
    return ca.Function(name, [x], [x * x + 1.0])


def test_compile_notice_reaches_the_user_once_per_build(plain, tmp_path, monkeypatch):
    buf, _ = plain
    monkeypatch.setenv(compile_mod.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(compile_mod.NO_COMPILE_ENV, raising=False)
    if compile_mod.compiler() is None:
        pytest.skip("no C compiler")
    for _ in range(2):  # the second call loads the cached library: no notice
        funcs = compile_mod.compile_functions([_tiny_function("progress_probe")], "progress_probe")
    assert funcs["__evaluator__"] == compile_mod.EVALUATOR_C
    assert buf.getvalue() == "stationbed: compiling progress_probe ...\n"


def test_compile_fallback_warning_is_prefixed(plain, tmp_path, monkeypatch):
    buf, _ = plain
    not_a_folder = tmp_path / "cache_file"
    not_a_folder.write_text("")
    monkeypatch.setenv(compile_mod.CACHE_ENV, str(not_a_folder))
    monkeypatch.delenv(compile_mod.NO_COMPILE_ENV, raising=False)
    if compile_mod.compiler() is None:
        pytest.skip("no C compiler")
    compile_mod.compile_functions([_tiny_function("progress_probe")], "progress_probe")
    assert buf.getvalue().startswith(f"stationbed: warning: {compile_mod.CACHE_ENV}={not_a_folder} is not a folder")


def _cli_plain(*argv):
    """The command line with progress in plain mode and no delay (every update is due), as a
    pipe sees it."""
    code = ("import sys\nfrom stationbed.core import progress\nfrom stationbed.cli import _main, _parser\n"
            "progress.configure('plain', delay_s=0.0, interval_s=0.0)\nsys.exit(_main(_parser().parse_args(sys.argv[1:])))\n")
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=ROOT)


@pytest.mark.slow
def test_stability_study_reports_progress_per_case_and_run(tmp_path):
    res = _cli_plain("study", "stability", "--quick", "--cases", "cmg_singularity", "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    assert any(line.startswith("stationbed: study stability: case 1/1 cmg_singularity: steering ") for line in lines), lines
    assert all(line.startswith("stationbed: ") for line in lines) and "Traceback" not in res.stderr


@pytest.mark.slow
def test_precision_study_reports_progress_per_method(tmp_path):
    res = _cli_plain("study", "precision", ROOT / "scenarios" / "articulated_stress.toml", "--quick", "--duration", "60",
                     "--formulations", "momentum", "--integrators", "rk4", "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    assert any(line.startswith("stationbed: study precision: method 1/1 rk4/momentum step ") for line in lines), lines
    assert all(line.startswith("stationbed: ") for line in lines) and "Traceback" not in res.stderr
