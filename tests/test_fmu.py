"""FMI co-simulation units (FMUs) as the loop's attitude law (issue 23).

The FMUs are built here, from ``tests/fmu_laws/``: pythonfmu (FMI 2) and pythonfmu3 (FMI 3) pack
a Python class with the binary their wheels ship, so no compiler or network is needed. The FMU
runs the shipped ``pd`` law itself (``stationbed.controllers.pd``) on the values the loop wrote
through FMI, and keeps its own clock (a step that does not start where the last one ended fails,
as in the FMI reference FMUs).

Truths:

* the Python ``pd`` law called every tick: flying its FMU must give the same trajectory **bit for
  bit** (FMI passes float64 values unchanged, both run the same Python arithmetic on them, and
  the loop takes the same path for both: any wrong index, sign, unit or a tick of delay would
  show);
* the fused ``pd`` (the same law compiled as casadi C): round-off, the bound of
  tests/test_controller_contract.py;
* an FMI 3 FMU with *array* variables (``tests/fmu_laws/pd_fmi3_arrays.py``): the same again;
* a C FMU (no Python inside, as Simulink and Modelica export them) against the same law in
  Python: bit for bit;
* renaming the FMU's variables (its modelDescription.xml, the binary untouched) and mapping them
  back in ``[controller.variables]`` gives the same trajectory again;
* the FMU's clock check proves the reset between runs (a reused instance not reset starts its
  second run at the first run's end, and its first ``doStep`` fails);
* a Monte Carlo study's table, serial = on 2 Dask workers (exactly: tests/test_montecarlo_dask.py).
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import scenes
from stationbed import montecarlo, simulate
from stationbed.controllers.pd import PD
from stationbed.run.controller import ControllerError
from stationbed.run.laws import build_controller
from stationbed.run.simulation import SimulationError
from stationbed.scene import scene_from_dict

fmpy = pytest.importorskip("fmpy", reason="FMPy is not installed (pip install 'stationbed[fmi]')")
pythonfmu = pytest.importorskip("pythonfmu", reason="pythonfmu (builds the test FMUs) is not installed: pip install -e '.[test]'")

from stationbed.run.fmu import FmuController, FmuError  # noqa: E402
from stationbed.run.fmu_unit import unit_stats  # noqa: E402

LAWS = Path(__file__).parent / "fmu_laws"
PERIOD_S = 0.5  # s
DURATION_S = 30.0  # s: 60 ticks, the 5-deg error halves
PD_PARAMS = {"bandwidth": 0.05, "damping": 0.7}  # rad/s, -
#: the fused pd (casadi C) against the per-tick law: tests/test_controller_contract.py FUSED_RTOL
FUSED_RTOL = 1e-9
VERSIONS = pytest.mark.parametrize("version", [2, 3], ids=["fmi2", "fmi3"])


def _build(version, dest: Path) -> Path:
    """The pd FMU of FMI ``version`` (2, 3, or "3a": FMI 3 with array variables)."""
    if version == 2:
        from pythonfmu import FmuBuilder
    else:
        pythonfmu3 = pytest.importorskip("pythonfmu3", reason="pythonfmu3 (builds the FMI 3 test FMU) is not installed")
        FmuBuilder = pythonfmu3.FmuBuilder
    script = LAWS / ("pd_fmi3_arrays.py" if version == "3a" else f"pd_fmi{version}.py")
    return FmuBuilder.build_FMU(script, dest=dest, project_files=[LAWS / "pd_core.py"])


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    """FMI version -> a function building the pd FMU once (FMI 3 only when a test asks)."""
    folder = tmp_path_factory.mktemp("fmus")
    built = {}

    def get(version) -> Path:
        if version not in built:
            built[version] = _build(version, folder / f"v{version}")
        return built[version]

    return get


def pd_scene(controller: dict, **over) -> dict:
    """A small station in a 400 km orbit, held in LVLH by pd from a 5-deg roll error, no CMG (the
    torque request acts directly)."""
    d = {
        "name": "fmu_pd",
        "simulation": {"duration": DURATION_S, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
        "initial": {"frame": "lvlh", "q_BN": [math.cos(0.5 * math.radians(5.0)), math.sin(0.5 * math.radians(5.0)), 0.0, 0.0],
                    "omega_BN_B": [0.0, 1.0e-4, 0.0]},  # rad/s
        "body": {"mass": 1.0e5, "inertia": [[1.2e6, 5.0e4, -3.0e4], [5.0e4, 0.9e6, 2.0e4], [-3.0e4, 2.0e4, 1.5e6]]},  # kg, kg m²
        "orbit": {"altitude": 400.0e3, "inclination": 0.9},  # m, rad
        "controller": {"period": PERIOD_S, **controller},
    }
    for path, value in over.items():
        node = d
        *head, last = path.split(".")
        for k in head:
            node = node.setdefault(k, {})
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value
    return d


def on(integrator: str) -> dict:
    """Scene changes for ``integrator`` (an adaptive one takes no step)."""
    return {"simulation.integrator": integrator, "simulation.step": PERIOD_S if integrator == "rk4" else None}


def fmu_scene(path, params=None, variables=None, **over):
    c = {"fmu": str(path), "params": {**PD_PARAMS, **(params or {})}}
    if variables:
        c["variables"] = variables
    return scene_from_dict(pd_scene(c, **over))


@pytest.fixture(scope="module")
def python_pd():
    """The Python pd law called every tick (not fused), per integrator."""
    cache = {}

    def get(integrator="rk4"):
        if integrator not in cache:
            s = scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS}, **on(integrator)))
            cache[integrator] = simulate(s, fused=False)
        return cache[integrator]

    return get


# ---------------------------------------------------------------------------------------------
# the same law, through FMI
# ---------------------------------------------------------------------------------------------

@VERSIONS
@pytest.mark.parametrize("integrator", ["rk4", "dop853"], ids=["fused_tick", "generic"])
def test_the_pd_fmu_flies_the_python_pd_bit_for_bit(fmus, python_pd, version, integrator):
    """Every column of every row (attitude, rate, momentum, commanded torque, attitude error
    against the FMU's q_ref_BN output) equals the Python law's: the bound is zero."""
    fmu = simulate(fmu_scene(fmus(version), **on(integrator)))
    ref = python_pd(integrator)
    assert fmu.columns == ref.columns
    np.testing.assert_array_equal(fmu.data, ref.data)
    s = fmu.meta["summary"]
    assert s["fmi_version"] == f"{version}.0" and s["controller_updates"] == round(DURATION_S / PERIOD_S) + 1
    assert np.ptp(ref["tau_cmd_x"]) > 10.0  # N m: the law worked (the roll error was taken out)


def test_a_compiled_c_fmu_flies_its_python_twin_bit_for_bit(tmp_path):
    """An FMU as Simulink or Modelica export one: a C shared library behind the FMI 2 functions, no
    Python inside (tests/fmu_laws/c_rate_damp.py, rate damping on the plant fact ``inertia_O_B``
    the loop sets). The same law in Python, the same operations in the same order (the C built
    without fused multiply-adds): the same trajectory, bit for bit."""
    from fmu_laws import c_rate_damp

    if c_rate_damp.compiler() is None:
        pytest.skip("no C compiler (cc) to build the C FMU")
    path = c_rate_damp.build(tmp_path, platform=fmpy.platform)
    spin = {"initial.omega_BN_B": [0.01, -0.02, 0.005]}  # rad/s
    fmu = simulate(scene_from_dict(pd_scene({"fmu": str(path)}, **spin)))
    ref = simulate(scene_from_dict(pd_scene({"name": "pd"}, **spin)), controller=c_rate_damp.RateDamp(period=PERIOD_S))
    np.testing.assert_array_equal(fmu.data, ref.data)
    assert abs(fmu["wx"][-1]) < 0.5 * abs(fmu["wx"][0])  # the rate was damped


def test_the_fmu_sees_the_sensors_measurement(fmus):
    """With sensor noise and a one-period delay the FMU is given what a Python law is given (the
    corrupted, delayed measurement, the same draws): the same trajectory, bit for bit."""
    sensor = {"attitude_noise": 1.0e-4, "rate_noise": 1.0e-6, "delay": PERIOD_S, "seed": 3}  # rad, rad/s, s
    ref = simulate(scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS, "sensor": sensor})), fused=False)
    fmu = simulate(fmu_scene(fmus(2), **{"controller.sensor": sensor}))
    np.testing.assert_array_equal(fmu.data, ref.data)


def test_the_pd_fmu_matches_the_fused_pd_to_round_off(fmus):
    """The fused pd is the same law compiled as casadi C: it differs from the Python arithmetic
    the FMU runs by round-off only (FUSED_RTOL of each column's largest value)."""
    fused = simulate(scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS})))
    fmu = simulate(fmu_scene(fmus(2)))
    assert fused.meta["summary"]["fused"] and not fmu.meta["summary"]["fused"]
    scale = np.maximum(np.abs(fused.data).max(axis=0), 1e-300)
    rel = np.abs(fmu.data - fused.data) / scale
    assert rel.max() <= FUSED_RTOL


