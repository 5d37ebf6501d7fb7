"""An FMU law's process: refused before the first row, freed in order, cleaned up on every exit
(issue 32).

Truths: the FMI state machine (after a ``fatal`` status no call of the instance is allowed, after
``error`` only ``freeInstance``); the command line's contract (one ``stationbed: error:`` line,
exit 2 for bad input with no output opened, exit 1 for a failed or interrupted run with its
rows kept); and the file system (the FMU's extracted folder, under the process's ``TMPDIR``, is
gone when the process has ended, whatever ended it).

The FMUs are the pd law of tests/test_fmu.py (built with pythonfmu: the FMU's Python runs in the
process's interpreter, so an exception in its ``do_step`` is the FMU's ``fatal`` status).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import pytest

import scenes

pytest.importorskip("fmpy", reason="FMPy is not installed (pip install 'stationbed[fmi]')")
pytest.importorskip("pythonfmu", reason="pythonfmu (builds the test FMUs) is not installed: pip install -e '.[test]'")

from test_fmu import FAIL_AT_S, PERIOD_S, _build, _rewrite, _scene_file  # noqa: E402

from stationbed.run.fmu import FmuController, FmuError  # noqa: E402

EXE = Path(sys.executable).parent / "stationbed"
#: a failing run's subprocess: start-up, compile cache warm, 10 ticks [s]
RUN_TIMEOUT_S = 60.0
#: runs of the Python FMU that raises: before the fix, 8 of 8 (FMI 2) ended in a segmentation fault
RAISING_RUNS = 4
#: a run long enough to be interrupted mid-flight
LONG_DURATION_S = 1.0e6
#: each FMU step sleeps this long [s]: the signal lands inside the FMU's own Python almost always
STEP_WALL_S = 0.01


@pytest.fixture(scope="module")
def fmu2(tmp_path_factory) -> Path:
    return _build(2, tmp_path_factory.mktemp("fmu2"))


def _stationbed(args, tmp: Path, cwd: Path, **kw):
    """``stationbed ARGS`` in a subprocess whose temporary files go under ``tmp``."""
    tmp.mkdir(exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"TMPDIR": str(tmp)}
    return subprocess.Popen([str(EXE), *map(str, args)], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


# ---------------------------------------------------------------------------------------------
# refused before the first row
# ---------------------------------------------------------------------------------------------

def _unloadable(src: Path, dest: Path) -> Path:
    """The FMU with its binary replaced by bytes no loader takes."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            zout.writestr(item, b"not a shared library" if item.filename.startswith("binaries/") and
                          item.filename.endswith(".so") else data)
    return dest


BEFORE_THE_FIRST_ROW = {
    "a_variable_the_fmu_lacks": ({"variables": {"omega_BN_B": "w"}},
                                 "controller.variables.omega_BN_B: FMU 'laws/pd.fmu' has no variables w[0..2]"),
    "a_binary_that_cannot_load": ({"unloadable": True}, "FMU 'laws/pd.fmu': cannot instantiate it"),
}


@pytest.mark.parametrize("case", list(BEFORE_THE_FIRST_ROW), ids=list(BEFORE_THE_FIRST_ROW))
def test_an_fmu_set_up_error_opens_no_output(fmu2, tmp_path, case):
    """``stationbed run``: the FMU's variables are bound, its binary instantiated and initialised
    before the CSV is created: exit 2, one line, no output folder."""
    spec, expected = BEFORE_THE_FIRST_ROW[case]
    fmu = _unloadable(fmu2, tmp_path / "bad.fmu") if spec.get("unloadable") else fmu2
    scene = _scene_file(tmp_path / "case", fmu, params=spec.get("params"), variables=spec.get("variables"))
    proc = _stationbed(["run", scene, "--out", tmp_path / "out"], tmp_path / "tmp", tmp_path)
    _, err = proc.communicate(timeout=RUN_TIMEOUT_S)
    assert proc.returncode == 2, err
    assert expected in scenes.one_error_line(err)
    assert not (tmp_path / "out").exists()
    assert list((tmp_path / "tmp").iterdir()) == []


