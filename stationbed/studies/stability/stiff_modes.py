"""Case ``stiff_modes``: a flexible array with a 0.1 Hz mode and a stiff one (1 to 20 Hz), explicit
against implicit integrators.

Fixed step: the largest stable step against the stiff mode's frequency, with the linear
stability boundary of the explicit Runge-Kutta methods as prediction, and the Newton defect of
the implicit step. Adaptive: the RHS evaluations a fixed attitude accuracy costs, with the
stiff mode lightly and well damped.
"""

from __future__ import annotations

import math

import numpy as np

from ...core.beam import beam_mode
from ...integrators import INTEGRATORS
from ...run.simulation import simulate
from ...scene import Scene, scene_from_dict
from ..common import registered_integrators, try_simulate
from ..plotting import MARKERS, STYLES, colours
from ..probes import (
    RK4_TABLEAU,
    explicit_tableaus,
    max_errors,
    modal_energy,
    newton_defects,
    predicted_step,
    rhs_eigenvalues,
    stability_boundary,
    stability_function,
)
from .base import Case, Context, stability_case
from .scenes import tumble_scene

__all__ = ["STIFF_FREQS_HZ", "QUICK_STIFF_FREQS_HZ", "STIFF_TARGET_RAD", "stiff_scene", "stiff_modes"]

#: a 100 t station core with one 37 m, 1100 kg wing (a 12 m x 37 m plate: span y, normal z in P)
#: bending in two modes: the first at 0.1 Hz, released from a 0.1 m tip deflection, and a stiff
#: one (the second cantilever shape, its frequency set to ``f_hi``) that only the coupling excites
_STIFF_BEAM = {"length": 37.0, "root": [0.0, -18.5, 0.0], "span": "y", "deflection": "z"}
_STIFF_SCENE = {
    "name": "study_stiff_modes",
    "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
    "body": {"mass": 1.0e5, "inertia": [[1.0e7, 0.0, 0.0], [0.0, 0.8e7, 0.0], [0.0, 0.0, 1.5e7]], "cm": [0.0, 0.0, 0.0]},
    "appendage": [{
        "name": "wing", "mass": 1100.0, "cm": [0.0, 30.0, 0.0],
        "inertia": [[1.255e5, 0.0, 0.0], [0.0, 1.32e4, 0.0], [0.0, 0.0, 1.387e5]],
    }],
}
STIFF_LOW_HZ = 0.1
STIFF_ETA0_M = 0.1
STIFF_DAMPING = 0.005
#: the adaptive sweep is repeated at the highest frequency with the stiff mode this damped: its
#: eigenvalues then lie 17° off the imaginary axis (BDF of order 3-5 is stable only in a sector
#: around the negative real axis: A(86°), A(73°), A(52°))
STIFF_DAMPED = 0.3
STIFF_FREQS_HZ = [1.0, 2.0, 5.0, 10.0, 20.0]
QUICK_STIFF_FREQS_HZ = [1.0, 20.0]
#: six (quick: two) periods of the 0.1 Hz mode
STIFF_DURATION_S = 60.0
QUICK_STIFF_DURATION_S = 20.0
#: output rows about this far apart [s] (energy and attitude error are read there)
STIFF_OUTPUT_DT_S = 0.5
#: fixed-step scan: doubling from this step [s] up to a quarter of the run, then bisections
STIFF_SCAN_START_S = 0.005
QUICK_STIFF_SCAN_START_S = 0.01
STIFF_BISECTIONS = 6
#: a fixed-step run is unstable when it stops (non-finite state, Newton not converged) or when a
#: mode's energy η̇² + ω²η² peaks above this many times the reference's peak: an unstable mode
#: grows exponentially (>= 6e4x in the full run), a stable step at most loses less of it than the
#: physical damping (<= 1.6x, rk4 right at its limit, where |R(hλ)| -> 1)
STIFF_MODE_GROWTH = 10.0
#: adaptive sweep: rtol (= atol) by half decades until the attitude error is below the target
#: [rad] (the 0.1 Hz mode rocks the station by 2.9e-4 rad: the target is 3.4e-5 of that)
STIFF_RTOLS = [10.0 ** (-k / 2) for k in range(6, 21)]
STIFF_TARGET_RAD = 1e-8
STIFF_REF = {"integrator": "dop853", "rtol": 1e-11, "atol": 1e-13}
#: log-log slope of cost against f_hi above which a method's cost is set by the stiff mode
STIFF_SLOPE = 0.5
#: the Newton-defect panel: the rigid tumble of the other cases over this long a run [s], for
#: contrast with the stiff modes (one step from ``probes.NEWTON_STATES`` states along each run)
NEWTON_TUMBLE_S = 2000.0


