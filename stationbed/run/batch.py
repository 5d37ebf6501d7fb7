"""Monte Carlo batches: one compiled DOP853 step mapped over many samples (DESIGN §9).

:func:`simulate_batch` runs ``n`` open-loop samples of one scene (dispersed initial attitudes and
rates, and optionally dispersed parameters through one :class:`~stationbed.Scene` per sample)
and returns their states on a common output grid.

Design (why DOP853, not a fixed-step RK4 map)
---------------------------------------------
Every sample runs *exactly* the algorithm of ``simulate(..., integrator="dop853")``: the same
compiled step function (12 stages + FSAL + Hairer's error norm, and the 3 extra stages of the
7th-order dense output), the same per-sample step-size control (scipy's DOP853 rules:
``StepControl`` of ``integrators/dop853.py``, as the C driver ``dop853_driver.c``), the same
tolerances (the scene's ``rtol`` and its scaled ``atol``, computed per sample as ``simulate``
does) and the same output grid. The samples advance in *lockstep*
(``integrators/dop853_batch.py``): each iteration makes one step attempt for every unfinished
sample in **one** call of ``dop853_dense.map(n, "thread" | "serial")``, and numpy applies the
step control to all samples at once (each keeps its own ``t`` and ``h``; a finished sample is
evaluated with ``h = 0`` and ignored). So a batch costs about as many Python round trips as *one* run has
steps (~40 per orbit at rtol 1e-9), and each sample agrees with its individual ``simulate`` run
to round-off (same step sequence; the batch always calls the dense variant of the step and
evaluates the interpolant in numpy, so only the order of floating-point operations differs).

A fixed-step RK4 map was the alternative. It costs far more work for the same accuracy
(measured on one orbit of ``iss_lvlh_gravity_gradient`` against DOP853 at rtol 1e-13:
RK4 at 1 s is 1.1e-11 rad for 22 216 RHS evaluations, DOP853 at rtol 1e-12 is 1.0e-11 rad
for 1 133; at the scene's rtol 1e-9 DOP853 is 2.3e-8 rad for 521) and its results would not
be those of the adaptive single runs. With DOP853 the accuracy of a batch is the user's
``rtol``, and both rtol 1e-9 and 1e-12 batches of 1000 orbits fit the 60 s budget by far
(``benchmarks/bench_batch.py``).

Limits: open loop only (a scene with a ``[controller]`` is refused: its Python controller runs
per sample); the batch always integrates with DOP853 whatever the scene's ``integrator`` says.
A sample that fails (non-finite state, step-size underflow) is flagged in ``status`` and its
remaining rows are NaN; the others continue.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..core.compile import FastCall
from ..model import Structure
from ..integrators import DOP853
from ..integrators.dop853_batch import OK, STATUS_TEXT, DOP853Lockstep, mapped
from ..core.rotation import quat_mult
from ..scene import QUAT_NORM_TOL, Scene, load_scene
from .initial import characteristic_scales, from_lvlh, initial_x
from .segments import breakpoints, output_times, segment_input, smooth_cuts
from .system import build_system

__all__ = ["BatchResult", "disperse_initial", "simulate_batch"]


@dataclass
class BatchResult:
    """States of ``n`` samples on a common time grid.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Output times [s] (0, every ``output_dt``, and the duration), as ``simulate``'s rows.
    x : ndarray, shape (n, m, nx)
        Formulation states (q_BN first, then H_O_B or omega_BN_B, then extra states).
    q_BN : ndarray, shape (n, m, 4)
        Attitude of B relative to N, scalar first, normalised.
    omega_BN_B : ndarray, shape (n, m, 3)
        Angular velocity of B relative to N, B components [rad/s].
    H_O_N : ndarray, shape (n, m, 3)
        Total angular momentum about the composite mass centre, N components [N m s].
    T : ndarray, shape (n, m)
        Rotational kinetic energy [J].
    status : ndarray of int, shape (n,)
        0 ok, 1 step-size underflow, 2 non-finite state (the sample's later rows are NaN).
    q0_BN, omega0_BN_B : ndarray, shapes (n, 4), (n, 3)
        Initial attitude and rate relative to N actually used (after a frame conversion).
    meta : dict
        ``wall_s``, ``iterations`` (lockstep step attempts), ``n_steps`` / ``n_rejected`` per
        sample, ``n_rhs`` (total), ``threads``, ``formulation``, ``rtol``, ``atol``.
    """

    t: np.ndarray
    x: np.ndarray
    q_BN: np.ndarray
    omega_BN_B: np.ndarray
    H_O_N: np.ndarray
    T: np.ndarray
    status: np.ndarray
    q0_BN: np.ndarray
    omega0_BN_B: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.x.shape[0]

    @property
    def ok(self) -> np.ndarray:
        """Per sample: whether it ran to the end (bool array, shape (n,))."""
        return self.status == OK


# ---------------------------------------------------------------------------------------
# dispersion
# ---------------------------------------------------------------------------------------


def _rotvec_quat(theta: np.ndarray) -> np.ndarray:
    """Quaternions (k, 4) of rotation vectors ``theta`` (k, 3) [rad]."""
    ang = np.linalg.norm(theta, axis=1)
    half = 0.5 * ang
    # sin(a/2)/a without 0/0: its series below 1e-8 rad
    s = np.where(ang > 1e-8, np.sin(half) / np.where(ang > 0, ang, 1.0), 0.5 - ang**2 / 48.0)
    return np.column_stack([np.cos(half), s[:, None] * theta])


def disperse_initial(
    scene: Scene, n: int, *, attitude_sigma_rad: float, rate_sigma_rad_s: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Seeded Gaussian dispersion of the scene's initial attitude and rate.

    Sample ``i`` is ``q_i = q0 ⊗ exp(θ_i / 2)`` with ``θ_i ~ N(0, attitude_sigma² E)`` (a small
    rotation about B axes, 1-sigma per axis) and ``ω_i = ω0 + δω_i`` with
    ``δω_i ~ N(0, rate_sigma² E)``. Both stay in the scene's ``initial.frame`` (relative to LVLH
    for an ``"lvlh"`` scene), so they can be passed straight to :func:`simulate_batch`.

    Returns
    -------
    q0s : ndarray, shape (n, 4)   unit quaternions, scalar first
    w0s : ndarray, shape (n, 3)   [rad/s]
    """
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"n must be a positive integer, got {n!r}")
    for name, v in (("attitude_sigma_rad", attitude_sigma_rad), ("rate_sigma_rad_s", rate_sigma_rad_s)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
    rng = np.random.default_rng(seed)
    theta = rng.normal(0.0, attitude_sigma_rad, (n, 3))
    dw = rng.normal(0.0, rate_sigma_rad_s, (n, 3))
    q_nom = np.array(scene.initial.q_BN, dtype=float)
    dq = _rotvec_quat(theta)
    q = np.array([quat_mult(q_nom, d) for d in dq])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q, np.array(scene.initial.omega_BN_B, dtype=float) + dw


# ---------------------------------------------------------------------------------------
# input checks
# ---------------------------------------------------------------------------------------


def _as_rows(a, k: int, name: str, n: int | None) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim == 1 and a.size == k:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != k:
        raise ValueError(f"{name} must have shape (n, {k}), got {np.shape(a)}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name} has {a.shape[0]} rows but q0s has {n}")
    bad = ~np.all(np.isfinite(a), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}[{i}] is not finite: {a[i].tolist()}")
    return a


def _check_quaternions(q: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(q, axis=1)
    bad = np.abs(norm - 1.0) > QUAT_NORM_TOL
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(
            f"q0s[{i}] has norm {norm[i]:.9g}, not 1 (tolerance {QUAT_NORM_TOL:g}); "
            "pass unit quaternions, scalar first"
        )
    return q / norm[:, None]  # as the scene file's validator does


# ---------------------------------------------------------------------------------------
# the batch
# ---------------------------------------------------------------------------------------

#: serial by default: on this 2-core machine the "thread" map measured no faster (0.55 s serial vs
#: 0.60 s with 2 threads for 1000 orbits, medians of 5 under load; the mapped step is only about
#: half of the wall time, the rest is numpy step control and the output rows). Same numbers.
DEFAULT_THREADS = 1


def simulate_batch(
    scene: Scene | str,
    q0s,
    w0s,
    *,
    scenes: list[Scene] | None = None,
    frame: str | None = None,
    formulation: str | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    duration: float | None = None,
    output_dt: float | None = None,
    threads: int | None = None,
) -> BatchResult:
    """Run ``n`` open-loop samples of ``scene`` from the initial conditions ``q0s``, ``w0s``.

    Parameters
    ----------
    scene : Scene or path
        The nominal scene (structure, tolerances, duration, output grid, torques).
    q0s : array_like, shape (n, 4)
        Initial attitudes, unit quaternions, scalar first, relative to ``frame``.
    w0s : array_like, shape (n, 3)
        Initial angular velocities of B relative to ``frame``, B components [rad/s].
    scenes : list of Scene, optional
        One scene per sample for dispersed parameters (inertia, arrays, orbit, ...): each must
        have the nominal scene's structure and the same torque windows. Their ``[initial]`` is
        ignored (``q0s``/``w0s`` are used).
    frame : {"inertial", "lvlh"}, optional
        Frame of ``q0s``/``w0s``; default: the scene's ``initial.frame``.
    formulation, rtol, atol, duration [s], output_dt [s] : optional
        Override the scene's values, as in :func:`stationbed.simulate`.
    threads : int, optional
        Threads of the mapped step (casadi ``"thread"`` map); default 1 = ``"serial"`` map.

    Returns
    -------
    BatchResult

    Raises
    ------
    ValueError
        Bad shapes, non-unit quaternions, NaN/inf, a closed-loop scene, mismatched ``scenes``.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if scene.controller is not None:
        raise ValueError(
            f"scene {scene.name!r} has a [controller]: simulate_batch runs open loop only "
            "(run closed-loop samples with stationbed.simulate)"
        )
    q0s = _check_quaternions(_as_rows(q0s, 4, "q0s", None))
    n = q0s.shape[0]
    w0s = _as_rows(w0s, 3, "w0s", n)
    frame = scene.initial.frame if frame is None else frame
    if frame not in ("inertial", "lvlh"):
        raise ValueError(f"frame must be 'inertial' or 'lvlh', got {frame!r}")
    if frame == "lvlh" and scene.orbit is None:
        raise ValueError("frame = 'lvlh' needs a scene with an [orbit] table")
    threads = DEFAULT_THREADS if threads is None else int(threads)
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    sim = scene.simulation
    rtol = sim.rtol if rtol is None else float(rtol)
    atol = sim.atol if atol is None else float(atol)
    duration = sim.duration if duration is None else float(duration)
    output_dt = sim.output_dt if output_dt is None else float(output_dt)
    for name, v in (("rtol", rtol), ("atol", atol), ("duration", duration), ("output_dt", output_dt)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    structure = Structure.of(scene)
    bps, steps = breakpoints(scene, duration)
    if scenes is None:
        scenes = [scene] * n
    else:
        scenes = list(scenes)
        if len(scenes) != n:
            raise ValueError(f"scenes has {len(scenes)} entries but q0s has {n}")
        for i, s in enumerate(scenes):
            if Structure.of(s) != structure:
                raise ValueError(f"scenes[{i}] ({s.name!r}) has a different structure from {scene.name!r}")
            if s.torque != scene.torque or breakpoints(s, duration) != (bps, steps):
                raise ValueError(f"scenes[{i}] ({s.name!r}) has different torques or rate steps from {scene.name!r}")

    system = build_system(structure, formulation or sim.formulation, DOP853)
    form, funcs = system.formulation, system.funcs
    model = form.model
    nx, nu = form.nx, model.nu

    # -- per-sample parameters, initial states and tolerances (as simulate does) -------------
    P = np.empty((n, model.layout.size))
    X0 = np.empty((n, nx))
    TOL = np.empty((n, 1 + nx))
    QN = np.empty((n, 4))
    WN = np.empty((n, 3))
    p_cache: dict[int, np.ndarray] = {}
    for i, s in enumerate(scenes):
        p = p_cache.get(id(s))
        if p is None:
            p = p_cache[id(s)] = model.params(s)
        q, w = q0s[i], w0s[i]
        if frame == "lvlh":
            q, w = from_lvlh(s.orbit, q, w)
        rate_scale, momentum_scale = characteristic_scales(s, w, model, p)
        P[i], X0[i], QN[i], WN[i] = p, initial_x(system, s, q, w, p), q, w
        TOL[i, 0] = rtol
        TOL[i, 1:] = form.atol_vector(atol, rate_scale, momentum_scale)
    max_step = math.inf if sim.max_step is None else float(sim.max_step)

    wall0 = time.perf_counter()
    t_out = output_times(duration, output_dt)
    X = np.full((n, t_out.size, nx), np.nan)
    X[:, 0] = X0
    run = DOP853Lockstep(funcs, n, nx, nu, P, TOL, max_step, threads)
    jump = None
    if form.omega_is_state and steps and sim.impulse_jump:
        jump = FastCall.of(funcs["jump"])
    cuts = {c for s in {id(s): s for s in scenes}.values() for c in smooth_cuts(s, duration, DOP853)}
    edges = sorted(set([0.0, duration] + bps) | cuts)
    x = X0.copy()
    u = np.zeros(nu)
    for a, b in zip(edges[:-1], edges[1:]):
        inner = t_out[(t_out > a) & (t_out < b)]
        ts = np.concatenate([[a], inner, [b]])
        segment_input(scene, model, a, b, u)
        whole = ts.size == t_out.size  # one segment over the whole grid: write rows in place
        xs = run.segment(ts, x, u, out=X if whole else None)  # (n, len(ts), nx)
        x = xs[:, -1].copy()
        if jump is not None and b in steps:
            for i in np.flatnonzero(run.status == OK):
                ja = jump.args
                ja[0][0] = b * (1.0 - 1e-15) - 1e-300  # just before the step (as simulate)
                ja[1][0] = b
                ja[2][:] = x[i]
                ja[3][:] = P[i]
                jump()
                x[i] = jump.res[0]
            xs[:, -1] = x
        if not whole:
            keep = np.isin(ts[1:], t_out)
            idx = np.searchsorted(t_out, ts[1:][keep])
            X[:, idx] = xs[:, 1:][:, keep]
    omega, H, T = _outputs(funcs, t_out, X, P, threads, system)
    wall = time.perf_counter() - wall0
    iq = form.state_layout.slice("q_BN")  # the attitude, by the state layout
    qn = X[:, :, iq] / np.linalg.norm(X[:, :, iq], axis=2, keepdims=True)
    meta = dict(
        scene=scene.name,
        formulation=form.name,
        integrator="dop853",
        rtol=rtol,
        atol=atol,
        threads=threads,
        wall_s=wall,
        iterations=run.iterations,
        n_steps=run.n_steps,
        n_rejected=run.n_rejected,
        n_rhs=int(run.n_rhs),
        failures={int(i): STATUS_TEXT[int(run.status[i])] + f" at t = {run.t_stop[i]:.6g} s"
                  for i in np.flatnonzero(run.status != OK)},
    )
    return BatchResult(t_out, X, qn, omega, H, T, run.status.copy(), QN, WN, meta)


def _outputs(funcs, t_out, X, P, threads, system):
    """ω, H_O_N, T for every sample and row: the compiled ``out`` mapped over the samples."""
    n, m, nx = X.shape
    n_out, lay = system.n_out, system.out_layout
    out = mapped(funcs["out"], n, threads)
    out.args[2][:] = P.reshape(-1)
    res = np.empty((n, m, n_out))
    for j in range(m):
        out.args[0][:] = t_out[j]
        out.args[1][:] = np.nan_to_num(X[:, j]).reshape(-1)
        out()
        res[:, j] = out.res[0].reshape(n, n_out)
    res[~np.all(np.isfinite(X), axis=2)] = np.nan
    return res[:, :, lay["omega_BN_B"]], res[:, :, lay["H_O_N"]], res[:, :, lay["T"].start]