def _with_member(src: Path, dest: Path, name: str, data: bytes) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            zout.writestr(item, zin.read(item.filename))
        zout.writestr(name, data)
    return dest


def _with_bad_crc(src: Path, dest: Path) -> Path:
    """The FMU with one byte of its binary's stored data flipped (the zip's CRC no longer matches)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            zout.writestr(item, zin.read(item.filename), compress_type=zipfile.ZIP_STORED)
    with zipfile.ZipFile(dest) as z:
        item = next(i for i in z.infolist() if i.filename.startswith("binaries/") and i.file_size > 0)
    raw = bytearray(dest.read_bytes())
    start = item.header_offset + 30 + len(item.filename.encode()) + len(item.extra)  # the local header's size
    raw[start + item.file_size // 2] ^= 0xFF
    dest.write_bytes(bytes(raw))
    return dest


@pytest.mark.parametrize("damage", ["member_name", "crc"])
def test_an_fmu_that_cannot_be_extracted_is_one_line_naming_it(fmu2, tmp_path, monkeypatch, damage):
    """A member FMPy refuses to write (``resources/a:b.txt``) or a CRC error: an FmuError naming
    the FMU (not the zip library's own message alone), and no extracted folder left."""
    bad = (_with_member(fmu2, tmp_path / "bad.fmu", "resources/a:b.txt", b"x") if damage == "member_name"
           else _with_bad_crc(fmu2, tmp_path / "bad.fmu"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))  # this test's extraction folder only
    with pytest.raises(FmuError) as exc:
        FmuController(str(bad))
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"FMU '{bad}': cannot extract it (")
    assert list((tmp_path / "tmp").iterdir()) == []


# ---------------------------------------------------------------------------------------------
# a failure and a signal during the run
# ---------------------------------------------------------------------------------------------

def test_a_python_fmu_that_raises_in_do_step_ends_cleanly_every_time(fmu2, tmp_path):
    """``do_step`` raises: the FMU returns ``fatal``; the instance is then never called again (its
    ``fmi2Terminate`` crashed the process at exit). Each run: exit 1, one line naming the FMU and
    the time, the rows kept, no extracted folder left."""
    scene = _scene_file(tmp_path / "case", fmu2, params={"raise_at": FAIL_AT_S})
    for k in range(RAISING_RUNS):
        proc = _stationbed(["run", scene, "--out", tmp_path / "out", "-q"], tmp_path / "tmp", tmp_path)
        _, err = proc.communicate(timeout=RUN_TIMEOUT_S)
        assert proc.returncode == 1, f"run {k}: rc {proc.returncode}: {err}"
        line = scenes.one_error_line(err)
        assert "run stopped at t = 5 s" in line and "status 4 (fatal)" in line and "gain table lost" in line
        assert (tmp_path / "out" / "trajectory.partial.csv").read_text().count("\n") == 1 + round(FAIL_AT_S / PERIOD_S)
        assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_an_fmu_run_keeps_the_rows_and_removes_the_folder(fmu2, tmp_path, sig):
    """Ctrl-C or SIGTERM mid-run, landing inside the FMU's own Python step (which the FMU reports as
    ``fatal``): exit 1, "interrupted" with the rows kept, the instance never called again (its
    ``terminate`` had crashed the process) and the extracted folder removed (SIGTERM had ended
    the process with the folder left)."""
    scene = _scene_file(tmp_path / "case", fmu2, params={"step_wall_s": STEP_WALL_S})
    text = scene.read_text().replace(f"duration = {30.0}", f"duration = {LONG_DURATION_S}")
    scene.write_text(text)
    partial = tmp_path / "out" / "trajectory.partial.csv"
    # SIGINT as in a terminal (a child of a background job may inherit it ignored)
    proc = _stationbed(["run", scene, "--out", tmp_path / "out", "-q"], tmp_path / "tmp", tmp_path,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + RUN_TIMEOUT_S
        while not (partial.exists() and partial.read_text().count("\n") > 2) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()[1]
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=RUN_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, err
    assert "interrupted" in scenes.one_error_line(err) and "kept in" in err
    assert partial.exists()
    assert list((tmp_path / "tmp").iterdir()) == []
