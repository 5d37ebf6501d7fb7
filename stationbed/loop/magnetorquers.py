"""Magnetic torquers (issue 33 item 6): three rods along the body axes, an
:class:`~.actuator.Actuator` written as one casadi expression (docs/loop.md "Adding an actuator:
a worked example", where this file is shown whole).

The Earth's field at the station, a centred dipole along the spin axis (Wertz, *Spacecraft
Attitude Determination and Control*, 1978, app. H; the magnetic field of a dipole, Jackson,
*Classical Electrodynamics*, 3rd ed., eq. 5.56)::

    B_N = B0 (R / |r|)³ (3 (m̂·r̂) r̂ - m̂),   m̂ = -ẑ_N (the dipole points to geographic south)

so ``|B| = B0 (R/r)³`` over the equator (pointing north) and ``2 B0 (R/r)³`` over the poles.

Per tick, on what flight software knows (the attitude and position the law sees):
``B_B = C_BN B_N``, the dipole ``m = B_B × τ / |B_B|²`` (the request's part across the field:
``m × B_B = τ - (τ·B̂) B̂``), each rod clipped to its largest dipole. The torque the station
feels is ``m × B`` in the *true* field at the true attitude (``READS`` ``q_BN_true``,
``r_N_true``), held over the tick (one channel, on the whole tick: ``FULL_TICK``); the rest of
the request as flight software knows it (``τ - m × B_B``) goes on down the chain (thrusters, then the CMG cluster). The field turns ~1e-3 rad
in a 0.1 s tick at orbital rate, so holding the torque rather than the dipole changes it by
~1e-3 of itself per tick: a modelling choice, the same in every executor.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from stationbed.core.layout import Layout
from stationbed.core.rotation import dcm
from stationbed.loop.actuator import Actuator, register_actuator

__all__ = ["Magnetorquers", "dipole_field_N", "B0_T", "R_REF_M"]

#: the Earth's dipole field over the equator at the reference radius [T]: |g10| of IGRF-13 at
#: epoch 2020.0 (Alken et al., Earth Planets Space 73, 49, 2021), the axial dipole term
B0_T = 29404.8e-9
#: IGRF's reference radius [m] (the same source)
R_REF_M = 6371200.0


def dipole_field_N(r_N, B0, R):
    """The axial dipole's field at ``r_N`` (N components [m]) [T], casadi (module docstring)."""
    r = ca.norm_2(r_N)
    r_hat = r_N / r
    m_hat = ca.vertcat(0.0, 0.0, -1.0)
    return B0 * (R / r) ** 3 * (3.0 * ca.dot(m_hat, r_hat) * r_hat - m_hat)


@register_actuator
class Magnetorquers(Actuator):
    """The scene's ``[magnetorquers]`` rods (module docstring). Memory: the last tick's dipole
    ``m_B`` [A m²], the dipole used over the run ``dipole_Am2s = ∫ Σ|m_i| dt`` [A m² s] (the
    rods' charge, up to their turns and area) and the time any rod was at its limit."""

    kind = "magnetorquers"
    TABLE = "magnetorquers"
    ORDER = 10  # before the thrusters: the rods spend no propellant
    FULL_TICK = True
    n_channels = 1
    STATE = Layout(m_B=3, dipole_Am2s=1, clipped_s=1)
    PARAMS = Layout(m_max=3, B0=1, R=1)
    OUTPUTS = Layout(m_B=3, torque_B=3)
    READS = Layout(q_BN=4, r_N=3, q_BN_true=4, r_N_true=3)
    ROW_COLUMNS = {"mtq_m_x": ("m_B", 0), "mtq_m_y": ("m_B", 1), "mtq_m_z": ("m_B", 2), "mtq_dipole_Am2s": ("dipole_Am2s", 0)}

    def __init__(self, m_max_Am2):
        self.m_max = np.asarray(m_max_Am2, dtype=float).reshape(3)
        super().__init__()

    @classmethod
    def from_scene(cls, scene, known, plant) -> "Magnetorquers":
        return cls(scene.magnetorquers.max_dipole_Am2)

    def _params(self) -> dict:
        return dict(m_max=self.m_max, B0=B0_T, R=R_REF_M)

    def _initial(self) -> dict:
        return dict(m_B=np.zeros(3), dipole_Am2s=0.0, clipped_s=0.0)

    def _command(self, t, h, x, r, tau_B, p):
        B_known = ca.mtimes(dcm(r["q_BN"]), dipole_field_N(r["r_N"], p["B0"], p["R"]))
        m = ca.cross(B_known, tau_B) / ca.dot(B_known, B_known)
        m_B = ca.fmin(ca.fmax(m, -p["m_max"]), p["m_max"])  # each rod at most its largest dipole
        B_true = ca.mtimes(dcm(r["q_BN_true"]), dipole_field_N(r["r_N_true"], p["B0"], p["R"]))
        torque = ca.cross(m_B, B_true)  # what the station feels
        rest = tau_B - ca.cross(m_B, B_known)  # what flight software knows is left (its own field)
        clipped = ca.if_else(ca.sum1(m != m_B) > 0, 1.0, 0.0)
        x_next = dict(m_B=m_B, dipole_Am2s=x["dipole_Am2s"] + h * ca.sum1(ca.fabs(m_B)), clipped_s=x["clipped_s"] + h * clipped)
        return x_next, rest, ca.vertcat(h), torque, dict(m_B=m_B, torque_B=torque)

    def summary(self, x) -> dict:
        s = self.state.split(np.asarray(x, dtype=float))
        return {"magnetorquer_dipole_Am2s": float(s["dipole_Am2s"][0]), "magnetorquer_clipped_s": float(s["clipped_s"][0])}
