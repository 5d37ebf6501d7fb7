"""``stationbed montecarlo``: the command line of the Monte Carlo study.

    stationbed montecarlo SCENE [--n N] [--out DIR] [--workers K | --scheduler ADDRESS | --serial]
                                [--connect-timeout S] [--chunk C] [--resume] [--exit-zero]
                                [--set KEY.PATH=VALUE]
    stationbed montecarlo SCENE --sample K [--out DIR] [--rrd FILE]

Without ``--scheduler`` it starts a local Dask cluster of K worker processes (default: the
machine's cores; ``--serial`` runs in this process); with it, it connects to a running
``dask scheduler`` and ships the chunks there (the three are exclusive: one says where the
samples run). ``--sample K`` writes the exact scene of sample K (``DIR/sample_K.toml``; default
DIR ``out/<scene>_montecarlo/sample_K``, never a study's folder) and runs it alone (``DIR/trajectory.csv``, ``DIR/summary.json``; a failed run keeps its rows in
``DIR/trajectory.partial.csv``, as ``stationbed run``).

The study's folder also gets ``junit.xml`` (one test case per requirement) and ``report.html``
(verdicts, worst samples with the command that replays each, envelopes, provenance):
:mod:`stationbed.studies.report`.

Exit status: 0 when the study ran and every requirement is shown to hold, PASS (``--exit-zero``: 0
whatever the verdicts; they are in summary.json and printed); 1 when a requirement is not shown:
FAIL (a sample failed it) or NOT SHOWN (none failed, too few samples to show it); 1 also when a
``--sample`` run failed, when interrupted, or when the disk or the scheduler failed mid-study
(the finished chunks stay on disk: ``--resume``); 2 for bad input (nothing run).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

__all__ = ["add_parser", "main", "DEFAULT_CONNECT_TIMEOUT_S", "EXIT_FAILED", "EXIT_BAD_INPUT"]

#: how long a --scheduler may take to answer [s]
DEFAULT_CONNECT_TIMEOUT_S = 10.0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
#: the files a study writes in its folder (checked against the scene file first)
STUDY_FILES = ("samples.parquet", "summary.json", "study.json", "study.lock", "montecarlo.rrd", "chunks", "junit.xml",
               "report.html")


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``montecarlo`` command to an argparse ``sub`` (``add_subparsers()``) and return it."""
    p = sub.add_parser("montecarlo", help="closed-loop Monte Carlo of a scene's [montecarlo] table, on Dask")
    p.add_argument("scene", type=Path)
    p.add_argument("--n", type=int, default=None, help="samples (default: montecarlo.n)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene>_montecarlo)")
    p.add_argument("--workers", type=int, default=None, help="local Dask worker processes (default: cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a running dask scheduler (tcp://host:8786)")
    p.add_argument("--connect-timeout", type=float, default=DEFAULT_CONNECT_TIMEOUT_S, metavar="S",
                   help=f"wait this long for --scheduler to answer [s] (default {DEFAULT_CONNECT_TIMEOUT_S:g})")
    p.add_argument("--chunk", type=int, default=None, help="samples per task (default: montecarlo.chunk or n/(4 workers))")
    p.add_argument("--resume", action="store_true", help="keep the finished chunks in --out and run the rest")
    p.add_argument("--serial", action="store_true", help="run in this process, without Dask (same numbers)")
    p.add_argument("--sample", type=int, default=None, metavar="K", help="write and run sample K alone")
    p.add_argument("--rrd", type=Path, default=None, help="with --sample: also write a rerun recording of it")
    p.add_argument("--no-charts", action="store_true", help="no PNG charts")
    p.add_argument("--exit-zero", action="store_true",
                   help="exit 0 when the study ran, even if a requirement is not shown (default: exit 1)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="change one scene value first, read as TOML (repeatable)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress")
    return p


def _parser():
    class Parser(argparse.ArgumentParser):
        def error(self, message):  # one line, exit 2 (as stationbed's other commands)
            self.exit(2, f"stationbed: error: {message}\n")

    top = Parser(prog="stationbed")
    add_parser(top.add_subparsers(dest="cmd", parser_class=Parser))
    return top


def _positive(args, name):
    v = getattr(args, name)
    if v is not None and v < 1:
        raise ValueError(f"--{name} must be a positive integer, got {v}")


def _error(msg: str, code: int) -> int:
    from ...core import progress

    progress.close_all()  # nothing may follow the error line
    print(f"stationbed: error: {' | '.join(x.strip() for x in str(msg).splitlines() if x.strip())}", file=sys.stderr)
    return code


def _sample_paths(args, out: Path) -> dict[str, Path]:
    """``--sample K``'s outputs, checked against the scene file and each other (BadOutput)."""
    from ...core.paths import CSV_NAME, PARTIAL_CSV, SUMMARY_NAME, check_outputs, partial_path

    paths = {"the sample's scene file": out / f"sample_{args.sample}.toml", "the trajectory": out / CSV_NAME,
             "the partial trajectory": out / PARTIAL_CSV, "the summary": out / SUMMARY_NAME}
    if args.rrd is not None:
        paths.update({"--rrd": args.rrd, "the partial recording": partial_path(args.rrd)})
    check_outputs({"the scene file": args.scene}, paths)
    return paths


def _run_sample(scene, args, out: Path) -> int:
    from ...core.paths import partial_path
    from ...output.csv import CsvSink
    from ...output.rerun.recording import write_recording
    from ...run.metrics import METRICS
    from ...run.rows import trajectory_columns
    from ...run.simulation import SimulationError, simulate
    from .replay import sample_scene, write_sample_scene

    paths = list(_sample_paths(args, out).values())
    path, csv_path, partial, summary = paths[:4]
    sample_scene(scene, args.sample)  # refused samples and k out of range: before anything is written
    out.mkdir(parents=True, exist_ok=True)
    s = write_sample_scene(scene, args.sample, path)
    status = {"scene_file": str(path), "sample": args.sample}
    error = None
    with open(partial, "w", newline="") as fh:  # the run's rows: under the partial name until it ends
        sink = CsvSink(fh, trajectory_columns(s))
        try:
            tr = simulate(s, sink=sink, keep=args.rrd is not None)
            status.update(status="ok", summary=tr.meta["summary"])
        except SimulationError as e:
            tr = e.trajectory
            status.update(status="failed", reason=e.reason, stopped_at=e.t, summary=tr.meta.get("summary", {}),
                          rows_file=partial.name)
            error = f"sample {args.sample}: {e}; {tr.meta.get('n_rows', len(tr.t))} rows kept in {partial}"
    if error is None:
        os.replace(partial, csv_path)
        status["rows_file"] = csv_path.name
    status["metrics"] = {k: v for k, v in status["summary"].items() if k in METRICS}
    summary.write_text(json.dumps(status, indent=2) + "\n")
    if args.rrd is not None:
        write_recording(tr, s, args.rrd if error is None else partial_path(args.rrd))
    print(f"sample {args.sample}: {status['status']}; scene {path}")
    for k, v in status["metrics"].items():
        print(f"  {k} = {v:.10g}")
    return 0 if error is None else _error(error, EXIT_FAILED)


def _where(args) -> None:
    """One place the samples run: --workers, --scheduler and --serial exclude each other."""
    given = [o for o, v in (("--workers", args.workers), ("--scheduler", args.scheduler), ("--serial", args.serial))
             if v not in (None, False)]
    if len(given) > 1:
        raise ValueError(f"{' and '.join(given)}: choose one (--workers: a local cluster; --scheduler: a running "
                         f"one, whose workers run the study; --serial: this process)")
    if args.sample is not None and given:
        raise ValueError(f"--sample runs one sample in this process: drop {given[0]}")
    if args.sample is not None and (args.resume or args.chunk is not None):
        raise ValueError(f"{'--resume' if args.resume else '--chunk'} applies to a study, not to --sample")
    if args.sample is None and args.rrd is not None:
        raise ValueError("--rrd applies to --sample K (a study writes montecarlo.rrd in --out)")
    if not (args.connect_timeout > 0 and args.connect_timeout < float("inf")):
        raise ValueError(f"--connect-timeout must be a positive number of seconds, got {args.connect_timeout:g}")


def main(argv=None) -> int:
    """``stationbed montecarlo ...`` (``argv`` without the command name); returns the exit status."""
    args = _parser().parse_args(["montecarlo", *(sys.argv[2:] if argv is None else argv)])
    from ...core import progress
    from ...core.paths import check_outputs, default_out
    from ...scene import SceneError, load_scene, parse_assignments
    from .engine import run_study, study_scene
    from .folder import StudyStop
    from .report import table_text
    from .stats import FAIL, NOT_SHOWN

    if args.quiet:
        progress.configure("quiet")
    try:
        for name in ("n", "workers", "chunk"):
            _positive(args, name)
        _where(args)
        scene = load_scene(args.scene)
        if args.set:
            scene = scene.replace(parse_assignments(args.set), source=f"{args.scene} with --set")
        scene = study_scene(scene, args.n)
        out = args.out or default_out(scene.name, suffix="_montecarlo")
        if args.sample is not None:  # its own folder: its summary.json is not the study's
            out = args.out or out / f"sample_{args.sample}"
            if (out / "study.json").exists():
                raise ValueError(f"--out {out} holds a Monte Carlo study (study.json): --sample {args.sample} would "
                                 f"replace its summary.json; choose another --out")
            return _run_sample(scene, args, out)
        check_outputs({"the scene file": args.scene}, {f"the study's {f}": out / f for f in STUDY_FILES if f != "chunks"})
        workers = None if (args.serial or args.scheduler) else (args.workers or os.cpu_count() or 1)
        invocation = {"scene_file": str(args.scene.resolve()), "n": scene.montecarlo.n, "set": list(args.set)}
        res = run_study(scene, out=out, workers=workers, scheduler=args.scheduler, chunk=args.chunk,
                        resume=args.resume, charts=not args.no_charts, connect_timeout_s=args.connect_timeout,
                        invocation=invocation)
        from ..report import study_report, write_reports

        write_reports(study_report(out), out)  # junit.xml, report.html (issue 37)
    except (SceneError, ValueError) as e:
        return _error(e, EXIT_BAD_INPUT)
    except StudyStop as e:
        return _error(e, EXIT_FAILED)
    except OSError as e:  # the study is on disk; only its reports could not be written
        return _error(f"cannot write the reports in {out}: {e.strerror or e}; the study's results are kept: "
                      f"stationbed report {out} writes them again", EXIT_FAILED)
    except KeyboardInterrupt:
        return _error("interrupted; the finished chunks are kept (run again with --resume)", EXIT_FAILED)
    print(table_text(res.summary))
    print(f"wrote {out}/samples.parquet, summary.json, charts, montecarlo.rrd, junit.xml and report.html")
    failed = [r["metric"] for r in res.summary["requirements"] if r["verdict"] == FAIL]
    unshown = [r["metric"] for r in res.summary["requirements"] if r["verdict"] == NOT_SHOWN]
    if (failed or unshown) and not args.exit_zero:
        what = "; ".join(x for x in (f"failed by a sample: {', '.join(failed)}" if failed else "",
                                     f"not shown, no sample failed (too few samples): {', '.join(unshown)}"
                                     if unshown else "") if x)
        return _error(f"requirement(s) not shown to hold: {what} (verdicts above and in {out}/summary.json); "
                      f"--exit-zero exits 0 anyway", EXIT_FAILED)
    return 0
