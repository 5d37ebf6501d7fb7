"""The run loop: scene -> model -> formulation -> compiled functions -> integrator -> Trajectory.

The run is cut into *segments* at every discontinuity of the scene (torque-window edges); the
integrator advances each segment with the held input constant and lands exactly on every
output time. Rows stream to an optional sink as they are computed, so a run that fails keeps
everything up to the failure (:class:`SimulationError` carries the partial trajectory and
the time it stopped).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from ._compile import FastCall, compile_functions
from .environment import C_ON, omega_ON_O
from .formulations import Formulation, StationModel, Structure, get_formulation
from .integrators import Integrator, IntegrationError, get_integrator
from .rotation import dcm, quat_from_dcm
from .scene import ConstantTorque, Scene, load_scene
from .trajectory import Trajectory, base_columns

__all__ = ["simulate", "SimulationError", "build_system", "System", "initial_state"]

NU = 3  # held input: body torque [N m]
OUT_CHUNK = 64  # output rows evaluated per compiled call


class SimulationError(RuntimeError):
    """A run that failed part-way; ``trajectory`` holds the rows computed before ``t``."""

    def __init__(self, t: float, reason: str, trajectory: Trajectory):
        super().__init__(f"run stopped at t = {t:.6g} s: {reason}")
        self.t = t
        self.reason = reason
        self.trajectory = trajectory


@dataclass
class System:
    """Compiled functions of one (formulation, integrator, structure)."""

    formulation: Formulation
    integrator_cls: type[Integrator]
    funcs: dict
    build_s: float


_SYSTEMS: dict[tuple, System] = {}


def build_system(structure: Structure, formulation, integrator) -> System:
    """Build (or fetch from the in-process cache) the compiled functions for a structure."""
    form_cls = get_formulation(formulation)
    integ_cls = get_integrator(integrator)
    key = (form_cls, integ_cls, structure)
    if key in _SYSTEMS:
        return _SYSTEMS[key]
    t0 = time.perf_counter()
    model = StationModel(structure)
    form = form_cls(model)
    nx, npar = form.nx, model.layout.size
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", NU)
    p = ca.SX.sym("p", npar)
    q = ca.SX.sym("q", 4)
    w = ca.SX.sym("w", 3)
    rhs = ca.Function("rhs", [t, x, u, p], [form.rhs(t, x, u, p)])
    angles = []
    for a in model.arrays(t, p):
        angles += list(a[3])
    out = ca.Function(
        "out",
        [t, x, p],
        [ca.vertcat(form.omega(t, x, p), form.H_O_N(t, x, p), form.kinetic_energy(t, x, p), *angles)],
    )
    init = ca.Function("init", [t, q, w, p], [form.state(t, q, w, p)])
    # outputs for OUT_CHUNK rows in one call (p shared: reduce_in=[2])
    out_map = out.map("out_map", "serial", OUT_CHUNK, [2], [])
    fs = [rhs, out, out_map, init] + integ_cls.build(rhs, nx, NU, npar)
    tag = f"{form_cls.name}_{integ_cls.name}_{structure.key}"
    funcs = compile_functions(fs, tag, extra_c=integ_cls.extra_c)
    system = System(form, integ_cls, funcs, time.perf_counter() - t0)
    _SYSTEMS[key] = system
    return system


def initial_state(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``(q_BN, omega_BN_B)`` at t = 0, converting from LVLH when ``initial.frame = 'lvlh'``."""
    q = np.array(scene.initial.q_BN, dtype=float)
    w = np.array(scene.initial.omega_BN_B, dtype=float)
    if scene.initial.frame == "lvlh":
        o = scene.orbit
        C_BO = dcm(q)
        C_BN = C_BO @ C_ON(o.u0, o.inclination)
        q = quat_from_dcm(C_BN)
        w = w + C_BO @ omega_ON_O(o.mean_motion)
    return q, w


#: Floor of the characteristic rate: 1 mrad/s, the order of a LEO station's orbital rate.
RATE_SCALE_FLOOR_RAD_S = 1e-3


def characteristic_scales(scene: Scene, w0, model, p) -> tuple[float, float]:
    """Rate [rad/s] and momentum [N m s] units for the dimensionless ``atol``.

    rate = max(|ω0|, orbital rate, fastest array rate amplitude, 1 mrad/s); momentum = the
    largest principal moment of the total inertia at t = 0 times that rate.
    """
    rates = [float(np.linalg.norm(w0)), RATE_SCALE_FLOOR_RAD_S]
    if scene.orbit is not None:
        rates.append(scene.orbit.mean_motion)
    for a in scene.appendage:
        for pr in (a.alpha, a.beta):
            rates.append(abs(pr.rate) + abs(pr.amp * pr.freq))
    rate = max(rates)
    # about O: hub + parallel-axis terms, plus the arrays' own inertia (orientation ignored: a scale)
    I_total = p[model.layout["I0"]].reshape(3, 3) + sum((np.array(a.inertia) for a in scene.appendage), np.zeros((3, 3)))
    I_max = float(np.linalg.eigvalsh(I_total).max())
    return rate, I_max * rate


def _output_times(duration: float, dt: float) -> np.ndarray:
    n = int(math.floor(duration / dt + 1e-9))
    ts = np.arange(n + 1) * dt
    if duration - ts[-1] > 1e-9 * max(1.0, duration):
        ts = np.append(ts, duration)
    else:
        ts[-1] = min(ts[-1], duration)
    return ts


