"""Optional benchmark: the closest Basilisk scene beside stationbed (issue 5, item 4).

    python benchmarks/bench_basilisk.py [--repeats N] [--no-closed-loop] [--json PATH] [--smoke]

Compares with the Basilisk package (``pip install bsk``); without it, says so and runs the
stationbed side of both scenes alone (its rows, times and errors), so the script's own scenes
and paths are exercised anyway (CI runs it with ``--smoke``). Basilisk is never a CI dependency
and no test imports it.

(a) Open loop. A rigid spacecraft with the JEOD ISS inertia of
``scenarios/iss_lvlh_gravity_gradient.toml`` (4.0e5 kg, products of inertia included) in the same
400 km, 51.6 deg circular orbit, point-mass gravity gradient, free drift for one orbit from rest in
LVLH (B = LVLH at t = 0, ``omega_BN_B = (0, -n, 0)``). The two TP-2511 solar-array pairs are left
out on both sides: Basilisk's hub has no prescribed-angle articulated appendage with the
stationbed kinematics. Basilisk: ``spacecraft.Spacecraft`` (its default RK4, fixed step = task
rate), a point-mass Earth (no spherical harmonics, ``mu`` set to stationbed's) and
``GravityGradientEffector``; Basilisk integrates the orbit, stationbed uses the analytic circular
orbit. stationbed: ``stationbed.simulate`` of the same scene (momentum formulation) with rk4 at
the same step and dop853 at rtol 1e-9. Both give ``q_BN`` (Basilisk's ``sigma_BN`` converted);
the attitude difference must be of the size of the integration error.

(b) Closed loop (``--no-closed-loop`` skips it): the rigid principal-axis station of
``scenarios/iss_lvlh_hold.toml`` (no arrays, no aero-like torque), 4 CMGs, a 10 Hz attitude
controller holding LVLH from the scene's 0.55 deg initial error, one orbit. Basilisk: 4
``vscmgStateEffector`` units (gimbal + wheel dynamics, RK4 at 0.1 s) driven by hillPoint ->
attTrackingError -> mrpFeedback -> vscmgVelocitySteering -> vscmgGimbalRateServo at 10 Hz;
stationbed: the iss_lvlh_hold scene without arrays / aero torque, its 10 Hz ``pd`` and 4 DGCMGs
(momentum-exchange model, gimbal rates commanded), rk4 at 0.1 s, fused and per-tick Python paths.
The two loops are comparable in cost and task, not equivalent in numbers (different laws and
actuator models): only wall times and final pointing errors are reported.

Timing: one warm-up run each (stationbed compiles or loads its cached build; Basilisk loads its
libraries), then ``--repeats`` runs interleaved, median wall time. Basilisk's time counts the
scene construction and ``InitializeSimulation`` + ``ExecuteSimulation`` (it cannot be re-run
without re-building); the construction alone is reported too.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

try:
    import Basilisk  # noqa: F401
except ImportError:
    Basilisk = None

OPEN_SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
HOLD_SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"
STEPS_S = (1.0, 0.1)  # fixed steps compared in (a) [s]
RTOL, ATOL = 1e-9, 1e-12  # stationbed dop853 row of (a)
OUTPUT_DT_S = 10.0  # attitude compared every 10 s [s]


# ----------------------------------------------------------------------------- scenes
def _orbit_params(data: dict) -> tuple[float, float, float, float]:
    """``(radius [m], inclination [rad], mu [m3/s2], n [rad/s])`` of a scene's [orbit] table."""
    from stationbed.scene import scene_from_dict

    o = scene_from_dict(data).orbit
    return o.radius_m, o.inclination, o.mu, o.mean_motion


def _duration_s(n: float) -> float:
    """One orbit rounded to whole seconds, so every compared step divides it exactly."""
    return float(round(2.0 * math.pi / n))


def open_loop_scene(duration: float | None = None) -> dict:
    """iss_lvlh_gravity_gradient without its array pairs, one orbit (or ``duration`` [s]), output every 10 s."""
    data = tomllib.loads(OPEN_SCENE.read_text())
    data.pop("appendage", None)
    data["name"] = "iss_rigid_lvlh_gravity_gradient"
    _, _, _, n = _orbit_params(data)
    sim = data["simulation"]
    sim["duration"] = duration or _duration_s(n)
    sim["output_dt"] = OUTPUT_DT_S
    return data


