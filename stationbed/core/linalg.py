"""Small linear algebra on casadi symbols (pure helpers: nothing else of the package)."""

from __future__ import annotations

import casadi as ca

__all__ = ["inv3"]


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
