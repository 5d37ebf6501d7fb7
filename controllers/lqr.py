"""``lqr``: linear-quadratic regulator about an LVLH-fixed attitude, with gravity gradient.

Design (once, in ``reset``): the rigid station of the plant facts, what flight software believes
(``[knowledge]``, the nominal scene in a Monte Carlo; never the truth flown): its inertia about O on a
circular orbit of the plant's mean motion, gravity gradient as the knowledge says (the simulator's own
equations, :func:`stationbed.analysis.design.design_linearization`), linearised about the reference
frame R fixed in LVLH (which turns at ``(0, -n, 0)``) with state ``x = (θ, δω)``:
``θ = 2 vec(q_BR)`` [rad] and ``δω = ω_BN_B - C_BR ω_RN_R`` [rad/s]; input the body control torque
``u`` [N m]. ``A, B`` are the casadi Jacobians (``ca.jacobian``) at ``x = 0``; ``K`` comes from python-control
(``control.lqr(control.ss(A, B, I, 0), Q, R)``) with Bryson weights
``Q = diag(1/θ_max², 1/ω_max²)``, ``R = 1/τ_max² I``.

Law (every tick): ``τ = u0 - K x``, with ``u0`` the torque that makes R an equilibrium of the
model (gravity gradient and ``ω × Iω`` at rest in R; zero when R is a principal-axis LVLH
attitude; ``feedforward = false`` drops it). The gyroscopic terms are in ``A`` (exact Jacobian),
so there is no separate gyroscopic compensation; the ``ω × h`` of the CMG momentum is
cancelled by the steering law (stationbed.model.cmg: ``ḣ = -τ - ω × h``), as in the model.

Reported (attributes and ``summary()``): the closed-loop poles ``eig(A - B K)``, per input
channel the gain and phase margins of the loop broken at that input (the other two closed),
and the predicted settling time ``4 / |Re(slowest pole)|``.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from stationbed.run.controller import Controller, ControllerError, ControllerParams, UnitQuaternion

from stationbed.analysis.design import design_linearization
from stationbed.analysis.margins import loop_margins, settling_time

from ._quat import lvlh_rate_varies, rotate

#: Largest |pole| x period for which the continuous design is used with a zero-order hold:
#: the hold's half-period delay costs |s| T / 2 rad of phase (0.25 rad = 14 deg of the >= 60 deg
#: LQR phase margin at 0.5).
MAX_POLE_PERIOD = 0.5


class LQRParams(ControllerParams):
    q_ref: UnitQuaternion = [1.0, 0.0, 0.0, 0.0]  # R relative to LVLH
    max_attitude: float = Field(default=0.01, gt=0.0)  # rad, Bryson: acceptable attitude error per axis
    max_rate: float = Field(default=1.0e-4, gt=0.0)  # rad/s, acceptable rate error per axis
    max_torque: float = Field(default=20.0, gt=0.0)  # N m, acceptable torque per axis
    feedforward: bool = True  # add the equilibrium torque u0 that holds R



def bryson(maxima) -> np.ndarray:
    """Bryson's rule: ``diag(1 / x_max²)``."""
    return np.diag(1.0 / np.asarray(maxima, dtype=float) ** 2)


def design_lqr(A, B, Q, R):
    """``K`` and the closed-loop poles from python-control (``control.ss``, ``control.lqr``)."""
    import control

    sys = control.ss(A, B, np.eye(A.shape[0]), np.zeros((A.shape[0], B.shape[1])))
    K, _, E = control.lqr(sys, Q, R)
    return np.asarray(K, float), np.asarray(E)


def _finite_or_none(v: float):
    """JSON has no inf: an unbounded margin is reported as None."""
    return float(v) if math.isfinite(v) else None


def pole_report(poles) -> list[list[float]]:
    """Poles as ``[re, im]`` pairs [rad/s], sorted by real part (JSON-friendly)."""
    return [[float(p.real), float(p.imag)] for p in sorted(np.asarray(poles, complex), key=lambda s: (s.real, s.imag))]


