"""Scene builders and paths shared by the tests (importable as ``scenes``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))


def scenario_ids():
    return [p.stem for p in SCENARIOS]


def C_PB(alpha, beta):
    """``Ax(β) Ay(α)`` (DESIGN §4), written out independently of the library; complex angles
    allowed (complex-step derivatives)."""
    ca_, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    Ay = np.array([[ca_, 0, -sa], [0, 1, 0], [sa, 0, ca_]])
    Ax = np.array([[1, 0, 0], [0, cb, sb], [0, -sb, cb]])
    return Ax @ Ay


RIGID = {
    "name": "test_rigid",
    "simulation": {"duration": 100.0, "rtol": 1e-12, "atol": 1e-14, "output_dt": 1.0},
    "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
    "body": {"mass": 1000.0, "inertia": [[100.0, 0, 0], [0, 200.0, 0], [0, 0, 250.0]], "cm": [0, 0, 0]},
}


def articulated_dict(duration=300.0, rtol=1e-12, atol=1e-14, alpha_rate=0.01):
    """A hub with two arrays on sine profiles, deep space, products of inertia everywhere."""
    return {
        "name": "test_articulated",
        "simulation": {"duration": duration, "rtol": rtol, "atol": atol, "output_dt": 5.0},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.003, -0.002, 0.004]},
        "body": {
            "mass": 5.0e4,
            "inertia": [[2.0e6, 1.0e5, -5.0e4], [1.0e5, 1.5e6, 2.0e4], [-5.0e4, 2.0e4, 2.8e6]],
            "cm": [0.3, -0.1, 0.2],
        },
        "appendage": [
            {
                "name": "a",
                "mass": 4000.0,
                "inertia": [[3.0e5, 1.0e4, 0.0], [1.0e4, 8.0e4, 2.0e3], [0.0, 2.0e3, 3.5e5]],
                "cm": [0.0, 15.0, 1.0],
                "alpha": {"a0": 0.1, "rate": alpha_rate, "amp": 0.6, "freq": 0.04, "phase": 0.2},
                "beta": {"a0": -0.1, "amp": 0.4, "freq": 0.03, "phase": 1.0},
            },
            {
                "name": "b",
                "mass": 3000.0,
                "inertia": [[2.0e5, 0.0, 5.0e3], [0.0, 6.0e4, 0.0], [5.0e3, 0.0, 2.4e5]],
                "cm": [1.0, -14.0, 0.0],
                "alpha": {"a0": 0.3, "rate": -alpha_rate, "amp": 0.5, "freq": 0.05},
                "beta": {"a0": 0.2, "amp": 0.3, "freq": 0.02, "phase": -0.4},
            },
        ],
    }



def one_error_line(stderr: str) -> str:
    """The CLI's one-line error: exactly one ``stationbed: error:`` line, the last one, no
    traceback; any line before it is a ``stationbed: `` notice (progress, compiling, warning).
    Returns the error line."""
    lines = stderr.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith("stationbed: error:")]
    assert len(errors) == 1 and lines[-1] == errors[0], stderr
    assert all(ln.startswith("stationbed: ") for ln in lines) and "Traceback" not in stderr, stderr
    return errors[0]


def lockstep_batch(scenes, keep: bool = True) -> list:
    """The lockstep batch itself on ``scenes`` (stationbed/run/lockstep.py ``_Lockstep``), each a
    sample of one batch whatever ``executor`` would choose (a law with only ``_update`` is sent
    per tick there): the results, as ``run_lockstep``'s, for tests of the batch's own paths."""
    from stationbed.run.lockstep import _Lockstep, _Sample  # noqa: PLC0415
    from stationbed.run.simulation import SimulationError  # noqa: PLC0415

    return _Lockstep([_Sample(s, None, keep, False) for s in scenes]).run(SimulationError)


#: the executors a closed-loop run can take, by the name the tests give them
EXECUTORS = ("per_tick", "fused", "lockstep")


def fly_on(scene, executor: str):
    """``scene`` flown on ``executor`` (:data:`EXECUTORS`), checked to have run there: fused or
    per tick as the summary says; lockstep as a batch of two copies (one sample alone runs the
    per-tick loop), both copies' rows the same."""
    from stationbed import simulate  # noqa: PLC0415
    from stationbed.run.lockstep import run_lockstep  # noqa: PLC0415

    if executor == "lockstep":
        [(kind, tr), (kind2, tr2)] = run_lockstep([scene, scene], keep=True, fused=False)
        assert kind == kind2 == "batch"
        assert np.array_equal(tr.data, tr2.data, equal_nan=True)
        return tr
    tr = simulate(scene, fused=executor == "fused")
    assert tr.meta["summary"]["fused"] == (executor == "fused"), tr.meta["summary"].get("not_fused")
    return tr
