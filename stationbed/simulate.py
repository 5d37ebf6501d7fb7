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

from ._compile import FastCall, compile_functions, sx_function
from .cmg import capacity, singularity_measure
from .environment import C_ON, omega_ON_O, orbit_position_N, q_ON
from .formulations import Formulation, StationModel, Structure, get_formulation
from .integrators import Integrator, IntegrationError, get_integrator
from .rotation import dcm, quat_from_dcm, rotation_angle
from .scene import ConstantTorque, Scene, load_scene
from .trajectory import Trajectory, base_columns

__all__ = ["simulate", "SimulationError", "build_system", "System", "initial_state", "initial_x", "from_lvlh"]

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
    n_out: int
    sx: dict = None  # the SX Functions before compilation (the fused loop composes them)


_SYSTEMS: dict[tuple, System] = {}


def _track_errors(model: StationModel, t, x, p):
    """Per array: angle between its normal (+z of P) and the sun [rad] (casadi)."""
    s_B = model.sun_B(x[0:4], p)
    errs = []
    for a in model.arrays(t, x[0:4], x[7:], p):
        n_B = a[4][2, :].T
        errs.append(ca.atan2(ca.norm_2(ca.cross(n_B, s_B)), ca.dot(n_B, s_B)))
    return errs


def _tick_functions(model, rhs, fs, nx, nu, npar, ng) -> list[ca.Function]:
    """One control period fused in one compiled call, for the fixed-step RK4 closed loop.

    ``tick_<cmd>(t, h, x, cmd, u_ext, p) -> (x(t + h), y(t + h), act)``: the actuation at
    ``(t, x)`` (steering law and limits; ``act = [u_cmg, m, rate_limited, saturated]``), one RK4
    step of ``h`` with that input held, and the measurement at the end. Same functions as the
    generic path (actuate, rk4 step, meas), composed, so both paths give the same numbers.
    """
    by_name = {f.name(): f for f in fs}
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    x, u_ext, p = ca.SX.sym("x", nx), ca.SX.sym("u_ext", 3), ca.SX.sym("p", npar)
    out = []
    kinds = [("torque", 3)] + ([("rates", ng)] if ng else [])
    for kind, ncmd in kinds:
        cmd = ca.SX.sym("cmd", ncmd)
        if model.cmg is None:
            act = ca.SX.zeros(0, 1)
            u = u_ext + cmd
        else:
            f_act = by_name["actuate" if kind == "torque" else "actuate_rates"]
            act = f_act(t, x, cmd if kind == "torque" else ca.vertcat(cmd, ca.SX.zeros(max(ng, 1) - ng)), p)
            u = ca.vertcat(u_ext, act[0 : model.nu_cmg])
        if model.has_steps:
            u = ca.vertcat(u, t + h / 2)  # the segment's time for the side of a rate step
        k1 = rhs(t, x, u, p)
        k2 = rhs(t + h / 2, x + h / 2 * k1, u, p)
        k3 = rhs(t + h / 2, x + h / 2 * k2, u, p)
        k4 = rhs(t + h, x + h * k3, u, p)
        x1 = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        y1 = by_name["meas"](t + h, x1, p)
        out.append(sx_function(f"tick_{kind}", [t, h, x, cmd, u_ext, p], [x1, y1, act]))
    return out


