"""Every executor of a run against the momentum balance, a truth none of them shares (issue 19 A1,
DESIGN §8.4).

What the executors share (the held inputs, where a run is cut, the held commands) is not checked
by comparing them with each other: a bug they share passes such a check (issue 19: a torque
window whose edges lay on the 0.1 s tick grid acted over [stop, end) instead of [start, stop) in
every closed-loop path, and the equivalence tests passed). Here each executor is held to

* the momentum balance ``ΔH_N(t) = ∫_0^t C_NB L_B dt``: the total angular momentum about the
  mass centre (body + CMG cluster) changes only by the external torque's impulse;
* closed forms where the balance reduces to ``impulse = F t_on``: a spherical body under torques
  about one body axis turns about that axis only, so ``C_NB L_B = C_NB(0) L_B`` exactly;
* the held command: each command of a controller acts over exactly its own period
  ``[t_k, t_k+1)``, so with no cluster (the request acts on the body) ``ΔH_N = Σ τ_k Δt_k``.

The integrals are computed here from the logged attitude and hand-written torque models
(gravity gradient, orbital harmonics; aero and SRP from the logged torque columns, whose models
test_aero.py and test_srp.py prove), never from the executors' code. Windows are drawn by
hypothesis with edges on the tick grid, off it, at 0, at the duration and beyond it.

Executors: the generic per-period path (``RK4Generic``: RK4 declared not fusable; ``dop853``),
the per-tick fused tick (``rk4``, ``fused=False``), the fused loop (``rk4`` with a symbolic
law; it splits its chunks at edges on the tick grid, and flies a tick holding an edge between
ticks as a piece of its own, its step cut at the edge: it takes every run here, asserted), the open loop and the open-loop batch (``simulate_batch``; the
Monte Carlo's closed-loop samples run through ``simulate``, i.e. the executors above).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from balance_helpers import C_NB, torque_integral_N
from stationbed import simulate, simulate_batch
from stationbed.integrators import RK4
from stationbed.run.controller import Controller
from stationbed.core.rotation import rotation_angle
from stationbed.scene import scene_from_dict

PERIOD_S = 0.1  # s, the control period and RK4 step (10 Hz, as the shipped scenes)
J_SPHERE = 1.0e6  # kg m², spherical inertia: no gyroscopic coupling, rotation stays about x
L_X = 10.0  # N m, the window's torque about body x
DURATION_S = 20.0  # s, 200 ticks
#: round-off of ~200 RK4 steps of momenta up to ~200 N m s (float64 ε 2e-16 x 200 x 200 x margin)
CLOSED_FORM_ABS = 1e-9  # N m s
#: a misplaced tick is L_X * PERIOD_S = 1 N m s: every tolerance here is far below it
ONE_TICK_NMS = L_X * PERIOD_S


class RK4Generic(RK4):
    """RK4 declared not fusable: the closed loop takes the generic per-period path."""

    fusable = False


#: executor -> (the scene's integrator, simulate's integrator override, simulate's fused flag)
CLOSED = {
    "generic_rk4": ("rk4", RK4Generic, False),
    "fast_tick": ("rk4", None, False),
    "fused": ("rk4", None, True),
    "dop853": ("dop853", None, False),
}


def _set(d: dict, **over) -> dict:
    for path, value in over.items():
        node = d
        keys = path.split(".")
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    return d


def sphere_scene(windows, *, integrator="rk4", controller=True, cmg=True, duration=DURATION_S) -> dict:
    """A spherical body in deep space; ideal CMG and ``pd`` holding inertial (closed loop), or
    nothing (open loop); ``windows``: (start, stop) pairs of ``L_X`` about body x."""
    d = {
        "name": "balance_sphere",
        "simulation": {"duration": duration, "integrator": integrator, "output_dt": 1.0,
                       "rtol": 1e-12, "atol": 1e-14},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 1.0e3, "inertia": [[J_SPHERE, 0, 0], [0, J_SPHERE, 0], [0, 0, J_SPHERE]]},
        "torque": [{"kind": "constant", "torque_B": [L_X, 0.0, 0.0], "start": a, "stop": b} for a, b in windows],
    }
    if integrator != "dop853":
        d["simulation"]["step"] = PERIOD_S
    if cmg:
        d["cmg"] = {"kind": "ideal"}
    if controller:
        d["controller"] = {"name": "pd", "period": PERIOD_S,
                           "params": {"reference": "inertial", "bandwidth": 0.05, "damping": 0.9}}
    return d


def window_impulse_x(windows, t) -> np.ndarray:
    """``L_X`` times the time each window [start, stop) overlaps [0, t], per time in ``t``."""
    t = np.asarray(t, dtype=float)
    total = np.zeros_like(t)
    for a, b in windows:
        total += L_X * np.clip(np.minimum(b, t) - max(a, 0.0), 0.0, None)
    return total


def run_closed(executor: str, windows, **kw):
    integrator, override, fused = CLOSED[executor]
    tr = simulate(scene_from_dict(sphere_scene(windows, integrator=integrator, **kw)), integrator=override, fused=fused)
    used = tr.meta["summary"]["fused"]
    # the fused loop takes every run (an edge between ticks: the edge tick's case), the others none
    assert used == (executor == "fused"), tr.meta["summary"]
    return tr


# ---------------------------------------------------------------------------------------------
# edges: property-based (few examples: one compiled system serves all, windows are held inputs)
# ---------------------------------------------------------------------------------------------

on_grid = st.integers(-3, int(DURATION_S / PERIOD_S) + 3).map(lambda k: k * PERIOD_S)  # the tick clock's own floats
off_grid = st.floats(-0.5, DURATION_S + 0.5, allow_nan=False).filter(lambda v: abs(v / PERIOD_S - round(v / PERIOD_S)) > 1e-6)
ends = st.sampled_from([0.0, DURATION_S, DURATION_S + 5.0, -math.inf, math.inf])
edge = st.one_of(on_grid, off_grid, ends)
window = st.tuples(edge, edge).filter(lambda w: w[1] > w[0]).map(tuple)
windows_st = st.lists(window, min_size=1, max_size=2)

EDGE_SETTINGS = settings(max_examples=12, deadline=None, derandomize=True,
                         suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@pytest.mark.parametrize("executor", list(CLOSED))
@EDGE_SETTINGS
@given(windows=windows_st)
def test_window_impulse_closed_loop(executor, windows):
    """Closed loop (ideal CMG, pd holding inertial, spherical body): at every row the total
    angular momentum has changed by exactly L_X times the windows' time on so far, along N's x."""
    tr = run_closed(executor, windows)
    dH = tr.H_O_N - tr.H_O_N[0]
    expect = window_impulse_x(windows, tr.t)
    assert_allclose(dH[:, 0], expect, rtol=0, atol=CLOSED_FORM_ABS)
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)


@EDGE_SETTINGS
@given(windows=windows_st)
def test_window_impulse_open_loop(windows):
    """Open loop (no controller, no cluster): the same closed form, RK4 at 0.1 s."""
    tr = simulate(scene_from_dict(sphere_scene(windows, controller=False, cmg=False)))
    dH = tr.H_O_N - tr.H_O_N[0]
    assert_allclose(dH[:, 0], window_impulse_x(windows, tr.t), rtol=0, atol=CLOSED_FORM_ABS)
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)


#: DOP853 at rtol 1e-12 on a momentum of up to ~200 N m s, and the batch's dense output
BATCH_ABS = 1e-8  # N m s


@settings(max_examples=6, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.filter_too_much])
@given(windows=windows_st)
def test_window_impulse_batch(windows):
    """The open-loop batch (``simulate_batch``, DOP853 in lockstep): three samples at different
    initial attitudes; each turns about its body x, fixed in N, so ``ΔH_N = C_NB(q0) x̂ L_X t_on``."""
    scene = scene_from_dict(sphere_scene(windows, integrator="dop853", controller=False, cmg=False))
    q0s = np.array([[1.0, 0.0, 0.0, 0.0], [0.8, 0.6, 0.0, 0.0], [0.5, 0.5, -0.5, 0.5]])
    res = simulate_batch(scene, q0s, np.zeros((3, 3)))
    assert res.ok.all()
    for i, q in enumerate(q0s):
        x_N = C_NB(q)[:, 0]
        expect = window_impulse_x(windows, res.t)[:, None] * x_N
        assert_allclose(res.H_O_N[i] - res.H_O_N[i, 0], expect, rtol=0, atol=BATCH_ABS)


# ---------------------------------------------------------------------------------------------
# the held command: each command acts over exactly its own period
# ---------------------------------------------------------------------------------------------

TAU_AMP = 5.0  # N m
TAU_W = 0.7  # rad/s: the command changes by up to 0.35 N m per tick: a shifted hold is ~1 N m s off


def tau_x(t):
    """The commanded torque about body x at tick time t [N m] (numpy or casadi)."""
    import casadi as ca

    return TAU_AMP * (ca.sin(TAU_W * t) if isinstance(t, (ca.SX, ca.MX)) else math.sin(TAU_W * t))


class SineTorque(Controller):
    """Open-loop torque about body x, ``τ(t_k) = TAU_AMP sin(TAU_W t_k)`` at each tick, in
    Python and in casadi (so the fused loop can run it)."""

    name = "sine_torque"
    command = "torque"

    def _reset(self, plant):
        self.t = []

    def _update(self, t, meas):
        self.t.append(t)
        return (tau_x(t), 0.0, 0.0)

    def symbolic_params(self):
        return []

    def symbolic(self, t, y, cp):
        import casadi as ca

        return ca.vertcat(tau_x(t), 0.0, 0.0), ca.DM([1.0, 0.0, 0.0, 0.0])


def held_command_impulse(t_rows, duration, period=PERIOD_S) -> np.ndarray:
    """``Σ_k τ(t_k) (t_k+1 - t_k)`` over the ticks before each row time, t_k = k period, the last
    period cut at the duration: a zero-order hold, summed by hand."""
    K = math.ceil(duration / period - 1e-9)
    ts = np.arange(K + 1) * period
    ts[-1] = duration
    dt = np.diff(ts)
    cum = np.concatenate([[0.0], np.cumsum([tau_x(t) * h for t, h in zip(ts[:-1], dt)])])
    return np.interp(t_rows, ts, cum)  # rows lie on ticks: exact picks


@pytest.mark.parametrize("executor", list(CLOSED))
@pytest.mark.parametrize(
    "windows", [[], [(5.0, 12.0)], [(5.03, 12.07)], [(0.0, 30.0)]], ids=["none", "on_grid", "off_grid", "whole"]
)
def test_held_command_acts_over_its_period(executor, windows):
    """No cluster: the torque request acts on the body. The momentum at every row is the sum of
    the commands, each times its own period, plus the windows' impulse; the last period is short
    (duration 10.05 s) and its command acts over 0.05 s."""
    integrator, override, fused = CLOSED[executor]
    duration = 10.05
    d = sphere_scene(windows, integrator=integrator, cmg=False, duration=duration)
    d["controller"] = {"name": "sine_torque", "period": PERIOD_S}
    d["simulation"]["output_dt"] = 0.5
    ctrl = SineTorque(period=PERIOD_S)
    tr = simulate(scene_from_dict(d), integrator=override, controller=ctrl, fused=fused)
    assert tr.meta["summary"]["fused"] == (executor == "fused")
    dH = tr.H_O_N - tr.H_O_N[0]
    expect = held_command_impulse(tr.t, duration) + window_impulse_x(windows, tr.t)
    assert tr.t[-1] == duration
    assert_allclose(dH[:, 0], expect, rtol=0, atol=CLOSED_FORM_ABS)
    assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)


# ---------------------------------------------------------------------------------------------
# every external-torque kind: ΔH_N = ∫ C_NB L_B dt from the logged attitude
# ---------------------------------------------------------------------------------------------

MU = 3.986004418e14  # m³/s², the scene's default (Earth)
R_ORBIT = 6778137.0  # m, 400 km up
INCL = 0.9006  # rad
U0 = 0.3  # rad
I_ISS = np.array([[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]])  # kg m²
HARMONIC = {"bias_B": [1.0, -2.0, 0.5], "cos1_B": [0.5, 0.0, -1.0], "sin1_B": [0.0, 2.0, 0.0],
            "cos2_B": [0.3, 0.3, 0.0], "sin2_B": [0.0, 0.0, 0.8]}  # N m
L_WIN = np.array([4.0, -10.0, 3.0])  # N m, the constant window
KIND_DURATION_S = 60.0  # s
Q0_BN = [0.9, 0.3, -0.2, math.sqrt(1.0 - 0.94)]  # unit, scalar first
#: trapezoid over 0.5 s rows of torques that change on the orbit's and the loop's time scales
#: (|L''| < 1e-3 N m/s²: T dt² |L''| / 12 < 1.3e-3 N m s), and the window's attitude interpolation
KIND_ABS = 2e-3  # N m s  (a misplaced tick is >= 1 N m s)


def kinds_scene(windows, integrator="rk4", controller=True) -> dict:
    """The JEOD ISS inertia in a 400 km orbit with every torque kind: gravity gradient, orbital
    harmonics, aero and SRP on a truss box and a plate, and constant windows ``L_WIN``."""
    d = {
        "name": "balance_kinds",
        "simulation": {"duration": KIND_DURATION_S, "integrator": integrator, "output_dt": 0.5,
                       "rtol": 1e-12, "atol": 1e-12},
        "initial": {"q_BN": Q0_BN, "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 4.0e5, "inertia": I_ISS.tolist(), "cm": [0.0, 0.0, 0.0]},
        "orbit": {"radius": R_ORBIT, "inclination": INCL, "u0": U0, "gravity_gradient": True},
        "sun": {"beta": 0.1, "u_noon": 0.5, "eclipse": "conical"},
        "torque": [{"kind": "aero"}, {"kind": "srp"}, {"kind": "orbital_harmonic", **HARMONIC}]
        + [{"kind": "constant", "torque_B": L_WIN.tolist(), "start": a, "stop": b} for a, b in windows],
        "surface": [
            {"name": "truss", "size": [5.0, 100.0, 5.0], "centre": [0.0, 2.0, 0.0]},
            {"name": "panel", "area": 400.0, "normal": [0.0, 0.6, 0.8], "centre": [-5.0, 1.5, 6.0]},
        ],
    }
    if integrator != "dop853":
        d["simulation"]["step"] = PERIOD_S
    if controller:
        d["cmg"] = {"kind": "ideal"}
        d["controller"] = {"name": "pd", "period": PERIOD_S,
                           "params": {"reference": "inertial", "q_ref": d["initial"]["q_BN"], "bandwidth": 0.05}}
    return d


def smooth_torque_B(tr) -> np.ndarray:
    """Gravity gradient and orbital harmonics by hand, aero and SRP from their logged columns,
    at every row (N m, B components), shape (N, 3)."""
    n = math.sqrt(MU / R_ORBIT**3)
    out = np.zeros((len(tr.t), 3))
    for j, (t, q) in enumerate(zip(tr.t, tr.q_BN)):
        u = U0 + n * t
        R_N = np.array([math.cos(u), math.sin(u) * math.cos(INCL), math.sin(u) * math.sin(INCL)])
        R_B = C_NB(q).T @ R_N
        gg = 3 * n**2 * np.cross(R_B, I_ISS @ R_B)
        h = HARMONIC
        harm = (np.array(h["bias_B"]) + np.array(h["cos1_B"]) * math.cos(u) + np.array(h["sin1_B"]) * math.sin(u)
                + np.array(h["cos2_B"]) * math.cos(2 * u) + np.array(h["sin2_B"]) * math.sin(2 * u))
        out[j] = gg + harm
    out += tr.cols("tau_aero_x", "tau_aero_y", "tau_aero_z") + tr.cols("tau_srp_x", "tau_srp_y", "tau_srp_z")
    return out


def window_integral_N(tr, windows) -> np.ndarray:
    """``∫ C_NB L_WIN dt`` over the windows ∩ [0, t_row], per row (N, 3): the attitude between rows
    by normalised linear interpolation of q, the pieces cut at the windows' edges, trapezoids."""
    t = tr.t
    q = tr.q_BN
    edges = sorted({e for w in windows for e in w if t[0] < e < t[-1]})
    nodes = np.union1d(t, edges)
    qn = np.column_stack([np.interp(nodes, t, q[:, i]) for i in range(4)])
    f = np.array([C_NB(qq) @ L_WIN for qq in qn])
    cum = np.zeros((len(nodes), 3))
    for i in range(1, len(nodes)):
        a, b = nodes[i - 1], nodes[i]
        on = any(w0 <= 0.5 * (a + b) < w1 for w0, w1 in windows)
        cum[i] = cum[i - 1] + (0.5 * (f[i - 1] + f[i]) * (b - a) if on else 0.0)
    return cum[np.searchsorted(nodes, t)]


