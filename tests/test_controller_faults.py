"""A controller that misbehaves or cannot be found (issue 3; issue 12 items 13, 14, 16, 17).

One contract for every way a user's law goes wrong during a run: it raises, returns a command
that is not ``n`` finite real numbers (the wrong length, a (3, 1) array, strings, None, a dict,
a generator, NaN...), or sets a ``q_ref_BN`` that is not a quaternion. The run stops with a
:class:`SimulationError` whose one-line reason names the controller, what went wrong and the
time; the rows before it are kept (and on disk with ``stationbed run``, exit 1, with a
``summary.json``); an exception the law raised is the error's ``__cause__``, its traceback
intact. The same on both per-tick paths of the loop: the *fused tick* (RK4 at one step per
period, the command written straight into a compiled buffer) and the *generic path* (DOP853).

A controller that cannot be built is a one-line :class:`ControllerError` (``stationbed run``
exit 2): unknown name or parameter, a module that cannot be imported, and for a controller
*file* (``controller.name = "laws/x.py:X"``, relative to the scene file): missing, a syntax
error, raising at load, no such class, not a Controller subclass.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest

import scenes
from numpy.testing import assert_allclose

from test_control_loop import J_SPHERE, W0, ZOH_TOL_RAD_S, Recorder, loop_scene
from stationbed import Trajectory, load_scene, simulate
from stationbed.run.controller import Controller, ControllerError, command_values, get_controller
from stationbed.run.simulation import SimulationError
from stationbed.scene import scene_from_dict

INTEGRATORS = pytest.mark.parametrize("integrator", ["rk4", "dop853"], ids=["fused_tick", "generic"])


def run_cli(*args, env_path=None, cwd=None):
    """``stationbed ARGS`` in a fresh process, PYTHONPATH set to ``env_path`` (or unset)."""
    exe = Path(sys.executable).parent / "stationbed"
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # only what a test adds
    if env_path is not None:
        env["PYTHONPATH"] = str(env_path)
    return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd)


def one_error_line(res) -> str:
    """The CLI's one-line error (tests/scenes.py), from a finished process."""
    return scenes.one_error_line(res.stderr)


# ---------------------------------------------------------------------------------------
# a controller that raises
# ---------------------------------------------------------------------------------------

FAIL_AT_S = 5.0  # s


class Raising(Controller):
    """Raises from ``FAIL_AT_S`` on (a bug in a user's law)."""

    name = "raising"

    def _update(self, t, meas):
        if t >= FAIL_AT_S:
            raise ZeroDivisionError("gain schedule hit an empty table")
        return (0.0, 0.0, 1.0e-3)


@INTEGRATORS
def test_raising_controller_stops_the_run_and_keeps_the_trajectory(integrator):
    """SimulationError names the controller, the exception and the time; the trajectory keeps
    every output row before that time."""
    d = loop_scene(**{"simulation.output_dt": 1.0})
    with pytest.raises(SimulationError) as exc:
        simulate(scene_from_dict(d), controller=Raising(), integrator=integrator)
    e = exc.value
    msg = str(e)
    assert "'raising'" in msg and "ZeroDivisionError" in msg and "empty table" in msg
    assert "t = 5 s" in msg and e.t == FAIL_AT_S
    tr = e.trajectory
    assert np.array_equal(tr.t, np.arange(0.0, FAIL_AT_S))  # rows at 0..4 s
    assert tr.meta["status"] == "failed" and tr.meta["stopped_at"] == FAIL_AT_S
    # and they are the right rows: ω grows by the held 1e-3 N m about z
    assert_allclose(tr["wz"], W0[2] + 1e-3 * tr.t / J_SPHERE, rtol=0, atol=ZOH_TOL_RAD_S)


