"""Peak memory of one benchmark path, measured in a fresh subprocess.

    python benchmarks/_mem.py PATH_NAME [--n N] [--duration S]     (prints one JSON line)

Why a subprocess: ``ru_maxrss`` is a process-wide high-water mark that never goes down, so
paths measured one after another in one process would hide each other. Each path gets its own
interpreter, which

1. imports stationbed and runs the path once *briefly* (a few seconds of simulated time, or a
   batch of the same size over a short duration) so that its compiled library is loaded and
   its buffers exist: what is left is the cost of the run itself, not of compiling;
2. resets the kernel's resident-set high-water mark (``echo 5 > /proc/self/clear_refs``, Linux
   >= 4.0; the counter ``getrusage`` reads) and reads the resident set size (``VmRSS``: the
   baseline);
3. runs the full path with ``tracemalloc`` tracing;
4. reports
   - ``peak_rss_mib``: the peak RSS of the whole process over its life (interpreter, numpy,
     casadi, compiled libraries, results): what a user's machine must have for this path. It is
     the kernel's high-water mark of the process's memory (``VmHWM``; the larger of its value
     before the reset and after the run). Not ``resource.getrusage(...).ru_maxrss``: on Linux
     that also keeps the *parent's* peak across fork + exec (measured: every probe reported the
     benchmark's own 412 MiB), so it is only used where ``/proc`` is missing;
   - ``run_peak_rss_mib`` / ``run_increase_mib``: ``VmHWM`` after the run (peak RSS *during*
     the run, thanks to the reset) and its excess over the baseline: what the run adds;
   - ``tracemalloc_peak_mib``: the peak of Python objects and numpy arrays allocated during
     the run (casadi's C++ work memory is invisible to it; a cross-check of the increase).

When the reset is refused (not Linux), the run's peak falls back to ``ru_maxrss``, which then
may include the warm-up's.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

GG_SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
HOLD_SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"

#: path name -> human description (the table's first column)
PATHS = {
    "open_loop": "one orbit open loop, compiled DOP853 rtol 1e-9 (iss_lvlh_gravity_gradient)",
    "closed_python": "one orbit closed loop 10 Hz, Python controller (iss_lvlh_hold, fused=False)",
    "closed_fused": "one orbit closed loop 10 Hz, fused compiled loop (iss_lvlh_hold, fused=True)",
    "batch": "batch of N one-orbit samples, mapped DOP853 (iss_lvlh_gravity_gradient)",
}


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _reset_hwm() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _runner(name: str, n: int, threads: int, rtol: float | None = None, duration: float | None = None):
    """(warm-up, full run) callables of a path; the full run covers one orbit, or ``duration`` [s]
    (smoke mode)."""
    import stationbed
    from stationbed.run.batch import disperse_initial, simulate_batch

    if name == "open_loop":
        scene = stationbed.load_scene(GG_SCENE)
        T = duration or 2 * math.pi / scene.orbit.mean_motion
        return (lambda: stationbed.simulate(scene, duration=100.0)), (lambda: stationbed.simulate(scene, duration=T))
    if name in ("closed_python", "closed_fused"):
        scene = stationbed.load_scene(HOLD_SCENE)
        T = duration or 2 * math.pi / scene.orbit.mean_motion
        fused = name == "closed_fused"
        return (lambda: stationbed.simulate(scene, duration=20.0, fused=fused)), (
            lambda: stationbed.simulate(scene, duration=T, fused=fused)
        )
    if name == "batch":
        scene = stationbed.load_scene(GG_SCENE)
        T = duration or 2 * math.pi / scene.orbit.mean_motion
        q0s, w0s = disperse_initial(scene, n, attitude_sigma_rad=math.radians(1.0), rate_sigma_rad_s=1e-5, seed=1)
        kw = dict(threads=threads, rtol=rtol)
        return (lambda: simulate_batch(scene, q0s, w0s, duration=20.0, **kw)), (
            lambda: simulate_batch(scene, q0s, w0s, duration=T, **kw)
        )
    raise SystemExit(f"unknown path {name!r}; valid: {', '.join(PATHS)}")


def measure_here(name: str, n: int = 1000, threads: int = 2, rtol: float | None = None,
                 duration: float | None = None) -> dict:
    warm, run = _runner(name, n, threads, rtol, duration)
    warm()
    hwm_warm = _status_kib("VmHWM")
    reset = _reset_hwm()
    base = _status_kib("VmRSS")
    tracemalloc.start()
    result = run()
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    if hwm_warm and reset:
        run_peak = _status_kib("VmHWM")
        peak = max(hwm_warm, run_peak)
    else:  # no /proc: getrusage (may include the warm-up's and the parent's peak)
        run_peak = peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    del result
    return dict(
        path=name,
        peak_rss_mib=peak / 1024.0,
        baseline_rss_mib=base / 1024.0,
        run_peak_rss_mib=run_peak / 1024.0,
        run_increase_mib=max(0, run_peak - base) / 1024.0,
        tracemalloc_peak_mib=traced_peak / 2**20,
        hwm_reset=reset,
    )


def measure(name: str, n: int = 1000, threads: int = 2, rtol: float | None = None, timeout: float = 600.0,
            duration: float | None = None) -> dict:
    """Run :func:`measure_here` in a fresh interpreter; returns its dict."""
    cmd = [sys.executable, str(Path(__file__).resolve()), name, "--n", str(n), "--threads", str(threads)]
    if rtol is not None:
        cmd += ["--rtol", repr(rtol)]
    if duration is not None:
        cmd += ["--duration", repr(duration)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=dict(os.environ))
    if res.returncode != 0:
        raise RuntimeError(f"memory probe {name!r} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("path", choices=list(PATHS))
    ap.add_argument("--n", type=int, default=1000, help="batch samples (batch path)")
    ap.add_argument("--threads", type=int, default=2, help="batch threads (batch path)")
    ap.add_argument("--rtol", type=float, default=None, help="batch rtol (default: the scene's)")
    ap.add_argument("--duration", type=float, default=None, help="simulated time of the full run [s] (default: one orbit)")
    a = ap.parse_args()
    print(json.dumps(measure_here(a.path, a.n, a.threads, a.rtol, a.duration)))
