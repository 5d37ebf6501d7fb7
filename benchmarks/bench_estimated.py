"""The closed loop flown on sensors and the MEKF vs on the truth, side by side (issue 20).

    python benchmarks/bench_estimated.py [--repeats N] [--environment-rate N] [--profile] [--json PATH] [--smoke]

One orbit of ``scenarios/iss_lvlh_hold_estimated.toml`` (two 10 Hz gyros, two 1 Hz star-tracker
heads, the MEKF; the pd law on the estimate) against the same scene with ``sensor = []`` and no
estimator (the pd law on the truth), interleaved in one process, median of ``--repeats`` runs
each after a warm-up run that compiles or loads the cached builds:

* ``fused``: the fused loop (``simulate(..., fused=True)``), target: estimated <= 1.5x truth-fed
  (judged on the wall medians; the process CPU times are printed beside them, less disturbed by
  other processes on a loaded machine, with the load average);
* ``per_tick`` (info): the per-tick loop (the law in Python, one compiled flight tick per tick).

``--environment-rate N``: both sides with ``[simulation] environment_rate = N`` (aero and solar
pressure once per N ticks, held: run/env_block.py, the composed loop's env block; the same accuracy on both
sides, as the ratio asks). The default is both scenes' default, ``auto`` (the bound's choice,
run/rate_auto.py: 20 ticks on both); then the every-stage pair (``environment_rate = 0`` on both)
is timed beside it too (``fused_every``, info). ``--profile``: after the rounds, each fused run once more under ``cProfile``, its time split into
the compiled calls (``FastCall``), the sensor noise draws (``SuiteNoise.draw``) and the rest
(Python: rows, reports, set-up); the profiler inflates the Python share, not the compiled one.
"""

from __future__ import annotations

import argparse
import cProfile
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

import stationbed  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml"
TARGET_RATIO = 1.5  # issue 20: the estimated fused loop <= 1.5x the fused loop without sensors


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--environment-rate", type=lambda v: v if v == "auto" else int(v), default="auto",
                    help="both sides' [simulation] environment_rate (default auto, the scenes' default)")
    ap.add_argument("--profile", action="store_true", help="split each fused run's time (compiled, noise, rest)")
    args = _smoke.parse(ap, argv)
    est = stationbed.load_scene(SCENE)
    est = est.replace({"simulation.environment_rate": args.environment_rate})
    truth = est.replace({"sensor": [], "estimator": None})
    every = args.environment_rate == "auto"  # the every-stage pair beside the defaults
    est0, truth0 = (s.replace({"simulation.environment_rate": 0}) for s in (est, truth))
    T = _smoke.orbit_s(est, args.smoke)
    runs = {
        "fused_truth": lambda: stationbed.simulate(truth, duration=T, fused=True),
        "fused_estimated": lambda: stationbed.simulate(est, duration=T, fused=True),
        "per_tick_truth": lambda: stationbed.simulate(truth, duration=T, fused=False),
        "per_tick_estimated": lambda: stationbed.simulate(est, duration=T, fused=False),
    }
    if every:
        runs["fused_every_truth"] = lambda: stationbed.simulate(truth0, duration=T, fused=True)
        runs["fused_every_estimated"] = lambda: stationbed.simulate(est0, duration=T, fused=True)
    timed = _smoke.interleaved(runs, args.repeats)
    first, med, cpu = timed.first, timed.wall, timed.cpu
    ratio = med["fused_estimated"] / med["fused_truth"]
    ratio_tick = med["per_tick_estimated"] / med["per_tick_truth"]
    ratio_cpu = cpu["fused_estimated"] / cpu["fused_truth"]
    s = first["fused_estimated"].meta["summary"]
    print(f"# one orbit ({T:.1f} s) of {est.name}, fused and per-tick, estimated vs truth-fed "
          f"(median of {args.repeats} interleaved; {_smoke.warmup_load(timed, cores=True)}; "
          f"environment_rate {args.environment_rate}: "
          f"{first['fused_truth'].meta['summary'].get('environment_rate_ticks')} / "
          f"{first['fused_estimated'].meta['summary'].get('environment_rate_ticks')} ticks run)")
    print("| path | truth-fed wall [s] | estimated wall [s] | ratio | truth-fed CPU [s] | estimated CPU [s] | CPU ratio |")
    print("|---|---|---|---|---|---|---|")
    print(f"| fused | {med['fused_truth']:.3f} | {med['fused_estimated']:.3f} | {ratio:.2f} "
          f"| {cpu['fused_truth']:.3f} | {cpu['fused_estimated']:.3f} | {ratio_cpu:.2f} |")
    print(f"| per tick | {med['per_tick_truth']:.3f} | {med['per_tick_estimated']:.3f} | {ratio_tick:.2f} "
          f"| {cpu['per_tick_truth']:.3f} | {cpu['per_tick_estimated']:.3f} "
          f"| {cpu['per_tick_estimated'] / cpu['per_tick_truth']:.2f} |")
    if every:
        print(f"| fused, every stage | {med['fused_every_truth']:.3f} | {med['fused_every_estimated']:.3f} "
              f"| {med['fused_every_estimated'] / med['fused_every_truth']:.2f} | {cpu['fused_every_truth']:.3f} "
              f"| {cpu['fused_every_estimated']:.3f} | {cpu['fused_every_estimated'] / cpu['fused_every_truth']:.2f} |")
    print(f"estimation: max error {s.get('max_est_err_deg', math.nan):.2e} deg, RMS {s.get('rms_est_err_deg', math.nan):.2e} deg, "
          f"mean NEES {s.get('mean_nees', math.nan):.2f}, inside 3 sigma {s.get('est_inside_3sigma', math.nan):.4f}, "
          f"star-tracker dropouts {s.get('st_dropout_s')} s")
    if args.profile:
        print("| fused run (profiled once) | total [s] | compiled calls [s] | noise draws [s] | rest (Python) [s] |")
        print("|---|---|---|---|---|")
        for name in ("fused_truth", "fused_estimated"):
            print("| " + name + " | " + " | ".join(f"{v:.3f}" for v in _split(runs[name])) + " |")
    ok = _smoke.ratio_target("fused estimated / truth-fed", ratio, TARGET_RATIO, args.smoke)
    _smoke.write_json(args.json, {"walls": timed.walls, "cpu": timed.cpus, "median": med, "median_cpu": cpu,
                                  "load_average": timed.load, "ratio_fused_cpu": ratio_cpu, "ratio_fused": ratio,
                                  "ratio_per_tick": ratio_tick, "summary": s}, indent=1, default=float)
    return _smoke.targets_exit(ok, args.smoke)


def _split(run) -> tuple[float, float, float, float]:
    """(total, compiled, noise, rest) [s] of one call of ``run`` under cProfile."""
    pr = cProfile.Profile()
    pr.enable()
    run()
    pr.disable()
    pr.create_stats()
    total = compiled = noise = 0.0
    for (path, _, fn), (_, _, tt, ct, _) in pr.stats.items():
        total += tt
        if fn == "__call__" and path.endswith("compile.py"):
            compiled += tt
        if fn == "draw" and path.endswith("suite.py"):
            noise += ct
    return total, compiled, noise, total - compiled - noise


if __name__ == "__main__":
    sys.exit(main())
