"""What every script in benchmarks/ shares: smoke mode (issue 19, item 20), side-by-side timing,
and the report's tail (verdicts, the ratio table, the load and the machine, the JSON file).

``--smoke`` (or ``STATIONBED_BENCH_SMOKE=1`` in the environment) runs a benchmark with tiny
sizes (a few simulated seconds instead of an orbit, a handful of samples), one repeat, and judges
no target: every path it would time still runs, so a benchmark cannot rot unnoticed. CI runs each
script this way (tests/test_benchmarks_smoke.py; ``make bench-smoke``). Its numbers are not
measurements: the first line printed says so.
"""

from __future__ import annotations

import json
import math
import os
import platform
import statistics
import time
from typing import NamedTuple

__all__ = ["ENV", "SMOKE_DURATION_S", "ORBIT_WHAT", "add_option", "announce", "parse", "orbit_s", "verdict",
           "targets_exit", "rounds", "interleaved", "Timed", "load_now", "mean_load", "machine", "warmup_load",
           "ratio_table", "ratio_target", "write_json"]

#: the environment variable that turns smoke mode on for every script (e.g. in CI)
ENV = "STATIONBED_BENCH_SMOKE"
#: simulated time a smoke run covers in place of an orbit [s]: long enough for several controller
#: ticks, output rows and adaptive steps, short enough that a script's runs take well under a second
SMOKE_DURATION_S = 20.0


def add_option(ap) -> None:
    """Add ``--smoke`` to an argparse parser (default: on when :data:`ENV` is set, not "0")."""
    ap.add_argument("--smoke", action="store_true", default=os.environ.get(ENV, "") not in ("", "0"),
                    help=f"tiny sizes, one repeat, no target judged (CI; also ${ENV}=1)")


def announce(smoke: bool, what: str = "") -> None:
    """Print the smoke-mode line first, when on."""
    if smoke:
        print(f"smoke mode ({what or 'tiny sizes, one repeat'}): every path runs, no number below is a measurement, "
              "no target is judged")


#: what a script that flies an orbit does in smoke mode instead (its :func:`announce` line)
ORBIT_WHAT = f"{SMOKE_DURATION_S:g} s instead of an orbit, one repeat"


def parse(ap, argv=None, what: str = ORBIT_WHAT):
    """``ap``'s arguments with ``--smoke`` added: the smoke line announced first and, in smoke
    mode, ``repeats`` set to 1 (a script with a ``--repeats`` option)."""
    add_option(ap)
    args = ap.parse_args(argv)
    announce(args.smoke, what)
    if args.smoke and hasattr(args, "repeats"):
        args.repeats = 1
    return args


def orbit_s(scene, smoke: bool) -> float:
    """The simulated time of a timed run [s]: one orbit of ``scene``, or :data:`SMOKE_DURATION_S`
    in smoke mode."""
    return SMOKE_DURATION_S if smoke else 2 * math.pi / scene.orbit.mean_motion


def verdict(ok: bool, smoke: bool, passed: str = "PASS", failed: str = "FAIL") -> str:
    """``passed`` / ``failed`` (PASS / FAIL) of a target, or that it was not judged (smoke mode)."""
    return "not judged (smoke)" if smoke else (passed if ok else failed)


def targets_exit(ok: bool, smoke: bool) -> int:
    """The exit status of a script whose targets are ``ok``: 0 in smoke mode whatever they are."""
    return 0 if smoke or ok else 1


def load_now() -> float:
    """The machine's 1-minute load average (NaN where the platform has none)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def mean_load(load0: float) -> float:
    """The mean of the load average ``load0`` (:func:`load_now` at the start) and the load now:
    the load a measurement between the two saw."""
    return (load0 + load_now()) / 2


def machine() -> str:
    """``x86_64, 2 cores, python 3.12.3``: the machine a report's numbers were measured on."""
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}"


class Timed(NamedTuple):
    """What :func:`interleaved` measured: the warm-up results by name, the warm-up's wall time
    [s], the median wall and process-CPU times [s] by name, the load average (mean of before and
    after the rounds; NaN where the platform has none), every round's wall and CPU times by name."""

    first: dict
    build_s: float
    wall: dict
    cpu: dict
    load: float
    walls: dict
    cpus: dict


def rounds(runs: dict, repeats: int) -> tuple[dict, dict]:
    """``repeats`` rounds calling each callable of ``runs`` once in turn (interleaved: every run
    sees the same machine load); every call's wall and process-CPU times [s] by name."""
    walls = {name: [] for name in runs}
    cpus = {name: [] for name in runs}
    for _ in range(repeats):
        for name, f in runs.items():
            c0, t0 = time.process_time(), time.perf_counter()
            f()
            walls[name].append(time.perf_counter() - t0)
            cpus[name].append(time.process_time() - c0)
    return walls, cpus


def interleaved(runs: dict, repeats: int) -> Timed:
    """Time the callables of ``runs`` side by side: one warm-up call each (compiles, loads), then
    ``repeats`` :func:`rounds`."""
    t_build = time.perf_counter()
    first = {name: f() for name, f in runs.items()}
    build_s = time.perf_counter() - t_build
    load0 = load_now()
    walls, cpus = rounds(runs, repeats)
    load = mean_load(load0)
    wall = {k: statistics.median(v) for k, v in walls.items()}
    cpu = {k: statistics.median(v) for k, v in cpus.items()}
    return Timed(first, build_s, wall, cpu, load, walls, cpus)


def warmup_load(timed: Timed, cores: bool = False) -> str:
    """``warm-up incl. compile/load 1.2 s; load average 3.4`` (with ``cores``: `` on 2 cores``):
    the part of a report's header that says what the medians of ``timed`` ran beside."""
    return (f"warm-up incl. compile/load {timed.build_s:.1f} s; load average {timed.load:.1f}"
            + (f" on {os.cpu_count()} cores" if cores else ""))


def ratio_table(timed: Timed, base: str, new: str, base_label: str, new_label: str) -> tuple[float, float]:
    """Print the CPU and wall medians of the fused runs ``base`` and ``new`` of ``timed`` and
    their ratios (new / base) as a markdown table, columns headed ``base_label`` and
    ``new_label``; returns (CPU ratio, wall ratio)."""
    cpu, wall = timed.cpu, timed.wall
    ratio, ratio_wall = cpu[new] / cpu[base], wall[new] / wall[base]
    print(f"| fused loop | {base_label} [s] | {new_label} [s] | ratio |")
    print("|---|---|---|---|")
    print(f"| CPU time | {cpu[base]:.3f} | {cpu[new]:.3f} | {ratio:.2f} |")
    print(f"| wall time | {wall[base]:.3f} | {wall[new]:.3f} | {ratio_wall:.2f} |")
    return ratio, ratio_wall


def ratio_target(label: str, ratio: float, target: float, smoke: bool) -> bool:
    """Print ``label: 1.05 (target <= 1.1): PASS`` (:func:`verdict`); whether ``ratio`` meets
    ``target``."""
    ok = ratio <= target
    print(f"{label}: {ratio:.2f} (target <= {target}): {verdict(ok, smoke)}")
    return ok


def write_json(path, data, indent: int = 2, default=None, newline: bool = False) -> None:
    """``data`` as JSON (``json.dumps``'s ``indent`` and ``default``; a final newline when
    ``newline``) into ``path``, a :class:`~pathlib.Path`; nothing when ``path`` is None (no
    ``--json`` given)."""
    if path is not None:
        path.write_text(json.dumps(data, indent=indent, default=default) + ("\n" if newline else ""))
