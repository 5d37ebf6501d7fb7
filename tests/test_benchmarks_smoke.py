"""Every benchmark runs (issue 19, item 20): each script in benchmarks/ in smoke mode (tiny sizes,
one repeat, no target judged) as its own process, exit 0, saying it is a smoke run. A benchmark
that no test runs rots: bench_basilisk's closed loop broke when scenes gained surfaces on arrays
and nothing noticed."""

import argparse
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from stationbed.scene import scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
SCRIPTS = sorted(BENCH.glob("bench_*.py"))
#: a smoke run of the slowest script (bench_montecarlo: three Dask clusters) on a loaded 2-core
#: machine takes ~50 s; anything near this is a benchmark that no longer shrinks in smoke mode [s]
SMOKE_TIMEOUT_S = 240.0


def _module(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_benchmark_script_is_covered():
    assert len(SCRIPTS) >= 10
    for path in SCRIPTS:
        text = path.read_text()  # the option added itself, or by _smoke.parse (which adds it)
        assert "_smoke.add_option(ap)" in text or "_smoke.parse(ap" in text, f"{path.name} has no --smoke option"


@pytest.mark.slow
@pytest.mark.parametrize("script", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_benchmark_runs_in_smoke_mode(script, tmp_path):
    env = dict(os.environ, STATIONBED_BENCH_SMOKE="1")  # the environment switch, as CI may set it
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=SMOKE_TIMEOUT_S)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.startswith("smoke mode"), res.stdout[:500]
    assert "PASS" not in res.stdout and "FAIL" not in res.stdout  # no target judged


@pytest.mark.parametrize("env, argv, smoke", [("", [], False), ("1", [], True), ("0", [], False), ("", ["--smoke"], True)],
                         ids=["off", "env", "env_zero", "flag"])
def test_smoke_switch(monkeypatch, env, argv, smoke):
    sys.path.insert(0, str(BENCH))
    try:
        import _smoke
    finally:
        sys.path.remove(str(BENCH))
    monkeypatch.setenv(_smoke.ENV, env)
    ap = argparse.ArgumentParser()
    _smoke.add_option(ap)
    assert ap.parse_args(argv).smoke is smoke
    assert _smoke.targets_exit(False, True) == 0 and _smoke.targets_exit(False, False) == 1


def test_basilisk_scenes_are_valid_without_basilisk():
    """The stationbed side of bench_basilisk: both scenes load (the hold scene drops the surfaces
    that rode on its arrays, and the torques and sun that went with them)."""
    mod = _module("bench_basilisk")
    hold = scene_from_dict(mod.hold_scene(), "bench_basilisk hold")
    assert hold.appendage == [] and hold.surface == [] and hold.torque == [] and hold.controller is not None
    assert scene_from_dict(mod.open_loop_scene(20.0)).simulation.duration == 20.0