@INTEGRATORS
def test_the_controller_exception_is_the_cause_with_its_traceback(integrator):
    """The law's own exception is the SimulationError's ``__cause__``, and its traceback reaches
    the law's ``_update`` (what ``STATIONBED_DEBUG=1`` prints, and what a debugger opens)."""
    with pytest.raises(SimulationError) as exc:
        simulate(scene_from_dict(loop_scene()), controller=Raising(), integrator=integrator)
    cause = exc.value.__cause__
    assert isinstance(cause, ZeroDivisionError)
    frames = traceback.extract_tb(cause.__traceback__)
    assert (frames[-1].filename, frames[-1].name) == (__file__, "_update")


def test_a_multiline_exception_message_is_one_line():
    """The reason stays one line whatever the user's exception says."""

    class Verbose(Raising):
        def _update(self, t, meas):
            raise RuntimeError("solver failed\nsee the log for details")

    with pytest.raises(SimulationError) as exc:
        simulate(scene_from_dict(loop_scene()), controller=Verbose())
    assert "\n" not in str(exc.value) and "solver failed | see the log" in str(exc.value)


class RaisingReset(Controller):
    name = "raising_reset"

    def _reset(self, plant):
        raise ZeroDivisionError("no inertia table")

    def _update(self, t, meas):  # pragma: no cover - never reached
        return (0.0, 0.0, 0.0)


def test_a_bug_in_reset_names_the_controller():
    """An exception in ``_reset`` (other than the law's own ValueError refusals): a ControllerError
    naming the controller, the original chained."""
    with pytest.raises(ControllerError, match=r"controller 'raising_reset' raised ZeroDivisionError in reset") as exc:
        simulate(scene_from_dict(loop_scene()), controller=RaisingReset())
    assert isinstance(exc.value.__cause__, ZeroDivisionError)


class BrokenSymbolic(Controller):
    """A Python law whose casadi form (the fused loop's) is broken."""

    name = "broken_symbolic"

    def _update(self, t, meas):
        return (0.0, 0.0, 0.0)

    def symbolic_params(self):
        return [1.0]

    def symbolic(self, t, y, cp):
        raise KeyError("omega")


def test_a_broken_symbolic_form_names_the_controller():
    with pytest.raises(ControllerError, match=r"controller 'broken_symbolic': symbolic\(\) raised KeyError"):
        simulate(scene_from_dict(loop_scene()), controller=BrokenSymbolic(), fused=True)


# ---------------------------------------------------------------------------------------
# a controller that returns a bad command
# ---------------------------------------------------------------------------------------

BAD_AT_S = 1.0  # s


class BadCommand(Controller):
    """Returns zeros until ``BAD_AT_S``, then ``BadCommand.bad()``."""

    name = "bad_command"
    n_cmd = 3
    bad = staticmethod(lambda: None)

    def _update(self, t, meas):
        if t < BAD_AT_S:
            return (0.0,) * self.n_cmd
        return self.bad()


class BadRates(BadCommand):
    name = "bad_rates"
    command = "gimbal_rates"


NAN = float("nan")
#: id -> (a function making the bad command afresh, words the reason must hold)
BAD = {
    "nan": (lambda: (0.0, 0.0, NAN), "non-finite values [0.0, 0.0, nan]"),
    "inf": (lambda: (math.inf, 0.0, 0.0), "non-finite values"),
    "nan_array": (lambda: np.array([0.0, NAN, 0.0]), "non-finite values"),
    "too_few": (lambda: (1.0, 2.0), "returned 2 values, expected 3"),
    "too_many": (lambda: [1.0, 2.0, 3.0, 4.0], "returned 4 values, expected 3"),
    "column_3x1": (lambda: np.zeros((3, 1)), "shape (3, 1), expected shape (3,)"),
    "row_1x3": (lambda: np.zeros((1, 3)), "shape (1, 3), expected shape (3,)"),
    "string": (lambda: "abc", "returned 'abc' (str), not a sequence"),
    "numeric_string": (lambda: "123", "returned '123' (str), not a sequence"),
    "strings": (lambda: ("1.0", "2.0", "3.0"), "element 0 is '1.0' (str), not a real number"),
    "string_array": (lambda: np.array(["1", "2", "3"]), "dtype <U1"),
    "none": (lambda: None, "returned None, not a sequence"),
    "dict": (lambda: {"x": 0.0, "y": 0.0, "z": 0.0}, "(dict), not a sequence"),
    "object_array": (lambda: np.array([0.0, None, 0.0], dtype=object), "element 1 is None, not a real number"),
    "generator": (lambda: (v for v in (0.0, 0.0, 0.0)), "(generator), not a sequence"),
    "number": (lambda: 1.0, "returned 1.0 (float), not a sequence"),
    "set": (lambda: {0.0, 1.0, 2.0}, "(set), not a sequence"),
    "complex": (lambda: (1j, 0.0, 0.0), "element 0 is 1j (complex), not a real number"),
}
CMG = {"none": None, "pyramid": {"kind": "sgcmg_pyramid", "h_rotor": 10.0}, "ideal": {"kind": "ideal"}}


