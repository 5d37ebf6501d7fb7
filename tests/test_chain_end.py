"""The end of the actuator chain as Actuator plug-ins (issue 20, loop/cmg_cluster.py): the ideal
torquer and the CMG cluster, and the run's composition (run/composition.py) every executor reads.

Independent truths:

* ideal torquer: one tick of a held request is the impulse ``tau h`` (the pieces the executors
  integrate, :func:`~stationbed.loop.actuator.pulse_pieces`, summed by hand); in closed loop the
  momentum balance ``ΔH_N = Σ τ_k Δt_k`` on every executor is
  ``test_closed_loop_balance.py::test_held_command_acts_over_its_period`` (no cluster: the
  request goes through this plug-in, per tick and fused);
* CMG cluster: its steering output delivers the commanded momentum rate, ``A δ̇ = -τ - ω × h``,
  with ``A`` and ``h`` from Wie's closed form (tests/test_cmg.py's independent model), and its
  gimbal-rate path passes rates inside the limit unchanged and scales a faster set down to the
  limit, direction kept; the closed loop's momentum balance (body + cluster) stays
  tests/test_closed_loop_balance.py's;
* the plant's compiled ``actuate`` (run/system.py) is the plug-in's function at the plant's
  state: the same numbers, bit for bit, at random states;
* the composition: named layouts own the indices the executors used to write by hand
  (``x[0:4]``, ``x[7:7 + n]``, ``u[3:3 + nu]``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import load_scene
from stationbed.loop import ACTUATORS, pulse_pieces
from stationbed.loop.cmg_cluster import CmgClusterActuator, IdealTorquer, chain_end
from stationbed.loop.layout import Layout
from stationbed.model.cmg import CmgModel
from stationbed.run.prepare import prepare
from test_cmg import H0, MP_TORQUE_REL, cfg, random_nonsingular_pyramid, wie_pyramid_A, wie_pyramid_h

PERIOD_S = 0.1  # s, one control tick
MAX_RATE_RAD_S = 0.1  # rad/s, the gimbal rate limit of the rate-path tests
#: the impulse of one tick: one product tau * h, exactly the executors' one piece [0, h]
IMPULSE_ABS = 0.0  # N m s


def test_both_are_registered_actuator_kinds():
    assert ACTUATORS["ideal_torquer"] is IdealTorquer
    assert ACTUATORS["cmg_cluster"] is CmgClusterActuator


@pytest.mark.parametrize("h", [PERIOD_S, 0.037], ids=["full", "short_last"])
def test_ideal_torquer_tick_impulse_is_tau_h(h, rng):
    """One tick of a held request: the pieces the executors integrate give the impulse tau h,
    nothing is left to a next actuator."""
    tau = rng.normal(0.0, 100.0, 3)  # N m
    _, rest, on_s, torque_B, _ = IdealTorquer().command(12.3, h, np.zeros(0), np.zeros(0), tau)
    impulse = sum(torque_B[:, on].sum(axis=1) * (b - a) for a, b, on in pulse_pieces(on_s, h))
    assert_allclose(impulse, tau * h, rtol=0, atol=IMPULSE_ABS)
    assert np.array_equal(rest, np.zeros(3))
    assert IdealTorquer.FULL_TICK and np.array_equal(on_s, [h])  # no edge inside the tick: no split


def _pyramid(steering="mp", max_rate=1e6):
    c = cfg("sgcmg_pyramid", steering=steering, max_gimbal_rate=max_rate)
    model = CmgModel.of(c)
    return CmgClusterActuator(model, model.params(c)), model


def _out(act, r, tau=None, rates=None, t=3.7):
    """The plug-in's out (u_cmg, m, rate_limited, saturated) by name, numerically."""
    if rates is None:
        _, rest, on_s, torque_B, out = act.command(t, PERIOD_S, np.zeros(0), r, tau)
        assert on_s.size == 0 and torque_B.shape == (3, 0) and np.array_equal(rest, np.zeros(3))  # internal, end of chain
    else:
        out = np.array(act.rates_function()(t, r, rates, act.params)).ravel()
    return act.outputs.split(out)


def test_cmg_cluster_steering_delivers_the_commanded_momentum_rate(rng):
    """Moore-Penrose steering through the plug-in: A δ̇ = -τ - ω × h (Wie's closed form)."""
    act, _ = _pyramid("mp")
    for d in random_nonsingular_pyramid(rng, 10):
        tau = rng.normal(0.0, 50.0, 3)  # N m
        w = rng.normal(0.0, 0.01, 3)  # rad/s
        out = _out(act, act.reads.pack(omega_BN_B=w, x_cmg=d), tau=tau)
        hdot_cmd = -tau - np.cross(w, wie_pyramid_h(d))
        assert out["rate_limited"] == 0.0
        assert_allclose(wie_pyramid_A(d) @ out["u_cmg"], hdot_cmd, rtol=0, atol=MP_TORQUE_REL * np.linalg.norm(hdot_cmd))


