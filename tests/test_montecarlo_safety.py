"""What the Monte Carlo says and what it writes, under attack (issue 19, items 5-15 and part of 16).

Claims, each a case that misbehaved before:

* statistics only where n supports them: a percentile p needs n >= 1/(1 - p) (one sample
  expected beyond it), by hand: 2, 10, 100, 371 for p50, p90, p99, p99.73; every envelope band
  holds at least the fraction of samples its label says, at every time (checked on drawn data
  by counting, for n = 20, 100 and 1000); a study whose requirements are not shown exits 1,
  ``--exit-zero`` exits 0;
* outputs: the default folder stays inside ``out/`` for montecarlo, linearize and margins; an
  output that is the scene file is refused before anything is written; a failing ``--sample``
  leaves a finished trajectory.csv alone and says where its rows are;
* the study folder: a second study is refused while one holds the lock; chunks are tagged with
  their study, and a resume refuses another study's chunks, a damaged chunk or study.json, and an
  edited controller file (naming it); a fresh start removes only its own kind of files; a resume
  with other workers keeps the recorded chunk size, and the ranges it runs tile the missing
  samples exactly (random cases); work is drawn lazily with a bounded number in flight; an n
  that cannot fit is refused at once;
* stops: a full disk (a write raising ENOSPC) and an unreachable scheduler end in one
  ``stationbed: error:`` line naming the file or address, what is kept and how to resume;
* no stray stderr: no numpy warning from the reports, and a warning that every Dask worker sees
  is said once, with the prefix.
"""

from __future__ import annotations

import errno
import json
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from scenes import ROOT, one_error_line
from stationbed import load_scene, montecarlo
from stationbed.cli import main
from stationbed.scene import SceneError
from stationbed.studies.montecarlo import charts, stats
from stationbed.studies.montecarlo.report import table_text

MC_SCENE = ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml"
STATIONBED = Path(sys.executable).parent / "stationbed"
#: the longest any one command here may take [s] (a bound, never reached when fine)
RUN_TIMEOUT_S = 120


def short_text(n=4, duration=60.0, extra="") -> str:
    """The scenario cut to ``duration`` (10 Hz closed loop), envelopes every 20 s, n samples."""
    text = MC_SCENE.read_text().replace("duration = 5553.6", f"duration = {duration}")
    text = text.replace("settle_s = 1800.0", "settle_s = 20.0").replace("envelope_dt = 30.0", "envelope_dt = 20.0")
    return text.replace("n = 1000", f"n = {n}") + extra


@pytest.fixture
def scene_file(tmp_path):
    p = tmp_path / "scene.toml"
    p.write_text(short_text())
    return p


def _study(scene, out, *more):
    return main(["montecarlo", str(scene), "--serial", "--out", str(out), "--no-charts", "-q", "--exit-zero", *more])


def _cli(*args, cwd=None, env=None, timeout=RUN_TIMEOUT_S):
    return subprocess.run([str(STATIONBED), *map(str, args)], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=timeout)


# -- item 5: statistics the sample count supports -------------------------------------------------
@pytest.mark.parametrize("p, need", [(50.0, 2), (90.0, 10), (99.0, 100), (99.73, 371), (100.0, 1)],
                         ids=["p50", "p90", "p99", "p99.73", "max"])
def test_percentile_needs_one_sample_beyond_it(p, need):
    # by hand: n (1 - p) >= 1 first at need (0.0027 * 371 = 1.0017, 0.0027 * 370 = 0.999)
    assert stats.percentile_needs(p) == need
    if p < 100:
        assert need * (1 - p / 100) >= 1 - 1e-12 > (need - 1) * (1 - p / 100)