def stiff_scene(f_hi: float, duration: float, damping_hi: float = STIFF_DAMPING) -> Scene:
    """The stiff-modes scene: the core with its wing's 0.1 Hz mode and a stiff second mode.

    Parameters
    ----------
    f_hi : float
        Frequency of the stiff mode (clamped) [Hz].
    duration : float
        [s].
    damping_hi : float
        Damping ratio of the stiff mode [-].

    Returns
    -------
    Scene
    """
    d = dict(_STIFF_SCENE, simulation={"duration": duration, "output_dt": STIFF_OUTPUT_DT_S})
    wing = dict(_STIFF_SCENE["appendage"][0])
    shapes = []
    for n in (1, 2):  # the beam's integrals given directly: a beam = {..} key recomputes them at every run
        phi_bar, H_hat, M = beam_mode(n, mass=wing["mass"], **_STIFF_BEAM)
        shapes.append({"translation": phi_bar.tolist(), "rotation": H_hat.tolist(), "modal_mass": M})
    wing["mode"] = [
        {"frequency_hz": STIFF_LOW_HZ, "damping": STIFF_DAMPING, "eta0": STIFF_ETA0_M, **shapes[0]},
        {"frequency_hz": f_hi, "damping": damping_hi, **shapes[1]},
    ]
    d["appendage"] = [wing]
    return scene_from_dict(d, source="study stiff-modes scene")


def _why(status: str) -> str:
    """Why a fixed-step run stopped, in the CSV's words."""
    if "not finite" in status:
        return "blows up"
    if "did not converge" in status:
        return "Newton does not converge"
    return status