def _bad_cases():
    for integ in ("rk4", "dop853"):
        for cmg in CMG:
            for bad in BAD:
                yield pytest.param(integ, cmg, bad, id=f"{integ}-{cmg}-{bad}")


def bad_run(bad, integrator="rk4", cmg="none") -> SimulationError:
    """The SimulationError of a run whose controller returns ``BAD[bad]`` from 1 s on."""
    d = loop_scene(**{"simulation.duration": 3.0, "simulation.output_dt": 0.5})
    if CMG[cmg] is not None:
        d["cmg"] = CMG[cmg]
    ctrl = BadCommand()
    ctrl.bad = BAD[bad][0]
    with pytest.raises(SimulationError) as exc:
        simulate(scene_from_dict(d), controller=ctrl, integrator=integrator)
    return exc.value


@pytest.mark.parametrize("integrator, cmg, bad", list(_bad_cases()))
def test_bad_command_is_a_clear_error(integrator, cmg, bad):
    """A SimulationError at the tick that returned it, its one-line reason naming the controller,
    what came back and what was expected."""
    e = bad_run(bad, integrator, cmg)
    msg = str(e)
    assert "'bad_command'" in msg and BAD[bad][1] in msg and "t = 1 s" in msg and e.t == BAD_AT_S, msg
    assert "\n" not in msg


@pytest.mark.parametrize("integrator", ["rk4", "dop853"])
@pytest.mark.parametrize("bad", ["column_3x1", "string", "nan"])
def test_bad_command_keeps_the_rows_before_it(integrator, bad):
    """The rows before the bad tick are kept, finite, with the run's summary (the per-tick fused
    tick also keeps the row of the bad tick itself: its state is still the good one)."""
    tr = bad_run(bad, integrator).trajectory
    assert np.array_equal(tr.t[:2], [0.0, 0.5]) and tr.t[-1] <= BAD_AT_S
    assert np.all(np.isfinite(tr.data[:, :12]))
    assert tr.meta["status"] == "failed" and tr.meta["stopped_at"] == BAD_AT_S
    assert tr.meta["summary"]["controller"] == "bad_command"


@INTEGRATORS
def test_wrong_number_of_gimbal_rates(integrator):
    """A gimbal-rate law must return one rate per gimbal (4 for the pyramid)."""
    d = loop_scene(**{"simulation.duration": 3.0, "simulation.output_dt": 0.5})
    d["cmg"] = CMG["pyramid"]
    ctrl = BadRates()
    ctrl.n_cmd = 4
    ctrl.bad = lambda: (0.01, 0.0, -0.01)
    with pytest.raises(SimulationError, match=r"returned 3 values, expected 4 real numbers \(gimbal_rates\)"):
        simulate(scene_from_dict(d), controller=ctrl, integrator=integrator)