def test_percentiles_blank_below_their_sample_count_and_the_table_says_why():
    rng = np.random.default_rng(5)
    df = pd.DataFrame({"index": range(20), "status": "ok", "max_att_err_deg": rng.lognormal(size=20)})
    s = stats.metric_stats(df, ["max_att_err_deg"])["max_att_err_deg"]
    assert s["p99.73"] is None and s["p99"] is None
    assert s["p90"] == np.percentile(df["max_att_err_deg"], 90) and s["p50"] == np.median(df["max_att_err_deg"])
    summary = {"scene": "x", "n": 20, "counts": {"ok": 20, "failed": 0, "refused": 0, "redraws": 0},
               "metrics": {"max_att_err_deg": s}, "requirements": []}
    assert "p99.73 blank: it needs n >= 371" in table_text(summary)
    big = pd.DataFrame({"index": range(371), "status": "ok", "max_att_err_deg": rng.lognormal(size=371)})
    assert stats.metric_stats(big, ["max_att_err_deg"])["max_att_err_deg"]["p99.73"] is not None


@pytest.mark.parametrize("n", [20, 100, 1000])
def test_every_envelope_band_holds_what_its_label_says(n):
    rng = np.random.default_rng(n)
    y = rng.lognormal(sigma=1.0, size=(n, 7))  # n samples at 7 times, a heavy tail
    y[rng.integers(0, n, 3), 2] = np.nan  # failed samples leave NaN behind
    bands = charts.envelope_bands(n)
    for lo, hi, coverage, label in bands:
        low, high = charts.band_limits(y, lo, hi)
        with np.errstate(invalid="ignore"):
            inside = np.nansum((y >= low) & (y <= high), axis=0) / np.sum(~np.isnan(y), axis=0)
        assert np.all(inside >= coverage), (label, inside)
        assert f"{100 * coverage:g} %" in label or f"all {n} samples" in label
    labels = " ".join(b[3] for b in bands)
    assert ("at least 99.73 %" in labels) == (n >= 741)  # each 0.135 % tail needs 741 samples
    assert bands[0][2] >= 0.9973  # the widest band shown holds the worst sample at every time


def test_failed_requirements_exit_1_unless_exit_zero(scene_file, tmp_path, capsys):
    args = ["montecarlo", str(scene_file), "--n", "2", "--serial", "--no-charts", "-q", "--out", str(tmp_path / "o")]
    assert main(args) == 1  # 2 samples cannot show 99.73 % at 90 % confidence
    err = one_error_line(capsys.readouterr().err)
    assert "max_att_err_deg" in err and "--exit-zero" in err
    assert main([*args, "--exit-zero"]) == 0


def test_too_few_samples_with_none_failed_print_not_shown_and_exit_1(scene_file, tmp_path, capsys):
    """Two samples that both meet a loose requirement: no sample failed, yet 2 samples cannot
    show 99.73 % at 90 % confidence (852 needed): NOT SHOWN, never FAIL; still exit 1."""
    loose = scene_file.read_text().replace("max = 3.0", "max = 1.0e9")
    scene_file.write_text(loose.replace("max = 0.9", "max = 1.0e9"))
    args = ["montecarlo", str(scene_file), "--n", "2", "--serial", "--no-charts", "-q", "--out", str(tmp_path / "o")]
    assert main(args) == 1
    out, err = capsys.readouterr()
    lines = [x for x in out.splitlines() if x.startswith("requirement max_att_err_deg")]
    assert len(lines) == 1 and ": NOT SHOWN (0 of 2 fail" in lines[0] and "needs >= 852 samples" in lines[0]
    assert "FAIL" not in out
    assert "not shown, no sample failed (too few samples): max_att_err_deg, max_h_fraction" in one_error_line(err)


# -- item 6: one default output folder ----------------------------------------------------------
@pytest.mark.parametrize("command", [["montecarlo", "--sample", "0"], ["linearize"], ["margins"]],
                         ids=["montecarlo", "linearize", "margins"])
