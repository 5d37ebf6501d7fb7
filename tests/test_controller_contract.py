"""One contract for every registered controller (STYLE 6: the moment a law is registered in
``controllers/``, these tests exercise it).

Per controller: it builds from its defaults (plus the documented example values of any
parameter that has no default, :data:`EXAMPLE_PARAMS`), names an unknown parameter in a
:class:`ControllerError`, runs a short closed loop on a scene that has what it may need (an orbit
for LVLH references, a gimballed CMG cluster so both torque requests and gimbal rates can act),
returns a finite command of the right length at every tick, the run logs that command, and its
``summary()`` is plain JSON.
"""

from __future__ import annotations

import copy
from pathlib import Path
import json

import numpy as np
import pytest

from stationbed import simulate
from stationbed.run.controller import Controller, ControllerError, command_values, controller_registry
from stationbed.scene import scene_from_dict

REGISTRY = controller_registry()
NAMES = sorted(REGISTRY)

#: Values for parameters that have no default (a law that needs them says so: a missing one is
#: a ControllerError naming it, tested below). Every such parameter must appear here.
EXAMPLE_PARAMS = {"torque_command": {"torque_B": [2.0, -1.0, 0.5]},  # N m
                  # a hand-written LVLH hold plan (tests/data/hold_plan/README.md)
                  "schedule": {"plan": str(Path(__file__).parent / "data" / "hold_plan" / "plan.json")}}

PERIOD_S = 0.1  # s
#: ticks per run: enough for the warm-up of every law (filters, integrators, plan shifts) to be
#: exercised; the MPC solves an NLP per tick (~0.25 s here), so it gets fewer
TICKS = {"default": 30, "mpc": 5}

#: An ISS-sized rigid station (JEOD inertia with products) in a 400 km, 51.6 deg orbit with
#: gravity gradient, 0.55 deg off LVLH, with a 4-CMG pyramid (gimbal rates or SR-steered torque).
CONTRACT_SCENE = {
    "name": "controller_contract",
    "simulation": {"duration": 1.0, "integrator": "rk4", "step": PERIOD_S, "output_dt": PERIOD_S},
    "initial": {"frame": "lvlh", "q_BN": [0.99998858, 0.0035, -0.0025, 0.0018]},
    "body": {"mass": 4.0e5, "inertia": [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5],
                                        [-5.48e6, 5.9e5, 1.64e8]]},
    "orbit": {"altitude": 400000.0, "inclination": 0.9006},
    "cmg": {"kind": "sgcmg_pyramid", "h_rotor": 4760.0, "steering": "sr"},
    "controller": {"name": "pd", "period": PERIOD_S},
}


def params_of(name: str) -> dict:
    return copy.deepcopy(EXAMPLE_PARAMS.get(name, {}))


def test_registry_has_the_shipped_laws():
    """The issue's laws are registered under their scene names (the contract below runs on all)."""
    assert "pd" in REGISTRY
    for name, cls in REGISTRY.items():
        assert issubclass(cls, Controller) and cls.name == name
        assert cls.command in ("torque", "gimbal_rates")


@pytest.mark.parametrize("name", NAMES)
def test_builds_from_defaults(name):
    cls = REGISTRY[name]
    required = [k for k, f in cls.Params.model_fields.items() if f.is_required()]
    missing = [k for k in required if k not in params_of(name)]
    assert not missing, f"add example values for {name}'s required parameters {missing} to EXAMPLE_PARAMS"
    ctrl = cls(period=PERIOD_S, **params_of(name))
    assert ctrl.period == PERIOD_S
    for k in required:  # a missing required parameter is a clear error naming it
        with pytest.raises(ControllerError, match=rf"controller '{name}': params\.{k}"):
            cls(period=PERIOD_S, **{kk: v for kk, v in params_of(name).items() if kk != k})


@pytest.mark.parametrize("name", NAMES)
def test_rejects_an_unknown_parameter(name):
    with pytest.raises(ControllerError, match=rf"controller '{name}': unknown parameter 'no_such_param'"):
        REGISTRY[name](period=PERIOD_S, no_such_param=1.0, **params_of(name))


def contract_scene(name: str):
    d = copy.deepcopy(CONTRACT_SCENE)
    ticks = TICKS.get(name, TICKS["default"])
    d["simulation"]["duration"] = ticks * PERIOD_S
    d["controller"] = {"name": name, "period": PERIOD_S, "params": params_of(name)}
    return scene_from_dict(d), ticks


@pytest.fixture(scope="module", params=NAMES)
def contract_run(request):
    """A short closed loop of one law on the contract scene; every command recorded."""
    name = request.param
    scene, ticks = contract_scene(name)
    ctrl = REGISTRY[name](period=PERIOD_S, **params_of(name))
    tick_update = ctrl.tick_update
    commands = []

    def recording_tick_update():  # what the per-tick loop calls every tick (_update or the compiled law)
        update, counted = tick_update()

        def recording(t, meas):
            cmd = update(t, meas)
            commands.append((t, cmd))
            return cmd
        return recording, counted

    ctrl.tick_update = recording_tick_update
    traj = simulate(scene, controller=ctrl, fused=False)
    return name, scene, ctrl, traj, commands, ticks


