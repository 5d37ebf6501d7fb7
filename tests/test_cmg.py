"""CMG cluster model (stationbed/model/cmg/) against independent truths, at the unit level.

Truths used (none of them calls the library's own geometry or steering code):

* Wie's closed-form pyramid momentum and Jacobian (B. Wie, Space Vehicle Dynamics and Control,
  2nd ed., §7.3; JGCD 28(5), 2005): ``h/h0 = (-cβ s1 - c2 + cβ s3 + c4, c1 - cβ s2 - c3 + cβ s4,
  sβ Σ s_i)``;
* double-gimbal spin axes built as rotations with ``scipy.spatial.transform`` (the inner gimbal
  is carried by the outer one: ``s = R(δo e1) R(δi e2) e3``), on the documented default layout;
* central finite differences of ``h(δ)``;
* the steering laws' algebra (``Â δ̇ = ḣ`` for Moore-Penrose; the regularisation ``λ E`` recovered
  from the law's outputs and compared with Wie's 2005 definition);
* closed-form singularity measures (``4 cos²β sin β`` for the pyramid at δ = 0, 4 for the default
  DGCMG layout at zero angles, 0 at the known singular configurations).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed.model.cmg import CmgModel, cluster_functions
from stationbed.scene import Cmg

BETA_WIE_RAD = math.atan2(4.0, 3.0)  # 53.13 deg: cos β = 0.6, sin β = 0.8
H0 = 1000.0  # N m s, rotor momentum used throughout
#: Pyramid configuration where Moore-Penrose stalls for a command along x (Wie 2005):
#: h = 2 cos β h0 x̂ and every Jacobian column is orthogonal to x.
DELTA_2H_SING = np.deg2rad([-90.0, 0.0, 90.0, 0.0])
#: External (saturation) singularity of the pyramid: h = 4 sin β h0 ẑ.
DELTA_Z_SAT = np.deg2rad([90.0, 90.0, 90.0, 90.0])
#: Default DGCMG layout (stationbed/model/cmg/dgcmg.py, dgcmg_triads): outer axes and zero-angle spins.
DG_OUTER = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
DG_SPIN0 = np.array([[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]], float)
#: Default DGCMG angles (outer, inner per unit) that align every spin with +z: saturation, h = 4 h0 ẑ.
DG_ALL_Z = np.deg2rad([0.0, 0.0, -90.0, 0.0, 180.0, 0.0, -90.0, 0.0])

# -- tolerances (each with its reason) ------------------------------------------------------
#: float64 round-off of a few dozen trig/products, relative to h0
ROUNDOFF_REL = 1e-12
#: central differences with step 1e-6 rad: truncation ~h0 ε²/6 ≈ 2e-13 h0, round-off ~1e-16/ε = 1e-10 h0
FD_STEP_RAD = 1e-6
FD_REL = 1e-8
#: Moore-Penrose adds MP_FLOOR = 1e-12 to Â Âᵀ; at configurations with σ²_min(Â Âᵀ) ≥ 0.05 that
#: is ≤ 2e-11 relative torque error, plus round-off
MP_TORQUE_REL = 1e-10
#: recovering λE = M - Â Âᵀ from three steering solutions loses ~cond(Â Âᵀ) digits (< 1e3 here)
E_RECOVERY_ABS = 1e-10


# -- independent models -------------------------------------------------------------------------
def wie_pyramid_h(delta, beta=BETA_WIE_RAD, h0=H0):
    s, c = np.sin(delta), np.cos(delta)
    cb, sb = math.cos(beta), math.sin(beta)
    return h0 * np.array(
        [
            -cb * s[0] - c[1] + cb * s[2] + c[3],
            c[0] - cb * s[1] - c[2] + cb * s[3],
            sb * (s[0] + s[1] + s[2] + s[3]),
        ]
    )


def wie_pyramid_A(delta, beta=BETA_WIE_RAD, h0=H0):
    """∂h/∂δ of Wie's closed form, differentiated by hand [N m s/rad]."""
    s, c = np.sin(delta), np.cos(delta)
    cb, sb = math.cos(beta), math.sin(beta)
    return h0 * np.array(
        [
            [-cb * c[0], s[1], cb * c[2], -s[3]],
            [-s[0], -cb * c[1], s[2], cb * c[3]],
            [sb * c[0], sb * c[1], sb * c[2], sb * c[3]],
        ]
    )