def test_default_output_folder_stays_inside_out(tmp_path, command, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    scene = work / "scene.toml"
    scene.write_text(short_text(duration=10.0).replace('name = "iss_lvlh_hold_montecarlo"', 'name = "../../escaped"'))
    monkeypatch.chdir(work)
    assert main([command[0], str(scene), *command[1:]]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]
    assert sorted(p.name for p in work.iterdir()) == ["out", "scene.toml"]
    assert [p.name for p in (work / "out").iterdir()] == [f"escaped{'_montecarlo' if command[0] == 'montecarlo' else ''}"]


def test_a_sample_never_replaces_its_studys_summary(scene_file, tmp_path, capsys):
    out = tmp_path / "o"
    assert _study(scene_file, out) == 0
    summary = (out / "summary.json").read_bytes()
    assert main(["montecarlo", str(scene_file), "--sample", "1", "--out", str(out), "-q"]) == 2
    assert "holds a Monte Carlo study" in one_error_line(capsys.readouterr().err)
    assert (out / "summary.json").read_bytes() == summary


# -- item 7: outputs checked against inputs ------------------------------------------------------
@pytest.mark.parametrize("how", ["sample_scene", "rrd", "study_summary"])
def test_an_output_that_is_the_scene_file_is_refused(tmp_path, how, capsys):
    out = tmp_path / "o"
    out.mkdir()
    scene = {"sample_scene": out / "sample_0.toml", "rrd": tmp_path / "scene.toml",
             "study_summary": out / "summary.json"}[how]
    scene.write_text(short_text(duration=10.0))
    before = scene.read_bytes()
    extra = {"sample_scene": ["--sample", "0"], "rrd": ["--sample", "0", "--rrd", str(scene)],
             "study_summary": ["--serial"]}[how]
    assert main(["montecarlo", str(scene), "--out", str(out), "-q", *extra]) == 2
    assert str(scene) in one_error_line(capsys.readouterr().err)
    assert scene.read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ([scene.name] if scene.parent == out else [])


# -- item 8: a failing --sample keeps the partial-file contract -----------------------------------
def test_failing_sample_keeps_the_finished_trajectory_and_says_where_its_rows_are(scene_file, tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["montecarlo", str(scene_file), "--sample", "0", "--out", str(out), "-q"]) == 0
    finished = (out / "trajectory.csv").read_bytes()
    capsys.readouterr()
    # an air density 1e300 times the table's: the drag torque overflows the state
    code = main(["montecarlo", str(scene_file), "--sample", "0", "--out", str(out), "-q",
                 "--set", "atmosphere.density_scale=1e300"])
    assert code == 1
    err = one_error_line(capsys.readouterr().err)
    assert str(out / "trajectory.partial.csv") in err and "sample 0" in err
    assert (out / "trajectory.csv").read_bytes() == finished
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"


# -- item 9: lock and tags -----------------------------------------------------------------------
def test_a_second_study_into_a_locked_folder_is_refused(scene_file, tmp_path, capsys):
    import fcntl

    out = tmp_path / "o"
    out.mkdir()
    with open(out / "study.lock", "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a running study holds it
        assert _study(scene_file, out) == 2
        assert "another study is running" in one_error_line(capsys.readouterr().err)
    assert sorted(p.name for p in out.iterdir()) == ["study.lock"]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_a_forked_worker_does_not_keep_the_study_locked(tmp_path):
    """Local workers are forked from the driver (.cluster): a child alive after the driver let
    the lock go must not hold it (flock lives until every copy of the descriptor is closed)."""
    import fcntl
    import signal

    from stationbed.studies.montecarlo.folder import locked

    r, w = os.pipe()
    with locked(tmp_path):
        pid = os.fork()
        if pid == 0:  # the child: says it runs, then outlives the block below, as a stray worker would
            os.write(w, b"1")
            time.sleep(30)
            os._exit(0)
        assert os.read(r, 1) == b"1"
    os.close(r)
    os.close(w)
    try:
        with open(tmp_path / "study.lock", "a+") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)  # raises while the child keeps the lock
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)