@stability_case("stiff_modes")
def stiff_modes(ctx: Context) -> Case:
    """Every integrator on the stiff-modes scene at each frequency of the stiff mode: fixed-step
    methods by a doubling scan and bisection of the step (stable while no mode's energy
    grows), implicit ones also by their Newton defect; adaptive methods by the RHS evaluations
    of the loosest rtol reaching ``STIFF_TARGET_RAD``."""
    freqs = QUICK_STIFF_FREQS_HZ if ctx.quick else STIFF_FREQS_HZ
    duration = QUICK_STIFF_DURATION_S if ctx.quick else STIFF_DURATION_S
    h0 = QUICK_STIFF_SCAN_START_S if ctx.quick else STIFF_SCAN_START_S
    case = Case(
        ctx.name,
        f"stiff array modes: {STIFF_LOW_HZ:g} Hz mode + a stiff mode at {', '.join(f'{f:g}' for f in freqs)} Hz "
        f"({duration:g} s, momentum form)",
        f"fixed step: unstable when the run stops or a mode's energy η̇² + ω²η² peaks above {STIFF_MODE_GROWTH:g}x "
        f"the reference's; doubling scan from {h0:g} s, then {STIFF_BISECTIONS} geometric bisections. "
        f"Adaptive: RHS evaluations of the loosest rtol (= atol, by half decades) with attitude error "
        f"<= {STIFF_TARGET_RAD:g} rad vs DOP853 rtol {STIFF_REF['rtol']:g}",
    )
    integs = registered_integrators()
    fixed = {n: c for n, c in integs.items() if not c.adaptive}
    adaptive = {n: c for n, c in integs.items() if c.adaptive}
    tableaus = explicit_tableaus()
    R4 = stability_function(*RK4_TABLEAU)
    scenes = {f: stiff_scene(f, duration) for f in freqs}
    ctx.note("eigenvalues of the linearised RHS")
    lams = {f: rhs_eigenvalues(sc) for f, sc in scenes.items()}
    w_max = {f: float(np.max(np.abs(lam))) for f, lam in lams.items()}
    rk4_pred = {f: predicted_step(R4, lam) for f, lam in lams.items()}
    refs: dict = {}

    def mode_label(key) -> str:
        """A scene of the sweep in words: ``"20 Hz"``, or ``"20 Hz damped 0.3"``."""
        return f"{freqs[-1]:g} Hz damped {STIFF_DAMPED:g}" if key == "damped" else f"{key:g} Hz"

    def ref(f, dt):
        if (f, dt) not in refs:
            ctx.note(f"reference dop853 at {mode_label(f)}")
            refs[(f, dt)] = simulate(scenes[f], formulation="momentum", output_dt=dt, duration=duration, **STIFF_REF)
        return refs[(f, dt)]

    rows = []
    header = ["part", "f_hi_hz", "omega_max_rad_s", "rk4_step_limit_s", "integrator", "step_s", "rtol", "status", "passed",
              "att_err_rad", "mode_energy_ratio", "n_rhs", "n_steps", "wall_s", "newton_defect"]

    def row(part, f, name, **kw):
        r = dict.fromkeys(header, math.nan)
        r.update(part=part, f_hi_hz=f, omega_max_rad_s=w_max.get(f, math.nan), rk4_step_limit_s=rk4_pred.get(f, math.nan),
                 integrator=name, status="", passed="")
        r.update(kw)
        rows.append(r)
        return r

    # (a) fixed step: largest stable step
    def run_fixed(f, name, h):
        dt = h * max(1, round(STIFF_OUTPUT_DT_S / h))  # rows every ~0.5 s, a whole number of steps
        ctx.note(f"{name} at {f:g} Hz, h {h:.3g} s")
        with np.errstate(all="ignore"):
            tr, status = try_simulate(scenes[f], "momentum", name, step=h, output_dt=dt, duration=duration)
        if status.startswith("skipped"):
            return None, status
        r = row("fixed", f, name, step_s=h, status=status)
        if tr is None or status != "ok" or len(tr) < 2:
            r.update(passed=0, why=_why(status))
            return r, status
        rf = ref(f, dt)
        growth = float(np.max(modal_energy(scenes[f], tr).max(axis=0) / modal_energy(scenes[f], rf).max(axis=0)))
        att, _ = max_errors(tr, rf)
        ok = growth <= STIFF_MODE_GROWTH
        r.update(att_err_rad=att, mode_energy_ratio=growth, n_rhs=int(tr.meta["n_rhs"]), n_steps=int(tr.meta["n_steps"]),
                 wall_s=tr.meta["wall_s"], passed=int(ok), why="ok" if ok else "a mode's energy grows")
        return r, status

    fixed_res: dict = {}  # name -> {f: (h_pass, h_fail, why, [rows])}
    skipped: dict = {}
    for name in fixed:
        for f in freqs:
            pts, h, h_pass, h_fail = [], h0, None, None
            while h <= duration / 4:
                r, status = run_fixed(f, name, h)
                if r is None:
                    skipped[name] = status
                    break
                pts.append(r)
                if r["passed"]:
                    h_pass, h = h, 2 * h
                else:
                    h_fail = h
                    break
            if name in skipped:
                break
            if h_pass is not None and h_fail is not None:
                for _ in range(STIFF_BISECTIONS):
                    hm = math.sqrt(h_pass * h_fail)
                    r, _ = run_fixed(f, name, hm)
                    pts.append(r)
                    h_pass, h_fail = (hm, h_fail) if r["passed"] else (h_pass, hm)
            pts.sort(key=lambda r: r["step_s"])
            why = next((r["why"] for r in pts if r["step_s"] == h_fail), "")
            fixed_res.setdefault(name, {})[f] = (h_pass, h_fail, why, pts)

    # radau's Newton iteration: the stiff linear modes against the nonlinear rigid tumble
    implicit = [n for n in fixed_res if math.isfinite(fixed[n].DEFECT_TOL)]
    tumble = tumble_scene(NEWTON_TUMBLE_S, NEWTON_TUMBLE_S / 10)
    w_tumble = float(np.linalg.norm(tumble.initial.omega_BN_B))  # rad/s
    newton: dict = {}
    for name in implicit:
        for f in freqs:
            hs = [r["step_s"] for r in fixed_res[name][f][3]]
            ctx.note(f"{name} Newton defects at {f:g} Hz")
            newton[(name, f)] = (hs, newton_defects(scenes[f], name, hs))
        hs = [2.0**k for k in range(0, 11)]  # 1 ... 1024 s
        ctx.note(f"{name} Newton defects on the rigid tumble")
        newton[(name, "tumble")] = (hs, newton_defects(tumble, name, hs))
    for (name, f), (hs, ds) in newton.items():
        for h, dd in zip(hs, ds):
            if f == "tumble":
                rows.append(dict(dict.fromkeys(header, math.nan), part="newton_rigid_tumble", integrator=name, step_s=h,
                                 status="", passed="", newton_defect=dd))
            else:
                row("newton", f, name, step_s=h, newton_defect=dd)

    # (b) adaptive: cost of a fixed accuracy; at the highest frequency also with the stiff mode
    # well damped (its eigenvalues leave the imaginary axis)
    f_hi = freqs[-1]
    scenes["damped"] = stiff_scene(f_hi, duration, damping_hi=STIFF_DAMPED)
    lam_damped = rhs_eigenvalues(scenes["damped"])
    w_max["damped"], rk4_pred["damped"] = float(np.max(np.abs(lam_damped))), predicted_step(R4, lam_damped)

    def cheapest(key, name):
        """The loosest rtol's run reaching the target (None: none did), or "skipped: ..."."""
        for rtol in STIFF_RTOLS:
            ctx.note(f"{name} at {mode_label(key)}, rtol {rtol:.2g}")
            tr, status = try_simulate(scenes[key], "momentum", name, rtol=rtol, atol=rtol, output_dt=STIFF_OUTPUT_DT_S,
                              duration=duration)
            if status.startswith("skipped"):
                return status
            r = row("adaptive" if key != "damped" else f"adaptive_damping_{STIFF_DAMPED:g}",
                    f_hi if key == "damped" else key, name, rtol=rtol, status=status, omega_max_rad_s=w_max[key],
                    rk4_step_limit_s=rk4_pred[key])
            if tr is None or status != "ok":
                continue
            att, _ = max_errors(tr, ref(key, STIFF_OUTPUT_DT_S))
            r.update(att_err_rad=att, n_rhs=int(tr.meta["n_rhs"]), n_steps=int(tr.meta["n_steps"]), wall_s=tr.meta["wall_s"])
            if att <= STIFF_TARGET_RAD:
                return r
        return None

    adapt_res: dict = {}  # name -> {f or "damped": row reaching the target, or None}
    for name in adaptive:
        for key in [*freqs, "damped"]:
            r = cheapest(key, name)
            if isinstance(r, str):
                skipped[name] = r
                break
            adapt_res.setdefault(name, {})[key] = r

    # verdicts
    fastest = lams[f_hi][np.argmax(np.abs(lams[f_hi]))]
    for name, cls in fixed.items():
        if name in skipped:
            case.add(name, math.nan, "s", skipped[name])
        else:
            case.add(name, *_fixed_verdict(name, cls, fixed_res[name], freqs, w_max, h0, tableaus, fastest, newton))
    for name in adaptive:
        if name in skipped:
            case.add(name, math.nan, "RHS evals", skipped[name])
        else:
            case.add(name, *_adaptive_verdict(name, adapt_res[name], freqs, w_max, duration, tableaus, fastest))

    fig = _plot_stiff(ctx.plt, case, freqs, duration, fixed_res, adapt_res, newton, w_max, w_tumble, rk4_pred, tableaus, lams)
    ctx.save(case, fig, [[r[c] for c in header] for r in rows], header)
    return case


