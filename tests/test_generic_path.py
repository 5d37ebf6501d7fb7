"""The per-tick loop's generic path flies the composer's blocks (issue 33, "What is left" item 1).

The generic path (an adaptive integrator, an edge between ticks, an array rate step, the LP
mapping) calls the run's composition block by block: the sense blocks on the measurement it is
handed, the law in Python, the actuator chain's pieces in order (compiled, a block that is not
symbolic by its Python step), the end, then the integrator split at the pulse edges
(run/parts.py ``GenericTick``, run/chain.py ``chain_advance``). On a scene both can fly (RK4 one
step per tick, declared not fusable: ``RK4Generic``), its rows are those of the composed parts
(the per-tick loop's compiled tick, ``fused=False``), which tests/test_executor_matrix.py holds
to the momentum balance: a wrong chain on the generic path (an actuator left out or out of
order, its on-times, the end's torque) moves the state by far more than round-off. Each scene's
chain is checked to act in the run (thrusters fire, the rods' dipole is on), so agreement is not
that of a chain doing nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenes import SCENARIOS
from stationbed import load_scene, simulate
from stationbed.run.controller import Controller
from stationbed.scene import scene_from_dict
from test_closed_loop_balance import RK4Generic, sphere_scene
from test_executor_matrix import THRUSTER_START, _steps_inside, assert_balance, assert_same_rows
from test_thrusters import pods, sphere

#: ticks flown: enough for the dump to fire (THRUSTER_START: within ~5 s; the sphere's at 10 s) and the rods to act
TICKS = 60
SPHERE_TICKS = 120
#: ticks of the fdir scene: its fault at mid-run, declared ~2 s after (docs/faults.md)
FDIR_TICKS = 80
PERIOD_S = 0.1  # s, the scenes' control period and RK4 step


def _full_flight_magnetorquers():
    """Sensors, MEKF, rods, 16 thrusters and 4 DGCMGs (the chain: rods, thrusters, the cluster)."""
    s = load_scene(next(p for p in SCENARIOS if p.stem == "iss_full_flight_loop_magnetorquers"))
    return s.replace({"simulation.duration": (TICKS + 0.5) * PERIOD_S, "simulation.output_dt": PERIOD_S,
                      **THRUSTER_START})


def _sphere_thrusters():
    """A sphere, 16 thrusters dumping the ideal cluster's momentum (started at 90 % of it)."""
    return sphere(pods(), duration=(SPHERE_TICKS + 0.5) * PERIOD_S).replace({"simulation.output_dt": PERIOD_S})


def _sphere_torquer():
    """No cluster: the ideal torquer ends the chain (its torque held over the tick)."""
    d = sphere_scene([(0.0, 2.0)], cmg=False, duration=(TICKS + 0.5) * PERIOD_S)
    d["simulation"]["output_dt"] = PERIOD_S
    return scene_from_dict(d)


def _cmg_failure_fdir():
    """[fdir] (the CMG detector, the mode manager: the chain's last block) with the scene's CMG
    failure moved to mid-run, so the detector declares inside the short run."""
    s = load_scene(next(p for p in SCENARIOS if p.stem == "iss_cmg_failure_fdir"))
    return s.replace({"simulation.duration": (FDIR_TICKS + 0.5) * PERIOD_S, "simulation.output_dt": PERIOD_S,
                      **_steps_inside(s, FDIR_TICKS, PERIOD_S)})


SCENES = {"full_flight_magnetorquers": _full_flight_magnetorquers, "sphere_thrusters": _sphere_thrusters,
          "sphere_torquer": _sphere_torquer, "cmg_failure_fdir": _cmg_failure_fdir}


def _acts(tr, col: str) -> bool:
    return col in tr.columns and np.abs(tr.cols(col)).max() > 0.0


@pytest.mark.parametrize("name", list(SCENES))
def test_generic_path_flies_the_composed_parts_rows(name):
    scene = SCENES[name]()
    parts = simulate(scene, fused=False)
    generic = simulate(scene, integrator=RK4Generic, fused=False)
    assert "integrator" in generic.meta["summary"]["not_fused"]  # it flew the generic path
    if scene.thruster and getattr(scene, "fdir", None) is None:  # (with [fdir] its mode manager holds them off)
        assert generic.cols("thr_firings")[-1, 0] > 0  # the chain acts: the dump fires
    if scene.magnetorquers is not None:
        assert _acts(generic, "mtq_m_x") or _acts(generic, "mtq_m_y") or _acts(generic, "mtq_m_z")
    if getattr(scene, "fdir", None) is not None:  # the detector declared, alike on both paths
        fdir = [{k: v for k, v in tr.meta["summary"].items() if k.startswith("fdir")} for tr in (parts, generic)]
        assert fdir[0]["fdir_cmg_detected"] and fdir[0] == fdir[1]
    assert_same_rows(parts, generic)


def test_a_block_in_python_between_compiled_pieces_keeps_the_balance():
    """The LP mapping (a block that is not symbolic) between the rods and the cluster: the chain
    in three pieces (rods compiled, thrusters in Python, the end compiled), which only the generic
    path flies. Its rows keep the momentum balance (the logged pulses and dipoles against ΔH_N,
    test_executor_matrix's truth): a pulse of the Python piece booked wrong (its on-times, its
    torques, its place in the chain's channels) breaks it."""
    scene = _full_flight_magnetorquers().replace({"thrusters.mapping": "lp"})
    tr = simulate(scene, fused=False)
    assert tr.meta["summary"]["not_fused"].startswith("thrusters: mapping = 'lp'")
    assert tr.cols("thr_firings")[-1, 0] > 0
    assert _acts(tr, "mtq_m_x") or _acts(tr, "mtq_m_y") or _acts(tr, "mtq_m_z")
    assert_balance(scene, tr)


class _FormNeverBuilt(Controller):
    """A law called in Python (``_update``: zero torque) that also has a ``symbolic`` form and
    numbers, which raise when anything builds them."""

    name = "form_never_built"

    def _update(self, t, meas):
        return (0.0, 0.0, 0.0)

    def symbolic_params(self):
        raise AssertionError("symbolic_params() was called")

    def symbolic(self, t, y, cp):
        raise AssertionError("symbolic() was called")


def test_the_generic_path_never_builds_the_laws_symbolic_form():
    """The generic path calls the law in Python every tick; the law's ``symbolic`` form is the
    fused loop's, and the generic path's composition has a stand-in in its place (its compiled
    parts are the sense blocks and the chain, whatever the law): neither the form nor its numbers
    are built. The law still runs every tick."""
    scene = _sphere_torquer()
    tr = simulate(scene, integrator=RK4Generic, fused=False, controller=_FormNeverBuilt(period=PERIOD_S))
    s = tr.meta["summary"]
    assert "integrator" in s["not_fused"]  # it flew the generic path
    assert s["controller_updates"] == s["ticks"] + 1  # (the last tick's command is reported, not flown)