def dgcmg_spins(angles):
    """Unit spin axes (n, 3) of the default DGCMG layout, by composing scipy rotations."""
    out = []
    for i, (e1, e3) in enumerate(zip(DG_OUTER, DG_SPIN0)):
        e2 = np.cross(e3, e1)  # inner-gimbal axis: (e1, e2, e3) right-handed
        d_out, d_in = angles[2 * i], angles[2 * i + 1]
        R = Rotation.from_rotvec(d_out * e1) * Rotation.from_rotvec(d_in * e2)  # inner carried by outer
        out.append(R.apply(e3))
    return np.array(out)


def dgcmg_h(angles, h0=H0):
    return h0 * dgcmg_spins(angles).sum(axis=0)


def dgcmg_A(angles, h0=H0):
    """∂h/∂δ of the default DGCMG layout by kinematics [N m s/rad]: turning the outer gimbal
    moves the spin at ``e1 × s``, turning the inner one at ``e2' × s`` (``e2' = R(δo e1) e2``, the
    inner axis carried by the outer gimbal)."""
    s = dgcmg_spins(angles)
    cols = []
    for i, (e1, e3) in enumerate(zip(DG_OUTER, DG_SPIN0)):
        e2_turned = Rotation.from_rotvec(angles[2 * i] * e1).apply(np.cross(e3, e1))
        cols += [np.cross(e1, s[i]), np.cross(e2_turned, s[i])]
    return h0 * np.column_stack(cols)


def wie_E(t, eps0, omega):
    """Wie 2005 (JGCD 28(5)) o-DSR weighting: ε_i = ε0 sin(ω t + φ_i), φ = (0, π/2, π)."""
    e1, e2, e3 = (eps0 * math.sin(omega * t + ph) for ph in (0.0, math.pi / 2, math.pi))
    return np.array([[1.0, e3, e2], [e3, 1.0, e1], [e2, e1, 1.0]])


# -- helpers -----------------------------------------------------------------------------------
def cfg(kind="sgcmg_pyramid", **kw):
    base = {"h_rotor": H0}
    if kind == "ideal":
        base = {}
    base.update(kw)
    return Cmg(kind=kind, **base)


def num(x):
    return np.array(x, dtype=float).ravel()


def actuate(f, t, x, tau, w=(0.0, 0.0, 0.0)):
    """``(u, m, rate_or_torque_limited, saturated)`` as numbers."""
    u, m, lim, sat = f["actuate"](t, num(x), num(tau), num(w))
    return num(u), float(m), float(lim), float(sat)


INDEPENDENT = {"sgcmg_pyramid": (wie_pyramid_h, wie_pyramid_A, 4), "dgcmg": (dgcmg_h, dgcmg_A, 8)}


def random_nonsingular(rng, n, kind="sgcmg_pyramid", min_sigma2=0.05):
    """Random gimbal angles with σ²_min(Â Âᵀ) ≥ min_sigma2 (by the independent Jacobian)."""
    _, A_of, ng = INDEPENDENT[kind]
    out = []
    while len(out) < n:
        d = rng.uniform(-math.pi, math.pi, ng)
        Ah = A_of(d) / H0
        if np.linalg.eigvalsh(Ah @ Ah.T)[0] >= min_sigma2:
            out.append(d)
    return out