def _rewrite(src: Path, dest: Path, edit_xml=None, keep=lambda name: True) -> Path:
    """A copy of the FMU ``src`` with its modelDescription.xml edited and some files left out."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            if not keep(item.filename):
                continue
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml" and edit_xml is not None:
                data = edit_xml(data.decode()).encode()
            zout.writestr(item, data)
    return dest


def test_renamed_variables_mapped_back_fly_the_same(fmus, python_pd, tmp_path):
    """An FMU with its own names, 1-based as Modelica and MATLAB number them (``q[1..4]``,
    ``torque[1..3]``), and an element named apart (``wx``): ``[controller.variables]`` maps
    whole fields and single elements, and the trajectory is the Python law's again."""

    def rename(xml):
        xml = re.sub(r'name="q_BN\[(\d)\]"', lambda m: f'name="q[{int(m.group(1)) + 1}]"', xml)
        xml = re.sub(r'name="tau_cmd\[(\d)\]"', lambda m: f'name="torque[{int(m.group(1)) + 1}]"', xml)
        return xml.replace('name="omega_BN_B[0]"', 'name="wx"')

    renamed = _rewrite(fmus(2), tmp_path / "renamed.fmu", rename)
    tr = simulate(fmu_scene(renamed, variables={"q_BN": "q", "tau_cmd": "torque", "omega_BN_B[0]": "wx"}))
    np.testing.assert_array_equal(tr.data, python_pd().data)


