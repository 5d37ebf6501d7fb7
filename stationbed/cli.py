"""``stationbed`` command line (DESIGN §6).

    stationbed run SCENE.toml [--out DIR] [--formulation NAME] [--integrator NAME]
                              [--rtol X] [--atol X] [--duration S] [--step S] [--rrd FILE]
    stationbed check SCENE.toml [--rtol X] [--duration S] [--rrd FILE] [--out DIR]
    stationbed report DIR   (junit.xml, report.html of a finished Monte Carlo, check or run folder)
    stationbed replay FILE.rrd [--web]
    stationbed plan SCENE.toml [--out DIR] [--intervals N] [--refine N] [--no-fly] [--set KEY.PATH=VALUE]
    stationbed list

Any bad input or failed run: one line on stderr (``stationbed: error: ...``), non-zero exit
(2 = bad input, 1 = the run or the check failed), and whatever was computed kept on disk.
Set ``STATIONBED_DEBUG=1`` to see the Python traceback (with its chained cause, e.g. the
frames of a controller that raised) before that line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import traceback
from pathlib import Path

# a failed or interrupted run leaves its rows under PARTIAL_CSV, never over a finished result
from .core.paths import CSV_NAME, PARTIAL_CSV, SUMMARY_NAME, BadOutput, WriteFailed, check_outputs, default_out, fresh
from .core.paths import partial_path as _partial
from .output.rerun import live, screenshot as screenshot_cli

EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's own convention)
        self.exit(EXIT_BAD_INPUT, f"stationbed: error: {message}\n")


def _positive(name):
    def conv(s):
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {s!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{name} must be a positive finite number, got {s!r}")
        return v

    return conv


#: run options that are scene values: each is validated by the scene, like the file's own value
SCENE_OPTIONS = {
    "formulation": "simulation.formulation",
    "integrator": "simulation.integrator",
    "rtol": "simulation.rtol",
    "atol": "simulation.atol",
    "duration": "simulation.duration",
    "step": "simulation.step",
    "output_dt": "simulation.output_dt",
}


def _scene_options(p, formulation: bool = True) -> None:
    if formulation:  # (check runs every formulation)
        p.add_argument("--formulation", default=None, help="simulation.formulation")
    p.add_argument("--integrator", default=None, help="simulation.integrator")
    p.add_argument("--rtol", type=float, default=None, help="simulation.rtol")
    p.add_argument("--atol", type=float, default=None, help="simulation.atol (dimensionless)")
    p.add_argument("--duration", type=float, default=None, help="simulation.duration [s]")
    p.add_argument("--output-dt", type=float, default=None, help="simulation.output_dt [s]")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="change one scene value, read as TOML (repeatable): --set simulation.rtol=1e-10, "
                        "--set appendage.stbd_pair.mass=3e3 (an array by name: stbd_pair in scenarios/iss_lvlh_*.toml), "
                        "--set 'simulation.integrator=\"rk4\"'")


def _scene_with_options(args):
    """The scene file with ``--set`` and the run options applied, validated like the file
    (``--rtol 2`` fails as ``rtol = 2`` in the file would); returns ``(scene, changes)``."""
    from .scene import load_scene, parse_assignments

    changes = parse_assignments(args.set)
    for flag, key in SCENE_OPTIONS.items():
        value = getattr(args, flag, None)
        if value is not None:
            changes[key] = value
    scene = load_scene(args.scene)
    if changes:
        scene = scene.replace(changes, source=f"{args.scene} with the command-line options")
    return scene, changes


def _quiet(p, top: bool = False) -> None:
    # before or after the command; a subcommand's default must not undo the top-level flag
    p.add_argument("-q", "--quiet", action="store_true", default=False if top else argparse.SUPPRESS,
                   help="no progress or notices (warnings and errors still show)")


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    p = _Parser(prog="stationbed", description="Space-station attitude control test bed")
    p.add_argument("--version", action="version", version=f"stationbed {__version__}")
    _quiet(p, top=True)
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=_Parser)

    r = sub.add_parser("run", help="simulate a scene, write trajectory.csv (and a rerun recording)")
    _quiet(r)
    r.add_argument("scene", type=Path)
    r.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene name>)")
    _scene_options(r)
    r.add_argument("--step", type=float, default=None, help="fixed step [s] (simulation.step)")
    r.add_argument("--rrd", type=Path, default=None, help="also write a rerun recording")
    live.add_options(r)  # --realtime, --hold-late, --live (issue 36)

    c = sub.add_parser("check", help="run every formulation and compare them")
    _quiet(c)
    c.add_argument("scene", type=Path)
    _scene_options(c, formulation=False)
    c.add_argument("--rrd", type=Path, default=None, help="all formulations in one recording")
    c.add_argument("--out", type=Path, default=None, help="write DIR/junit.xml, report.html and check.json")
    sub.add_parser("report", help="junit.xml and report.html of a finished study, check or run folder"
                   ).add_argument("folder", type=Path)

    sub.add_parser("list", help="every plug-in kind a scene can name: laws, sensors, estimators, actuators, torques, integrators, ...")

    pn = sub.add_parser("plan", help="plan a slew ([plan] table), fly it with the schedule law, compare an eigenaxis slew")
    _quiet(pn)
    pn.add_argument("scene", type=Path)
    pn.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene name>/plan)")
    pn.add_argument("--intervals", type=int, default=None, help="collocation intervals (default: plan.intervals)")
    pn.add_argument("--refine", type=int, default=None, help="solve again on this many intervals, warm started")
    pn.add_argument("--no-fly", action="store_true", help="only plan (no closed-loop flight)")
    pn.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="change one scene value, read as TOML (repeatable): --set 'plan.objective=\"peak_momentum\"'")

    rp = sub.add_parser("replay", help="open a rerun recording in the viewer (or say how to)")
    rp.add_argument("file", type=Path, help="a .rrd recording (stationbed run/check --rrd)")
    rp.add_argument("--web", action="store_true", help="serve the web viewer instead (rerun --web-viewer)")
    rp.add_argument("--bind", default=None, metavar="ADDR",
                    help=f"address the web viewer listens on (default {WEB_BIND_DEFAULT}: this machine only; "
                         "0.0.0.0 serves every network the machine is on)")

    screenshot_cli.add_parser(sub)  # stationbed screenshot (issue 24)
    st = sub.add_parser("study", help="work-precision and stability studies (CSV + PNG charts)")
    ss = st.add_subparsers(dest="study", required=True, parser_class=_Parser)
    sp = ss.add_parser("precision", help="work-precision diagram of one scene: error vs wall time and RHS evaluations")
    _quiet(sp)
    sp.add_argument("scene", type=Path)
    sp.add_argument("--out", type=Path, default=Path("out") / "study", help="output folder (default: out/study)")
    sp.add_argument("--duration", type=_positive("--duration"), default=None, help="[s] (default: the scene's)")
    sp.add_argument("--formulations", nargs="+", default=None, metavar="NAME", help="default: all registered")
    sp.add_argument("--integrators", nargs="+", default=None, metavar="NAME", help="default: all registered")
    sp.add_argument("--quick", action="store_true", help="a small sweep, one repeat (tests, CI)")
    sb = ss.add_parser("stability", help="cases where methods fail: detector, verdict and chart per case")
    _quiet(sb)
    sb.add_argument("--out", type=Path, default=Path("out") / "study", help="output folder (default: out/study)")
    sb.add_argument("--cases", nargs="+", default=None, metavar="NAME", help="default: all cases")
    sb.add_argument("--quick", action="store_true", help="shrink every case to seconds (tests, CI)")
    # its options are parsed by its own module (stationbed/studies/montecarlo/cli.py), imported when run
    sub.add_parser("montecarlo", add_help=False, help="closed-loop Monte Carlo on Dask (stationbed montecarlo -h)")
    from .analysis import cli as analysis_cli  # linearize, margins, plot, compare

    analysis_cli.add_parsers(sub)
    return p


#: set to print the Python traceback (with the chained cause, e.g. a controller's own frames)
#: before the one-line error
DEBUG_ENV = "STATIONBED_DEBUG"


def _debug_traceback(e: BaseException) -> None:
    if os.environ.get(DEBUG_ENV):
        traceback.print_exception(e)


def _fail(msg: str, code: int) -> int:
    from .core import progress

    progress.close_all()  # nothing may follow the error line
    msg = " | ".join(line.strip() for line in str(msg).splitlines() if line.strip())  # one line
    print(f"stationbed: error: {msg}", file=sys.stderr)
    return code


def _cmd_run(args) -> int:
    recorder = None
    if args.rrd or args.live:  # started by main() before the heavy imports; here when called directly
        recorder = getattr(args, "recorder", None) or _start_recording(args)
    try:
        return _run(args, recorder)
    finally:
        if recorder is not None:  # the run never opened it (bad scene, ...): stop the child
            recorder.abort()


def _output_paths(args, scene_name: str | None) -> dict[str, Path]:
    """The run's output files, checked against its inputs and each other (BadOutput)."""
    out = args.out if args.out is not None else default_out(scene_name)
    paths = {"csv": out / CSV_NAME, "partial_csv": out / PARTIAL_CSV, "summary": out / SUMMARY_NAME}
    if args.rrd is not None:
        paths.update(rrd=args.rrd, partial_rrd=_partial(args.rrd))
    check_outputs({"the scene file": args.scene}, {k.replace("_", " "): p for k, p in paths.items()})
    return {"out": out, **paths}


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str))
    os.replace(tmp, path)


