"""The library against an independent first-principles model (DESIGN §8, kind 3).

The reference model below shares no code with ``stationbed``: it has its own quaternion algebra,
its own joint-angle rotation matrices and their derivatives, and it never forms an appendage
inertia tensor, a Coriolis matrix or any TP-2511 equation. Every body is a cloud of point masses;
the station's angular momentum about the composite mass centre is the particle sum

    H_N = sum_i m_i r_i x v_i,   r_i = C_NB rho_i,   v_i = C_NB (omega x rho_i + rho_i'),

with rho_i a particle's position relative to the composite mass centre in B and rho_i' its
B-frame rate (from the analytic derivative of C_PB(t) along the prescribed joint angles).
Newton's laws about the mass centre give dH_N/dt = torque_N; at each instant omega follows from
H_N by solving the particle-inertia system

    omega = I_cloud(t)^-1 (C_BN H_N - sum_i m_i rho_i x rho_i').

The scene handed to the library is *derived* from the clouds (mass, mass centre and inertia of
each body computed from its particles), so the only shared inputs are numbers.

Gravity: the library uses the first-order gravity-gradient torque 3 n^2 R_hat x (I R_hat); the
reference applies the exact inverse-square field to every particle. Both reference variants are
available so the library can be held to integration accuracy (first order, same physics) and the
physics approximation can be measured separately (exact field, looser tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp

from stationbed import simulate
from stationbed.scene import scene_from_dict

# ---------------------------------------------------------------------------------------------
# Tolerances (each with its reason)
# ---------------------------------------------------------------------------------------------

#: Library and reference both integrate at rtol 1e-12 / atol 1e-14 over <= one orbit; the
#: deep-space case tumbles at ~1e-2 rad/s (~15 rad of total rotation in 1500 s). A global error of
#: ~1e-12 per radian turned, x~10 for error growth and the two integrators' different step
#: sequences, stays under 1e-9 rad. (Measured: ~3e-12 deep space, ~1e-11 over an orbit.)
ATT_TOL_RAD = 1e-9
#: omega follows from H_N rotated into B: an attitude error d(theta) moves it by ~|omega| d(theta)
#: (~1e-2 rad/s x 1e-9 rad, times the inertia condition number ~3), so the rate tolerance that is
#: consistent with ATT_TOL_RAD is ~3e-11 rad/s; 1e-11 rad/s (1e-9 of |omega|) is used.
#: (Measured: ~1.5e-14 rad/s.)
OMEGA_TOL_RAD_S = 1e-11
#: H_N [N m s] is integrated directly (momentum form) or rebuilt from omega (omega-state forms):
#: integration error only, ~1e-12 relative per unit of relative change; 1e-10 of the largest |H|
#: leaves ~10x margin over the measured ~4e-12 (orbit) and ~6e-13 (deep space).
H_RTOL = 1e-10
#: Kinetic energy column T (arrays' relative motion included) vs the particle sum 1/2 sum m v^2:
#: quadratic in omega, so ~2x its relative error; measured ~9e-13.
T_RTOL = 1e-10
#: With first-order gravity gradient on both sides the physics is identical: same tolerances.
GG_FIRST_ORDER_ATT_TOL_RAD = ATT_TOL_RAD
GG_FIRST_ORDER_OMEGA_TOL_RAD_S = OMEGA_TOL_RAD_S

#: Exact inverse-square gravity vs the library's first-order gravity gradient. The neglected
#: torque is O(|rho|/R) ~ 25 m / 6.8e6 m ~ 4e-6 of the gravity-gradient torque, whose effect on
#: this scene over one orbit is O(1) rad (it turns the station by ~pi relative to a torque-free
#: run). Measured difference over one orbit: 2.3e-6 rad and 2.1e-9 rad/s; the tolerances are
#: ~10x that. A sign or factor error in the library's torque would be ~5 orders larger.
EXACT_GG_ATT_TOL_RAD = 2e-5
EXACT_GG_OMEGA_TOL_RAD_S = 2e-8

#: Self-check of the reference: H_N recomputed from inertial particle velocities obtained by a
#: 4th-order central difference of the integrated inertial positions (step FD_STEP_S). Truncation
#: ~ (h * 0.03 rad/s)^4 / 30 ~ 1e-10, round-off ~ 1e-16 * 30 m / h; 1e-8 relative is ample (measured 3e-10).
FD_STEP_S = 0.25
REF_FD_H_RTOL = 1e-8
#: Self-check of the reference: arrays locked, no torque -> kinetic energy is constant to
#: the integration tolerance (rtol 1e-12 over ~1e3 s; measured 3e-12).
REF_ENERGY_RTOL = 1e-10

#: Integration settings of both models.
RTOL = 1e-12
ATOL = 1e-14

FORMULATIONS = ["momentum", "momentum27", "dalembert"]

MU_EARTH = 3.986004418e14


# ---------------------------------------------------------------------------------------------
# Own rotation algebra (no library code)
# ---------------------------------------------------------------------------------------------


def quat_mul(p, q):
    """Hamilton product, scalar first."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ]
    )


