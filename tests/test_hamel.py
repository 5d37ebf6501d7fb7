"""The ``hamel`` form (Quinn 1990, seed 000): its identities and its cost.

Agreement with momentum/momentum27/dalembert on every shipped scenario is in
tests/test_equivalence.py, which runs every registered formulation (``hamel`` included).
"""

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed.core.compile import sx_function
from stationbed.model.environment import orbit_position_N
from stationbed.formulations import FORMULATIONS
from stationbed.model import StationModel, Structure
from stationbed.formulations.hamel import HamelForm, orientation_gradient, perturbed
from stationbed.core.rotation import dcm, skew
from stationbed.scene import scene_from_dict
from scenes import RIGID

#: rounding of O(1)-magnitude 3x3 products and AD of the same expressions: a few ulps
ROUND_REL = 1e-13
#: issue 6: a rigid scene through ``hamel`` costs no more than 2x the momentum form
COST_RATIO_MAX = 2.0


def random_dcm(rng):
    q = rng.normal(size=4)
    return dcm(q / np.linalg.norm(q))


def random_inertia(rng):
    """A physical inertia about O: principal moments obeying the triangle inequality, rotated."""
    d = rng.uniform(1.0, 2.0, 3) * 1e6
    R = random_dcm(rng)
    return R @ np.diag(d) @ R.T


def quinn_tilde(a):
    """Quinn's Eq. 8b: ``ã`` is the transpose of the usual cross-product matrix."""
    return np.array(skew(a)).T


def test_quinn_tilde_is_the_transpose_of_skew_and_gives_C_dot():
    """Eq. 8a/8b: Ċ = ω̃ C for C = C_BN; with ω̃ = skew(ω)ᵀ this is the known Ċ_BN = -ω× C_BN."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w = rng.normal(size=3)
    q_dot = 0.5 * np.array([-q[1:] @ w, *(q[0] * w + np.cross(q[1:], w))])  # q ⊗ (0, ω)
    h = 1e-6  # central difference: truncation ~h² |C'''| ~ 1e-12
    C_dot = (dcm(q + h * q_dot) - dcm(q - h * q_dot)) / (2 * h)
    assert_allclose(C_dot, quinn_tilde(w) @ dcm(q), atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_orientation_gradient_by_AD_is_quinns_closed_form(seed):
    """Quinn Eq. 13-19: for T* = bᵀ C n, ∂T*/∂C = b̃ᵀ C n = b × (C n) (DESIGN §4 convention)."""
    rng = np.random.default_rng(seed)
    b, n, C = rng.normal(size=3), rng.normal(size=3), random_dcm(rng)
    theta = ca.SX.sym("theta", 3)
    Cs = ca.SX.sym("C", 3, 3)
    f = ca.dot(ca.DM(b), ca.mtimes(perturbed(Cs, theta), ca.DM(n)))
    g = ca.Function("g", [Cs, theta], [orientation_gradient(f, Cs, theta)])
    got = np.array(g(C, np.zeros(3))).ravel()
    expected = np.cross(b, C @ n)
    assert_allclose(got, expected, rtol=0, atol=ROUND_REL * np.linalg.norm(b) * np.linalg.norm(n))
    assert_allclose(expected, quinn_tilde(b).T @ C @ n, rtol=0, atol=1e-14 * np.linalg.norm(expected))


@pytest.mark.parametrize("seed", range(5))
def test_quinn_eq37_skew_identity(seed):
    """Quinn Eq. 37 (read in the damaged scan as a matrix identity):

    ``ã b̃ + b̃ᵀ ã + (b̃ a)~ = 0`` for all vectors a, b, with ``~`` Quinn's tilde. With
    ``~ = skewᵀ`` it is Jacobi's identity ``[a×][b×] - [b×][a×] = [(a×b)×]``.
    """
    rng = np.random.default_rng(100 + seed)
    a, b = rng.normal(size=3), rng.normal(size=3)
    lhs = quinn_tilde(a) @ quinn_tilde(b) + quinn_tilde(b).T @ quinn_tilde(a) + quinn_tilde(quinn_tilde(b) @ a)
    assert_allclose(lhs, np.zeros((3, 3)), atol=ROUND_REL * np.linalg.norm(a) * np.linalg.norm(b))
    # and it is not vacuous: each term is of order |a||b|
    assert np.linalg.norm(quinn_tilde(a) @ quinn_tilde(b)) > 0.1 * np.linalg.norm(a) * np.linalg.norm(b)


@pytest.mark.parametrize("seed", range(5))
def test_gravity_gradient_torque_from_the_potential(seed):
    """-∂V/∂C of V = (3/2) n² R̂_Bᵀ I R̂_B equals 3 μ/|R|³ R_B × I R_B / |R|² (point-mass Earth)."""
    rng = np.random.default_rng(200 + seed)
    model = StationModel(Structure(n_app=0, orbit=True, torques=("gravity_gradient",)))
    form = HamelForm(model)
    mu = 3.986004418e14  # m³/s², Earth
    radius = rng.uniform(6.6e6, 7.2e6)
    incl, u0 = rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)
    n = np.sqrt(mu / radius**3)
    I = random_inertia(rng)
    p = np.zeros(model.layout.size)
    p[model.layout["I0"]] = I.ravel()
    p[model.layout["orbit"]] = [radius, incl, u0, n, np.cos(incl), np.sin(incl)]
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    t = rng.uniform(0, 5000.0)
    terms = form.terms(t, q, np.zeros(3), np.zeros(0), p, np.zeros(model.nu))
    gT, gV = (np.array(v) for v in terms[6:8])
    R_B = dcm(q) @ orbit_position_N(u0 + n * t, radius, incl)  # environment's orbit, independent of V
    expected = 3 * mu / np.linalg.norm(R_B) ** 5 * np.cross(R_B, I @ R_B)
    assert np.linalg.norm(expected) > 1e-3 * n * n * np.trace(I)  # a real torque, not ~0
    assert_allclose(-gV.ravel(), expected, rtol=0, atol=ROUND_REL * 10 * n * n * np.trace(I))
    assert_allclose(gT.ravel(), 0.0, atol=0)  # T does not depend on the attitude


def rhs_ops(form_name, scene):
    model = StationModel(Structure.of(scene))
    form = FORMULATIONS[form_name](model)
    t, x = ca.SX.sym("t"), ca.SX.sym("x", form.nx)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.layout.size)
    return sx_function("rhs", [t, x, u, p], [form.rhs(t, x, u, p)]).n_instructions()


def test_rigid_scene_costs_at_most_twice_the_momentum_form():
    """Issue 6: the energy/AD form adds no cost a rigid scene would pay for (op count proxy)."""
    scene = scene_from_dict(RIGID)
    ops_h, ops_m = rhs_ops("hamel", scene), rhs_ops("momentum", scene)
    assert ops_h <= COST_RATIO_MAX * ops_m, f"hamel {ops_h} vs momentum {ops_m} instructions"


def test_rigid_scene_in_orbit_costs_at_most_twice_the_momentum_form():
    """Gravity gradient through V (AD of the potential) keeps a rigid scene within 2x momentum."""
    d = dict(RIGID, orbit={"altitude": 400000.0, "inclination": 0.9006, "u0": 0.0, "gravity_gradient": True})
    scene = scene_from_dict(d)
    assert Structure.of(scene).torques == ("gravity_gradient",)
    ops_h, ops_m = rhs_ops("hamel", scene), rhs_ops("momentum", scene)
    assert ops_h <= COST_RATIO_MAX * ops_m, f"hamel {ops_h} vs momentum {ops_m} instructions"
