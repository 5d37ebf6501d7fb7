"""The full flight loop's Monte Carlo on local Dask workers, and where a sample's time goes (issue 33).

    python benchmarks/bench_full_loop_montecarlo.py [--samples N] [--workers K] [--breakdown M] [--json PATH] [--smoke]

Scene: ``scenarios/iss_full_flight_loop_montecarlo.toml`` (one orbit per sample: CMGs, 16 assist
thrusters, ``momentum_manager`` on the MEKF's estimate, two gyros and two star trackers, every
dispersion of the scenario). Target of the issue: 1000 samples <= 90 s wall on 2 workers
(``stationbed montecarlo scenarios/iss_full_flight_loop_montecarlo.toml --n 1000 --workers 2``).

1. The study of ``--samples`` samples (default 1000) as a user runs it
   (``stationbed.montecarlo(scene, n, workers=K)``: the driver's warm-up, its own local cluster of
   forked workers, the samples, the close; no output folder, so no charts): the whole call's wall,
   the workers' CPU (``RUSAGE_CHILDREN``: the cluster's processes end with the call) and the
   driver's. Below 1000 samples the 1000-sample wall is extrapolated as ``fixed + per sample x
   1000`` with ``fixed`` the wall of a 2-sample study run first (said so); beside it the same from
   the CPU (``fixed + workers' CPU per sample x 1000 / K``: what an otherwise idle machine takes).
2. ``--breakdown M`` (default 20; 0: none): M samples run serially in this process, as a worker
   runs them (after the warm-up, the garbage collector's objects frozen as the forked workers'
   are), their CPU split by wrapping the pieces: the compiled calls (the fused loop, its rows,
   the filter's report), drawing the scene, the run's set-up, the sensors' noise, the rows and
   metrics, the rest.

The load average is printed: on a loaded machine only the CPU times mean much.
"""

from __future__ import annotations

import argparse
import functools
import gc
import os
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

from stationbed import load_scene, montecarlo  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_full_flight_loop_montecarlo.toml"
TARGET_S = 90.0  # issue 33: 1000 one-orbit samples of the full flight loop on 2 workers
TARGET_N = 1000
#: smoke mode: samples, workers and breakdown samples
SMOKE_N, SMOKE_WORKERS, SMOKE_BREAKDOWN = 2, 1, 2
#: the study whose wall stands for the fixed costs (warm-up, cluster start and close)
FIXED_N = 2


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _study(scene, n: int, workers: int) -> dict:
    cpu0, own0 = _children_cpu(), time.process_time()
    t0 = time.perf_counter()
    res = montecarlo(scene, n=n, workers=workers)
    wall = time.perf_counter() - t0
    return {"n": n, "wall_s": wall, "worker_cpu_s": _children_cpu() - cpu0, "driver_cpu_s": time.process_time() - own0,
            "failed": int((res.df["status"] != "ok").sum()), "executors": res.summary.get("executors", {})}


