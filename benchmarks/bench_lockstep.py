"""Lockstep batch executor benchmark (issue 22): per-sample CPU of each executor, side by side.

    python benchmarks/bench_lockstep.py [--n N] [--duration S] [--json PATH] [--smoke]

Scene: the Monte Carlo benchmark's (``bench_montecarlo.bench_scene``: iss_lvlh_hold_montecarlo,
sensor noise off, 10 Hz), ``--n`` samples (default 50, one Monte Carlo chunk) of ``--duration``
seconds (default 300) each, in this one process, one after the other so that the shared machine's
load hits every row alike. Rows (CPU time of this process, ``time.process_time``, per sample):

1. ``floor``: the compiled act part alone, mapped over the n samples (one call per tick, no law, no
   rows): what any executor pays for the physics;
2. ``pd`` fused (per sample, the fused loop; the shipped law with a ``symbolic`` form); each
   row times the samples' set-up and their run apart (CPU of this process);
3. ``example_hold`` batch, vectorised ``update_batch``;
4. ``example_hold`` batch with the default looping ``update_batch``;
5. ``example_hold`` per tick (``simulate`` per sample: what the Monte Carlo did before issue 22);
6. ``momentum_manager`` fused (its ``symbolic`` form with the law's state carried,
   stationbed/run/law_state.py) and batch (vectorised ``update_batch``, ``fused=False``);
7. ``example_hold`` on sensors and the MEKF (iss_lvlh_hold_estimated, each sample its own sensor
   seed), batch (the composed parts mapped, its sensing inside: stationbed/run/lockstep.py) and per tick;
8. each law's per-sample set-up alone (``prepare``, rows, loop, the law's design:
   ``momentum_manager`` designs an LQR and its loop margins per sample), which every executor pays
   once per sample, whatever its duration.

``--full-loop``: instead, the full flight loop's Monte Carlo samples
(``scenarios/iss_full_flight_loop_montecarlo.toml`` drawn as the study draws them: CMGs, 16 assist
thrusters, gyros, star trackers, the MEKF, ``momentum_manager``), three rows: ``fused`` (what the
study chooses), ``batch`` (the lockstep batch, ``fused=False``: the law's compiled form mapped
over the samples) and ``per_tick`` (each sample on the per-tick loop, ``fused=False``); e.g.
``--full-loop --n 16 --duration 5553.6 --repeats 3`` (one orbit, nothing extrapolated).

Each row is extrapolated to one-orbit samples as ``set-up + (row - set-up) x orbit/duration``
(the set-up does not grow with the duration), and to 1000 of them on 2 workers (x 500), and said
so: a measured ratio on a loaded machine, not a wall. ``--repeats R`` interleaves R rounds of
every row and reports the medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
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
from stationbed.run.simulation import SimulationError  # noqa: E402
from stationbed.run.controller import Controller  # noqa: E402
from stationbed.run.lockstep import _Lockstep, _Sample, run_lockstep  # noqa: E402
from stationbed.studies.montecarlo.replay import sample_scene  # noqa: E402

ORBIT_S = 5553.6  # s, the Monte Carlo scene's duration


def scenes(law: str, n: int, duration: float):
    params = {} if law == "momentum_manager" else None
    s = bench_scene("pd" if law == "pd" else "example_hold")  # (noise off: same scenes as bench_montecarlo)
    ch = {"simulation.duration": duration, "montecarlo.settle_s": duration / 3, "montecarlo.n": max(n, 2)}
    if law != "pd":
        ch["controller.name"] = law
    if params is not None:
        ch["controller.params"] = params
    s = s.replace(ch)
    return [sample_scene(s, k) for k in range(n)]


def estimated_scenes(n: int, duration: float):
    """iss_lvlh_hold_estimated (two gyros, two star-tracker heads, the MEKF) with ``example_hold``,
    sample k with sensor seed 7 + k (its own noise)."""
    from stationbed import load_scene  # noqa: PLC0415

    s = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml").replace(
        {"simulation.duration": duration, "simulation.output_dt": 1.0, "controller.name": "example_hold",
         "controller.params": {"reference": "lvlh"}})
    return [s.replace({"controller.sensor": {"seed": 7 + k}}) for k in range(n)]


def full_loop_scenes(n: int, duration: float):
    """Samples 0..n-1 of iss_full_flight_loop_montecarlo, drawn as the study draws them, of
    ``duration`` seconds."""
    from stationbed import load_scene  # noqa: PLC0415

    s = load_scene(ROOT / "scenarios" / "iss_full_flight_loop_montecarlo.toml").replace(
        {"simulation.duration": duration, "montecarlo.settle_s": duration / 3, "montecarlo.n": max(n, 2)})
    return [sample_scene(s, k) for k in range(n)]


def cpu(fn):
    c0 = time.process_time()
    out = fn()
    return time.process_time() - c0, out


def floor_row(sc, duration):
    """The mapped compiled act part alone (the composed tick after the law: chain, one RK4 step,
    the next tick's measurement and sensing), n samples, one call per tick."""
    smp = [_Sample(s, None, False, False) for s in sc]
    ls = _Lockstep(smp)
    C, P = ls.cm.carry, ls.cm.par
    k_ticks = int(round(duration / 0.1))
    for i, s in enumerate(smp):
        ls.PAR[i, P.slice("p")] = s.run.p
        ls.PAR[i, P.slice("h")], ls.PAR[i, P.slice("n_act")] = 0.1, k_ticks
        ls.C[i, C.slice("x")] = s.loop.x

    def go():
        for _ in range(k_ticks):
            ls.act()
            ls.C[:] = ls.C1
    return cpu(go)[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--repeats", type=int, default=1, help="interleaved rounds of every row (medians)")
    ap.add_argument("--full-loop", action="store_true",
                    help="the full flight loop's samples: fused, batch and per tick (module docstring)")
    args = _smoke.parse(ap, argv, "4 samples of 2 s")
    if args.smoke:
        args.n, args.duration = 4, 2.0
    n, dur = args.n, args.duration
    if args.full_loop:
        return full_loop(args)
    from stationbed.controllers.example_hold import ExampleHold  # noqa: PLC0415
    import stationbed.run.closed_loop as cl  # noqa: PLC0415

    looping = type("LoopingHold", (ExampleHold,), {"update_batch": Controller.update_batch})
    rows = {}
    eh, pd, mm = scenes("example_hold", n, dur), scenes("pd", n, dur), scenes("momentum_manager", n, dur)
    est = estimated_scenes(n, dur)
    for s in (eh[0], pd[0], mm[0], est[0]):  # compile / load once, outside the timings
        simulate(s.replace({"simulation.duration": 1.0}), keep=False)
    run_lockstep([s.replace({"simulation.duration": 0.2}) for s in eh])
    run_lockstep([s.replace({"simulation.duration": 0.2}) for s in est[:2]], fused=False)

    def timed_rows(sc, kind, fused=True, cls=None):
        """(set-up CPU, run CPU) of the samples ``sc``: each sample set up as every executor sets
        it up (prepare, rows, loop, the law's design), then run by ``kind``'s executor."""
        orig = cl.build_controller
        if cls is not None:
            cl.build_controller = lambda spec, base_dir=None: cls(period=spec.period, **spec.params)
        try:
            su, smp = cpu(lambda: [_Sample(s, None, False, fused) for s in sc])
        finally:
            cl.build_controller = orig
        if kind == "batch":  # (the default looping update_batch: executor() sends it per tick; timed in the batch here)
            assert all(s.kind == ("batch" if cls is None else "per-tick") for s in smp), [s.kind for s in smp]
            run, res = cpu(lambda: _Lockstep(smp).run(SimulationError))
            assert not any(isinstance(r, BaseException) for r in res), res[:1]
        else:
            assert kind == "per-tick" or all(s.kind == kind for s in smp), [s.kind for s in smp]
            run, _ = cpu(lambda: [s.loop.run() for s in smp])
        return su, run

    timings = [
        ("floor_compiled_tick", lambda: (0.0, floor_row(eh, dur))),
        ("pd_fused", lambda: timed_rows(pd, "fused")),
        ("example_hold_batch_vectorised", lambda: timed_rows(eh, "batch")),
        ("example_hold_batch_default_loop", lambda: timed_rows(eh, "batch", cls=looping)),
        ("example_hold_per_tick", lambda: timed_rows(eh, "per-tick", fused=False)),
        ("momentum_manager_fused", lambda: timed_rows(mm, "fused")),
        ("momentum_manager_batch", lambda: timed_rows(mm, "batch", fused=False)),
        ("estimated_example_hold_batch", lambda: timed_rows(est, "batch")),
        ("estimated_example_hold_per_tick", lambda: timed_rows(est, "per-tick", fused=False)),
    ]
    samples = {name: [] for name, _ in timings}
    for _ in range(args.repeats):  # interleaved rounds: the machine's load hits every row alike
        for name, fn in timings:
            samples[name].append(fn())
    ticks = dur / 0.1
    for name, _ in timings:
        su = statistics.median(s for s, _ in samples[name]) / n
        run = statistics.median(r for _, r in samples[name]) / n
        r = rows[name] = {"setup_per_sample_ms": 1e3 * su, "run_per_sample_tick_us": 1e6 * run / ticks,
                          "rounds_setup_run_s": samples[name]}
        r["one_orbit_sample_s"] = su + run * ORBIT_S / dur
        r["extrapolated_1000_orbit_2_workers_s"] = 500 * r["one_orbit_sample_s"]
        print(f"{name:34s} run {r['run_per_sample_tick_us']:6.2f} us per sample-tick, set-up {1e3 * su:6.1f} ms "
              f"per sample; one-orbit sample ~ {r['one_orbit_sample_s']:.3f} s CPU; 1000 on 2 workers ~ "
              f"{r['extrapolated_1000_orbit_2_workers_s']:5.0f} s (extrapolated from {n} x {dur:g} s)", flush=True)
    f = rows["floor_compiled_tick"]["run_per_sample_tick_us"]
    for name in list(rows):
        rows[name]["x_floor"] = rows[name]["run_per_sample_tick_us"] / f
    print("run alone / the compiled tick: " + ", ".join(f"{k} {v['x_floor']:.2f}" for k, v in rows.items()))
    pd1 = rows["pd_fused"]["one_orbit_sample_s"]
    for name in ("momentum_manager_fused", "momentum_manager_batch"):
        r = rows[name]["one_orbit_sample_s"] / pd1
        rows[name]["x_pd_fused_one_orbit"] = r
        rr = rows[name]["run_per_sample_tick_us"] / rows["pd_fused"]["run_per_sample_tick_us"]
        rows[name]["x_pd_fused_run"] = rr
        print(f"{name} / pd fused: per one-orbit sample (set-up included) {r:.2f} (target <= 1.5); run alone {rr:.2f}")
    for name, base in (("example_hold_batch_default_loop", "example_hold_per_tick"),
                       ("example_hold_batch_vectorised", "example_hold_per_tick"),
                       ("estimated_example_hold_batch", "estimated_example_hold_per_tick")):
        r = rows[name]["run_per_sample_tick_us"] / rows[base]["run_per_sample_tick_us"]
        rows[name]["x_per_tick"] = r
        print(f"{name} / {base}, run alone = {r:.2f}")
    rows["loadavg"] = os.getloadavg()
    print(f"load average {rows['loadavg']} on {os.cpu_count()} cores", flush=True)
    _smoke.write_json(args.json, rows, newline=True)
    return 0


def full_loop(args) -> int:
    """``--full-loop``: the full flight loop's samples fused, in the lockstep batch and per tick,
    ``--repeats`` interleaved rounds; set-up and run per sample, medians."""
    n, dur = args.n, args.duration
    sc = full_loop_scenes(n, dur)
    for fused in (True, False):  # compile / load once, outside the timings
        simulate(sc[0].replace({"simulation.duration": 1.0}), keep=False, fused=fused)
    run_lockstep([s.replace({"simulation.duration": 0.3}) for s in sc[:2]], fused=False)

    def row(kind):
        su, smp = cpu(lambda: [_Sample(s, None, False, kind == "fused") for s in sc])
        want = "per-tick" if kind == "per_tick" else kind
        assert want == "per-tick" or all(s.kind == want for s in smp), [s.kind for s in smp]
        if kind == "batch":
            run, res = cpu(lambda: _Lockstep(smp).run(SimulationError))
            assert not any(isinstance(r, BaseException) for r in res), res[:1]
        else:
            run, _ = cpu(lambda: [s.loop.run() for s in smp])
        return su, run

    kinds = ("fused", "batch", "per_tick")
    samples = {k: [] for k in kinds}
    load0 = _smoke.load_now()
    for _ in range(args.repeats):
        for k in kinds:
            samples[k].append(row(k))
    load = _smoke.mean_load(load0)
    rows = {}
    print(f"# the full flight loop's Monte Carlo samples, {n} x {dur:g} s, medians of {args.repeats} interleaved "
          f"rounds, load average {load:.1f} on {os.cpu_count()} cores ({_smoke.machine()})")
    print("| executor | set-up, ms per sample | run, ms per sample | µs per sample-tick | one-orbit sample, s CPU |")
    print("|---|---|---|---|---|")
    for k in kinds:
        su = statistics.median(s for s, _ in samples[k]) / n
        run = statistics.median(r for _, r in samples[k]) / n
        orbit = su + run * ORBIT_S / dur
        rows[k] = {"setup_ms": 1e3 * su, "run_ms": 1e3 * run, "us_per_sample_tick": 1e6 * run / (dur / 0.1),
                   "one_orbit_sample_s": orbit, "rounds_setup_run_s": samples[k]}
        print(f"| {k} | {1e3 * su:.1f} | {1e3 * run:.1f} | {rows[k]['us_per_sample_tick']:.2f} | {orbit:.3f} |")
    rows["loadavg"] = load
    _smoke.write_json(args.json, rows, newline=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
