"""``stationbed plot OUTDIR``: one dashboard PNG of a run folder (trajectory.csv, summary.json).

Panels, each drawn when the run has its columns: per-axis attitude error to the controller's
reference (``att_err_x/y/z_deg``), body rate, CMG momentum with its fraction of capacity, gimbal
angles, gimbal rates, torque command, array sun-tracking error, array modal coordinates, and every
other ``tau_*`` column (disturbance torques a scene models: ``tau_aero_*``, ...; whatever the
name after ``tau_``). Rows flagged ``cmg_saturated`` are marked by red ticks along the top of every
panel (a gimbal-rate limit or momentum saturation since the previous row).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.plotting import pyplot, save_png
from ..run.trajectory import Trajectory

__all__ = ["dashboard", "load_run", "time_axis"]


def load_run(outdir) -> tuple[Trajectory, dict]:
    """The trajectory and summary.json (``{}`` when absent) of a run folder; ValueError naming
    the file when the folder has no trajectory.csv."""
    outdir = Path(outdir)
    csv = outdir / "trajectory.csv"
    if not csv.is_file():
        raise ValueError(f"{csv}: no such file (a run folder written by 'stationbed run --out DIR')")
    tr = Trajectory.from_csv(csv)
    meta = {}
    if (outdir / "summary.json").is_file():
        meta = json.loads((outdir / "summary.json").read_text())
    tr.meta.update(meta)
    return tr, meta


def time_axis(t_end: float) -> tuple[float, str]:
    """(divisor, label) of the time axis: seconds, minutes or hours by the run's length."""
    if t_end > 3 * 3600:
        return 3600.0, "t [h]"
    if t_end > 1200:
        return 60.0, "t [min]"
    return 1.0, "t [s]"


def _groups(tr: Trajectory, meta: dict) -> list[tuple[str, list]]:
    """(panel title, [(column or array, label, scale)]) for the panels the run has data for."""
    cols = set(tr.columns)
    has = lambda *names: all(n in cols for n in names)  # noqa: E731
    deg = math.degrees(1.0)
    out = []
    if has("att_err_x_deg"):
        out.append(("attitude error to the reference [deg]",
                    [("att_err_x_deg", "x (roll)", 1), ("att_err_y_deg", "y (pitch)", 1), ("att_err_z_deg", "z (yaw)", 1),
                     ("att_err_deg", "total", 1)]))
    elif has("att_err_deg"):
        out.append(("attitude error to the reference [deg]", [("att_err_deg", "total", 1)]))
    out.append(("body rate ω_BN_B [deg/s]", [("wx", "x", deg), ("wy", "y", deg), ("wz", "z", deg)]))
    if not has("att_err_deg"):  # open loop: the momentum (conserved without external torque)
        out.append(("angular momentum H_O, inertial [N m s]", [("HNx", "x", 1), ("HNy", "y", 1), ("HNz", "z", 1)]))
    if has("hx"):
        out.append(("CMG momentum h (B) [N m s]", [("hx", "x", 1), ("hy", "y", 1), ("hz", "z", 1), ("|h|", "|h|", 1)]))
    gim = [c for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]
    if gim:
        out.append(("gimbal angles [deg]", [(c, c.removeprefix("gimbal_"), deg) for c in gim]))
        out.append(("gimbal rate commands [deg/s]", [(c + "_rate", c.removeprefix("gimbal_"), deg) for c in gim]))
    if has("tau_cmd_x"):
        out.append(("torque command [N m]", [("tau_cmd_x", "x", 1), ("tau_cmd_y", "y", 1), ("tau_cmd_z", "z", 1)]))
    trk = [c for c in tr.columns if c.startswith("track_err_deg_")]
    if trk:
        out.append(("array sun-tracking error [deg]", [(c, c.removeprefix("track_err_deg_"), 1) for c in trk]))
    eta = [c for c in tr.columns if c.startswith("eta_")]
    if eta:
        out.append(("array modal coordinates η (tip deflection) [mm]", [(c, c.removeprefix("eta_"), 1e3) for c in eta]))
    dist = [c for c in tr.columns if c.startswith("tau_") and not c.startswith("tau_cmd_")]
    if dist:
        out.append(("disturbance torques [N m]", [(c, c.removeprefix("tau_"), 1) for c in dist]))
    return out


def dashboard(outdir, png=None) -> Path:
    """Draw the dashboard of a run folder; returns the PNG's path (default OUTDIR/dashboard.png)."""
    tr, meta = load_run(outdir)
    if len(tr) == 0:
        raise ValueError(f"{Path(outdir) / 'trajectory.csv'}: no rows")
    plt = pyplot()
    png = Path(png) if png is not None else Path(outdir) / "dashboard.png"
    summ = meta.get("summary", {})
    groups = _groups(tr, meta)
    ncol = 1 if len(groups) == 1 else 2
    nrow = math.ceil(len(groups) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(7.5 * ncol, 3.1 * nrow + 0.9), sharex=True, squeeze=False)
    div, tlabel = time_axis(float(tr.t[-1]))
    t = tr.t / div
    sat = tr["cmg_saturated"] > 0.5 if "cmg_saturated" in tr.columns else np.zeros(len(tr), bool)
    cap = summ.get("h_capacity_Nms")
    if cap is None and summ.get("max_h_fraction"):
        cap = summ["max_h_Nms"] / summ["max_h_fraction"]
    for ax, (title, lines) in zip(axes.flat, groups):
        for col, label, scale in lines:
            y = np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1) if col == "|h|" else tr[col]
            style = {"color": "k", "lw": 1.0, "ls": "--"} if label in ("total", "|h|") else {"lw": 1.0}
            ax.plot(t, y * scale, label=label, **style)
        if title.startswith("CMG") and cap:
            if np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1).max() > 0.5 * cap:
                ax.axhline(cap, color="tab:red", lw=0.8, ls=":", label="capacity")
            ax2 = ax.twinx()  # the same scale as a fraction of the capacity
            ax2.set_ylim(np.array(ax.get_ylim()) / cap * 100.0)
            ax2.set_ylabel("|h| as % of capacity")
        if sat.any():
            ax.plot(t[sat], np.full(sat.sum(), 1.0), "|", color="tab:red", ms=8, transform=ax.get_xaxis_transform(),
                    label="CMG limit (rate or momentum)")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, ncol=min(4, len(lines) + int(sat.any())), loc="best")
    for ax in axes.flat[len(groups):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(tlabel)
        ax.tick_params(labelbottom=True)
    name = meta.get("scene", Path(outdir).name)
    ctrl = ""
    if summ.get("controller"):
        ctrl = f", controller {summ['controller']}"
    facts = []
    for key, fmt in (("max_att_err_deg", "max att. error {:.3g} deg"), ("final_att_err_deg", "final {:.3g} deg"),
                     ("max_h_fraction", "max |h| {:.0%} of capacity"), ("rate_limited_ticks", "rate-limited ticks {}"),
                     ("momentum_saturated_ticks", "saturated ticks {}")):
        if summ.get(key) is not None:
            facts.append(fmt.format(summ[key]))
    fig.suptitle(f"{name}{ctrl}" + (": " + "; ".join(facts) if facts else ""), fontsize=11)
    save_png(plt, fig, png, dpi=100)
    return png
