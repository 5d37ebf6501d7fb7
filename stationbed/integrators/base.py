"""The integrator interface (DESIGN §7, modelled on scipy's ``OdeSolver``): :class:`Integrator`
and :class:`IntegrationError`.

An :class:`Integrator` advances a state across one *smooth segment*: an interval over which the
held input ``u`` is constant and the scene has no discontinuity (the simulation loop splits
the run at torque-window edges and control ticks, so discontinuities are integrated across
exactly, by stopping at them). Within a segment it must land exactly on each requested time.
"""

from __future__ import annotations

import math
from typing import ClassVar

import casadi as ca
import numpy as np

from ..core.compile import FastCall

__all__ = ["Integrator", "IntegrationError"]


class IntegrationError(RuntimeError):
    """The integrator could not continue.

    Parameters
    ----------
    t : float
        Time where it stopped [s].
    reason : str
        Why (step-size underflow, non-finite state, an inner iteration that did not converge).
    partial : ndarray, shape (k, nx), optional
        The rows already integrated in the current segment (states at its first ``k``
        requested times).
    """

    def __init__(self, t: float, reason: str, partial: np.ndarray | None = None):
        super().__init__(f"integration stopped at t = {t:.6g} s: {reason}")
        self.t = t
        self.reason = reason
        self.partial = partial


