"""Compile time and generated C size against the number of solar arrays (issue 12, item 9).

    python benchmarks/bench_compile.py [--arrays 2 8 16 32 48] [--formulation momentum]
                                       [--integrator dop853] [--rhs-inline-max OPS] [--json PATH] [--smoke]

For each count, a rigid station with that many arrays on a ring (each turning at orbital rate,
gravity gradient on: :func:`array_scene`) is built from scratch into an empty temporary compile
cache (``STATIONBED_CACHE``), so every build generates and compiles its C. Prints a markdown
table: arrays, RHS operations (casadi instructions), generated C [kB], build time [s] (SX graph,
code generation and the C compiler; ``System.build_s``), and the evaluator used.

Before issue 12 every stage of the DOP853 step and of its dense output inlined the RHS (29
copies): 48 arrays took 222 s to compile. The stages now call one compiled RHS when it has more
operations than the integrator's ``RHS_INLINE_MAX_OPS`` (DOP853: always; RK4: above 6000);
``--rhs-inline-max inf`` restores the inlining, for comparison.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
from pathlib import Path

import casadi as ca

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

#: array counts of a smoke run: one build from an empty cache, the smallest station with arrays
SMOKE_ARRAYS = [1]


def array_scene(n: int, formulation: str = "momentum", integrator: str = "dop853") -> dict:
    """A rigid station with ``n`` arrays on a ring of radius ~20-25 m, in a 400 km orbit."""
    apps = []
    for k in range(n):
        ang = 2.0 * math.pi * k / n
        apps.append({
            "name": f"a{k}",
            "mass": 3000.0,
            "inertia": [[2.25e5, 0.0, 0.0], [0.0, 3.6e4, 0.0], [0.0, 0.0, 2.61e5]],
            "cm": [20.0 * math.cos(ang), 25.0 * math.sin(ang), -60.0],
            "alpha": {"a0": 0.0, "rate": -0.0011313},
            "beta": {"a0": 0.25},
        })
    return {
        "name": f"arrays_{n}",
        "simulation": {"duration": 100.0, "formulation": formulation, "integrator": integrator},
        "initial": {"q_BN": [1.0, 0.0, 0.0, 0.0], "omega_BN_B": [0.0, 0.0, 0.0]},
        "body": {"mass": 2.2e5, "inertia": [[9.1e7, 0.0, 0.0], [0.0, 8.7e7, 0.0], [0.0, 0.0, 7.5e6]], "cm": [0.0, 0.0, 10.0]},
        "appendage": apps,
        "orbit": {"altitude": 4.0e5, "inclination": 0.5, "u0": 0.0, "gravity_gradient": True},
    }


def measure(n: int, formulation: str, integrator: str, inline_max: float | None = None) -> dict:
    """Build the system of ``n`` arrays in an empty cache; sizes and times. ``inline_max``
    overrides the integrator's ``RHS_INLINE_MAX_OPS``."""
    from stationbed.integrators import get_integrator
    from stationbed.model import Structure
    from stationbed.run import system as system_mod
    from stationbed.scene import scene_from_dict

    if inline_max is not None:
        get_integrator(integrator).RHS_INLINE_MAX_OPS = inline_max

    with tempfile.TemporaryDirectory() as cache:
        os.chmod(cache, 0o700)
        os.environ["STATIONBED_CACHE"] = cache
        structure = Structure.of(scene_from_dict(array_scene(n, formulation, integrator)))
        system_mod._SYSTEMS.clear()
        system = system_mod.build_system(structure, formulation, integrator)
        cg = ca.CodeGenerator("sb_size.c", {"with_header": False})
        for f in system.sx.values():
            cg.add(f)
        return {
            "arrays": n,
            "rhs_ops": system.sx["rhs"].n_instructions(),
            "c_kB": len(cg.dump()) / 1e3,
            "build_s": system.build_s,
            "evaluator": getattr(system, "evaluator", "compiled C" if "__lib__" in system.funcs else "casadi VM"),
        }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arrays", type=int, nargs="+", default=[2, 8, 16, 32, 48], help="array counts (default %(default)s)")
    ap.add_argument("--formulation", default="momentum")
    ap.add_argument("--integrator", default="dop853")
    ap.add_argument("--rhs-inline-max", type=float, default=None, metavar="OPS",
                    help="override the integrator's RHS_INLINE_MAX_OPS (inf: inline the RHS into every stage)")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    args = _smoke.parse(ap, argv, f"arrays {SMOKE_ARRAYS}")
    if args.smoke:
        args.arrays = SMOKE_ARRAYS
    rows = []
    import stationbed

    inline = "" if args.rhs_inline_max is None else f", RHS_INLINE_MAX_OPS = {args.rhs_inline_max:g}"
    print(f"stationbed from {Path(stationbed.__file__).parent}; {args.formulation}/{args.integrator}{inline}, {platform.processor() or platform.machine()}, python {sys.version.split()[0]}")
    print("| arrays | RHS operations | generated C [kB] | build [s] | evaluator |")
    print("|---|---|---|---|---|")
    for n in args.arrays:
        r = measure(n, args.formulation, args.integrator, args.rhs_inline_max)
        rows.append(r)
        print(f"| {r['arrays']} | {r['rhs_ops']} | {r['c_kB']:.0f} | {r['build_s']:.1f} | {r['evaluator']} |", flush=True)
    _smoke.write_json(args.json, rows, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