class PdAsGimbalRates(PD):
    """A plumbing check, not a law: pd's torque and q_ref_BN[0] returned as the rates of the four
    gimbals [rad/s] (the cluster's rate limit clips them)."""

    name = "pd_as_gimbal_rates"
    command = "gimbal_rates"
    symbolic = None  # pd's casadi form returns a torque

    def _reset(self, plant):
        super()._reset(plant)
        self.pd = PD(period=self.period, **self.params.model_dump())  # pd itself, its one (compiled) form
        self.pd.reset(plant)

    def _update(self, t, meas):
        tau = self.pd.update(t, meas)
        self.q_ref_BN = self.pd.q_ref_BN
        return (*tau, self.q_ref_BN[0])


def test_an_fmu_commands_gimbal_rates_when_its_outputs_say_so(fmus):
    """``gimbal_rate_cmd[0..3]`` mapped onto the FMU's outputs makes it a gimbal-rate law of a
    4-SGCMG cluster: the same trajectory, bit for bit, as the Python law returning those values."""
    over = {"cmg": {"kind": "sgcmg_pyramid", "h_rotor": 50.0, "max_gimbal_rate": 0.02}}  # N m s, rad/s
    rates = {f"gimbal_rate_cmd[{i}]": f"tau_cmd[{i}]" for i in range(3)} | {"gimbal_rate_cmd[3]": "q_ref_BN[0]"}
    fmu = simulate(fmu_scene(fmus(2), variables=rates, **over))
    s = scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS}, **over))
    ref = simulate(s, controller=PdAsGimbalRates(period=PERIOD_S, **PD_PARAMS))
    np.testing.assert_array_equal(fmu.data, ref.data)
    assert all(np.ptp(fmu[f"gimbal_{i}"]) > 0.0 for i in range(1, 5))  # rad: every gimbal was driven