def quat_conj(q):
    return np.array([q[0], -q[1], -q[2], -q[3]])


def C_NB_of(q):
    """Body-to-inertial DCM of the scalar-first unit quaternion q_BN (v_N = C_NB v_B)."""
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def principal_angle(q1, q2):
    """Angle [rad] of the rotation taking q1 to q2 (sign-invariant, accurate near zero)."""
    d = quat_mul(quat_conj(q1), q2)
    return 2.0 * np.arctan2(np.linalg.norm(d[1:]), abs(d[0]))


def Ay(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def dAy(a):
    """d Ay / d a."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[-s, 0.0, -c], [0.0, 0.0, 0.0], [c, 0.0, -s]])


def Ax(b):
    c, s = np.cos(b), np.sin(b)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def dAx(b):
    """d Ax / d b."""
    c, s = np.cos(b), np.sin(b)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, c], [0.0, -c, -s]])


# ---------------------------------------------------------------------------------------------
# Point-mass model
# ---------------------------------------------------------------------------------------------


def cloud_props(m, x):
    """Mass, mass centre and inertia about the mass centre (off-diagonal = -sum m x y)."""
    M = m.sum()
    c = (m[:, None] * x).sum(axis=0) / M
    d = x - c
    J = np.sum(m * np.einsum("ij,ij->i", d, d)) * np.eye(3) - (m[:, None] * d).T @ d
    return M, c, 0.5 * (J + J.T)


@dataclass(frozen=True)
class Profile:
    a0: float = 0.0
    rate: float = 0.0
    amp: float = 0.0
    freq: float = 0.0
    phase: float = 0.0

    def value_rate(self, t):
        arg = self.freq * t + self.phase
        return (
            self.a0 + self.rate * t + self.amp * np.sin(arg),
            self.rate + self.amp * self.freq * np.cos(arg),
        )

    def as_dict(self):
        return dict(a0=self.a0, rate=self.rate, amp=self.amp, freq=self.freq, phase=self.phase)


@dataclass(frozen=True)
class ArrayCloud:
    """An articulated array: particles s_P about its own mass centre (P axes), which sits at r_B."""

    name: str
    m: np.ndarray
    s_P: np.ndarray
    r_B: np.ndarray
    alpha: Profile
    beta: Profile

    def C_PB_and_rate(self, t):
        a, ad = self.alpha.value_rate(t)
        b, bd = self.beta.value_rate(t)
        C = Ax(b) @ Ay(a)
        Cd = bd * dAx(b) @ Ay(a) + ad * Ax(b) @ dAy(a)
        return C, Cd


class PointMassStation:
    """Hub cloud (B frame) + array clouds; Newton's laws about the composite mass centre."""

    def __init__(self, hub_m, hub_x, arrays, orbit=None):
        self.hub_m = np.asarray(hub_m, float)
        self.hub_x = np.asarray(hub_x, float)
        self.arrays = list(arrays)
        self.orbit = orbit  # dict(radius, inclination, u0, mu) or None
        M_h, c_h, _ = cloud_props(self.hub_m, self.hub_x)
        M = M_h + sum(a.m.sum() for a in self.arrays)
        self.cm_B = (M_h * c_h + sum(a.m.sum() * a.r_B for a in self.arrays)) / M
        self.m = np.concatenate([self.hub_m] + [a.m for a in self.arrays])

    # -- geometry --------------------------------------------------------------------------
    def particles(self, t):
        """(rho, rho_dot): positions rel. to the composite CM and their B-frame rates, B axes."""
        rho = [self.hub_x - self.cm_B]
        rhod = [np.zeros_like(self.hub_x)]
        for a in self.arrays:
            C, Cd = a.C_PB_and_rate(t)
            rho.append(a.r_B - self.cm_B + a.s_P @ C)  # rows: (C_PB^T s_P)^T
            rhod.append(a.s_P @ Cd)
        return np.vstack(rho), np.vstack(rhod)

    def inertia(self, rho):
        m = self.m
        return np.sum(m * np.einsum("ij,ij->i", rho, rho)) * np.eye(3) - (m[:, None] * rho).T @ rho

    def omega(self, t, q, H_N):
        rho, rhod = self.particles(t)
        h_rel = np.sum(self.m[:, None] * np.cross(rho, rhod), axis=0)
        C_NB = C_NB_of(q)
        return np.linalg.solve(self.inertia(rho), C_NB.T @ H_N - h_rel)

    def H_N(self, t, q, w):
        rho, rhod = self.particles(t)
        v_B = np.cross(w, rho) + rhod
        return C_NB_of(q) @ np.sum(self.m[:, None] * np.cross(rho, v_B), axis=0)

    def kinetic_energy(self, t, w):
        rho, rhod = self.particles(t)
        v = np.cross(w, rho) + rhod
        return 0.5 * np.sum(self.m * np.einsum("ij,ij->i", v, v))

    # -- environment -----------------------------------------------------------------------
    def R_N(self, t):
        o = self.orbit
        n = np.sqrt(o["mu"] / o["radius"] ** 3)
        u = o["u0"] + n * t
        i = o["inclination"]
        return o["radius"] * np.array([np.cos(u), np.sin(u) * np.cos(i), np.sin(u) * np.sin(i)])

    def torque_N(self, t, q, gravity):
        if gravity is None:
            return np.zeros(3)
        mu = self.orbit["mu"]
        R = self.R_N(t)
        rho, _ = self.particles(t)
        C_NB = C_NB_of(q)
        if gravity == "exact":
            # Inverse-square field on each particle; the uniform part g(R) gives no torque about
            # the mass centre (sum m rho = 0), subtracting it only removes round-off.
            r_N = rho @ C_NB.T
            p = R + r_N
            g = -mu * p / np.linalg.norm(p, axis=1)[:, None] ** 3
            g0 = -mu * R / np.linalg.norm(R) ** 3
            return np.sum(self.m[:, None] * np.cross(r_N, g - g0), axis=0)
        if gravity == "first_order":
            Rn = np.linalg.norm(R)
            Rh_B = C_NB.T @ (R / Rn)
            L_B = 3.0 * mu / Rn**3 * np.cross(Rh_B, self.inertia(rho) @ Rh_B)
            return C_NB @ L_B
        raise ValueError(gravity)

    # -- integration -----------------------------------------------------------------------
    def propagate(self, q0, w0, t_eval, gravity=None):
        """Integrate x = (q_BN, H_N): q' = q (x) (0, omega)/2, H_N' = torque_N. Returns q, omega, H."""
        x0 = np.concatenate([q0, self.H_N(0.0, q0, w0)])

        def rhs(t, x):
            q, H = x[:4], x[4:]
            w = self.omega(t, q, H)
            return np.concatenate([0.5 * quat_mul(q, np.concatenate([[0.0], w])), self.torque_N(t, q, gravity)])

        sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), x0, method="DOP853", t_eval=t_eval, rtol=RTOL, atol=ATOL, dense_output=True)
        assert sol.success, sol.message
        qs = sol.y[:4].T / np.linalg.norm(sol.y[:4].T, axis=1)[:, None]
        Hs = sol.y[4:].T
        ws = np.array([self.omega(t, q, H) for t, q, H in zip(t_eval, qs, Hs)])
        return qs, ws, Hs, sol

    # -- scene -----------------------------------------------------------------------------
    def scene_dict(self, q0, w0, duration, output_dt=10.0):
        M_h, c_h, J_h = cloud_props(self.hub_m, self.hub_x)
        apps = []
        for a in self.arrays:
            M_p, c_p, J_p = cloud_props(a.m, a.s_P)
            assert np.allclose(c_p, 0.0, atol=1e-12)  # balanced: mass centre on the joint axes
            apps.append(
                dict(name=a.name, mass=float(M_p), inertia=J_p.tolist(), cm=a.r_B.tolist(), alpha=a.alpha.as_dict(), beta=a.beta.as_dict())
            )
        d = dict(
            name="independent_point_mass",
            simulation=dict(duration=duration, formulation="momentum", integrator="dop853", rtol=RTOL, atol=ATOL, output_dt=output_dt),
            initial=dict(q_BN=list(map(float, q0)), omega_BN_B=list(map(float, w0)), frame="inertial"),
            body=dict(mass=float(M_h), inertia=J_h.tolist(), cm=c_h.tolist()),
            appendage=apps,
        )
        if self.orbit is not None:
            o = self.orbit
            d["orbit"] = dict(radius=o["radius"], inclination=o["inclination"], u0=o["u0"], mu=o["mu"], gravity_gradient=True)
        return d