def test_resume_refuses_the_chunks_of_another_study(scene_file, tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    other = tmp_path / "other.toml"
    other.write_text(short_text().replace("seed = 2026", "seed = 7"))
    assert _study(other, a, "--chunk", "2") == 0
    assert _study(scene_file, b, "--chunk", "2") == 0
    (b / "chunks" / sorted(os.listdir(b / "chunks"))[0]).unlink()
    for p in (a / "chunks").iterdir():  # two studies that wrote into one folder
        (b / "chunks" / p.name).write_bytes(p.read_bytes())
    capsys.readouterr()
    assert _study(scene_file, b, "--chunk", "2", "--resume") == 2
    assert "another study" in one_error_line(capsys.readouterr().err)


def test_a_chunk_renamed_into_another_study_is_damaged(scene_file, tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    other = tmp_path / "other.toml"
    other.write_text(short_text().replace("seed = 2026", "seed = 7"))
    assert _study(other, a, "--chunk", "2") == 0
    assert _study(scene_file, b, "--chunk", "2") == 0
    mine = sorted((b / "chunks").glob("chunk_*.parquet"))[0]
    theirs = sorted((a / "chunks").glob("chunk_*.parquet"))[0]
    mine.write_bytes(theirs.read_bytes())  # same range, other study's rows, this study's name
    capsys.readouterr()
    assert _study(scene_file, b, "--chunk", "2", "--resume") == 2
    err = one_error_line(capsys.readouterr().err)
    assert str(mine) in err and "damaged" in err and "--resume" in err


# -- item 10: the law's source is part of the study ----------------------------------------------
def _law_scene(tmp_path) -> Path:
    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "hold.py").write_text((ROOT / "controllers" / "example_hold.py").read_text())
    text = short_text().replace('name = "pd"', 'name = "laws/hold.py:ExampleHold"')
    text = text.replace("bandwidth = 0.005           # rad/s\ndamping = 0.8\nmax_slew_rate = 0.001       # rad/s\n",
                        "kp = 4.0e-5\n")
    text = text.replace('key = "controller.params.bandwidth"', 'key = "controller.params.kp"')
    (tmp_path / "scene.toml").write_text(text)
    return tmp_path / "scene.toml"


def test_resume_after_editing_the_controller_file_is_refused_naming_it(tmp_path, capsys):
    scene = _law_scene(tmp_path)
    out = tmp_path / "o"
    assert _study(scene, out, "--n", "2", "--chunk", "1") == 0
    (out / "chunks" / sorted(p.name for p in (out / "chunks").glob("chunk_*"))[1]).unlink()
    law = tmp_path / "laws" / "hold.py"
    law.write_text(law.read_text() + "\n# gains retuned\n")
    capsys.readouterr()
    assert _study(scene, out, "--n", "2", "--chunk", "1", "--resume") == 2
    err = one_error_line(capsys.readouterr().err)
    assert str(law.resolve()) in err and "changed" in err


def test_law_sources_follow_the_files_it_imports_from_its_folder(tmp_path, monkeypatch):
    from stationbed.studies.montecarlo.folder import law_sources

    laws = tmp_path / "laws"
    laws.mkdir()
    (laws / "gains.py").write_text("KP = 4.0e-5\n")
    law = (ROOT / "controllers" / "example_hold.py").read_text()
    (laws / "hold.py").write_text(law.replace("from __future__ import annotations\n",
                                              "from __future__ import annotations\n\nimport gains  # noqa: F401\n"))
    monkeypatch.syspath_prepend(str(laws))
    scene = load_scene(MC_SCENE).replace({"controller.name": f"{laws / 'hold.py'}:ExampleHold",
                                          "controller.params": {"kp": 4.0e-5}, "montecarlo.disperse": []})
    got = law_sources(scene)
    assert set(got) == {str((laws / "hold.py").resolve()), str((laws / "gains.py").resolve())}
    import hashlib

    assert got[str((laws / "gains.py").resolve())] == hashlib.sha256(b"KP = 4.0e-5\n").hexdigest()


# -- item 11: a fresh start removes only its own files -------------------------------------------
def test_a_fresh_study_keeps_a_users_files_in_chunks(scene_file, tmp_path):
    out = tmp_path / "o"
    (out / "chunks").mkdir(parents=True)
    mine = ["notes_v1_final.txt", "chunk_a_b.csv", "envelope_0_1.npy.bak"]
    for name in mine:
        (out / "chunks" / name).write_text("a user's file\n")
    assert _study(scene_file, out, "--chunk", "2") == 0
    assert _study(scene_file, out, "--chunk", "2") == 0  # again, over the first one's chunks
    names = sorted(p.name for p in (out / "chunks").iterdir())
    assert [x for x in names if x in mine] == sorted(mine)
    assert len([x for x in names if x.startswith("chunk_") and x.endswith(".parquet")]) == 2


# -- item 12: an n that cannot fit ----------------------------------------------------------------
def test_a_billion_samples_are_refused_at_once_with_the_reason(scene_file, tmp_path):
    t0 = time.monotonic()
    res = _cli("montecarlo", scene_file, "--n", "1000000000", "--serial", "--out", tmp_path / "o", timeout=60)
    assert res.returncode == 2, res.stderr
    err = one_error_line(res.stderr)
    assert "1000000000" in err and "memory" in err and "samples fit" in err
    assert time.monotonic() - t0 < 60
    assert not (tmp_path / "o").exists()


def test_work_is_generated_lazily_and_bounded_in_flight():
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    from stationbed.studies.montecarlo.engine import in_flight

    consumed, finished, most = [], [], [0]

    def items():
        for k in range(50):
            consumed.append(k)
            yield k

    pending: set = set()
    with ThreadPoolExecutor(3) as pool:
        for fut in in_flight(items(), lambda k: pool.submit(lambda: k), lambda fs: wait(fs, return_when=FIRST_COMPLETED),
                             4, pending):
            most[0] = max(most[0], len(consumed) - len(finished))
            finished.append(fut.result())
    assert sorted(finished) == list(range(50))
    assert most[0] <= 4  # never more than the limit drawn and not yet handed back


# -- item 13: resume with other workers ----------------------------------------------------------
def test_resume_with_other_workers_keeps_the_recorded_chunk(scene_file, tmp_path):
    out = tmp_path / "o"
    assert _study(scene_file, out, "--n", "8") == 0  # serially: chunk ceil(8 / 4) = 2 (3 workers: 1)
    first = pd.read_parquet(out / "samples.parquet")
    recorded = json.loads((out / "study.json").read_text())["chunk"]
    assert recorded == 2
    assert main(["montecarlo", str(scene_file), "--n", "8", "--workers", "3", "--out", str(out), "--no-charts", "-q",
                 "--exit-zero", "--resume"]) == 0  # all done: no cluster is started
    assert json.loads((out / "study.json").read_text())["chunk"] == recorded
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), first)