def _breakpoints(scene: Scene, duration: float) -> list[float]:
    bps = set()
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque):
            for b in (trq.start, trq.stop):
                if 0.0 < b < duration:
                    bps.add(float(b))
    return sorted(bps)


def _held_torque(scene: Scene, t_mid: float) -> np.ndarray:
    u = np.zeros(NU)
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque) and trq.start <= t_mid < trq.stop:
            u += np.array(trq.torque_B)
    return u


def simulate(
    scene: Scene | str | Path,
    *,
    formulation=None,
    integrator=None,
    rtol: float | None = None,
    atol: float | None = None,
    duration: float | None = None,
    step: float | None = None,
    output_dt: float | None = None,
    sink=None,
) -> Trajectory:
    """Run a scene and return its :class:`Trajectory`.

    Parameters
    ----------
    scene : Scene or path
    formulation, integrator : str or class, optional
        Override the scene's ``simulation.formulation`` / ``simulation.integrator``.
    rtol, atol, duration [s], step [s], output_dt [s] : float, optional
        Override the scene's values.
    sink : object with ``write(rows)``, optional
        Receives each batch of output rows as soon as it is computed.

    Raises
    ------
    SimulationError
        The run failed part-way; ``.trajectory`` has the rows up to ``.t``.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    sim = scene.simulation
    formulation = formulation or sim.formulation
    integrator = integrator or sim.integrator
    rtol = sim.rtol if rtol is None else rtol
    atol = sim.atol if atol is None else atol
    duration = sim.duration if duration is None else duration
    output_dt = sim.output_dt if output_dt is None else output_dt
    step = sim.step if step is None else step
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")

    structure = Structure.of(scene)
    system = build_system(structure, formulation, integrator)
    form, funcs = system.formulation, system.funcs
    p = form.model.params(scene)
    nx = form.nx
    q0, w0 = initial_state(scene)
    rate_scale, momentum_scale = characteristic_scales(scene, w0, form.model, p)
    atol_vec = form.atol_vector(atol, rate_scale, momentum_scale)
    integ = system.integrator_cls(funcs, p, nx, rtol=rtol, atol=atol_vec, step=step, max_step=sim.max_step)

    init = FastCall.of(funcs["init"])
    init.args[0][0] = 0.0
    init.args[1][:] = q0
    init.args[2][:] = w0
    init.args[3][:] = p
    init()
    x = init.res[0].copy()

    out = FastCall.of(funcs["out_map"])
    out.args[2][:] = p
    columns = base_columns(scene.appendage_names)
    n_out = funcs["out"].numel_out(0)

    def rows_of(ts, xs):
        ts = np.asarray(ts, dtype=float)
        xs = np.asarray(xs, dtype=float).reshape(len(ts), nx)
        rows = np.empty((len(ts), 1 + 4 + n_out))
        rows[:, 0] = ts
        rows[:, 1:5] = xs[:, :4] / np.linalg.norm(xs[:, :4], axis=1, keepdims=True)
        for k in range(0, len(ts), OUT_CHUNK):
            n = min(OUT_CHUNK, len(ts) - k)
            out.args[0][:n] = ts[k : k + n]
            out.args[1].reshape(OUT_CHUNK, nx)[:n] = xs[k : k + n]
            out()
            rows[k : k + n, 5:] = out.res[0].reshape(OUT_CHUNK, n_out)[:n]
        return rows

    t_out = _output_times(duration, output_dt)
    bps = _breakpoints(scene, duration)
    edges = sorted(set([0.0, duration] + bps))
    all_rows = [rows_of([0.0], [x])]
    if sink is not None:
        sink.write(all_rows[0])
    meta = {
        "scene": scene.name,
        "formulation": form.name,
        "integrator": system.integrator_cls.name,
        "rtol": rtol,
        "atol": atol,
        "build_s": system.build_s,
    }
    wall0 = time.perf_counter()
    try:
        for a, b in zip(edges[:-1], edges[1:]):
            inner = t_out[(t_out > a) & (t_out < b)]
            ts = np.concatenate([[a], inner, [b]])
            u = _held_torque(scene, 0.5 * (a + b))
            xs = integ.integrate(ts, x, u)
            x = xs[-1].copy()
            keep = np.isin(ts[1:], t_out)
            rows = rows_of(ts[1:][keep], xs[1:][keep])
            if not np.all(np.isfinite(rows)):
                bad = int(np.argmax(~np.all(np.isfinite(rows), axis=1)))
                good = rows[:bad]
                all_rows.append(good)
                if sink is not None:
                    sink.write(good)
                raise IntegrationError(rows[bad, 0], "outputs are not finite (NaN or inf)")
            all_rows.append(rows)
            if sink is not None:
                sink.write(rows)
    except IntegrationError as e:
        if e.partial is not None and len(e.partial) > 1:
            # rows of the failing segment that were integrated before the failure
            ts_done = ts[1 : len(e.partial)]
            keep = np.isin(ts_done, t_out)
            rows = rows_of(ts_done[keep], e.partial[1:][keep])
            all_rows.append(rows)
            if sink is not None:
                sink.write(rows)
        meta.update(status="failed", stopped_at=e.t)
        traj = Trajectory(columns, np.vstack(all_rows), meta)
        raise SimulationError(e.t, e.reason, traj) from None
    meta.update(
        status="ok",
        wall_s=time.perf_counter() - wall0,
        n_rhs=integ.n_rhs,
        n_steps=integ.n_steps,
    )
    return Trajectory(columns, np.vstack(all_rows), meta)
