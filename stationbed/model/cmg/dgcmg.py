"""``dgcmg``: double-gimbal CMGs (ISS-style, default 4 x 4760 N m s).

Each unit's rotor momentum has the constant magnitude ``h_rotor`` along the spin axis

``s(δ_o, δ_i) = sin δ_i e1 + cos δ_i (cos δ_o e3 - sin δ_o e2)``

where ``e1`` is the body-fixed outer-gimbal axis and ``(e1, e2, e3)`` the unit's right-handed
triad at zero angles (``e2`` the inner-gimbal axis, ``e3`` the spin axis). State: the outer and
inner gimbal angles of each unit; held input: their rates. No gimbal stops; gimbal lock at
``δ_i = ±90°``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import GimballedGeometry

__all__ = ["DoubleGimbal", "dgcmg_triads"]


def dgcmg_triads(outer_axes_B=None) -> np.ndarray:
    """Per unit the triad ``(e1, e2, e3)`` (outer axis, inner axis, spin at zero angles).

    Default layout (4 units): outer axes ``+x, +y, -x, -y`` with spins ``+z, +x, -z, -x``: zero
    total momentum at zero gimbal angles and full 3-axis authority there (an idealised layout,
    not the ISS flight geometry). A user layout gets, per outer axis ``e1``, the spin
    ``e3 = unit(e1 × a)`` with ``a`` the coordinate axis least aligned with ``e1``.

    Parameters
    ----------
    outer_axes_B : array_like, shape (n, 3), optional  Outer-gimbal axes, B components (normalised here).

    Returns
    -------
    ndarray, shape (n, 3, 3)  ``[i, 0]`` = e1, ``[i, 1]`` = e2, ``[i, 2]`` = e3 of unit i, B components.
    """
    if outer_axes_B is None:
        e1s = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
        e3s = np.array([[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]], float)
    else:
        e1s = np.array(outer_axes_B, float)
        e1s /= np.linalg.norm(e1s, axis=1, keepdims=True)
        e3s = []
        for e1 in e1s:
            a = np.eye(3)[int(np.argmin(np.abs(e1)))]
            e3 = np.cross(e1, a)
            e3s.append(e3 / np.linalg.norm(e3))
        e3s = np.array(e3s)
    e2s = np.cross(e3s, e1s)
    return np.stack([e1s, e2s, e3s], axis=1)


class DoubleGimbal(GimballedGeometry):
    """Double-gimbal units; per unit ``pc`` holds its triad ``e1, e2, e3`` (9 numbers, B).

    Capacity ``n h_rotor`` (a spherical envelope), n the working units."""

    kind = "dgcmg"
    gimbals_per_unit = 2
    gimbal_suffixes = ("outer", "inner")
    unit_par = 9

    def _capacity(self, cfg):
        return (cfg.n_units - len(cfg.failed)) * cfg.h_rotor

    def _geometry_params(self, cfg):
        return dgcmg_triads(cfg.outer_axes_B).ravel()

    def _unit_spin(self, angles, geo):
        e1, e2, e3 = geo[0:3], geo[3:6], geo[6:9]
        so, co = ca.sin(angles[0]), ca.cos(angles[0])
        si, ci = ca.sin(angles[1]), ca.cos(angles[1])
        r = co * e3 - so * e2  # e3 turned about the outer axis
        spin = si * e1 + ci * r
        return spin, [ci * (-so * e3 - co * e2), ci * e1 - si * r]

    def _unit_spins_B(self, cfg, gimbal_angles):
        triads = dgcmg_triads(cfg.outer_axes_B)
        d = gimbal_angles[..., None]
        d_out, d_in = d[..., 0::2, :], d[..., 1::2, :]
        e1, e2, e3 = triads[:, 0], triads[:, 1], triads[:, 2]
        return np.sin(d_in) * e1 + np.cos(d_in) * (np.cos(d_out) * e3 - np.sin(d_out) * e2)

    def _unit_reach(self, geo):
        # two gimbals turn the spin anywhere: it reaches 1 along every axis
        return ca.DM.ones(3)

    def _mount_axes_B(self, cfg):
        return dgcmg_triads(cfg.outer_axes_B)[:, 0]