def _validate(scene) -> None:
    """Everything that can be refused before an output is opened: the formulation and integrator
    names, the step, the controller, its parameters and its plant (the system is reused by the run)."""
    from .run.closed_loop import plant_facts
    from .run.laws import build_controller
    from .run.prepare import prepare

    system = prepare(scene).system
    spec = scene.controller
    if spec is not None:  # an FMU's variables and binary are checked here, before the first row
        build_controller(spec, base_dir=scene.folder).check(plant_facts(scene, system, spec.period))


def _run(args, recorder) -> int:
    from .run.rows import trajectory_columns
    from .run.simulation import SimulationError, SinkError, simulate
    from .output.csv import CsvSink

    scene, changes = _scene_with_options(args)
    paths, (pace, live_url), recording = _output_paths(args, scene.name), live.options(args), args.rrd or args.live
    _validate(scene)
    out, csv_path, partial = paths["out"], paths["csv"], paths["partial_csv"]
    out.mkdir(parents=True, exist_ok=True)
    status = {"scene": str(args.scene)}
    rrd_error = None
    with CsvSink(fresh(partial), trajectory_columns(scene)) as csv:  # a link there is replaced, not followed
        sink = csv
        if recording:  # stream the rows into the recording (and --live: a viewer) too, as they are computed
            sink = _with_recording(csv, scene, paths.get("partial_rrd"), recorder, changes, live_url)
        try:
            traj = simulate(scene, sink=sink, keep=False, pace=pace)  # rows go to disk, memory stays bounded
        except KeyboardInterrupt:
            if recording:
                rrd_error = sink.close()
            status.update(status="interrupted", rows=csv.rows_written, last_t=csv.last_t, rows_file=partial.name)
            _write_json(paths["summary"], status)
            where = f"up to t = {csv.last_t:g} s " if csv.last_t is not None else ""
            return _fail(f"interrupted; {csv.rows_written} rows {where}kept in {partial}", EXIT_FAILED)
        except SinkError as e:  # the disk is full, say: the file holds whole rows, the message says to when
            if recording:
                rrd_error = sink.close()
            status.update(status="failed", reason=str(e), rows_file=partial.name)
            try:
                _write_json(paths["summary"], status)
            except OSError:
                pass  # the same full disk: the one-line error says it all
            return _fail(str(e), EXIT_FAILED)
        except SimulationError as e:
            _debug_traceback(e)
            if recording:  # finish the recording first: the message says whether it is complete
                rrd_error = sink.close()
            status.update(e.trajectory.meta, rows_file=partial.name)
            _write_json(paths["summary"], status)
            kept = f"{partial} and {paths['partial_rrd']}" if args.rrd and not rrd_error else str(partial)
            failed = f"; recording {paths['partial_rrd']} failed: {rrd_error}" if rrd_error else ""
            return _fail(f"{e}; {e.trajectory.meta['n_rows']} rows kept in {kept}{failed}", EXIT_FAILED)
        finally:
            if recording:  # flush and finish the recording whatever happened
                rrd_error = sink.close()
    os.replace(partial, csv_path)  # the run ended: its rows take the result's name
    if args.rrd and not rrd_error:
        os.replace(paths["partial_rrd"], args.rrd)
    status.update(traj.meta, rows_file=csv_path.name)
    _write_json(paths["summary"], status)
    msg = (
        f"{scene.name}: {traj.meta['n_rows']} rows, t = 0..{traj.t[-1]:g} s, {traj.meta['formulation']}/"
        f"{traj.meta['integrator']}, {traj.meta['n_rhs']} RHS evaluations, "
        f"{traj.meta['wall_s'] * 1e3:.1f} ms -> {csv_path}"
    )
    if args.rrd and not rrd_error:
        msg += f", {args.rrd}"
    print(msg)
    if "summary" in traj.meta:
        print(_summary_line(traj.meta["summary"]))
    if rrd_error:  # the run and its CSV are fine; the recording is not
        return _fail(f"recording {paths['partial_rrd']} failed: {rrd_error}; {csv_path} is complete", EXIT_FAILED)
    return 0