def test_cmg_cluster_rate_path_limits_rates_direction_kept(rng):
    """Commanded gimbal rates: inside the limit they are the held input unchanged; a faster set
    is scaled down together to the limit (its direction kept) and flagged."""
    act, _ = _pyramid("sr", MAX_RATE_RAD_S)
    d = random_nonsingular_pyramid(rng, 1)[0]
    r = act.reads.pack(omega_BN_B=np.zeros(3), x_cmg=d)
    slow = np.array([0.05, -0.02, 0.09, 0.0])  # rad/s
    out = _out(act, r, rates=slow)
    assert np.array_equal(out["u_cmg"], slow) and out["rate_limited"] == 0.0
    fast = 3.0 * slow
    out = _out(act, r, rates=fast)
    assert out["rate_limited"] == 1.0
    assert_allclose(np.abs(out["u_cmg"]).max(), MAX_RATE_RAD_S, rtol=1e-15, atol=0)
    assert_allclose(out["u_cmg"] / np.linalg.norm(out["u_cmg"]), fast / np.linalg.norm(fast), rtol=0, atol=1e-15)


def test_cmg_cluster_saturation_flag_at_the_capacity_envelope():
    """All four pyramid spins along +z (δ = 90°): |h| = 4 h0 sin β, the capacity: saturated."""
    act, model = _pyramid("sr")
    d = np.deg2rad([90.0, 90.0, 90.0, 90.0])
    assert_allclose(np.linalg.norm(wie_pyramid_h(d)), 4.0 * H0 * 0.8, rtol=1e-12)
    out = _out(act, act.reads.pack(omega_BN_B=np.zeros(3), x_cmg=d), tau=np.zeros(3))
    assert out["saturated"] == 1.0


@pytest.fixture(scope="module")
def hold():
    scene = load_scene("scenarios/iss_lvlh_hold.toml")
    return prepare(scene, scene.simulation.formulation, scene.simulation.integrator)


def test_plant_actuate_is_the_plugin_at_the_plant_state(hold, rng):
    """The system's compiled ``actuate`` (per tick) and the plug-in's own compiled function, fed
    the plant's true rate and cluster state by name: the same numbers, bit for bit."""
    system, p = hold.system, hold.p
    form = system.formulation
    model = form.model
    end = chain_end(model)
    assert isinstance(end, CmgClusterActuator)
    plant = system.funcs["actuate"]
    lay = form.state_layout
    pc = p[model.layout["cmg"]]
    out, w_at = system.funcs["out"], system.out_layout["omega_BN_B"]  # the true rate, by name
    for _ in range(5):
        x = hold.x0 + rng.normal(0.0, 1e-3, hold.x0.size)
        x[lay.slice("x_cmg")] = rng.uniform(-math.pi, math.pi, lay.shape("x_cmg")[0])
        tau = rng.normal(0.0, 100.0, 3)  # N m
        ref = np.array(plant(0.5, x, tau, p)).ravel()
        w = np.array(out(0.5, x, p)).ravel()[w_at]
        r = end.reads.pack(omega_BN_B=w, x_cmg=lay.get(x, "x_cmg"))
        end.params = pc
        got = end.command(0.5, PERIOD_S, np.zeros(0), r, tau)[4]
        assert np.array_equal(got, ref)


def test_state_and_input_layouts_own_the_indices(hold):
    """The named layouts give the indices the executors wrote by hand before."""
    form = hold.system.formulation
    model = form.model
    lay = form.state_layout
    assert lay.size == form.nx
    assert lay.slice("q_BN") == slice(0, 4)
    assert lay.slice(form.rate_field) == slice(4, 7)
    assert lay.slice("x_cmg") == slice(7, 7 + model.cmg.nx)
    assert tuple(lay.names) == ("q_BN", "H_O_B", "x_cmg", "joints")  # momentum form, driven arrays, no modes
    u = model.input_layout
    assert u.size == model.nu
    assert u.slice("u_ext") == slice(0, 3) and u.slice("u_cmg") == slice(3, 3 + model.nu_cmg)
    assert "t_step" not in u  # no array rate steps in this scene
    assert Layout(a=1) == Layout(a=1)  # (loop.layout re-exports core.layout's class)
