"""CMG cluster physics in the equations of motion and in the closed loop (issue 3).

(a) Internal momentum exchange keeps H_O_N constant: a torque-free body with a moving cluster,
    every CMG kind, every formulation.
(b) The torque on the body is -ḣ - ω × h: the formulations' ω̇ against an Euler equation written
    here, with h and ḣ from independent models (Wie's closed form, scipy rotations).
(c) On scenarios/sgcmg_singularity.toml: Moore-Penrose stalls at the internal singularity
    h = 2 cos β h0 x̂, SR and o-DSR pass through it (and, for the exactly symmetric command, only
    o-DSR escapes).
(d) The formulations agree on CMG scenes (every kind), CMG columns included. (These scenes
    have no arrays, so momentum27 and dalembert coincide here; CMG and arrays together are
    cross-checked on scenarios/iss_lvlh_hold.toml by tests/test_equivalence.py.)
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import FORMULATIONS, load_scene, simulate
from stationbed.studies.check import compare
from stationbed.run.controller import Controller
from stationbed.model import Structure
from stationbed.core.rotation import dcm
from stationbed.scene import scene_from_dict
from stationbed.run.system import build_system
from test_cmg import dgcmg_A, dgcmg_h, wie_pyramid_A, wie_pyramid_h

FORMS = sorted(FORMULATIONS)
OMEGA_FORMS = [n for n in FORMS if FORMULATIONS[n].omega_is_state]
KINDS = ["ideal", "dgcmg", "sgcmg_pyramid"]

#: body of the conservation scenes: products of inertia everywhere, spinning about no principal axis
I_BODY_B = np.array([[2.0e6, 1.0e5, -5.0e4], [1.0e5, 1.5e6, 2.0e4], [-5.0e4, 2.0e4, 2.8e6]])  # kg m²
OMEGA0_BN_B = [0.003, -0.002, 0.004]  # rad/s
H_ROTOR = 500.0  # N m s
RTOL = 1e-12  # integrator tolerance of the conservation / agreement runs

# -- tolerances -------------------------------------------------------------------------------
#: H_O_N drift relative to |H|: DOP853 at rtol 1e-12 over 600 control periods (measured ≤ 3.5e-15)
H_DRIFT_REL = 1e-12
#: ω̇ of the formulation's RHS vs the Euler equation here: float64 round-off of a 3x3 solve (cond(I) < 3)
OMEGA_DOT_REL = 1e-12
#: formulations vs each other: global error ≤ AGREE_GAIN · rtol (the check's allowance, 1e3 rtol)
AGREE_GAIN = 1e3
#: generated C vs casadi's VM on the same expressions: equal up to rounding, which the adaptive
#: step control can amplify to the order of rtol (measured: bit-identical)
COMPILED_VS_VM_REL = 1e3 * RTOL


class SineGimbalRates(Controller):
    """Open-loop gimbal rates ``a_i sin(ν_i t + i)`` (held per period): a cluster in motion."""

    name = "test_sine_gimbal_rates"
    command = "gimbal_rates"

    def _reset(self, plant):
        n = plant.n_gimbals
        self.amp = 0.02 * np.linspace(0.5, 1.5, n)  # rad/s
        self.nu = np.linspace(0.05, 0.2, n)  # rad/s
        self.phase = np.arange(n, dtype=float)

    def _update(self, t, meas):
        return tuple(self.amp * np.sin(self.nu * t + self.phase))


def cmg_scene_dict(kind: str, duration: float = 60.0) -> dict:
    """Deep space, a rigid body with a CMG cluster in motion, no external torque."""
    d = {
        "name": f"test_cmg_{kind}",
        "simulation": {"duration": duration, "rtol": RTOL, "atol": 1e-14, "output_dt": 1.0},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": OMEGA0_BN_B},
        "body": {"mass": 5.0e4, "inertia": I_BODY_B.tolist(), "cm": [0.0, 0.0, 0.0]},
    }
    if kind == "ideal":  # a momentum store driven by a torque request; stops at 40 s (a window edge)
        d["cmg"] = {"kind": "ideal", "h0_B": [100.0, -50.0, 30.0]}
        d["controller"] = {
            "name": "torque_command", "period": 0.1, "params": {"torque_B": [20.0, -10.0, 15.0], "stop": 40.0}
        }
    elif kind == "dgcmg":  # gimbal rates commanded directly (SineGimbalRates, passed to simulate)
        d["cmg"] = {"kind": "dgcmg", "h_rotor": H_ROTOR, "max_gimbal_rate": 0.05,
                    "gimbal0": [0.1, -0.2, 0.3, 0.4, -0.5, 0.6, 0.7, -0.8]}
        d["controller"] = {"name": "torque_command", "period": 0.1, "params": {"torque_B": [0.0, 0.0, 0.0]}}
    else:  # a torque request through the SR steering law
        d["cmg"] = {"kind": "sgcmg_pyramid", "h_rotor": H_ROTOR, "max_gimbal_rate": 0.5, "steering": "sr",
                    "gimbal0": [0.2, -0.1, 0.4, 0.3]}
        d["controller"] = {"name": "torque_command", "period": 0.1, "params": {"torque_B": [15.0, -20.0, 10.0]}}
    return d


@contextlib.contextmanager
def casadi_vm():
    """Build the (a), (b), (d) systems without generating C (casadi's virtual machine).

    Same SX expressions, same numbers (stationbed/core/compile.py); these runs are 600 ticks of a
    small model, ~0.2 s each in the VM, while generating and compiling C for their 9 structures
    took ~60 s of a cold-cache run of this file on 2 cores (measured). The compiled path is
    exercised by (c) here and by tests/test_equivalence.py on the CMG scenarios.
    """
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STATIONBED_NO_COMPILE", "1")
        yield


@functools.lru_cache(maxsize=None)
def run(kind: str, form: str):
    scene = scene_from_dict(cmg_scene_dict(kind))
    ctrl = SineGimbalRates(period=0.1) if kind == "dgcmg" else None
    with casadi_vm():
        return simulate(scene, formulation=form, controller=ctrl)


# =============================================================================================
# (a) internal momentum exchange
# =============================================================================================
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("kind", KINDS)
def test_internal_momentum_exchange_keeps_H_constant(kind, form):
    tr = run(kind, form)
    H = tr.H_O_N
    drift = np.max(np.linalg.norm(H - H[0], axis=1))
    assert drift <= H_DRIFT_REL * np.linalg.norm(H[0]), f"H_O_N drifts by {drift:.3e} N m s"
    # not vacuous: the cluster really exchanged momentum with the body (hundreds of N m s, while
    # leaving out -ω × h or -ḣ would move H_O_N by ~|ω||h| t ~ 100 N m s)
    h = tr.cols("hx", "hy", "hz")
    assert np.max(np.ptp(h, axis=0)) > 150.0
    assert tr.meta["summary"]["rate_limited_ticks"] == 0  # the commands were delivered as asked


def test_ideal_cluster_compiled_matches_vm():
    """The generated C of an ideal-cluster scene gives the VM's numbers (the scene structure's
    name must be a valid C identifier for that: the other (a) runs use the VM, see casadi_vm)."""
    scene = scene_from_dict(cmg_scene_dict("ideal"))
    compiled = simulate(scene, formulation="momentum")
    vm = run("ideal", "momentum")
    assert compiled.columns == vm.columns
    for c in vm.columns:
        if c.startswith("att_err_"):  # no reference attitude: NaN in both
            assert np.all(np.isnan(compiled[c])) and np.all(np.isnan(vm[c]))
            continue
        scale = np.max(np.abs(vm[c]))  # per column: units differ
        assert np.max(np.abs(compiled[c] - vm[c])) <= COMPILED_VS_VM_REL * scale, c


def test_torque_command_window():
    """torque_command requests torque_B on ticks in [start, stop) and zero after (ideal CMG scene)."""
    tr = run("ideal", "momentum")
    tau = tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")
    on = tr.t < 40.0
    assert_allclose(tau[on], np.tile([20.0, -10.0, 15.0], (on.sum(), 1)), rtol=0, atol=0)
    assert_allclose(tau[~on], 0.0, atol=0)
    assert np.all(np.isnan(tr["att_err_deg"]))  # no reference attitude


# =============================================================================================
# (b) torque on the body = -ḣ - ω × h (independent Euler equation)
# =============================================================================================
def independent_h_and_hdot(kind, xc, uc, w):
    """h and its body-frame rate from models written in the tests (not the library's)."""
    if kind == "sgcmg_pyramid":  # Wie's closed form and its hand-derived Jacobian
        return wie_pyramid_h(xc, h0=H_ROTOR), wie_pyramid_A(xc, h0=H_ROTOR) @ uc
    if kind == "dgcmg":  # scipy rotations; the rotor turns at δ̇o e1 + δ̇i e2' relative to B
        return dgcmg_h(xc, h0=H_ROTOR), dgcmg_A(xc, h0=H_ROTOR) @ uc
    return xc, -uc - np.cross(w, xc)  # ideal: the store absorbs the request τ


def random_state(kind, rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w = rng.normal(0.0, 0.01, 3)
    if kind == "ideal":
        xc, uc = rng.normal(0.0, 300.0, 3), rng.normal(0.0, 20.0, 3)
    else:
        n = 4 if kind == "sgcmg_pyramid" else 8
        xc, uc = rng.uniform(-math.pi, math.pi, n), rng.normal(0.0, 0.05, n)
    return q, w, xc, uc


@pytest.mark.parametrize("form", OMEGA_FORMS)
@pytest.mark.parametrize("kind", KINDS)
def test_body_torque_is_minus_hdot_minus_omega_cross_h(kind, form, rng):
    """I ω̇ = -ω × (I ω + h) - ḣ (torque-free): build_system's RHS against the equation written here."""
    scene = scene_from_dict(cmg_scene_dict(kind))
    with casadi_vm():
        system = build_system(Structure.of(scene), form, "dop853")
    p = system.formulation.model.params(scene)
    for _ in range(10):
        q, w, xc, uc = random_state(kind, rng)
        x = np.concatenate([q, w, xc])
        u = np.concatenate([np.zeros(3), uc])
        xdot = np.array(system.funcs["rhs"](0.0, x, u, p)).ravel()
        h, hdot = independent_h_and_hdot(kind, xc, uc, w)
        w_dot = np.linalg.solve(I_BODY_B, -np.cross(w, I_BODY_B @ w + h) - hdot)
        assert_allclose(xdot[4:7], w_dot, rtol=0, atol=OMEGA_DOT_REL * np.linalg.norm(w_dot))
        if kind == "ideal":  # the body receives exactly the request: I ω̇ = τ - ω × I ω
            assert_allclose(I_BODY_B @ xdot[4:7], uc - np.cross(w, I_BODY_B @ w), rtol=0,
                            atol=OMEGA_DOT_REL * np.linalg.norm(uc))
        assert_allclose(xdot[7:], hdot if kind == "ideal" else uc, rtol=1e-15, atol=1e-300)


@pytest.mark.parametrize("kind", KINDS)
def test_momentum_state_is_I_omega_plus_h(kind, rng):
    """The momentum form's state is H = I ω + h and it recovers ω = I⁻¹(H - h) (h independent)."""
    scene = scene_from_dict(cmg_scene_dict(kind))
    with casadi_vm():
        system = build_system(Structure.of(scene), "momentum", "dop853")
    f = system.funcs
    p = system.formulation.model.params(scene)
    for _ in range(5):
        q, w, xc, uc = random_state(kind, rng)
        h, _ = independent_h_and_hdot(kind, xc, uc, w)
        x = np.array(f["init"](0.0, q, w, xc, p)).ravel()
        assert_allclose(x[4:7], I_BODY_B @ w + h, rtol=0, atol=1e-12 * np.linalg.norm(I_BODY_B @ w + h))
        # and the total momentum reported in N is C_NB H
        out = np.array(f["out"](0.0, x, p)).ravel()
        assert_allclose(out[0:3], w, rtol=0, atol=1e-12 * np.linalg.norm(w))
        assert_allclose(out[3:6], dcm(q).T @ (I_BODY_B @ w + h), rtol=0, atol=1e-9)


# =============================================================================================
# (c) the singularity scenario: MP stalls, SR and o-DSR pass through
# =============================================================================================
SCENARIO = ROOT / "scenarios" / "sgcmg_singularity.toml"
COS_BETA = 0.6  # the scenario's skew: atan(4/3)


@functools.lru_cache(maxsize=None)
def singular_run(law: str, symmetric: bool = False):
    scene = load_scene(SCENARIO).replace(**{"cmg.steering": law})
    if symmetric:  # the exactly symmetric command, and long enough for o-DSR's dither to act
        scene = scene.replace(**{"controller.params.torque_B": [-100.0, 0.0, 0.0], "simulation.duration": 40.0})
    tr = simulate(scene)
    tau = np.array(scene.controller.params["torque_B"])
    return scene, tr, -tau / np.linalg.norm(tau)  # the direction the cluster must absorb momentum in


def stall_point(scene) -> float:
    """|h| at the internal singularity along x: 2 cos β h0 [N m s] (Wie 2005)."""
    return 2.0 * COS_BETA * scene.cmg.h_rotor


def test_scenario_geometry_is_wies_classic_case():
    scene = load_scene(SCENARIO)
    assert scene.cmg.kind == "sgcmg_pyramid"
    assert math.cos(scene.cmg.skew) == pytest.approx(COS_BETA, rel=1e-15)
    assert stall_point(scene) == pytest.approx(1200.0)


def test_moore_penrose_stalls_at_the_internal_singularity():
    scene, tr, e = singular_run("mp")
    S = tr.meta["summary"]
    h = tr.cols("hx", "hy", "hz")
    h0 = scene.cmg.h_rotor
    # stalls at 2 cos β h0 along the command, short of the 3.2 h0 envelope
    assert h[-1] @ e == pytest.approx(stall_point(scene), abs=0.01 * h0)
    # where: δ = (-90, 0, 90, 0) deg (the gimbals chatter within a few degrees of it)
    g = np.rad2deg(tr.cols("gimbal_1", "gimbal_2", "gimbal_3", "gimbal_4")[-1])
    assert_allclose(g, [-90.0, 0.0, 90.0, 0.0], atol=5.0)
    # the delivered torque collapses: over the last 10 s the cluster absorbs < 0.5 % of the
    # commanded 100 N m x 10 s
    last = tr.t >= tr.t[-1] - 10.0
    absorbed = (h[last][-1] - h[last][0]) @ e
    assert abs(absorbed) < 0.005 * 100.0 * 10.0
    # reported, never silent: gimbal rates at their limit on nearly every tick after the stall
    # (t = 12 s: 0.1 h0/s to reach 1.2 h0)
    ticks_after_stall = (tr.t[-1] - 12.5) / scene.controller.period
    assert S["rate_limited_ticks"] >= 0.9 * ticks_after_stall
    assert S["rate_limited_ticks"] <= S["ticks"]
    assert np.all(tr["cmg_saturated"][tr.t > 15.0] == 1.0)
    assert S["min_singularity"] < 0.05


def test_stall_summary_counts_each_limited_tick_once():
    """With a row per control tick, each row's cmg_saturated is that tick's flag: the summary's
    rate_limited_ticks must equal the number of flagged rows (the last row's actuation, at
    t = duration, is computed but never integrated: it may or may not be counted)."""
    scene = load_scene(SCENARIO).replace(**{"cmg.steering": "mp", "simulation.output_dt": 0.01})
    tr = simulate(scene)
    S = tr.meta["summary"]
    flagged = tr["cmg_saturated"]
    assert S["momentum_saturated_ticks"] == 0  # |h| ≤ 1200 < 0.9 x 3200 N m s: every flag is a rate limit
    assert np.sum(flagged[:-1]) <= S["rate_limited_ticks"] <= np.sum(flagged)


@pytest.mark.parametrize("law", ["sr", "odsr"])
def test_sr_and_odsr_pass_through_the_singularity(law):
    scene, tr, e = singular_run(law)
    S = tr.meta["summary"]
    h = tr.cols("hx", "hy", "hz")
    h0 = scene.cmg.h_rotor
    # they went through the singular region (not around it) ...
    assert S["min_singularity"] < 0.01
    t_sing = tr.t[np.argmin(tr["cmg_singularity"])]
    assert h[np.argmin(tr["cmg_singularity"])] @ e == pytest.approx(stall_point(scene), abs=0.02 * h0)
    # ... and past it: well beyond 2 cos β h0 along the command at the end
    assert h[-1] @ e > stall_point(scene) + 0.5 * h0
    # with the commanded torque delivered again after the passage (last 5 s: ≥ 95 % of 100 N m)
    last = tr.t >= tr.t[-1] - 5.0
    rate = (h[last][-1] - h[last][0]) @ e / 5.0
    assert rate == pytest.approx(100.0, rel=0.05)
    # the passage needed no gimbal rate beyond the limit
    assert S["rate_limited_ticks"] == 0
    assert t_sing < tr.t[-1] - 5.0


@pytest.mark.parametrize(
    "law,escapes",
    [("mp", False), ("sr", False), ("odsr", True)],
    ids=["mp-trapped", "sr-trapped", "odsr-escapes"],
)
def test_exactly_symmetric_command_traps_sr_but_not_odsr(law, escapes):
    """Command exactly along -x: the gimbals stay in δ2 = δ4 = 0 where Âᵀ x̂ = 0 at the singularity,
    so SR's diagonal λI gives no rate and SR is trapped like MP; o-DSR's off-diagonal dither
    (Wie 2005) turns the command out of the singular direction and escapes."""
    scene, tr, e = singular_run(law, symmetric=True)
    final = tr.cols("hx", "hy", "hz")[-1] @ e
    if escapes:
        assert final > stall_point(scene) + 0.3 * scene.cmg.h_rotor
    else:
        assert final == pytest.approx(stall_point(scene), abs=0.01 * scene.cmg.h_rotor)


# =============================================================================================
# (d) the formulations agree on CMG scenes
# =============================================================================================
PAIRS = list(itertools.combinations(FORMS, 2))


@pytest.mark.slow
@pytest.mark.parametrize("pair", PAIRS, ids=[f"{a}-vs-{b}" for a, b in PAIRS])
@pytest.mark.parametrize("kind", KINDS)
def test_formulations_agree_with_a_cmg(kind, pair):
    a, b = (run(kind, f) for f in pair)
    att, rate, H = compare(a, b)
    w_scale = np.max(np.linalg.norm(a.omega_BN_B, axis=1))
    h_scale = np.max(np.linalg.norm(a.H_O_N, axis=1)) + np.max(np.linalg.norm(a.cols("hx", "hy", "hz"), axis=1))
    tol = AGREE_GAIN * RTOL
    assert att <= tol
    assert rate <= tol * w_scale
    assert H <= tol * h_scale
    dh = np.max(np.abs(a.cols("hx", "hy", "hz") - b.cols("hx", "hy", "hz")))
    assert dh <= tol * h_scale
    if kind != "ideal":
        names = [c for c in a.columns if c.startswith("gimbal_") and not c.endswith("_rate")]
        assert np.max(np.abs(a.cols(*names) - b.cols(*names))) <= tol  # rad