class Integrator:
    """Base class of the steppers. Rules for implementers:

    1. Set ``name`` (the registry key), ``order`` and ``adaptive``.
    2. ``build(rhs, nx, nu, npar)`` (classmethod) returns the casadi Functions the integrator
       wants compiled (they are compiled once per model structure together with the RHS);
       ``rhs`` is ``f(t, x, u, p) -> xdot``. ``extra_c`` is C source appended to the generated
       code (a driver calling the built functions by name).
    3. ``_integrate(ts, x0, u)`` returns the states at every time of ``ts`` (``ts[0]`` is the
       start, ``x0`` the state there) as an array ``(len(ts), nx)``; it adds the RHS
       evaluations it made to ``self.n_rhs`` and accepted steps to ``self.n_steps``.
    4. It may keep memory between calls (step size) - segments follow each other in time.
    5. ``fusable = True`` declares that one step per control period can be composed with the
       controller into one compiled tick (the closed loop's fused tick and fused loop). The
       class then provides ``explicit_step(rhs, t, x, h, u, p)`` (casadi, no inner
       iteration), a fixed step ``h_nominal`` [s] and ``RHS_PER_STEP``; steps taken inside
       such a tick are booked with :meth:`count_steps`.
    6. A long segment is advanced in windows of requested times (:meth:`begin_segment`, then
       :meth:`continue_segment` per window), so that its rows reach the sink as they come and
       memory stays bounded. The windows must not change the numbers: the default (restart
       ``_integrate`` at each window) is exact for methods that step each requested interval on
       its own; a method whose steps span requested times overrides both and steps on across
       windows (``dop853``, the scipy paths).
    7. ``RHS_INLINE_MAX_OPS``: the built functions get an ``rhs`` they inline when it has at
       most this many operations (casadi instructions), else one that stays a call in their
       graphs (:func:`~stationbed.core.compile.sx_function` ``called=True``): one compiled
       copy of the RHS instead of one per stage, so the C compiler's time grows gently with
       the arrays. Lower it from the default (``inf``: always inlined) only when the built
       functions just evaluate ``rhs`` (never differentiate or inspect its expression).

    Parameters
    ----------
    funcs : dict
        Compiled functions by name (``rhs`` and those of :meth:`build`; ``"__lib__"`` is the
        path of the compiled library when there is one).
    p : ndarray, shape (npar,)
        Model parameter vector (layout of the model's ``ParamLayout``).
    nx : int
        Number of states.
    rtol : float
        Relative tolerance (adaptive methods; the Radau defect weight).
    atol : float or ndarray, shape (nx,)
        Absolute tolerance, a scalar or one value per state component (``simulate`` passes
        the vector scaled by the formulation).
    step : float, optional
        Fixed step [s] (fixed-step methods; their default otherwise).
    max_step : float, optional
        Largest step [s] (adaptive methods); unbounded by default.

    Attributes
    ----------
    n_rhs : int
        Right-hand-side evaluations made so far.
    n_steps : int
        Accepted steps made so far.
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 0
    adaptive: ClassVar[bool] = False
    #: one explicit step per control period composes with the controller into one compiled tick
    fusable: ClassVar[bool] = False
    #: the largest RHS (casadi instructions) the built functions inline; larger: a call (rule 6)
    RHS_INLINE_MAX_OPS: ClassVar[float] = math.inf
    #: RHS evaluations one step makes (fixed-step methods; :meth:`count_steps` books this many)
    RHS_PER_STEP: ClassVar[int] = 0
    #: C source appended to the generated code (a driver calling the built functions by name)
    extra_c: ClassVar[str] = ""

    def __init__(self, funcs: dict, p: np.ndarray, nx: int, *, rtol=1e-9, atol=1e-12, step=None, max_step=None):
        self.funcs = funcs
        self.p = np.asarray(p, dtype=float)
        self.nx = nx
        self.rtol = float(rtol)
        self.atol = np.broadcast_to(np.asarray(atol, dtype=float), (nx,)).copy()
        self.step = step
        self.max_step = math.inf if max_step is None else float(max_step)
        self.n_rhs = 0
        self.n_steps = 0
        self._rhs = FastCall.of(funcs["rhs"])
        self._rhs.args[3][:] = self.p

    def set_params(self, p) -> None:
        """New parameter values (a scheduled step, run/schedule.py): ``self.p`` changed in place
        and every compiled buffer that holds a copy of it refreshed (:meth:`_params_changed`)."""
        if p is not self.p:
            self.p[:] = p
        self._params_changed()

    def _params_changed(self) -> None:
        """Copy ``self.p`` into the buffers that hold it (a subclass with its own adds them)."""
        self._rhs.args[3][:] = self.p

    @classmethod
    def build(cls, rhs: ca.Function, nx: int, nu: int, npar: int) -> list[ca.Function]:
        """The casadi Functions this integrator wants compiled with the RHS.

        Parameters
        ----------
        rhs : casadi.Function
            ``rhs(t, x, u, p) -> xdot``: t [s], x (nx,), u (nu,), p (npar,).
        nx, nu, npar : int
            Sizes of the state, held input and parameter vectors.

        Returns
        -------
        list of casadi.Function
            None for the base class.
        """
        return []

    @classmethod
    def explicit_step(cls, rhs, t, x, h, u, p):
        """One explicit step of a :attr:`fusable` integrator, in casadi (see rule 5).

        Parameters
        ----------
        rhs : casadi.Function or callable
            ``rhs(t, x, u, p) -> xdot``.
        t : casadi.SX
            Start time of the step [s].
        x : casadi.SX, shape (nx, 1)
            State at ``t``.
        h : casadi.SX
            Step [s].
        u, p : casadi.SX
            Held input (nu,) and parameters (npar,).

        Returns
        -------
        casadi.SX, shape (nx, 1)
            The state at ``t + h``.
        """
        raise NotImplementedError(f"integrator {cls.name!r} is not fusable")

    def count_steps(self, n: int) -> None:
        """Book ``n`` steps of ``RHS_PER_STEP`` RHS evaluations each.

        For steps this integrator's :meth:`explicit_step` made inside a compiled tick that the
        run loop called (the counters stay the integrator's own).

        Parameters
        ----------
        n : int
            Number of steps (>= 0).
        """
        self.n_rhs += self.RHS_PER_STEP * n
        self.n_steps += n

    def f(self, t, x, u) -> np.ndarray:
        """One right-hand-side evaluation (counted in ``n_rhs``).

        Parameters
        ----------
        t : float
            Time [s].
        x : ndarray, shape (nx,)
            State.
        u : ndarray, shape (nu,)
            Held input.

        Returns
        -------
        ndarray, shape (nx,)
            The state derivative (a copy).
        """
        a = self._rhs.args
        a[0][0] = t
        a[1][:] = x
        a[2][:] = u
        self._rhs()
        self.n_rhs += 1
        return self._rhs.res[0].copy()

    def integrate(self, ts, x0, u) -> np.ndarray:
        """The states at the times ``ts`` of one smooth segment.

        Parameters
        ----------
        ts : array_like, shape (m,)
            Increasing times [s], m >= 2; ``ts[0]`` is the start.
        x0 : array_like, shape (nx,)
            State at ``ts[0]``.
        u : array_like, shape (nu,)
            Input held over the segment.

        Returns
        -------
        ndarray, shape (m, nx)
            States at ``ts`` (the first row is ``x0``).

        Raises
        ------
        ValueError
            ``ts`` not increasing or shorter than two.
        IntegrationError
            A non-finite state, or the method could not continue.
        """
        ts = np.asarray(ts, dtype=float)
        if ts.ndim != 1 or ts.size < 2 or np.any(np.diff(ts) <= 0):
            raise ValueError("ts must be an increasing sequence of at least two times")
        x0 = np.asarray(x0, dtype=float)
        if not np.all(np.isfinite(x0)):
            raise IntegrationError(ts[0], "state is not finite (NaN or inf)")
        return self._integrate(ts, x0, np.asarray(u, dtype=float))

    def advance(self, t0: float, t1: float, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The state at ``t1`` from ``x0`` at ``t0`` with held input ``u`` (one control period).

        Parameters
        ----------
        t0, t1 : float
            Start and end [s], ``t1 > t0``.
        x0 : ndarray, shape (nx,)
            State at ``t0``.
        u : ndarray, shape (nu,)
            Held input.

        Returns
        -------
        ndarray, shape (nx,)
            State at ``t1``.
        """
        if not np.all(np.isfinite(x0)):
            raise IntegrationError(t0, "state is not finite (NaN or inf)")
        return self._integrate(np.array([t0, t1]), x0, u)[-1]

    # -- a segment in windows ---------------------------------------------------------------
    def begin_segment(self, t0: float, t_end: float, x0: np.ndarray, u: np.ndarray) -> None:
        """Start a smooth segment ``[t0, t_end]`` that :meth:`continue_segment` advances window by
        window, so that a long segment's states can be handed on (and forgotten) as they come.

        Cutting the segment's requested times into windows never changes the numbers: the
        states are those of one :meth:`integrate` call over all the times (``t0`` first). This
        default restarts :meth:`_integrate` from the last state at each window, which is exact
        for methods that treat each requested interval on its own (the fixed-step ones); a method
        whose steps span requested times (adaptive step control) overrides both methods and keeps
        stepping across windows.

        Parameters
        ----------
        t0, t_end : float
            Start and end of the segment [s], ``t_end > t0``.
        x0 : array_like, shape (nx,)
            State at ``t0``.
        u : array_like, shape (nu,)
            Input held over the segment.

        Raises
        ------
        IntegrationError
            ``x0`` is not finite.
        """
        x0 = np.array(x0, dtype=float)
        if not np.all(np.isfinite(x0)):
            raise IntegrationError(t0, "state is not finite (NaN or inf)")
        self._seg = [float(t0), float(t_end), x0, np.array(u, dtype=float)]

    def continue_segment(self, ts) -> np.ndarray:
        """The states at the next requested times of the segment begun by :meth:`begin_segment`.

        Parameters
        ----------
        ts : array_like, shape (m,)
            Increasing times [s], m >= 1, after the previous window's last time (or ``t0``) and
            at most ``t_end``; the segment's last window ends with ``t_end``.

        Returns
        -------
        ndarray, shape (m, nx)
            States at ``ts``.

        Raises
        ------
        IntegrationError
            As :meth:`integrate`; ``partial`` holds the states at this window's first times.
        """
        t, _, x, u = self._seg
        ts = np.asarray(ts, dtype=float)
        try:
            xs = self._integrate(np.concatenate([[t], ts]), x, u)
        except IntegrationError as e:
            e.partial = None if e.partial is None else e.partial[1:]
            raise
        self._seg[0], self._seg[2] = float(ts[-1]), xs[-1].copy()
        return xs[1:]

    def _integrate(self, ts, x0, u):  # pragma: no cover - abstract
        raise NotImplementedError
