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
    nominal = stationbed.load_scene(SCENE)
    T = _smoke.orbit_s(nominal, args.smoke)
    T = round(T / nominal.simulation.output_dt) * nominal.simulation.output_dt
    nominal = nominal.replace({"simulation.duration": T})
    faulted = nominal.replace({"fault": faults(T, nominal.controller.period)})
    runs = {"nominal": lambda: stationbed.simulate(nominal, fused=True),
            "faulted": lambda: stationbed.simulate(faulted, fused=True)}
    timed = _smoke.interleaved(runs, args.repeats)
    s = timed.first["faulted"].meta["summary"]
    assert s["fused"] and "not_fused" not in s, f"the faulted run must fly fused: {s.get('not_fused')}"
    assert len(s["faults"]) == 2, s["faults"]
    print(f"# one orbit ({T:.0f} s) of {nominal.name}, fused, two faults vs none "
          f"(median of {args.repeats}, interleaved; {_smoke.warmup_load(timed)})")
    ratio, ratio_wall = _smoke.ratio_table(timed, "nominal", "faulted", "nominal", "two faults")
    print("faults applied: " + ", ".join(f"{f['kind']} unit {f['unit']} at {f['t']:.1f} s" for f in s["faults"]))
    ok = _smoke.ratio_target("faulted / nominal, CPU time", ratio, TARGET_RATIO, args.smoke)
    _smoke.write_json(args.json, {"walls": timed.walls, "cpus": timed.cpus, "median": timed.wall,
                                  "median_cpu": timed.cpu, "ratio_cpu": ratio, "ratio_wall": ratio_wall, "summary": s},
                      indent=1, default=float)
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