# ---------------------------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------------------------


def _balanced_plate(rng, n, half_extent):
    """Asymmetric flat-ish cloud with its mass centre exactly at the origin."""
    m = rng.uniform(80.0, 500.0, n)
    s = rng.uniform(-1.0, 1.0, (n, 3)) * half_extent
    s -= (m[:, None] * s).sum(axis=0) / m.sum()
    return m, s


def make_station(seed=2511, arrays_move=True, orbit=None):
    rng = np.random.default_rng(seed)
    # Hub: 8 masses around an offset centre -> ~1e4 kg, non-diagonal inertia ~1e5..1e6 kg m^2.
    hub_m = rng.uniform(600.0, 2000.0, 8)
    hub_x = rng.normal(0.0, 1.0, (8, 3)) * np.array([6.0, 4.0, 9.0]) + np.array([1.0, -0.5, 2.0])
    m1, s1 = _balanced_plate(rng, 6, np.array([2.0, 7.0, 0.4]))
    m2, s2 = _balanced_plate(rng, 7, np.array([2.5, 6.0, 0.3]))
    if arrays_move:
        p1a = Profile(a0=0.3, rate=2.0e-3, amp=0.6, freq=0.03, phase=0.4)
        p1b = Profile(a0=-0.2, rate=-1.0e-3, amp=0.4, freq=0.021, phase=1.1)
        p2a = Profile(a0=-0.5, rate=-1.5e-3, amp=0.8, freq=0.045, phase=-0.7)
        p2b = Profile(a0=0.1, rate=0.5e-3, amp=0.3, freq=0.012, phase=2.0)
    else:
        p1a, p1b, p2a, p2b = Profile(a0=0.3), Profile(a0=-0.2), Profile(a0=-0.5), Profile(a0=0.1)
    arrays = [
        ArrayCloud("stbd", m1, s1, np.array([2.0, 22.0, -4.0]), p1a, p1b),
        ArrayCloud("port", m2, s2, np.array([-1.5, -18.0, 3.0]), p2a, p2b),
    ]
    return PointMassStation(hub_m, hub_x, arrays, orbit=orbit)


