"""What the command line writes, and where (issue 12, items 1-4 and 16).

Claims, each a case that misbehaved before:

* the recording process is started isolated: a ``numpy.py`` in the working folder never runs;
* the default output folder stays inside ``out/`` whatever the scene's name;
* an output path that is an input or another output is refused before anything is written;
* a bad option never touches a finished result (validated before any output is opened); a run
  that fails leaves its rows under the partial name, beside the finished result it did not
  replace; a finished run removes nothing but its own partial file;
* ``--step`` with an adaptive integrator is refused, never ignored.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import ROOT, one_error_line
from stationbed import simulate
from stationbed.run.trajectory import Trajectory
from stationbed.scene import load_scene

STATIONBED = Path(sys.executable).parent / "stationbed"
#: seconds any one of these small runs may take (a bound, never reached when fine)
RUN_TIMEOUT_S = 120

SMALL = """
name = "{name}"
[simulation]
duration = 10.0
output_dt = 1.0
[body]
mass = 1000.0
inertia = [[100.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.0, 0.0, 250.0]]
[initial]
omega_BN_B = [0.01, 0.02, -0.01]
"""
FAILING = SMALL + """
[[torque]]
kind = "constant"
torque_B = [1e300, 1e300, 0.0]
start = 5.0
"""


def _scene(tmp_path, text=SMALL, name="small", file="scene.toml") -> Path:
    p = tmp_path / file
    p.write_text(text.format(name=name))
    return p


def _cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(STATIONBED), *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          timeout=RUN_TIMEOUT_S)


def _error_line(res) -> str:
    return one_error_line(res.stderr)


def test_recording_process_ignores_modules_in_the_working_folder(tmp_path):
    """Item 1: the child is ``python -I``: a numpy.py beside the user is not imported."""
    marker = tmp_path / "planted_module_ran"
    (tmp_path / "numpy.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\nraise SystemExit(3)\n")
    scene = _scene(tmp_path)
    res = _cli("run", scene, "--out", "o", "--rrd", "o/rec.rrd", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert not marker.exists()
    assert (tmp_path / "o" / "rec.rrd").is_file()


@pytest.mark.parametrize("name", ["../../../escaped", "/tmp/absolute_escape", "a/../../b", ".."],
                         ids=["dotdot", "absolute", "nested", "bare_dotdot"])
def test_default_output_folder_stays_inside_out(tmp_path, name):
    """Item 2: out/<scene name> is cleaned to one folder name under out/."""
    scene = _scene(tmp_path, name=name)
    res = _cli("run", scene, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    written = [p for p in (tmp_path / "out").iterdir()]
    assert len(written) == 1 and (written[0] / "trajectory.csv").is_file()
    assert not Path("/tmp/absolute_escape").exists() or name != "/tmp/absolute_escape"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene.toml"]


@pytest.mark.parametrize("target", ["scene", "csv", "summary", "out"], ids=["scene", "csv", "summary", "folder"])
def test_rrd_that_is_an_input_or_another_output_is_refused(tmp_path, target):
    """Item 3: --rrd naming the scene file, trajectory.csv, summary.json or the output folder:
    exit 2 before anything is written; the scene file is untouched."""
    scene = _scene(tmp_path)
    before = scene.read_bytes()
    out = tmp_path / "o"
    out.mkdir()
    rrd = {"scene": scene, "csv": out / "trajectory.csv", "summary": out / "summary.json", "out": out}[target]
    res = _cli("run", scene, "--out", out, "--rrd", rrd)
    assert res.returncode == 2
    assert str(rrd) in _error_line(res)
    assert scene.read_bytes() == before
    assert list(out.iterdir()) == []


@pytest.fixture
def finished(tmp_path):
    """A folder with a finished run: its CSV and summary bytes."""
    scene = _scene(tmp_path)
    out = tmp_path / "o"
    res = _cli("run", scene, "--out", out)
    assert res.returncode == 0, res.stderr
    return scene, out, (out / "trajectory.csv").read_bytes(), (out / "summary.json").read_bytes()


@pytest.mark.parametrize(
    "option", [["--integrator", "dop835"], ["--formulation", "momentun"], ["--rtol", "2"], ["--step", "0.5"]],
    ids=["integrator_typo", "formulation_typo", "rtol_out_of_range", "step_with_adaptive"],
)
def test_bad_option_leaves_a_finished_result_untouched(finished, option):
    """Item 4: every option is validated before an output is opened: exit 2, the folder as it was."""
    scene, out, csv, summary = finished
    res = _cli("run", scene, "--out", out, *option)
    assert res.returncode == 2, res.stderr
    _error_line(res)
    assert (out / "trajectory.csv").read_bytes() == csv
    assert (out / "summary.json").read_bytes() == summary
    assert sorted(p.name for p in out.iterdir()) == ["summary.json", "trajectory.csv"]


def test_failed_rerun_keeps_the_finished_result_and_names_its_partial_file(finished, tmp_path):
    """Item 4: a run that fails part-way writes trajectory.partial.csv and leaves trajectory.csv."""
    scene, out, csv, _ = finished
    failing = _scene(tmp_path, FAILING, file="failing.toml")
    res = _cli("run", failing, "--out", out)
    assert res.returncode == 1
    assert str(out / "trajectory.partial.csv") in _error_line(res)
    assert (out / "trajectory.csv").read_bytes() == csv
    partial = Trajectory.from_csv(out / "trajectory.partial.csv")
    assert partial.t[0] == 0.0 and 5.0 <= partial.t[-1] < 10.0


def test_finished_run_replaces_an_earlier_partial_file(finished, tmp_path):
    scene, out, _, _ = finished
    _cli("run", _scene(tmp_path, FAILING, file="failing.toml"), "--out", out)
    assert (out / "trajectory.partial.csv").exists()
    res = _cli("run", scene, "--out", out)
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["summary.json", "trajectory.csv"]


def test_step_with_an_adaptive_integrator_is_refused_by_the_api():
    """Item 16: the API refuses what it would ignore."""
    scene = load_scene(ROOT / "scenarios" / "torque_window.toml")
    with pytest.raises(ValueError, match="step = 0.5 s applies to fixed-step integrators; 'dop853' is adaptive"):
        simulate(scene, integrator="dop853", step=0.5)


def test_step_with_a_fixed_step_integrator_is_honoured():
    scene = load_scene(ROOT / "scenarios" / "torque_window.toml")
    tr = simulate(scene, integrator="rk4", step=0.5, duration=10.0)
    assert tr.meta["n_steps"] == 20
    assert np.all(np.isfinite(tr.data))


# -- item 19: scene values from the command line ------------------------------------------------


def test_set_changes_a_scene_value_validated_like_the_file(tmp_path):
    """--set KEY.PATH=VALUE (TOML value) and --output-dt change the run; the rows show it."""
    scene = _scene(tmp_path)
    res = _cli("run", scene, "--out", tmp_path / "o", "--set", "simulation.duration=4.0", "--output-dt", "0.5",
               "--set", "initial.omega_BN_B=[0.0, 0.0, 0.03]")
    assert res.returncode == 0, res.stderr
    tr = Trajectory.from_csv(tmp_path / "o" / "trajectory.csv")
    np.testing.assert_array_equal(tr.t, np.arange(0.0, 4.01, 0.5))
    np.testing.assert_allclose(tr["wz"], 0.03, rtol=1e-12)  # a torque-free spin about a principal axis


@pytest.mark.parametrize(
    "option, words",
    [(["--rtol", "2"], "simulation.rtol"), (["--set", "body.mass=true"], "body.mass"),
     (["--set", "simulation.rtoll=1e-9"], "did you mean 'rtol'"), (["--set", "body.mass"], "--set"),
     (["--output-dt", "-1"], "simulation.output_dt")],
    ids=["rtol_2", "bool_mass", "typo", "no_value", "negative_output_dt"],
)
def test_command_line_values_are_refused_like_the_file(tmp_path, option, words):
    scene = _scene(tmp_path)
    res = _cli("run", scene, "--out", tmp_path / "o", *option)
    assert res.returncode == 2
    assert words in _error_line(res)
    assert not (tmp_path / "o").exists()


def test_recording_draws_the_scene_with_the_set_values(tmp_path):
    """The recording child applies the same --set values (its own scene must match the run's)."""
    scene = _scene(tmp_path)
    res = _cli("run", scene, "--out", tmp_path / "o", "--rrd", tmp_path / "o" / "r.rrd",
               "--set", 'name="renamed"', "--set", "simulation.duration=3.0")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "o" / "r.rrd").is_file()
