"""One "numpy or casadi" rule for the helpers that accept either.

A helper written once serves numeric evaluation (numpy, float64) and the symbolic model (casadi
SX/MX, from which the C code is generated). It decides by its arguments: any casadi object makes
the result a casadi expression.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["is_symbolic", "vector", "matrix", "trig"]

_CASADI = (ca.SX, ca.MX, ca.DM)


def is_symbolic(*xs) -> bool:
    """Whether any of ``xs`` is a casadi object (SX, MX or DM)."""
    return any(isinstance(x, _CASADI) for x in xs)


def vector(items, like):
    """Column vector of the scalars ``items``: casadi when ``like`` is, else numpy float64 (n,)."""
    if is_symbolic(like):
        return ca.vertcat(*items)
    return np.array(items, dtype=float)


def matrix(rows, like):
    """Matrix from a list of rows of scalars: casadi when ``like`` is, else numpy float64."""
    if is_symbolic(like):
        return ca.vertcat(*[ca.horzcat(*r) for r in rows])
    return np.array(rows, dtype=float)


def trig(u):
    """``(cos u, sin u)`` in casadi or numpy, as ``u`` is."""
    if is_symbolic(u):
        return ca.cos(u), ca.sin(u)
    return np.cos(u), np.sin(u)