def breakdown(scene, m: int) -> dict:
    """CPU per sample [ms] of ``m`` samples run serially, by piece (module docstring, item 2)."""
    from stationbed.core import compile as compiled
    from stationbed.loop.flight import TickNoise
    from stationbed.run import lockstep
    from stationbed.run.composition import RunState
    from stationbed.studies.montecarlo import samples
    from stationbed.studies.montecarlo.engine import _warm, envelope_times, study_scene
    from stationbed.studies.montecarlo.dispersions import nominal_rate

    scene = study_scene(scene, m + 1)
    scene = scene.replace(nominal_rate(scene))
    n_env = envelope_times(scene)
    _warm(scene)
    samples.run_chunk(scene, 0, 1, n_env)  # every build loaded
    acc: dict[str, float] = {}
    clock = time.process_time
    undo = []

    def wrap(owner, name, label):
        f = getattr(owner, name)

        @functools.wraps(f)
        def timed(*a, **k):
            t = clock()
            try:
                return f(*a, **k)
            finally:
                acc[label] = acc.get(label, 0.0) + clock() - t

        setattr(owner, name, timed)
        undo.append((owner, name, f))

    def call(self):
        t = clock()
        self._trigger()
        acc["compiled"] = acc.get("compiled", 0.0) + clock() - t

    undo.append((compiled.FastCall, "__call__", compiled.FastCall.__call__))
    compiled.FastCall.__call__ = call
    wrap(samples, "_drawn", "draw")
    wrap(lockstep, "_Sample", "set-up")
    wrap(TickNoise, "rows_into", "noise")
    wrap(TickNoise, "rows", "noise")
    wrap(RunState, "rows_many", "rows")
    wrap(RunState, "end", "rows")
    wrap(lockstep, "_done", "rows")
    gc.collect()
    gc.freeze()  # as the forked workers (studies/montecarlo/cluster.py)
    try:
        t0 = clock()
        samples.run_chunk(scene, 1, m + 1, n_env)
        total = clock() - t0
    finally:
        gc.unfreeze()
        for owner, name, f in reversed(undo):
            setattr(owner, name, f)
    # (compiled calls inside the set-up, the draw or the rows are theirs: none of note but the noise's none)
    out = {k: 1e3 * v / m for k, v in acc.items()}
    out["total"] = 1e3 * total / m
    out["rest"] = out["total"] - sum(v for k, v in out.items() if k != "total")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=TARGET_N)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--breakdown", type=int, default=20, help="samples of the serial breakdown (0: none)")
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv, f"{SMOKE_N} samples of {_smoke.SMOKE_DURATION_S:g} s, {SMOKE_WORKERS} worker")
    scene = load_scene(SCENE)
    if args.smoke:
        args.samples, args.workers, args.breakdown = SMOKE_N, SMOKE_WORKERS, SMOKE_BREAKDOWN
        scene = scene.replace({"simulation.duration": _smoke.SMOKE_DURATION_S,
                               "montecarlo.settle_s": _smoke.SMOKE_DURATION_S / 2})
    load0 = _smoke.load_now()
    rows: dict = {"samples": args.samples, "workers": args.workers}
    measured = args.samples == TARGET_N
    scaled = not measured and args.samples <= FIXED_N  # (smoke) no fixed study: the wall scaled, an upper estimate
    if not (measured or scaled):
        rows["fixed"] = _study(scene, FIXED_N, args.workers)
    st = rows["study"] = _study(scene, args.samples, args.workers)
    if measured:
        total = st["wall_s"]
    elif scaled:
        total = st["wall_s"] * TARGET_N / args.samples
    else:
        fixed = rows["fixed"]["wall_s"]
        total = fixed + (st["wall_s"] - fixed) / (args.samples - FIXED_N) * TARGET_N
    if args.breakdown:
        rows["breakdown_ms"] = breakdown(scene, args.breakdown)
    load = _smoke.mean_load(load0)
    # what the 2 cores would take alone: the fixed wall plus the workers' CPU spread over them (a
    # loaded machine stretches the wall, much less the CPU)
    fixed_s = rows["fixed"]["wall_s"] if "fixed" in rows else 0.0
    cpu_estimate = fixed_s + st["worker_cpu_s"] / args.samples * TARGET_N / max(1, args.workers)
    rows.update(wall_1000_s=total, wall_1000_measured=measured, load_average=load, wall_1000_from_cpu_s=cpu_estimate)
    print(f"# the full flight loop's study, {args.samples} one-orbit samples on {args.workers} workers (load average "
          f"{load:.1f} on {os.cpu_count()} cores; the whole call: warm-up, cluster start and close included)")
    print(f"wall {st['wall_s']:.1f} s, workers' CPU {1e3 * st['worker_cpu_s'] / args.samples:.0f} ms per sample, the "
          f"driver's {st['driver_cpu_s']:.1f} s; {st['failed']} failed; executors {st['executors']}")
    if args.breakdown:
        b = rows["breakdown_ms"]
        print(f"a sample's CPU, {args.breakdown} samples serially: " + ", ".join(
            f"{k} {v:.1f} ms" + ("" if k == "total" else f" ({100 * v / b['total']:.0f} %)") for k, v in b.items()))
    print(f"{TARGET_N} samples from the CPU: {cpu_estimate:.1f} s (the fixed wall + the workers' CPU per sample x "
          f"{TARGET_N} / {args.workers}: what an otherwise idle machine would take)")
    ok = total <= TARGET_S
    how = ("measured" if measured else "scaled from the whole wall" if scaled else
           f"extrapolated: the {FIXED_N}-sample study's {rows['fixed']['wall_s']:.1f} s + per sample")
    print(f"{TARGET_N} samples: {total:.1f} s ({how}; target <= {TARGET_S:g} s): {_smoke.verdict(ok, args.smoke)}")
    _smoke.write_json(args.json, rows, indent=1, default=float, newline=True)
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