def smooth_integral_N(tr) -> np.ndarray:
    return torque_integral_N(tr, smooth_torque_B(tr))


def test_the_balance_scene_has_every_registered_torque_kind():
    """A kind added to the registry must join the balance below (and its torque its integral)."""
    from stationbed.model.torques import TORQUES

    scene = scene_from_dict(kinds_scene([(20.0, 40.0)]))
    assert [k for k, cls in TORQUES.items() if not cls.present(scene)] == []


KIND_WINDOWS = {
    "on_grid": [(20.0, 40.0)],
    "off_grid": [(20.05, 40.03)],
    "whole": [(0.0, KIND_DURATION_S)],
    "beyond": [(30.0, 1.0e6), (-5.0, 10.0)],
}
KIND_EXECUTORS = {**CLOSED, "open_loop_rk4": ("rk4", None, None), "open_loop_dop853": ("dop853", None, None)}


@pytest.mark.parametrize("case", list(KIND_WINDOWS))
@pytest.mark.parametrize("executor", list(KIND_EXECUTORS))
def test_every_torque_kind_balance(executor, case):
    """Gravity gradient, orbital harmonics, aero, SRP and a constant window together: at every row
    ``H_N(t) - H_N(0) = ∫_0^t C_NB L_B dt`` (the cluster's momentum included)."""
    windows = KIND_WINDOWS[case]
    integrator, override, fused = KIND_EXECUTORS[executor]
    closed = fused is not None
    tr = simulate(scene_from_dict(kinds_scene(windows, integrator, controller=closed)), integrator=override,
                  fused=bool(fused))
    if closed:
        assert tr.meta["summary"]["fused"] == (executor == "fused")
    expect = smooth_integral_N(tr) + window_integral_N(tr, windows)
    assert np.abs(expect[-1]).max() > 100 * ONE_TICK_NMS  # the balance has something to check
    assert_allclose(tr.H_O_N - tr.H_O_N[0], expect, rtol=0, atol=KIND_ABS)


