"""Core speed benchmark: one orbit, compiled library paths vs scipy + numpy (DESIGN §9).

    python benchmarks/bench_core.py [--scene PATH] [--repeats N] [--scipy-repeats N] [--rk4-step S]
                                    [--no-flex] [--json PATH] [--smoke]

For one orbit (T = 2 pi / n) of the scene at rtol 1e-9, atol 1e-12:

* every formulation in ``stationbed.FORMULATIONS`` through ``stationbed.simulate`` with DOP853 and
  with fixed-step RK4 (``--rk4-step``, default 1 s), and its RHS count; every compiled path is
  timed side by side: one warm-up run each (compilation is cached), then ``--repeats`` rounds in
  which every path runs an untimed call and ``BLOCK`` timed ones back to back (interleaved, the
  order rotated each round, so that the load of a shared machine hits them alike), the median
  per path (:func:`_time_interleaved`). Issue 6's target: ``hamel`` costs at most 2x
  ``momentum`` on a rigid scene (ratio printed per integrator);
* the cost of flexibility (issue 6, skipped with ``--no-flex``): the same scene with two elastic
  modes per array (:func:`flexible_scene`: each array's two halves as cantilevers bending out
  of the array's plane at 0.1 Hz, 0.5 % damping, one wing bent 5 cm at t = 0), ``momentum``
  and ``hamel`` with both integrators, in the same interleaved rounds as the rigid paths; its
  accuracy against the flexible ``momentum`` at rtol 1e-12 (attitude and modal coordinates). The
  rigid rows' state size and RHS count show that a rigid scene's equations are those of before;
* scipy ``solve_ivp(method="DOP853")`` with the plain-numpy momentum RHS of
  ``benchmarks/numpy_rhs.py`` at the same output times (median of ``--scipy-repeats`` runs);
* accuracy: the max attitude difference (principal rotation angle) of each path against a tight
  reference (the library's momentum form at rtol 1e-12), and numpy vs library directly; as an
  independent check of the reference itself, the numpy RHS at rtol 1e-13 against it.
* one "(info)" row: the library with outputs at 0 and T only (the cost of the output grid).

Prints markdown tables, the targets (<= 10 ms per orbit compiled, >= 50x faster than
scipy + numpy, ``hamel`` <= 2x ``momentum`` per integrator) with PASS/FAIL, and the machine;
``--json PATH`` writes the numbers. BLAS runs single-threaded (see below) unless the environment
says otherwise.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import gc
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

# Every path here is single-threaded; a multi-threaded BLAS only adds threads that spin after a
# LAPACK call and, on a busy 2-core machine, take the core the run needs. The flexible scene's
# set-up (the beam modes' Gauss-Legendre nodes, numpy's `leggauss` -> `eigvalsh`, at every
# `simulate`) measured 64 ms median with OpenBLAS's default threads at load 3.7, 4.3 ms with one.
# Set before numpy is imported; an explicit setting in the environment wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import _smoke  # noqa: E402
import stationbed  # noqa: E402
from stationbed.scene import scene_from_dict  # noqa: E402
from numpy_rhs import initial_state as np_initial_state  # noqa: E402
from numpy_rhs import make_rhs, quat_angle  # noqa: E402

DEFAULT_SCENE = ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml"
FALLBACK_SCENE = ROOT / "scenarios" / "power_tower_free_drift.toml"
RTOL, ATOL = 1e-9, 1e-12
REF_RTOL, REF_ATOL = 1e-12, 1e-14
NP_REF_RTOL, NP_REF_ATOL = 1e-13, 1e-16  # independent check of the reference (scipy + numpy)
TARGET_MS = 10.0
TARGET_SPEEDUP = 50.0
TARGET_HAMEL_RATIO = 2.0  # issue 6: a rigid scene through `hamel` costs <= 2x `momentum`
INTEGRATORS = ("dop853", "rk4")
BLOCK = 3  # timed back-to-back calls per path and round (see _time_interleaved)
RK4_STEP_S = 1.0  # s: RK4's fixed step (the library's default); dop853 is adaptive
FLEX_FORMS = ("momentum", "hamel")
#: Elastic modes added to every array by flexible_scene (issue 6), one per wing (see there).
FLEX_FREQUENCY_HZ = 0.1  # first bending mode of a large array (order of magnitude)
FLEX_DAMPING = 0.005
FLEX_ETA0_M = 0.05  # m, tip deflection of the first wing at t = 0 (the other starts straight)


def _orbit_period(scene) -> float:
    if scene.orbit is None:
        raise SystemExit(f"scene {scene.name!r} has no [orbit]: 'one orbit' is undefined")
    return 2.0 * math.pi / scene.orbit.mean_motion


def flexible_scene(scene):
    """``scene`` with two elastic modes per array: its two halves (wings) along its long axis.

    A wing-declared array (``appendage.wing``) bends each wing out of its plane (the beams derived
    from the wing); otherwise, per array (inertia diagonal in P): the long axis is that of the smallest moment, the plate's
    normal that of the largest; each half is a uniform cantilever of half the array's mass from
    the array's mass centre along +-long axis, as long as half the equivalent box's side
    (``side² = 6 (I_a + I_b - I_long) / m``; ~36 m for the ISS array pairs), bending along the
    normal (out of the blanket), first mode at ``FLEX_FREQUENCY_HZ``; the first wing is bent
    ``FLEX_ETA0_M`` at its tip at t = 0.
    """
    d = scene.model_dump(exclude_unset=True)
    d["name"] = f"{scene.name}_flex"
    axes = "xyz"
    for a in d["appendage"]:
        if "wing" in a:  # declared once (issue 32): each wing bends out of its plane, its beam derived
            a["mode"] = [
                dict(frequency_hz=FLEX_FREQUENCY_HZ, damping=FLEX_DAMPING, wing=dict(side="+", deflection="normal", n=1),
                     eta0=FLEX_ETA0_M),
                dict(frequency_hz=FLEX_FREQUENCY_HZ, damping=FLEX_DAMPING, wing=dict(side="-", deflection="normal", n=1)),
            ]
            continue
        moments = np.diag(np.asarray(a["inertia"], float))
        i_long, i_normal = int(np.argmin(moments)), int(np.argmax(moments))
        half = 0.5 * math.sqrt(6.0 * (moments.sum() - 2.0 * moments[i_long]) / a["mass"])
        beam = dict(length=half, root=[0.0, 0.0, 0.0], deflection=axes[i_normal], n=1, mass=0.5 * a["mass"])
        a["mode"] = [
            dict(frequency_hz=FLEX_FREQUENCY_HZ, damping=FLEX_DAMPING, beam=dict(beam, span=f"+{axes[i_long]}"), eta0=FLEX_ETA0_M),
            dict(frequency_hz=FLEX_FREQUENCY_HZ, damping=FLEX_DAMPING, beam=dict(beam, span=f"-{axes[i_long]}")),
        ]
    return scene_from_dict(d)


def _state_size(scene, form: str, integrator: str) -> int:
    from stationbed.model import Structure
    from stationbed.run.system import build_system

    return int(build_system(Structure.of(scene), form, integrator).formulation.nx)


def _time_interleaved(runs: dict, repeats: int, block: int = BLOCK) -> dict:
    """``runs``: key -> zero-argument callable returning a Trajectory. One warm-up call each, then
    ``repeats`` rounds; in each round every path in turn (the order rotated each round) runs one
    untimed call and ``block`` timed calls back to back. Interleaving makes the load of a shared
    machine hit every path alike; the untimed call and the block make each timed call a warm
    one, as in back-to-back runs (a ~1 ms run timed right after a 20 ms run of another path
    starts with cold caches: measured, that made the rigid DOP853 rows ~1.5x slower).
    Returns key -> (last trajectory, median wall [s] of the call, median integrator wall
    ``meta["wall_s"]`` [s]) over the ``repeats * block`` timed calls."""
    keys = list(runs)
    for k in keys:
        runs[k]()  # warm-up: compiles, or loads the cached build
    walls = {k: [] for k in keys}
    inner = {k: [] for k in keys}
    last = {}
    for r in range(repeats):
        for k in keys[r % len(keys):] + keys[: r % len(keys)]:
            gc.collect()  # the previous path's garbage is not this path's cost
            runs[k]()
            for _ in range(block):
                t0 = time.perf_counter()
                traj = runs[k]()
                walls[k].append(time.perf_counter() - t0)
                inner[k].append(traj.meta.get("wall_s", float("nan")))
            last[k] = traj
    return {k: (last[k], statistics.median(walls[k]), statistics.median(inner[k])) for k in keys}


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


def _fixed_step(integ: str) -> bool:
    """The integrator takes ``--rk4-step`` (a fixed-step method), by its declared capability."""
    return not stationbed.INTEGRATORS[integ].adaptive


def _integ_label(r) -> str:
    return f"{r['integrator']}, h = {r['step_s']:g} s" if r["step_s"] is not None else r["integrator"]


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
    ap.add_argument("--repeats", type=int, default=15, help="interleaved rounds of the compiled paths (default 15)")
    ap.add_argument("--scipy-repeats", type=int, default=3, help="timed scipy+numpy runs (default 3)")
    ap.add_argument("--no-numpy-ref", action="store_true", help="skip the numpy rtol 1e-13 cross-check")
    ap.add_argument("--no-diagnostics", action="store_true", help="skip the (info) row")
    ap.add_argument("--rk4-step", type=float, default=RK4_STEP_S, help="RK4's fixed step [s] (default %(default)s)")
    ap.add_argument("--no-flex", action="store_true", help="skip the flexible-scene rows (issue 6)")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers as JSON")
    args = _smoke.parse(ap, argv)
    if args.smoke:
        args.scipy_repeats = 1

    scene_path = args.scene
    if not scene_path.exists() and scene_path == DEFAULT_SCENE and FALLBACK_SCENE.exists():
        print(f"note: {scene_path.name} not found, using {FALLBACK_SCENE.name}", file=sys.stderr)
        scene_path = FALLBACK_SCENE
    scene = stationbed.load_scene(scene_path)
    T = _smoke.SMOKE_DURATION_S if args.smoke else _orbit_period(scene)
    forms = ["momentum", "momentum27", "dalembert"]
    forms += [f for f in stationbed.FORMULATIONS if f not in forms]
    forms = [f for f in forms if f in stationbed.FORMULATIONS]
    started = time.perf_counter()

    # -- reference: the library at rtol 1e-12 ------------------------------------------
    ref = stationbed.simulate(scene, formulation="momentum", rtol=REF_RTOL, atol=REF_ATOL, duration=T)
    t_eval = ref.t
    q_ref = ref.q_BN

    # -- compiled paths: every formulation x integrator, rigid and flexible, interleaved -------
    flex = None if args.no_flex or not scene.appendage else flexible_scene(scene)
    runs = {}

    def add(tag, sc, form, integ):
        step = args.rk4_step if _fixed_step(integ) else None
        runs[(tag, form, integ)] = lambda: stationbed.simulate(
            sc, formulation=form, integrator=integ, rtol=RTOL, atol=ATOL, duration=T, step=step
        )

    for integ in INTEGRATORS:
        for form in forms:
            add("rigid", scene, form, integ)
        if flex is not None:
            for form in FLEX_FORMS:
                add("flex", flex, form, integ)
    timed = _time_interleaved(runs, args.repeats, block=1 if args.smoke else BLOCK)
    for (tag, form, integ), (traj, _, _) in timed.items():
        if tag == "rigid" and not np.array_equal(traj.t, t_eval):
            raise SystemExit(f"{form}/{integ}: output times differ from the reference run")

    def summary(tag, form, integ, q_ref_, eta_ref=None):
        traj, wall, inner = timed[(tag, form, integ)]
        out = dict(
            scene=tag,
            formulation=form,
            integrator=integ,
            step_s=args.rk4_step if _fixed_step(integ) else None,
            nx=_state_size(flex if tag == "flex" else scene, form, integ),
            median_wall_ms=1e3 * wall,
            median_integrate_ms=1e3 * inner,
            n_rhs=int(traj.meta["n_rhs"]),
            n_steps=int(traj.meta.get("n_steps", -1)),
            us_per_rhs=1e6 * inner / max(int(traj.meta["n_rhs"]), 1),
            err_vs_ref_rad=float(np.max(quat_angle(traj.q_BN, q_ref_))),
        )
        if eta_ref is not None:
            out["eta_err_vs_ref_m"] = float(np.max(np.abs(traj.cols(*eta_cols) - eta_ref)))
        return out

    rows = []
    lib = {}
    forms_table = []
    for form in forms:
        traj, wall, inner = timed[("rigid", form, "dop853")]
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
        forms_table += [summary("rigid", form, integ, q_ref) for integ in INTEGRATORS]
    for r in forms_table:
        mom = next(m for m in forms_table if m["formulation"] == "momentum" and m["integrator"] == r["integrator"])
        r["ratio_to_momentum"] = r["median_wall_ms"] / mom["median_wall_ms"]

    flex_table = []
    if flex is not None:
        ref_flex = stationbed.simulate(flex, formulation="momentum", rtol=REF_RTOL, atol=REF_ATOL, duration=T)
        eta_cols = [c for c in ref_flex.columns if c.startswith("eta_")]
        for form in FLEX_FORMS:
            for integ in INTEGRATORS:
                rigid = next(r for r in forms_table if r["formulation"] == form and r["integrator"] == integ)
                f = summary("flex", form, integ, ref_flex.q_BN, ref_flex.cols(*eta_cols))
                f["ratio_to_rigid"] = f["median_wall_ms"] / rigid["median_wall_ms"]
                f["rigid"] = rigid
                flex_table.append(f)

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
    for r in forms_table:
        if r["formulation"] == "hamel":
            targets.append(
                dict(
                    target=f"rigid scene: `hamel` <= {TARGET_HAMEL_RATIO:g}x `momentum` ({_integ_label(r)})",
                    value=f"{r['ratio_to_momentum']:.2f}x",
                    ok=r["ratio_to_momentum"] <= TARGET_HAMEL_RATIO,
                )
            )
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
        f"compiled: median of {args.repeats} interleaved rounds after 1 warm-up each, scipy: median of {args.scipy_repeats}; "
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
    print(
        f"### every formulation x integrator, rigid scene (one orbit; medians of {args.repeats} interleaved rounds)"
    )
    print()
    print("| formulation | integrator | states | median wall [ms] | ratio to `momentum` | integration alone [ms] | RHS evals | µs per RHS (integration alone) | max attitude error vs reference [rad] |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in forms_table:
        print(
            f"| `{r['formulation']}` | {_integ_label(r)} | {r['nx']} | {r['median_wall_ms']:.2f} | "
            f"{r['ratio_to_momentum']:.2f}x | {r['median_integrate_ms']:.2f} | {r['n_rhs']} | {r['us_per_rhs']:.2f} | "
            f"{r['err_vs_ref_rad']:.2e} |"
        )
    print()
    print(
        "wall = the whole `simulate()` call (set-up: parameters, initial state; integration; output rows); "
        "integration alone = the integrator's own loop (`meta['wall_s']`)"
    )
    if flex_table:
        print()
        print(
            f"### cost of flexibility: `{flex.name}` = the scene with 2 beam modes per array "
            f"({FLEX_FREQUENCY_HZ:g} Hz, damping {FLEX_DAMPING:g}), same interleaved rounds"
        )
        print()
        print("| formulation | integrator | rigid wall [ms] | flexible wall [ms] | flexible / rigid | integration alone rigid / flexible [ms] | states rigid / flexible | RHS evals rigid / flexible | µs per RHS rigid / flexible | flexible: max attitude error [rad] / max eta error [m] vs its reference |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for f in flex_table:
            r = f["rigid"]
            print(
                f"| `{f['formulation']}` | {_integ_label(f)} | {r['median_wall_ms']:.2f} | {f['median_wall_ms']:.2f} | "
                f"{f['ratio_to_rigid']:.1f}x | {r['median_integrate_ms']:.2f} / {f['median_integrate_ms']:.2f} | "
                f"{r['nx']} / {f['nx']} | {r['n_rhs']} / {f['n_rhs']} | "
                f"{r['us_per_rhs']:.2f} / {f['us_per_rhs']:.2f} | {f['err_vs_ref_rad']:.1e} / {f['eta_err_vs_ref_m']:.1e} |"
            )
        print()
        for integ in INTEGRATORS:
            h, m = (next(f for f in flex_table if f["formulation"] == x and f["integrator"] == integ) for x in ("hamel", "momentum"))
            print(
                f"flexible scene, {_integ_label(h)}: `hamel` / `momentum` = {h['median_wall_ms'] / m['median_wall_ms']:.2f}x "
                f"(integration alone {h['median_integrate_ms'] / m['median_integrate_ms']:.2f}x)"
            )
        print()
        print(
            f"flexible reference: `momentum` at rtol {REF_RTOL:g}, atol {REF_ATOL:g} on the flexible scene; "
            "a rigid scene's rows above are the rigid equations (no modal states), the same as before issue 6"
        )
    print()
    print("| target | value | result |")
    print("|---|---:|---|")
    for tg in targets:
        print(f"| {tg['target']} | {tg['value']} | {_smoke.verdict(tg['ok'], args.smoke)} |")
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
            forms_table=forms_table,
            flex_table=[{k: v for k, v in f.items() if k != "rigid"} for f in flex_table],
            flex_scene=None if flex is None else dict(
                name=flex.name, frequency_hz=FLEX_FREQUENCY_HZ, damping=FLEX_DAMPING, eta0_m=FLEX_ETA0_M
            ),
            rk4_step_s=args.rk4_step,
            targets=targets,
            checks=checks,
            machine=machine,
            date=now.isoformat(timespec="seconds"),
        )
        args.json.parent.mkdir(parents=True, exist_ok=True)
        _smoke.write_json(args.json, payload, newline=True)
    return _smoke.targets_exit(all(tg["ok"] for tg in targets), args.smoke)


if __name__ == "__main__":
    sys.exit(main())
