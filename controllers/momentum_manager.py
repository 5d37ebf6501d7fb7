"""``momentum_manager``: TEA-seeking attitude/momentum control (Wie, Byun, Warren, Geller, Long &
Sunkel, "New approach to attitude/momentum control for the Space Station", JGCD 12(5), 1989).

A station whose LVLH attitude is not a torque-equilibrium attitude (products of inertia, an
aerodynamic bias) needs a steady control torque to hold it, and a CMG cluster that supplies a
steady torque fills up (``h`` grows by that torque times time). Wie et al. control attitude and
CMG momentum together: with the integral of the momentum as a state, the only equilibrium of the
closed loop has ``h = 0`` on average, so the control torque averages to zero and the station
settles where gravity gradient balances the other torques — its torque-equilibrium attitude
(TEA), found by the loop, not commanded. Cyclic torques leave a bounded cyclic ``h``.

Design model (the rigid station of the plant facts with an ideal CMG cluster, linearised by
:func:`stationbed.analysis.design.design_linearization` on the simulator's own equations, then
augmented with ``z``), 12 states:
``x = (θ, δω, h, z)``: attitude ``θ = 2 vec(q_BO)`` relative to LVLH [rad], rate relative to LVLH
``δω = ω_BN_B - C_BO (0, -n, 0)`` [rad/s], CMG momentum ``h`` (B) [N m s] with
``ḣ = -u - ω × h``, and ``z = ∫ h dt`` [N m s²]; input: the body control torque ``u`` [N m];
rigid body with the plant's inertia about O and gravity gradient. ``A, B`` are casadi Jacobians
at the linearisation point, ``K`` from python-control's ``lqr`` with Bryson weights.

The linearisation point (``linearize_about``):

* ``"tea"`` (default): the TEA of the design model (the principal-axis attitude nearest LVLH,
  found by Newton on the nonlinear model; ``h = 0``, ``u = 0``): the gains fit where the station
  will fly, which matters when products of inertia put the TEA tens of degrees from LVLH;
* ``"lvlh"``: Wie et al.'s choice, LVLH itself with ``ω = (0, -n, 0)``; the torque the model needs
  there is treated as a bias the momentum integral rejects.

Law (every tick, on floats): ``u = -K (x - x_e)``, ``z ← z + T h`` (rectangle rule, period T).
The law keeps a state (``z`` and the orbit average below): its ``symbolic`` form takes it and
returns the next (``symbolic_state``, stationbed/run/law_state.py), so the fused loop carries it
and runs the law compiled; ``set_symbolic_state`` hands it back at the end (the TEA found).
Reported (``summary()``, prefix ``mm_``): closed-loop poles [rad/s], per-input gain/phase margins
(loop broken at that input), the predicted settling time ``4/|Re s_slow|`` [s], the design TEA
and the TEA the loop actually found (the attitude averaged over the last whole orbit), both as
``theta = 2 vec(q_BO)`` in degrees (≈ roll, pitch, yaw for small angles).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from stationbed.run.controller import Controller, ControllerError, ControllerParams

from stationbed.analysis.design import design_linearization
from stationbed.analysis.margins import loop_margins, settling_time

from ._quat import lvlh_rate_varies, rotate
from .lqr import MAX_POLE_PERIOD, _finite_or_none, bryson, design_lqr, pole_report


#: the design by its inputs (the knowledge's inertia about O, mean motion, gravity gradient, period and
#: the law's params): a Monte Carlo's samples share the nominal knowledge, so the design (TEA, LQR and
#: the loop margins: ~0.08 s of CPU, 29 % of a one-orbit sample of iss_full_flight_loop_montecarlo, whose
#: 1000 samples took 288 s of CPU before, 205 s after) runs once per process, not once per sample; the
#: same numbers (the same code on the same inputs). Entries are read-only (shared by the law's instances).
_DESIGNS: dict = {}
_DESIGNS_MAX = 16


def _design(inertia_O_B, n: float, gg: bool, period: float, P) -> dict:
    key = (np.asarray(inertia_O_B, dtype=float).tobytes(), float(n), bool(gg), float(period), P.model_dump_json())
    hit = _DESIGNS.get(key)
    if hit is not None:
        return hit
    try:
        tea = design_linearization(inertia_O_B, n, "tea", gravity_gradient=gg, cmg=True, trim=False)
    except ValueError as e:
        raise ControllerError(f"controller 'momentum_manager': {e}") from None
    tea_design = tea.tea_theta
    lin = tea if P.linearize_about == "tea" else design_linearization(
        inertia_O_B, n, "lvlh", gravity_gradient=gg, cmg=True, trim=False)
    x_e = np.zeros(12)
    if P.linearize_about == "tea":
        x_e[0:3] = tea_design
    # (θ, δω, h) from the plant; z = ∫ h dt is the law's own state: ż = h
    A9, B9 = lin.ss.A, lin.ss.B[:, 0:3]
    A = np.block([[A9, np.zeros((9, 3))], [np.zeros((3, 6)), np.eye(3), np.zeros((3, 3))]])
    B = np.vstack([B9, np.zeros((3, 3))])
    z_max = P.max_momentum / n if P.max_momentum_integral is None else P.max_momentum_integral
    Q = bryson([P.max_attitude] * 3 + [P.max_rate] * 3 + [P.max_momentum] * 3 + [z_max] * 3)
    R = bryson([P.max_torque] * 3)
    try:
        K, _ = design_lqr(A, B, Q, R)
    except Exception as e:  # noqa: BLE001 - python-control's own message says why
        raise ControllerError(f"controller 'momentum_manager': LQR design failed: {e}") from None
    poles = np.linalg.eigvals(A - B @ K)
    if not np.all(poles.real < 0):
        raise ControllerError(f"controller 'momentum_manager': closed loop not stable, poles {poles}")
    fastest = float(np.max(np.abs(poles)))
    if fastest * period > MAX_POLE_PERIOD:
        raise ControllerError(
            f"controller 'momentum_manager': fastest closed-loop pole {fastest:.3g} rad/s is too fast for the "
            f"period {period} s; lower params.max_torque"
        )
    margins = loop_margins(A, B, K)
    settling_time_s = settling_time(poles)
    q_TO = _theta_to_q(tea_design)  # the design TEA as a quaternion relative to LVLH
    _k = tuple(tuple(float(v) for v in row) for row in K)
    _xe = tuple(float(v) for v in x_e[0:3])
    d = {"tea_design": tea_design, "x_e": x_e, "A": A, "B": B, "Q": Q, "R": R, "K": K, "poles": poles,
         "margins": margins, "settling_time_s": settling_time_s, "q_TO": q_TO, "_k": _k, "_xe": _xe}
    for k in ("x_e", "A", "B", "Q", "R", "K", "poles"):
        d[k].setflags(write=False)
    if len(_DESIGNS) >= _DESIGNS_MAX:
        _DESIGNS.pop(next(iter(_DESIGNS)))
    _DESIGNS[key] = d
    return d


class MomentumManagerParams(ControllerParams):
    max_attitude: float = Field(default=0.1, gt=0.0)  # rad, Bryson: attitude excursion from the TEA
    max_rate: float = Field(default=1.0e-4, gt=0.0)  # rad/s, rate relative to LVLH
    max_momentum: float = Field(default=2000.0, gt=0.0)  # N m s, CMG momentum per axis
    max_momentum_integral: float | None = Field(default=None, gt=0.0)  # N m s², default max_momentum / n
    max_torque: float = Field(default=10.0, gt=0.0)  # N m, control torque per axis
    linearize_about: Literal["tea", "lvlh"] = "tea"


def _theta_to_q(th) -> tuple[float, float, float, float]:
    e = [0.5 * float(v) for v in th]
    return (math.sqrt(max(0.0, 1.0 - sum(v * v for v in e))), *e)


class MomentumManager(Controller):
    name = "momentum_manager"
    command = "torque"
    Params = MomentumManagerParams

    def _reset(self, plant):
        P = self.params
        if plant.mean_motion is None:
            raise ControllerError("controller 'momentum_manager': needs an [orbit] (gravity gradient, LVLH)")
        n = plant.mean_motion
        gg = bool(getattr(getattr(plant.scene, "orbit", None), "gravity_gradient", True))
        self.w_ON_O = (0.0, -n, 0.0)
        self._vy = -n
        self.varying = lvlh_rate_varies(plant)  # two-body orbit: LVLH's rate measured every tick
        d = _design(plant.inertia_O_B, n, gg, plant.period, P)
        for k, v in d.items():
            setattr(self, k, v)
        self._T = plant.period
        self.z = [0.0, 0.0, 0.0]
        # TEA the loop finds: the attitude relative to LVLH averaged over each whole orbit
        self._orbit_s = 2.0 * math.pi / n
        self._next_orbit = self._orbit_s
        self._sum = [0.0, 0.0, 0.0]
        self._count = 0
        self.tea_found = None

    # -- the law, written once (every executor: stationbed/run/law_compiled.py; its state: law_state.py)
    def symbolic_params(self):
        return [v for row in self._k for v in row] + [*self._xe, *self.q_TO, self._vy, self._T, self._orbit_s,
                                                      float(self.varying)]

    def symbolic_state(self):
        """``(z (3), orbit sum of theta (3), ticks in it, next orbit end [s], TEA found (3), found)``."""
        tea = self.tea_found
        return [*self.z, *self._sum, float(self._count), self._next_orbit, *(tea or (0.0, 0.0, 0.0)),
                float(tea is not None)]

    def set_symbolic_state(self, s):
        s = [float(v) for v in s]
        self.z, self._sum, self._count, self._next_orbit = s[0:3], s[3:6], int(s[6]), s[7]
        self.tea_found = tuple(s[8:11]) if s[11] > 0.5 else None

    def symbolic(self, t, y, cp, s):
        # _update's float operations, in its order, on casadi scalars (bit for bit where gcc
        # compiles them as CPython does: no FMA at -O2 without -march; docs/design.md)
        import casadi as ca

        from stationbed.run.controller import measurement_fields

        lay = measurement_fields(self.plant.n_gimbals, len(self.plant.scene.appendage))

        def part(name):  # the measurement's field, by name, as scalars
            v = lay.get(y, name)
            return [v[j] for j in range(v.numel())]

        ka, kb, kc = ([cp[12 * r + j] for j in range(12)] for r in range(3))  # the rows of K
        e0, e1, e2 = cp[36], cp[37], cp[38]
        aw, ax, ay, az = cp[39], cp[40], cp[41], cp[42]
        vy, T, orbit_s, varying = cp[43], cp[44], cp[45], cp[46]
        ow, ox, oy, oz = part("q_ON")
        q_ref = ca.vertcat(
            ow * aw - ox * ax - oy * ay - oz * az,
            ow * ax + ox * aw + oy * az - oz * ay,
            ow * ay - ox * az + oy * aw + oz * ax,
            ow * az + ox * ay - oy * ax + oz * aw,
        )
        qw, qx, qy, qz = part("q_BN")
        ew = ow * qw + ox * qx + oy * qy + oz * qz
        ex = ow * qx - ox * qw - oy * qz + oz * qy
        ey = ow * qy + ox * qz - oy * qw - oz * qx
        ez = ow * qz - ox * qy + oy * qx - oz * qw
        neg = ew < 0.0
        ew, ex, ey, ez = (ca.if_else(neg, -v, v) for v in (ew, ex, ey, ez))
        th0, th1, th2 = 2.0 * ex, 2.0 * ey, 2.0 * ez
        tx = -2.0 * ez * vy
        tz = 2.0 * ex * vy
        wx, wy, wz = part("omega_BN_B")
        r0, r1, r2 = rotate((ew, ex, ey, ez), part("omega_ON_O"))
        on = varying > 0.5  # two-body orbit: the measured LVLH rate
        w0 = ca.if_else(on, wx - r0, wx - (-ew * tx + ey * tz))
        w1 = ca.if_else(on, wy - r1, wy - (vy + (ez * tx - ex * tz)))
        w2 = ca.if_else(on, wz - r2, wz - (-ew * tz - ey * tx))
        h0, h1, h2 = part("h_B")
        z0, z1, z2, s0, s1, s2, c, nxt, f0, f1, f2, found = (s[j] for j in range(12))
        x0, x1, x2 = th0 - e0, th1 - e1, th2 - e2
        u = [-(a[0] * x0 + a[1] * x1 + a[2] * x2 + a[3] * w0 + a[4] * w1 + a[5] * w2)
             - (a[6] * h0 + a[7] * h1 + a[8] * h2 + a[9] * z0 + a[10] * z1 + a[11] * z2) for a in (ka, kb, kc)]
        due = t >= nxt
        cc = ca.fmax(c, 1.0)  # (c >= 1 whenever due: the quotient is _update's)
        s_next = ca.vertcat(
            z0 + T * h0, z1 + T * h1, z2 + T * h2,
            ca.if_else(due, 0.0, s0) + th0, ca.if_else(due, 0.0, s1) + th1, ca.if_else(due, 0.0, s2) + th2,
            ca.if_else(due, 0.0, c) + 1.0, ca.if_else(due, nxt + orbit_s, nxt),
            ca.if_else(due, s0 / cc, f0), ca.if_else(due, s1 / cc, f1), ca.if_else(due, s2 / cc, f2),
            ca.if_else(due, 1.0, found),
        )
        return ca.vertcat(*u), q_ref, s_next

    def summary(self):
        if self.plant is None:
            return {}
        out = {
            "mm_poles_rad_s": pole_report(self.poles),
            "mm_slowest_pole_rad_s": float(np.min(np.abs(self.poles.real))),
            "mm_settling_time_s": self.settling_time_s,
            "mm_gain_margin_down": [m["gain_margin_down"] for m in self.margins],
            "mm_gain_margin_up": [_finite_or_none(m["gain_margin_up"]) for m in self.margins],  # None: unbounded
            "mm_phase_margin_deg": [m["phase_margin_deg"] for m in self.margins],
            "mm_linearized_about": self.params.linearize_about,
            "mm_tea_design_deg": np.degrees(self.tea_design).tolist(),
        }
        if self.tea_found is not None:
            out["mm_tea_found_deg"] = [math.degrees(v) for v in self.tea_found]
        return out