def test_every_torque_kind_balance_batch():
    """The open-loop batch on the same scene (window on the grid): each sample's balance."""
    windows = KIND_WINDOWS["on_grid"]
    scene = scene_from_dict(kinds_scene(windows, "dop853", controller=False))
    q0s = np.array([Q0_BN, [1.0, 0.0, 0.0, 0.0]])
    res = simulate_batch(scene, q0s, np.zeros((2, 3)))
    assert res.ok.all()
    for i, q0 in enumerate(q0s):
        tr = simulate(scene.replace({"initial.q_BN": q0.tolist()}))  # for the aero/SRP columns only
        assert_allclose(res.q_BN[i], tr.q_BN, rtol=0, atol=1e-9)
        expect = smooth_integral_N(tr) + window_integral_N(tr, windows)
        assert_allclose(res.H_O_N[i] - res.H_O_N[i, 0], expect, rtol=0, atol=KIND_ABS)


# ---------------------------------------------------------------------------------------------
# the lockstep batch executor (stationbed/run/lockstep.py, issue 22): its own balance
# ---------------------------------------------------------------------------------------------

#: the samples of one batch: sample i's windows shifted by i x LOCKSTEP_SHIFT_S (off the tick
#: grid for i = 1), so the batch carries edges on and off the grid at once
LOCKSTEP_SHIFT_S = 0.037


