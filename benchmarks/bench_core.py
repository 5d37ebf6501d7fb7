"""Core speed benchmark: one orbit, compiled library paths vs scipy + numpy (DESIGN §9).

    python benchmarks/bench_core.py [--scene PATH] [--repeats N] [--scipy-repeats N] [--json PATH]

For one orbit (T = 2 pi / n) of the scene at rtol 1e-9, atol 1e-12:

* every formulation in ``stationbed.FORMULATIONS`` through ``stationbed.simulate`` (one warm-up
  run, compilation is cached; then the median of ``--repeats`` runs) and its RHS count;
* scipy ``solve_ivp(method="DOP853")`` with the plain-numpy momentum RHS of
  ``benchmarks/numpy_rhs.py`` at the same output times (median of ``--scipy-repeats`` runs);
* accuracy: the max attitude difference (principal rotation angle) of each path against a tight
  reference (the library's momentum form at rtol 1e-12), and numpy vs library directly; as an
  independent check of the reference itself, the numpy RHS at rtol 1e-13 against it.
* one "(info)" row: the library with outputs at 0 and T only (the cost of the output grid).

Prints a markdown table, the targets (<= 10 ms per orbit compiled, >= 50x faster than
scipy + numpy) with PASS/FAIL, and the machine; ``--json PATH`` writes the numbers.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import stationbed  # noqa: E402
from numpy_rhs import initial_state as np_initial_state  # noqa: E402
from numpy_rhs import make_rhs, quat_angle  # noqa: E402

DEFAULT_SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
FALLBACK_SCENE = ROOT / "scenarios" / "power_tower_free_drift.toml"
RTOL, ATOL = 1e-9, 1e-12
REF_RTOL, REF_ATOL = 1e-12, 1e-14
NP_REF_RTOL, NP_REF_ATOL = 1e-13, 1e-16  # independent check of the reference (scipy + numpy)
TARGET_MS = 10.0
TARGET_SPEEDUP = 50.0


def _orbit_period(scene) -> float:
    if scene.orbit is None:
        raise SystemExit(f"scene {scene.name!r} has no [orbit]: 'one orbit' is undefined")
    return 2.0 * math.pi / scene.orbit.mean_motion


def _time_library(scene, form: str, duration: float, repeats: int, output_dt=None):
    kw = dict(formulation=form, rtol=RTOL, atol=ATOL, duration=duration, output_dt=output_dt)
    stationbed.simulate(scene, **kw)  # warm-up (compiles, or loads the cached build)
    walls, inner = [], []
    traj = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        traj = stationbed.simulate(scene, **kw)
        walls.append(time.perf_counter() - t0)
        inner.append(traj.meta.get("wall_s", float("nan")))
    return traj, statistics.median(walls), statistics.median(inner)


def _time_scipy(scene, duration: float, t_eval: np.ndarray, repeats: int, rtol=RTOL, atol=ATOL):
    f = make_rhs(scene)
    x0 = np_initial_state(scene)
    walls = []
    sol = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol = solve_ivp(f, (0.0, duration), x0, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
        walls.append(time.perf_counter() - t0)
        if not sol.success:
            raise SystemExit(f"solve_ivp failed: {sol.message}")
    return sol, statistics.median(walls)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=DEFAULT_SCENE, help="scene file (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=7, help="timed runs per compiled path (default 7)")
    ap.add_argument("--scipy-repeats", type=int, default=3, help="timed scipy+numpy runs (default 3)")
    ap.add_argument("--no-numpy-ref", action="store_true", help="skip the numpy rtol 1e-13 cross-check")
    ap.add_argument("--no-diagnostics", action="store_true", help="skip the (info) row")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers as JSON")
    args = ap.parse_args(argv)

    scene_path = args.scene
    if not scene_path.exists() and scene_path == DEFAULT_SCENE and FALLBACK_SCENE.exists():
        print(f"note: {scene_path.name} not found, using {FALLBACK_SCENE.name}", file=sys.stderr)
        scene_path = FALLBACK_SCENE
    scene = stationbed.load_scene(scene_path)
    T = _orbit_period(scene)
    forms = ["momentum", "momentum27", "dalembert"]
    forms += [f for f in stationbed.FORMULATIONS if f not in forms]
    forms = [f for f in forms if f in stationbed.FORMULATIONS]
    started = time.perf_counter()

    # -- reference: the library at rtol 1e-12 ------------------------------------------
    ref = stationbed.simulate(scene, formulation="momentum", rtol=REF_RTOL, atol=REF_ATOL, duration=T)
    t_eval = ref.t
    q_ref = ref.q_BN

    # -- compiled paths -----------------------------------------------------------------
    rows = []
    lib = {}
    for form in forms:
        traj, wall, inner = _time_library(scene, form, T, args.repeats)
        if not np.array_equal(traj.t, t_eval):
            raise SystemExit(f"{form}: output times differ from the reference run")
        lib[form] = traj
        rows.append(
            dict(
                path=f"stationbed `{form}` (compiled, {traj.meta.get('integrator', '?')})",
                key=form,
                median_wall_ms=1e3 * wall,
                median_integrate_ms=1e3 * inner,
                n_rhs=int(traj.meta["n_rhs"]),
                n_steps=int(traj.meta.get("n_steps", -1)),
                err_vs_ref_rad=float(np.max(quat_angle(traj.q_BN, q_ref))),
            )
        )

    # -- scipy + numpy ------------------------------------------------------------------
    sol, wall_sp = _time_scipy(scene, T, t_eval, args.scipy_repeats)
    q_np = sol.y[:4].T
    q_np = q_np / np.linalg.norm(q_np, axis=1, keepdims=True)
    rows.append(
        dict(
            path="scipy `solve_ivp` DOP853 + numpy RHS",
            key="scipy_numpy",
            median_wall_ms=1e3 * wall_sp,
            median_integrate_ms=1e3 * wall_sp,
            n_rhs=int(sol.nfev),
            n_steps=None,
            err_vs_ref_rad=float(np.max(quat_angle(q_np, q_ref))),
        )
    )
    # -- diagnostic: the cost of the 10 s output grid itself ------------------------------
    # The library's outputs come from DOP853's dense output (as scipy's t_eval), so they do not
    # cap the step; this row shows what is left when only t = 0 and T are requested.
    if not args.no_diagnostics:
        coarse, wall_c, inner_c = _time_library(scene, "momentum", T, args.repeats, output_dt=T)
        ref_T = q_ref[-1] if abs(t_eval[-1] - coarse.t[-1]) < 1e-9 * T else None
        rows.append(
            dict(
                path="(info) stationbed `momentum`, outputs at 0 and T only (own step control; error at T)",
                key="momentum_no_outputs",
                median_wall_ms=1e3 * wall_c,
                median_integrate_ms=1e3 * inner_c,
                n_rhs=int(coarse.meta["n_rhs"]),
                n_steps=int(coarse.meta.get("n_steps", -1)),
                err_vs_ref_rad=float(quat_angle(coarse.q_BN[-1], ref_T)[0]) if ref_T is not None else float("nan"),
            )
        )
    for r in rows:
        r["ratio_to_scipy_numpy"] = wall_sp / (r["median_wall_ms"] / 1e3)

    # -- accuracy cross-checks ----------------------------------------------------------
    d_np_lib = quat_angle(q_np, lib["momentum"].q_BN)
    checks = {
        "numpy_vs_library_momentum_rad": float(np.max(d_np_lib)),
        "numpy_vs_library_momentum_at_s": float(t_eval[int(np.argmax(d_np_lib))]),
    }
    for form in forms:
        if form != "momentum":
            checks[f"{form}_vs_momentum_rad"] = float(np.max(quat_angle(lib[form].q_BN, lib["momentum"].q_BN)))
    if not args.no_numpy_ref:
        sol_ref, _ = _time_scipy(scene, T, t_eval, 1, rtol=NP_REF_RTOL, atol=NP_REF_ATOL)
        q_np_ref = sol_ref.y[:4].T
        d = quat_angle(q_np_ref, q_ref)
        checks["numpy_ref_vs_library_ref_rad"] = float(np.max(d))
        # omega as a second, independent channel
        from numpy_rhs import omega_of

        om = omega_of(scene)
        w_np = np.array([om(t, x) for t, x in zip(sol_ref.t, sol_ref.y.T)])
        checks["numpy_ref_vs_library_ref_omega_rad_s"] = float(np.max(np.abs(w_np - ref.omega_BN_B)))

    # -- report -------------------------------------------------------------------------
    best = min((r for r in rows if r["key"] in forms), key=lambda r: r["median_wall_ms"])
    mom = next(r for r in rows if r["key"] == "momentum")
    targets = [
        dict(
            target=f"compiled momentum <= {TARGET_MS:g} ms per orbit",
            value=f"{mom['median_wall_ms']:.2f} ms",
            ok=mom["median_wall_ms"] <= TARGET_MS,
        ),
        dict(
            target=f"compiled momentum >= {TARGET_SPEEDUP:g}x faster than scipy + numpy",
            value=f"{mom['ratio_to_scipy_numpy']:.0f}x",
            ok=mom["ratio_to_scipy_numpy"] >= TARGET_SPEEDUP,
        ),
    ]
    now = _dt.datetime.now().astimezone()
    machine = dict(
        platform=platform.platform(),
        processor=platform.processor() or platform.machine(),
        python=platform.python_version(),
        nproc=os.cpu_count(),
        numpy=np.__version__,
        stationbed=getattr(stationbed, "__version__", "?"),
    )

    print(f"## bench_core: one orbit of `{scene.name}`")
    print()
    print(
        f"scene `{scene_path.relative_to(ROOT) if scene_path.is_relative_to(ROOT) else scene_path}`, "
        f"T = {T:.1f} s, rtol {RTOL:g}, atol {ATOL:g}, {len(t_eval)} output times; "
        f"compiled: median of {args.repeats} after 1 warm-up, scipy: median of {args.scipy_repeats}; "
        f"reference: stationbed `momentum` at rtol {REF_RTOL:g}, atol {REF_ATOL:g}"
    )
    print()
    print("| path | median wall [ms] | RHS evals | ratio to scipy+numpy | max attitude error vs reference [rad] |")
    print("|---|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['path']} | {r['median_wall_ms']:.2f} | {r['n_rhs']} | "
            f"{r['ratio_to_scipy_numpy']:.1f}x | {r['err_vs_ref_rad']:.2e} |"
        )
    print()
    print(
        "wall = the whole `simulate()` call (incl. output rows); integrator alone (meta wall_s): "
        + ", ".join(f"{r['key']} {r['median_integrate_ms']:.2f} ms" for r in rows if r["key"] in forms)
    )
    print()
    print("| target | value | result |")
    print("|---|---:|---|")
    for tg in targets:
        print(f"| {tg['target']} | {tg['value']} | {'PASS' if tg['ok'] else 'FAIL'} |")
    print()
    print("accuracy cross-checks (max over the orbit):")
    for k, v in checks.items():
        print(f"- {k}: {v:.3e}")
    print()
    print(
        f"machine: {machine['platform']}, {machine['processor']}, nproc {machine['nproc']}, "
        f"python {machine['python']}, numpy {machine['numpy']}; date {now.isoformat(timespec='seconds')}; "
        f"bench time {time.perf_counter() - started:.1f} s (fastest compiled: {best['key']})"
    )

    if args.json is not None:
        payload = dict(
            scene=str(scene_path),
            scene_name=scene.name,
            orbit_period_s=T,
            rtol=RTOL,
            atol=ATOL,
            ref_rtol=REF_RTOL,
            ref_atol=REF_ATOL,
            n_output=len(t_eval),
            repeats=args.repeats,
            scipy_repeats=args.scipy_repeats,
            rows=rows,
            targets=targets,
            checks=checks,
            machine=machine,
            date=now.isoformat(timespec="seconds"),
        )
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(payload, indent=2) + "\n")
    return 0 if all(tg["ok"] for tg in targets) else 1


if __name__ == "__main__":
    sys.exit(main())
