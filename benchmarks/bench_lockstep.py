"""Lockstep batch executor benchmark (issue 22): per-sample CPU of each executor, side by side.

    python benchmarks/bench_lockstep.py [--n N] [--duration S] [--json PATH] [--smoke]

Scene: the Monte Carlo benchmark's (``bench_montecarlo.bench_scene``: iss_lvlh_hold_montecarlo,
sensor noise off, 10 Hz), ``--n`` samples (default 50, one Monte Carlo chunk) of ``--duration``
seconds (default 300) each, in this one process, one after the other so that the shared machine's
load hits every row alike. Rows (CPU time of this process, ``time.process_time``, per sample):

1. ``floor``: the compiled tick alone, mapped over the n samples (one call per tick, no law, no
   rows): what any executor pays for the physics;
2. ``pd`` fused (per sample, the fused loop; the shipped law with a ``symbolic`` form);
3. ``example_hold`` batch, vectorised ``update_batch``;
4. ``example_hold`` batch with the default looping ``update_batch``;
5. ``example_hold`` per tick (``simulate`` per sample: what the Monte Carlo did before issue 22);
6. ``momentum_manager`` batch (vectorised; it has no symbolic form), and its per-sample set-up
   alone (the law's design), which every executor pays.

Each row is extrapolated to 1000 one-orbit samples on 2 workers (CPU per sample x orbit/duration
x 500), and said so: a measured ratio on a loaded machine, not a wall.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

import _smoke  # noqa: E402
from bench_montecarlo import bench_scene  # noqa: E402
from stationbed import simulate  # noqa: E402
from stationbed.run.controller import Controller  # noqa: E402
from stationbed.run.lockstep import _Lockstep, _Sample, run_lockstep  # noqa: E402
from stationbed.studies.montecarlo.replay import sample_scene  # noqa: E402

ORBIT_S = 5553.6  # s, the Monte Carlo scene's duration


def scenes(law: str, n: int, duration: float):
    params = {} if law == "momentum_manager" else None
    s = bench_scene("pd" if law == "pd" else "example_hold")
    ch = {"simulation.duration": duration, "montecarlo.settle_s": duration / 3, "montecarlo.n": max(n, 2)}
    if law != "pd":
        ch["controller.name"] = law
    if params is not None:
        ch["controller.params"] = params
    s = s.replace(ch)
    return [sample_scene(s, k) for k in range(n)]


def cpu(fn):
    c0 = time.process_time()
    out = fn()
    return time.process_time() - c0, out


def floor_row(sc, duration):
    """The mapped compiled tick alone, n samples, one call per tick."""
    smp = [_Sample(s, None, False, False) for s in sc]
    ls = _Lockstep(smp)
    for i, s in enumerate(smp):
        ls.P[i] = s.run.p
        ls.X[i] = s.loop.x
    ls.H[:] = 0.1
    k_ticks = int(round(duration / 0.1))

    def go():
        for k in range(k_ticks):
            ls.T[:] = k * 0.1
            ls.fc()
            ls.X[:] = ls.X1
    return cpu(go)[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--json", type=Path, default=None)
    _smoke.add_option(ap)
    args = ap.parse_args(argv)
    _smoke.announce(args.smoke, "4 samples of 2 s")
    if args.smoke:
        args.n, args.duration = 4, 2.0
    n, dur = args.n, args.duration
    from stationbed.controllers.example_hold import ExampleHold  # noqa: PLC0415
    import stationbed.run.closed_loop as cl  # noqa: PLC0415

    looping = type("LoopingHold", (ExampleHold,), {"update_batch": Controller.update_batch})
    rows = {}
    eh, pd, mm = scenes("example_hold", n, dur), scenes("pd", n, dur), scenes("momentum_manager", n, dur)
    for s in (eh[0], pd[0], mm[0]):  # compile / load once, outside the timings
        simulate(s.replace({"simulation.duration": 1.0}), keep=False)
    run_lockstep([s.replace({"simulation.duration": 0.2}) for s in eh])

    def batch(sc):
        res = run_lockstep(sc)
        assert all(k == "batch" and not isinstance(r, BaseException) for k, r in res), res[:1]

    def looping_batch():
        orig = cl.build_controller
        cl.build_controller = lambda spec, base_dir=None: looping(period=spec.period, **spec.params)
        try:
            batch(eh)
        finally:
            cl.build_controller = orig

    timings = [
        ("floor_compiled_tick", lambda: floor_row(eh, dur)),
        ("pd_fused", lambda: cpu(lambda: [simulate(s, keep=False) for s in pd])[0]),
        ("example_hold_batch_vectorised", lambda: cpu(lambda: batch(eh))[0]),
        ("example_hold_batch_default_loop", lambda: cpu(looping_batch)[0]),
        ("example_hold_per_tick", lambda: cpu(lambda: [simulate(s, keep=False) for s in eh])[0]),
        ("momentum_manager_batch", lambda: cpu(lambda: batch(mm))[0]),
        # its per-sample set-up alone (the law's design: linearisation, LQR, loop margins), which
        # a single run pays as well
        ("momentum_manager_setup_only", lambda: cpu(lambda: [_Sample(s, None, False, False) for s in mm])[0]),
    ]
    ticks = dur / 0.1
    for name, fn in timings:
        c = fn()
        per = c / n
        rows[name] = {"cpu_s": c, "per_sample_ms": 1e3 * per, "per_sample_tick_us": 1e6 * per / ticks,
                      "extrapolated_1000_orbit_2_workers_s": per * ORBIT_S / dur * 500}
        print(f"{name:34s} {1e6 * per / ticks:7.2f} us per sample-tick; 1000 one-orbit samples on 2 workers "
              f"~ {per * ORBIT_S / dur * 500:6.0f} s (extrapolated from {n} x {dur:g} s)", flush=True)
    f = rows["floor_compiled_tick"]["per_sample_tick_us"]
    for name in list(rows):
        rows[name]["x_floor"] = rows[name]["per_sample_tick_us"] / f
    r = rows["momentum_manager_batch"]["per_sample_tick_us"] / rows["pd_fused"]["per_sample_tick_us"]
    run_only = rows["momentum_manager_batch"]["per_sample_tick_us"] - rows["momentum_manager_setup_only"]["per_sample_tick_us"]
    rows["momentum_manager_batch"]["run_only_per_sample_tick_us"] = run_only
    print(f"momentum_manager batch without its set-up: {run_only:.2f} us per sample-tick "
          f"({run_only / rows['pd_fused']['per_sample_tick_us']:.2f} x pd fused)")
    print("ratios to the compiled tick: " + ", ".join(f"{k} {v['x_floor']:.2f}" for k, v in rows.items()))
    print(f"momentum_manager batch / pd fused = {r:.2f} (target <= 1.5)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