def _lockstep(scenes, itself: bool = False):
    """The samples' results in the lockstep batch: through run_lockstep (each must be chosen for
    the batch), or with ``itself`` the batch run directly (a law with only ``_update``, which
    run_lockstep sends per tick: the batch's default looping update_batch)."""
    from stationbed.run.lockstep import run_lockstep  # noqa: PLC0415

    if itself:
        from scenes import lockstep_batch  # noqa: PLC0415

        return lockstep_batch(scenes)
    res = run_lockstep(scenes, keep=True, fused=False)
    # every sample in the batch: one with an edge between ticks flies that tick as the edge tick's case
    assert [k for k, _ in res] == ["batch"] * len(scenes), [k for k, _ in res]
    return [tr for _, tr in res]


@EDGE_SETTINGS
@given(windows=windows_st)
def test_window_impulse_lockstep(windows):
    """Three samples in lockstep (ideal CMG, pd holding inertial, its vectorised update_batch),
    each with its own windows: at every row each sample's ΔH_N is L_X times its own windows'
    time on so far, along N's x."""
    per = [[(a + i * LOCKSTEP_SHIFT_S, b + i * LOCKSTEP_SHIFT_S) for a, b in windows] for i in range(3)]
    for w, tr in zip(per, _lockstep([scene_from_dict(sphere_scene(w)) for w in per])):
        dH = tr.H_O_N - tr.H_O_N[0]
        assert_allclose(dH[:, 0], window_impulse_x(w, tr.t), rtol=0, atol=CLOSED_FORM_ABS)
        assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)


