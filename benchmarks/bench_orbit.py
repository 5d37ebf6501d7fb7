"""What a two-body orbit costs (issue 14): eccentric vs circular, one orbit, open loop, DOP853.

    python benchmarks/bench_orbit.py [--repeats N] [--json PATH] [--smoke]

Two scenes, each flown on four orbits of the same semi-major axis (so the same period):

* ``circular``: the circular form (``radius = a``), gravity gradient only: ``u = u0 + n t``;
* ``e=0.0078``: the scene's ISS-like two-body orbit (Kepler's equation, 2 Newton steps);
* ``e=0.05``: the same plane, e = 0.05 (3 Newton steps; perigee 43 km up: a cost case, not a real orbit);
* ``e=0.0078+J2``: the ISS-like orbit with J2 secular drift (node and perigee angles per RHS).

Scenes: ``jeod_style_eccentric_libration`` (rigid slender body) and ``iss_lvlh_gravity_gradient``
(the benchmark ISS with two turning array pairs). rtol 1e-9, atol 1e-12, ``momentum``, one orbit;
timed interleaved as in ``bench_core.py`` (median of ``repeats x 3`` warm calls per path). Prints
wall time per orbit, the integrator's own wall, RHS evaluations, the operations of one RHS
(:func:`rhs_ops`) and the ratio of the wall time to the circular path (issue 14's target for the eccentric orbit: <= 2x, with aero and SRP).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import casadi as ca  # noqa: E402

import _smoke  # noqa: E402
import stationbed  # noqa: E402
from bench_core import _time_interleaved  # noqa: E402
from stationbed.core.compile import sx_function  # noqa: E402
from stationbed.formulations import get_formulation  # noqa: E402
from stationbed.model import StationModel, Structure  # noqa: E402

SCENES = ("jeod_style_eccentric_libration", "iss_lvlh_gravity_gradient")
RTOL, ATOL = 1e-9, 1e-12
TARGET_RATIO = 2.0
#: the ISS-like state of the eccentric scenario, as elements (a [m], e, i, raan, argp, nu [rad])
ISS = {"a": 6759052.98, "e": 0.0077838841, "i": 0.9013452468, "raan": 1.742047249, "argp": 3.812166641, "nu": 3.791924869}


def variants(scene):
    """Orbit name -> the scene flown on it (every variant: the same a, so the same period)."""
    o = {"mu": scene.orbit.mu, "gravity_gradient": True}
    out = {"circular": {**o, "radius": ISS["a"], "inclination": ISS["i"], "u0": ISS["argp"] + ISS["nu"]}}
    out["e=0.0078"] = {**o, "elements": ISS}
    out["e=0.05"] = {**o, "elements": {**ISS, "e": 0.05}}
    out["e=0.0078+J2"] = {**o, "elements": ISS, "j2": True}
    return {k: scene.replace({"orbit": v}) for k, v in out.items()}


def rhs_ops(scene) -> int:
    """Operations of the scene's ``momentum`` RHS (casadi SX instructions after CSE, inputs and
    outputs included; the RHS is inlined in the compiled DOP853 step, so its cost shows here)."""
    model = StationModel(Structure.of(scene))
    form = get_formulation("momentum")(model)
    t, x = ca.SX.sym("t"), ca.SX.sym("x", form.nx)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.layout.size)
    return sx_function("rhs", [t, x, u, p], [form.rhs(t, x, u, p)]).n_instructions()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path)
    args = _smoke.parse(ap, argv)
    results = {}
    print(f"machine: {_smoke.machine()}")
    for name in SCENES:
        base = stationbed.load_scene(ROOT / "scenarios" / f"{name}.toml")
        scenes = variants(base)
        T = _smoke.orbit_s(scenes["circular"], args.smoke)
        runs = {k: (lambda s=s: stationbed.simulate(s, formulation="momentum", integrator="dop853", rtol=RTOL, atol=ATOL,
                                                    duration=T)) for k, s in scenes.items()}
        timed = _time_interleaved(runs, args.repeats, block=1 if args.smoke else 3)
        print(f"\n### {name}: one orbit ({T:.0f} s), momentum/dop853, rtol {RTOL:g}\n")
        print("| orbit | wall per orbit [ms] | integrator [ms] | RHS evals | RHS ops | ratio to circular |")
        print("|---|---|---|---|---|---|")
        ref = timed["circular"][1]
        rows = {}
        for k, (tr, wall, inner) in timed.items():
            n_rhs = tr.meta.get("n_rhs", 0)
            ops = rhs_ops(scenes[k])
            rows[k] = {"wall_ms": 1e3 * wall, "integrator_ms": 1e3 * inner, "n_rhs": n_rhs, "rhs_ops": ops, "ratio": wall / ref}
            print(f"| {k} | {1e3 * wall:.2f} | {1e3 * inner:.2f} | {n_rhs} | {ops} | {wall / ref:.2f} |")
        worst = max(r["ratio"] for r in rows.values())
        print(f"\ntarget: two-body <= {TARGET_RATIO}x circular: {_smoke.verdict(worst <= TARGET_RATIO, args.smoke)} (worst {worst:.2f}x)")
        results[name] = rows
    _smoke.write_json(args.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
