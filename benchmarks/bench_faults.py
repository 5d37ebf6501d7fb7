"""A faulted run against its nominal run, both fused (issue 34: a faulted run costs <= 1.1x).

    python benchmarks/bench_faults.py [--repeats N] [--json PATH] [--smoke]

One orbit of ``scenarios/iss_lvlh_hold.toml`` (DGCMG cluster, pd law, aero and SRP, fused)
without faults and with two scheduled faults mid-orbit (``[[fault]]``: CMG unit 2 failed at
half an orbit, its rotor stopped and its momentum handed to the body; unit 3's gimbals rate
limited to 0.01 rad/s from a third of the orbit): a fault is a scheduled step, new numbers in
the same compiled loop, so the faulted run stays fused (asserted) and costs about the nominal.
Interleaved in one process, median of ``--repeats`` runs each after a warm-up run that
compiles or loads the cached builds; judged on CPU time (one thread each).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

import stationbed  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"
TARGET_RATIO = 1.1  # issue 34: a faulted run <= 1.1x its nominal run, fused


def faults(T: float, period: float) -> list[dict]:
    """The two faults, on the control tick grid."""
    tick = lambda t: round(t / period) * period  # noqa: E731
    return [{"t": tick(T / 2), "kind": "cmg_failed", "unit": 2},
            {"t": tick(T / 3), "kind": "gimbal_rate_limit", "unit": 3, "limit": 0.01}]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv)
    T = _smoke.SMOKE_DURATION_S if args.smoke else None
    nominal = stationbed.load_scene(SCENE)
    T = T or 2 * math.pi / nominal.orbit.mean_motion
    T = round(T / nominal.simulation.output_dt) * nominal.simulation.output_dt
    nominal = nominal.replace({"simulation.duration": T})
    faulted = nominal.replace({"fault": faults(T, nominal.controller.period)})
    runs = {"nominal": lambda: stationbed.simulate(nominal, fused=True),
            "faulted": lambda: stationbed.simulate(faulted, fused=True)}
    first, build_s, med, cpu, load, walls, cpus = _smoke.interleaved(runs, args.repeats)
    s = first["faulted"].meta["summary"]
    assert s["fused"] and "not_fused" not in s, f"the faulted run must fly fused: {s.get('not_fused')}"
    assert len(s["faults"]) == 2, s["faults"]
    ratio, ratio_wall = cpu["faulted"] / cpu["nominal"], med["faulted"] / med["nominal"]
    print(f"# one orbit ({T:.0f} s) of {nominal.name}, fused, two faults vs none "
          f"(median of {args.repeats}, interleaved; warm-up incl. compile/load {build_s:.1f} s; load average {load:.1f})")
    print("| fused loop | nominal [s] | two faults [s] | ratio |")
    print("|---|---|---|---|")
    print(f"| CPU time | {cpu['nominal']:.3f} | {cpu['faulted']:.3f} | {ratio:.2f} |")
    print(f"| wall time | {med['nominal']:.3f} | {med['faulted']:.3f} | {ratio_wall:.2f} |")
    print("faults applied: " + ", ".join(f"{f['kind']} unit {f['unit']} at {f['t']:.1f} s" for f in s["faults"]))
    ok = ratio <= TARGET_RATIO
    print(f"faulted / nominal, CPU time: {ratio:.2f} (target <= {TARGET_RATIO}): {_smoke.verdict(ok, args.smoke)}")
    if args.json:
        args.json.write_text(json.dumps({"walls": walls, "cpus": cpus, "median": med, "median_cpu": cpu,
                                         "ratio_cpu": ratio, "ratio_wall": ratio_wall, "summary": s},
                                        indent=1, default=float))
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