@pytest.mark.parametrize(
    "windows", [[], [(5.0, 12.0)], [(5.03, 12.07)]], ids=["none", "on_grid", "off_grid"]
)
def test_held_command_acts_over_its_period_lockstep(windows):
    """The held-command balance for the batch executor, with the default (looping)
    update_batch of a law that has none (SineTorque, loaded by module:Class): every command acts
    over its own period, the short last one included, for each of two samples."""
    duration = 10.05
    scenes = []
    for _ in range(2):
        d = sphere_scene(windows, cmg=False, duration=duration)
        d["controller"] = {"name": f"{__name__}:SineTorque", "period": PERIOD_S}
        d["simulation"]["output_dt"] = 0.5
        scenes.append(scene_from_dict(d))
    for tr in _lockstep(scenes, itself=True):
        dH = tr.H_O_N - tr.H_O_N[0]
        assert tr.t[-1] == duration
        expect = held_command_impulse(tr.t, duration) + window_impulse_x(windows, tr.t)
        assert_allclose(dH[:, 0], expect, rtol=0, atol=CLOSED_FORM_ABS)
        assert_allclose(dH[:, 1:], 0.0, rtol=0, atol=CLOSED_FORM_ABS)

# sensors and the MEKF flown (issue 20): the law flies on the estimate, the balance still holds
# ---------------------------------------------------------------------------------------------

