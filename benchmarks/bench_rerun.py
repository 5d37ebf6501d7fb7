"""What a rerun recording costs a run (issue 4).

    python benchmarks/bench_rerun.py [--scene PATH] [--repeats N] [--cli-repeats N]

Medians of ``--repeats`` warm runs (compiled functions cached, rerun already imported) of the
scene, as ``stationbed run`` does them:

* ``simulate``            no sink (the integration alone);
* ``simulate + csv``      rows streamed to trajectory.csv (``stationbed run``);
* ``simulate + csv + rrd``  also streamed through an RrdSink, opened and closed inside the timing
  (``stationbed run --rrd``, minus the one-off ``import rerun``);

then the RrdSink cost split into: open (stream, blueprint, static geometry), ``write`` per 1000
rows (one big batch, incl. the blocking flush), the fixed cost of one batch (a 1-row write),
close (footer); ``import rerun`` in a fresh interpreter; and the wall time of the whole
``stationbed run`` process with and without ``--rrd`` (medians of ``--cli-repeats``).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT_SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
BIN = Path(sys.executable).parent


def _median_ms(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(ts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", type=Path, default=DEFAULT_SCENE)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--cli-repeats", type=int, default=5)
    args = ap.parse_args(argv)

    import numpy as np

    import stationbed
    from stationbed.trajectory import CsvSink

    scene = stationbed.load_scene(args.scene)
    traj = stationbed.simulate(scene)  # warm-up: compile / load the cached functions
    import rerun  # noqa: F401  (the one-off import is measured separately below)
    from stationbed.rerun_log import RrdSink, TeeSink

    tmp = Path(tempfile.mkdtemp(prefix="bench_rerun_"))
    rrd = tmp / "recording.rrd"
    R = args.repeats

    def run_plain():
        stationbed.simulate(scene)

    def run_csv():
        with open(tmp / "trajectory.csv", "w", newline="") as fh:
            stationbed.simulate(scene, sink=CsvSink(fh, traj.columns))

    def run_csv_rrd():
        with open(tmp / "trajectory.csv", "w", newline="") as fh:
            sink = TeeSink(CsvSink(fh, traj.columns), RrdSink(scene, rrd, traj.columns))
            try:
                stationbed.simulate(scene, sink=sink)
            finally:
                sink.close()

    t_plain = _median_ms(run_plain, R)
    t_csv = _median_ms(run_csv, R)
    t_rrd = _median_ms(run_csv_rrd, R)

    # the RrdSink's parts
    def parts():
        t0 = time.perf_counter()
        s = RrdSink(scene, rrd, traj.columns)
        t1 = time.perf_counter()
        s.write(traj.data)
        t2 = time.perf_counter()
        s.write(traj.data[:1])
        t3 = time.perf_counter()
        s.close()
        t4 = time.perf_counter()
        return t1 - t0, t2 - t1, t3 - t2, t4 - t3

    samples = np.array([parts() for _ in range(R)]) * 1e3
    t_open, t_write, t_one, t_close = np.median(samples, axis=0)
    n = len(traj)

    imp = []
    for _ in range(max(3, args.cli_repeats)):
        out = subprocess.run(
            [sys.executable, "-c", "import time; t = time.perf_counter(); import rerun; print(time.perf_counter() - t)"],
            capture_output=True, text=True, check=True,
        )
        imp.append(float(out.stdout) * 1e3)
    t_import = statistics.median(imp)

    def cli(*extra):
        ts = []
        for _ in range(args.cli_repeats):
            t0 = time.perf_counter()
            subprocess.run([str(BIN / "stationbed"), "run", str(args.scene), "--out", str(tmp / "cli"), *extra],
                           capture_output=True, check=True)
            ts.append(time.perf_counter() - t0)
        return 1e3 * statistics.median(ts)

    t_cli = cli()
    t_cli_rrd = cli("--rrd", str(tmp / "cli" / "recording.rrd"))

    print(f"scene {scene.name}: {n} output rows, {traj.meta['n_rhs']} RHS evaluations; medians of {R} warm runs")
    print()
    print("| path | wall [ms] | added by rrd |")
    print("|---|---:|---:|")
    print(f"| simulate (no sink) | {t_plain:.2f} | |")
    print(f"| simulate + csv (`stationbed run`) | {t_csv:.2f} | |")
    print(f"| simulate + csv + rrd, open..close (`--rrd`) | {t_rrd:.2f} | {t_rrd - t_csv:+.2f} ms = {100 * (t_rrd - t_csv) / t_csv:+.0f} % of csv run |")
    print()
    print("| RrdSink part | ms |")
    print("|---|---:|")
    print(f"| open: stream, blueprint, static geometry | {t_open:.2f} |")
    print(f"| write {n} rows in one batch (incl. flush) | {t_write:.2f} |")
    print(f"| = per 1000 rows | {1000 * t_write / n:.2f} |")
    print(f"| fixed cost of one batch (1-row write) | {t_one:.2f} |")
    print(f"| close (footer) | {t_close:.2f} |")
    print(f"| `import rerun` (fresh interpreter, once per process) | {t_import:.0f} |")
    print()
    print(f"| `stationbed run` process (median of {args.cli_repeats}) | ms |")
    print("|---|---:|")
    print(f"| without --rrd | {t_cli:.0f} |")
    print(f"| with --rrd | {t_cli_rrd:.0f} ({t_cli_rrd - t_cli:+.0f} ms = {100 * (t_cli_rrd - t_cli) / t_cli:+.0f} %) |")
    target = 0.10 * t_plain
    print()
    print(
        f"target <= 10 % of the run: {target:.2f} ms of the {t_plain:.2f} ms integration -> "
        f"{'PASS' if t_rrd - t_csv <= target else 'FAIL'} (rrd adds {t_rrd - t_csv:.2f} ms in-process, "
        f"{t_cli_rrd - t_cli:.0f} ms to the process, most of it `import rerun`)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
