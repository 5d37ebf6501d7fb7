"""The run: scene -> model -> formulation -> compiled functions -> integrator -> Trajectory.

The run is cut into *segments* at every discontinuity of the scene (torque-window edges); the
integrator advances each segment with the held input constant and lands exactly on every
output time, one window of at most :data:`~.rows.ROW_BATCH` output times per call (fewer when
a call takes longer than :data:`~.rows.FLUSH_S`), the steps running on across windows, so the
numbers do not depend on the windows. Rows stream to an optional sink a window at a time, so a
run that fails or is killed keeps everything up to the window in progress
(:class:`SimulationError` carries the partial trajectory and the time it stopped), and a run
that does not keep its rows (``keep=False``) holds one window in memory. A scene with a
``[controller]`` runs the closed loop (:mod:`.closed_loop`).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..core import progress
from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..scene import Scene, load_scene
from .closed_loop import ControlLoop, ControllerFailure
from .controller import Controller
from .prepare import prepare
from .rate_auto import set_runner
from .rows import FLUSH_S, ROW_BATCH, Rows, SinkError, check_rows
from .segments import OutputTimes, breakpoints, segment_input, smooth_cuts
from .trajectory import Trajectory

__all__ = ["simulate", "SimulationError", "SinkError"]


class SimulationError(RuntimeError):
    """A run that failed part-way; ``trajectory`` holds the rows computed before ``t``.

    When a controller raised, its exception is ``__cause__`` (with the controller's frames in
    its ``__traceback__``): ``traceback.print_exception(err)`` shows both."""

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
    keep: bool = True,
    pace=None,
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
        Receives each batch of output rows (ndarray (k, columns), k <= ``ROW_BATCH``) as soon
        as it is made. Open loop: a window's rows when its integrator call returns, so a
        failure, Ctrl-C or kill loses at most the window in progress (``ROW_BATCH`` rows, or
        about ``FLUSH_S`` of work). Closed loop: batches of ``ROW_BATCH`` rows or ``FLUSH_S``;
        a :class:`SimulationError` or ``KeyboardInterrupt`` hands over the rest first, a kill
        loses at most one batch.
    controller : Controller, optional
        A controller instance to use instead of the law named in the scene's ``[controller]``
        table; the scene must still have that table, for the period and the sensor (a scene
        without one is refused, never run open loop).
    fused : bool
        Run controller and dynamics in one compiled loop when the controller offers a symbolic
        form and the scene allows it (RK4 at one step per period, no discontinuity, no sensor
        errors); ``False`` always calls the Python ``_update`` every tick. Same numbers.
    keep : bool
        Keep every row in the returned trajectory (and the failed run's). ``False`` (for a
        sink that takes them, e.g. a run of millions of rows): memory stays bounded, the
        trajectory holds the last row only; ``meta["n_rows"]`` counts the rows either way and
        the closed loop's ``meta["summary"]`` is computed over all of them.
    pace : Pacer, optional
        Pace the run to the wall clock (:class:`~.pacing.Pacer`, ``run --realtime``): the
        per-tick executor waits for every tick's deadline, every executor hands each row over
        at its deadline. The numbers are the unpaced run's; ``meta["realtime"]`` (and the closed
        loop's summary) records the factor achieved, the deadline misses and the lateness.

    Raises
    ------
    SimulationError
        The run failed part-way; ``.trajectory`` has the rows up to ``.t``. A controller that
        raised or returned a bad command is one (its exception is the ``__cause__``).
    TypeError
        ``controller`` is not a :class:`Controller` instance.
    ValueError
        ``controller`` given for a scene without a ``[controller]`` table; bad overrides.
    SinkError
        The sink could not take a batch (e.g. the disk is full); an ``OSError`` whose message
        names the file and the time of the last complete row in it.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if controller is not None:
        _check_controller_argument(scene, controller)
    sim = scene.simulation
    formulation = formulation or sim.formulation
    integrator = integrator or sim.integrator
    rtol = sim.rtol if rtol is None else rtol
    atol = sim.atol if atol is None else atol
    duration = sim.duration if duration is None else duration
    output_dt = sim.output_dt if output_dt is None else output_dt
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")

    run = prepare(scene, formulation, integrator, rtol=rtol, atol=atol, step=step)
    system, p, integ, x = run.system, run.p, run.integrator, run.x0
    form, funcs = system.formulation, system.funcs
    model = form.model

    rows = Rows(scene, system, p, sink, keep)
    rows.clock = pace
    with progress.task(f"run {scene.name}", total=duration, unit="s") as bar:
        rows.progress = bar  # updated with the time of every batch of rows handed over
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
            if pace is not None and hasattr(loop.ctrl, "paced_by"):  # a socket law's late replies (socket_law.py)
                loop.ctrl.paced_by(pace)
            try:
                try:
                    loop.run()
                finally:
                    if hasattr(loop.ctrl, "end_run"):  # a law in another process: END, the connection closed
                        loop.ctrl.end_run()
            except (IntegrationError, ControllerFailure) as e:
                meta.update(status="failed", stopped_at=e.t, summary=_paced(loop.summary(), pace))
                # the controller's own exception, if it raised, stays chained for the API user and
                # the CLI's STATIONBED_DEBUG traceback; the loop's internals are not
                raise SimulationError(e.t, e.reason, rows.trajectory(meta)) from e.__cause__
            meta.update(status="ok", wall_s=time.perf_counter() - wall0, n_rhs=integ.n_rhs, n_steps=integ.n_steps)
            meta["summary"] = _paced(loop.summary(), pace)
            return rows.trajectory(meta)

        clock = OutputTimes(duration, output_dt)
        edges = sorted(set([0.0, duration] + bps + smooth_cuts(scene, duration, system.integrator_cls)))
        u = np.zeros(model.nu)
        rows.emit(rows.make([0.0], [x]))
        n_win = 1  # output times per integrator call: up to ROW_BATCH, fewer when calls take long
        try:
            for a, b in zip(edges[:-1], edges[1:]):
                segment_input(scene, model, a, b, u)
                k, k_end = clock.first_after(a), clock.first_after(b, strict=False)  # times inside (a, b)
                b_is_output = clock.time(k_end) == b
                integ.begin_segment(a, b, x, u)
                while True:  # windows of the output times inside, the last one closed by b
                    k1 = min(k + n_win, k_end)
                    ts = clock.times(k, k1)
                    last = k1 == k_end
                    if last:
                        ts = np.append(ts, b)
                    wall = time.perf_counter()
                    try:
                        xs = integ.continue_segment(ts)
                    except IntegrationError as e:
                        n_done = 0 if e.partial is None else len(e.partial)
                        n_out = min(n_done, k1 - k) + (n_done > k1 - k and b_is_output)
                        if n_out:
                            rows.emit(rows.make(ts[:n_out], e.partial[:n_out]))
                        raise
                    n_win = max(1, min(ROW_BATCH, int(FLUSH_S * len(ts) / max(time.perf_counter() - wall, 1e-9))))
                    if last:
                        x = apply_jump(b, xs[-1].copy())  # an array rate step at b: the state just after it
                        xs[-1] = x
                        if not b_is_output:
                            ts, xs = ts[:-1], xs[:-1]
                    if len(ts):
                        check_rows(rows.make(ts, xs), rows.emit)
                    k = k1
                    if last:
                        break
        except IntegrationError as e:
            meta.update(status="failed", stopped_at=e.t)
            raise SimulationError(e.t, e.reason, rows.trajectory(meta)) from None
        meta.update(
            status="ok",
            wall_s=time.perf_counter() - wall0,
            n_rhs=integ.n_rhs,
            n_steps=integ.n_steps,
        )
        if pace is not None:
            meta["realtime"] = pace.summary()
        return rows.trajectory(meta)


def _paced(summary: dict, pace) -> dict:
    """The closed loop's summary, with the pacing's figures (:meth:`~.pacing.Pacer.summary`)."""
    if pace is not None:
        summary.update(pace.summary())
    return summary


def _check_controller_argument(scene: Scene, controller) -> None:
    """Refuse a ``controller=`` that would be ignored or misused: not an instance, or a scene
    without a ``[controller]`` table (which gives the period and the sensor)."""
    if not isinstance(controller, Controller):
        if isinstance(controller, type) and issubclass(controller, Controller):
            raise TypeError(
                f"simulate(controller=...) takes a Controller instance, got the class {controller.__name__}: "
                f"pass {controller.__name__}(...)"
            )
        raise TypeError(
            f"simulate(controller=...) takes a Controller instance, got {type(controller).__name__}; "
            "to choose a law by name, set the scene's controller.name"
        )
    if scene.controller is None:
        raise ValueError(
            f"simulate(controller={controller.name or type(controller).__name__!r}): scene {scene.name!r} has no "
            "[controller] table; add one (name, period, optional sensor): the object replaces the law it "
            "names, the table gives the period and the sensor"
        )


set_runner(simulate)  # the environment-rate probe's runner (run/rate_auto.py: it may not import this module)