def test_returns_a_finite_command_of_the_right_length_every_tick(contract_run):
    name, scene, ctrl, traj, commands, ticks = contract_run
    n_cmd = 3 if ctrl.command == "torque" else scene.cmg.n_gimbals
    assert [t for t, _ in commands] == [k * PERIOD_S for k in range(ticks)] + [ticks * PERIOD_S]
    for t, cmd in commands:  # the loop's own definition of a valid command (ValueError if not)
        command_values(cmd, n_cmd, ctrl.command)
    assert traj.meta["summary"]["controller_updates"] == ticks + 1 == ctrl.n_updates


def test_the_run_logs_the_command(contract_run):
    """Torque laws: ``tau_cmd`` is the request of each row's tick; gimbal-rate laws: the logged
    gimbal rates are the command (inside the rate limit, where nothing is scaled)."""
    name, scene, ctrl, traj, commands, ticks = contract_run
    cmds = np.array([c for _, c in commands], dtype=float)
    if ctrl.command == "torque":
        assert np.array_equal(traj.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z"), cmds)
    else:
        names = [f"gimbal_{i + 1}_rate" for i in range(scene.cmg.n_gimbals)]
        inside = np.abs(cmds).max(axis=1) <= scene.cmg.max_gimbal_rate
        assert np.array_equal(traj.cols(*names)[inside], cmds[inside])
        assert np.all(np.isnan(traj.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")))


def test_the_run_stays_physical(contract_run):
    """A short run of any law from 0.55 deg off LVLH: the state stays finite and the station does
    not start to tumble (|ω| below ten times the orbital rate)."""
    name, scene, ctrl, traj, commands, ticks = contract_run
    assert np.all(np.isfinite(traj.data[:, :12]))
    assert np.linalg.norm(traj.omega_BN_B, axis=1).max() < 10 * scene.orbit.mean_motion


def test_summary_is_json(contract_run):
    """``summary()`` holds JSON types only (no numpy scalars, complex poles or arrays), before and
    after the run's own keys are merged in."""
    name, scene, ctrl, traj, commands, ticks = contract_run
    s = ctrl.summary()
    assert isinstance(s, dict)
    text = json.dumps(s)  # what `stationbed run` writes to summary.json
    assert json.loads(text).keys() == s.keys()
    json.dumps(traj.meta["summary"])
    for k in s:
        assert k in traj.meta["summary"], f"{name}: summary key {k!r} missing from the run summary"


#: the same arithmetic compiled as two programs (fused loop vs per-tick calls): round-off only
FUSED_RTOL = 1e-9


@pytest.mark.parametrize("name", [n for n in NAMES if callable(getattr(REGISTRY[n], "symbolic", None))])
def test_symbolic_form_gives_the_python_law(name):
    """A law that offers ``symbolic`` flies the same trajectory per tick (its compiled form
    called from Python every tick, or its ``_update`` when it has one) as fused (inlined in the
    compiled loop)."""
    scene, _ = contract_scene(name)
    per_tick = simulate(scene, fused=False)
    fused = simulate(scene, fused=True)
    assert fused.meta["summary"]["fused"] is True and per_tick.meta["summary"]["fused"] is False
    assert np.array_equal(np.isnan(fused.data), np.isnan(per_tick.data))
    scale = np.maximum(np.abs(per_tick.data).max(axis=0), 1e-300)
    rel = np.nan_to_num(np.abs(fused.data - per_tick.data), nan=0.0) / scale
    assert rel.max() <= FUSED_RTOL, f"{per_tick.columns[int(np.argmax(rel.max(axis=0)))]}: {rel.max():.2e}"


@pytest.mark.parametrize("name", ["pd", "lqr", "momentum_manager"])
def test_a_symbolic_law_is_written_once(name):
    """pd, lqr and momentum_manager are their ``symbolic`` form alone (no float ``_update``, no
    numpy ``update_batch``): the per-tick loop calls that form compiled, uncounted (the loop
    counts), and the lockstep loop takes its compiled batch (issue 33)."""
    from stationbed.run.law_compiled import CompiledLaw
    from stationbed.run.lockstep import vectorised

    cls = REGISTRY[name]
    assert "_update" not in vars(cls) and "update_batch" not in vars(cls)
    ctrl = cls(period=PERIOD_S, **params_of(name))
    call, counted = ctrl.tick_update()
    assert isinstance(call, CompiledLaw) and not counted and vectorised(ctrl)


def test_a_law_without_symbolic_form_is_called_in_python():
    """example_hold (no ``symbolic``) keeps the Python path: ``_update`` per tick."""
    ctrl = REGISTRY["example_hold"](period=PERIOD_S)
    call, counted = ctrl.tick_update()
    assert not ctrl.has_symbolic() and call == ctrl._update and not counted
