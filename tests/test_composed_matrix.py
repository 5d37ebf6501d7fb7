"""The combination matrix of the loop's blocks (issue 33 item 7): every combination of thrusters
x sensors and MEKF x a law with a state x the ideal measurement's noise, flown fused and per
tick, on a spherical station with an ideal momentum store (tests/test_thrusters.py's ``sphere``).

Independent truths, per combination and executor:

* the momentum balance: the store is internal, the thrusters the only external torque, so the
  total momentum changes by ``Σ_ticks C_NB(t_k) Σ_j (r_j × F_j ĝ_j) Δt_on,j`` (the on-times
  logged per tick, the arms from the scene, summed here), and not at all without thrusters;
* where the combination flies fused, the per-tick loop's rows to round-off; where it cannot,
  the summary names why (``not_fused``) and nothing else.

The product is enumerated in full (16 combinations): hypothesis would draw from the same 16.
Sensors come with the MEKF, except beside the ideal measurement's noise (a scene refuses an
estimator with it: the sensors are then flown and recorded beside the noisy ideal path).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import simulate
from test_composed import _C_NB
from test_law_state import CountedSine
from test_thrusters import PERIOD_S, hand_arms, pods, sphere

#: fused vs per tick: the same expressions in another order over 200 ticks (relative to
#: max(|value|, 1)); the NEES is a ratio of small numbers
EXEC_REL = 1e-8
#: the balance with the attitude at each tick's start: the sphere turns < 1e-3 rad/s, a pulse
#: is <= 100 N x 20 m x 0.1 s = 200 N m s: < 0.02 N m s per pulse; a lost 20 ms pulse is 40 N m s
BALANCE_ABS = 0.5  # N m s
DURATION_S = 20.0

GYRO = {"kind": "gyro", "name": "g1", "period": PERIOD_S, "sigma_v": 1e-7, "sigma_u": 1e-10}
STAR = {"kind": "star_tracker", "name": "s1", "period": 0.5, "boresight_B": [0.0, 0.0, 1.0],
        "nea_cross": 1e-5, "nea_about": 5e-5}
NOISE = {"attitude_noise": 1e-4, "rate_noise": 1e-6, "seed": 7}
COMBOS = list(itertools.product([False, True], repeat=4))


def _scene(thrusters: bool, sensors: bool, state: bool, noise: bool):
    s = sphere(pods(), duration=DURATION_S)
    over = {"simulation.output_dt": PERIOD_S}
    if not thrusters:
        over.update({"thruster": [], "thrusters": None})
    if sensors:  # (with the ideal measurement's noise, no estimator: a scene refuses the two together)
        over.update({"sensor": [GYRO, STAR], **({} if noise else {"estimator": {"kind": "mekf"}})})
    if state:
        over["controller"] = {"name": "counted_sine", "period": PERIOD_S}
    if noise:
        over["controller.sensor"] = NOISE
    return s.replace(over)


def _fuses(thrusters, sensors, state, noise) -> str | None:
    """What the summary must name when the combination cannot fly fused (None: it flies fused)."""
    if sensors and noise:
        return "noise: [controller.sensor] noise with [[sensor]] tables"
    if thrusters and noise and state:
        return "thrusters: [controller.sensor] noise with a law that has a state"
    return None


def _impulse_N(tr) -> np.ndarray:
    D, _ = hand_arms(pods())
    names = [f"t{i}" for i in range(16)]
    on = tr.data[:, [tr.columns.index(f"thr_on_s_{n}") for n in names]]
    imp_B = np.diff(on, axis=0) @ (D.T * 100.0)  # F_N = 100 N each (tests/test_thrusters.py)
    imp_N = np.array([_C_NB(q) @ v for q, v in zip(tr.q_BN[:-1], imp_B)])
    return np.vstack([np.zeros(3), np.cumsum(imp_N, axis=0)])


@pytest.mark.parametrize("thrusters, sensors, state, noise", COMBOS,
                         ids=["-".join(n for n, on in zip(("thr", "sens", "state", "noise"), c) if on) or "bare"
                              for c in COMBOS])
def test_every_combination_flies_as_per_tick_and_keeps_the_balance(thrusters, sensors, state, noise):
    s = _scene(thrusters, sensors, state, noise)
    runs = {f: simulate(s, fused=f, controller=CountedSine(period=PERIOD_S) if state else None) for f in (False, True)}
    a, b = runs[False], runs[True]
    why = _fuses(thrusters, sensors, state, noise)
    sm = b.meta["summary"]
    if why is None:
        assert sm["fused"] and "not_fused" not in sm
        keep = [j for j, c in enumerate(a.columns) if not (state and c.startswith("att_err"))]  # (no reference in Python)
        assert a.columns == b.columns
        assert np.nanmax(np.abs(a.data[:, keep] - b.data[:, keep]) / np.maximum(np.abs(a.data[:, keep]), 1.0)) < EXEC_REL
    else:
        assert not sm["fused"] and sm["not_fused"].startswith(why)
    for tr in (a, b):
        dH = tr.H_O_N - tr.H_O_N[0]
        expect = _impulse_N(tr) if thrusters else np.zeros_like(dH)
        if thrusters:
            assert tr.meta["summary"]["thruster_firings"] > 0
        assert_allclose(dH, expect, rtol=0, atol=BALANCE_ABS)