SENSED = {
    "sensor": [
        {"kind": "gyro", "name": "g", "period": PERIOD_S, "sigma_v": 1e-5, "sigma_u": 1e-7, "bias0": [2e-5, -1e-5, 3e-5]},
        {"kind": "star_tracker", "name": "h", "period": 1.0, "boresight_B": [0.0, 0.0, 1.0],
         "nea_cross": 2e-5, "nea_about": 1e-4},
    ],
    "estimator": {"kind": "mekf"},
}


@pytest.mark.parametrize("executor", list(CLOSED))
def test_window_impulse_with_sensors_and_mekf(executor):
    """The pd law on the MEKF's estimate (noisy gyro and head): the estimate's noise turns the
    sphere about every axis, so the closed form above no longer applies, but the balance does:
    ``ΔH_N = ∫ C_NB L_B dt`` over the windows, integrated here from the attitude logged at every
    tick (trapezoids cut at the window edges). Its quadrature error is bounded by the data,
    ``Σ h/12 |Δ²f|`` over the windows' intervals (trapezoid error h³/12 |f''|, f'' ≈ Δ²f/h²),
    plus round-off. The fused loop takes the run (edges on the tick grid)."""
    windows = [(0.0, 5.0), (12.3, 15.0)]
    integrator, override, fused = CLOSED[executor]
    d = {**sphere_scene(windows, integrator=integrator), **SENSED}
    d["simulation"]["output_dt"] = PERIOD_S
    tr = simulate(scene_from_dict(d), integrator=override, fused=fused)
    assert tr.meta["summary"]["fused"] == (executor == "fused")
    assert "nees" in tr.columns
    t, q = tr.t, tr.q_BN
    nodes = np.union1d(t, [e for w in windows for e in w if t[0] < e < t[-1]])
    qn = np.column_stack([np.interp(nodes, t, q[:, i]) for i in range(4)])
    f = np.array([C_NB(qq) @ np.array([L_X, 0.0, 0.0]) for qq in qn])
    d2 = np.abs(np.diff(f, 2, axis=0)).max()
    cum, bound = np.zeros((len(nodes), 3)), 0.0
    for i in range(1, len(nodes)):
        a, b = nodes[i - 1], nodes[i]
        if any(w0 <= 0.5 * (a + b) < w1 for w0, w1 in windows):
            cum[i] = cum[i - 1] + 0.5 * (f[i - 1] + f[i]) * (b - a)
            bound += (b - a) / 12 * d2
        else:
            cum[i] = cum[i - 1]
    dH = tr.H_O_N - tr.H_O_N[0]
    assert bound < 1e-3 * ONE_TICK_NMS  # the check can still see a misplaced tick
    assert_allclose(dH, cum[np.searchsorted(nodes, t)], rtol=0, atol=bound + CLOSED_FORM_ABS)