def test_resume_fills_the_gaps_with_another_chunk_size(scene_file, tmp_path):
    out = tmp_path / "o"
    assert _study(scene_file, out, "--chunk", "2") == 0
    first = pd.read_parquet(out / "samples.parquet")
    sorted((out / "chunks").glob("chunk_*.parquet"))[1].unlink()  # samples 2, 3
    assert _study(scene_file, out, "--chunk", "1", "--resume") == 0
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), first)
    ranges = sorted(tuple(int(x) for x in p.stem.split("_")[2:]) for p in (out / "chunks").glob("chunk_*.parquet"))
    assert ranges == [(0, 2), (2, 3), (3, 4)]


# -- item 14: one line, naming the file or address -----------------------------------------------
@pytest.mark.parametrize("what", ["chunk", "study_json"])
def test_damaged_files_on_resume_are_named_with_how_to_go_on(scene_file, tmp_path, capsys, what):
    out = tmp_path / "o"
    assert _study(scene_file, out, "--chunk", "2") == 0
    first = pd.read_parquet(out / "samples.parquet")
    bad = sorted((out / "chunks").glob("chunk_*.parquet"))[1] if what == "chunk" else out / "study.json"
    bad.write_bytes(bad.read_bytes()[: len(bad.read_bytes()) // 2])  # cut, as a crash or a full disk leaves it
    capsys.readouterr()
    assert _study(scene_file, out, "--chunk", "2", "--resume") == 2
    err = one_error_line(capsys.readouterr().err)
    assert str(bad) in err and "damaged" in err and "kept" in err and "--resume" in err
    bad.unlink()  # as the message says
    assert _study(scene_file, out, "--chunk", "2", "--resume") == 0
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), first)


