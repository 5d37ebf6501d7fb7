"""``stationbed plot OUTDIR``: one dashboard PNG of a run folder (trajectory.csv, or the partial rows
of a failed run, and summary.json).

Panels, each drawn when the run has its columns: per-axis attitude error to the controller's
reference (``att_err_x/y/z_deg``); the body rate relative to that reference (inertial in open
loop; :mod:`.signals`); CMG momentum h and, apart, |h| as a fraction of the capacity (from 0);
gimbal angles and rates; the torque command beside the torque the cluster delivered; the
estimation error per axis against its ±3σ (symmetric-log axis: the first rows' error is the
initial uncertainty, the rest arc-seconds), NEES with its expected value and the 95 % band of one
run, and each star-tracker head's state (valid, dropout, or no valid sample yet: a head's rows
before its first sample read 0 and are not a dropout, :func:`~stationbed.loop.flight.st_dropouts`);
the thrusters' firings and propellant (totals) with the momentum dump and thruster-only control
shaded; array sun-tracking error; array modal coordinates; every other ``tau_*`` column
(disturbance torques: ``tau_gg_*`` gravity gradient, ``tau_aero_*``, ``tau_srp_*``, ...).

Rows flagged ``cmg_saturated`` (a limit at a tick since the previous row) are ticked along the top
of every panel, named for what they were (:func:`~.signals.cmg_limit_kinds`): "CMG momentum
saturation" (red) only where the working units' |h| reached the saturation threshold, else
"gimbal-rate limit" (an ideal cluster's "torque limit"; orange). Legends are kept inside their
axes (:func:`~stationbed.core.plotting.save_png`). A failed or interrupted run's rows are drawn
with its state in the title.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.plotting import pyplot, save_png
from ..loop.flight import st_dropouts
from ..run.trajectory import Trajectory
from ..run.working_h import summary_capacity_Nms
from .signals import (CMG_MOMENTUM_SATURATED, CMG_RATE_LIMIT, ERR_AXES, cmg_limit_kinds, cmg_limit_name,
                      delivered_torque, h_fraction, relative_rate)

__all__ = ["dashboard", "load_run", "run_state", "capacity_Nms", "time_axis", "ROWS_FILES"]


#: NEES of a consistent filter over 6 states (3 attitude, 3 bias) is χ² with 6 dof: its mean, and
#: the two-sided 95 % band of one row (scipy.stats.chi2.ppf(0.025 / 0.975, 6))
NEES_DOF = 6
NEES_BAND_95 = (1.2373442457912045, 14.449375335447922)
ARCSEC_PER_DEG = 3600.0
#: the names of the disturbance torques' column stems (``tau_<stem>_x``); others keep their stem
DISTURBANCE_NAMES = {"gg": "gravity gradient", "aero": "aero", "srp": "SRP"}
RGB_VALID, RGB_DROPOUT, RGB_NO_SAMPLE = "tab:green", "tab:red", "0.75"

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
    """The CMG cluster's momentum capacity at the start [N m s] a run reported (None when it has none)."""
    return summary_capacity_Nms(summary)


def saturation_Nms(summary: dict) -> float | None:
    """|h| at which the run's cluster counts as momentum saturated [N m s]: summary.json's
    ``h_saturation_Nms``, or (a summary written before it was kept) the scene tables' default
    ``saturation_fraction`` of the capacity; None without a finite capacity."""
    if summary.get("h_saturation_Nms") is not None:
        return float(summary["h_saturation_Nms"])
    cap = capacity_Nms(summary)
    from ..scene.tables import Cmg

    return None if cap is None else Cmg.model_fields["saturation_fraction"].default * cap


def _panels(tr: Trajectory, summ: dict) -> list[tuple[str, list, dict]]:
    """(panel title, [(values (k,), label, style)], options) for the panels the run has data for;
    options: ``yscale``, ``hlines``, ``hspans``, ``bars`` (per head: runs of states), ``twin``
    (a right axis: label and lines), ``vspans`` (shaded rows), ``ylabel``."""
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
        frac = h_fraction(tr, summ)
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
        out.append(("disturbance torques, B [N m]", [(tr[c], _disturbance_label(c), {}) for c in dist]))
    out += _estimation_panels(tr) + _thruster_panels(tr)
    return [p if len(p) == 3 else (*p, {}) for p in out]


def _disturbance_label(col: str) -> str:
    """``tau_gg_x`` -> "gravity gradient x"."""
    stem, _, axis = col.removeprefix("tau_").rpartition("_")
    return f"{DISTURBANCE_NAMES.get(stem, stem)} {axis}" if stem else col.removeprefix("tau_")


