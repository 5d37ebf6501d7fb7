"""Small linear algebra on casadi symbols, and numpy rows (pure helpers: nothing else of the package)."""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["inv3", "row_norms"]


def inv3(A):
    """Inverse of a 3x3 casadi matrix by cofactors (exact, ~40 flops, no pivoting needed for SPD)."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    adj = ca.vertcat(
        ca.horzcat(c00, A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2], A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]),
        ca.horzcat(c01, A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0], A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]),
        ca.horzcat(c02, A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1], A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]),
    )
    return adj / det


def row_norms(x: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """The Euclidean norm of each row of a real 2-d array: ``np.linalg.norm(x, axis=1,
    keepdims=keepdims)``'s own arithmetic (the square root of the row's sum of squares, numpy's
    pairwise ``add.reduce``), bit for bit, without its ~5 µs of argument checks (the output rows
    call it a few times per batch: issue 25)."""
    return np.sqrt(np.add.reduce(x * x, axis=1, keepdims=keepdims))