#: the environment torques at their own rate (issue 25, stationbed/run/env_block.py): every tick, and
#: a whole 0.5 s row (5 ticks, the most a block spans here); the held torque's error averages out
#: over each block to ~|L''| Δ² (docs/design.md), far inside KIND_ABS
#: each option, and the default ("auto": the bound's choice, here the row's 5 ticks)
ENV_RATES = [1, 5, "auto"]


@pytest.mark.parametrize("fused", [True, False], ids=["fused", "fast_tick"])
@pytest.mark.parametrize("case", ["on_grid", "whole"])
@pytest.mark.parametrize("rate", ENV_RATES, ids=[f"env_every_{n}" for n in ENV_RATES])
def test_every_torque_kind_balance_at_each_environment_rate(rate, case, fused):
    """The fused loop and the per-tick loop (the composed parts' env block, run/parts.py) with aero and SRP
    held over blocks of ``rate`` ticks keep the balance (the integral takes the every-stage
    torque columns the run logs); the window's edges on the grid cut the blocks."""
    windows = KIND_WINDOWS[case]
    d = kinds_scene(windows)
    d["simulation"]["environment_rate"] = rate
    tr = simulate(scene_from_dict(d), fused=fused)
    assert tr.meta["summary"]["fused"] == fused and tr.meta["summary"]["environment_rate_ticks"] == (5 if rate == "auto" else rate)
    expect = smooth_integral_N(tr) + window_integral_N(tr, windows)
    assert_allclose(tr.H_O_N - tr.H_O_N[0], expect, rtol=0, atol=KIND_ABS)


#: the per-tick tick against the fused chunk's: the same operations, a tick's time k h against
#: t0 + i h (round-off in t over 600 ticks; a block not cut at an edge is 1.6e-7 rad off)
EXECUTOR_ROUNDOFF_RAD = 1e-14
#: per sample, its window's edges on the grid at its own ticks: each sample's blocks are cut
#: at its own edges (the batch evaluates the environment for the samples whose block starts)
HELD_BATCH_WINDOWS = [[(20.0, 40.0)], [(20.3, 33.7)], [(0.0, KIND_DURATION_S)]]


def test_every_torque_kind_balance_lockstep_at_the_default_rate():
    """Three samples in the lockstep batch with aero and SRP held at the default (``auto``:
    5 ticks here), each with windows on the grid at its own ticks: each sample's balance, each
    is its single per-tick run bit for bit, and the fused run (the same blocks, cut at the same
    edges) to round-off."""
    scenes = [scene_from_dict(kinds_scene(w)) for w in HELD_BATCH_WINDOWS]
    for w, tr, scene in zip(HELD_BATCH_WINDOWS, _lockstep(scenes), scenes):
        assert tr.meta["summary"]["environment_rate_ticks"] == 5
        np.testing.assert_array_equal(tr.data, simulate(scene, fused=False).data)
        fused = simulate(scene, fused=True)
        assert fused.meta["summary"]["fused"]
        assert float(np.max(rotation_angle(tr.q_BN, fused.q_BN))) <= EXECUTOR_ROUNDOFF_RAD
        expect = smooth_integral_N(tr) + window_integral_N(tr, w)
        assert_allclose(tr.H_O_N - tr.H_O_N[0], expect, rtol=0, atol=KIND_ABS)


def test_torque_kind_balance_on_sensors_and_mekf_at_the_default_rate():
    """The fused flight loop (the pd law on the MEKF's estimate) with aero and SRP held at the
    default rate (``auto``: the bound holds on the estimate's loop, run/rate_auto.py; here the
    row's 5 ticks) keeps the balance: the same integral of the logged torque columns."""
    windows = KIND_WINDOWS["whole"]
    d = {**kinds_scene(windows), **SENSED}
    tr = simulate(scene_from_dict(d), fused=True)
    s = tr.meta["summary"]
    assert s["fused"] and "nees" in tr.columns and (s["environment_rate_asked"], s["environment_rate_ticks"]) == ("auto", 5)
    expect = smooth_integral_N(tr) + window_integral_N(tr, windows)
    assert_allclose(tr.H_O_N - tr.H_O_N[0], expect, rtol=0, atol=KIND_ABS)
