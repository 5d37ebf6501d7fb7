"""``pd``: quaternion feedback in Wie's eigenaxis form, with a slew-rate limit.

Wie, Weiss & Arapostathis (JGCD 12(3), 1989) and Wie & Lu (JGCD 18(6), 1995):

    τ = -c J [ sat_ω_max((k / c) e) + ω_e ] + ω × J ω

with ``e`` the vector part of the error quaternion ``q_BR = conj(q_RN) ⊗ q_BN`` (sign chosen
so that its scalar part is ≥ 0: the short way round), ``ω_e = ω_BN_B - C_BR ω_RN_R`` the rate
relative to the reference frame R, and ``sat`` scaling the *vector* (k/c)e down to a length of
``max_slew_rate``: the rate command keeps the eigenaxis direction, so a large slew turns about
the eigenaxis at no more than ``max_slew_rate``. The last term cancels the body's gyroscopic
torque. (Not ``ω × h``: the steering law already commands ``ḣ = -τ - ω × h``, so the body
receives exactly ``τ``; adding ``ω × h`` here would apply it twice.) For small angles (e ≈ θ/2) every axis is a second-order system
with ``ω_n² = k / 2`` and ``2 ζ ω_n = c``: the parameters are ``bandwidth`` (ω_n) and ``damping``.

The reference frame R is LVLH (``reference = "lvlh"``, the station's flight attitude) or N
(``"inertial"``); ``q_ref`` is R's target attitude relative to that frame.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from stationbed.run.controller import Controller, ControllerParams, UnitQuaternion

from ._quat import lvlh_rate_varies, rotate


class PDParams(ControllerParams):
    reference: Literal["lvlh", "inertial"] = "lvlh"
    q_ref: UnitQuaternion = [1.0, 0.0, 0.0, 0.0]
    bandwidth: float = Field(default=0.01, gt=0.0)  # rad/s, closed-loop natural frequency ω_n
    damping: float = Field(default=0.9, gt=0.0)  # ζ
    max_slew_rate: float = Field(default=0.005, gt=0.0)  # rad/s, eigenaxis rate limit
    gyro_compensation: bool = True



class PD(Controller):
    name = "pd"
    command = "torque"
    Params = PDParams

    def _reset(self, plant):
        P = self.params
        if P.reference == "lvlh" and plant.mean_motion is None:
            raise ValueError("pd: reference = 'lvlh' needs an [orbit] in the scene")
        self.k = 2.0 * P.bandwidth**2
        self.c = 2.0 * P.damping * P.bandwidth
        self.J = tuple(tuple(float(v) for v in row) for row in plant.inertia_O_B)
        self.q_RO = tuple(P.q_ref)
        n = plant.mean_motion or 0.0
        # rate of R relative to N in R components: R is fixed in LVLH, which turns at (0, -n, 0)
        self.w_RN_R = rotate(self.q_RO, (0.0, -n, 0.0)) if P.reference == "lvlh" else (0.0, 0.0, 0.0)
        self.lvlh = P.reference == "lvlh"
        self.varying = self.lvlh and lvlh_rate_varies(plant)  # then R's rate is measured every tick
        self.kc = self.k / self.c
        self.lim = P.max_slew_rate
        self.lim2 = P.max_slew_rate**2
        self.gyro = P.gyro_compensation

    # -- the law, written once: evaluated compiled by every executor (stationbed/run/law_compiled.py)
    def symbolic_params(self):
        return [v for row in self.J for v in row] + [self.kc, self.c, self.lim, *self.w_RN_R, *self.q_RO,
                                                     float(self.lvlh), float(self.gyro), float(self.varying)]

    def symbolic(self, t, y, cp):
        import casadi as ca

        from stationbed.run.controller import measurement_fields
        from stationbed.core.rotation import dcm, quat_mult

        plant = self.plant
        lay = measurement_fields(plant.n_gimbals, len(plant.scene.appendage))

        def part(name):  # the measurement's field, by name
            return lay.get(y, name)

        q, w, q_ON = part("q_BN"), part("omega_BN_B"), part("q_ON")
        J = ca.reshape(cp[0:9], 3, 3).T
        kc, c, lim = cp[9], cp[10], cp[11]
        w_RN_R, q_RO, lvlh, gyro = cp[12:15], cp[15:19], cp[19], cp[20]
        w_RN_R = ca.if_else(cp[21] > 0.5, ca.mtimes(dcm(q_RO), part("omega_ON_O")), w_RN_R)  # two-body orbit: measured
        q_RN = ca.if_else(lvlh > 0.5, quat_mult(q_ON, q_RO), q_RO)
        conj = ca.vertcat(q_RN[0], -q_RN[1:4])
        qe = quat_mult(conj, q)
        r = ca.if_else(qe[0] >= 0, kc, -kc) * qe[1:4]
        rn = ca.norm_2(r)
        r = ca.if_else(rn > lim, r * (lim / ca.fmax(rn, 1e-300)), r)
        tv = 2.0 * ca.cross(qe[1:4], w_RN_R)
        w_ref = w_RN_R - qe[0] * tv + ca.cross(qe[1:4], tv)
        tau = -c * ca.mtimes(J, r + w - w_ref)
        tau = tau + gyro * ca.cross(w, ca.mtimes(J, w))
        return tau, q_RN

    def summary(self):
        return {"pd_bandwidth_rad_s": self.params.bandwidth, "pd_damping": self.params.damping}
