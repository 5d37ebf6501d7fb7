"""Monte Carlo benchmark (issue 13): closed-loop samples of one orbit on a local Dask cluster.

    python benchmarks/bench_montecarlo.py [--n N] [--n-python N] [--n-eff N] [--workers K]
                                          [--samples N] [--rows pd,example_hold,...] [--environment-rate N]
                                          [--only-pd] [--json PATH] [--smoke]

``--samples N`` runs every study row (``pd``, ``example_hold``, ``momentum_manager``) with N samples,
measured, not extrapolated (``--samples 1000``: the issues' targets); ``--rows`` picks the rows
(default all: pd, example_hold, momentum_manager, efficiency, per_sample). ``--only-pd --n 1000``:
the 1000-sample ``pd`` row alone, quietly. ``--environment-rate N`` runs every row's samples with
``[simulation] environment_rate = N`` (0: every stage; default ``auto``, the scenario's: the
bound's choice for the nominal scene, 20 ticks, docs/design.md "Effects at their own rate").

Scene: ``scenarios/iss_lvlh_hold_montecarlo.toml`` (one orbit, 10 Hz, every dispersion of the
scenario) with the sensor noise off, so the ``pd`` law runs fused (controller, steering and
dynamics in one compiled loop; it now runs fused with the noise too, README "Monte Carlo"). Rows, in one run:

1. ``pd`` fused, ``--n`` samples (default 1000) on ``--workers`` (default 2) local worker
   processes: wall of the whole ``stationbed.montecarlo(..., workers=K)`` call, its cluster's
   start-up (workers forked after the driver's warm-up, README "Speed") and close included (target <= 45 s, issue 25; it was 60 s);
2. ``example_hold`` (a Python controller: since issue 22 its chunks run in lockstep, its vectorised
   ``update_batch`` called once per tick for all samples; ``benchmarks/bench_lockstep.py`` times
   every executor side by side), ``--n-python`` samples (default 200),
   the same way; its 1000-sample time is extrapolated linearly from the per-sample rate (and
   said so) unless ``--n-python 1000`` (target <= 150 s, issue 22);
2b. ``momentum_manager`` (it runs fused since issue 22: its symbolic form with the law's state
   carried), ``--n-python`` samples, the same way (target <= 1.5x ``pd`` fused per sample);
3. parallel efficiency 1 -> 2 workers: ``--n-eff`` samples (default 100) of ``pd`` on a cluster
   started beforehand (start-up excluded), ``T1 / (2 T2)`` (target >= 85 %);
4. per-sample cost: the 1-worker wall / n against the median of ``stationbed.simulate`` of the
   same samples' scenes, one by one in this process (target within 10 %);
5. peak memory (``VmHWM``, the kernel's resident-set high-water mark) of the driver and of each
   worker after row 1;
6. the workers' CPU time per sample (``time.process_time`` summed over the workers), which other
   work on a shared machine inflates much less than the wall, and the load average.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402
from stationbed import load_scene, montecarlo, simulate  # noqa: E402
from stationbed.studies.montecarlo.replay import sample_scene  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_lvlh_hold_montecarlo.toml"


def vm_hwm_mib() -> float:
    """The process's resident-set high-water mark [MiB] (Linux /proc)."""
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def children_peak_mib() -> float:
    """The largest resident-set high-water mark among this process's finished children [MiB]
    (the study's local workers, once its cluster closed; a forked worker counts the pages it
    shares with the driver)."""
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


#: smoke mode: samples of each row (pd, example_hold, efficiency) and workers
SMOKE_N, SMOKE_WORKERS = 2, 1