def build_system(structure: Structure, formulation, integrator) -> System:
    """Build (or fetch from the in-process cache) the compiled functions for a structure."""
    from .controller import measurement_layout

    form_cls = get_formulation(formulation)
    integ_cls = get_integrator(integrator)
    key = (form_cls, integ_cls, structure)
    if key in _SYSTEMS:
        return _SYSTEMS[key]
    t0 = time.perf_counter()
    model = StationModel(structure)
    form = form_cls(model)
    nx, npar, nu = form.nx, model.layout.size, model.nu
    t = ca.SX.sym("t")
    t2 = ca.SX.sym("t2")
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", npar)
    q = ca.SX.sym("q", 4)
    w = ca.SX.sym("w", 3)
    xe = ca.SX.sym("xe", model.n_extra + 2 * model.n_modes)
    rhs = sx_function("rhs", [t, x, u, p], [form.rhs(t, x, u, p)])
    arrays = form.arrays(t, x, p)
    outs = [form.omega(t, x, p), form.H_O_N(t, x, p), form.kinetic_energy(t, x, p)]
    for a in arrays:
        outs += list(a[3])
    cmg = model.cmg
    if cmg is not None:
        outs.append(model.h(x[7:], p))
        if cmg.kind != "ideal":
            pc = p[model.layout["cmg"]]
            outs.append(singularity_measure(cmg.A_hat(x[7 : 7 + cmg.nx], pc)))
    if structure.sun:
        outs += _track_errors(model, t, x, p)
    if model.n_modes:
        outs += [model.eta(x[7:]), form.modal_rates(t, x, p), form.strain_energy(t, x, p)]
    out = sx_function("out", [t, x, p], [ca.vertcat(*outs)])
    init = sx_function("init", [t, q, w, xe, p], [form.state(t, q, w, xe, p)])
    fs = [rhs, out, out.map("out_map", "serial", OUT_CHUNK, [2], []), init]
    if form.omega_is_state:
        fs.append(sx_function("jump", [t, t2, x, p], [form.jump(t, t2, x, p)]))
    # controller side: the measurement vector, and the actuation (steering law + limits)
    ng = 0 if cmg is None else cmg.n_gimbals
    lay = measurement_layout(ng, structure.n_app)
    wv = form.omega(t, x, p)
    meas = [x[0:4], wv, model.h(x[7:], p), x[7 : 7 + ng]]
    meas += [a[3][0] for a in arrays] + [a[3][1] for a in arrays]
    if structure.orbit:
        radius, incl, u0, n = (p[model.layout["orbit"]][i] for i in range(4))
        meas += [orbit_position_N(u0 + n * t, radius, incl), ca.reshape(model.C_ON(t, p).T, 9, 1)]
        meas.append(q_ON(u0 + n * t, incl))
    else:
        meas += [ca.DM.zeros(3), ca.reshape(ca.DM.eye(3), 9, 1), ca.DM([1.0, 0.0, 0.0, 0.0])]
    meas.append(p[model.layout["sun"]] if structure.sun else ca.DM.zeros(3))
    y = ca.vertcat(*meas)
    assert y.numel() == sum(k for _, k in lay.values())
    fs.append(sx_function("meas", [t, x, p], [y]))
    if cmg is not None:
        cmd = ca.SX.sym("cmd", 3)
        rates = ca.SX.sym("rates", max(ng, 1))
        pc = p[model.layout["cmg"]]
        xc = x[7 : 7 + cmg.nx]
        steered = cmg.actuate(t, xc, cmd, wv, pc)
        fs.append(sx_function("actuate", [t, x, cmd, p], [ca.vertcat(*steered)]))
        if ng:
            direct = cmg.actuate(t, xc, cmd, wv, pc, direct_rates=rates[0:ng])
            fs.append(sx_function("actuate_rates", [t, x, rates, p], [ca.vertcat(*direct)]))
    fs.append(sx_function("inertia", [t, x, p], [model.inertia(t, p, arrays)]))
    if integ_cls.name == "rk4":
        fs += _tick_functions(model, rhs, fs, nx, nu, npar, ng)
    fs += integ_cls.build(rhs, nx, nu, npar)
    tag = f"{form_cls.name}_{integ_cls.name}_{structure.key}"
    funcs = compile_functions(fs, tag, extra_c=integ_cls.extra_c)
    system = System(form, integ_cls, funcs, time.perf_counter() - t0, out.numel_out(0), {f.name(): f for f in fs})
    _SYSTEMS[key] = system
    return system


def from_lvlh(orbit, q_BO, omega_BO_B) -> tuple[np.ndarray, np.ndarray]:
    """``(q_BN, omega_BN_B)`` at t = 0 from an attitude and rate relative to LVLH."""
    C_BO = dcm(np.asarray(q_BO, dtype=float))
    q = quat_from_dcm(C_BO @ C_ON(orbit.u0, orbit.inclination))
    return q, np.asarray(omega_BO_B, dtype=float) + C_BO @ omega_ON_O(orbit.mean_motion)


