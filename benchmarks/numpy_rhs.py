"""Plain-numpy right-hand side of the MSFC momentum form (NASA TP-2511 Eq. 17-19).

The "same physics" as stationbed's compiled ``momentum`` formulation, written independently of
the library (only ``stationbed.load_scene`` and ``stationbed.run.initial.initial_state`` are used,
to read the scene and the attitude/rate at t = 0). It is the baseline of
``benchmarks/bench_core.py``: scipy ``solve_ivp`` + this RHS is the "plain Python" way.

State ``x = [q_BN (4, scalar first), H_O_B (3)]``:

    omega   = I(t)^-1 (H - sum_p I_p omega_p)
    q_dot   = 0.5 q (x) (0, omega)            (Hamilton product)
    H_dot   = L - omega x H                    (B-frame derivative of H about O)

with ``I(t) = I0 + sum_p C_PB^T J_p C_PB``, ``C_PB = Ax(beta) Ay(alpha)``,
``omega_PB_P = [beta_dot, alpha_dot cos b, -alpha_dot sin b]``, ``omega_p = C_PB^T omega_PB_P``,
and ``L`` = gravity gradient ``3 n^2 R_B x (I R_B)`` (when the scene's orbit asks for it) plus
the scene's external torques (constant windows, orbital harmonics).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "Model",
    "make_model",
    "make_rhs",
    "initial_state",
    "omega_of",
    "quat_angle",
]


def _parallel_axis(m: float, r: np.ndarray) -> np.ndarray:
    return m * (float(r @ r) * np.eye(3) - np.outer(r, r))


def _profile(prof) -> tuple[float, float, float, float, float]:
    return (float(prof.a0), float(prof.rate), float(prof.amp), float(prof.freq), float(prof.phase))


def _angle_and_rate(c, t: float) -> tuple[float, float]:
    a0, rate, amp, freq, phase = c
    arg = freq * t + phase
    return a0 + rate * t + amp * math.sin(arg), rate + amp * freq * math.cos(arg)


def _dcm_T(q: np.ndarray) -> np.ndarray:
    """C_BN: transpose of the standard (Hamilton, active) rotation matrix of q = (w, x, y, z)."""
    w, x, y, z = q
    # standard R(q) (body -> inertial), then transpose
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)],
            [2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)],
            [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class Model:
    """Constant data of a scene and the time-varying inertia/relative-momentum terms."""

    def __init__(self, scene):
        body = scene.body
        m_h = float(body.mass)
        r_h = np.asarray(body.cm, dtype=float)
        masses = [m_h] + [float(a.mass) for a in scene.appendage]
        cms = [r_h] + [np.asarray(a.cm, dtype=float) for a in scene.appendage]
        M = sum(masses)
        self.O_B = sum(m * r for m, r in zip(masses, cms)) / M  # composite mass centre in B

        I0 = np.asarray(body.inertia, dtype=float) + _parallel_axis(m_h, r_h - self.O_B)
        for a in scene.appendage:
            I0 = I0 + _parallel_axis(float(a.mass), np.asarray(a.cm, dtype=float) - self.O_B)
        self.I0 = I0
        self.J = [a.inertia_P for a in scene.appendage]
        self.alpha = [_profile(a.alpha) for a in scene.appendage]
        self.beta = [_profile(a.beta) for a in scene.appendage]

        orb = scene.orbit
        self.gg = orb is not None and bool(orb.gravity_gradient)
        if orb is not None:
            self.n = float(orb.mean_motion)
            self.u0 = float(orb.u0)
            self.ci, self.si = math.cos(orb.inclination), math.sin(orb.inclination)
            self.k_gg = 3.0 * self.n**2  # 3 mu / R^3
        self.const_torques = []
        self.harm_torques = []
        for trq in scene.torque:
            if trq.kind == "constant":
                self.const_torques.append(
                    (float(trq.start), float(trq.stop), np.asarray(trq.torque_B, dtype=float))
                )
            elif trq.kind == "orbital_harmonic":
                self.harm_torques.append(
                    tuple(np.asarray(v, dtype=float) for v in (trq.bias_B, trq.cos1_B, trq.sin1_B, trq.cos2_B, trq.sin2_B))
                )
            else:  # pragma: no cover - a kind this baseline does not know
                raise NotImplementedError(f"torque kind {trq.kind!r}")

    # -- time-varying parts -------------------------------------------------------------
    def inertia_and_h_rel(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Total inertia about O (B axes) and the relative momentum ``sum_p I_p omega_p``."""
        I = self.I0.copy()
        h = np.zeros(3)
        for J, ca_, cb_ in zip(self.J, self.alpha, self.beta):
            a, ad = _angle_and_rate(ca_, t)
            b, bd = _angle_and_rate(cb_, t)
            sa, cA = math.sin(a), math.cos(a)
            sb, cB = math.sin(b), math.cos(b)
            Ay = np.array([[cA, 0.0, -sa], [0.0, 1.0, 0.0], [sa, 0.0, cA]])
            Ax = np.array([[1.0, 0.0, 0.0], [0.0, cB, sb], [0.0, -sb, cB]])
            C_PB = Ax @ Ay
            I_p = C_PB.T @ J @ C_PB
            w_PB_P = np.array([bd, ad * cB, -ad * sb])
            w_p = C_PB.T @ w_PB_P
            I += I_p
            h += I_p @ w_p
        return I, h

    def torque(self, t: float, q: np.ndarray, I: np.ndarray) -> np.ndarray:
        L = np.zeros(3)
        if self.gg:
            u = self.u0 + self.n * t
            cu, su = math.cos(u), math.sin(u)
            R_N = np.array([cu, su * self.ci, su * self.si])
            R_B = _dcm_T(q / math.sqrt(q @ q)) @ R_N
            L += self.k_gg * np.cross(R_B, I @ R_B)
        for start, stop, tq in self.const_torques:
            if start <= t < stop:
                L += tq
        if self.harm_torques:
            u = self.u0 + self.n * t
            c1, s1, c2, s2 = math.cos(u), math.sin(u), math.cos(2 * u), math.sin(2 * u)
            for bias, k1, l1, k2, l2 in self.harm_torques:
                L += bias + c1 * k1 + s1 * l1 + c2 * k2 + s2 * l2
        return L

    def omega(self, t: float, x: np.ndarray) -> np.ndarray:
        I, h = self.inertia_and_h_rel(t)
        return np.linalg.solve(I, x[4:7] - h)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        q = x[:4]
        H = x[4:7]
        I, h = self.inertia_and_h_rel(t)
        w = np.linalg.solve(I, H - h)
        qw, qv = q[0], q[1:]
        dx = np.empty(7)
        dx[0] = -0.5 * (qv @ w)
        dx[1:4] = 0.5 * (qw * w + np.cross(qv, w))
        dx[4:7] = self.torque(t, q, I) - np.cross(w, H)
        return dx


