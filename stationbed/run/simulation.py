"""The run: scene -> model -> formulation -> compiled functions -> integrator -> Trajectory.

The run is cut into *segments* at every discontinuity of the scene (torque-window edges); the
integrator advances each segment with the held input constant and lands exactly on every
output time. Rows stream to an optional sink as they are computed, so a run that fails keeps
everything up to the failure (:class:`SimulationError` carries the partial trajectory and
the time it stopped). A scene with a ``[controller]`` runs the closed loop (:mod:`.closed_loop`).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..scene import Scene, load_scene
from .closed_loop import ControlLoop, ControllerFailure
from .prepare import prepare
from .rows import Rows, check_rows
from .segments import breakpoints, output_times, segment_input
from .trajectory import Trajectory

__all__ = ["simulate", "SimulationError"]


class SimulationError(RuntimeError):
    """A run that failed part-way; ``trajectory`` holds the rows computed before ``t``."""

    def __init__(self, t: float, reason: str, trajectory: Trajectory):
        super().__init__(f"run stopped at t = {t:.6g} s: {reason}")
        self.t = t
        self.reason = reason
        self.trajectory = trajectory


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

    run = prepare(scene, formulation, integrator, rtol=rtol, atol=atol, step=step)
    system, p, integ, x = run.system, run.p, run.integrator, run.x0
    form, funcs = system.formulation, system.funcs
    model = form.model

    rows = Rows(scene, system, p, sink)
    bps, steps = breakpoints(scene, duration)
    jump = FastCall.of(funcs["jump"]) if (form.omega_is_state and steps and sim.impulse_jump) else None
    meta = {
        "scene": scene.name,
        "formulation": form.name,
        "integrator": system.integrator_cls.name,
        "rtol": rtol,
        "atol": atol,
        "build_s": system.build_s,
        "evaluator": system.evaluator,
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
        loop = ControlLoop(scene, system, integ, p, x, rows, duration, output_dt, bps, apply_jump, controller, fused)
        try:
            loop.run()
        except (IntegrationError, ControllerFailure) as e:
            meta.update(status="failed", stopped_at=e.t, summary=loop.summary())
            raise SimulationError(e.t, e.reason, rows.trajectory(meta)) from None
        meta.update(status="ok", wall_s=time.perf_counter() - wall0, n_rhs=integ.n_rhs, n_steps=integ.n_steps)
        meta["summary"] = loop.summary()
        return rows.trajectory(meta)

    t_out = output_times(duration, output_dt)
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
            check_rows(rows.make(ts[1:][keep], xs[1:][keep]), rows.emit)
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