def spans(t, mask) -> list[tuple[float, float]]:
    """``(start, width)`` of the runs of rows where ``mask`` holds, each row standing for the
    interval since the previous row (a flag reports the ticks since then; the first row, t[0])."""
    out = []
    i, n = 0, len(mask)
    while i < n:
        if not mask[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and mask[j + 1]:
            j += 1
        a = t[i - 1] if i > 0 else t[0]
        out.append((float(a), float(t[j] - a)))
        i = j + 1
    return out


def _estimation_panels(tr: Trajectory) -> list:
    """The estimation error against its ±3σ, NEES, and the star-tracker heads' states."""
    cols = set(tr.columns)
    out = []
    if all(f"est_err_{a}_deg" in cols and f"est_3sigma_{a}_deg" in cols for a in "xyz"):
        lines = []
        for i, a in enumerate("xyz"):
            s3 = tr[f"est_3sigma_{a}_deg"] * ARCSEC_PER_DEG
            lines += [(tr[f"est_err_{a}_deg"] * ARCSEC_PER_DEG, f"{a} error", {"color": f"C{i}"}),
                      (s3, f"{a} ±3σ", {"color": f"C{i}", "ls": "--", "lw": 0.8}),
                      (-s3, "_nolegend_", {"color": f"C{i}", "ls": "--", "lw": 0.8})]
        s3_all = np.abs(tr.cols(*(f"est_3sigma_{a}_deg" for a in "xyz"))) * ARCSEC_PER_DEG
        lin = float(np.nanmedian(s3_all)) if np.isfinite(s3_all).any() else 1.0
        out.append(("estimation error (solid) against its ±3σ (dashed), B [arcsec]", lines,
                    {"yscale": ("symlog", {"linthresh": lin if lin > 0 else 1.0})}))
    if "nees" in cols:
        lo, hi = NEES_BAND_95
        mean = float(np.nanmean(tr["nees"])) if np.isfinite(tr["nees"]).any() else math.nan
        out.append((f"NEES ({NEES_DOF} states): χ² with {NEES_DOF} dof when consistent",
                    [(tr["nees"], f"NEES (mean {mean:.3g})", {"color": "k"})],
                    {"hlines": [(float(NEES_DOF), f"expected {NEES_DOF}", {"color": "tab:blue", "ls": "--"})],
                     "hspans": [(lo, hi, "95 % band of one row", {"color": "tab:blue", "alpha": 0.12})]}))
    heads = [c for c in tr.columns if c.startswith("st_valid_")]
    if heads:
        bars = []
        for k, c in enumerate(heads):
            v = tr[c]
            drop, _ = st_dropouts(v)
            ok = v >= 0.5
            before = ~ok & ~drop
            n_drop = int(np.sum(drop[1:] & ~drop[:-1]) + (drop[0] if len(drop) else 0))
            bars.append((k, c.removeprefix("st_valid_") + f" ({n_drop} dropouts)",
                         [(ok, "valid", RGB_VALID), (drop, "dropout", RGB_DROPOUT), (before, "no valid sample yet", RGB_NO_SAMPLE)]))
        out.append(("star-tracker heads: valid, dropout, no valid sample yet", [], {"bars": bars}))
    return out


def _thruster_panels(tr: Trajectory) -> list:
    """Firings and propellant (totals since t = 0), the dump and thruster-only control shaded."""
    cols = set(tr.columns)
    if not {"thr_firings", "thr_propellant_kg"} <= cols:
        return []
    shade = [(col, label, color) for col, label, color in (("thr_dumping", "momentum dump", "tab:orange"),
                                                           ("thr_mode", "thruster-only control", "tab:red"))
             if col in cols]
    return [("thrusters: firings and propellant (totals), dump shaded",
             [(tr["thr_firings"], "firings", {"color": "k", "drawstyle": "steps-post"})],
             {"ylabel": "firings", "twin": ("propellant [kg]", [(tr["thr_propellant_kg"], "propellant [kg]",
                                                                 {"color": "tab:purple", "ls": "--", "drawstyle": "steps-post"})]),
              "vspans": [(tr[c] >= 0.5, label, color) for c, label, color in shade]})]


def _finite_range(lines, opts=None) -> bool:
    """True when some value of the panel is finite (an all-NaN panel is drawn empty, not warned about)."""
    return bool((opts or {}).get("bars")) or any(np.isfinite(y).any() for y, _, _ in lines)


def _limit_marks(tr: Trajectory, summ: dict) -> list[tuple[np.ndarray, str, str]]:
    """(rows, label, colour) of the CMG limit ticks: momentum saturation, and the rate (torque) limit."""
    if "cmg_saturated" not in tr.columns:
        return []
    frac = h_fraction(tr, summ)  # the working units' |h| over their capacity at the row, as the flag weighs it
    h_sat, cap = saturation_Nms(summ), capacity_Nms(summ)
    ticks = (summ["rate_limited_ticks"], summ["momentum_saturated_ticks"]) \
        if summ.get("rate_limited_ticks") is not None and summ.get("momentum_saturated_ticks") is not None else None
    kind = cmg_limit_kinds(tr["cmg_saturated"], np.full(len(tr), np.nan) if frac is None else frac,
                           None if frac is None or h_sat is None else h_sat / cap, ticks=ticks)
    limit = cmg_limit_name(any(c.startswith("gimbal_") for c in tr.columns))
    marks = [(kind == CMG_MOMENTUM_SATURATED, "CMG momentum saturation", "tab:red"),
             (kind == CMG_RATE_LIMIT, f"CMG {limit}", "tab:orange")]
    return [m for m in marks if m[0].any()]


def _draw(ax, t, lines, opts) -> list:
    """Draw one panel's lines and options on ``ax``; returns the axes whose legend entries the
    panel's legend gathers (``ax`` and its twin)."""
    axes = [ax]
    for y, label, style in lines:
        ax.plot(t, y, label=label, **({"lw": 1.0} | style))
    if "yscale" in opts:
        scale, kw = opts["yscale"]
        ax.set_yscale(scale, **kw)
    for y, label, style in opts.get("hlines", ()):
        ax.axhline(y, label=label, lw=0.9, **style)
    for lo, hi, label, style in opts.get("hspans", ()):
        ax.axhspan(lo, hi, label=label, lw=0, **style)
    for mask, label, color in opts.get("vspans", ()):
        for k, (a, w) in enumerate(spans(t, mask)):
            ax.axvspan(a, a + w, color=color, alpha=0.2, lw=0, label=label if k == 0 else "_nolegend_")
    if opts.get("bars"):
        named = set()
        for k, _, states in opts["bars"]:
            for mask, label, color in states:
                runs = spans(t, mask)
                if runs:
                    ax.broken_barh(runs, (k - 0.35, 0.7), color=color, label=label if label not in named else "_nolegend_")
                    named.add(label)
        ax.set_yticks([k for k, _, _ in opts["bars"]], [name for _, name, _ in opts["bars"]], fontsize=8)
        ax.set_ylim(-0.6, len(opts["bars"]) - 0.4 + 0.6)  # room above the heads for the legend
    if "ylabel" in opts:
        ax.set_ylabel(opts["ylabel"], fontsize=8)
    if "twin" in opts:
        label, more = opts["twin"]
        right = ax.twinx()
        for y, name, style in more:
            right.plot(t, y, label=name, **({"lw": 1.0} | style))
        right.set_ylabel(label, fontsize=8)
        axes.append(right)
    return axes


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
    marks = _limit_marks(tr, summ)
    for n, (ax, (title, lines, opts)) in enumerate(zip(axes.flat, groups)):
        drawn = _draw(ax, t, lines, opts)
        if title.startswith("CMG momentum |h|"):
            top = max(1.1, float(np.nanmax(lines[0][0])) * 1.05) if _finite_range(lines) else 1.1
            ax.set_ylim(0.0, top)  # a fraction of a norm: never below 0
            ax.axhline(1.0, color="tab:red", lw=0.8, ls=":", label="capacity")
            h_sat, cap = saturation_Nms(summ), capacity_Nms(summ)
            if h_sat and cap and h_sat < cap:
                ax.axhline(h_sat / cap, color="tab:red", lw=0.8, ls="--", label="saturation threshold")
        # the limit ticks on every panel, named in the first panel's and the |h| panel's legends
        say = n == 0 or title.startswith("CMG momentum |h|")
        for rows, label, color in marks:
            ax.plot(t[rows], np.full(int(rows.sum()), 1.0), "|", color=color, ms=8, clip_on=False,
                    transform=ax.get_xaxis_transform(), label=label if say else "_nolegend_")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        if _finite_range(lines, opts):
            handles, labels = [], []
            for a in drawn:
                hs, ls = a.get_legend_handles_labels()
                handles += hs
                labels += ls
            drawn[-1].legend(handles, labels, fontsize=7, ncol=min(6, len(labels)), loc="best")
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
