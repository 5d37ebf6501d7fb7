"""``stationbed montecarlo``: the command line of the Monte Carlo study.

    stationbed montecarlo SCENE [--n N] [--out DIR] [--workers K] [--scheduler ADDRESS]
                                [--chunk C] [--resume] [--serial] [--set KEY.PATH=VALUE]
    stationbed montecarlo SCENE --sample K [--out DIR] [--rrd FILE]

Without ``--scheduler`` it starts a local Dask cluster of K worker processes (default: the
machine's cores; ``--serial`` runs in this process); with it, it connects to a running
``dask scheduler`` and ships the chunks there. ``--sample K`` writes the exact scene of sample K
(``DIR/sample_K.toml``) and runs it alone (``DIR/trajectory.csv``, ``DIR/summary.json``).
Exit status: 0 when the study ran (whatever its verdicts: they are in summary.json and printed),
2 for bad input, 1 when interrupted (finished chunks stay on disk: ``--resume``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

__all__ = ["add_parser", "main"]


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``montecarlo`` command to an argparse ``sub`` (``add_subparsers()``) and return it."""
    p = sub.add_parser("montecarlo", help="closed-loop Monte Carlo of a scene's [montecarlo] table, on Dask")
    p.add_argument("scene", type=Path)
    p.add_argument("--n", type=int, default=None, help="samples (default: montecarlo.n)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: out/<scene>_montecarlo)")
    p.add_argument("--workers", type=int, default=None, help="local Dask worker processes (default: cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a running dask scheduler (tcp://host:8786)")
    p.add_argument("--chunk", type=int, default=None, help="samples per task (default: montecarlo.chunk or n/(4 workers))")
    p.add_argument("--resume", action="store_true", help="keep the finished chunks in --out and run the rest")
    p.add_argument("--serial", action="store_true", help="run in this process, without Dask (same numbers)")
    p.add_argument("--sample", type=int, default=None, metavar="K", help="write and run sample K alone")
    p.add_argument("--rrd", type=Path, default=None, help="with --sample: also write a rerun recording of it")
    p.add_argument("--no-charts", action="store_true", help="no PNG charts")
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


def _run_sample(scene, args, out: Path) -> int:
    from ...output.csv import CsvSink
    from ...output.rerun.recording import write_recording
    from ...run.metrics import METRICS
    from ...run.rows import trajectory_columns
    from ...run.simulation import SimulationError, simulate
    from .replay import write_sample_scene

    path = out / f"sample_{args.sample}.toml"
    s = write_sample_scene(scene, args.sample, path)
    status = {"scene_file": str(path), "sample": args.sample}
    with open(out / "trajectory.csv", "w", newline="") as fh:
        sink = CsvSink(fh, trajectory_columns(s))
        try:
            tr = simulate(s, sink=sink, keep=args.rrd is not None)
            status.update(status="ok", summary=tr.meta["summary"])
            code = 0
        except SimulationError as e:
            tr = e.trajectory
            status.update(status="failed", reason=e.reason, stopped_at=e.t, summary=tr.meta.get("summary", {}))
            code = 1
    status["metrics"] = {k: v for k, v in status["summary"].items() if k in METRICS}
    (out / "summary.json").write_text(json.dumps(status, indent=2) + "\n")
    if args.rrd is not None:
        write_recording(tr, s, args.rrd)
    print(f"sample {args.sample}: {status['status']}; scene {path}")
    for k, v in status["metrics"].items():
        print(f"  {k} = {v:.10g}")
    return code


def main(argv=None) -> int:
    """``stationbed montecarlo ...`` (``argv`` without the command name); returns the exit status."""
    args = _parser().parse_args(["montecarlo", *(sys.argv[2:] if argv is None else argv)])
    from ...core import progress
    from ...scene import SceneError, load_scene, parse_assignments
    from .engine import run_study, study_scene
    from .report import table_text

    if args.quiet:
        progress.configure("quiet")
    try:
        for name in ("n", "workers", "chunk"):
            _positive(args, name)
        scene = load_scene(args.scene)
        if args.set:
            scene = scene.replace(parse_assignments(args.set), source=f"{args.scene} with --set")
        scene = study_scene(scene, args.n)
        out = args.out or Path("out") / f"{scene.name}_montecarlo"
        out.mkdir(parents=True, exist_ok=True)
        if args.sample is not None:
            return _run_sample(scene, args, out)
        workers = None if (args.serial or args.scheduler) else (args.workers or os.cpu_count() or 1)
        res = run_study(scene, out=out, workers=workers, scheduler=args.scheduler, chunk=args.chunk,
                        resume=args.resume, charts=not args.no_charts)
    except (SceneError, ValueError) as e:
        progress.close_all()
        print(f"stationbed: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        progress.close_all()
        print("stationbed: error: interrupted; the finished chunks are kept (run again with --resume)", file=sys.stderr)
        return 1
    print(table_text(res.summary))
    print(f"wrote {out}/samples.parquet, summary.json, charts and montecarlo.rrd")
    return 0