def test_a_full_disk_mid_study_keeps_the_finished_chunks(scene_file, tmp_path, capsys, monkeypatch):
    import pyarrow.parquet as pq

    out = tmp_path / "o"
    real, calls = pq.write_table, []

    def full_disk(table, where, *a, **k):  # the second chunk finds the disk full
        calls.append(str(where) if isinstance(where, (str, Path)) else str(getattr(where, "path", where)))
        if len(calls) == 2:
            if isinstance(where, (str, Path)):
                Path(where).write_bytes(b"PAR1 half a file")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), calls[-1])
        return real(table, where, *a, **k)

    other = tmp_path / "other.toml"
    other.write_text(short_text(n=1).replace("seed = 2026", "seed = 7"))
    assert _study(other, out) == 0  # a finished study in the folder first: its results must not stay
    capsys.readouterr()
    monkeypatch.setattr(pq, "write_table", full_disk)
    assert _study(scene_file, out, "--chunk", "1") == 1
    err = one_error_line(capsys.readouterr().err)
    assert "No space left on device" in err and str(Path(calls[1]).with_suffix("")) in err
    assert "1 finished chunks" in err and "--resume" in err
    assert sorted(p.suffix for p in (out / "chunks").iterdir()) == [".npy", ".npy", ".parquet"]  # no .tmp left
    assert sorted(p.name for p in out.iterdir()) == ["chunks", "study.json", "study.lock"]  # nothing of the other
    monkeypatch.setattr(pq, "write_table", real)
    assert _study(scene_file, out, "--chunk", "1", "--resume") == 0
    serial = montecarlo(load_scene(scene_file), chunk=4, charts=False).df
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), serial)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: how long the study may wait for a scheduler that is not there [s]
CONNECT_TIMEOUT_S = 1.0


def test_an_unreachable_scheduler_is_one_line_after_the_connect_timeout(scene_file, tmp_path, capsys):
    address = f"tcp://127.0.0.1:{_free_port()}"  # nobody listens
    t0 = time.monotonic()
    code = main(["montecarlo", str(scene_file), "--scheduler", address, "--connect-timeout", str(CONNECT_TIMEOUT_S),
                 "--out", str(tmp_path / "o"), "-q"])
    assert code == 1 and time.monotonic() - t0 < 10 * CONNECT_TIMEOUT_S + 5
    err = one_error_line(capsys.readouterr().err)
    assert address in err and "nothing was run" in err
    assert not (tmp_path / "o").exists()


# -- item 15: no stray stderr ----------------------------------------------------------------------
def test_reports_of_a_study_whose_samples_all_fail_raise_no_numpy_warning(tmp_path, recwarn):
    scene = load_scene(MC_SCENE).replace({"simulation.duration": 60.0, "montecarlo.envelope_dt": 20.0,
                                          "montecarlo.settle_s": 20.0, "atmosphere.density_scale": 1e300})
    res = montecarlo(scene, n=2, out=tmp_path, chunk=2)
    assert (res.df["status"] == "failed").all()
    assert (tmp_path / "envelope_att_err.png").is_file()
    assert [str(w.message) for w in recwarn if issubclass(w.category, RuntimeWarning)] == []


@pytest.fixture
def port_8787_taken():
    """Another process's server on Dask's default HTTP port (a second cluster, a notebook): the
    study's scheduler must not take it, nor warn about it on stderr."""
    import socket  # noqa: PLC0415

    s = socket.socket()
    try:
        s.bind(("127.0.0.1", 8787))
        s.listen()
    except OSError:
        pass  # taken already: the same situation
    yield
    s.close()


def test_a_warning_every_worker_sees_is_said_once_with_the_prefix(tmp_path, port_8787_taken):
    """A law whose reset overflows a float: numpy warns in every process that runs a sample (and
    nothing else is said: the scheduler's HTTP server takes a free port, not a busy 8787)."""
    scene = _law_scene(tmp_path)
    law = tmp_path / "laws" / "hold.py"
    law.write_text(law.read_text().replace("        self.J = np.array(plant.inertia_O_B)\n",
                                           "        self.J = np.array(plant.inertia_O_B)\n"
                                           "        self.big = np.float64(1e308) * 10.0  # overflows: numpy warns\n"))
    scene.write_text(scene.read_text().replace("duration = 60.0", "duration = 10.0"))
    res = _cli("montecarlo", scene, "--n", "2", "--workers", "2", "--chunk", "1", "--out", tmp_path / "o",
               "--no-charts", "-q", "--exit-zero")
    assert res.returncode == 0, res.stderr
    lines = res.stderr.strip().splitlines()
    assert all(ln.startswith("stationbed: warning: ") for ln in lines), res.stderr
    assert len([ln for ln in lines if "overflow" in ln]) == 1, res.stderr


