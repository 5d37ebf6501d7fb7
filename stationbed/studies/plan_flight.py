"""``stationbed plan SCENE --out DIR``: plan a slew (stationbed.plan), fly it in the closed loop
with the ``schedule`` law, and fly the same slew as an eigenaxis ``pd`` slew (issue 26).

Writes into DIR: plan.csv, plan.json (with a ``flight`` entry: planned vs flown and the eigenaxis
slew), plan.png, flown.csv, eigenaxis.csv, flight.png, plan.rrd (rerun: ``plan/...`` series of
planned vs flown momentum and attitude, the eigenaxis slew's momentum, the commands) and flown.rrd
(the flown run drawn as ``stationbed run --rrd`` draws it), and summary.json, the flown run's as
``stationbed run`` writes it, naming flown.csv as its rows: DIR is then a run folder to ``stationbed
plot`` and ``compare`` (the flown run's attitude error is to the plan's attitude, issue 32).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.paths import write_bytes, writing
from ..core.plotting import pyplot, save_png
from ..core.rotation import quat_conj, quat_mult, rotation_angle
from ..model.environment import q_ON
from ..plan import PlanError, plan_scene, read_plan, write_plan
from ..run.simulation import simulate

__all__ = ["plan_and_fly", "fly_plan", "eigenaxis_pd_scene", "EIGENAXIS_TIME_FRACTION", "FLIGHT_FILES"]

#: the eigenaxis pd slew's rate limit turns the slew angle in this fraction of the plan's duration
#: (the rest: acceleration, braking and settling of the same law's bandwidth)
EIGENAXIS_TIME_FRACTION = 0.8
#: the files a flight of the plan writes beside plan.json (removed when a new plan is written,
#: flown or not: they would describe the earlier plan)
FLIGHT_FILES = ("flown.csv", "eigenaxis.csv", "flight.png", "plan.rrd", "flown.rrd", "summary.json")


def _relative_attitude(scene, traj) -> np.ndarray:
    """The flown attitude relative to the plan's frame, per row (N, 4)."""
    q = traj.q_BN
    if scene.plan.frame != "lvlh":
        return q
    o = scene.orbit
    out = np.empty_like(q)
    for k, t in enumerate(traj.t):
        out[k] = np.asarray(quat_mult(quat_conj(np.asarray(q_ON(o.u0 + o.mean_motion * t, o.inclination), float)), q[k]))
    return out


def eigenaxis_pd_scene(scene, plan: dict):
    """The same slew flown by the ``pd`` law (Wie's eigenaxis quaternion feedback) to the plan's
    end attitude, with the plan law's bandwidth (√kp) and damping (kd / 2√kp)."""
    spec = scene.plan
    wn = math.sqrt(plan["kp"])
    rate = math.radians(plan["slew_deg"]) / (EIGENAXIS_TIME_FRACTION * spec.duration)
    params = {"reference": "lvlh" if spec.frame == "lvlh" else "inertial", "q_ref": list(spec.q_end),
              "bandwidth": wn, "damping": plan["kd"] / (2.0 * wn), "max_slew_rate": rate}
    period = scene.controller.period if scene.controller else 1.0
    return scene.replace({"controller": {"name": "pd", "period": period, "params": params},
                          "simulation.duration": spec.duration})