def random_nonsingular_pyramid(rng, n, min_sigma2=0.05):
    return random_nonsingular(rng, n, "sgcmg_pyramid", min_sigma2)


# =============================================================================================
# momentum and Jacobian
# =============================================================================================
@pytest.mark.parametrize("skew_deg", [53.13010235415598, 30.0, 75.0], ids=["wie53", "skew30", "skew75"])
def test_pyramid_h_matches_wie_closed_form(skew_deg, rng):
    beta = math.radians(skew_deg)
    f = cluster_functions(cfg(skew=beta))
    for d in rng.uniform(-math.pi, math.pi, (20, 4)):
        assert_allclose(num(f["h"](d)), wie_pyramid_h(d, beta), rtol=0, atol=ROUNDOFF_REL * H0)


def test_pyramid_zero_momentum_and_2h_point():
    """Zero momentum at δ = 0; h = 2 cos β h0 x̂ = 1200 N m s at (-90, 0, 90, 0) deg (cos β = 0.6)."""
    f = cluster_functions(cfg(skew=BETA_WIE_RAD))
    assert_allclose(num(f["h"](np.zeros(4))), 0.0, atol=ROUNDOFF_REL * H0)
    assert_allclose(num(f["h"](DELTA_2H_SING)), [1.2 * H0, 0.0, 0.0], atol=ROUNDOFF_REL * H0)


def test_dgcmg_h_matches_scipy_rotations(rng):
    f = cluster_functions(cfg("dgcmg"))
    for ang in rng.uniform(-math.pi, math.pi, (20, 8)):
        assert_allclose(num(f["h"](ang)), dgcmg_h(ang), rtol=0, atol=ROUNDOFF_REL * H0)


def test_dgcmg_default_layout_zero_momentum_and_saturation():
    f = cluster_functions(cfg("dgcmg"))
    assert_allclose(num(f["h"](np.zeros(8))), 0.0, atol=ROUNDOFF_REL * H0)
    # all spins along +z: the envelope, 4 h0 (the capacity the summary's fraction refers to)
    assert_allclose(num(f["h"](DG_ALL_Z)), [0.0, 0.0, 4 * H0], atol=ROUNDOFF_REL * H0)


def test_dgcmg_rotor_momentum_has_constant_magnitude(rng):
    """A single unit on a user outer axis: |h| = h0 at every gimbal angle (gimbals only turn it)."""
    single = cluster_functions(cfg("dgcmg", count=1, outer_axes_B=[[0.3, -0.5, 0.8]]))
    for ang in rng.uniform(-math.pi, math.pi, (20, 2)):
        assert np.linalg.norm(num(single["h"](ang))) == pytest.approx(H0, rel=ROUNDOFF_REL)


JACOBIAN_CASES = {
    "pyramid": dict(kind="sgcmg_pyramid"),
    "pyramid_skew30": dict(kind="sgcmg_pyramid", skew=math.radians(30.0)),
    "dgcmg_default": dict(kind="dgcmg"),
    "dgcmg_user_axes": dict(
        kind="dgcmg", outer_axes_B=[[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 0.0, 1.0], [0.3, -0.5, 0.8]]
    ),
    "dgcmg_6_units": dict(
        kind="dgcmg", count=6, outer_axes_B=[[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]]
    ),
}


@pytest.mark.parametrize("case", list(JACOBIAN_CASES), ids=list(JACOBIAN_CASES))
def test_jacobian_matches_finite_differences(case, rng):
    c = cfg(**JACOBIAN_CASES[case])
    f = cluster_functions(c)
    n = c.n_gimbals
    for x in rng.uniform(-math.pi, math.pi, (5, n)):
        A = np.array(f["A"](x))
        A_fd = np.empty((3, n))
        for j in range(n):
            dx = np.zeros(n)
            dx[j] = FD_STEP_RAD
            A_fd[:, j] = (num(f["h"](x + dx)) - num(f["h"](x - dx))) / (2 * FD_STEP_RAD)
        assert_allclose(A, A_fd, rtol=0, atol=FD_REL * H0)