def test_a_gimbal_rate_fmu_needs_one_output_per_gimbal(fmus):
    rates = {f"gimbal_rate_cmd[{i}]": f"tau_cmd[{i}]" for i in range(3)}
    with pytest.raises(FmuError, match=r"controller.variables.gimbal_rate_cmd\[3\]: FMU '.*' has no variable 'gimbal_rate_cmd\[3\]'"):
        simulate(fmu_scene(fmus(2), variables=rates, cmg={"kind": "sgcmg_pyramid", "h_rotor": 50.0}))


def test_fmi3_array_variables_fly_the_same(fmus, python_pd):
    """An FMI 3 FMU whose inputs, outputs and parameters are arrays (``q_BN`` of 4, the plant fact
    ``inertia_O_B`` of 9, the command as the array ``torque`` mapped by ``tau_cmd = "torque"``): one
    value reference per array, all values in one call; the Python law's trajectory, bit for bit."""
    tr = simulate(fmu_scene(fmus("3a"), params={"q_ref": [1.0, 0.0, 0.0, 0.0]}, variables={"tau_cmd": "torque"}))
    np.testing.assert_array_equal(tr.data, python_pd().data)


def test_an_array_where_a_scalar_is_mapped_is_refused(fmus):
    with pytest.raises(FmuError, match=r"controller.variables.tau_cmd\[0\]: FMU '.*' variable 'torque' is an array of 3 values, "
                                       r"expected 1: map the whole field to an array"):
        simulate(fmu_scene(fmus("3a"), variables={f"tau_cmd[{i}]": "torque" for i in range(3)}))


def test_a_run_whose_duration_is_not_whole_periods_keeps_the_fmu_clock(fmus):
    """The last tick (at the duration, logged, never flown) continues the FMU's clock: the FMU
    refuses any step that does not start where its last one ended."""
    tr = simulate(fmu_scene(fmus(2), **{"simulation.duration": 10.25}))
    assert tr.t[-1] == 10.25 and np.isfinite(tr["tau_cmd_x"][-1])


# ---------------------------------------------------------------------------------------------
# instances: extracted once, reused with reset
# ---------------------------------------------------------------------------------------------

def test_runs_reuse_one_instance_reset_between_them(fmus):
    """Three runs of the same FMU: one extraction, one instance, the same trajectory each time.
    Without the reset the FMU's clock would be at 30 s when the second run steps from 0: it fails."""
    path = fmus(2)
    first = simulate(fmu_scene(path))
    before = unit_stats()
    runs = [simulate(fmu_scene(path)) for _ in range(2)]
    after = unit_stats()
    assert after == before  # nothing extracted or instantiated again
    for tr in runs:
        np.testing.assert_array_equal(tr.data, first.data)


def test_a_failed_instance_is_replaced(fmus):
    """An instance whose ``doStep`` failed is freed, not reused: the next run gets a new one and
    flies normally."""
    path = fmus(2)
    with pytest.raises(SimulationError):
        simulate(fmu_scene(path, params={"fail_at": 2.0}))
    before = unit_stats()["instantiated"]
    tr = simulate(fmu_scene(path))
    assert unit_stats()["instantiated"] == before + 1
    assert tr.meta["status"] == "ok"


# ---------------------------------------------------------------------------------------------
# failures during the run: one line, the rows kept
# ---------------------------------------------------------------------------------------------

