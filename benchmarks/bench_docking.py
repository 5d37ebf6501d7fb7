"""The fused closed loop with a docking vs the same run without it (issue 35).

    python benchmarks/bench_docking.py [--repeats N] [--duration S] [--environment-rate N] [--smoke]

``scenarios/iss_progress_docking.toml`` (a Progress docks at 600 s, the law told 60 s later:
two scheduled steps, the fused loop's chunks cut there) against the same scene with
``event = []`` (the vehicle's plates still in the structure, off), fused, interleaved in one
process, median of ``--repeats`` runs each after a warm-up run that compiles or loads the cached
builds. Target: with the docking <= 1.1x without, judged on the CPU time of the runs (one thread
each; the wall time, printed too, counts the waits for a core on a shared machine).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

import stationbed  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_progress_docking.toml"
TARGET_RATIO = 1.1  # issue 35: a run with a docking <= 1.1x the same run without, fused


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--duration", type=float, default=None, help="simulated time [s] (default: the scene's, 3000 s)")
    ap.add_argument("--environment-rate", type=int, default=None,
                    help="simulation.environment_rate of both runs (default: the scene's 'auto', chosen per run: the "
                         "docking's transient makes it choose a finer rate than the undisturbed hold)")
    args = _smoke.parse(ap, argv, what=f"{_smoke.SMOKE_DURATION_S:g} s, the docking at 10 s, one repeat")
    dock = stationbed.load_scene(SCENE)
    if args.duration is not None:
        dock = dock.replace({"simulation.duration": args.duration})
    if args.environment_rate is not None:
        dock = dock.replace({"simulation.environment_rate": args.environment_rate})
    T = dock.simulation.duration
    if args.smoke:
        T = _smoke.SMOKE_DURATION_S
        dock = dock.replace({"simulation.duration": T, "simulation.output_dt": 1.0, "event[0].t": 10.0,
                             "event[0].update_after_s": 1.0})
    bare = dock.replace({"event": []})
    runs = {
        "fused_bare": lambda: stationbed.simulate(bare, fused=True),
        "fused_docking": lambda: stationbed.simulate(dock, fused=True),
    }
    timed = _smoke.interleaved(runs, args.repeats)
    s, bare_s = (timed.first[k].meta["summary"] for k in ("fused_docking", "fused_bare"))
    assert s["fused"] and bare_s["fused"], "both runs must take the fused loop"
    assert len(s["events"]) == 2, "the docking and the law's update must both be applied"
    print(f"# {T:g} s of {dock.name}, fused, a docking at {dock.event[0].t:g} s vs none "
          f"(median of {args.repeats}, interleaved; {_smoke.warmup_load(timed)}); "
          f"environment every {bare_s['environment_rate_ticks']} / {s['environment_rate_ticks']} ticks")
    ratio, _ = _smoke.ratio_table(timed, "fused_bare", "fused_docking", "no docking", "docking")
    ok = _smoke.ratio_target("fused with a docking / without, CPU time", ratio, TARGET_RATIO, args.smoke)
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