@pytest.mark.parametrize("kind", list(INDEPENDENT))
def test_jacobian_matches_independent_closed_form(kind, rng):
    """Pyramid: Wie's hand-differentiated A; DGCMG: the spin kinematics (e1 × s, e2' × s)."""
    _, A_of, ng = INDEPENDENT[kind]
    f = cluster_functions(cfg(kind))
    for d in rng.uniform(-math.pi, math.pi, (20, ng)):
        assert_allclose(np.array(f["A"](d)), A_of(d), rtol=0, atol=ROUNDOFF_REL * H0)


# =============================================================================================
# steering laws
# =============================================================================================
LAWS = ["mp", "sr", "odsr"]


@pytest.mark.parametrize("kind", list(INDEPENDENT))
def test_mp_delivers_commanded_hdot_exactly(kind, rng):
    """Moore-Penrose: A δ̇ = ḣ_cmd = -τ - ω × h, away from singularities (no rate limit hit);
    A and h from the independent models."""
    h_of, A_of, _ = INDEPENDENT[kind]
    f = cluster_functions(cfg(kind, steering="mp", max_gimbal_rate=1e6))
    for d in random_nonsingular(rng, 20, kind):
        tau = rng.normal(0.0, 50.0, 3)  # N m
        w = rng.normal(0.0, 0.01, 3)  # rad/s
        u, m, lim, sat = actuate(f, 3.7, d, tau, w)
        hdot_cmd = -tau - np.cross(w, h_of(d))
        assert lim == 0.0
        assert_allclose(A_of(d) @ u, hdot_cmd, rtol=0, atol=MP_TORQUE_REL * np.linalg.norm(hdot_cmd))


def test_mp_is_minimum_norm(rng):
    """Moore-Penrose rates have no null-space component: δ̇ ⟂ null(A) (the minimum-norm solution)."""
    f = cluster_functions(cfg(steering="mp", max_gimbal_rate=1e6))
    for d in random_nonsingular_pyramid(rng, 10):
        u, *_ = actuate(f, 0.0, d, rng.normal(0.0, 50.0, 3))
        null = np.linalg.svd(wie_pyramid_A(d))[2][3]  # the pyramid's one null direction
        assert abs(null @ u) <= 1e-12 * np.linalg.norm(u)


@pytest.mark.parametrize("kind", list(INDEPENDENT))
@pytest.mark.parametrize("law", ["sr", "odsr"])
@pytest.mark.parametrize("mu", [10.0, 0.0], ids=["wie_mu10", "mu0_lambda_eq_lambda0"])
def test_sr_and_odsr_torque_error_set_by_lambda(kind, law, mu, rng):
    """The torque error of SR / o-DSR is λ E M⁻¹ v (v = ḣ/h0, M = Â Âᵀ + λE), so with
    λ = λ0 exp(-μ det(Â Âᵀ)) and 1 - 2ε0 ≤ eig(E) ≤ 1 + 2ε0 it lies between
    λ(1 - 2ε0)/(σ²_max + λ(1 + 2ε0)) ‖v‖ and λ(1 + 2ε0)/(σ²_min - λ(1 + 2ε0)) ‖v‖.

    With Wie's μ = 10 it is negligible away from singularities (λ ~ 1e-7 λ0/0.01); with μ = 0
    (λ = λ0 = 0.01 everywhere) it is ~1 %: the law really regularises, by the amount λ sets.
    """
    _, A_of, _ = INDEPENDENT[kind]
    lam0, eps0 = 0.01, 0.01
    f = cluster_functions(cfg(kind, steering=law, max_gimbal_rate=1e6, sr_lambda0=lam0, sr_mu=mu, dither_eps0=eps0))
    for d in random_nonsingular(rng, 20, kind):
        tau = rng.normal(0.0, 50.0, 3)
        u, *_ = actuate(f, 1.3, d, tau)
        Ah = A_of(d) / H0
        AAt = Ah @ Ah.T
        lam = lam0 * math.exp(-mu * np.linalg.det(AAt))
        eig = np.linalg.eigvalsh(AAt)
        v = -tau / H0
        err = np.linalg.norm(Ah @ u - v) / np.linalg.norm(v)
        upper = lam * (1 + 2 * eps0) / (eig[0] - lam * (1 + 2 * eps0))
        lower = lam * (1 - 2 * eps0) / (eig[-1] + lam * (1 + 2 * eps0))
        assert lower * (1 - 1e-6) - 1e-15 <= err <= upper * (1 + 1e-6) + 1e-15