def test_a_workers_warnings_are_held_for_the_driver(capsys):
    import logging
    import warnings

    from stationbed.studies.montecarlo.samples import held_warnings

    with held_warnings() as said:
        logging.getLogger("stationbed").warning("running without compiled code")
        warnings.warn("a law's own warning", UserWarning)
    assert said[0] == "running without compiled code" and said[1].startswith("UserWarning: a law's own warning")
    assert capsys.readouterr().err == ""


# -- item 16 (part): dispersion keys and where the samples run ------------------------------------
@pytest.mark.parametrize(
    "changes, message",
    [({"montecarlo.disperse": [{"key": "controller.name", "kind": "normal", "sigma": 0.1}]},
      r"montecarlo.disperse\[0\].key: 'controller.name' holds str 'pd'; kind 'normal' needs a number"),
     ({"montecarlo.disperse": [{"key": "body.inertya", "kind": "normal", "sigma": 0.1}]},
      "no key 'inertya'; did you mean 'inertia'"),
     ({"montecarlo.disperse": [{"key": "appendage.stbd_pir.mass", "kind": "scale_normal", "sigma": 0.1}]},
      "no entry named 'stbd_pir'; did you mean 'stbd_pair'"),
     ({"montecarlo.disperse": [{"key": "body.mass", "kind": "inertia", "sigma": 0.1}]},
      "kind 'inertia' needs an array of shape \\(3, 3\\)")],
    ids=["normal_on_text", "key_typo", "entry_typo", "inertia_on_a_number"],
)
def test_dispersion_keys_are_checked_against_their_kind(changes, message):
    with pytest.raises(SceneError, match=message):
        montecarlo(load_scene(MC_SCENE).replace(changes), n=1)


@pytest.mark.parametrize("options", [["--scheduler", "tcp://127.0.0.1:1", "--workers", "2"],
                                     ["--serial", "--workers", "2"], ["--serial", "--scheduler", "tcp://127.0.0.1:1"]],
                         ids=["scheduler_and_workers", "serial_and_workers", "serial_and_scheduler"])
def test_two_places_to_run_are_refused(scene_file, tmp_path, capsys, options):
    assert main(["montecarlo", str(scene_file), "--out", str(tmp_path / "o"), *options]) == 2
    assert "choose one" in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


# -- item 14: a scheduler that dies mid-study (real processes, bounded in time) --------------------
#: the longest wait for the scheduler and its worker to come up, and for the study to stop [s]
START_TIMEOUT_S = 60.0


def _wait_port(port: int, proc, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        assert proc.poll() is None, f"the dask scheduler exited with {proc.returncode}"
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise TimeoutError(f"no dask scheduler on port {port} after {timeout} s")


def test_a_scheduler_that_dies_mid_study_is_one_line_and_resume_completes(tmp_path):
    from distributed import Client

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    log = open(tmp_path / "dask.log", "w")
    procs = []
    scene = tmp_path / "scene.toml"
    scene.write_text(short_text(n=8, duration=300.0))
    out = tmp_path / "o"
    try:
        sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--dashboard-address", ":0", "--no-show"],
                                 stdout=log, stderr=subprocess.STDOUT, env=env)
        procs.append(sched)
        _wait_port(port, sched, START_TIMEOUT_S)
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                       "--no-nanny", "--dashboard-address", ":0"],
                                      stdout=log, stderr=subprocess.STDOUT, env=env))
        with Client(address, timeout=f"{START_TIMEOUT_S}s") as c:
            c.wait_for_workers(1, timeout=START_TIMEOUT_S)
        study = subprocess.Popen([str(STATIONBED), "montecarlo", str(scene), "--scheduler", address, "--out", str(out),
                                  "--chunk", "1", "--no-charts", "-q", "--exit-zero"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        procs.append(study)
        end = time.monotonic() + RUN_TIMEOUT_S
        while time.monotonic() < end and study.poll() is None and not any((out / "chunks").glob("chunk_*.parquet")):
            time.sleep(0.05)
        assert study.poll() is None, "the study ended before its scheduler could be stopped"
        sched.kill()
        _, err = study.communicate(timeout=START_TIMEOUT_S)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.kill()
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
        log.close()
    assert study.returncode == 1, err
    line = one_error_line(err)
    assert address in line and "kept" in line and "--resume" in line
    kept = list((out / "chunks").glob("chunk_*.parquet"))
    assert 1 <= len(kept) < 8 and not (out / "samples.parquet").exists()
    assert _study(scene, out, "--resume") == 0  # the rest serially, same numbers
    serial = montecarlo(load_scene(scene), chunk=8, charts=False).df
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), serial)