#: A command exactly representable in float32 [N m] (so every accepted form holds the same numbers).
TAU_EXACT = (2.0**-10, -(2.0**-11), 2.0**-12)
#: id -> the accepted forms of TAU_EXACT
GOOD = {
    "list": lambda: list(TAU_EXACT),
    "float64_array": lambda: np.array(TAU_EXACT),
    "float32_array": lambda: np.array(TAU_EXACT, dtype=np.float32),
    "object_array": lambda: np.array(TAU_EXACT, dtype=object),
    "numpy_scalars": lambda: tuple(np.float32(v) for v in TAU_EXACT),
}


class Constant(Controller):
    """Returns ``Constant.form()`` every tick."""

    name = "constant"
    form = staticmethod(lambda: TAU_EXACT)

    def _update(self, t, meas):
        return self.form()


@INTEGRATORS
@pytest.mark.parametrize("form", list(GOOD))
def test_accepted_command_forms_fly_the_same_trajectory(integrator, form):
    """A list, a 1-D float64/float32/object array or numpy scalars: the same trajectory, bit for
    bit, as the tuple of floats (the checks refuse nothing a law may return)."""
    scene = scene_from_dict(loop_scene(**{"simulation.duration": 3.0}))
    ref = simulate(scene, controller=Constant(), integrator=integrator)
    ctrl = Constant()
    ctrl.form = GOOD[form]
    tr = simulate(scene, controller=ctrl, integrator=integrator)
    assert np.array_equal(tr.data, ref.data, equal_nan=True)


@pytest.mark.parametrize("bad", list(BAD))
def test_command_values_refuses_what_the_loop_refuses(bad):
    """The one definition of a valid command (what the loop calls): ValueError with the words."""
    with pytest.raises(ValueError) as exc:
        command_values(BAD[bad][0](), 3, "torque")
    assert BAD[bad][1].removeprefix("returned ") in str(exc.value)


class BadReference(Controller):
    """A good command; from ``BAD_AT_S`` on, ``q_ref_BN = BadReference.q_ref()``."""

    name = "bad_reference"
    q_ref = staticmethod(lambda: None)

    def _update(self, t, meas):
        self.q_ref_BN = (1.0, 0.0, 0.0, 0.0) if t < BAD_AT_S else self.q_ref()
        return (0.0, 0.0, 0.0)


BAD_Q_REF = {
    "string": (lambda: "identity", "'identity' (str), not a sequence"),
    "three_values": (lambda: (1.0, 0.0, 0.0), "3 values, expected 4"),
    "column_4x1": (lambda: np.array([[1.0], [0.0], [0.0], [0.0]]), "shape (4, 1), expected shape (4,)"),
}


@INTEGRATORS
@pytest.mark.parametrize("bad", list(BAD_Q_REF))
def test_bad_reference_attitude_is_a_clear_error(integrator, bad):
    """``q_ref_BN`` (logged as ``att_err_deg``) that is not 4 numbers: the same contract as a bad
    command, naming the attribute."""
    ctrl = BadReference()
    ctrl.q_ref = BAD_Q_REF[bad][0]
    with pytest.raises(SimulationError) as exc:
        simulate(scene_from_dict(loop_scene(**{"simulation.duration": 3.0})), controller=ctrl, integrator=integrator)
    msg = str(exc.value)
    assert "controller 'bad_reference' set q_ref_BN to" in msg and BAD_Q_REF[bad][1] in msg, msg
    assert exc.value.t == BAD_AT_S


# ---------------------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------------------

CLI_SCENE = """
name = "cli_loop"
[simulation]
duration = 20.0
integrator = "rk4"
step = 0.1
output_dt = 1.0
[body]
mass = 100.0
inertia = [[500.0, 0.0, 0.0], [0.0, 500.0, 0.0], [0.0, 0.0, 500.0]]
[controller]
name = "{name}"
period = 0.1
{params}
"""

USER_MODULE = """
import numpy as np
from stationbed.run.controller import Controller

class Boom(Controller):
    name = "boom"

    def _update(self, t, meas):
        if t >= 5.0:
            raise RuntimeError({message!r})
        return (0.0, 0.0, 0.0)

class Column(Controller):
    name = "column"

    def _update(self, t, meas):
        return np.zeros((3, 1)) if t >= 5.0 else np.zeros(3)
"""