def recover_lambda_E(f, t, d, A_hat):
    """``λE = M - Â Âᵀ`` from the law's answers to ḣ/h0 = e_1, e_2, e_3 (δ̇_k = Âᵀ M⁻¹ e_k)."""
    R = np.column_stack([actuate(f, t, d, -H0 * e)[0] for e in np.eye(3)])
    P = A_hat @ R  # = Â Âᵀ M⁻¹
    AAt = A_hat @ A_hat.T
    M = np.linalg.solve(P, AAt)
    return M - AAt


@pytest.mark.parametrize("t", [0.0, 0.37, 1.0, 2.9, 11.2], ids=lambda t: f"t{t}")
def test_odsr_weighting_is_wies_E(t):
    """o-DSR's regularisation is λE with Wie's E (ε_i = ε0 sin(ωt + φ_i), φ = 0, π/2, π).

    μ = 0 makes λ = λ0 exactly; λ0 and ε0 are large enough that λE is measured to ~1e-10.
    """
    lam0, eps0, om = 0.5, 0.2, math.pi / 2
    f = cluster_functions(
        cfg(steering="odsr", max_gimbal_rate=1e6, sr_lambda0=lam0, sr_mu=0.0, dither_eps0=eps0, dither_omega=om)
    )
    d = np.deg2rad([10.0, -35.0, 60.0, 120.0])
    lamE = recover_lambda_E(f, t, d, wie_pyramid_A(d) / H0)
    assert_allclose(lamE, lam0 * wie_E(t, eps0, om), rtol=0, atol=E_RECOVERY_ABS)


@pytest.mark.parametrize("law,expected", [("sr", "identity"), ("mp", "zero")])
def test_sr_and_mp_weighting(law, expected):
    """SR regularises with λI (no dither); Moore-Penrose with nothing (its 1e-12 floor only)."""
    lam0 = 0.5
    f = cluster_functions(cfg(steering=law, max_gimbal_rate=1e6, sr_lambda0=lam0, sr_mu=0.0, dither_eps0=0.2))
    d = np.deg2rad([10.0, -35.0, 60.0, 120.0])
    lamE = recover_lambda_E(f, 0.37, d, wie_pyramid_A(d) / H0)
    assert_allclose(lamE, lam0 * np.eye(3) if expected == "identity" else np.zeros((3, 3)), rtol=0, atol=E_RECOVERY_ABS)


@pytest.mark.parametrize("law", ["sr", "odsr"])
def test_lambda_schedule_is_wies(law):
    """λ = λ0 exp(-μ det(Â Âᵀ)) with Wie's λ0 = 0.01, μ = 10, near the 2H singularity (det ≈ 0.02)."""
    lam0, mu = 0.01, 10.0
    f = cluster_functions(cfg(steering=law, max_gimbal_rate=1e6, sr_lambda0=lam0, sr_mu=mu, dither_eps0=0.0))
    d = np.deg2rad([-80.0, 5.0, 80.0, -5.0])
    Ah = wie_pyramid_A(d) / H0
    det = np.linalg.det(Ah @ Ah.T)
    assert 1e-3 < det < 0.1  # close to the singularity: λ is a sizeable fraction of λ0
    lamE = recover_lambda_E(f, 0.0, d, Ah)
    assert_allclose(lamE, lam0 * math.exp(-mu * det) * np.eye(3), rtol=0, atol=E_RECOVERY_ABS)