def fly_plan(scene, plan_json, out_dir) -> dict:
    """Fly the plan at ``plan_json`` with ``schedule``, and the eigenaxis ``pd`` slew; write the
    trajectories, the comparison chart and the recording; return the ``flight`` summary."""
    out = Path(out_dir)
    plan = read_plan(plan_json)
    period = scene.controller.period if scene.controller else 1.0
    fly_scene = scene.replace({"controller": {"name": "schedule", "period": period,
                                              "params": {"plan": str(Path(plan_json).resolve())}},
                               "simulation.duration": scene.plan.duration})
    flown = simulate(fly_scene)
    with writing(out / "flown.csv") as path:
        flown.to_csv(path)
    summary = {"scene": scene.name, **flown.meta, "rows_file": "flown.csv"}  # a run folder's (cli.py's run)
    with writing(out / "summary.json") as path:
        path.write_text(json.dumps(summary, indent=2, default=str) + "\n")
    eig = simulate(eigenaxis_pd_scene(scene, plan))
    with writing(out / "eigenaxis.csv") as path:
        eig.to_csv(path)
    # compared at the plan's own points (no interpolation of the plan; the flown rows are
    # interpolated, exact where the output grid holds the point)
    t = plan["t"]
    h_flown = np.interp(t, flown.t, np.linalg.norm(flown.cols("hx", "hy", "hz"), axis=1))
    h_plan = np.linalg.norm(plan["h_planned_B"], axis=1)
    q_rel = _relative_attitude(scene, flown)
    q_flown = np.column_stack([np.interp(t, flown.t, q_rel[:, k]) for k in range(4)])
    att = rotation_angle(q_flown, plan["q_BR_planned"])
    h_eig = np.linalg.norm(eig.cols("hx", "hy", "hz"), axis=1)
    sf, se = flown.meta.get("summary", {}), eig.meta.get("summary", {})
    cap = plan["capacity_Nms"]
    q_end = np.asarray(scene.plan.q_end, float)
    flight = {
        "flown_peak_h_Nms": float(np.max(np.linalg.norm(flown.cols("hx", "hy", "hz"), axis=1))),
        "flown_peak_fraction": float(np.max(np.linalg.norm(flown.cols("hx", "hy", "hz"), axis=1))) / cap,
        "flown_vs_planned_max_dh_Nms": float(np.max(np.abs(h_flown - h_plan))),
        "flown_vs_planned_max_attitude_deg": math.degrees(float(np.max(att))),
        "flown_final_error_deg": math.degrees(float(rotation_angle(_relative_attitude(scene, flown)[-1], q_end)[0])),
        "flown_saturated_ticks": sf.get("momentum_saturated_ticks"),
        "flown_rate_limited_ticks": sf.get("rate_limited_ticks"),
        "flown_min_singularity": (float(np.min(flown["cmg_singularity"])) if "cmg_singularity" in flown.columns
                                  else None),
        "eigenaxis_peak_h_Nms": float(np.max(h_eig)),
        "eigenaxis_peak_fraction": float(np.max(h_eig)) / cap,
        "eigenaxis_saturated_ticks": se.get("momentum_saturated_ticks"),
        "eigenaxis_final_error_deg": math.degrees(float(rotation_angle(_relative_attitude(scene, eig)[-1], q_end)[0])),
        "eigenaxis_pd": {k: v for k, v in eigenaxis_pd_scene(scene, plan).controller.params.items() if k != "q_ref"},
    }
    with writing(out / "flight.png") as path:
        _chart(scene, plan, t, h_plan, h_flown, eig.t, h_eig, att, cap, path)
    _record(scene, fly_scene, flown, plan, h_plan, eig.t, h_eig, att, out / "plan.rrd")
    return flight


def _chart(scene, plan, t, h_plan, h_flown, t_eig, h_eig, att, cap, path) -> None:
    plt = pyplot(PlanError)
    fig, ax = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    ax[0].plot(t / 60, h_plan, label="planned")
    ax[0].plot(t / 60, h_flown, "o", ms=3, label="flown (schedule, closed loop)")
    ax[0].plot(t_eig / 60, h_eig, label="eigenaxis pd slew")
    ax[0].axhline(cap, color="k", lw=1, label="capacity")
    ax[0].set_ylabel("|h| [N m s]")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"{scene.name}: planned vs flown, and the eigenaxis slew")
    ax[1].plot(t / 60, np.degrees(att))
    ax[1].set_ylabel("flown vs planned attitude [deg]")
    ax[1].set_xlabel("time [min]")
    save_png(plt, fig, path)


def _record(scene, fly_scene, flown, plan, h_plan, eig_t, h_eig, att, path) -> None:
    from ..output.rerun.recording import write_recording
    from ..output.rerun.sdk import APPLICATION_ID, TIMELINE, import_rerun, saving

    write_recording(flown, fly_scene, Path(path).parent / "flown.rrd")
    rr = import_rerun()
    rec = rr.RecordingStream(APPLICATION_ID)
    with saving(rec, path):  # a full disk: WriteFailed naming the file, never a hang
        rec.send_recording_name(f"{scene.name} plan")

        def send(entity, t, values, names):
            rec.log(entity, rr.SeriesLines(names=names), static=True)
            rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                             columns=rr.Scalars.columns(scalars=values))

        send("plan/h_norm_planned", plan["t"], h_plan, ["planned |h|"])
        send("plan/h_norm_flown", flown.t, np.linalg.norm(flown.cols("hx", "hy", "hz"), axis=1), ["flown |h|"])
        send("plan/h_norm_eigenaxis", eig_t, h_eig, ["eigenaxis pd |h|"])
        send("plan/flown_vs_planned_deg", plan["t"], np.degrees(att), ["attitude difference"])
        t = flown.t
        send("plan/q_CR", plan["t"], plan["q_CR"], ["w", "x", "y", "z"])
        send("plan/q_BR_planned", plan["t"], plan["q_BR_planned"], ["w", "x", "y", "z"])
        send("plan/q_BR_flown", t, _relative_attitude(scene, flown), ["w", "x", "y", "z"])
        rec.flush()


def plan_and_fly(scene, out_dir, *, intervals=None, refine=None, fly=True) -> dict:
    """Plan ``scene.plan``, write the plan's files, and (``fly``) fly it; returns plan.json's dict."""
    out = Path(out_dir)
    prob, sol = plan_scene(scene, intervals=intervals, refine=refine)
    for name in FLIGHT_FILES:  # an earlier flight's files go (links removed, never followed)
        with writing(out / name):
            pass
    info = write_plan(scene, prob, sol, out)
    if fly:
        info["flight"] = fly_plan(scene, out / "plan.json", out)
        write_bytes(out / "plan.json", (json.dumps(info, indent=2) + "\n").encode())
    return info