FAIL_AT_S = 5.0  # s


@VERSIONS
def test_a_failing_do_step_stops_the_run_and_keeps_the_rows(fmus, python_pd, version):
    """``doStep`` refused at 5 s: the reason names the FMU, the call, its time and the FMU's own
    message; the rows before 5 s are the successful run's."""
    path = fmus(version)
    with pytest.raises(SimulationError) as exc:
        simulate(fmu_scene(path, params={"fail_at": FAIL_AT_S}))
    e = exc.value
    msg = str(e)
    assert "\n" not in msg and e.t == FAIL_AT_S
    assert f"controller '{path}'" in msg and "doStep(5 s, 0.5 s)" in msg and "gain table exhausted" in msg
    tr, ref = e.trajectory, python_pd()
    assert tr.meta["status"] == "failed" and tr.t[-1] == FAIL_AT_S - PERIOD_S
    np.testing.assert_array_equal(tr.data, ref.data[: len(tr.t)])


def test_an_fmi3_step_that_asks_to_terminate_stops_the_run(fmus, python_pd):
    with pytest.raises(SimulationError) as exc:
        simulate(fmu_scene(fmus(3), params={"terminate_at": FAIL_AT_S}))
    e = exc.value
    assert e.t == FAIL_AT_S and "doStep(5 s, 0.5 s) asked to terminate the simulation" in str(e)
    assert "end of mission at 5.0 s" in str(e)  # the FMU's own last words
    np.testing.assert_array_equal(e.trajectory.data, python_pd().data[: len(e.trajectory.t)])


def test_a_non_finite_output_names_the_variable(fmus):
    with pytest.raises(SimulationError) as exc:
        simulate(fmu_scene(fmus(2), params={"nan_at": 7.0}))
    assert exc.value.t == 7.0
    assert "output 'tau_cmd[1]' is nan after doStep(7 s, 0.5 s)" in str(exc.value)


# ---------------------------------------------------------------------------------------------
# set-up errors: one line naming the FMU and the variable
# ---------------------------------------------------------------------------------------------

SETUP_ERRORS = {
    "mistyped_variable": ({"variables": {"q_BN[0]": "q_BN[O]"}},
                          "controller.variables.q_BN[0]: FMU '{fmu}' has no variable 'q_BN[O]'; nearest: 'q_BN[0]'"),
    "unknown_loop_name": ({"variables": {"q_NB[0]": "q_BN[0]"}},
                          "controller.variables.q_NB[0]: 'q_NB[0]' is not a loop name; nearest: q_BN"),
    "mistyped_parameter": ({"params": {"bandwith": 0.05}},
                           "controller.params.bandwith: FMU '{fmu}' has no parameter 'bandwith'; nearest: 'bandwidth'"),
    "output_as_parameter": ({"params": {"tau_cmd[0]": 1.0}},
                            "controller.params.tau_cmd[0]: FMU '{fmu}' variable 'tau_cmd[0]' is an output, not a parameter"),
    "input_as_command": ({"variables": {"tau_cmd[0]": "q_BN[0]"}},
                         "controller.variables.tau_cmd[0]: FMU '{fmu}' variable 'q_BN[0]' is an input, not an output"),
    "parameter_of_the_wrong_type": ({"params": {"gyro_compensation": 1.0}},
                                    "controller.params.gyro_compensation: FMU '{fmu}' parameter 'gyro_compensation' is Boolean, got 1.0"),
    "input_driven_by_nothing": ({"variables": {"q_BN[0]": "q_BN[1]"}},
                                "FMU '{fmu}' input 'q_BN[0]' is driven by no measurement"),
    "field_not_in_the_fmu": ({"variables": {"omega_BN_B": "w"}},
                             "controller.variables.omega_BN_B: FMU '{fmu}' has no variables w[0..2] or w[1..3]"),
}