Q0 = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
W0 = np.array([4.0e-3, -7.0e-3, 2.5e-3])
DEEP_SPACE_DURATION_S = 1500.0

ORBIT = dict(radius=6778137.0, inclination=0.9006, u0=0.4, mu=MU_EARTH)
ORBIT_PERIOD_S = 2 * np.pi * np.sqrt(ORBIT["radius"] ** 3 / MU_EARTH)
#: In orbit a slow tumble keeps the gravity-gradient torque's effect large relative to omega.
W0_ORBIT = np.array([2.0e-4, -1.2e-3, 5.0e-4])


def _max_errors(tr, q_ref, w_ref):
    att = max(principal_angle(a, b) for a, b in zip(tr.q_BN, q_ref))
    rate = np.max(np.abs(tr.omega_BN_B - w_ref))
    return att, rate


# ---------------------------------------------------------------------------------------------
# Fixtures
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def deep_space():
    st = make_station()
    scene = scene_from_dict(st.scene_dict(Q0, W0, DEEP_SPACE_DURATION_S))
    return st, scene


@pytest.fixture(scope="module")
def deep_space_reference(deep_space):
    st, scene = deep_space
    t = simulate(scene, rtol=RTOL, atol=ATOL)["t"]
    q, w, H, sol = st.propagate(Q0, W0, t)
    return t, q, w, H, sol


