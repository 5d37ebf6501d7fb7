"""The command line contract (DESIGN §6): columns, exit codes, one-line errors, partial output."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import ROOT, one_error_line
from stationbed import Trajectory, load_scene
from stationbed.cli import main

CONTRACT = ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "HNx", "HNy", "HNz", "T"]


def run_cli(*args, cwd=None):
    """The installed console script, as a user (and CI's other tools) would call it."""
    exe = Path(sys.executable).parent / "stationbed"
    return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, cwd=cwd)


def test_run_writes_contract_csv(tmp_path):
    scene = ROOT / "scenarios" / "power_tower_free_drift.toml"
    res = run_cli("run", scene, "--out", tmp_path, "--duration", 600)
    assert res.returncode == 0, res.stderr
    tr = Trajectory.from_csv(tmp_path / "trajectory.csv")
    assert tr.columns[:12] == CONTRACT
    # after the contract: the arrays' angles, then the gravity-gradient torque (issue 32)
    assert tr.columns[12:] == ["alpha_stbd", "beta_stbd", "alpha_port", "beta_port", "tau_gg_x", "tau_gg_y", "tau_gg_z"]
    assert np.allclose(tr.t, np.arange(0, 601, 10.0))
    s = load_scene(scene)
    assert tr["alpha_stbd"][-1] == pytest.approx(s.appendage[0].alpha.rate * 600.0)


@pytest.mark.parametrize("form", ["momentum27", "dalembert"])
def test_run_options_override_scene(tmp_path, form):
    scene = ROOT / "scenarios" / "torque_window.toml"
    res = run_cli("run", scene, "--out", tmp_path, "--formulation", form, "--integrator", "rk4", "--step", 0.5, "--duration", 100)
    assert res.returncode == 0, res.stderr
    assert f"{form}/rk4" in res.stdout


def test_check_passes_and_prints_numbers(tmp_path):
    res = run_cli("check", ROOT / "scenarios" / "torque_window.toml", "--duration", 1500)
    assert res.returncode == 0, res.stderr
    assert "momentum vs dalembert" in res.stdout and "tolerance" in res.stdout


def _write(tmp_path, text):
    p = tmp_path / "scene.toml"
    p.write_text(text)
    return p


GOOD = """
name = "cli_case"
[simulation]
duration = 100.0
output_dt = 1.0
[body]
mass = 10.0
inertia = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.5]]
"""


@pytest.mark.parametrize(
    "text, words",
    [
        (GOOD.replace("output_dt", "output_dtt"), "simulation.output_dtt: unknown key; did you mean 'output_dt'?"),
        (GOOD.replace("mass = 10.0", "mass = nan"), "body.mass: must be a finite number"),
        (GOOD.replace("2.5]]", "5.0]]"), "triangle inequality"),
        (GOOD.replace("[simulation]", "[simulation"), "malformed TOML"),
        (GOOD.replace("duration = 100.0", "duration = -5.0"), "simulation.duration"),
    ],
    ids=["typo", "nan", "triangle", "malformed", "negative_duration"],
)
def test_bad_input_one_line_nonzero_exit(tmp_path, text, words):
    res = run_cli("run", _write(tmp_path, text), "--out", tmp_path / "o")
    assert res.returncode == 2
    assert words in one_error_line(res.stderr)


def test_missing_file_and_bad_names(tmp_path):
    assert main(["run", str(tmp_path / "missing.toml")]) == 2
    scene = _write(tmp_path, GOOD)
    for args in (["--formulation", "momentom"], ["--integrator", "euler"], ["--rtol", "-1"], ["--duration", "nan"]):
        res = run_cli("run", scene, "--out", tmp_path / "o", *args)
        assert res.returncode == 2, args
        one_error_line(res.stderr)


def test_failed_run_keeps_partial_output(tmp_path):
    """An absurd torque from t = 50 s blows the state up; rows up to the failure stay on disk, under
    the partial name the message gives (a failed run never takes the result's name)."""
    text = GOOD + '\n[[torque]]\nkind = "constant"\ntorque_B = [1e300, 1e300, 0.0]\nstart = 50.0\n'
    res = run_cli("run", _write(tmp_path, text), "--out", tmp_path / "o")
    assert res.returncode == 1
    assert one_error_line(res.stderr).startswith("stationbed: error: run stopped at t = 5")
    assert str(tmp_path / "o" / "trajectory.partial.csv") in res.stderr
    assert not (tmp_path / "o" / "trajectory.csv").exists()
    tr = Trajectory.from_csv(tmp_path / "o" / "trajectory.partial.csv")
    assert tr.t[0] == 0.0 and tr.t[-1] >= 50.0 and tr.t[-1] < 100.0
    assert np.all(np.isfinite(tr.data))
    assert "failed" in (tmp_path / "o" / "summary.json").read_text()