def _summary_line(s: dict) -> str:
    """The closed loop's run summary in one line (saturation is never silent)."""
    parts = [f"controller {s['controller']} at {1 / s['period_s']:g} Hz, {s['ticks']} ticks"]
    if "final_att_err_deg" in s:
        parts.append(f"attitude error final {s['final_att_err_deg']:.3g} deg, max {s['max_att_err_deg']:.3g} deg")
    if "final_cmd_err_deg" in s:  # a law whose command leads its reference (schedule: issue 32)
        parts.append(f"command error (it leads the body) final {s['final_cmd_err_deg']:.3g} deg, max {s['max_cmd_err_deg']:.3g} deg")
    if "max_h_Nms" in s:
        frac = f" ({100 * s['max_h_fraction']:.0f} % of capacity)" if "max_h_fraction" in s else ""
        parts.append(f"max |h| {s['max_h_Nms']:.4g} N m s{frac}")
    if "min_singularity" in s:
        parts.append(f"min singularity measure {s['min_singularity']:.3g}")
    if "rate_limited_ticks" in s:
        parts.append(
            f"gimbal-rate limited {s['rate_limited_ticks']} ticks, momentum saturated {s['momentum_saturated_ticks']} ticks"
        )
    if "mean_nees" in s:  # sensors and the MEKF (issue 20; the window after convergence: issue 32)
        parts.append(f"estimate converged at t = {s['est_converged_s']:.4g} s; estimation error after it: max "
                     f"{s['max_est_err_deg']:.3g} deg, RMS {s['rms_est_err_deg']:.3g} deg, "
                     f"inside 3 sigma {100 * s['est_inside_3sigma']:.1f} %, mean NEES {s['mean_nees']:.3g} (6 states)")
    if "st_dropout_s" in s:
        parts.append(f"star-tracker dropouts {s['st_dropout_s']:.4g} s")
    if s.get("faults"):  # scheduled faults (issue 34)
        parts.append("faults: " + ", ".join(f"{f['kind']} {f['unit']} at {f['t']:g} s" + (" cleared" if f.get("clears") else "")
                                            for f in s["faults"]))
    from .run.chain import chain_summary_parts  # each actuator kind's parts (thrusters: issue 21)
    return "; ".join(parts + chain_summary_parts(s) + live.summary_parts(s))  # a socket law, --realtime (issue 36)


