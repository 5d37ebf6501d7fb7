"""FMU law cost per tick (issue 23): laws flown as Python and as FMI 2 / FMI 3 FMUs.

    python benchmarks/bench_fmu.py [--duration S] [--repeats N] [--smoke] [--json PATH]

The FMUs are the tests' (tests/fmu_laws/), built here into a temporary folder: the shipped ``pd``
packed by pythonfmu (FMI 2) and pythonfmu3 (FMI 3), and a rate-damping law compiled from C (no
Python inside: what a Simulink or Modelica export is). Timed side by side in one process
(interleaved, median of ``--repeats``, after a warm-up that loads the compiled system and
instantiates the FMUs), on the tests' scene (a small station in LVLH, no CMG) at 10 Hz for
``--duration`` seconds:

* ``python pd``, ``python rate damping``: the law's Python ``_update`` every tick (``fused=False``);
* ``fmu ...``: the same law inside an FMU, through FMPy every tick; "added" is its cost over its
  Python twin, whose trajectory it flies bit for bit (checked here);
* ``FMU call alone``: the instance's tick (write the inputs, ``doStep``, read the outputs) in a bare
  loop, no simulation: what the FMU itself costs.

Per tick is the slope between a run of the duration and one a fifth as long (a run's set-up
cancels). ``--smoke``: a 50 s run, one repeat (CI: does it run).
"""

from __future__ import annotations

import argparse
import statistics
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
import stationbed  # noqa: E402

#: a 10 Hz law (iss_lvlh_hold's rate), a row every 10 s
PERIOD_S = 0.1
OUTPUT_DT_S = 10.0


def _build(version: int, dest: Path):
    laws = ROOT / "tests" / "fmu_laws"
    try:
        if version == 2:
            from pythonfmu import FmuBuilder
        else:
            from pythonfmu3 import FmuBuilder
    except ImportError as e:
        return None, f"not built ({e.name} is not installed: pip install -e '.[test]')"
    return FmuBuilder.build_FMU(laws / f"pd_fmi{version}.py", dest=dest / f"v{version}", project_files=[laws / "pd_core.py"]), ""