def initial_state(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``(q_BN, omega_BN_B)`` at t = 0, converting from LVLH when ``initial.frame = 'lvlh'``."""
    q = np.array(scene.initial.q_BN, dtype=float)
    w = np.array(scene.initial.omega_BN_B, dtype=float)
    if scene.initial.frame == "lvlh":
        q, w = from_lvlh(scene.orbit, q, w)
    return q, w


def initial_x(system: System, scene: Scene, q_BN, omega_BN_B, p) -> np.ndarray:
    """The formulation's state at t = 0 with attitude ``q_BN``, rate ``omega_BN_B`` and the
    scene's extra states (CMG, sun-tracking joints)."""
    xe0 = system.formulation.model.initial_extra(scene, q_BN, p)
    init = FastCall.of(system.funcs["init"])
    init.args[0][0] = 0.0
    init.args[1][:] = q_BN
    init.args[2][:] = omega_BN_B
    init.args[3][:] = xe0
    init.args[4][:] = p
    init()
    return init.res[0].copy()


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
            if pr.tracked:
                rates.append(pr.max_rate)
            else:
                rates.append(abs(pr.rate) + abs(pr.amp * pr.freq) + sum(abs(st.delta) for st in pr.rate_step))
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


def _breakpoints(scene: Scene, duration: float) -> tuple[list[float], set[float]]:
    """Times where the scene is discontinuous, and the subset where array rates step (impulses)."""
    bps, steps = set(), set()
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque):
            for b in (trq.start, trq.stop):
                if 0.0 < b < duration:
                    bps.add(float(b))
    for a in scene.appendage:
        for j in (a.alpha, a.beta):
            if not j.tracked:
                for st in j.rate_step:
                    if st.t < duration:
                        bps.add(float(st.t))
                        steps.add(float(st.t))
    return sorted(bps), steps


def _held_torque(scene: Scene, t_mid: float) -> np.ndarray:
    u = np.zeros(3)
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque) and trq.start <= t_mid < trq.stop:
            u += np.array(trq.torque_B)
    return u


def segment_input(scene: Scene, model: StationModel, a: float, b: float, u: np.ndarray) -> None:
    """Set the held input of the smooth segment [a, b] in place: the external torque held over it
    and, when the scene has array rate steps, the segment's time that decides their side."""
    t_mid = 0.5 * (a + b)
    u[0:3] = _held_torque(scene, t_mid)
    if model.has_steps:
        u[-1] = t_mid


def trajectory_columns(scene: Scene) -> list[str]:
    """The CSV columns of a run of ``scene`` (DESIGN §6 core, then CMG, controller, sun)."""
    from .cmg import CmgModel

    cols = base_columns(scene.appendage_names)
    c = scene.cmg
    if c is not None:
        cols += ["hx", "hy", "hz"]
        names = CmgModel(c.kind, c.n_units, c.steering).gimbal_names
        cols += names + [f"{n}_rate" for n in names]
        if c.kind != "ideal":
            cols.append("cmg_singularity")
        cols.append("cmg_saturated")
    if scene.controller is not None:
        cols += ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg"]
    if scene.sun is not None:
        cols += [f"track_err_deg_{n}" for n in scene.appendage_names]
    modes = [(a.name, k + 1) for a in scene.appendage for k in range(len(a.mode))]
    if modes:
        cols += [f"eta_{n}_{k}" for n, k in modes] + [f"etadot_{n}_{k}" for n, k in modes] + ["U_strain"]
    return cols


