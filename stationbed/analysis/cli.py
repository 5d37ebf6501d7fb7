"""Commands ``stationbed linearize | margins | plot | compare`` (parsers and handlers; registered in
stationbed/cli.py). Heavy imports happen in the handlers, not when the parsers are built."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

__all__ = ["COMMANDS", "add_parsers", "main"]

COMMANDS = ("linearize", "margins", "plot", "compare")


def _about(s: str):
    if s in ("lvlh", "tea"):
        return s
    raise ValueError(f"--about must be 'lvlh' or 'tea', got {s!r}")


def _seconds(positive: bool = False):
    """argparse type of a time option: a finite number of seconds, >= 0 (> 0 when ``positive``);
    anything else is refused (argparse names the option; exit 2) before any work."""
    import argparse

    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number of seconds, got {s!r}") from None
        if not math.isfinite(v) or v < 0 or (positive and v == 0):
            raise argparse.ArgumentTypeError(f"must be a finite time {'> 0' if positive else '>= 0'} [s], got {s!r}")
        return v

    return conv


def add_parsers(sub) -> None:
    """Add the four commands to the ``stationbed`` subparsers."""
    lz = sub.add_parser("linearize", help="linear plant of a scene (python-control StateSpace): matrices, poles, zeros, Bode and pole-zero PNGs")
    lz.add_argument("scene", type=Path)
    lz.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene>/linearize)")
    lz.add_argument("--about", default="lvlh", help="'lvlh' (R fixed in LVLH) or 'tea' (torque-equilibrium attitude, found)")
    lz.add_argument("--t", type=_seconds(), default=0.0, help="time the time-varying terms are frozen at [s] (default 0)")
    lz.add_argument("--dt", type=_seconds(positive=True), default=None, help="also write the zero-order-hold plant for this period [s]")
    lz.add_argument("--command", default="torque", choices=["torque", "gimbal_rates"], help="control input (default torque)")
    lz.add_argument("--config", default="before", help="configuration: 'before' (as the scene starts), 'after' (every "
                                                      "[[event]] done) or n (after event n) (docs/docking.md)")
    mg = sub.add_parser("margins", help="loop margins of the scene's controller (exact, or finite differences of a Python-only law): "
                                          "table, Bode and Nichols PNGs")
    mg.add_argument("scene", type=Path)
    mg.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene>/margins)")
    mg.add_argument("--t", type=_seconds(), default=0.0, help="time the time-varying terms are frozen at [s] (default 0)")
    mg.add_argument("--config", default="before", help="configuration: 'before', 'after' or n (after event n)")
    pl = sub.add_parser("plot", help="dashboard PNG of a run folder (trajectory.csv, summary.json)")
    pl.add_argument("outdir", type=Path)
    pl.add_argument("--png", type=Path, default=None, help="output file (default: OUTDIR/dashboard.png)")
    cp = sub.add_parser("compare", help="overlay runs and print their metrics (the Monte Carlo's definitions)")
    cp.add_argument("outdirs", type=Path, nargs="+")
    cp.add_argument("--png", type=Path, default=None, help="output file (default: compare_<A>_vs_<B>_<hash>.png in the first folder's parent, one per set of runs)")
    cp.add_argument("--settle", type=_seconds(), default=None, help="settling time for the metrics [s] (default: the metrics' own)")


def main(args) -> int:
    """Run one of :data:`COMMANDS`; returns the exit status."""
    return {"linearize": _linearize, "margins": _margins, "plot": _plot, "compare": _compare}[args.cmd](args)


def _configuration(scene, which: str):
    """``--config``: the scene in that configuration (scene/docking.py); a bad name is an error
    naming the option (exit 2)."""
    from ..scene.docking import configuration_at

    try:
        return configuration_at(scene, which)
    except ValueError as e:
        print(f"stationbed: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def _out(args, scene, what: str, files: tuple[str, ...]) -> Path:
    """``--out`` or ``out/<scene name>/<what>`` (core.paths.default_out, never outside ``out/``),
    its files checked against the scene file before anything is written."""
    from ..core.paths import check_outputs, default_out

    out = args.out or default_out(scene.name, what)
    check_outputs({"the scene file": args.scene}, {f"{what}'s {f}": out / f for f in files})
    return out


def _png_is_no_input(png, outdirs) -> None:
    """``--png`` is checked against the run files it reads (BadOutput before anything is read)."""
    if png is None:
        return
    from ..core.paths import CSV_NAME, PARTIAL_CSV, SUMMARY_NAME, check_outputs

    inputs = {f"the input {d / f}": d / f for d in outdirs for f in (CSV_NAME, PARTIAL_CSV, SUMMARY_NAME)}
    check_outputs(inputs, {"--png": png})


def _fmt_pole(s) -> str:
    wn = abs(s)
    if abs(s.imag) < 1e-15:
        return f"{s.real:+.4g}"
    zeta = -s.real / wn if wn > 0 else 0.0
    return f"{s.real:+.4g} ± {abs(s.imag):.4g}j (ωn {wn:.4g} rad/s, ζ {zeta:.3g})"


def _poles_text(poles) -> list[str]:
    seen, out = [], []
    for s in sorted(poles, key=lambda s: (abs(s), s.imag)):
        if s.imag < 0:
            continue
        out.append(_fmt_pole(complex(s)))
        seen.append(s)
    return out


def _linearize(args) -> int:
    import numpy as np

    from ..scene import load_scene
    from . import figures
    from .plant import linearize

    scene = _configuration(load_scene(args.scene), args.config)
    out = _out(args, scene, "linearize", ("plant.npz", "poles_zeros.json", "bode.png", "pole_zero.png"))
    out.mkdir(parents=True, exist_ok=True)
    sys = linearize(scene, _about(args.about), t=args.t, command=args.command)
    lin = sys.linearization
    nv = len(sys.input_labels) - 3
    zeros = {}
    for i in range(min(nv, 3) if args.command == "torque" else 0):
        zeros[f"{sys.input_labels[i]}→{sys.output_labels[i]}"] = figures.siso_zeros(sys.A, sys.B[:, i], sys.C[i])
    arrays = dict(A=sys.A, B=sys.B, C=sys.C, D=sys.D, states=np.array(sys.state_labels), inputs=np.array(sys.input_labels),
                  outputs=np.array(sys.output_labels), z0=lin.z0, u0=lin.u0, t=lin.t, q_RO=lin.q_RO, poles=sys.poles())
    if args.dt is not None:
        import control

        sd = control.c2d(sys, args.dt, method="zoh")
        arrays.update(Ad=sd.A, Bd=sd.B, dt=args.dt)
    np.savez(out / "plant.npz", **arrays)
    poles = sys.poles()
    text = {"scene": scene.name, "about": args.about, "t_s": lin.t, "n_states": sys.nstates,
            "states": sys.state_labels, "inputs": sys.input_labels, "outputs": sys.output_labels,
            "poles_rad_s": [[float(p.real), float(p.imag)] for p in poles],
            "zeros_rad_s": {k: [[float(z.real), float(z.imag)] for z in v] for k, v in zeros.items()}}
    if lin.trim_torque is not None:
        text["trim_torque_Nm"] = lin.trim_torque.tolist()
    if lin.tea_theta is not None:
        text["tea_deg"] = np.degrees(lin.tea_theta).tolist()
    (out / "poles_zeros.json").write_text(json.dumps(text, indent=1) + "\n")
    from .plant import modal_poles

    modal = modal_poles(sys.A, lin.modal_states)
    title = f"{scene.name} about {args.about}"
    pairs = [(i, i, f"{sys.input_labels[i]} → {sys.output_labels[i]}") for i in range(min(nv, 3))] if args.command == "torque" else []
    figures.bode_png(out / "bode.png", sys, pairs or [(0, 0, f"{sys.input_labels[0]} → {sys.output_labels[0]}")],
                     f"{title}: control torque to attitude error", "rad/(N m)")
    figures.pole_zero_png(out / "pole_zero.png", poles, zeros, title, modal)
    where = args.about if scene.orbit is not None else "N (no orbit: R fixed in N)"
    print(f"{scene.name}: linear plant about {where} at t = {lin.t:g} s: {sys.nstates} states, "
          f"{sys.ninputs} inputs ({nv} control, 3 disturbance), {sys.noutputs} outputs")
    print("  states: " + ", ".join(sys.state_labels))
    if lin.tea_theta is not None:
        print("  TEA (θ relative to LVLH) [deg]: " + ", ".join(f"{v:.4f}" for v in np.degrees(lin.tea_theta)))
    if lin.trim_torque is not None:
        print("  torque that holds the point [N m]: " + ", ".join(f"{v:.4g}" for v in lin.trim_torque)
              + (" (beyond the cluster's limits: linearised at zero command)" if lin.trim_limited else ""))
    tiny = 1e-9 * max(1.0, float(np.abs(poles).max()))
    small = [p for p in poles if abs(p) < tiny]
    print(f"  poles [rad/s] ({len(small)} within {tiny:.0e} of 0: states nothing pulls back, e.g. gimbal angles):")
    for s, p in zip(_poles_text([p for p in poles if abs(p) >= tiny]), sorted([p for p in poles if abs(p) >= tiny and p.imag >= 0], key=lambda s: (abs(s), s.imag))):
        mark = "   (array mode)" if any(abs(p - m) < 1e-12 * abs(m) for m in modal) else ""
        print("    " + s + mark)
    for k, z in zeros.items():
        z = [v for v in sorted(z, key=abs) if v.imag >= 0 and abs(v) >= tiny]
        print(f"  zeros {k}:")
        print("    " + ("\n    ".join(_fmt_pole(complex(v)) for v in z) or "none"))
    print(f"  wrote {out}/plant.npz, poles_zeros.json, bode.png, pole_zero.png")
    return 0


def _num(v, fmt=".3g") -> str:
    return "inf" if v == math.inf else ("-" if not math.isfinite(v) else format(v, fmt))


def _margins(args) -> int:
    import numpy as np

    from ..scene import load_scene
    from . import figures
    from .margins import loop_analysis

    scene = _configuration(load_scene(args.scene), args.config)
    out = _out(args, scene, "margins", ("margins.json", "loop_bode.png", "nichols.png"))
    out.mkdir(parents=True, exist_ok=True)
    la = loop_analysis(scene, t=args.t)
    ctrl = la.controller
    print(f"{scene.name}: controller '{ctrl.name}' ({ctrl.command}), loop broken at each plant input, "
          f"the others closed (t = {args.t:g} s)")
    if la.gain == "numerical":
        from .margins import FD_REL

        print(f"  K = ∂command/∂state by central differences of the law's update (it has no symbolic form; "
              f"step {FD_REL:.2g} x max(|state|, 1) in SI units)")
    if la.left_out:
        print("  the law is closed on the true state; left out: " + "; ".join(la.left_out)
              + " (their sampling, noise, filter dynamics and delay are not in these margins)")
    head = f"  {'channel':<14}{'GM up':>9}{'GM down':>9}{'PM [deg]':>10}{'at [rad/s]':>12}{'disk':>7}{'DGM':>7}{'DPM':>7}{'BW [rad/s]':>12}{'|S|max':>8}"
    print(head)
    for c in la.channels:
        print(f"  {c['channel']:<14}{_num(c['gain_margin_up']):>9}{_num(c['gain_margin_down']):>9}"
              f"{_num(c['phase_margin_deg'], '.1f'):>10}{_num(c['crossover_rad_s']):>12}{_num(c['disk_margin']):>7}"
              f"{_num(c['disk_gain_margin']):>7}{_num(c['disk_phase_margin_deg'], '.1f'):>7}"
              f"{_num(c['bandwidth_rad_s']):>12}{_num(c['sensitivity_peak']):>8}")
    print("  GM down .. GM up: the gain interval; each loop, closed with gain k (the others at 1), keeps its "
          "stability for GM down < k < GM up")
    zero = int(np.sum(np.abs(la.poles) == 0.0))
    print(f"  closed-loop poles [rad/s] (slowest first; {zero} at exactly 0: states without feedback,"
          " e.g. gimbal angles, joint drives at rest):")
    shown = _poles_text([p for p in la.poles if p != 0])
    for s in shown[:14]:
        print("    " + s)
    if len(shown) > 14:
        print(f"    ... {len(la.poles)} in all (margins.json)")
    unstable = [(p, s) for p, s in zip(la.poles, la.pole_states) if p.real > 1e-9 * max(1.0, float(np.abs(la.poles).max()))]
    inside = [(p, s) for p, s in unstable if s in la.loop_states]
    outside = [(p, s) for p, s in unstable if s not in la.loop_states]
    if inside:
        print("  UNSTABLE closed-loop poles: " + ", ".join(f"{_fmt_pole(complex(p))} (mostly {s})" for p, s in inside))
    if outside:
        print("  slow drift of states the attitude loop does not see (no feedback on them): "
              + ", ".join(f"{_fmt_pole(complex(p))} ({s})" for p, s in outside))
    if la.structural_in_band:
        print("  WARNING structural mode(s) inside the control bandwidth: " + ", ".join(f"{w:.3g} rad/s" for w in la.structural_in_band))
    else:
        print("  no structural mode inside the control bandwidth")
    labels = [c["channel"] for c in la.channels]
    figures.loop_bode_png(out / "loop_bode.png", la.loops, labels, f"{scene.name}: loop L_i(jω) of '{ctrl.name}' per input")
    figures.nichols_png(out / "nichols.png", la.loops, labels, f"{scene.name}: Nichols chart of '{ctrl.name}' per input")
    res = {"scene": scene.name, "controller": ctrl.name, "t_s": args.t, "channels": la.channels,
           "closed_loop_poles_rad_s": [[float(p.real), float(p.imag)] for p in la.poles],
           "structural_modes_in_band_rad_s": la.structural_in_band, "loop_states": la.loop_states,
           "gain": la.gain, "left_out": la.left_out}
    (out / "margins.json").write_text(json.dumps(res, indent=1, default=lambda v: None if not math.isfinite(v) else v) + "\n")
    print(f"  wrote {out}/margins.json, loop_bode.png, nichols.png")
    return 0


def _plot(args) -> int:
    from .dashboard import dashboard, load_run, run_state

    _png_is_no_input(args.png, [args.outdir])
    run = load_run(args.outdir)
    png = dashboard(args.outdir, args.png, run=run)
    state = run_state(run[1])
    print(f"wrote {png}" + (f" ({state})" if state else ""))
    return 0


def _compare(args) -> int:
    from .compare import compare

    _png_is_no_input(args.png, args.outdirs)
    table, png = compare(args.outdirs, args.png, settle_s=args.settle)
    print(table)
    print(f"wrote {png}")
    return 0