@pytest.mark.parametrize("kind", ["sgcmg_pyramid", "dgcmg"])
@pytest.mark.parametrize("law", LAWS)
def test_rate_limit_never_exceeded_and_flagged(kind, law, rng):
    """Rates above max_gimbal_rate are scaled down together (same direction) and flagged."""
    max_rate = 0.05  # rad/s
    limited = cluster_functions(cfg(kind, steering=law, max_gimbal_rate=max_rate))
    free = cluster_functions(cfg(kind, steering=law, max_gimbal_rate=1e6))
    n = 4 if kind == "sgcmg_pyramid" else 8
    n_flagged = 0
    for _ in range(30):
        x = rng.uniform(-math.pi, math.pi, n)
        tau = rng.normal(0.0, 1.0, 3) * 10 ** rng.uniform(0.0, 3.0)  # 1 .. 1000 N m
        u, _, lim, _ = actuate(limited, 2.0, x, tau)
        u_free, _, lim_free, _ = actuate(free, 2.0, x, tau)
        assert lim_free == 0.0
        assert np.max(np.abs(u)) <= max_rate * (1 + 1e-14)
        if np.max(np.abs(u_free)) > max_rate:
            n_flagged += 1
            assert lim == 1.0
            scale = max_rate / np.max(np.abs(u_free))
            assert_allclose(u, scale * u_free, rtol=1e-12, atol=0)  # direction kept
        else:
            assert lim == 0.0
            assert_allclose(u, u_free, rtol=1e-14, atol=0)
    assert 5 <= n_flagged <= 25  # both branches were exercised


@pytest.mark.parametrize("kind", ["sgcmg_pyramid", "dgcmg"])
def test_direct_gimbal_rates_are_limited_and_flagged(kind):
    """A controller commanding gimbal rates bypasses the steering law, not the rate limit."""
    c = cfg(kind, max_gimbal_rate=0.1)
    model = CmgModel(c.kind, c.n_units, c.steering)
    p = ca.DM(model.params(c))
    x = ca.DM(np.linspace(-1.0, 1.0, c.n_gimbals))
    zero = ca.DM.zeros(3)
    slow = np.linspace(-0.05, 0.08, c.n_gimbals)
    u, _, lim, _ = model.actuate(0.0, x, zero, zero, p, direct_rates=ca.DM(slow))
    assert_allclose(num(ca.evalf(u)), slow, rtol=1e-15)
    assert float(ca.evalf(lim)) == 0.0
    fast = 4.0 * slow  # peak 0.32 rad/s
    u, _, lim, _ = model.actuate(0.0, x, zero, zero, p, direct_rates=ca.DM(fast))
    assert_allclose(num(ca.evalf(u)), fast * (0.1 / 0.32), rtol=1e-14)
    assert float(ca.evalf(lim)) == 1.0


# =============================================================================================
# singularity measure
# =============================================================================================
def test_pyramid_singularity_measure_closed_form_at_zero():
    """δ = 0: Â Âᵀ = diag(2cos²β, 2cos²β, 4sin²β), so m = 4 cos²β sin β (= 1.152 at 53.13 deg)."""
    f = cluster_functions(cfg())
    _, m, _, _ = actuate(f, 0.0, np.zeros(4), [1.0, 0.0, 0.0])
    cb, sb = 0.6, 0.8
    assert m == pytest.approx(4 * cb**2 * sb, rel=ROUNDOFF_REL)