class _Rows:
    """Turns states into output rows (compiled outputs + the loop's held values) and streams them."""

    def __init__(self, scene, system, p, sink):
        f = system.funcs
        self.form = system.formulation
        self.nx = self.form.nx
        self.n_out = system.n_out
        self.out = FastCall.of(f["out_map"])
        self.out.args[2][:] = p
        self.columns = trajectory_columns(scene)
        self.scene = scene
        self.sink = sink
        self.rows: list[np.ndarray] = []
        n_app = len(scene.appendage)
        cmg = self.form.model.cmg
        self.ng = 0 if cmg is None else cmg.n_gimbals
        self.has_cmg = cmg is not None
        # compiled output layout: w(3) HN(3) T(1) angles(2 n_app) [h(3) [m]] [track errs]
        self.k_h = 7 + 2 * n_app
        self.k_m = self.k_h + 3
        self.gimbaled = cmg is not None and cmg.kind != "ideal"
        self.k_track = self.k_m + (1 if self.gimbaled else 0) if cmg is not None else 7 + 2 * n_app
        self.has_sun = scene.sun is not None
        self.has_ctrl = scene.controller is not None
        # modal outputs (eta, etadot, U_strain) close the compiled row
        self.n_flex = 2 * self.form.model.n_modes + 1 if self.form.model.n_modes else 0

    def make(self, ts, xs, held=None) -> np.ndarray:
        """Rows for times ``ts`` and states ``xs``; ``held`` (k, m) are the loop's values per row:
        gimbal rates, cmg_saturated, tau_cmd(3), att_err_deg (those that apply)."""
        ts = np.asarray(ts, dtype=float)
        xs = np.asarray(xs, dtype=float).reshape(len(ts), self.nx)
        comp = np.empty((len(ts), self.n_out))
        o = self.out
        for k in range(0, len(ts), OUT_CHUNK):
            n = min(OUT_CHUNK, len(ts) - k)
            o.args[0][:n] = ts[k : k + n]
            o.args[1].reshape(OUT_CHUNK, self.nx)[:n] = xs[k : k + n]
            o()
            comp[k : k + n] = o.res[0].reshape(OUT_CHUNK, self.n_out)[:n]
        parts = [ts[:, None], xs[:, :4] / np.linalg.norm(xs[:, :4], axis=1, keepdims=True), comp[:, : self.k_h]]
        held = np.zeros((len(ts), 0)) if held is None else np.asarray(held, dtype=float).reshape(len(ts), -1)
        j = 0
        if self.has_cmg:
            parts.append(comp[:, self.k_h : self.k_h + 3])
            parts.append(xs[:, 7 : 7 + self.ng])
            rates = held[:, j : j + self.ng] if held.shape[1] else np.zeros((len(ts), self.ng))
            parts.append(rates)
            if self.gimbaled:
                parts.append(comp[:, self.k_m : self.k_m + 1])
            parts.append(held[:, j + self.ng : j + self.ng + 1] if held.shape[1] else np.zeros((len(ts), 1)))
            j += self.ng + 1
        if self.has_ctrl:
            parts.append(held[:, j : j + 4])
            j += 4
        if self.has_sun:
            parts.append(np.rad2deg(comp[:, self.k_track : self.n_out - self.n_flex]))
        if self.n_flex:
            parts.append(comp[:, self.n_out - self.n_flex :])
        return np.hstack(parts)

    def emit(self, rows: np.ndarray) -> None:
        if len(rows):
            self.rows.append(rows)
            if self.sink is not None:
                self.sink.write(rows)

    def trajectory(self, meta) -> Trajectory:
        data = np.vstack(self.rows) if self.rows else np.zeros((0, len(self.columns)))
        return Trajectory(self.columns, data, meta)