class LQR(Controller):
    name = "lqr"
    command = "torque"
    Params = LQRParams

    def _reset(self, plant):
        P = self.params
        if plant.mean_motion is None:
            raise ControllerError("controller 'lqr': holds an LVLH attitude, the scene needs an [orbit]")
        n = plant.mean_motion
        gg = bool(getattr(getattr(plant.scene, "orbit", None), "gravity_gradient", True))
        self.q_RO = tuple(P.q_ref)
        self.w_RN_R = rotate(self.q_RO, (0.0, -n, 0.0))
        self.varying = lvlh_rate_varies(plant)  # two-body orbit: R's rate measured every tick
        lin = design_linearization(plant.inertia_O_B, n, "lvlh", q_ref=self.q_RO, gravity_gradient=gg)
        self.u0 = lin.trim_torque if P.feedforward else np.zeros(3)
        self.A, self.B = lin.ss.A, lin.ss.B[:, 0:3]
        self.Q = bryson([P.max_attitude] * 3 + [P.max_rate] * 3)
        self.R = bryson([P.max_torque] * 3)
        try:
            self.K, E = design_lqr(self.A, self.B, self.Q, self.R)
        except Exception as e:  # noqa: BLE001 - python-control's own message says why
            raise ControllerError(f"controller 'lqr': LQR design failed: {e}") from None
        self.poles = np.linalg.eigvals(self.A - self.B @ self.K)
        self.lqr_poles = E
        if not np.all(self.poles.real < 0):
            raise ControllerError(f"controller 'lqr': closed loop not stable, poles {self.poles}")
        fastest = float(np.max(np.abs(self.poles)))
        if fastest * plant.period > MAX_POLE_PERIOD:
            raise ControllerError(
                f"controller 'lqr': fastest closed-loop pole {fastest:.3g} rad/s is too fast for the period "
                f"{plant.period} s (|s| T = {fastest * plant.period:.2f} > {MAX_POLE_PERIOD}); "
                "lower params.max_torque or raise params.max_attitude"
            )
        self.margins = loop_margins(self.A, self.B, self.K)
        self.settling_time_s = settling_time(self.poles)
        self._k = tuple(tuple(float(v) for v in row) for row in self.K)
        self._u0 = tuple(float(v) for v in self.u0)

    # -- the law, written once: evaluated compiled by every executor (stationbed/run/law_compiled.py)
    def symbolic_params(self):
        return [v for row in self._k for v in row] + [*self._u0, *self.q_RO, *self.w_RN_R, float(self.varying)]

    def symbolic(self, t, y, cp):
        import casadi as ca

        from stationbed.run.controller import measurement_fields
        from stationbed.core.rotation import dcm, quat_mult

        lay = measurement_fields(self.plant.n_gimbals, len(self.plant.scene.appendage))

        def part(name):  # the measurement's field, by name
            return lay.get(y, name)

        q, w, q_ON = part("q_BN"), part("omega_BN_B"), part("q_ON")
        K = ca.reshape(cp[0:18], 6, 3).T
        u0, q_RO, w_R = cp[18:21], cp[21:25], cp[25:28]
        w_R = ca.if_else(cp[28] > 0.5, ca.mtimes(dcm(q_RO), part("omega_ON_O")), w_R)  # two-body orbit: measured
        q_RN = quat_mult(q_ON, q_RO)
        qe = quat_mult(ca.vertcat(q_RN[0], -q_RN[1:4]), q)
        qe = ca.if_else(qe[0] >= 0, qe, -qe)
        e = qe[1:4]
        tv = 2.0 * ca.cross(e, w_R)
        dw = w - (w_R - qe[0] * tv + ca.cross(e, tv))
        tau = u0 - ca.mtimes(K, ca.vertcat(2.0 * e, dw))
        return tau, q_RN

    def summary(self):
        if self.plant is None:
            return {}
        return {
            "lqr_poles_rad_s": pole_report(self.poles),
            "lqr_slowest_pole_rad_s": float(np.min(np.abs(self.poles.real))),
            "lqr_settling_time_s": self.settling_time_s,
            "lqr_gain_margin_down": [m["gain_margin_down"] for m in self.margins],
            "lqr_gain_margin_up": [_finite_or_none(m["gain_margin_up"]) for m in self.margins],  # None: unbounded
            "lqr_phase_margin_deg": [m["phase_margin_deg"] for m in self.margins],
            "lqr_feedforward_torque_Nm": self.u0.tolist(),
        }