def _fixed_verdict(name, cls, res, freqs, w_max, h0, tableaus, fastest, newton) -> tuple:
    """``(value [s], unit, verdict)`` of a fixed-step method: its largest stable step per frequency."""
    f_lo, f_hi = freqs[0], freqs[-1]
    acc = {f: max((r["step_s"] for r in res[f][3] if r["passed"] and r["att_err_rad"] <= STIFF_TARGET_RAD), default=math.nan)
           for f in freqs}
    acc_txt = f"attitude error <= {STIFF_TARGET_RAD:g} rad up to h = " + ", ".join(f"{acc[f]:.3g} s ({f:g} Hz)" for f in freqs)
    failing = [f for f in freqs if res[f][1] is not None]
    if res[f_hi][0] is None or res[f_lo][0] is None:
        f = f_hi if res[f_hi][0] is None else f_lo
        return math.nan, "s", f"fails already at h = {h0:g} s at {f:g} Hz ({res[f][2]})"
    if failing:
        x = [w_max[f] * res[f][0] for f in failing]
        pred = ""
        if name in tableaus:
            bound = stability_boundary(stability_function(*tableaus[name]), fastest)
            pred = f" (its stability boundary on the fastest eigenvalue: {bound:.3g})"
        return res[f_hi][0], "s", (
            f"stability-bound: largest stable step {res[f_lo][0]:.3g} s at {f_lo:g} Hz, {res[f_hi][0]:.3g} s at "
            f"{f_hi:g} Hz; ω_max h_max = {min(x):.3g}–{max(x):.3g}{pred}; fails by: {res[f_hi][2]}; {acc_txt}")
    h_top = res[f_hi][0]
    defects = [d for f in freqs for d in newton.get((name, f), ([], []))[1]]
    newton_txt = f"; largest Newton defect {max(defects):.2g} (tolerance {cls.DEFECT_TOL:g})" if defects else ""
    return h_top, "s", (f"stable at every step tried, up to {h_top:g} s (ω_max h = {w_max[f_hi] * h_top:.3g} at "
                        f"{f_hi:g} Hz){newton_txt}; {acc_txt}")