def _cli_case(tmp_path, name, params="", message="sensor bus timeout"):
    (tmp_path / "user_laws.py").write_text(USER_MODULE.format(message=message))
    scene = tmp_path / "scene.toml"
    scene.write_text(CLI_SCENE.format(name=name, params=params))
    return run_cli("run", scene, "--out", tmp_path / "out", env_path=tmp_path)


@pytest.mark.parametrize(
    "name, words",
    [("user_laws:Boom", "'boom' raised RuntimeError: sensor bus timeout"),
     ("user_laws:Column", "'column' returned a numpy array of shape (3, 1)")],
    ids=["raises", "returns_3x1"],
)
def test_cli_misbehaving_controller_is_a_failed_run(tmp_path, name, words):
    """`stationbed run` with a user's law that raises or returns a (3, 1) array: exit 1 (a failed
    run, not bad input), one line naming the controller, what went wrong and the time, the rows
    up to then on disk and a summary.json saying so."""
    res = _cli_case(tmp_path, name)
    assert res.returncode == 1, res.stderr
    line = one_error_line(res)
    assert words in line and "t = 5 s" in line, line
    tr = Trajectory.from_csv(tmp_path / "out" / "trajectory.partial.csv")  # a failed run keeps the partial name
    assert np.array_equal(tr.t, np.arange(0.0, 5.0))
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["stopped_at"] == 5.0


def test_cli_raising_controller_multiline_message_is_one_line(tmp_path):
    """The one-line contract holds whatever the user's exception says."""
    res = _cli_case(tmp_path, "user_laws:Boom", message="solver failed\nsee the log for details")
    assert res.returncode == 1
    one_error_line(res)


# ---------------------------------------------------------------------------------------
# simulate(controller=...)
# ---------------------------------------------------------------------------------------


def test_controller_argument_needs_a_controller_table():
    """A controller object for a scene without ``[controller]`` is refused (it would run open
    loop): the table gives the period and the sensor."""
    d = loop_scene()
    del d["controller"]
    with pytest.raises(ValueError, match=r"scene 'loop' has no \[controller\] table"):
        simulate(scene_from_dict(d), controller=Recorder())


def test_controller_argument_must_be_an_instance():
    with pytest.raises(TypeError, match=r"takes a Controller instance, got the class Recorder: pass Recorder\(\.\.\.\)"):
        simulate(scene_from_dict(loop_scene()), controller=Recorder)


# ---------------------------------------------------------------------------------------
# bad names and parameters
# ---------------------------------------------------------------------------------------


def test_unknown_controller_name_lists_the_valid_ones():
    with pytest.raises(ControllerError, match=r"unknown controller 'no_such_law'; valid: .*\bpd\b"):
        simulate(scene_from_dict(loop_scene(**{"controller.name": "no_such_law"})))


def test_unknown_parameter_is_named():
    d = loop_scene(**{"controller.name": "pd", "controller.params": {"reference": "inertial", "bandwith": 0.1}})
    with pytest.raises(ControllerError, match=r"controller 'pd': unknown parameter 'bandwith'; valid: .*bandwidth"):
        simulate(scene_from_dict(d))


def test_bad_parameter_value_is_named():
    d = loop_scene(**{"controller.name": "pd", "controller.params": {"reference": "inertial", "damping": -1.0}})
    with pytest.raises(ControllerError, match=r"controller 'pd': params\.damping"):
        simulate(scene_from_dict(d))


@pytest.mark.parametrize(
    "name, params, words",
    [
        ("no_such_law", "", "unknown controller 'no_such_law'"),
        ("pd", "[controller.params]\nreference = \"inertial\"\nbandwith = 0.1", "unknown parameter 'bandwith'"),
        ("no_such_module:Law", "", "cannot import module 'no_such_module'"),
        ("user_laws:NoSuchClass", "", "no class 'NoSuchClass' in 'user_laws'"),
    ],
    ids=["name", "parameter", "module", "class"],
)
def test_cli_bad_controller_is_exit_2_one_line(tmp_path, name, params, words):
    res = _cli_case(tmp_path, name, params)
    assert res.returncode == 2, res.stderr
    assert words in one_error_line(res), res.stderr