@pytest.mark.parametrize(
    "kind,x",
    [("sgcmg_pyramid", DELTA_2H_SING), ("sgcmg_pyramid", DELTA_Z_SAT), ("dgcmg", DG_ALL_Z)],
    ids=["pyramid_2h_internal", "pyramid_z_saturation", "dgcmg_all_spins_z"],
)
def test_singularity_measure_zero_at_known_singularities(kind, x):
    f = cluster_functions(cfg(kind))
    _, m, _, _ = actuate(f, 0.0, x, [1.0, 0.0, 0.0])
    assert m <= 1e-7  # sqrt of a determinant that is 0 to round-off (~1e-16)


def test_pyramid_2h_singular_direction_is_x():
    """At (-90, 0, 90, 0) deg every Jacobian column is orthogonal to x (no torque about x)."""
    A = wie_pyramid_A(DELTA_2H_SING)
    assert_allclose(A[0], 0.0, atol=ROUNDOFF_REL * H0)
    assert np.linalg.matrix_rank(A[1:], tol=1e-9 * H0) == 2


def test_singularity_measure_matches_independent_det_elsewhere(rng):
    f = cluster_functions(cfg())
    for d in rng.uniform(-math.pi, math.pi, (20, 4)):
        Ah = wie_pyramid_A(d) / H0
        _, m, _, _ = actuate(f, 0.0, d, [1.0, 0.0, 0.0])
        expected = math.sqrt(max(np.linalg.det(Ah @ Ah.T), 0.0))
        assert m == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert m > 0.0  # random configurations are non-singular (the singular set has measure zero)


def test_dgcmg_singularity_measure_at_zero_angles():
    """Default layout at zero angles: Â Âᵀ = Σ (e1 e1ᵀ + e2 e2ᵀ) = diag(2, 4, 2), m = 4."""
    f = cluster_functions(cfg("dgcmg"))
    _, m, _, _ = actuate(f, 0.0, np.zeros(8), [1.0, 0.0, 0.0])
    assert m == pytest.approx(4.0, rel=ROUNDOFF_REL)


# =============================================================================================
# ideal CMG: torque and momentum limits, applied and flagged
# =============================================================================================
def test_ideal_torque_limit_keeps_direction_and_flags():
    f = cluster_functions(cfg("ideal", max_torque=10.0))
    u, _, lim, sat = actuate(f, 0.0, [0.0, 0.0, 0.0], [30.0, 40.0, 0.0])
    assert_allclose(u, [6.0, 8.0, 0.0], rtol=1e-15)
    assert (lim, sat) == (1.0, 0.0)
    u, _, lim, sat = actuate(f, 0.0, [0.0, 0.0, 0.0], [3.0, 4.0, 0.0])
    assert_allclose(u, [3.0, 4.0, 0.0], rtol=1e-15)
    assert (lim, sat) == (0.0, 0.0)


def test_ideal_full_store_refuses_to_fill_but_drains():
    """|h| = max_momentum: the part of τ that would grow |h| (ḣ = -τ, τ·h < 0) is removed."""
    f = cluster_functions(cfg("ideal", max_momentum=100.0))
    h_full = [100.0, 0.0, 0.0]  # N m s
    u, _, lim, sat = actuate(f, 0.0, h_full, [-5.0, 3.0, 0.0])  # would push h further along +x
    assert_allclose(u, [0.0, 3.0, 0.0], atol=1e-15)
    assert sat == 1.0
    u, _, lim, sat = actuate(f, 0.0, h_full, [5.0, 3.0, 0.0])  # drains: passes unchanged
    assert_allclose(u, [5.0, 3.0, 0.0], rtol=1e-15)
    assert sat == 1.0  # still flagged: at 100 % of capacity (≥ saturation_fraction 0.9)
    u, _, lim, sat = actuate(f, 0.0, [50.0, 0.0, 0.0], [-5.0, 3.0, 0.0])
    assert_allclose(u, [-5.0, 3.0, 0.0], rtol=1e-15)
    assert sat == 0.0


