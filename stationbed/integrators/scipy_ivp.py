"""scipy ``solve_ivp`` on the compiled right-hand side (:class:`ScipyIVP` and its variants by
method): the reference paths, not the fast ones."""

from __future__ import annotations

import math

import numpy as np
import scipy.integrate

from .base import IntegrationError, Integrator

__all__ = ["ScipyIVP", "scipy_variant"]


class ScipyIVP(Integrator):
    """scipy ``solve_ivp`` on the compiled RHS (a reference path, not the fast one).

    A segment is ``solve_ivp``'s own loop with ``t_eval`` the requested times, the run's
    ``rtol``/``atol`` (per component) and ``max_step``: the method's solver class stepped to the
    segment end, each step's requested times read from its dense output. The loop is written
    out (:meth:`begin_segment`, :meth:`continue_segment`) so that a segment can be advanced
    window by window with the numbers of one call: a step that spans past a window keeps its
    interpolant for the next. The interpolant is read one requested time at a time (a matrix
    product over a batch of times, as ``solve_ivp`` does, may round a time's row differently
    with the batch: ``RK45``, ``Radau``, ``BDF``, ``LSODA`` differ from ``solve_ivp``'s rows in
    the last bit or two, ``DOP853`` not at all). ``n_rhs`` counts the RHS calls made through
    :meth:`~.base.Integrator.f`, ``n_steps`` the output intervals.

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.base.Integrator`.
    """

    name = "scipy_dop853"
    method = "DOP853"
    order = 8
    adaptive = True

    def begin_segment(self, t0, t_end, x0, u):
        super().begin_segment(t0, t_end, x0, u)
        u = np.array(u, dtype=float)

        def fun(t, x):
            return self.f(t, x, u)

        kw = {}
        if math.isfinite(self.max_step):
            kw["max_step"] = self.max_step
        self._t0 = float(t0)
        self._solver = getattr(scipy.integrate, self.method)(
            fun, float(t0), x0, float(t_end), vectorized=False, rtol=self.rtol, atol=self.atol, **kw
        )
        self._sol = None  # the last step's interpolant

    def continue_segment(self, ts):
        ts = np.asarray(ts, dtype=float)
        out = np.empty((ts.size, self.nx))
        solver = self._solver
        # requested times inside the last step (it ended past the previous window)
        i = int(np.searchsorted(ts, solver.t, side="right")) if self._sol is not None else 0
        self._read(ts[:i], out[:i])
        while i < ts.size and solver.status == "running":
            message = solver.step()
            if solver.status == "failed":
                raise IntegrationError(float(solver.t), f"solve_ivp({self.method}): {message}", out[:i])
            self._sol = solver.dense_output()
            j = int(np.searchsorted(ts, solver.t, side="right"))
            self._read(ts[i:j], out[i:j])
            i = max(i, j)
        self.n_steps += int(np.count_nonzero(ts > self._t0))
        return out

    def _read(self, ts, out):
        """The last step's interpolant at ``ts``, one time per call: a matrix-product interpolant
        (RK45, Radau, BDF, LSODA) rounds a column the same way whatever the others, so the rows
        do not depend on how the requested times are cut into windows."""
        for k, t in enumerate(ts):
            out[k] = self._sol(t)

    def _integrate(self, ts, x0, u):
        self.begin_segment(ts[0], ts[-1], x0, u)
        return self.continue_segment(ts)  # ts[0] too, from the first step's interpolant (as solve_ivp)


def scipy_variant(method: str, order: int) -> type[ScipyIVP]:
    """A :class:`ScipyIVP` subclass for another ``solve_ivp`` method.

    Parameters
    ----------
    method : str
        The ``solve_ivp`` method (``"RK45"``, ``"Radau"``, ``"BDF"``, ``"LSODA"``, ...); the
        class is registered as ``scipy_<method in lower case>``.
    order : int
        Its nominal order (the class attribute).

    Returns
    -------
    type
        The subclass.
    """
    return type(f"Scipy{method}", (ScipyIVP,), {"name": f"scipy_{method.lower()}", "method": method, "order": order})