@pytest.mark.parametrize("case", list(SETUP_ERRORS), ids=list(SETUP_ERRORS))
def test_setup_errors_name_the_fmu_and_the_variable(fmus, case):
    spec, expected = SETUP_ERRORS[case]
    path = fmus(2)
    with pytest.raises(FmuError) as exc:
        simulate(fmu_scene(path, params=spec.get("params"), variables=spec.get("variables")))
    msg = str(exc.value)
    assert "\n" not in msg
    assert expected.format(fmu=path) in msg


def test_a_model_exchange_only_fmu_is_refused(fmus, tmp_path):
    me = _rewrite(fmus(2), tmp_path / "me.fmu", lambda x: x.replace("<CoSimulation", "<ModelExchange"))
    with pytest.raises(FmuError, match=r"FMU '.*me.fmu' is model exchange only: stationbed flies co-simulation FMUs"):
        FmuController(str(me))


def test_an_fmu_without_a_binary_for_this_platform_is_refused(fmus, tmp_path):
    plat = fmpy.platform  # FMI 2 folder name (linux64 here)
    other = _rewrite(fmus(2), tmp_path / "win.fmu", keep=lambda n: not n.startswith(f"binaries/{plat}/"))
    with pytest.raises(FmuError) as exc:
        FmuController(str(other))
    assert f"has no binary for this platform: binaries/{plat}/PdFmi2" in str(exc.value)
    assert "it has binaries for win64" in str(exc.value)


def test_a_file_that_is_not_an_fmu_is_refused(tmp_path):
    bad = tmp_path / "law.fmu"
    bad.write_text("not a zip")
    with pytest.raises(FmuError, match=r"FMU '.*law.fmu': not a readable FMU"):
        FmuController(str(bad))


def test_a_missing_fmu_names_the_folder_it_was_looked_for_in(tmp_path):
    with pytest.raises(FmuError, match=r"controller.fmu: no FMU .*laws/hold.fmu .*'laws/hold.fmu' is relative to the scene"):
        FmuController("laws/hold.fmu", base_dir=tmp_path)


def test_without_fmpy_the_error_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "fmpy", None)  # import fmpy raises ImportError
    spec = fmu_scene(tmp_path / "law.fmu").controller
    with pytest.raises(ControllerError, match=r"needs FMPy, which is not installed: pip install 'stationbed\[fmi\]'"):
        build_controller(spec)


def test_the_scene_takes_a_law_or_an_fmu_not_both():
    with pytest.raises(ValueError, match=r"controller.fmu: give name = 'pd' or fmu = 'a.fmu', not both"):
        scene_from_dict(pd_scene({"name": "pd", "fmu": "a.fmu"}))


# ---------------------------------------------------------------------------------------------
# the command line and the Monte Carlo
# ---------------------------------------------------------------------------------------------

def _scene_file(folder: Path, fmu: Path, params=None, mc: dict | None = None, variables=None) -> Path:
    """``folder/scene.toml`` flying ``folder/laws/pd.fmu`` (a copy of ``fmu``), named relatively."""
    from stationbed.studies.montecarlo.replay import scene_toml

    (folder / "laws").mkdir(parents=True, exist_ok=True)
    shutil.copy(fmu, folder / "laws" / "pd.fmu")
    d = pd_scene({"fmu": "laws/pd.fmu", "params": {**PD_PARAMS, **(params or {})}, **({"variables": variables} if variables else {})})
    if mc is not None:
        d["montecarlo"] = mc
    path = folder / "scene.toml"
    path.write_text(scene_toml(scene_from_dict(d)))
    return path