def _start_recording(args):
    """Start the process that writes ``run --rrd``'s recording (stationbed/output/rerun/child.py).

    Called first thing for ``run --rrd``, before the simulation's modules are imported, so that
    the child's ``import rerun`` and set-up overlap the parent's start-up and run.
    """
    from .output.rerun.child import RecordingChild

    if args.rrd and os.path.realpath(args.rrd) == os.path.realpath(args.scene):
        raise BadOutput(f"--rrd {args.rrd} is the scene file: choose another recording path")
    return RecordingChild.start(args.scene, _partial(args.rrd) if args.rrd else None)


class _RecordingTee:
    """Every batch to the CSV sink and to the recording child; :meth:`close` returns ``None`` or
    why the recording failed (the CSV is never affected by the recording)."""

    def __init__(self, csv_sink, recorder):
        self.csv_sink, self.recorder = csv_sink, recorder
        self.columns = csv_sink.columns

    def write(self, rows) -> None:
        self.csv_sink.write(rows)
        self.recorder.write(rows)

    def close(self) -> str | None:
        return self.recorder.close()


def _with_recording(csv_sink, scene, path, recorder=None, changes=None, live_url=None):
    """``csv_sink`` teed with a rerun recording at ``path``, written by ``recorder`` (a started
    :class:`~stationbed.output.rerun.child.RecordingChild`, which builds the same
    :class:`~stationbed.output.rerun.sink.RrdSink`); ``close()`` finishes it and returns ``None`` or the
    reason it failed (one line)."""
    if recorder is None:  # no child (a caller without one): the same sink, in this process
        from .output.rerun.sink import RrdSink, TeeSink

        return TeeSink(csv_sink, RrdSink(scene, path, csv_sink.columns, duration=scene.simulation.duration, live=live_url))
    return _RecordingTee(csv_sink, recorder.open(csv_sink.columns, scene.simulation.duration, scene.name, changes, live_url))


