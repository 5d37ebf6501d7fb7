"""Linearisation speed: the flexible ISS scene (issue 15's target: under a second once compiled).

    python benchmarks/bench_linearize.py [--scene PATH] [--repeats N] [--json PATH] [--smoke]

Timed (median of ``--repeats``, after a warm-up call that builds the plant's casadi functions and
loads or compiles the scene's system):

* ``linearize``: ``stationbed.linearize(scene, "lvlh")`` (the plant's exact Jacobians at the point,
  the trim torque, the control.StateSpace with named signals);
* ``linearize_tea``: ``about="tea"`` (adds the Newton search of the torque-equilibrium attitude
  over 24 instants of an orbit, sun-tracking arrays on their targets);
* ``margins``: ``loop_analysis`` (plant + the controller's Jacobian + per-channel margins).

The first call's time (building the casadi expressions and their Jacobians) is reported too.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402
from stationbed import load_scene  # noqa: E402
from stationbed.analysis import linearize, loop_analysis  # noqa: E402

TARGET_S = 1.0
DEFAULT_SCENE = ROOT / "scenarios" / "iss_flexible_lvlh_hold.toml"
#: the rigid hold: the same paths (lvlh, tea, margins) without the flexible scene's ~2 min of
#: Jacobian building on a loaded 2-core machine
SMOKE_SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"


def _median(f, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help=f"default {DEFAULT_SCENE.name} ({SMOKE_SCENE.name} with --smoke)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv, what="one repeat")
    if args.scene is None:
        args.scene = SMOKE_SCENE if args.smoke else DEFAULT_SCENE
    warnings.simplefilter("ignore")  # python-control's margin search on flat phase curves
    scene = load_scene(args.scene)
    t0 = time.perf_counter()
    sys_ = linearize(scene, "lvlh")
    first = time.perf_counter() - t0
    tea_scene = scene
    linearize(tea_scene, "tea")  # warm-up: builds the TEA residual
    res = {
        "scene": scene.name,
        "states": sys_.nstates,
        "first_call_s": first,
        "linearize_s": _median(lambda: linearize(scene, "lvlh"), args.repeats),
        "linearize_tea_s": _median(lambda: linearize(tea_scene, "tea"), max(1, args.repeats // 2)),
        "margins_s": _median(lambda: loop_analysis(scene), max(1, args.repeats // 2)),
    }
    print(f"{scene.name}: {res['states']} states; first call (builds the Jacobians) {first:.2f} s")
    for k in ("linearize_s", "linearize_tea_s", "margins_s"):
        print(f"  {k[:-2]:<15} {res[k] * 1e3:8.1f} ms (median)")
    ok = res["linearize_s"] < TARGET_S
    print(f"  target: linearize < {TARGET_S:g} s once compiled: "
          + _smoke.verdict(ok, args.smoke, "met", "MISSED"))
    _smoke.write_json(args.json, res, indent=1, newline=True)
    return _smoke.targets_exit(ok, args.smoke)


if __name__ == "__main__":
    sys.exit(main())