def test_stationbed_run_keeps_the_rows_of_a_failing_fmu(fmus, tmp_path):
    """``stationbed run``: a relative ``fmu`` path from the scene's folder; a ``doStep`` failure
    is exit 1, one line on stderr naming the FMU and the time, the CSV up to then on disk."""
    scene = _scene_file(tmp_path / "case", fmus(2), params={"fail_at": FAIL_AT_S})
    exe = Path(sys.executable).parent / "stationbed"
    res = subprocess.run([str(exe), "run", str(scene), "--out", str(tmp_path / "out")], capture_output=True, text=True,
                         cwd=tmp_path, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert res.returncode == 1, res.stderr
    line = scenes.one_error_line(res.stderr)
    assert "run stopped at t = 5 s" in line and "controller 'laws/pd.fmu'" in line and "doStep(5 s, 0.5 s)" in line
    csv = pd.read_csv(next((tmp_path / "out").rglob("*.csv")))
    assert csv["t"].iloc[-1] == FAIL_AT_S - PERIOD_S


MC_TABLE = {
    "n": 4,
    "seed": 7,
    "disperse": [
        {"key": "initial.q_BN", "kind": "attitude_normal", "sigma": 0.02},  # rad
        {"key": "controller.params.bandwidth", "kind": "scale_uniform", "low": -0.2, "high": 0.2},
    ],
}


def test_a_sample_scene_written_elsewhere_still_finds_the_fmu(fmus, tmp_path):
    """``stationbed montecarlo --sample K`` writes the sample's scene to another folder: its
    relative ``fmu`` path becomes absolute, and the written scene flies sample K."""
    from stationbed import load_scene
    from stationbed.studies.montecarlo.replay import write_sample_scene

    scene = load_scene(_scene_file(tmp_path / "mc", fmus(2), mc=MC_TABLE))
    back = write_sample_scene(scene, 1, tmp_path / "elsewhere" / "sample_1.toml")
    assert Path(back.controller.fmu) == (tmp_path / "mc" / "laws" / "pd.fmu").resolve()
    assert simulate(back, duration=2.0).meta["status"] == "ok"


@pytest.mark.slow
def test_a_monte_carlo_of_an_fmu_law_gives_the_serial_table_on_two_workers(fmus, tmp_path):
    """Four samples of 30 s, the FMU's bandwidth dispersed: the serial study extracts the FMU once
    and instantiates it once; the table on 2 Dask workers equals the serial one exactly (the scene
    names the FMU relative to its file; each worker finds it)."""
    from stationbed import load_scene

    scene = load_scene(_scene_file(tmp_path / "mc", fmus(2), mc=MC_TABLE))
    before = unit_stats()
    serial = montecarlo(scene, chunk=1).df
    after = unit_stats()
    # this process: the study's FMU file extracted once, one instance for the warm-up run and
    # the four samples (reset between them)
    assert (after["extracted"] - before["extracted"], after["instantiated"] - before["instantiated"]) == (1, 1)
    assert (serial["status"] == "ok").all(), serial["reason"].tolist()
    assert serial["final_att_err_deg"].nunique() == len(serial)  # the samples differ
    pd.testing.assert_frame_equal(montecarlo(scene, workers=2, chunk=1).df, serial)


@pytest.mark.slow  # two Dask worker processes start (~2 s)
def test_an_fmu_study_writes_the_same_table_bytes_serially_and_on_two_workers(fmus, tmp_path):
    """Issue 32: eight samples with the default chunks (serial: 2 samples a chunk, 2 workers: 1)
    once wrote ``executor`` "batch" serially and "per-tick" on the workers (a sample alone in its
    lockstep group): the same inputs must give the same ``samples.parquet``, byte for byte. An
    FMU law has no vectorised ``update_batch``, so every sample now runs per tick (run/lockstep.py
    ``executor``)."""
    from stationbed import load_scene

    scene = load_scene(_scene_file(tmp_path / "mc", fmus(2), mc={**MC_TABLE, "n": 8}))
    serial = montecarlo(scene, out=tmp_path / "serial", charts=False)
    workers = montecarlo(scene, workers=2, out=tmp_path / "workers", charts=False)
    assert serial.summary["chunk"] != workers.summary["chunk"]  # the case: other chunks
    assert set(serial.df["executor"]) == {"per-tick"}
    table = "samples.parquet"
    assert (tmp_path / "serial" / table).read_bytes() == (tmp_path / "workers" / table).read_bytes()