def make_model(scene) -> Model:
    return Model(scene)


def make_rhs(scene):
    """``f(t, x) -> x_dot`` for scipy's ``solve_ivp``."""
    return Model(scene).rhs


def initial_state(scene) -> np.ndarray:
    """``x0 = [q_BN, H_O_B]`` at t = 0 from the scene's initial attitude and rate."""
    from stationbed.run.initial import initial_state as lib_initial_state

    q0, w0 = lib_initial_state(scene)
    model = Model(scene)
    I, h = model.inertia_and_h_rel(0.0)
    H0 = I @ np.asarray(w0, dtype=float) + h
    return np.concatenate([np.asarray(q0, dtype=float), H0])


def omega_of(scene):
    """``g(t, x) -> omega_BN_B`` recovered from the momentum state."""
    return Model(scene).omega


def quat_angle(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Principal rotation angle [rad] between quaternions (rows, scalar first), sign-invariant."""
    q1 = np.atleast_2d(q1) / np.linalg.norm(np.atleast_2d(q1), axis=-1, keepdims=True)
    q2 = np.atleast_2d(q2) / np.linalg.norm(np.atleast_2d(q2), axis=-1, keepdims=True)
    # delta = conj(q1) (x) q2
    w1, v1 = q1[:, 0], q1[:, 1:]
    w2, v2 = q2[:, 0], q2[:, 1:]
    dw = w1 * w2 + np.sum(v1 * v2, axis=1)
    dv = w1[:, None] * v2 - w2[:, None] * v1 - np.cross(v1, v2)
    return 2.0 * np.arctan2(np.linalg.norm(dv, axis=1), np.abs(dw))