# ---------------------------------------------------------------------------------------
# a controller file next to the scene
# ---------------------------------------------------------------------------------------

#: The held torque of the file's law [N m], and the file's name relative to the scene.
TAU_FILE_NM = 2.0e-3
W0_FILE_Z = 0.0  # rad/s: CLI_SCENE starts at rest
LAW_REL = "laws/const_law.py"

LAW_FILE = f'''
"""A user's law in a file next to the scene (no PYTHONPATH)."""
from pathlib import Path

from stationbed.run.controller import Controller

with open(Path(__file__).with_name("loads.txt"), "a") as fh:  # top-level code: runs at load
    fh.write("x")


class ConstTorque(Controller):
    name = "const_torque"

    def _update(self, t, meas):
        return (0.0, 0.0, {TAU_FILE_NM!r})


class NotALaw:
    pass
'''


@pytest.fixture
def law_scene(tmp_path, monkeypatch):
    """A scene file in tmp_path naming ``laws/const_law.py:ConstTorque``; the current folder is
    elsewhere, so only the scene's folder can resolve the file."""
    (tmp_path / "laws").mkdir()
    (tmp_path / LAW_REL).write_text(LAW_FILE)
    scene = tmp_path / "scene.toml"
    scene.write_text(CLI_SCENE.format(name=f"{LAW_REL}:ConstTorque", params=""))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    return scene


def assert_held_torque(tr: Trajectory) -> None:
    """ω_z grows by the file law's held torque over the spherical inertia (closed form)."""
    assert_allclose(tr["wz"], W0_FILE_Z + TAU_FILE_NM * tr.t / J_SPHERE, rtol=0, atol=ZOH_TOL_RAD_S)


@pytest.mark.parametrize("how", ["path", "load_scene", "replace"])
def test_controller_file_relative_to_the_scene(law_scene, how):
    """``controller.name = "laws/const_law.py:ConstTorque"`` loads that file from the scene
    file's folder (not the current one), whether simulate gets the path, the loaded scene or a
    ``replace``d copy of it."""
    scene = {"path": lambda: law_scene, "load_scene": lambda: load_scene(law_scene),
             "replace": lambda: load_scene(law_scene).replace(**{"simulation.duration": 5.0})}[how]()
    tr = simulate(scene)
    assert tr.meta["summary"]["controller"] == "const_torque"
    assert_held_torque(tr)


def test_controller_file_absolute_path(law_scene):
    d = loop_scene(**{"controller.name": f"{law_scene.parent / LAW_REL}:ConstTorque", "initial.omega_BN_B": [0.0] * 3})
    assert_held_torque(simulate(scene_from_dict(d), duration=5.0))


def test_cli_runs_a_controller_file(law_scene):
    """`stationbed run` from another folder, no PYTHONPATH: the file law flies."""
    out = law_scene.parent / "out"
    res = run_cli("run", law_scene, "--out", out, cwd=law_scene.parent / "elsewhere")
    assert res.returncode == 0, res.stderr
    assert_held_torque(Trajectory.from_csv(out / "trajectory.csv"))


def test_controller_file_runs_its_top_level_code_once_per_version(law_scene):
    """The file's top-level code runs when it is loaded; loaded again unchanged, it is the same
    class (not run again); edited, it is loaded afresh."""
    name, folder = f"{LAW_REL}:ConstTorque", law_scene.parent
    loads = folder / "laws" / "loads.txt"
    first = get_controller(name, base_dir=folder)
    assert get_controller(name, base_dir=folder) is first and loads.read_text() == "x"
    (folder / LAW_REL).write_text(LAW_FILE + "\n# edited\n")
    assert get_controller(name, base_dir=folder) is not first and loads.read_text() == "xx"