def _adaptive_verdict(name, res, freqs, w_max, duration, tableaus, fastest) -> tuple:
    """``(value [RHS evals], unit, verdict)`` of an adaptive method: its cost of the target
    accuracy against the stiff mode's frequency (log-log slope)."""
    f_hi = freqs[-1]
    got = [f for f in freqs if res[f] is not None]
    missed = [f for f in freqs if res[f] is None]
    cost = ", ".join(f"{res[f]['n_rhs']} ({f:g} Hz, rtol {res[f]['rtol']:.2g})" for f in got)
    parts = []
    if len(got) >= 2:
        slope = float(np.polyfit(np.log(got), np.log([res[f]["n_rhs"] for f in got]), 1)[0])
        grows = "grows with" if slope > STIFF_SLOPE else "independent of"
        parts.append(f"cost {grows} the stiff mode (slope {slope:.2f}): RHS evals {cost}")
    elif got:
        parts.append(f"RHS evals {cost}")
    if missed:
        parts.append(f"does not reach {STIFF_TARGET_RAD:g} rad at {', '.join(f'{f:g}' for f in missed)} Hz")
    damped = res.get("damped")
    parts.append(f"stiff mode at damping {STIFF_DAMPED:g}: "
                 + (f"{damped['n_rhs']} at {f_hi:g} Hz" if damped else f"does not reach {STIFF_TARGET_RAD:g} rad"))
    if name in tableaus and res[f_hi] is not None and res[f_hi]["n_steps"] > 0:
        bound = stability_boundary(stability_function(*tableaus[name]), fastest)
        parts.append(f"mean ω_max h at {f_hi:g} Hz {w_max[f_hi] * duration / res[f_hi]['n_steps']:.3g} "
                     f"(stability boundary {bound:.3g})")
    return (float(res[f_hi]["n_rhs"]) if res[f_hi] else math.nan), "RHS evals", "; ".join(parts)


