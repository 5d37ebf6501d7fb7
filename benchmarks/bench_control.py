"""Closed-loop speed benchmark: one orbit of iss_lvlh_hold with the 10 Hz pd (issue 3, DESIGN §9).

    python benchmarks/bench_control.py [--scene PATH] [--repeats N] [--json PATH] [--smoke]

Paths, timed side by side in one process (interleaved, median of ``--repeats`` runs each, after a
warm-up run that compiles or loads the cached build):

* ``python``: the controller called from Python every tick (``pd``: its ``symbolic`` form as one
  compiled Function, stationbed/run/law_compiled.py; 0.260 -> 0.215 s/orbit against its former
  float ``_update``, issue 33), the fused per-tick compiled
  call (steering law + one RK4 step + measurement) in between (``simulate(..., fused=False)``);
* ``fused``: controller (its casadi form), steering and RK4 in one compiled loop per output
  interval (``simulate(..., fused=True)``), at the default accuracy: ``environment_rate =
  "auto"`` (issue 25: aero and SRP held over the largest block whose proven bound is inside
  1e-6 rad; its probe is paid by the warm-up and kept per scene, and timed alone below);
* ``fused_every_stage``: the same with ``environment_rate = 0`` (aero and SRP at every RK4
  stage);
* ``dop853`` (info, one run): the per-tick Python controller with the adaptive DOP853 driver
  called once per period (rtol 1e-9) — the accurate but slower path.

Accuracy: each path's largest attitude difference from a reference run with the same
zero-order-hold loop integrated by DOP853 at rtol 1e-12.

Targets (issue 3): <= 0.3 s per orbit with the controller in Python; <= 0.1 s fused.
For scale (issue text, not measured here): Basilisk 2.12 takes ~1.5 s for one orbit of a
comparable station with 4 CMGs and a 10 Hz controller on this machine.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

import stationbed  # noqa: E402
from stationbed.run import rate_auto  # noqa: E402
from stationbed.core.rotation import rotation_angle  # noqa: E402

DEFAULT_SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"
TARGET_PYTHON_S = 0.3
TARGET_FUSED_S = 0.1
TARGET_ENV_DIFF_RAD = 1e-6
#: repeats of the default's probe timed alone (run/rate_auto.py)
PROBE_REPEATS = 3


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=DEFAULT_SCENE)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-dop853", action="store_true", help="skip the DOP853 info row")
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv)

    scene = stationbed.load_scene(args.scene)
    T = _smoke.orbit_s(scene, args.smoke)
    every = scene.replace({"simulation.environment_rate": 0})
    runs = {
        "python": lambda: stationbed.simulate(scene, duration=T, fused=False),
        "fused": lambda: stationbed.simulate(scene, duration=T, fused=True),
        "fused_every_stage": lambda: stationbed.simulate(every, duration=T, fused=True),
    }
    # warm-up (compile / load cached builds), then interleaved rounds: all see the same machine
    # load; CPU time is what other work on a shared machine inflates least
    first, build_s, med, med_cpu, _, walls, cpus = _smoke.interleaved(runs, args.repeats)

    ref = stationbed.simulate(scene, duration=T, integrator="dop853", rtol=1e-12, atol=1e-14)
    rows = []
    for name in runs:
        tr = first[name]
        err = float(np.max(rotation_angle(tr.q_BN, ref.q_BN)))
        rows.append((name, med[name], tr.meta["n_rhs"], err, tr.meta["summary"]["fused"]))
    if not args.no_dop853:
        t0 = time.perf_counter()
        tr = stationbed.simulate(scene, duration=T, integrator="dop853", rtol=1e-9)
        wall = time.perf_counter() - t0
        err = float(np.max(rotation_angle(tr.q_BN, ref.q_BN)))
        rows.append(("dop853 (info, 1 run)", wall, tr.meta["n_rhs"], err, False))

    ticks = first["python"].meta["summary"]["ticks"]
    print(f"# closed loop, one orbit ({T:.1f} s, {ticks} ticks at 10 Hz) of {scene.name}")
    print(f"machine: {_smoke.machine()}; warm-up incl. compile/load: {build_s:.1f} s")
    print()
    print("| path | wall per orbit [s] | CPU per orbit [s] | per tick [us] | RHS evaluations | max attitude error [rad] |")
    print("|---|---|---|---|---|---|")
    for name, wall, n_rhs, err, _ in rows:
        cpu = f"{med_cpu[name]:.3f}" if name in med_cpu else "-"
        print(f"| {name} | {wall:.3f} | {cpu} | {wall / ticks * 1e6:.2f} | {n_rhs} | {err:.1e} |")
    print()
    ok_py = med["python"] <= TARGET_PYTHON_S
    ok_fu = med["fused"] <= TARGET_FUSED_S
    print(f"python controller: {med['python']:.3f} s/orbit (target <= {TARGET_PYTHON_S} s): {_smoke.verdict(ok_py, args.smoke)}")
    print(f"fused:             {med['fused']:.3f} s/orbit (target <= {TARGET_FUSED_S} s): {_smoke.verdict(ok_fu, args.smoke)}")
    fe = "fused_every_stage"
    summ = first["fused"].meta["summary"]
    env_diff = float(np.max(rotation_angle(first[fe].q_BN, first["fused"].q_BN)))
    probe = []
    for _ in range(1 if args.smoke else PROBE_REPEATS):  # the default's probe alone (paid once per scene and process)
        t0 = time.process_time()
        rate_auto._probe(rate_auto._probe_scene(scene))  # (the probe flies its own scene: 1 s tick, truth-fed)
        probe.append(time.process_time() - t0)
    probe_cpu = sorted(probe)[len(probe) // 2]
    print(f"default accuracy: environment every {summ['environment_rate_ticks']} ticks ({summ['environment_rate_asked']}; "
          f"bound {summ['environment_rate_bound_rad']} rad); {med[fe] / med['fused']:.2f}x faster than every stage; "
          f"attitude difference from it {env_diff:.2e} rad (target <= {TARGET_ENV_DIFF_RAD:g}): "
          f"{_smoke.verdict(env_diff <= TARGET_ENV_DIFF_RAD, args.smoke)}; load average {_smoke.load_now():.1f}")
    print(f"CPU per orbit (medians): " + ", ".join(f"{k} {v:.3f} s" for k, v in med_cpu.items())
          + f" (fused at the default, target <= {TARGET_FUSED_S} s: "
          + f"{_smoke.verdict(med_cpu['fused'] <= TARGET_FUSED_S, args.smoke)}); the default's probe alone "
          + f"{probe_cpu:.3f} s CPU (once per scene and process; with it, one 1-orbit run: "
          + f"{med_cpu['fused'] + probe_cpu:.3f} s)")
    print(f"fused / python speed-up: {med['python'] / med['fused']:.1f}x; all runs: "
          + ", ".join(f"{k} {[round(w, 3) for w in v]}" for k, v in walls.items()))
    _smoke.write_json(args.json, {"median_s": med, "median_cpu_s": med_cpu, "walls_s": walls, "cpus_s": cpus,
                                  "rows": rows, "ticks": ticks, "probe_cpu_s": probe_cpu,
                                  "environment_rate": summ["environment_rate_ticks"]})
    return 0


if __name__ == "__main__":
    sys.exit(main())
