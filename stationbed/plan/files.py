"""A plan on disk: ``plan.csv`` (the command history and what the model predicts), ``plan.json``
(cost, peak momentum, solver statistics, the law and frame a replay needs) and ``plan.png``.

``plan.csv`` columns, one row per collocation point (nodes and interval midpoints): ``t`` [s];
``qc_w, qc_x, qc_y, qc_z``: the commanded attitude ``q_CR`` (relative to the plan's frame);
``q_w .. q_z``: the predicted ``q_BR``; ``wx, wy, wz``: predicted ``ω_BN_B`` [rad/s];
``hx, hy, hz``: predicted CMG momentum ``h_B`` [N m s]; ``h_norm`` [N m s];
``tau_x, tau_y, tau_z``: the law's body torque ``τ_B`` [N m]; ``h_dot_norm``: ``|ḣ|`` [N m].
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from ..core.paths import write_bytes, writing
from ..core.plotting import pyplot, save_png
from ..core.rotation import dcm, euler_321
from .collocation import PlanError, Problem, Solution, eigenaxis_commands, simulate_commands

__all__ = ["write_plan", "read_plan", "COLUMNS", "eigenaxis_baseline"]

COLUMNS = ["t", "qc_w", "qc_x", "qc_y", "qc_z", "q_w", "q_x", "q_y", "q_z", "wx", "wy", "wz",
           "hx", "hy", "hz", "h_norm", "tau_x", "tau_y", "tau_z", "h_dot_norm"]


def eigenaxis_baseline(prob: Problem, t) -> np.ndarray:
    """The model flown by its law through the eigenaxis command path: ``|h|`` at ``t`` [N m s]."""
    q1 = prob.q1 if float(np.dot(prob.q0, prob.q1)) >= 0 else -prob.q1
    xs = simulate_commands(prob, t, eigenaxis_commands(prob.q0, q1, t, prob.T))
    return np.linalg.norm(xs[:, 7:10], axis=1)


def write_plan(scene, prob: Problem, sol: Solution, out_dir, *, chart: bool = True) -> dict:
    """Write plan.csv, plan.json and (``chart``) plan.png into ``out_dir``; returns the JSON dict.
    Each is a new file (a link there is replaced, never written through); a write that fails
    raises :class:`~stationbed.core.paths.WriteFailed` naming the file."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    h_norm = np.linalg.norm(sol.h_B, axis=1)
    rows = np.column_stack([sol.t, sol.q_CR, sol.q_BR, sol.omega_BN_B, sol.h_B, h_norm, sol.tau_B,
                            np.linalg.norm(sol.h_dot_B, axis=1)])
    with writing(out / "plan.csv") as path, open(path, "x", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        w.writerows([f"{v:.12g}" for v in r] for r in rows)
    eig = eigenaxis_baseline(prob, sol.t)
    spec = scene.plan
    info = {
        "scene": scene.name,
        "csv": "plan.csv",
        "frame": spec.frame,
        "duration_s": prob.T,
        "kp": prob.model.kp,
        "kd": prob.model.kd,
        "inertia_O_B": prob.model.J.tolist(),
        "objective": spec.objective,
        "weight_energy": prob.w_energy,
        "weight_peak": prob.w_peak,
        "cost": sol.cost,
        "energy_N2m2s": sol.energy_N2m2s,
        "gamma_N2m2s2": sol.gamma_N2m2s2,
        "peak_h_Nms": sol.peak_h_Nms,
        "capacity_Nms": prob.h_max,
        "peak_fraction": sol.peak_h_Nms / prob.h_max,
        "max_torque_Nm": prob.tau_max,
        "peak_h_dot_Nm": float(np.max(np.linalg.norm(sol.h_dot_B, axis=1))),
        "slew_deg": math.degrees(_angle(prob.q0, prob.q1)),
        "eigenaxis_commands_peak_h_Nms": float(np.max(eig)),
        "eigenaxis_commands_peak_fraction": float(np.max(eig)) / prob.h_max,
        "solver": sol.stats,
    }
    write_bytes(out / "plan.json", (json.dumps(info, indent=2) + "\n").encode())
    if chart:
        with writing(out / "plan.png") as path:
            plot_plan(sol, prob, eig, path, title=f"{scene.name}: planned slew")
    return info


def _angle(q0, q1) -> float:
    d = abs(float(np.dot(q0, q1))) / (np.linalg.norm(q0) * np.linalg.norm(q1))
    return 2.0 * math.acos(min(1.0, d))


def plot_plan(sol: Solution, prob: Problem, eig_h, path, title: str) -> None:
    """Momentum magnitude against capacity (and the eigenaxis command path's), the attitude
    relative to the plan's frame (3-2-1 angles), and the law's torque against the limit."""
    plt = pyplot(PlanError)
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    t_min = sol.t / 60.0
    ax[0].plot(t_min, np.linalg.norm(sol.h_B, axis=1), label="planned |h|")
    ax[0].plot(t_min, eig_h, "--", label="eigenaxis commands, same law")
    ax[0].axhline(prob.h_max, color="k", lw=1, label="capacity")
    ax[0].set_ylabel("|h| [N m s]")
    ax[0].legend(fontsize=8)
    ang = np.degrees(np.array([euler_321(dcm(q)) for q in sol.q_BR]))
    cmd = np.degrees(np.array([euler_321(dcm(q)) for q in sol.q_CR]))
    for k, name in enumerate(("roll", "pitch", "yaw")):
        line, = ax[1].plot(t_min, ang[:, k], label=name)
        ax[1].plot(t_min, cmd[:, k], ":", color=line.get_color())
    ax[1].set_ylabel("attitude (3-2-1) [deg]\n(dotted: command)")
    ax[1].legend(fontsize=8)
    for k, name in enumerate("xyz"):
        ax[2].plot(t_min, sol.tau_B[:, k], label=f"tau_{name}")
    ax[2].plot(t_min, np.linalg.norm(sol.h_dot_B, axis=1), "k", lw=1, label="|h_dot|")
    ax[2].axhline(prob.tau_max, color="k", ls="--", lw=1, label="torque limit")
    ax[2].set_ylabel("torque [N m]")
    ax[2].set_xlabel("time [min]")
    ax[2].legend(fontsize=8, ncol=3)
    ax[0].set_title(title)
    save_png(plt, fig, path)


def read_plan(path) -> dict:
    """A plan written by :func:`write_plan`: the JSON's entries plus ``t`` (M,) and ``q_CR`` (M, 4).

    Raises
    ------
    PlanError
        The file is missing or not a plan (one line naming it).
    """
    path = Path(path)
    try:
        info = json.loads(path.read_text())
        csv_path = path.parent / info["csv"]
        data = np.genfromtxt(csv_path, delimiter=",", names=True)
        info["t"] = np.asarray(data["t"], float)
        info["q_CR"] = np.column_stack([data[c] for c in ("qc_w", "qc_x", "qc_y", "qc_z")])
        info["h_planned_B"] = np.column_stack([data[c] for c in ("hx", "hy", "hz")])
        info["q_BR_planned"] = np.column_stack([data[c] for c in ("q_w", "q_x", "q_y", "q_z")])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise PlanError(f"{path}: not a readable plan ({type(e).__name__}: {e})") from None
    return info