def _cmd_check(args) -> int:
    from .studies.check import check_scene
    from .studies.report import check_outputs_of, write_check

    scene, _ = _scene_with_options(args)
    outs = check_outputs_of(args)  # --rrd, --out's files
    if outs:  # before the formulations run: an output never replaces the scene
        check_outputs({"the scene file": args.scene}, outs)
    res = check_scene(scene)
    print(res.table())
    if args.out:  # junit.xml, report.html and check.json (issue 37)
        write_check(res, scene, args)
    if args.rrd:
        from .output.rerun.recording import write_check_recording

        write_check_recording(res, scene, args.rrd)
    if not res.ok:
        return _fail(f"formulations disagree on {scene.name} beyond tolerance (table above)", EXIT_FAILED)
    print("ok: all formulations agree")
    return 0


def _cmd_report(args) -> int:
    from .studies.report import main

    return main(args.folder)


def _cmd_list(args) -> int:
    from .plugins import format_listing

    print(format_listing())
    return 0


#: First bytes of a rerun recording file (RRF2 in rerun 0.41; RRF0/RRF1 in older files).
RRD_MAGIC = b"RRF"
#: where ``replay --web`` serves: this machine only unless ``--bind`` says otherwise (rerun's own
#: default, 0.0.0.0, would offer the recording to every network the machine is on)
WEB_BIND_DEFAULT = "127.0.0.1"


def _cmd_replay(args) -> int:
    """Open FILE in the rerun viewer and wait until it is closed.

    Exit 0: the viewer ran (and closed normally), or there is no display: then the commands
    that show the recording are printed on stdout (the answer, not an error). Exit 1: the
    viewer binary is missing or failed (the same commands printed, the reason on stderr).
    Exit 2: FILE is missing or not a rerun recording. ``--web`` serves the web viewer
    (``rerun --web-viewer --bind 127.0.0.1 FILE``, http://localhost:9090), which needs no display;
    it listens on this machine only unless ``--bind ADDR`` names another address.
    """
    import shlex
    import subprocess

    from .output.rerun.viewer import has_display, rerun_binary, rerun_command

    f = args.file
    if not f.is_file():
        return _fail(f"no recording at {f}", EXIT_BAD_INPUT)
    with open(f, "rb") as fh:
        if fh.read(len(RRD_MAGIC)) != RRD_MAGIC:
            return _fail(f"{f} is not a rerun recording (.rrd)", EXIT_BAD_INPUT)
    exe = rerun_binary()
    shown = rerun_command(exe)
    native = f"{shown} {shlex.quote(str(f))}"
    bind = getattr(args, "bind", None)
    if bind is not None and not args.web:
        return _fail("--bind is where the web viewer listens: it needs --web", EXIT_BAD_INPUT)
    bind = bind or WEB_BIND_DEFAULT
    web = f"{shown} --web-viewer --bind {shlex.quote(bind)} {shlex.quote(str(f))}"

    def how(reason: str) -> None:
        print(f"{reason}; to replay {f}:")
        print(f"  {native}    # native viewer, on a machine with a display")
        print(f"  {web}    # web viewer here, then open http://localhost:9090 (ssh -L 9090:localhost:9090 ...)")

    if exe is None:
        how("the rerun viewer is not installed (pip install rerun-sdk==0.41.0)")
        return _fail("no rerun binary found", EXIT_FAILED)
    if not args.web and not has_display():
        how("no display ($DISPLAY and $WAYLAND_DISPLAY are unset), so no viewer window can open")
        return 0
    cmd = [exe, "--web-viewer", "--bind", bind, str(f)] if args.web else [exe, str(f)]
    try:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL)
    except OSError as e:
        how(f"{exe} could not be started")
        return _fail(f"{exe}: {e.strerror or e}", EXIT_FAILED)
    try:
        code = proc.wait()
    except KeyboardInterrupt:  # Ctrl-C reached the viewer too; make sure it is gone
        proc.terminate()
        proc.wait()
        return 130
    if code != 0:
        how(f"the viewer exited with status {code}")
        return _fail(f"{' '.join(map(shlex.quote, cmd))} exited with status {code}", EXIT_FAILED)
    return 0


