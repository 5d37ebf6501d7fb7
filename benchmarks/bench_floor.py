"""Where the fused tick's time goes (issue 25): one orbit of iss_lvlh_hold fused, with each effect
taken out in turn, timed side by side.

    python benchmarks/bench_floor.py [--repeats N] [--json PATH] [--smoke]

Rows (process CPU per orbit, medians of ``--repeats`` interleaved rounds after a warm-up that
compiles or loads each structure; CPU time because the machine is shared):

* ``default``: the scene as shipped (``environment_rate = "auto"``: aero + SRP held over 20 ticks);
* ``every_stage``: aero + SRP at each RK4 stage (``environment_rate = 0``);
* ``no_environment``: no aero, no SRP (and no surfaces);
* ``no_environment_no_gg``: also no gravity gradient;
* ``ideal_cmg``: the default with an ideal torquer (4 x 4760 N m s, 1000 N m) instead of the 4
  DGCMGs and their SR steering;
* ``mp_steering``: the default with Moore-Penrose steering instead of singularity-robust.

The differences between rows are each effect's cost in the compiled tick (plus what it adds to
the run's Python, ~nothing: the rows are the same). Smoke mode (``--smoke``) runs 20 s of the
first two rows only (the others are compiled structures of their own, too costly for CI's cold
cache). docs/design.md "The floor at the default" holds a measured table and the ``perf`` profile.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _smoke  # noqa: E402

import stationbed  # noqa: E402

SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"
#: the ideal torquer standing in for the cluster: the same capacity (4 x 4760 N m s)
IDEAL = {"kind": "ideal", "max_torque": 1000.0, "max_momentum": 19040.0}


def variants(scene, smoke: bool) -> dict:
    rows = {
        "default": scene,
        "every_stage": scene.replace({"simulation.environment_rate": 0}),
    }
    if not smoke:
        rows.update({
            "no_environment": scene.replace({"torque": [], "surface": []}),
            "no_environment_no_gg": scene.replace({"torque": [], "surface": [], "orbit.gravity_gradient": False}),
            "ideal_cmg": scene.replace({"cmg": IDEAL}),
            "mp_steering": scene.replace({"cmg.steering": "mp"}),
        })
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv, f"{_smoke.SMOKE_DURATION_S:g} s, the default and every-stage rows, one repeat")
    scene = stationbed.load_scene(SCENE)
    T = _smoke.orbit_s(scene, args.smoke)
    rows = variants(scene, args.smoke)
    runs = {k: (lambda s=s: stationbed.simulate(s, duration=T, keep=False)) for k, s in rows.items()}
    timed = _smoke.interleaved(runs, args.repeats)
    base = timed.cpu["default"]
    print(f"# iss_lvlh_hold fused, {T:.1f} s; CPU medians of {args.repeats} interleaved "
          f"rounds; load average {timed.load:.1f}")
    print("| variant | CPU [s] | minus the default [s] | environment ticks | fused |")
    print("|---|---:|---:|---:|---|")
    for k, cpu in timed.cpu.items():
        s = timed.first[k].meta["summary"]
        print(f"| {k} | {cpu:.4f} | {cpu - base:+.4f} | {s.get('environment_rate_ticks')} | {s.get('fused')} |")
    _smoke.write_json(args.json, {"cpu_s": timed.cpu, "wall_s": timed.wall, "load": timed.load})
    return 0


if __name__ == "__main__":
    sys.exit(main())