#: the tables of iss_lvlh_hold that go with its arrays and environment: the arrays themselves, the
#: sun they track, the aero and solar-pressure torques and the surfaces those act on (two of which
#: ride on the arrays: a surface on a missing array, or one no torque uses, is a scene error)
HOLD_DROPPED = ("appendage", "torque", "sun", "surface", "atmosphere")


#: the environment rate of the full-scene row (issue 25: the largest whose proven bound is inside
#: 1e-6 rad per orbit, docs/design.md "Effects at their own rate")
FULL_ENV_RATE = 20


def hold_scene(duration: float | None = None) -> dict:
    """iss_lvlh_hold without arrays, sun, surfaces and their torques, one orbit (or ``duration`` [s])."""
    data = tomllib.loads(HOLD_SCENE.read_text())
    for key in HOLD_DROPPED:
        data.pop(key, None)
    data["name"] = "iss_rigid_lvlh_hold"
    _, _, _, n = _orbit_params(data)
    data["simulation"]["duration"] = duration or _duration_s(n)
    data["simulation"]["output_dt"] = OUTPUT_DT_S
    return data


# ----------------------------------------------------------------------------- Basilisk
def _bsk_base(data: dict, step: float):
    """Basilisk sim with the rigid hub in the scene's orbit, point-mass Earth + gravity gradient."""
    from Basilisk.simulation import GravityGradientEffector, spacecraft
    from Basilisk.utilities import RigidBodyKinematics as rbk
    from Basilisk.utilities import SimulationBaseClass, macros, simIncludeGravBody

    from stationbed.run.initial import initial_state
    from stationbed.scene import scene_from_dict

    scene = scene_from_dict(data)
    r, inc, mu, n = _orbit_params(data)
    u0 = scene.orbit.u0
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("dyn")
    proc.addTask(sim.CreateNewTask("dynTask", macros.sec2nano(step)))
    sc = spacecraft.Spacecraft()
    sc.ModelTag = "station"
    sc.hub.mHub = float(data["body"]["mass"])
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = [list(map(float, row)) for row in data["body"]["inertia"]]
    sim.AddModelToTask("dynTask", sc, 10)
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()  # point mass: no spherical harmonics loaded
    earth.isCentralBody = True
    earth.mu = mu  # stationbed's GM (Basilisk's default differs in the 10th digit)
    grav.addBodiesTo(sc)
    gg = GravityGradientEffector.GravityGradientEffector()
    gg.ModelTag = sc.ModelTag
    gg.addPlanetName(earth.planetName)
    sc.addDynamicEffector(gg)
    sim.AddModelToTask("dynTask", gg, 9)
    # stationbed's orbit: R_N = r (cos u, sin u cos i, sin u sin i), node on N's x axis
    cu, su, ci, si = math.cos(u0), math.sin(u0), math.cos(inc), math.sin(inc)
    sc.hub.r_CN_NInit = [r * cu, r * su * ci, r * su * si]
    v = r * n
    sc.hub.v_CN_NInit = [-v * su, v * cu * ci, v * cu * si]
    q_BN, omega_BN_B = initial_state(scene)
    sc.hub.sigma_BNInit = [[float(s)] for s in rbk.EP2MRP(q_BN)]
    sc.hub.omega_BN_BInit = [[float(w)] for w in omega_BN_B]
    return sim, sc, earth, macros


def _q_from_sigma(sigma: np.ndarray) -> np.ndarray:
    """Rows of MRPs ``sigma_BN`` -> scalar-first ``q_BN`` (same DCM convention, C_BN maps N to B)."""
    s2 = np.sum(sigma * sigma, axis=1, keepdims=True)
    return np.hstack([(1.0 - s2), 2.0 * sigma]) / (1.0 + s2)


def basilisk_open_loop(data: dict, step: float):
    """Run (a) in Basilisk; returns ``(t [s], q_BN rows, build_s, run_s)``."""
    t0 = time.perf_counter()
    sim, sc, _, macros = _bsk_base(data, step)
    rec = sc.scStateOutMsg.recorder(macros.sec2nano(OUTPUT_DT_S))
    sim.AddModelToTask("dynTask", rec)
    t1 = time.perf_counter()
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(data["simulation"]["duration"]))
    sim.ExecuteSimulation()
    t2 = time.perf_counter()
    t = np.asarray(rec.times(), dtype=float) * 1e-9
    return t, _q_from_sigma(np.asarray(rec.sigma_BN)), t1 - t0, t2 - t0


