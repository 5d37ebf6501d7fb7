"""scipy ``solve_ivp`` on the compiled right-hand side (:class:`ScipyIVP` and its variants by
method): the reference paths, not the fast ones."""

from __future__ import annotations

import math

from scipy.integrate import solve_ivp

from .base import IntegrationError, Integrator

__all__ = ["ScipyIVP", "scipy_variant"]


class ScipyIVP(Integrator):
    """scipy ``solve_ivp`` on the compiled RHS (a reference path, not the fast one).

    One ``solve_ivp`` call per segment with ``t_eval`` the requested times, the run's
    ``rtol``/``atol`` (per component) and ``max_step``. ``n_rhs`` counts the RHS calls made
    through :meth:`~.base.Integrator.f`, ``n_steps`` the output intervals.

    Parameters
    ----------
    funcs, p, nx, **kw
        As :class:`~.base.Integrator`.
    """

    name = "scipy_dop853"
    method = "DOP853"
    order = 8
    adaptive = True

    def _integrate(self, ts, x0, u):
        def fun(t, x):
            return self.f(t, x, u)

        kw = {}
        if math.isfinite(self.max_step):
            kw["max_step"] = self.max_step
        sol = solve_ivp(fun, (ts[0], ts[-1]), x0, method=self.method, t_eval=ts, rtol=self.rtol, atol=self.atol, **kw)
        if sol.status != 0:
            t_fail = float(sol.t[-1]) if sol.t.size else float(ts[0])
            raise IntegrationError(t_fail, f"solve_ivp({self.method}): {sol.message}", sol.y.T)
        self.n_steps += max(0, sol.t.size - 1)
        return sol.y.T.copy()


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


