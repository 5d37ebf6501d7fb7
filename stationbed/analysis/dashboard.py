"""``stationbed plot OUTDIR``: one dashboard PNG of a run folder (trajectory.csv, or the partial rows
of a failed run, and summary.json).

Panels, each drawn when the run has its columns: per-axis attitude error to the controller's
reference (``att_err_x/y/z_deg``); the body rate relative to that reference (inertial in open
loop; :mod:`.signals`); CMG momentum h and, apart, |h| as a fraction of the capacity (from 0);
gimbal angles and rates; the torque command beside the torque the cluster delivered; array
sun-tracking error; array modal coordinates; every other ``tau_*`` column (disturbance torques a
scene models: ``tau_aero_*``, ...; whatever the name after ``tau_``). Rows flagged
``cmg_saturated`` are marked by red ticks along the top of every panel (a gimbal-rate limit or
momentum saturation since the previous row). A failed or interrupted run's rows are drawn with its
state in the title.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.plotting import pyplot, save_png
from ..run.trajectory import Trajectory
from .signals import ERR_AXES, delivered_torque, h_fraction, relative_rate

__all__ = ["dashboard", "load_run", "run_state", "capacity_Nms", "time_axis", "ROWS_FILES"]


#: the files a run folder holds its rows in: the result, or the rows a failed or interrupted run kept
ROWS_FILES = ("trajectory.csv", "trajectory.partial.csv")


def load_run(outdir) -> tuple[Trajectory, dict]:
    """The trajectory and summary.json (``{}`` when absent) of a run folder.

    The rows are the ones summary.json names (``rows_file``: the last run's, finished or not; a
    plan folder's ``flown.csv``),
    else ``trajectory.csv``, else ``trajectory.partial.csv`` (a failed or interrupted run keeps its
    rows there); ``meta["rows_file"]`` says which was read and ``meta["partial"]`` whether they are
    a failed or interrupted run's; a partial file's torn last row (a run killed mid-write) is
    dropped and counted in ``meta["torn_rows"]``. ValueError naming the file for a folder without rows, a CSV
    cut mid-row or damaged, or a summary.json that is not JSON.
    """
    outdir = Path(outdir)
    meta = {}
    summary = outdir / "summary.json"
    if summary.is_file():
        try:
            meta = json.loads(summary.read_text())
        except (ValueError, UnicodeDecodeError) as e:
            raise ValueError(f"{summary}: not JSON ({e})") from None
        if not isinstance(meta, dict):
            raise ValueError(f"{summary}: not a run summary (a JSON object)")
    named = meta.get("rows_file")
    # a file of this folder that summary.json names (a plan folder's flown.csv), else the run's
    own = named in ROWS_FILES or (isinstance(named, str) and named.endswith(".csv") and Path(named).name == named)
    order = ([named] if own else []) + [n for n in ROWS_FILES if n != named]
    csv = next((outdir / n for n in order if (outdir / n).is_file()), None)
    if csv is None:
        raise ValueError(f"{outdir / ROWS_FILES[0]}: no such file, nor {ROWS_FILES[1]} "
                         "(a run folder written by 'stationbed run --out DIR')")
    partial = csv.name == ROWS_FILES[1]
    tr = Trajectory.from_csv(csv, torn_tail=partial)  # a killed run's last row may be torn
    meta["rows_file"] = csv.name
    meta["partial"] = partial
    meta["torn_rows"] = tr.meta.get("torn_rows", 0)
    if named is not None and named != csv.name:  # summary.json is another run's (the file it names is gone): not these rows'
        meta = {"rows_file": csv.name, "partial": partial, "torn_rows": meta["torn_rows"]}
    tr.meta.update(meta)
    return tr, meta


def run_state(meta: dict) -> str:
    """'' for a finished run, else what the rows are ("failed run: rows to t = 100 s, trajectory.partial.csv")."""
    if not meta.get("partial"):
        return ""
    what = meta.get("status") if meta.get("status") in ("failed", "interrupted") else "unfinished"
    at = meta.get("stopped_at", meta.get("last_t"))
    torn = ", its torn last row dropped" if meta.get("torn_rows") else ""
    return f"{what} run: rows to t = {at:g} s in {meta['rows_file']}{torn}" if isinstance(at, (int, float)) else \
        f"{what} run: rows in {meta['rows_file']}{torn}"


def time_axis(t_end: float) -> tuple[float, str]:
    """(divisor, label) of the time axis: seconds, minutes or hours by the run's length."""
    if t_end > 3 * 3600:
        return 3600.0, "t [h]"
    if t_end > 1200:
        return 60.0, "t [min]"
    return 1.0, "t [s]"


def capacity_Nms(summary: dict) -> float | None:
    """The CMG cluster's momentum capacity [N m s] a run reported (None when it has none)."""
    cap = summary.get("h_capacity_Nms")
    if cap is None and summary.get("max_h_fraction"):
        cap = summary["max_h_Nms"] / summary["max_h_fraction"]
    return float(cap) if cap is not None and math.isfinite(cap) and cap > 0 else None


def _panels(tr: Trajectory, summ: dict) -> list[tuple[str, list]]:
    """(panel title, [(values (k,), label, style)]) for the panels the run has data for."""
    cols = set(tr.columns)
    has = lambda *names: all(n in cols for n in names)  # noqa: E731
    deg = math.degrees(1.0)
    total = {"color": "k", "lw": 1.0, "ls": "--"}
    axes3 = ("x", "y", "z")
    out = []
    if has(*ERR_AXES):
        out.append(("attitude error to the reference [deg]",
                    [(tr[c], f"{a} ({n})", {}) for c, a, n in zip(ERR_AXES, axes3, ("roll", "pitch", "yaw"))]
                    + [(tr["att_err_deg"], "total", total)]))
    elif has("att_err_deg"):
        out.append(("attitude error to the reference [deg]", [(tr["att_err_deg"], "total", total)]))
    w_BR = relative_rate(tr)
    if w_BR is not None:
        out.append(("body rate relative to the reference ω_BR_B [deg/s]", [(w_BR[:, i] * deg, a, {}) for i, a in enumerate(axes3)]))
    else:
        out.append(("body rate ω_BN_B (inertial) [deg/s]", [(tr[c] * deg, a, {}) for c, a in zip(("wx", "wy", "wz"), axes3)]))
    if not has("att_err_deg"):  # open loop: the momentum (conserved without external torque)
        out.append(("angular momentum H_O, inertial [N m s]", [(tr[c], a, {}) for c, a in zip(("HNx", "HNy", "HNz"), axes3)]))
    if has("hx"):
        out.append(("CMG momentum h (B) [N m s]", [(tr[c], a, {}) for c, a in zip(("hx", "hy", "hz"), axes3)]))
        frac = h_fraction(tr, capacity_Nms(summ))
        if frac is not None:
            out.append(("CMG momentum |h| / capacity", [(frac, "|h| / capacity", {"color": "k", "lw": 1.0})]))
    gim = [c for c in tr.columns if c.startswith("gimbal_") and not c.endswith("_rate")]
    if gim:
        out.append(("gimbal angles [deg]", [(tr[c] * deg, c.removeprefix("gimbal_"), {}) for c in gim]))
        out.append(("gimbal rate commands [deg/s]", [(tr[c + "_rate"] * deg, c.removeprefix("gimbal_"), {}) for c in gim]))
    tau = delivered_torque(tr)
    if has("tau_cmd_x") or tau is not None:
        lines = []
        for i, a in enumerate(axes3):
            color = f"C{i}"
            if has("tau_cmd_x"):
                lines.append((tr[f"tau_cmd_{a}"], f"{a} command", {"color": color, "lw": 1.0}))
            if tau is not None:
                lines.append((tau[:, i], f"{a} delivered", {"color": color, "lw": 1.0, "ls": "--"}))
        title = "CMG torque on the body: command (solid), delivered -(ḣ + ω×h) (dashed) [N m]" if tau is not None \
            else "torque command [N m]"
        out.append((title, lines))
    trk = [c for c in tr.columns if c.startswith("track_err_deg_")]
    if trk:
        out.append(("array sun-tracking error [deg]", [(tr[c], c.removeprefix("track_err_deg_"), {}) for c in trk]))
    eta = [c for c in tr.columns if c.startswith("eta_")]
    if eta:
        out.append(("array modal coordinates η (tip deflection) [mm]", [(tr[c] * 1e3, c.removeprefix("eta_"), {}) for c in eta]))
    dist = [c for c in tr.columns if c.startswith("tau_") and not c.startswith("tau_cmd_")]
    if dist:
        out.append(("disturbance torques [N m]", [(tr[c], c.removeprefix("tau_"), {}) for c in dist]))
    return out


def _finite_range(lines) -> bool:
    """True when some value of the panel is finite (an all-NaN panel is drawn empty, not warned about)."""
    return any(np.isfinite(y).any() for y, _, _ in lines)


def dashboard(outdir, png=None, run=None) -> Path:
    """Draw the dashboard of a run folder; returns the PNG's path (default OUTDIR/dashboard.png).
    ``run``: the folder's ``(trajectory, meta)`` when already read (:func:`load_run`)."""
    tr, meta = run if run is not None else load_run(outdir)
    if len(tr) == 0:
        raise ValueError(f"{Path(outdir) / meta['rows_file']}: no rows (the run stopped before its first output row)")
    plt = pyplot()
    png = Path(png) if png is not None else Path(outdir) / "dashboard.png"
    summ = meta.get("summary", {})
    with np.errstate(all="ignore"):  # NaN rows (no reference yet, a gimbal-rate law's torque) are gaps
        groups = _panels(tr, summ)
    ncol = 1 if len(groups) == 1 else 2
    nrow = math.ceil(len(groups) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(7.5 * ncol, 3.1 * nrow + 0.9), sharex=True, squeeze=False)
    div, tlabel = time_axis(float(tr.t[-1]))
    t = tr.t / div
    sat = tr["cmg_saturated"] > 0.5 if "cmg_saturated" in tr.columns else np.zeros(len(tr), bool)
    for ax, (title, lines) in zip(axes.flat, groups):
        for y, label, style in lines:
            ax.plot(t, y, label=label, **({"lw": 1.0} | style))
        if title.startswith("CMG momentum |h|"):
            top = max(1.1, float(np.nanmax(lines[0][0])) * 1.05) if _finite_range(lines) else 1.1
            ax.set_ylim(0.0, top)  # a fraction of a norm: never below 0
            ax.axhline(1.0, color="tab:red", lw=0.8, ls=":", label="capacity")
        if sat.any():
            ax.plot(t[sat], np.full(sat.sum(), 1.0), "|", color="tab:red", ms=8, transform=ax.get_xaxis_transform(),
                    label="CMG limit (rate or momentum)")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        if _finite_range(lines):
            ax.legend(fontsize=7, ncol=min(6, len(lines) + int(sat.any())), loc="best")
        else:
            ax.text(0.5, 0.5, "no values (NaN in every row)", ha="center", va="center", transform=ax.transAxes, color="0.4")
    for ax in axes.flat[len(groups):]:
        ax.set_visible(False)
    for col in range(ncol):  # the lowest panel of each column carries the time axis
        shown = [ax for ax in axes[:, col] if ax.get_visible()]
        shown[-1].set_xlabel(tlabel)
        shown[-1].tick_params(labelbottom=True)
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
    state = run_state(meta)
    fig.suptitle(f"{name}{ctrl}" + (": " + "; ".join(facts) if facts else "") + (f"\n{state}" if state else ""),
                 fontsize=11, color="tab:red" if state else "k")
    save_png(plt, fig, png, dpi=100, title_in=0.1 + 0.2 * (1 + bool(state)))
    return png