def bench_scene(controller: str = "pd", duration: float | None = None, environment_rate: int | str = "auto"):
    s = load_scene(SCENE)
    disperse = [d.model_dump(exclude_unset=True) for d in s.montecarlo.disperse if not d.key.startswith("controller.sensor")]
    changes = {"controller.sensor": {}, "montecarlo.disperse": disperse}
    changes["simulation.environment_rate"] = environment_rate
    if duration is not None:  # smoke: a few seconds per sample (the settling time inside them)
        changes.update({"simulation.duration": duration, "montecarlo.settle_s": 0.5 * duration})
    if controller != "pd":
        disperse = [d for d in disperse if not d["key"].startswith("controller.params")]
        params = {"reference": "lvlh"} if controller == "example_hold" else {}
        changes.update({"controller.name": controller, "controller.params": params,
                        "montecarlo.disperse": disperse})
    return s.replace(changes)


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--n-python", type=int, default=200)
    ap.add_argument("--n-eff", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--only-pd", action="store_true", help="row 1 and the driver's memory only (e.g. --n 10000)")
    ap.add_argument("--samples", type=int, default=None, help="N samples for every study row (pd, example_hold, "
                    "momentum_manager): measured, not extrapolated")
    ap.add_argument("--rows", default="pd,example_hold,momentum_manager,efficiency,per_sample",
                    help="comma-separated rows to run")
    ap.add_argument("--environment-rate", type=lambda v: v if v == "auto" else int(v), default="auto",
                    help="[simulation] environment_rate of every sample (ticks; 0 = every stage; default auto, "
                         "the scenario's)")
    args = _smoke.parse(ap, argv,
                        f"{SMOKE_N} samples of {_smoke.SMOKE_DURATION_S:g} s per row, {SMOKE_WORKERS} workers")
    duration = None
    if args.samples is not None:
        args.n = args.n_python = args.samples
    want = set(args.rows.split(","))
    if args.smoke:
        args.n = args.n_python = args.n_eff = SMOKE_N
        args.workers, duration = SMOKE_WORKERS, _smoke.SMOKE_DURATION_S
    from distributed import Client, LocalCluster

    rows = {"loadavg_start": os.getloadavg()}
    pd_scene = bench_scene("pd", duration, args.environment_rate)
    # 1. pd fused, whole call (cluster start-up included)
    def study_on_new_cluster():  # montecarlo(..., workers=K): its own cluster, started after its warm-up
        res = montecarlo(pd_scene, n=args.n, workers=args.workers)
        return res, children_peak_mib()

    if "pd" in want or args.only_pd:
        wall, (res, worker_mib) = timed(study_on_new_cluster)
        rows["pd_fused"] = {"n": args.n, "workers": args.workers, "wall_s": wall, "target_s": 45.0,
                            "environment_rate": args.environment_rate,
                            "failed": int((res.df["status"] != "ok").sum()), "worker_peak_mib": worker_mib,
                            "executors": res.summary.get("executors", {})}
        rows["memory_driver_peak_mib"] = vm_hwm_mib()
        print(f"pd fused (environment_rate {args.environment_rate}): {args.n} samples on {args.workers} workers: "
              f"{wall:.1f} s (target 45 s); load average {_smoke.load_now():.1f}; driver peak "
              f"{rows['memory_driver_peak_mib']:.0f} MiB, worker peak {worker_mib:.0f} MiB", flush=True)
    if args.only_pd:
        _smoke.write_json(args.json, rows, newline=True)
        return 0
    # 2. example_hold (Python, lockstep batch) and momentum_manager (fused, the law's state carried)
    for law, key, target in (("example_hold", "example_hold", 150.0), ("momentum_manager", "momentum_manager", None)):
        if key not in want:
            continue
        py_scene = bench_scene(law, duration, args.environment_rate)
        wall, res = timed(lambda: montecarlo(py_scene, n=args.n_python, workers=args.workers))
        per = wall / args.n_python
        rows[key] = {"n": args.n_python, "workers": args.workers, "wall_s": wall,
                     "extrapolated_1000_s": per * 1000 if args.n_python != 1000 else wall, "target_s": target,
                     "executors": res.summary.get("executors", {}),
                     "failed": int((res.df["status"] != "ok").sum())}
        if "pd_fused" in rows:
            rows[key]["x_pd_fused_per_sample"] = per / (rows["pd_fused"]["wall_s"] / rows["pd_fused"]["n"])
        print(f"{law} ({res.summary.get('executors', {})}): {args.n_python} samples: {wall:.1f} s; 1000 samples ~ "
              f"{per * 1000:.0f} s ({'measured' if args.n_python == 1000 else 'extrapolated'}"
              f"{'; target %g s' % target if target else ''})"
              + (f"; x{rows[key]['x_pd_fused_per_sample']:.2f} pd fused per sample" if "pd_fused" in rows else ""),
              flush=True)
    if not want & {"efficiency", "per_sample"}:
        rows["loadavg_end"] = os.getloadavg()
        _smoke.write_json(args.json, rows, newline=True)
        return 0
    # 3. + 5. efficiency and worker memory, on clusters started beforehand
    walls, cpus = {}, {}
    for k in (1, 2):
        with LocalCluster(n_workers=k, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, \
                Client(cl) as client:
            montecarlo(pd_scene, n=2 * k, client=client)  # workers load the compiled system
            cpu0 = sum(client.run(time.process_time).values())
            walls[k], _ = timed(lambda: montecarlo(pd_scene, n=args.n_eff, client=client))
            cpus[k] = sum(client.run(time.process_time).values()) - cpu0
            if k == 2:
                rows["memory_worker_peak_mib"] = max(client.run(vm_hwm_mib).values())
    eff = walls[1] / (2 * walls[2])
    rows["efficiency"] = {"n": args.n_eff, "wall_1_s": walls[1], "wall_2_s": walls[2], "efficiency": eff,
                          "cpu_1_s": cpus[1], "cpu_2_s": cpus[2], "target": 0.85}
    print(f"parallel efficiency 1 -> 2 workers ({args.n_eff} samples): {walls[1]:.1f} s / {walls[2]:.1f} s "
          f"= {100 * eff:.0f} % (target 85 %); worker CPU {cpus[1]:.1f} s / {cpus[2]:.1f} s "
          f"({1e3 * cpus[2] / args.n_eff:.0f} ms per sample)", flush=True)
    # 4. per-sample cost against simulate of the same samples
    singles = []
    for k in range(min(20, args.n_eff)):
        s = sample_scene(pd_scene.replace({"montecarlo.n": args.n_eff}), k)
        if k == 0:
            simulate(s, keep=False)
        singles.append(timed(lambda: simulate(s, keep=False))[0])
    per_sample = walls[1] / args.n_eff
    rows["per_sample"] = {"montecarlo_1_worker_s": per_sample, "simulate_median_s": statistics.median(singles),
                          "ratio": per_sample / statistics.median(singles), "target_ratio": 1.10}
    print(f"per sample: {per_sample * 1e3:.0f} ms in the study (1 worker) vs {statistics.median(singles) * 1e3:.0f} ms "
          f"for simulate alone: x{per_sample / statistics.median(singles):.3f} (target <= 1.10)", flush=True)
    print(f"peak memory: driver {rows['memory_driver_peak_mib']:.0f} MiB after {args.n} samples; "
          f"worker {rows['memory_worker_peak_mib']:.0f} MiB", flush=True)
    rows["loadavg_end"] = os.getloadavg()
    print(f"load average (1, 5, 15 min) at start {rows['loadavg_start']}, at end {rows['loadavg_end']} "
          f"on {os.cpu_count()} cores: other work on the machine inflates the walls", flush=True)
    _smoke.write_json(args.json, rows, newline=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