def _plot_stiff(plt, case, freqs, duration, fixed_res, adapt_res, newton, w_max, w_tumble, rk4_pred, tableaus, lams):
    from matplotlib.lines import Line2D

    fig, ((ax_e, ax_h), (ax_n, ax_c)) = plt.subplots(2, 2, figsize=(16, 11), constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    fcol = {f: cmap(0.85 * i / max(1, len(freqs) - 1)) for i, f in enumerate(freqs)}
    names = list(fixed_res)
    icol = colours(plt, names)
    style = {n: (STYLES[j % len(STYLES)], MARKERS[j % len(MARKERS)]) for j, n in enumerate(names)}
    fail_y = 1e-2

    # (a) attitude error against the fixed step, per stiff-mode frequency
    for j, name in enumerate(names):
        ls, mk = style[name]
        lw = max(3.5 - 1.0 * j, 1.2)  # methods with equal errors (rk4, lie_rk4) stay visible
        for f in freqs:
            pts = fixed_res[name][f][3]
            good = [r for r in pts if r["passed"]]
            ax_e.loglog([r["step_s"] for r in good], [max(r["att_err_rad"], 1e-16) for r in good], color=fcol[f],
                        linestyle=ls, marker=mk, markersize=4 + lw, linewidth=lw, alpha=0.9)
            bad = [r for r in pts if not r["passed"]]
            ax_e.plot([r["step_s"] for r in bad], [fail_y] * len(bad), "x", color=fcol[f], markersize=8)
    for f in freqs:
        ax_e.axvline(rk4_pred[f], color=fcol[f], linestyle=":", linewidth=1)
    ax_e.axhline(STIFF_TARGET_RAD, color="red", linestyle="--", linewidth=0.9)
    handles = [Line2D([], [], color=fcol[f], linewidth=2.5, label=f"stiff mode {f:g} Hz (ω_max {w_max[f]:.3g} rad/s)") for f in freqs]
    handles += [Line2D([], [], color="k", linestyle=style[n][0], marker=style[n][1], linewidth=max(3.5 - 1.0 * j, 1.2),
                       label=n) for j, n in enumerate(names)]
    handles += [Line2D([], [], color="k", marker="x", linestyle="", label=f"unstable (drawn at {fail_y:g})"),
                Line2D([], [], color="0.4", linestyle=":", label="RK4 stability limit, predicted"),
                Line2D([], [], color="red", linestyle="--", label=f"target {STIFF_TARGET_RAD:g} rad")]
    ax_e.legend(handles=handles, fontsize=8, loc="lower right")
    ax_e.set_xlabel("fixed step h [s]")
    ax_e.set_ylabel("max attitude error vs reference [rad]")
    ax_e.set_title("(a) fixed step: attitude error against step size")
    ax_e.grid(True, which="both", alpha=0.3)

    # (b) largest stable step against the stiff mode's frequency
    for name in names:
        res = fixed_res[name]
        fs = [f for f in freqs if res[f][0] is not None]
        if not fs:
            continue
        bounded = any(res[f][1] is not None for f in fs)
        j = names.index(name)
        ax_h.loglog(fs, [res[f][0] for f in fs], color=icol[name], linestyle=style[name][0],
                    marker=style[name][1] if bounded else "^", markersize=max(13 - 4 * j, 7) if bounded else 10,
                    label=f"{name}: largest stable step" if bounded else f"{name}: stable at every step tried (the largest drawn)")
    ax_h.loglog(freqs, [rk4_pred[f] for f in freqs], color="k", linestyle="--", linewidth=1,
                label=f"RK4 prediction: stability boundary / ω_max ({rk4_pred[freqs[-1]] * w_max[freqs[-1]]:.3g} / ω_max)")
    ax_h.set_xlabel("stiff mode frequency [Hz]")
    ax_h.set_ylabel("largest stable fixed step [s]")
    ax_h.set_title(f"(b) largest stable fixed step (runs of {duration:g} s)")
    ax_h.legend(fontsize=8)
    ax_h.grid(True, which="both", alpha=0.3)

    # (c) Newton defect of one implicit step: stiff linear modes against a nonlinear tumble
    for (name, f), (hs, ds) in newton.items():
        if f == "tumble":
            label = f"{name}, rigid tumble of the long-horizon case (|ω| {w_tumble:.2g} rad/s, no modes)"
        else:
            label = f"{name}, stiff mode {f:g} Hz (ω_max h up to {w_max[f] * max(hs):.0f})"
        ax_n.loglog(hs, np.maximum(np.asarray(ds, dtype=float), 1e-16), marker="o", markersize=4,
                    color="k" if f == "tumble" else fcol[f], linewidth=2 if f == "tumble" else 1.2, label=label)
    for name in {n for n, _ in newton}:
        ax_n.axhline(INTEGRATORS[name].DEFECT_TOL, color="red", linestyle="--", linewidth=0.9,
                     label=f"{name} stops above {INTEGRATORS[name].DEFECT_TOL:g}")
    ax_n.set_xlabel("fixed step h [s]")
    ax_n.set_ylabel("largest Newton defect of one step [-] (0 drawn at 1e-16)")
    ax_n.set_title("(c) implicit step: Newton defect, stiff linear modes vs a nonlinear rigid tumble")
    ax_n.legend(fontsize=8)
    ax_n.grid(True, which="both", alpha=0.3)

    # (d) adaptive methods: RHS evaluations for a fixed accuracy
    acol = colours(plt, list(adapt_res))
    f_hi = freqs[-1]
    for name, res in adapt_res.items():
        fs = [f for f in freqs if res[f] is not None]
        ax_c.loglog(fs, [res[f]["n_rhs"] for f in fs], color=acol[name], marker="o", label=name)
        miss = [f for f in freqs if res[f] is None]
        if miss:
            ax_c.plot(miss, [max((r["n_rhs"] for r in res.values() if r), default=1e3)] * len(miss), "x",
                      color=acol[name], markersize=9)
    for name, res in adapt_res.items():
        if res.get("damped"):
            ax_c.plot([f_hi], [res["damped"]["n_rhs"]], marker="D", markersize=9, markerfacecolor="none",
                      markeredgewidth=1.5, color=acol[name], linestyle="")
    ax_c.plot([], [], marker="D", markerfacecolor="none", color="k", linestyle="",
              label=f"open: the {f_hi:g} Hz mode damped at {STIFF_DAMPED:g} instead of {STIFF_DAMPING:g}")
    if "dop853" in adapt_res and "dop853" in tableaus:
        R = stability_function(*tableaus["dop853"])
        stages = len(tableaus["dop853"][1])
        bound = [stages * duration * w_max[f] / stability_boundary(R, lams[f][np.argmax(np.abs(lams[f]))]) for f in freqs]
        ax_c.loglog(freqs, bound, color="0.3", linestyle=":", linewidth=1.5,
                    label=f"dop853 with every step on its stability boundary ({stages} RHS per step)")
    ax_c.set_xlabel("stiff mode frequency [Hz]")
    ax_c.set_ylabel(f"RHS evaluations to reach {STIFF_TARGET_RAD:g} rad")
    ax_c.set_title(f"(d) adaptive: cost of {STIFF_TARGET_RAD:g} rad attitude accuracy")
    ax_c.legend(fontsize=8)
    ax_c.grid(True, which="both", alpha=0.3)
    fig.suptitle(case.title)
    return fig