@pytest.fixture(scope="module")
def in_orbit():
    st = make_station(orbit=ORBIT)
    scene = scene_from_dict(st.scene_dict(Q0, W0_ORBIT, float(ORBIT_PERIOD_S)))
    return st, scene


@pytest.fixture(scope="module")
def in_orbit_references(in_orbit):
    st, scene = in_orbit
    t = simulate(scene, rtol=RTOL, atol=ATOL)["t"]
    return t, {g: st.propagate(Q0, W0_ORBIT, t, gravity=g) for g in ("first_order", "exact")}


# ---------------------------------------------------------------------------------------------
# Self-checks of the reference model
# ---------------------------------------------------------------------------------------------


def test_reference_scene_is_what_the_clouds_say(deep_space):
    """The scene's mass properties reproduce the particle inertia about the composite CM."""
    st, scene = deep_space
    d = st.scene_dict(Q0, W0, DEEP_SPACE_DURATION_S)
    t = 123.0
    # parallel-axis assembly from the scene numbers (independent of the library's massprops)
    M = d["body"]["mass"] + sum(a["mass"] for a in d["appendage"])
    cm = (d["body"]["mass"] * np.array(d["body"]["cm"]) + sum(a["mass"] * np.array(a["cm"]) for a in d["appendage"])) / M

    def shift(m, r):
        return m * (r @ r * np.eye(3) - np.outer(r, r))

    I = np.array(d["body"]["inertia"]) + shift(d["body"]["mass"], np.array(d["body"]["cm"]) - cm)
    for a, arr in zip(d["appendage"], st.arrays):
        C, _ = arr.C_PB_and_rate(t)
        I += C.T @ np.array(a["inertia"]) @ C + shift(a["mass"], np.array(a["cm"]) - cm)
    rho, _ = st.particles(t)
    assert_allclose(cm, st.cm_B, rtol=0, atol=1e-12)
    assert_allclose(I, st.inertia(rho), rtol=1e-12, atol=1e-12 * np.abs(I).max())
    assert_allclose(np.sum(st.m[:, None] * rho, axis=0), 0.0, atol=1e-9)


def test_reference_rates_match_finite_differences(deep_space):
    """rho_dot from the analytic dC_PB/dt equals a central difference of rho(t)."""
    st, _ = deep_space
    t, h = 321.0, 1e-3
    _, rhod = st.particles(t)
    fd = (st.particles(t + h)[0] - st.particles(t - h)[0]) / (2 * h)
    assert_allclose(rhod, fd, rtol=0, atol=1e-7)


def test_reference_momentum_from_inertial_particle_velocities(deep_space, deep_space_reference):
    """H_N = sum m r x v with v from differencing the integrated inertial positions r = C_NB rho.

    This checks the kinematics (q' with the solved omega, and rho') as well as the momentum
    balance: a wrong sign or frame in the reference would make H drift or jump here.
    """
    st, _ = deep_space
    t, _, _, H, sol = deep_space_reference
    H0 = H[0]
    h = FD_STEP_S

    def r_N(tt):
        x = sol.sol(tt)
        return st.particles(tt)[0] @ C_NB_of(x[:4]).T

    for tc in np.linspace(t[2], t[-3], 7):
        v = (-r_N(tc + 2 * h) + 8 * r_N(tc + h) - 8 * r_N(tc - h) + r_N(tc - 2 * h)) / (12 * h)
        H_fd = np.sum(st.m[:, None] * np.cross(r_N(tc), v), axis=0)
        assert_allclose(H_fd, H0, rtol=0, atol=REF_FD_H_RTOL * np.linalg.norm(H0))


def test_reference_energy_constant_with_arrays_locked():
    """No torque and no joint motion: nothing does work, so T = sum m v^2 / 2 is constant."""
    st = make_station(arrays_move=False)
    t = np.linspace(0.0, 1000.0, 101)
    _, w, _, _ = st.propagate(Q0, W0, t)
    T = np.array([st.kinetic_energy(ti, wi) for ti, wi in zip(t, w)])
    assert_allclose(T, T[0], rtol=REF_ENERGY_RTOL)


