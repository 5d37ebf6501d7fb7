"""Butcher tables of the explicit Runge-Kutta methods, as exact rational data.

A table is data, not code (as scipy's ``RungeKutta.A/B/C``): the stage builder
(:func:`stationbed.integrators.rk.explicit_rk_step`) reads it, and one parametrized test checks
every table in :data:`TABLEAUS` (row sums equal ``c``, weights sum to one, the order conditions
up to the declared order, Hairer-Nørsett-Wanner II.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

__all__ = ["ButcherTableau", "CLASSICAL_RK4", "TABLEAUS"]


@dataclass(frozen=True)
class ButcherTableau:
    """An explicit Runge-Kutta method: ``x1 = x0 + h Σ b_i k_i``,
    ``k_i = f(t0 + c_i h, x0 + h Σ_{j<i} a_ij k_j)``.

    Parameters
    ----------
    name : str
        What the method is called.
    order : int
        Its classical order (the order conditions it meets at the step boundaries).
    a : tuple of tuple of Fraction
        Row ``i`` holds ``a_i0 .. a_i,i-1`` (strictly lower triangular; row 0 is empty).
    b : tuple of Fraction, shape (s,)
        Weights.
    c : tuple of Fraction, shape (s,)
        Nodes (fractions of the step).
    """

    name: str
    order: int
    a: tuple[tuple[Fraction, ...], ...]
    b: tuple[Fraction, ...]
    c: tuple[Fraction, ...]

    @property
    def stages(self) -> int:
        """Number of stages ``s`` (RHS evaluations per step)."""
        return len(self.b)

    @staticmethod
    def common_denominator(row) -> tuple[list[int], int]:
        """``(numerators, denominator)`` of a row of fractions over their least common denominator.

        Parameters
        ----------
        row : sequence of Fraction

        Returns
        -------
        numerators : list of int
            ``row[j] * denominator`` (0 for a zero entry).
        denominator : int
            The least common denominator of the nonzero entries (1 if there are none).
        """
        den = math.lcm(*[q.denominator for q in row if q != 0] or [1])
        return [int(q * den) for q in row], den

    def a_float(self) -> list[list[float]]:
        """``a`` as rows of floats (row ``i`` has ``i`` entries)."""
        return [[float(q) for q in row] for row in self.a]

    def b_float(self) -> list[float]:
        """``b`` as floats."""
        return [float(q) for q in self.b]

    def c_float(self) -> list[float]:
        """``c`` as floats."""
        return [float(q) for q in self.c]


def _f(n: int, d: int = 1) -> Fraction:
    return Fraction(n, d)


#: Kutta's classical fourth-order method (1901).
CLASSICAL_RK4 = ButcherTableau(
    name="classical Runge-Kutta 4",
    order=4,
    a=((), (_f(1, 2),), (_f(0), _f(1, 2)), (_f(0), _f(0), _f(1))),
    b=(_f(1, 6), _f(1, 3), _f(1, 3), _f(1, 6)),
    c=(_f(0), _f(1, 2), _f(1, 2), _f(1)),
)

#: every table defined here (the invariants test runs over all of them)
TABLEAUS: tuple[ButcherTableau, ...] = (CLASSICAL_RK4,)
