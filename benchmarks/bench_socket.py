"""A law over a socket and runs paced to the wall clock (issue 36).

    python benchmarks/bench_socket.py [--duration S] [--repeats N] [--realtime-duration S]
                                      [--parts orbit,realtime1,realtime100] [--smoke] [--json PATH]

On the tests' scene (tests/test_socket_law.py: a small station in LVLH, no CMG) at 10 Hz:

* **socket law, one orbit** (``--duration``, default 5554 s: 55,540 round trips) flown through
  the shipped Python and C clients (clients/socket_law/), against the in-process ``pd`` called
  every tick, side by side (a warm-up, then ``--repeats`` rounds: medians): wall time of the run,
  and the round trip per tick as the law measures it (send the measurement frame, receive the
  command frame: median and 99.9th percentile). Target: the run <= 3 s with the C client.
  Checked: the socket runs are the in-process run, bit for bit.
* **--realtime 1** for ``--realtime-duration`` (default 600 s of simulated time, 10 minutes of
  wall time) with the in-process pd per tick (a deadline every 0.1 s): the lateness at the end
  (the drift; target < 1 ms), the worst lateness, the deadline misses.
* **--realtime 100 with the socket law** (the Python client) for ``--duration``: the factor
  achieved, the misses and the worst lateness (per tick: a deadline every 1 ms).

``--smoke``: 20 s runs, one repeat, a 20 s realtime run at x10 (CI: does it run; no target judged).
"""

from __future__ import annotations

import argparse
import math
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

PERIOD_S = 0.1  # s: 10 Hz, iss_lvlh_hold's rate
ORBIT_S = 5554.0  # s, 400 km
#: targets (issue 36)
ORBIT_RUN_S = 3.0  # s: a one-orbit run with the socket law
DRIFT_MS = 1.0  # ms: the lateness at the end of 10 minutes at --realtime 1
#: the benchmark's parts (--parts)
PARTS = ("orbit", "realtime1", "realtime100")


def _scene(controller: dict, duration: float):
    from test_socket_law import pd_scene

    d = pd_scene(controller).model_dump(exclude_unset=True)
    d["simulation"].update(duration=duration, step=PERIOD_S, output_dt=10.0)
    d["controller"]["period"] = PERIOD_S
    from stationbed.scene import scene_from_dict

    return scene_from_dict(d)


def _c_client(folder: Path):
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    exe = folder / "pd_client"
    subprocess.run([cc, "-O2", "-ffp-contract=off", "-o", str(exe), str(ROOT / "clients/socket_law/pd_client.c"), "-lm"],
                   check=True)
    return exe