def _check_rows(rows: np.ndarray, emit) -> None:
    """Emit the finite rows; raise at the first non-finite one."""
    bad = ~np.all(np.isfinite(rows), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        emit(rows[:i])
        raise IntegrationError(rows[i, 0], "outputs are not finite (NaN or inf)")
    emit(rows)


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
    controller=None,
    fused: bool = True,
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
    controller : Controller, optional
        A controller instance to use instead of the scene's ``[controller]`` (which the scene
        must still have, for its period and sensor).
    fused : bool
        Run controller and dynamics in one compiled loop when the controller offers a symbolic
        form and the scene allows it (RK4 at one step per period, no discontinuity, no sensor
        errors); ``False`` always calls the Python ``_update`` every tick. Same numbers.

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
    model = form.model
    p = model.params(scene)
    nx = form.nx
    q0, w0 = initial_state(scene)
    rate_scale, momentum_scale = characteristic_scales(scene, w0, model, p)
    atol_vec = form.atol_vector(atol, rate_scale, momentum_scale)
    integ = system.integrator_cls(funcs, p, nx, rtol=rtol, atol=atol_vec, step=step, max_step=sim.max_step)
    x = initial_x(system, scene, q0, w0, p)

    rows = _Rows(scene, system, p, sink)
    bps, steps = _breakpoints(scene, duration)
    jump = FastCall.of(funcs["jump"]) if (form.omega_is_state and steps and sim.impulse_jump) else None
    meta = {
        "scene": scene.name,
        "formulation": form.name,
        "integrator": system.integrator_cls.name,
        "rtol": rtol,
        "atol": atol,
        "build_s": system.build_s,
    }

    def apply_jump(t, x):
        if jump is None or t not in steps:
            return x
        a = jump.args
        a[0][0] = t * (1.0 - 1e-15) - 1e-300  # just before the step
        a[1][0] = t
        a[2][:] = x
        a[3][:] = p
        jump()
        return jump.res[0].copy()

    wall0 = time.perf_counter()
    if scene.controller is not None:
        loop = _ControlLoop(scene, system, integ, p, x, rows, duration, output_dt, bps, apply_jump, controller, fused)
        try:
            loop.run()
        except (IntegrationError, _ControllerFailure) as e:
            meta.update(status="failed", stopped_at=e.t, summary=loop.summary())
            raise SimulationError(e.t, e.reason, rows.trajectory(meta)) from None
        meta.update(status="ok", wall_s=time.perf_counter() - wall0, n_rhs=integ.n_rhs, n_steps=integ.n_steps)
        meta["summary"] = loop.summary()
        return rows.trajectory(meta)

    t_out = _output_times(duration, output_dt)
    edges = sorted(set([0.0, duration] + bps))
    u = np.zeros(model.nu)
    rows.emit(rows.make([0.0], [x]))
    try:
        for a, b in zip(edges[:-1], edges[1:]):
            inner = t_out[(t_out > a) & (t_out < b)]
            ts = np.concatenate([[a], inner, [b]])
            segment_input(scene, model, a, b, u)
            try:
                xs = integ.integrate(ts, x, u)
            except IntegrationError as e:
                if e.partial is not None and len(e.partial) > 1:
                    ts_done = ts[1 : len(e.partial)]
                    keep = np.isin(ts_done, t_out)
                    rows.emit(rows.make(ts_done[keep], e.partial[1:][keep]))
                raise
            x = apply_jump(b, xs[-1].copy())  # an array rate step at b: the state just after it
            xs[-1] = x
            keep = np.isin(ts[1:], t_out)
            _check_rows(rows.make(ts[1:][keep], xs[1:][keep]), rows.emit)
    except IntegrationError as e:
        meta.update(status="failed", stopped_at=e.t)
        raise SimulationError(e.t, e.reason, rows.trajectory(meta)) from None
    meta.update(
        status="ok",
        wall_s=time.perf_counter() - wall0,
        n_rhs=integ.n_rhs,
        n_steps=integ.n_steps,
    )
    return rows.trajectory(meta)


class _ControllerFailure(Exception):
    def __init__(self, t: float, reason: str):
        super().__init__(reason)
        self.t = t
        self.reason = reason


#: rows collected before they are streamed to the sink in the closed loop
ROW_BATCH = 64


