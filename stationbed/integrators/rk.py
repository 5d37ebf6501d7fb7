"""The one explicit Runge-Kutta stage builder: a :class:`~.tableau.ButcherTableau` and a
right-hand side in, the expression of one step out (casadi SX, or anything with the same
arithmetic, e.g. floats).

The expression is written from the table's rationals the way a person writes the method by
hand, so the graph (and the generated C, whose hash names the cached library) is that of the
hand-written form. For classical RK4 it is exactly::

    k1 = rhs(t, x, u, p)
    k2 = rhs(t + h / 2, x + h / 2 * k1, u, p)
    k3 = rhs(t + h / 2, x + h / 2 * k2, u, p)
    k4 = rhs(t + h, x + h * k3, u, p)
    x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

Rules: a row of ``a`` (or ``b``) over its least common denominator ``den`` with numerators
``num_j`` gives ``x + (h / den) * (Σ num_j k_j)`` (``h`` when ``den == 1``; the sum left to
right over the nonzero ``num_j``, a term ``k_j`` when ``num_j == 1``, else ``num_j * k_j``); a
node ``c = n / d`` gives the time ``t`` (c = 0), ``t + h`` (c = 1), ``t + h / d`` (n = 1) or
``t + n * h / d``.
"""

from __future__ import annotations

from fractions import Fraction

from .tableau import ButcherTableau

__all__ = ["explicit_rk_step"]


def _h_over(h, den: int):
    """``h / den`` (``h`` itself for ``den == 1``)."""
    return h if den == 1 else h / den


def _node_time(t, h, c: Fraction):
    """The stage time ``t + c h`` (see the module docstring for the forms)."""
    if c == 0:
        return t
    if c.numerator == 1:
        return t + _h_over(h, c.denominator)
    return t + c.numerator * h / c.denominator


def _increment(x, h, row, ks):
    """``x + h Σ row_j k_j`` for a row of fractions (``x`` itself for a zero row)."""
    nums, den = ButcherTableau.common_denominator(row)
    if not any(nums):
        return x
    scale = _h_over(h, den)  # first, as Python evaluates the hand-written ``h / den * (...)``
    total = None
    for num, k in zip(nums, ks):
        if num == 0:
            continue
        term = k if num == 1 else num * k
        total = term if total is None else total + term
    return x + scale * total


def explicit_rk_step(tableau: ButcherTableau, rhs, t, x, h, u, p):
    """One step of an explicit Runge-Kutta method, as an expression.

    Parameters
    ----------
    tableau : ButcherTableau
        The method (explicit: ``a`` strictly lower triangular).
    rhs : callable
        ``rhs(t, x, u, p) -> xdot`` (a casadi Function, or a lambda adapting another signature).
    t : casadi.SX or float
        Start of the step [s].
    x : casadi.SX, shape (nx, 1)
        State at ``t``.
    h : casadi.SX or float
        Step [s].
    u, p
        Held input and parameters, passed to ``rhs`` unchanged.

    Returns
    -------
    casadi.SX, shape (nx, 1)
        The state at ``t + h``.
    """
    ks = []
    for row, c in zip(tableau.a, tableau.c):
        ks.append(rhs(_node_time(t, h, c), _increment(x, h, row, ks), u, p))
    return _increment(x, h, tableau.b, ks)