# ---------------------------------------------------------------------------------------------
# Library vs reference
# ---------------------------------------------------------------------------------------------


def _H_scale(H):
    return np.linalg.norm(H, axis=1).max()


def _assert_matches_reference(tr, formulation, t, q_ref, w_ref, H_ref, att_tol, omega_tol):
    """Same output times; attitude, ω and H_O_N within the given tolerances."""
    assert_allclose(tr["t"], t, rtol=0, atol=0)
    att, _ = _max_errors(tr, q_ref, w_ref)
    assert att < att_tol, f"{formulation}: attitude differs by {att:.3e} rad"
    assert_allclose(tr.omega_BN_B, w_ref, rtol=0, atol=omega_tol)
    assert_allclose(tr.H_O_N, H_ref, rtol=0, atol=H_RTOL * _H_scale(H_ref))


@pytest.mark.parametrize("formulation", FORMULATIONS, ids=FORMULATIONS)
def test_deep_space_articulated_matches_point_masses(deep_space, deep_space_reference, formulation):
    """Torque-free hub + 2 arrays on sine + ramp profiles: q, omega, H_N and T agree."""
    st, scene = deep_space
    t, q_ref, w_ref, H_ref, _ = deep_space_reference
    tr = simulate(scene, formulation=formulation, rtol=RTOL, atol=ATOL)
    _assert_matches_reference(tr, formulation, t, q_ref, w_ref, H_ref, ATT_TOL_RAD, OMEGA_TOL_RAD_S)
    T_ref = np.array([st.kinetic_energy(ti, wi) for ti, wi in zip(t, w_ref)])
    assert_allclose(tr["T"], T_ref, rtol=T_RTOL, atol=0)


@pytest.mark.slow
@pytest.mark.parametrize("formulation", FORMULATIONS, ids=FORMULATIONS)
def test_gravity_gradient_matches_first_order_point_masses(in_orbit, in_orbit_references, formulation):
    """Same first-order gravity-gradient physics on both sides, one orbit: integration error only."""
    _, scene = in_orbit
    t, refs = in_orbit_references
    q_ref, w_ref, H_ref, _ = refs["first_order"]
    tr = simulate(scene, formulation=formulation, rtol=RTOL, atol=ATOL)
    _assert_matches_reference(
        tr, formulation, t, q_ref, w_ref, H_ref, GG_FIRST_ORDER_ATT_TOL_RAD, GG_FIRST_ORDER_OMEGA_TOL_RAD_S
    )


def test_exact_gravity_reference_differs_from_first_order_only_at_order_rho_over_R(in_orbit_references):
    """Guards the exact-gravity test below: the torque acts strongly (H_N changes by more than its
    initial size over the orbit) while exact and first-order gravity stay within the tolerance."""
    _, refs = in_orbit_references
    q_ex, w_ex, H_ex, _ = refs["exact"]
    q_fo, w_fo, H_fo, _ = refs["first_order"]
    assert np.linalg.norm(H_fo[-1] - H_fo[0]) > np.linalg.norm(H_fo[0])
    assert max(principal_angle(a, b) for a, b in zip(q_ex, q_fo)) < EXACT_GG_ATT_TOL_RAD
    assert_allclose(w_ex, w_fo, rtol=0, atol=EXACT_GG_OMEGA_TOL_RAD_S)


def test_gravity_gradient_matches_exact_inverse_square(in_orbit, in_orbit_references):
    """Exact per-particle inverse-square gravity vs the library's first-order torque, one orbit."""
    _, scene = in_orbit
    _, refs = in_orbit_references
    q_ex, w_ex, _, _ = refs["exact"]
    tr = simulate(scene, rtol=RTOL, atol=ATOL)
    att, _ = _max_errors(tr, q_ex, w_ex)
    assert att < EXACT_GG_ATT_TOL_RAD, f"attitude differs from exact gravity by {att:.3e} rad"
    assert_allclose(tr.omega_BN_B, w_ex, rtol=0, atol=EXACT_GG_OMEGA_TOL_RAD_S)