class _ControlLoop:
    """Sense -> control (integer ticks, zero-order hold) -> actuate -> integrate -> record.

    One integrator call per period (split only at scene discontinuities inside it); the
    integrator keeps its memory (step size) across periods, so nothing restarts per tick.
    """

    def __init__(self, scene, system, integ, p, x, rows, duration, output_dt, bps, apply_jump, controller, fused):
        from .cmg import cluster_functions
        from .controller import Measurement, Plant, get_controller, measurement_layout

        spec = scene.controller
        self.system, self.fused, self.used_fused = system, fused, False
        self.scene, self.integ, self.p, self.x, self.rows = scene, integ, p, x, rows
        self.duration, self.bps, self.apply_jump = duration, bps, apply_jump
        self.period = spec.period
        self.n_per_out = int(round(output_dt / spec.period))
        f = system.funcs
        model = system.formulation.model
        self.model = model
        cmg = model.cmg
        self.ng = 0 if cmg is None else cmg.n_gimbals
        self.ctrl = controller if controller is not None else get_controller(spec.name)(period=spec.period, **spec.params)
        if self.ctrl.command == "gimbal_rates" and self.ng == 0:
            raise ValueError(
                f"controller '{self.ctrl.name}' commands gimbal rates: the scene needs a gimballed [cmg]"
            )
        inertia = FastCall.of(f["inertia"])
        inertia.args[0][0] = 0.0
        inertia.args[1][:] = x
        inertia.args[2][:] = p
        inertia()
        c = scene.cmg
        plant = Plant(
            scene=scene,
            inertia_O_B=inertia.res[0].reshape(3, 3).T.copy(),
            mean_motion=None if scene.orbit is None else scene.orbit.mean_motion,
            period=self.period,
        )
        if c is not None:
            plant.cmg_kind = c.kind
            plant.h_capacity = capacity(c)
            plant.max_torque = c.max_torque or math.inf if c.kind == "ideal" else math.inf
            plant.n_gimbals = self.ng
            plant.max_gimbal_rate = c.max_gimbal_rate if self.ng else math.inf
            plant.h_rotor = c.h_rotor if self.ng else 0.0
            plant.cmg_functions = cluster_functions(c)
        self.capacity = plant.h_capacity
        self.ctrl.reset(plant)
        # measurement: compiled, written into y; the controller sees views of y (or of a noisy,
        # delayed copy)
        self.meas = FastCall.of(f["meas"])
        self.meas.args[2][:] = p
        self.layout = measurement_layout(self.ng, len(scene.appendage))
        sensor = spec.sensor
        self.noisy = sensor.attitude_noise > 0 or sensor.rate_noise > 0 or sensor.delay > 0
        if self.noisy:
            self.delay = int(round(sensor.delay / self.period))
            self.history = np.zeros((self.delay + 1, self.meas.res[0].size))
            self.rng = np.random.default_rng(sensor.seed)
            self.seen = np.zeros(self.meas.res[0].size)
            self.M = Measurement(self.seen, self.layout)
        else:
            self.M = Measurement(self.meas.res[0], self.layout)
        self.sensor = sensor
        self.act = None
        if cmg is not None:
            name = "actuate_rates" if self.ctrl.command == "gimbal_rates" else "actuate"
            self.act = FastCall.of(f[name])
            self.act.args[3][:] = p
        self.u = np.zeros(model.nu)
        self.nu_cmg = model.nu_cmg
        self.n_cmd = self.ng if self.ctrl.command == "gimbal_rates" else 3
        self.last_cmd = (0.0, 0.0, 0.0)
        self.meas_out = None  # where the fused tick writes y, when the controller reads it there
        self.u_ext = None  # the fused tick's held-torque input, when the loop has a fused tick
        self.n_slow = 0  # periods integrated by the generic path
        self.ticks = 0
        self.n_rate_limited = 0
        self.n_momentum_saturated = 0

    # -- one tick ------------------------------------------------------------------------
    def _sense(self, k: int, t: float) -> None:
        m = self.meas
        m.args[0][0] = t
        m.args[1][:] = self.x
        m()
        self.n_slow += 1 if k > 0 else 0
        if self.meas_out is not None:
            self.meas_out[:] = m.res[0]
        self.M.t = t
        if self.noisy:
            self._corrupt(k)

    def _corrupt(self, k: int) -> None:
        y = self.meas.res[0]
        slot = k % (self.delay + 1)
        if k == 0:
            self.history[:] = y
        self.history[slot] = y
        self.seen[:] = self.history[(k - self.delay) % (self.delay + 1)] if k >= self.delay else self.history[0]
        s = self.sensor
        if s.attitude_noise > 0:
            o = self.layout["q_BN"][0]
            q = self.seen[o : o + 4]
            d = 0.5 * self.rng.normal(0.0, s.attitude_noise, 3)
            qn = np.array(
                [
                    q[0] - q[1] * d[0] - q[2] * d[1] - q[3] * d[2],
                    q[1] + q[0] * d[0] + q[2] * d[2] - q[3] * d[1],
                    q[2] + q[0] * d[1] + q[3] * d[0] - q[1] * d[2],
                    q[3] + q[0] * d[2] + q[1] * d[1] - q[2] * d[0],
                ]
            )
            q[:] = qn / np.linalg.norm(qn)
        if s.rate_noise > 0:
            o = self.layout["omega_BN_B"][0]
            self.seen[o : o + 3] += self.rng.normal(0.0, s.rate_noise, 3)

    def _actuate(self, t: float, cmd, count: bool = True) -> int:
        """Set the held input from the command; returns the saturation flag (0/1)."""
        if self.act is None:  # no cluster: the torque request acts directly (ideal torquer)
            return 0
        a = self.act
        a.args[0][0] = t
        a.args[1][:] = self.x
        a.args[2][: self.n_cmd] = cmd
        a()
        return self._flags(a.res[0], count)

    def _advance(self, t0: float, t1: float, cmd) -> None:
        """Generic path: one integrator call per period, split at discontinuities inside it."""
        inner = [b for b in self.bps if t0 < b < t1]
        edges = [t0] + inner + [t1]
        for a, b in zip(edges[:-1], edges[1:]):
            segment_input(self.scene, self.model, a, b, self.u)
            if self.u_ext is not None:
                self.u_ext[:] = self.u[0:3]  # the fused tick's copy of the held torque
            u = self.u.copy()
            if self.act is None:
                u[0:3] += cmd
            # an array rate step at b: continue from the state just after it
            self.x[:] = self.apply_jump(b, self.integ.advance(a, b, self.x, u))

    def _held_row(self, sat_flag: int):
        vals = []
        if self.model.cmg is not None:
            vals += list(self.u[3 : 3 + self.ng]) if self.ng else []
            vals.append(float(sat_flag))
        q_ref = self.ctrl.q_ref_BN
        if q_ref is None:
            err = math.nan
        else:
            err = math.degrees(float(rotation_angle(np.asarray(q_ref, float)[None], self.x[None, 0:4])[0]))
        tau = self.last_cmd if self.ctrl.command == "torque" else (math.nan,) * 3
        vals += list(tau) + [err]
        return vals

    def run(self) -> None:
        period, duration = self.period, self.duration
        K = max(1, math.ceil(duration / period - 1e-9))
        if self.fused:
            from ._fused import fused_ok, run_fused

            if fused_ok(self):
                return run_fused(self, K)
        pending_t, pending_x, pending_h = [], [], []
        sat_since_row = 0

        def flush():
            if pending_t:
                rows = self.rows.make(pending_t, pending_x, pending_h)
                pending_t.clear(), pending_x.clear(), pending_h.clear()
                _check_rows(rows[:, :12], lambda ok: self.rows.emit(rows[: len(ok)]))

        tick = self._fast_tick()
        bps = [b for b in self.bps if 0.0 < b < duration]
        ib = 0  # next breakpoint
        self.u[0:3] = _held_torque(self.scene, 0.5 * period)
        if tick is not None:
            self.u_ext[:] = self.u[0:3]
            fc, xin, res_x, res_y, res_act = tick
            a_t, a_h, a_cmd = fc.args[0], fc.args[1], fc.args[3]
        # the loop checks commands and counts updates itself (Controller.update's job) so the
        # hot path makes one Python call per tick into the controller
        update, ctrl, n_per_out = self.ctrl._update, self.ctrl, self.n_per_out
        nu = self.nu_cmg
        i_lim, i_sat = nu + 1, nu + 2
        has_act = self.act is not None
        ncmd = self.n_cmd
        noisy = self.noisy
        M = self.M
        ticks = 0
        h_set = -1.0
        next_bp = bps[0] if bps else math.inf
        fast = tick is not None
        if fast:
            trigger = fc._trigger  # FastCall's bound buffer trigger: one C call, no wrapper
        try:
            self._sense(0, 0.0)
            for k in range(K + 1):
                t = k * period  # integer tick clock: no accumulated drift
                if k == K:
                    t = duration
                M.t = t
                try:
                    cmd = update(t, M)
                except Exception as e:  # the user's code: report it, keep the trajectory
                    raise _ControllerFailure(t, f"controller '{ctrl.name}' raised {type(e).__name__}: {e}") from None
                t_next = (k + 1) * period
                if t_next > duration:
                    t_next = duration
                smooth = fast and k < K and next_bp > t_next  # a step at t_next needs the jump
                if smooth:  # fused: actuate + one RK4 step + measure, one compiled call
                    a_t[0] = t
                    if t_next - t != h_set:
                        h_set = t_next - t
                        a_h[0] = h_set
                    if cmd is None or len(cmd) != ncmd:
                        self._check_command(t, cmd)
                    a_cmd[:] = cmd
                    trigger()
                    if has_act and (res_act[i_lim] or res_act[i_sat]):
                        sat_since_row |= self._flags(res_act)
                else:
                    self._check_command(t, cmd)
                    # the final tick's actuation is reported in its row but never integrated:
                    # it is not counted in the summary
                    sat_since_row |= self._actuate(t, cmd, count=k < K)
                if k % n_per_out == 0 or k == K:
                    if len(cmd) == 3:
                        self.last_cmd = cmd
                    if smooth and has_act:
                        self.u[3 : 3 + nu] = res_act[:nu]  # the row's held rates (flags counted above)
                    pending_t.append(t)
                    pending_x.append(self.x.copy())
                    pending_h.append(self._held_row(sat_since_row))
                    sat_since_row = 0
                    if len(pending_t) >= ROW_BATCH:
                        flush()
                if k == K:
                    break
                ticks += 1
                if smooth:
                    v = res_x[4]
                    if not -1e300 < v < 1e300:
                        self.ticks = ticks
                        self._check_command(t, cmd)
                        raise IntegrationError(t_next, "state is not finite (NaN or inf)")
                    xin[:] = res_x
                    if noisy:
                        self.meas.res[0][:] = res_y
                        self._corrupt(k + 1)
                else:
                    self.ticks = ticks
                    while ib < len(bps) and bps[ib] <= t_next:
                        ib += 1
                    next_bp = bps[ib] if ib < len(bps) else math.inf
                    self._advance(t, t_next, cmd)
                    self._sense(k + 1, t_next)
        finally:
            self.ticks = ticks
            ctrl.n_updates += ticks + 1
            if tick is not None:
                n_fast = self.ticks - self.n_slow
                self.integ.n_rhs += 4 * n_fast
                self.integ.n_steps += n_fast
            flush()

    def _check_command(self, t: float, cmd) -> None:
        """A clear error for a command of the wrong size or with NaN/inf (generic path, or after
        the fused path met a non-finite state)."""
        name = self.ctrl.name
        try:
            n = len(cmd)
            total = sum(float(c) for c in cmd)
        except TypeError:
            raise _ControllerFailure(t, f"controller '{name}' returned {cmd!r}, not a sequence") from None
        if n != self.n_cmd:
            raise _ControllerFailure(
                t, f"controller '{name}' returned {n} values, expected {self.n_cmd} ({self.ctrl.command})"
            )
        if not math.isfinite(total):
            raise _ControllerFailure(t, f"controller '{name}' returned a non-finite command {list(cmd)}")

    def _fast_tick(self):
        """The fused tick when the integrator is RK4 with one step per period, else None."""
        from .controller import Measurement

        integ = self.integ
        f = integ.funcs
        name = "tick_rates" if self.ctrl.command == "gimbal_rates" else "tick_torque"
        if getattr(integ, "name", "") != "rk4" or name not in f:
            return None
        if math.ceil(self.period / integ.h_nominal - 1e-9) != 1:
            return None
        fc = FastCall.of(f[name])
        fc.args[5][:] = self.p
        fc.args[2][:] = self.x
        self.x = fc.args[2]  # the loop's state lives in the tick's input buffer
        self.u_ext = fc.args[4]
        if not self.noisy:  # the controller reads the tick's output directly (no copy)
            self.meas_out = fc.res[1]
            self.M = Measurement(self.meas_out, self.layout)
        return fc, fc.args[2], fc.res[0], fc.res[1], fc.res[2]

    def _flags(self, r, count: bool = True) -> int:
        if self.act is None:
            return 0
        nu = self.nu_cmg
        self.u[3 : 3 + nu] = r[:nu]
        lim, sat = r[nu + 1] > 0.5, r[nu + 2] > 0.5
        if count:
            self.n_rate_limited += lim
            self.n_momentum_saturated += sat
        return int(lim or sat)

    def summary(self) -> dict:
        rows = self.rows
        out = {
            "controller": self.ctrl.name,
            "fused": self.used_fused,
            "period_s": self.period,
            "ticks": self.ticks,
            "controller_updates": self.ctrl.n_updates,
        }
        traj = rows.trajectory({}) if rows.rows else None
        if self.model.cmg is not None:
            out["rate_limited_ticks"] = int(self.n_rate_limited)
            out["momentum_saturated_ticks"] = int(self.n_momentum_saturated)
            if traj is not None:
                h = np.linalg.norm(traj.cols("hx", "hy", "hz"), axis=1)
                out["max_h_Nms"] = float(h.max())
                if math.isfinite(self.capacity):
                    out["max_h_fraction"] = float(h.max() / self.capacity)
                if "cmg_singularity" in traj.columns:
                    out["min_singularity"] = float(traj["cmg_singularity"].min())
        if traj is not None:
            err = traj["att_err_deg"]
            if np.isfinite(err).any():
                out["final_att_err_deg"] = float(err[-1])
                out["max_att_err_deg"] = float(np.nanmax(err))
        out.update(self.ctrl.summary())
        return out
