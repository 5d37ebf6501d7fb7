"""Shared pieces of the momentum-balance tests (the independent truth every closed-loop path is
held to): the attitude matrix written out, and the trapezoid integral of logged torques."""

from __future__ import annotations

import numpy as np


def C_NB(q) -> np.ndarray:
    """DCM of unit quaternion ``q_BN`` (scalar first), B -> N, written out (DESIGN §3)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def torque_integral_N(tr, L_B) -> np.ndarray:
    """``∫ C_NB L_B dt`` from the first row to each row of ``tr`` (trapezoids between rows; ``L_B``
    the torque at each row, B components [N m], (N, 3)): N components [N m s], (N, 3)."""
    f = np.einsum("nij,nj->ni", np.array([C_NB(q) for q in tr.q_BN]), L_B)
    return np.vstack([np.zeros(3), np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(tr.t)[:, None], axis=0)])


def logged_torques_B(tr, kinds=("gg", "aero", "srp")) -> np.ndarray:
    """The sum of the logged ``tau_<kind>_x/y/z`` columns of ``kinds`` at every row [N m], (N, 3)."""
    return sum(tr.cols(f"tau_{k}_x", f"tau_{k}_y", f"tau_{k}_z") for k in kinds)