def _orbit(duration: float, repeats: int, c_exe, smoke: bool, out: dict) -> bool:
    """The one-orbit runs, side by side: the in-process pd per tick and the socket law through
    each client (started once: each serves every run). True when the targets hold."""
    from stationbed import simulate
    from test_socket_law import PD_PARAMS, client_command, start, stop

    kinds = ["python", "c"] if c_exe is not None else ["python"]
    ref = simulate(_scene({"name": "pd", "params": PD_PARAMS}, duration), fused=False)
    rtt = {kind: [] for kind in kinds}
    same = {kind: True for kind in kinds}
    clients = {}

    def socket_run(kind):
        def run():
            tr = simulate(_scene({"port": f"127.0.0.1:{clients[kind][1]}", "params": PD_PARAMS}, duration))
            s = tr.meta["summary"]
            rtt[kind].append((s["socket_round_trip_us_p50"], s["socket_round_trip_us_p999"]))
            same[kind] &= np.array_equal(tr.data, ref.data)
        return run

    runs = {"in_process_pd_per_tick": lambda: simulate(_scene({"name": "pd", "params": PD_PARAMS}, duration), fused=False)}
    runs.update({f"socket_{kind}": socket_run(kind) for kind in kinds})
    try:
        for kind in kinds:
            clients[kind] = start(client_command(kind, c_exe))
        timed = _smoke.interleaved(runs, repeats)
    finally:
        for proc, _ in clients.values():
            stop(proc)
    out["load_average"] = timed.load
    out["in_process_pd_per_tick_s"] = timed.wall["in_process_pd_per_tick"]
    print(f"{duration:g} s at 10 Hz ({round(duration / PERIOD_S)} ticks), median of {repeats} rounds side by side, "
          f"load average {timed.load:.1f}; in-process pd per tick: {timed.wall['in_process_pd_per_tick']:.2f} s")
    ok = True
    for kind in kinds:
        wall, walls = timed.wall[f"socket_{kind}"], timed.walls[f"socket_{kind}"]
        p50, p999 = (float(np.median([r[i] for r in rtt[kind][1:]])) for i in (0, 1))  # (the warm-up left out)
        target = kind != "c" or wall <= ORBIT_RUN_S
        ok &= same[kind] and (target or duration < ORBIT_S)
        out[f"socket_{kind}"] = {"run_s": wall, "runs_s": walls, "round_trip_us_p50": p50, "round_trip_us_p999": p999,
                                 "bit_identical": same[kind]}
        print(f"socket law, {kind} client: run {wall:.2f} s (rounds {', '.join(f'{w:.2f}' for w in walls)}); round trip "
              f"median {p50:.1f} us, 99.9 % {p999:.1f} us; bit-identical to in-process pd: {same[kind]}"
              + (f"; one orbit <= {ORBIT_RUN_S:g} s: {_smoke.verdict(target, smoke)}" if kind == "c" else ""))
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=ORBIT_S, help="s of simulated time (default: one orbit)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds of the one-orbit runs, side by side (median)")
    ap.add_argument("--realtime-duration", type=float, default=600.0, help="s at --realtime 1 (default 600)")
    ap.add_argument("--parts", default=",".join(PARTS), help=f"which parts to run, of {','.join(PARTS)} (default all)")
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv, "20 s runs, one repeat, a 20 s paced run at x10")
    duration = _smoke.SMOKE_DURATION_S if args.smoke else args.duration
    rt_duration, rt_factor = (20.0, 10.0) if args.smoke else (args.realtime_duration, 1.0)
    parts = set(args.parts.split(","))
    if not parts <= set(PARTS):
        ap.error(f"--parts: {', '.join(sorted(parts - set(PARTS)))} is not one of {', '.join(PARTS)}")

    from stationbed import simulate
    from stationbed.run.pacing import Pacer
    from test_socket_law import PD_PARAMS, client_command, start, stop

    out: dict = {"machine": platform.platform(), "duration_s": duration, "smoke": args.smoke, "repeats": args.repeats}
    ok = True
    if "orbit" in parts:
        with tempfile.TemporaryDirectory() as tmp:
            ok &= _orbit(duration, args.repeats, _c_client(Path(tmp)), args.smoke, out)

    if "realtime1" in parts:
        pacer = Pacer(rt_factor)
        simulate(_scene({"name": "pd", "params": PD_PARAMS}, rt_duration), fused=False, pace=pacer)
        r = pacer.summary()
        out["realtime_1"] = r
        drift_ok = r["realtime_final_late_ms"] < DRIFT_MS
        if not args.smoke and rt_duration >= 600.0:
            ok &= drift_ok
        print(f"--realtime {rt_factor:g} over {rt_duration:g} s (in-process pd, a deadline every tick): lateness at the end "
              f"{r['realtime_final_late_ms']:.3f} ms (< {DRIFT_MS:g} ms: {_smoke.verdict(drift_ok, args.smoke)}), worst "
              f"{r['realtime_worst_late_ms']:.3f} ms, {r['realtime_misses']} of {r['realtime_deadlines']} deadlines missed, "
              f"achieved x{r['realtime_achieved_factor']:.6g}")

    if "realtime100" in parts:
        proc, port = start(client_command("python"))
        try:
            pacer = Pacer(100.0)
            simulate(_scene({"port": f"127.0.0.1:{port}", "params": PD_PARAMS}, duration), pace=pacer)
        finally:
            stop(proc)
        r = pacer.summary()
        out["realtime_100_socket"] = r
        print(f"--realtime 100 with the socket law (python client) over {duration:g} s: achieved "
              f"x{r['realtime_achieved_factor']:.5g}, {r['realtime_misses']} of {r['realtime_deadlines']} deadlines missed "
              f"(> 1 ms late), worst lateness {r['realtime_worst_late_ms']:.3g} ms, work per tick median "
              f"{r['realtime_work_ms_p50']:.3g} ms, 99 % {r['realtime_work_ms_p99']:.3g} ms")
    _smoke.write_json(args.json, out, default=str)
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