# ----------------------------------------------------------------------------- helpers
def _median_interleaved(runs: dict, repeats: int) -> dict:
    walls = {k: [] for k in runs}
    for _ in range(repeats):
        for k, f in runs.items():  # interleaved: all see the same machine load
            t0 = time.perf_counter()
            f()
            walls[k].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in walls.items()}


def _on_grid(t_ref, q_ref, t, q):
    """``q_ref`` and ``q`` rows at the times the two grids share."""
    idx = {round(x * 1e3): i for i, x in enumerate(t)}  # exact times, in ms
    keep = [(i, idx[round(x * 1e3)]) for i, x in enumerate(t_ref) if round(x * 1e3) in idx]
    a, b = zip(*keep)
    return q_ref[list(a)], q[list(b)]


def _max_angle(t_a, q_a, t_b, q_b) -> float:
    from stationbed.core.rotation import rotation_angle

    qa, qb = _on_grid(t_a, q_a, t_b, q_b)
    return float(np.max(rotation_angle(qa, qb)))


# ----------------------------------------------------------------------------- (a)
def open_loop(repeats: int, bsk: bool = True, duration: float | None = None) -> list[dict]:
    """Rows of (a); without Basilisk (``bsk`` False) the stationbed rows only."""
    import stationbed
    from stationbed.scene import scene_from_dict

    data = open_loop_scene(duration)
    scene = scene_from_dict(data, "bench_basilisk:open")
    ref = stationbed.simulate(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    t_ref, q_ref = ref.t, ref.q_BN
    sb_runs = {f"stationbed rk4 {h:g} s": (lambda h=h: stationbed.simulate(scene, integrator="rk4", step=h))
               for h in STEPS_S}
    sb_runs[f"stationbed dop853 rtol {RTOL:g}"] = lambda: stationbed.simulate(
        scene, integrator="dop853", rtol=RTOL, atol=ATOL)
    bsk_runs = {f"Basilisk RK4 {h:g} s": (lambda h=h: basilisk_open_loop(data, h)) for h in STEPS_S} if bsk else {}
    first = {k: f() for k, f in {**sb_runs, **bsk_runs}.items()}  # warm-up + results
    med = _median_interleaved({**sb_runs, **bsk_runs}, repeats)
    rows = []
    for k, res in first.items():
        if k.startswith("Basilisk"):
            t, q, _, _ = res
            build_s = bsk_runs[k]()[2]  # construction time once the libraries are loaded
        else:
            t, q, build_s = res.t, res.q_BN, None
        rows.append(dict(path=k, wall_s=med[k], build_s=build_s, err_ref_rad=_max_angle(t_ref, q_ref, t, q),
                         t=t, q=q))
    # pairwise: Basilisk vs stationbed at the same step
    dop = next(r for r in rows if r["path"].startswith("stationbed dop853"))
    for h in STEPS_S if bsk else ():
        b = next(r for r in rows if r["path"] == f"Basilisk RK4 {h:g} s")
        s = next(r for r in rows if r["path"] == f"stationbed rk4 {h:g} s")
        b["vs_same_step_rad"] = _max_angle(s["t"], s["q"], b["t"], b["q"])
        b["ratio"] = b["wall_s"] / s["wall_s"]
        b["ratio_dop853"] = b["wall_s"] / dop["wall_s"]
    return rows


# ----------------------------------------------------------------------------- (b)
#: LVLH O -> Hill frame R (Basilisk's hillPoint: r1 radial out, r3 orbit normal): r1 = -z_O,
#: r2 = x_O, r3 = -y_O. Basilisk's body axes are the station's relabelled by this constant DCM, so
#: hillPoint's "B = R" is stationbed's "B = O".
C_RO = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
CMG_H_NMS = 4760.0  # N m s per unit, as iss_lvlh_hold
CMG_OMEGA_RAD_S = 6600.0 * 2.0 * math.pi / 60.0  # ISS CMG rotor speed, 6600 rpm
CMG_IW1 = CMG_H_NMS / CMG_OMEGA_RAD_S  # kg m2, so that IW1 * Omega = 4760 N m s
PYRAMID_RAD = math.radians(54.75)  # skew angle of the 4-unit pyramid (Basilisk's VSCMG tests)


def _vscmg_units():
    """4 single-gimbal VSCMG payloads in a pyramid (Basilisk has no double-gimbal CMG)."""
    from Basilisk.architecture import messaging

    units = []
    ca, sa = math.cos(PYRAMID_RAD), math.sin(PYRAMID_RAD)
    for k in range(4):
        psi = k * math.pi / 2.0
        g = np.array([ca * math.cos(psi), ca * math.sin(psi), sa])  # gimbal axis
        s0 = np.array([-math.sin(psi), math.cos(psi), 0.0])  # spin axis at gamma = 0
        t0 = np.cross(g, s0)
        u = messaging.VSCMGConfigMsgPayload()
        u.rGB_B = [[0.0], [0.0], [0.0]]
        u.gsHat0_B = [[x] for x in s0]
        u.gtHat0_B = [[x] for x in t0]
        u.ggHat_B = [[x] for x in g]
        u.u_s_max = -1
        u.u_s_min = -1
        u.u_s_f = 0.0
        u.wheelLinearFrictionRatio = -1
        u.u_g_current = 0.0
        u.u_g_max = -1
        u.u_g_min = -1
        u.u_g_f = 0.0
        u.gimbalLinearFrictionRatio = -1
        u.Omega = CMG_OMEGA_RAD_S
        u.gamma = 0.0  # zero net momentum: the four spin axes cancel
        u.gammaDot = 0.0
        u.Omega_max = 2.0 * CMG_OMEGA_RAD_S
        u.gammaDot_max = -1
        u.IW1, u.IW2, u.IW3 = CMG_IW1, 0.5 * CMG_IW1, 0.5 * CMG_IW1
        u.IG1, u.IG2, u.IG3 = 2.0, 2.0, 2.0  # kg m2, gimbal frame
        u.U_s = 0.0
        u.U_d = 0.0
        u.l = 0.0
        u.L = 0.0
        u.rGcG_G = [[0.0], [0.0], [0.0]]
        u.massW = 0.0
        u.massG = 0.0
        u.VSCMGModel = 0  # balanced wheels
        units.append(u)
    return units


def basilisk_closed_loop(data: dict, pd_bandwidth: float, pd_damping: float):
    """Run (b) in Basilisk; returns ``(t [s], attitude error from LVLH [rad] rows, run_s)``."""
    from Basilisk.architecture import messaging
    from Basilisk.fswAlgorithms import (attTrackingError, hillPoint, mrpFeedback, vscmgGimbalRateServo,
                                        vscmgVelocitySteering)
    from Basilisk.simulation import simpleNav, vscmgStateEffector
    from Basilisk.utilities import RigidBodyKinematics as rbk
    from Basilisk.utilities import fswSetupVSCMGs

    t0 = time.perf_counter()
    dt = float(data["controller"]["period"])
    data = dict(data, body=dict(data["body"]))
    I_O = np.array(data["body"]["inertia"], dtype=float)
    I_R = C_RO @ I_O @ C_RO.T
    data["body"]["inertia"] = I_R.tolist()
    sim, sc, earth, macros = _bsk_base(data, dt)
    # the initial state in the relabelled body axes
    sig = np.array(sc.hub.sigma_BNInit).ravel()
    C_BN = rbk.MRP2C(sig)
    sc.hub.sigma_BNInit = [[float(x)] for x in rbk.C2MRP(C_RO @ C_BN)]
    sc.hub.omega_BN_BInit = [[float(x)] for x in C_RO @ np.array(sc.hub.omega_BN_BInit).ravel()]
    # actuators
    cmgs = vscmgStateEffector.VSCMGStateEffector()
    cmgs.ModelTag = "cmgs"
    units = _vscmg_units()
    for u in units:
        cmgs.AddVSCMG(u)
    sc.addStateEffector(cmgs)
    sim.AddModelToTask("dynTask", cmgs, 11)
    nav = simpleNav.SimpleNav()
    nav.ModelTag = "nav"
    nav.scStateInMsg.subscribeTo(sc.scStateOutMsg)
    sim.AddModelToTask("dynTask", nav, 8)
    # flight software at 10 Hz (same task rate as the dynamics)
    earth_msg = messaging.EphemerisMsg().write(messaging.EphemerisMsgPayload())  # Earth at rest at N origin
    hill = hillPoint.hillPoint()
    hill.ModelTag = "hill"
    hill.transNavInMsg.subscribeTo(nav.transOutMsg)
    hill.celBodyInMsg.subscribeTo(earth_msg)
    sim.AddModelToTask("dynTask", hill, 7)
    err = attTrackingError.attTrackingError()
    err.ModelTag = "err"
    err.attNavInMsg.subscribeTo(nav.attOutMsg)
    err.attRefInMsg.subscribeTo(hill.attRefOutMsg)
    sim.AddModelToTask("dynTask", err, 6)
    veh = messaging.VehicleConfigMsgPayload()
    veh.ISCPntB_B = I_R.ravel().tolist()
    veh_msg = messaging.VehicleConfigMsg().write(veh)
    ctl = mrpFeedback.mrpFeedback()
    ctl.ModelTag = "mrpFeedback"
    I_mean = float(np.trace(I_O)) / 3.0
    ctl.K = 4.0 * I_mean * pd_bandwidth**2  # sigma ~ theta / 4: same stiffness as the pd [N m]
    ctl.P = 2.0 * pd_damping * pd_bandwidth * I_mean  # [N m s]
    ctl.Ki = -1.0  # no integral term (the pd has none)
    ctl.guidInMsg.subscribeTo(err.attGuidOutMsg)
    ctl.vehConfigInMsg.subscribeTo(veh_msg)
    sim.AddModelToTask("dynTask", ctl, 5)
    fswSetupVSCMGs.clearSetup()
    for u in units:
        fswSetupVSCMGs.create(u.gsHat0_B, u.gtHat0_B, u.ggHat_B, u.IG1, u.IG2, u.IG3, u.IW1, u.IW2, u.IW3,
                              u.Omega, u.gamma, u.gammaDot)
    cfg_msg = fswSetupVSCMGs.writeConfigMessage()
    steer = vscmgVelocitySteering.VscmgVelocitySteering()
    steer.ModelTag = "steer"
    steer.setMu(1e-9)
    steer.setW0_s([200.0] * 4)
    steer.setW_g([1.0] * 4)
    steer.vscmgParamsInMsg.subscribeTo(cfg_msg)
    steer.vehControlInMsg.subscribeTo(ctl.cmdTorqueOutMsg)
    steer.attNavInMsg.subscribeTo(nav.attOutMsg)
    steer.attGuideInMsg.subscribeTo(err.attGuidOutMsg)
    steer.speedsInMsg.subscribeTo(cmgs.speedOutMsg)
    sim.AddModelToTask("dynTask", steer, 4)
    servo = vscmgGimbalRateServo.VscmgGimbalRateServo()
    servo.ModelTag = "servo"
    servo.setK_gammaDot(1.0)
    servo.vsmcgParamsInMsg.subscribeTo(cfg_msg)
    servo.vscmgRefStatesInMsg.subscribeTo(steer.vscmgRefStatesOutMsg)
    servo.attInMsg.subscribeTo(nav.attOutMsg)
    servo.speedsInMsg.subscribeTo(cmgs.speedOutMsg)
    sim.AddModelToTask("dynTask", servo, 3)
    cmgs.cmdsInMsg.subscribeTo(servo.cmdsOutMsg)
    servo.cmdsOutMsg.write(messaging.VSCMGArrayTorqueMsgPayload())  # zero torques before the first FSW tick
    rec = err.attGuidOutMsg.recorder(macros.sec2nano(OUTPUT_DT_S))
    sim.AddModelToTask("dynTask", rec)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(data["simulation"]["duration"]))
    sim.ExecuteSimulation()
    run_s = time.perf_counter() - t0
    sig = np.asarray(rec.sigma_BR)
    ang = 4.0 * np.arctan(np.linalg.norm(sig, axis=1))
    return np.asarray(rec.times(), dtype=float) * 1e-9, ang, run_s