def test_check_refuses_a_recording_that_is_the_scene_file(tmp_path, capsys):
    """Item 7 for `check`: the output is checked before any formulation runs."""
    scene = tmp_path / "scene.toml"
    scene.write_text((ROOT / "scenarios" / "torque_window.toml").read_text())
    before = scene.read_bytes()
    assert main(["check", str(scene), "--rrd", str(scene)]) == 2
    assert str(scene) in one_error_line(capsys.readouterr().err)
    assert scene.read_bytes() == before


@pytest.mark.parametrize("options, words", [(["--rrd", "x.rrd"], "--rrd applies to --sample"),
                                            (["--sample", "0", "--resume"], "--resume applies to a study"),
                                            (["--sample", "0", "--workers", "2"], "drop --workers")],
                         ids=["rrd_without_sample", "resume_with_sample", "workers_with_sample"])
def test_an_option_the_mode_would_ignore_is_refused(scene_file, tmp_path, capsys, options, words):
    assert main(["montecarlo", str(scene_file), "--out", str(tmp_path / "o"), *options]) == 2
    assert words in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


#: random cases of the tiling check (each a few microseconds)
GAP_CASES = 300


def test_the_gaps_a_resume_runs_are_exactly_the_missing_samples():
    """Items 12-13: the lazily generated ranges and the finished chunks tile 0..n-1 exactly,
    for random n, chunk sizes and finished chunks (of any sizes, as a resume with another
    --chunk leaves them)."""
    from stationbed.studies.montecarlo.engine import _gaps

    rng = np.random.default_rng(13)
    for _ in range(GAP_CASES):
        n, size = int(rng.integers(1, 60)), int(rng.integers(1, 10))
        edges = sorted({0, n, *(int(c) for c in rng.integers(0, n, rng.integers(0, 12)))})
        done = {a: (b, None, None) for a, b in zip(edges, edges[1:]) if rng.random() < 0.5}
        tail_workers = int(rng.integers(0, 4))  # 0: plain chunks; else the guided tail of a default size
        gaps = list(_gaps(n, size, done, tail_workers))
        assert all(0 < b - a <= size for a, b in gaps)
        covered = sorted([*gaps, *((a, v[0]) for a, v in done.items())])
        assert covered[0][0] == 0 and covered[-1][1] == n, (n, size, done, gaps)
        assert all(b == c for (_, b), (c, _) in zip(covered, covered[1:])), (n, size, done, gaps)  # no gap, no overlap


def test_the_guided_tail_shrinks_the_last_chunks_and_ends_the_workers_together():
    """A default-sized study on K workers: chunks non-increasing, full ones first, then none
    longer than the samples left / (TAIL_SPLIT K) nor shorter than size // TAIL_MIN_DIV (bar
    the very last, a remainder): the study ends on a short chunk, not a full one."""
    from stationbed.studies.montecarlo.engine import TAIL_MIN_DIV, TAIL_SPLIT, _gaps

    for n, size, k in ((1000, 50, 2), (1000, 50, 4), (97, 13, 2), (400, 50, 3)):
        lens = [b - a for a, b in _gaps(n, size, {}, k)]
        assert sum(lens) == n
        assert lens == sorted(lens, reverse=True), lens
        left = n
        for i, m in enumerate(lens):
            if i < len(lens) - 1:
                assert m >= max(1, size // TAIL_MIN_DIV), lens
            assert m <= max(max(1, size // TAIL_MIN_DIV), math.ceil(left / (TAIL_SPLIT * k))) or m == size, lens
            left -= m
        assert lens[-1] <= max(1, size // TAIL_MIN_DIV), lens  # the one that ends the study is short