def _call_alone(ctrl, n: int) -> float:
    """Seconds per ``Instance.tick`` of the controller's FMU instance (reset for a run), fixed inputs."""
    inst = ctrl._inst
    inst.inputs[:] = 0.0
    inst.inputs[0] = 1.0  # q_BN = identity
    t0 = time.perf_counter()
    for k in range(n):
        inst.tick(k * ctrl.period, ctrl.period)
    return (time.perf_counter() - t0) / n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="s of simulated time per run (default 600)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = _smoke.parse(ap, argv, "a 50 s run, one repeat")
    if args.smoke:
        args.duration = 50.0
    try:
        import fmpy
    except ImportError:
        print("bench_fmu: FMPy is not installed (pip install 'stationbed[fmi]'): nothing measured")
        return 0
    from fmu_laws import c_rate_damp
    from stationbed.run.laws import build_controller
    from test_fmu import PD_PARAMS, fmu_scene, pd_scene

    from stationbed.scene import scene_from_dict

    tmp = Path(tempfile.mkdtemp(prefix="bench_fmu_"))
    over = {"controller.period": PERIOD_S, "simulation.step": PERIOD_S, "simulation.output_dt": OUTPUT_DT_S,
            "simulation.duration": args.duration}
    # name -> (scene, Python controller or None, the Python twin it must fly the same as)
    runs = {"python pd": (scene_from_dict(pd_scene({"name": "pd", "params": PD_PARAMS}, **over)), None, None)}
    notes = {}
    for version in (2, 3):
        path, why = _build(version, tmp)
        if path is None:
            notes[f"fmu pd (FMI {version}, pythonfmu)"] = why
            continue
        runs[f"fmu pd (FMI {version}, pythonfmu)"] = (fmu_scene(path, **over), None, "python pd")
    spin = {**over, "initial.omega_BN_B": [0.01, -0.02, 0.005]}  # rad/s
    runs["python rate damping"] = (scene_from_dict(pd_scene({"name": "pd"}, **spin)), c_rate_damp.RateDamp, None)
    if c_rate_damp.compiler() is None:
        notes["fmu rate damping (FMI 2, C)"] = "not built (no C compiler)"
    else:
        path = c_rate_damp.build(tmp / "c", platform=fmpy.platform)
        runs["fmu rate damping (FMI 2, C)"] = (scene_from_dict(pd_scene({"fmu": str(path)}, **spin)), None,
                                                "python rate damping")

    def fly(name, scene, keep=True):
        _, law, _ = runs[name]
        return stationbed.simulate(scene, fused=False, keep=keep, controller=law(period=PERIOD_S) if law else None)

    first = {name: fly(name, r[0]) for name, r in runs.items()}  # warm-up
    for name, (_, _, twin) in runs.items():
        if twin is not None and not np.array_equal(first[name].data, first[twin].data, equal_nan=True):
            print(f"bench_fmu: {name} does not fly {twin}'s trajectory", file=sys.stderr)
            return 1
    ref = first["python pd"]
    # per tick: the slope between a run of the duration and one of a fifth of it (the set-up of a
    # run, the same for both, cancels)
    short = {name: r[0].replace({"simulation.duration": args.duration / 5}) for name, r in runs.items()}
    walls = {name: [] for name in runs}
    slopes = {name: [] for name in runs}
    ticks = ref.meta["summary"]["ticks"] + 1  # controller calls per run
    ticks_short = round(args.duration / 5 / PERIOD_S) + 1
    for _ in range(args.repeats):
        for name in runs:  # interleaved: all see the same machine load
            t0 = time.perf_counter()
            fly(name, runs[name][0], keep=False)
            t1 = time.perf_counter()
            fly(name, short[name], keep=False)
            t2 = time.perf_counter()
            walls[name].append(t1 - t0)
            slopes[name].append(((t1 - t0) - (t2 - t1)) / (ticks - ticks_short))
    per_tick = {k: statistics.median(v) for k, v in slopes.items()}
    alone = {}
    for name, (s, _, _) in runs.items():
        if name.startswith("fmu"):
            ctrl = build_controller(s.controller, base_dir=s.folder)
            times = []
            for _ in range(3):
                ctrl.reset(_plant(s))  # a fresh start of the FMU's clock
                times.append(_call_alone(ctrl, max(200, ticks)))
            alone[name] = min(times)

    print(f"# FMU law cost per tick: {args.duration:g} s at {1 / ref.meta['summary']['period_s']:g} Hz "
          f"({ticks} ticks), median of {args.repeats}")
    print(f"machine: {_smoke.machine()}, FMPy {fmpy.__version__}")
    print()
    print("| law | wall per run [s] | per tick (slope) [us] | added per tick vs its Python twin [us] | FMU call alone [us] |")
    print("|---|---|---|---|---|")
    for name, (_, _, twin) in runs.items():
        extra = "" if twin is None else f"{(per_tick[name] - per_tick[twin]) * 1e6:.1f}"
        a = f"{alone[name] * 1e6:.1f}" if name in alone else ""
        print(f"| {name} | {statistics.median(walls[name]):.3f} | {per_tick[name] * 1e6:.1f} | {extra} | {a} |")
    for name, why in notes.items():
        print(f"| {name} | {why} | | | |")
    print()
    print("each FMU flies its Python twin's trajectory, bit for bit: yes")
    _smoke.write_json(args.json, {"per_tick_s": per_tick, "walls_s": walls, "call_alone_s": alone, "ticks": ticks})
    return 0


def _plant(scene):
    """The plant facts of ``scene`` (as the loop builds them), for a controller outside a run."""
    from stationbed.run.closed_loop import plant_facts
    from stationbed.run.prepare import prepare

    run = prepare(scene)
    return plant_facts(scene, run.system, scene.controller.period)


if __name__ == "__main__":
    sys.exit(main())