def test_ideal_limits_never_silent(rng):
    """Whenever the delivered torque differs from the request, a flag says so."""
    f = cluster_functions(cfg("ideal", max_torque=20.0, max_momentum=100.0, saturation_fraction=0.95))
    n_changed = 0
    for _ in range(200):
        h = rng.normal(0.0, 1.0, 3)
        h *= rng.uniform(0.0, 110.0) / np.linalg.norm(h)
        tau = rng.normal(0.0, 15.0, 3)
        u, _, lim, sat = actuate(f, 0.0, h, tau)
        if np.linalg.norm(u - tau) > 1e-12 * np.linalg.norm(tau):
            n_changed += 1
            assert lim == 1.0 or sat == 1.0
        assert np.linalg.norm(u) <= 20.0 * (1 + 1e-14)
        if np.linalg.norm(h) >= 100.0:
            assert u @ h >= -1e-9 * np.linalg.norm(h)  # ḣ·h = -u·h ≤ 0: the store does not grow
    assert n_changed >= 20


@pytest.mark.parametrize("kind", ["sgcmg_pyramid", "dgcmg"])
def test_healthy_cluster_leaves_the_fault_numbers_out(kind, rng):
    """A scene without ``[[fault]]`` (``unit_faults`` False): h, its derivative and the actuation
    read no unit's ``rotor`` or ``rate_cap`` (the fused tick of iss_lvlh_hold carried ~130 SX
    instructions of them: x 1 and a clamp at RATE_CAP_NONE), and give the faultable cluster's
    numbers bit for bit at the scene's (healthy) numbers."""
    c = cfg(kind, steering="sr")
    healthy, faultable = (CmgModel(c.kind, c.n_units, c.steering, faults) for faults in (False, True))
    t, pc = ca.SX.sym("t"), ca.SX.sym("pc", healthy.n_par)
    xc, uc, w, tau = ca.SX.sym("x", healthy.nx), ca.SX.sym("u", healthy.nu), ca.SX.sym("w", 3), ca.SX.sym("tau", 3)
    tail = [healthy.geometry.unit_index(name, u) for name in ("rotor", "rate_cap") for u in range(1, c.n_units + 1)]

    def outputs(m):
        return [m.h(xc, pc), m.h_dot(xc, uc, w, pc), *m.actuate(t, xc, tau, w, pc)]

    def reads_tail(m):
        return [any(ca.depends_on(e, pc[i]) for i in tail) for e in outputs(m)]

    assert not any(reads_tail(healthy))
    assert reads_tail(faultable)[0] and reads_tail(faultable)[2]  # (the check can see a read)
    args = [0.7, rng.uniform(-1.0, 1.0, healthy.nx), rng.uniform(-0.01, 0.01, healthy.nu), rng.normal(0.0, 1e-3, 3),
            rng.normal(0.0, 50.0, 3), healthy.params(c)]
    numbers = [ca.Function("f", [t, xc, uc, w, tau, pc], outputs(m))(*args) for m in (healthy, faultable)]
    for a, b in zip(*numbers):
        np.testing.assert_array_equal(num(a), num(b))


def test_structure_knows_a_scene_with_faults():
    """The structure (and its key, the compiled library's and the composed loop's caches) tells a
    scene with ``[[fault]]`` from one without: the same cluster, two codes."""
    from pathlib import Path

    from stationbed.model.structure import Structure
    from stationbed.scene import load_scene

    scenarios = Path(__file__).resolve().parents[1] / "scenarios"
    plain = Structure.of(load_scene(scenarios / "iss_lvlh_hold.toml"))
    faulted = Structure.of(load_scene(scenarios / "iss_cmg_failure_fdir.toml"))
    assert plain.cmg == ("dgcmg", 4, "sr", False) and faulted.cmg == ("dgcmg", 4, "sr", True)
    assert "cdgcmg4srE" in plain.key and "cdgcmg4sruE" in faulted.key
