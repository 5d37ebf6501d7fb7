"""Monte Carlo batch benchmark (issue 5 part 4): 1000 one-orbit samples in <= 60 s, and peak memory.

    python benchmarks/bench_batch.py [--n N] [--repeats R] [--threads 1,2] [--check K]
                                     [--memory | --no-memory] [--json PATH] [--smoke]

Batch: ``--n`` samples (default 1000) of one orbit (T = 2 pi / n) of
``scenarios/iss_lvlh_gravity_gradient.toml``, open loop, momentum form, initial attitude dispersed
1 deg (1-sigma per axis) about LVLH and rate 1e-5 rad/s (1-sigma per axis), seed 1, outputs every
10 s (557 rows per sample). ``stationbed.run.batch.simulate_batch``: the compiled DOP853 step mapped
over the samples with casadi ``map`` ("serial" for 1 thread, "thread" otherwise), per-sample step
control in numpy. Each thread count is timed ``--repeats`` times, interleaved, after a warm-up
(median wall of the whole call: per-sample set-up, integration and output evaluation).

Accuracy, on ``--check`` samples spread over the batch:

* agreement: max attitude angle between batch sample and ``stationbed.simulate`` of the same
  initial conditions and settings (DOP853 rtol 1e-9): should be round-off;
* error: against ``simulate`` at rtol 1e-13 (the truth for that sample): the integration error
  the batch actually has. A second batch row at rtol 1e-12 shows the accuracy the 60 s budget
  can buy.

Memory (``benchmarks/_mem.py``, one fresh subprocess per path, after a warm-up run): peak RSS
of the process (its RSS high-water mark ``VmHWM``; see ``_mem.py`` for why not
``getrusage``), the run's own increase over the loaded baseline
(RSS high-water mark reset before the run) and ``tracemalloc``'s peak, for one orbit open loop
(compiled DOP853), one orbit closed loop 10 Hz (``iss_lvlh_hold``, Python and fused paths) and
the batch. ``--memory`` prints only this table; ``--no-memory`` skips it (and the batch rows'
memory column).

Basilisk: compared only if ``import Basilisk`` works in this interpreter (never a dependency).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

import _mem  # noqa: E402
import _smoke  # noqa: E402
import stationbed  # noqa: E402
from stationbed.run.batch import disperse_initial, simulate_batch  # noqa: E402
from stationbed.core.rotation import rotation_angle  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
TARGET_S = 60.0
SMOKE_N = 4  # samples in smoke mode
ATT_SIGMA_RAD = math.radians(1.0)  # 1 deg 1-sigma per axis about LVLH
RATE_SIGMA_RAD_S = 1e-5  # rad/s 1-sigma per axis
TIGHT_RTOL = 1e-12
TRUTH_RTOL, TRUTH_ATOL = 1e-13, 1e-15


def _single(scene, q0, w0, T, **kw):
    s = scene.replace(**{"initial.q_BN": list(q0), "initial.omega_BN_B": list(w0)})
    return stationbed.simulate(s, duration=T, integrator="dop853", **kw)


def _accuracy(scene, batch, idx, T, rtol):
    """(max agreement with simulate at the same rtol, max error vs simulate at rtol 1e-13) [rad]."""
    agree, err = 0.0, 0.0
    for i in idx:
        same = _single(scene, batch.q0_in[i], batch.w0_in[i], T, rtol=rtol, atol=scene.simulation.atol)
        truth = _single(scene, batch.q0_in[i], batch.w0_in[i], T, rtol=TRUTH_RTOL, atol=TRUTH_ATOL)
        agree = max(agree, float(np.max(rotation_angle(same.q_BN, batch.q_BN[i]))))
        err = max(err, float(np.max(rotation_angle(truth.q_BN, batch.q_BN[i]))))
    return agree, err


def _memory_table(n: int, threads: int, duration: float | None = None) -> list[dict]:
    rows = []
    for name, what in _mem.PATHS.items():
        r = _mem.measure(name, n=n, threads=threads, duration=duration)
        r["what"] = what.replace("N one-orbit", f"{n} one-orbit") + (f", threads={threads}" if name == "batch" else "")
        rows.append(r)
    return rows


def _print_memory(rows):
    print("\n### Peak memory per path (fresh process each, after a warm-up run)\n")
    print("| path | peak RSS of the process (MiB) | run's own increase (MiB) | tracemalloc peak (MiB) |")
    print("|---|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['what']} | {r['peak_rss_mib']:.0f} | {r['run_increase_mib']:.1f} | {r['tracemalloc_peak_mib']:.1f} |"
        )
    print(
        "\nPeak RSS: the process's RSS high-water mark, VmHWM (interpreter + numpy + casadi + compiled"
        " libraries + results; not getrusage's ru_maxrss, which on Linux inherits the parent's peak"
        " across fork + exec). Increase: the RSS high-water mark during the run (reset with"
        " /proc/self/clear_refs) minus the RSS before it. tracemalloc: Python objects and numpy arrays"
        " allocated during the run (not casadi's C++ work memory)."
    )


def _basilisk_note() -> str:
    try:
        import Basilisk  # noqa: F401
    except ImportError:
        return (
            "Basilisk (`bsk`) is not installed in this interpreter: no comparison"
            " (optional, never a dependency)."
        )
    return "Basilisk is importable, but no equivalent batch scene is written yet: no comparison."


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="samples (default 1000)")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per thread count (default 3)")
    ap.add_argument("--threads", default="1,2", help="thread counts to time (default 1,2)")
    ap.add_argument("--check", type=int, default=5, help="samples compared with simulate (default 5)")
    ap.add_argument("--seed", type=int, default=1)
    mem = ap.add_mutually_exclusive_group()
    mem.add_argument("--memory", action="store_true", help="print only the peak-memory table")
    mem.add_argument("--no-memory", action="store_true", help="skip the memory measurements")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers as JSON")
    args = _smoke.parse(ap, argv,
                        f"{SMOKE_N} samples of {_smoke.SMOKE_DURATION_S:g} s, one repeat, memory of each path once")
    duration = None
    if args.smoke:
        args.n, args.check, duration = SMOKE_N, 1, _smoke.SMOKE_DURATION_S
    thread_counts = [int(t) for t in args.threads.split(",")]
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    stamp = _dt.datetime.now().isoformat(timespec="seconds")

    if args.memory:
        rows = _memory_table(args.n, max(thread_counts), duration)
        _print_memory(rows)
        print(f"\n{_basilisk_note()}\nmachine: {machine}; {stamp}")
        _smoke.write_json(args.json, dict(memory=rows, machine=machine, when=stamp))
        return 0

    scene = stationbed.load_scene(SCENE)
    T = duration or 2 * math.pi / scene.orbit.mean_motion
    q0s, w0s = disperse_initial(
        scene, args.n, attitude_sigma_rad=ATT_SIGMA_RAD, rate_sigma_rad_s=RATE_SIGMA_RAD_S, seed=args.seed
    )
    idx = np.unique(np.linspace(0, args.n - 1, max(1, min(args.check, args.n))).astype(int))

    def run(threads, rtol=None):
        t0 = time.perf_counter()
        b = simulate_batch(scene, q0s, w0s, duration=T, threads=threads, rtol=rtol)
        b.q0_in, b.w0_in = q0s, w0s
        return b, time.perf_counter() - t0

    for th in thread_counts:  # warm-up: loads the compiled library, builds the maps
        simulate_batch(scene, q0s, w0s, duration=20.0, threads=th)
    walls = {th: [] for th in thread_counts}
    batches = {}
    for _ in range(args.repeats):
        for th in thread_counts:  # interleaved: machine noise hits every path alike
            b, w = run(th)
            walls[th].append(w)
            batches[th] = b
    best = min(thread_counts, key=lambda th: statistics.median(walls[th]))
    tight, tight_wall = run(best, TIGHT_RTOL)

    rows = []
    for th in thread_counts:
        b = batches[th]
        agree, err = _accuracy(scene, b, idx, T, scene.simulation.rtol)
        rows.append(
            dict(rtol=scene.simulation.rtol, threads=th, wall_s=statistics.median(walls[th]), walls_s=walls[th],
                 b=b, agree=agree, err=err)
        )
    agree, err = _accuracy(scene, tight, idx, T, TIGHT_RTOL)
    rows.append(dict(rtol=TIGHT_RTOL, threads=best, wall_s=tight_wall, walls_s=[tight_wall], b=tight, agree=agree, err=err))
    if not args.no_memory and not args.smoke:  # (smoke: the batch path is measured once, in the table below)
        for r in rows:
            m = _mem.measure("batch", n=args.n, threads=r["threads"], rtol=r["rtol"])
            r["peak_rss_mib"], r["run_increase_mib"] = m["peak_rss_mib"], m["run_increase_mib"]

    n = args.n
    print(f"### Batch: {n} one-orbit samples ({T:.0f} s) of {SCENE.name}, open loop, momentum form\n")
    print(
        f"Dispersion: attitude {math.degrees(ATT_SIGMA_RAD):g} deg and rate {RATE_SIGMA_RAD_S:g} rad/s 1-sigma per axis"
        f" about LVLH, seed {args.seed}; {tight.t.size} output rows per sample; casadi map of the compiled"
        f" DOP853 step, per-sample step control. Agreement / error over {idx.size} samples.\n"
    )
    print(
        "| samples | rtol | threads | wall (s, median) | per sample (ms) | DOP853 steps per sample (mean) |"
        " lockstep calls | peak RSS (MiB) | run's increase (MiB) | agreement with simulate (rad) |"
        " error vs rtol 1e-13 (rad) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        b = r["b"]
        mem_cols = (
            f"{r['peak_rss_mib']:.0f} | {r['run_increase_mib']:.0f}" if "peak_rss_mib" in r else "- | -"
        )
        print(
            f"| {n} | {r['rtol']:.0e} | {r['threads']} | {r['wall_s']:.3f} | {1e3 * r['wall_s'] / n:.3f} |"
            f" {np.mean(b.meta['n_steps']):.1f} | {b.meta['iterations']} | {mem_cols} | {r['agree']:.1e} | {r['err']:.1e} |"
        )
    worst = max(statistics.median(walls[th]) for th in thread_counts)
    ok = worst <= TARGET_S and all(np.all(r["b"].status == 0) for r in rows)
    print(
        f"\ntarget: {n} one-orbit samples <= {TARGET_S:g} s: slowest median {worst:.2f} s"
        f" -> {_smoke.verdict(ok, args.smoke)}"
    )
    print(f"all runs (s): " + "; ".join(f"{th} thread(s): " + ", ".join(f"{w:.3f}" for w in walls[th]) for th in thread_counts))
    mem_rows = None
    if not args.no_memory:
        mem_rows = _memory_table(n, best, duration)
        _print_memory(mem_rows)
    print(f"\n{_basilisk_note()}\nmachine: {machine}; {stamp}")
    batch = [{k: v for k, v in r.items() if k != "b"} | dict(iterations=r["b"].meta["iterations"]) for r in rows]
    _smoke.write_json(args.json, dict(machine=machine, when=stamp, samples=n, orbit_s=T, target_s=TARGET_S,
                                      passed=bool(ok), batch=batch, memory=mem_rows))
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    raise SystemExit(main())
