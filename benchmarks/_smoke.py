"""Smoke mode, shared by every script in benchmarks/ (issue 19, item 20).

``--smoke`` (or ``STATIONBED_BENCH_SMOKE=1`` in the environment) runs a benchmark with tiny
sizes (a few simulated seconds instead of an orbit, a handful of samples), one repeat, and judges
no target: every path it would time still runs, so a benchmark cannot rot unnoticed. CI runs each
script this way (tests/test_benchmarks_smoke.py; ``make bench-smoke``). Its numbers are not
measurements: the first line printed says so.
"""

from __future__ import annotations

import os
import statistics
import time
from typing import NamedTuple

__all__ = ["ENV", "SMOKE_DURATION_S", "ORBIT_WHAT", "add_option", "announce", "parse", "verdict", "targets_exit", "interleaved", "Timed"]

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


def verdict(ok: bool, smoke: bool) -> str:
    """PASS / FAIL of a target, or that it was not judged (smoke mode)."""
    return "not judged (smoke)" if smoke else ("PASS" if ok else "FAIL")


def targets_exit(ok: bool, smoke: bool) -> int:
    """The exit status of a script whose targets are ``ok``: 0 in smoke mode whatever they are."""
    return 0 if smoke or ok else 1


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


def interleaved(runs: dict, repeats: int) -> Timed:
    """Time the callables of ``runs`` side by side: one warm-up call each (compiles, loads), then
    ``repeats`` rounds calling each once in turn (interleaved: every run sees the same machine
    load)."""
    t_build = time.perf_counter()
    first = {name: f() for name, f in runs.items()}
    build_s = time.perf_counter() - t_build
    walls = {name: [] for name in runs}
    cpus = {name: [] for name in runs}
    load0 = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    for _ in range(repeats):
        for name, f in runs.items():
            c0, t0 = time.process_time(), time.perf_counter()
            f()
            walls[name].append(time.perf_counter() - t0)
            cpus[name].append(time.process_time() - c0)
    load = (load0 + os.getloadavg()[0]) / 2 if hasattr(os, "getloadavg") else float("nan")
    wall = {k: statistics.median(v) for k, v in walls.items()}
    cpu = {k: statistics.median(v) for k, v in cpus.items()}
    return Timed(first, build_s, wall, cpu, load, walls, cpus)