def _cmd_plan(args) -> int:
    from .scene.plan import MAX_INTERVALS
    from .studies.plan_flight import plan_and_fly

    for name in ("intervals", "refine"):  # the NLP's size: plan.intervals' range
        if (v := getattr(args, name)) is not None and not 2 <= v <= MAX_INTERVALS:
            return _fail(f"--{name} must be between 2 and {MAX_INTERVALS}, got {v}", EXIT_BAD_INPUT)
    if (scene := _scene_with_options(args)[0]).plan is None:
        return _fail(f"{args.scene}: plan: missing [plan] table", EXIT_BAD_INPUT)
    out = args.out or default_out(scene.name, "plan")  # a scene named ../../x stays under out/
    try:
        info = plan_and_fly(scene, out, intervals=args.intervals, refine=args.refine, fly=not args.no_fly)
    except WriteFailed as e:  # a full disk: the files written before it stay
        return _fail(str(e), EXIT_FAILED)
    st = info["solver"]
    print(f"plan: cost {info['cost']:.7g}, peak |h| {info['peak_h_Nms']:.6g} N m s "
          f"({100 * info['peak_fraction']:.1f} % of capacity); {st['intervals']} intervals, "
          f"{st['iterations']} iterations, {st['time_s']:.2f} s")
    if "flight" in info:
        f = info["flight"]
        print(f"flown: peak |h| {f['flown_peak_h_Nms']:.6g} N m s, max |h| - planned {f['flown_vs_planned_max_dh_Nms']:.3g} "
              f"N m s, attitude within {f['flown_vs_planned_max_attitude_deg']:.3g} deg of the plan; eigenaxis pd slew: "
              f"peak |h| {f['eigenaxis_peak_h_Nms']:.6g} N m s ({100 * f['eigenaxis_peak_fraction']:.0f} %), "
              f"{f['eigenaxis_saturated_ticks']} saturated ticks")
    print(f"wrote {out}")
    return 0


def _cmd_study(args) -> int:
    from .studies import StudyError, precision_study, stability_study

    try:
        if args.study == "precision":
            res = precision_study(
                args.scene, out=args.out, duration=args.duration, formulations=args.formulations,
                integrators=args.integrators, quick=args.quick,
            )
            print(res.table())
        else:
            res = stability_study(out=args.out, quick=args.quick, cases=args.cases)
        files = res.files if args.study == "precision" else [f for c in res for f in c.files]
    except StudyError as e:
        return _fail(str(e), EXIT_FAILED)
    print(f"wrote {len(files)} files to {args.out}")
    return 0


def _cmd_montecarlo(args) -> int:
    from .studies.montecarlo.cli import main as montecarlo_main

    return montecarlo_main(args.rest)


def main(argv=None) -> int:
    """The command line: ``stationbed run|check|list|replay|study ...``; returns the exit status
    (0 ok, 1 failed run, 2 bad input)."""
    args, args.rest = _parser().parse_known_args(argv)
    if args.rest and args.cmd != "montecarlo":
        _parser().error(f"unrecognized arguments: {' '.join(args.rest)}")
    from .core import interrupts, progress

    progress.configure("quiet" if args.quiet else None)
    try:
        with interrupts.handled():  # SIGTERM stops a command as Ctrl-C does: its clean-up runs
            return _main(args)
    finally:
        progress.reset()  # a caller in Python (tests, notebooks) gets the library default back


def _main(args) -> int:
    if args.cmd == "run" and (args.rrd or args.live):  # first, so the recorder's start-up overlaps the run's
        try:
            args.recorder = _start_recording(args)
        except BadOutput as e:
            return _fail(str(e), EXIT_BAD_INPUT)
    from .scene import SceneError

    try:
        from .analysis import cli as analysis_cli

        if args.cmd in analysis_cli.COMMANDS:
            return analysis_cli.main(args)
        if args.cmd == "screenshot":
            return screenshot_cli.main(args)
        return {"run": _cmd_run, "check": _cmd_check, "list": _cmd_list, "replay": _cmd_replay, "study": _cmd_study,
                "plan": _cmd_plan, "montecarlo": _cmd_montecarlo, "report": _cmd_report}[args.cmd](args)
    except SceneError as e:
        _debug_traceback(e)
        return _fail(str(e), EXIT_BAD_INPUT)
    except ValueError as e:  # unknown formulation/integrator names and other bad arguments
        _debug_traceback(e)
        return _fail(str(e), EXIT_BAD_INPUT)
    except KeyboardInterrupt:  # before a run opened its outputs (a run reports its own rows)
        return _fail("interrupted", EXIT_FAILED)
    except Exception as e:  # never a traceback for a user; keep it one line
        if os.environ.get(DEBUG_ENV):
            raise
        return _fail(f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}", EXIT_FAILED)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