#: id -> (file content or None for no file, controller name, words the error must hold)
FILE_ERRORS = {
    "missing": (None, "laws/nope.py:ConstTorque", "no file {folder}/laws/nope.py"),
    "syntax": ("def broken(:\n", f"{LAW_REL}:ConstTorque", "{folder}/laws/const_law.py:1: syntax error"),
    "raises": ("raise RuntimeError('no licence\\nfor this law')\n", f"{LAW_REL}:ConstTorque",
               "loading {folder}/laws/const_law.py raised RuntimeError: no licence | for this law"),
    "no_class": (LAW_FILE, f"{LAW_REL}:Nope", "no class 'Nope' in {folder}/laws/const_law.py"),
    "not_a_controller": (LAW_FILE, f"{LAW_REL}:NotALaw", "'NotALaw' is not a Controller subclass in {folder}/laws/const_law.py"),
    "no_class_named": (LAW_FILE, LAW_REL, f"name its class: '{LAW_REL}:ClassName'"),
}


@pytest.mark.parametrize("case", list(FILE_ERRORS))
def test_controller_file_errors_name_the_file(tmp_path, case):
    """A one-line ControllerError naming the controller file (resolved against the scene's folder)."""
    content, name, words = FILE_ERRORS[case]
    (tmp_path / "laws").mkdir()
    if content is not None:
        (tmp_path / LAW_REL).write_text(content)
    scene = tmp_path / "scene.toml"
    scene.write_text(CLI_SCENE.format(name=name, params=""))
    with pytest.raises(ControllerError) as exc:
        simulate(scene)
    msg = str(exc.value)
    assert words.format(folder=tmp_path.resolve()) in msg and "\n" not in msg, msg


def test_cli_missing_controller_file_is_exit_2(law_scene):
    scene = law_scene.parent / "missing.toml"
    scene.write_text(CLI_SCENE.format(name="laws/nope.py:ConstTorque", params=""))
    res = run_cli("run", scene, "--out", law_scene.parent / "out")
    assert res.returncode == 2, res.stderr
    assert f"no file {law_scene.parent.resolve()}/laws/nope.py" in one_error_line(res)


def test_module_name_of_a_file_beside_the_scene_suggests_the_file_form(tmp_path):
    """``user_laws:Boom`` with user_laws.py beside the scene but not importable: the error says
    how to name the file instead of setting PYTHONPATH."""
    (tmp_path / "user_laws.py").write_text(USER_MODULE.format(message="x"))
    with pytest.raises(ControllerError, match=r"cannot import module 'user_laws'.*name it 'user_laws\.py:Boom'"):
        get_controller("user_laws:Boom", base_dir=tmp_path)


def test_cli_debug_flag_prints_the_controllers_traceback(tmp_path, monkeypatch):
    """STATIONBED_DEBUG=1: the controller's own frame is printed (chained cause), then the one
    error line; exit 1 as without the flag."""
    monkeypatch.setenv("STATIONBED_DEBUG", "1")
    res = _cli_case(tmp_path, "user_laws:Boom")
    assert res.returncode == 1
    assert "user_laws.py" in res.stderr and "in _update" in res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("stationbed: error: run stopped at t = 5 s")


class BadSummary(Controller):
    """A law whose summary() raises (a bug in reporting, not in control)."""

    name = "bad_summary"

    def _update(self, t, meas):
        return (0.0, 0.0, 0.0)

    def summary(self):
        raise KeyError("gain_table")


def test_raising_summary_does_not_hide_the_run():
    """The run finishes and reports the summary's failure in one field instead of raising."""
    tr = simulate(scene_from_dict(loop_scene()), controller=BadSummary(), duration=1.0)
    assert tr.meta["status"] == "ok"
    assert tr.meta["summary"]["controller_summary_error"] == "KeyError: 'gain_table'"
