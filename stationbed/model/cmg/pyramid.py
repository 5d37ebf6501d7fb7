"""``sgcmg_pyramid``: four single-gimbal CMGs in Wie's pyramid (zero momentum at δ = 0).

Gimbal axes ``g_i = (sin β cos φ_i, sin β sin φ_i, cos β)``, ``φ_i = 0, 90, 180, 270 deg``, skew
``β`` (53.13 deg default), spin ``s_i = cos δ_i s0_i + sin δ_i (g_i × s0_i)`` with
``s0_i = (-sin φ_i, cos φ_i, 0)``. State: the four gimbal angles; held input: their rates.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .base import GimballedGeometry

__all__ = ["Pyramid", "pyramid_axes"]


def pyramid_axes(skew: float) -> tuple[np.ndarray, np.ndarray]:
    """Gimbal axes and zero-angle spin axes of the 4-CMG pyramid.

    Parameters
    ----------
    skew : float  Skew angle β of the gimbal axes from the pyramid's z axis [rad].

    Returns
    -------
    g : ndarray, shape (4, 3)  Gimbal axes, B components.
    s0 : ndarray, shape (4, 3)  Spin axes at zero gimbal angle, B components.
    """
    phi = np.deg2rad([0.0, 90.0, 180.0, 270.0])
    sb, cb = math.sin(skew), math.cos(skew)
    g = np.stack([sb * np.cos(phi), sb * np.sin(phi), np.full(4, cb)], axis=1)
    s0 = np.stack([-np.sin(phi), np.cos(phi), np.zeros(4)], axis=1)
    return g, s0


class Pyramid(GimballedGeometry):
    """Single-gimbal units on a pyramid; per unit ``pc`` holds ``g`` then ``s0`` (6 numbers, B).

    Capacity ``h_rotor min(2 + 2 cos β, 4 sin β)``: the envelope along x/y and along z
    (3.2 h_rotor at 53.13 deg, where the envelope is nearly spherical). In general, along each
    body axis e the sum over the working units of the largest component of their spin, which
    turns in the plane normal to its gimbal axis g: ``|g × e|``; the capacity is the least of
    the three (with a failed unit, its term is left out)."""

    kind = "sgcmg_pyramid"
    gimbals_per_unit = 1
    unit_par = 6

    def _capacity(self, cfg):
        if not cfg.failed:
            return cfg.h_rotor * min(2 + 2 * math.cos(cfg.skew), 4 * math.sin(cfg.skew))
        g, _ = pyramid_axes(cfg.skew)
        work = [i for i in range(self.n_units) if i + 1 not in cfg.failed]
        return cfg.h_rotor * min(sum(float(np.linalg.norm(np.cross(g[i], e))) for i in work) for e in np.eye(3))

    def _geometry_params(self, cfg):
        g, s0 = pyramid_axes(cfg.skew)
        return np.concatenate([g, s0], axis=1).ravel()

    def _unit_spin(self, angles, geo):
        g, s0 = geo[0:3], geo[3:6]
        gs = ca.cross(g, s0)
        s, c = ca.sin(angles[0]), ca.cos(angles[0])
        return c * s0 + s * gs, [-s * s0 + c * gs]

    def _unit_spins_B(self, cfg, gimbal_angles):
        g, s0 = pyramid_axes(cfg.skew)
        d = gimbal_angles[..., None]
        return np.cos(d) * s0 + np.sin(d) * np.cross(g, s0)

    def _unit_reach(self, geo):
        # the spin turns in the plane normal to g: along body axis e it reaches |g x e|
        g = geo[0:3]
        return ca.vertcat(*[ca.norm_2(ca.cross(g, ca.DM(e))) for e in np.eye(3)])

    def _mount_axes_B(self, cfg):
        return pyramid_axes(cfg.skew)[0]
