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

import math
from typing import Literal

import numpy as np
from pydantic import Field

from stationbed.run.controller import Controller, ControllerParams, UnitQuaternion

from ._quat import lvlh_rate_varies, qmul, rotate


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

    def reference_N(self, meas):
        """``q_RN``: the reference attitude relative to N at this tick."""
        return qmul(tuple(meas.q_ON.tolist()), self.q_RO) if self.lvlh else self.q_RO

    def _update(self, t, meas):
        # Written out on floats: this runs every tick (controllers/_quat.py has the helpers it
        # inlines; tests/test_controller_contract.py::test_symbolic_form_gives_the_python_law
        # checks it against its casadi form, written with stationbed.core.rotation).
        qw, qx, qy, qz = meas.q_BN.tolist()
        wx, wy, wz = meas.omega_BN_B.tolist()
        if self.lvlh:
            rw, rx, ry, rz = qmul(meas.q_ON.tolist(), self.q_RO)
        else:
            rw, rx, ry, rz = self.q_RO
        self.q_ref_BN = (rw, rx, ry, rz)
        # q_BR = conj(q_RN) ⊗ q_BN
        ew = rw * qw + rx * qx + ry * qy + rz * qz
        ex = rw * qx - rx * qw - ry * qz + rz * qy
        ey = rw * qy + rx * qz - ry * qw - rz * qx
        ez = rw * qz - rx * qy + ry * qx - rz * qw
        kc = self.kc if ew >= 0.0 else -self.kc
        r0, r1, r2 = kc * ex, kc * ey, kc * ez  # eigenaxis rate command (before the limit)
        rn2 = r0 * r0 + r1 * r1 + r2 * r2
        if rn2 > self.lim2:
            f = self.lim / math.sqrt(rn2)
            r0, r1, r2 = r0 * f, r1 * f, r2 * f
        # C_BR ω_RN_R (rotate(), inlined)
        vx, vy, vz = rotate(self.q_RO, meas.omega_ON_O.tolist()) if self.varying else self.w_RN_R
        tx = 2.0 * (ey * vz - ez * vy)
        ty = 2.0 * (ez * vx - ex * vz)
        tz = 2.0 * (ex * vy - ey * vx)
        v0 = r0 + wx - (vx - ew * tx + (ey * tz - ez * ty))
        v1 = r1 + wy - (vy - ew * ty + (ez * tx - ex * tz))
        v2 = r2 + wz - (vz - ew * tz + (ex * ty - ey * tx))
        (J00, J01, J02), (J10, J11, J12), (J20, J21, J22) = self.J
        c = self.c
        t0 = -c * (J00 * v0 + J01 * v1 + J02 * v2)
        t1 = -c * (J10 * v0 + J11 * v1 + J12 * v2)
        t2 = -c * (J20 * v0 + J21 * v1 + J22 * v2)
        if self.gyro:
            Hx = J00 * wx + J01 * wy + J02 * wz
            Hy = J10 * wx + J11 * wy + J12 * wz
            Hz = J20 * wx + J21 * wy + J22 * wz
            t0 += wy * Hz - wz * Hy
            t1 += wz * Hx - wx * Hz
            t2 += wx * Hy - wy * Hx
        return (t0, t1, t2)

    def update_batch(self, t, meas):
        # many samples at once (stationbed/run/lockstep.py): _update's float operations on (n,)
        # arrays, in the same order (each sample's numbers are its _update's, bit for bit);
        # per sample: kc, c, lim, lim2 (n,), J (n, 3, 3), q_RO (n, 4), w_RN_R (n, 3)
        if any(isinstance(v, list) for v in (self.lvlh, self.varying, self.gyro)):
            return super().update_batch(t, meas)  # switches that differ between samples
        qw, qx, qy, qz = meas.q_BN.T
        wx, wy, wz = meas.omega_BN_B.T
        q_RO = tuple(self.q_RO.T)
        rw, rx, ry, rz = qmul(tuple(meas.q_ON.T), q_RO) if self.lvlh else q_RO
        self.q_ref_BN = np.stack(np.broadcast_arrays(rw, rx, ry, rz), axis=1)
        ew = rw * qw + rx * qx + ry * qy + rz * qz
        ex = rw * qx - rx * qw - ry * qz + rz * qy
        ey = rw * qy + rx * qz - ry * qw - rz * qx
        ez = rw * qz - rx * qy + ry * qx - rz * qw
        kc = np.where(ew >= 0.0, self.kc, -self.kc)
        r0, r1, r2 = kc * ex, kc * ey, kc * ez
        rn2 = r0 * r0 + r1 * r1 + r2 * r2
        big = rn2 > self.lim2
        f = self.lim / np.sqrt(np.where(big, rn2, 1.0))
        r0, r1, r2 = (np.where(big, r * f, r) for r in (r0, r1, r2))
        vx, vy, vz = rotate(q_RO, tuple(meas.omega_ON_O.T)) if self.varying else tuple(self.w_RN_R.T)
        tx = 2.0 * (ey * vz - ez * vy)
        ty = 2.0 * (ez * vx - ex * vz)
        tz = 2.0 * (ex * vy - ey * vx)
        v0 = r0 + wx - (vx - ew * tx + (ey * tz - ez * ty))
        v1 = r1 + wy - (vy - ew * ty + (ez * tx - ex * tz))
        v2 = r2 + wz - (vz - ew * tz + (ex * ty - ey * tx))
        J = self.J
        c = self.c
        t0 = -c * (J[:, 0, 0] * v0 + J[:, 0, 1] * v1 + J[:, 0, 2] * v2)
        t1 = -c * (J[:, 1, 0] * v0 + J[:, 1, 1] * v1 + J[:, 1, 2] * v2)
        t2 = -c * (J[:, 2, 0] * v0 + J[:, 2, 1] * v1 + J[:, 2, 2] * v2)
        if self.gyro:
            Hx = J[:, 0, 0] * wx + J[:, 0, 1] * wy + J[:, 0, 2] * wz
            Hy = J[:, 1, 0] * wx + J[:, 1, 1] * wy + J[:, 1, 2] * wz
            Hz = J[:, 2, 0] * wx + J[:, 2, 1] * wy + J[:, 2, 2] * wz
            t0 = t0 + (wy * Hz - wz * Hy)
            t1 = t1 + (wz * Hx - wx * Hz)
            t2 = t2 + (wx * Hy - wy * Hx)
        return np.stack([t0, t1, t2], axis=1)

    # -- fused form (stationbed/run/fused.py): the same law in casadi --------------------------
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