def closed_loop(repeats: int, bsk: bool = True, duration: float | None = None) -> list[dict]:
    """Rows of (b); without Basilisk (``bsk`` False) the stationbed rows only."""
    import stationbed
    from stationbed.model.environment import q_ON
    from stationbed.core.rotation import rotation_angle
    from stationbed.scene import scene_from_dict

    data = hold_scene(duration)
    scene = scene_from_dict(data, "bench_basilisk:hold")
    params = data["controller"]["params"]
    u0, inc, n = scene.orbit.u0, scene.orbit.inclination, scene.orbit.mean_motion

    def lvlh_error(tr):
        q_ON_rows = np.array([q_ON(u0 + n * t, inc) for t in tr.t])
        return rotation_angle(tr.q_BN, q_ON_rows)

    # the issue-25 comparison: the whole iss_lvlh_hold (arrays tracking the sun, aero + SRP on
    # the surfaces, conical eclipse) fused, environment at its bound-chosen rate, same duration
    full = stationbed.load_scene(HOLD_SCENE).replace(
        {"simulation.environment_rate": FULL_ENV_RATE, "simulation.output_dt": OUTPUT_DT_S})
    runs = {
        "stationbed rk4 0.1 s, pd in Python": lambda: stationbed.simulate(scene, fused=False),
        "stationbed rk4 0.1 s, fused": lambda: stationbed.simulate(scene, fused=True),
        f"stationbed iss_lvlh_hold in full (arrays, aero, SRP), fused, environment every {FULL_ENV_RATE} ticks":
            lambda: stationbed.simulate(full, duration=scene.simulation.duration, fused=True),
    }
    if bsk:
        runs["Basilisk RK4 0.1 s, mrpFeedback + VSCMG steering"] = lambda: basilisk_closed_loop(
            data, params["bandwidth"], params["damping"])
    first = {k: f() for k, f in runs.items()}
    med = _median_interleaved(runs, repeats)
    rows = []
    for k, res in first.items():
        ang = res[1] if k.startswith("Basilisk") else lvlh_error(res)
        rows.append(dict(path=k, wall_s=med[k], err0_rad=float(ang[0]), err_end_rad=float(ang[-1]),
                         err_max_last_half_rad=float(np.max(ang[len(ang) // 2:]))))
    fused = rows[1]["wall_s"]
    for r in rows:
        r["ratio_to_fused"] = r["wall_s"] / fused
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-closed-loop", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv)
    duration = _smoke.SMOKE_DURATION_S if args.smoke else None
    import stationbed

    bsk = Basilisk is not None
    if bsk:
        from Basilisk.architecture import bskLogging

        bskLogging.setDefaultLogLevel(bskLogging.BSK_WARNING)
        ver = getattr(Basilisk, "__version__", None) or _bsk_version()
        print(f"Basilisk {ver}, stationbed {stationbed.__version__}, {_smoke.machine()}")
    else:
        print("Basilisk is not installed (optional; `pip install bsk` to compare): the stationbed side of each "
              f"scene runs alone, without Basilisk rows; stationbed {stationbed.__version__}, "
              f"{_smoke.machine()}")
    rows = open_loop(args.repeats, bsk, duration)
    print("\n(a) open loop: rigid JEOD-ISS inertia, gravity gradient, one orbit free drift from LVLH")
    print("| path | wall [s] (median) | Basilisk / stationbed rk4, same step | Basilisk / stationbed dop853 "
          "| max angle vs ref [rad] | max angle Basilisk vs stationbed rk4, same step [rad] |")
    print("|---|---|---|---|---|---|")

    def fmt(r, key, spec):
        return format(r[key], spec) if key in r else "-"

    for r in rows:
        print(f"| {r['path']} | {r['wall_s']:.4f} | {fmt(r, 'ratio', '.1f')} | {fmt(r, 'ratio_dop853', '.0f')} | "
              f"{r['err_ref_rad']:.2e} | {fmt(r, 'vs_same_step_rad', '.2e')} |")
    builds = ", ".join(f"{r['build_s'] * 1e3:.1f} ms" for r in rows if r["build_s"] is not None)
    print("ref: stationbed dop853 rtol 1e-12." + (f" Basilisk wall includes building its sim ({builds} of it)." if bsk else ""))
    out = {"open_loop": [{k: v for k, v in r.items() if k not in ("t", "q")} for r in rows]}
    if not args.no_closed_loop:
        rows_b = closed_loop(args.repeats, bsk, duration)
        print("\n(b) closed loop: rigid principal-axis station, 4 CMGs, 10 Hz attitude control, LVLH hold, one orbit")
        print("| path | wall [s] (median) | / stationbed fused | error from LVLH at t=0 / end / max 2nd half [deg] |")
        print("|---|---|---|---|")
        for r in rows_b:
            print(f"| {r['path']} | {r['wall_s']:.3f} | {r['ratio_to_fused']:.1f} | "
                  f"{math.degrees(r['err0_rad']):.3f} / {math.degrees(r['err_end_rad']):.4f} / "
                  f"{math.degrees(r['err_max_last_half_rad']):.4f} |")
        out["closed_loop"] = rows_b
    _smoke.write_json(args.json, out)
    return 0


def _bsk_version() -> str:
    try:
        from importlib.metadata import version

        return version("bsk")
    except Exception:  # pragma: no cover
        return "?"


if __name__ == "__main__":
    raise SystemExit(main())
