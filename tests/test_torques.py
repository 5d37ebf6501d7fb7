"""External-torque kinds (stationbed/model/torques.py): one contract for every registered kind.

Every test here is parametrized over ``TORQUES``, so a new kind is checked the moment it is
registered; a kind without an example scene (``EXAMPLES``) or, for a symbolic kind, without an
independent reference torque (``REFERENCE_TORQUE_B``) fails ``test_every_kind_has_an_example``.

Truths used: the torques written out here from their definitions (numpy, the environment's
orbit position), the potential's attitude gradient by casadi AD (for conservative kinds), and
the key strings of the libraries cached before the torque registry existed.
"""

from __future__ import annotations

import copy
import math
import typing

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import RIGID
from stationbed.core.rotation import dcm
from stationbed.formulations.hamel import orientation_gradient, perturbed
from stationbed.model import StationModel, Structure
from stationbed.model.environment import orbit_position_N
from stationbed.model.torques import TORQUES, held_torque_B, torque_breakpoints
from stationbed.scene import Torque, scene_from_dict

KINDS = list(TORQUES)

#: 400 km circular orbit, inclined [m, rad]
ORBIT = {"altitude": 400000.0, "inclination": 0.9006, "u0": 0.4, "gravity_gradient": False}
#: hub inertia with products of inertia [kg m²]
I_HUB_B = [[2.0e6, 1.0e5, -5.0e4], [1.0e5, 1.5e6, 2.0e4], [-5.0e4, 2.0e4, 2.8e6]]

#: per kind, how a scene names it (applied to a rigid hub in orbit without any torque)
EXAMPLES = {
    "constant": lambda d: d.update(
        torque=[
            {"kind": "constant", "torque_B": [1.0, -2.0, 0.5], "start": 10.0, "stop": 40.0},
            {"kind": "constant", "torque_B": [0.0, 3.0, 0.0], "start": 25.0},
        ]
    ),
    "gravity_gradient": lambda d: d["orbit"].update(gravity_gradient=True),
    "orbital_harmonic": lambda d: d.update(
        torque=[
            {"kind": "orbital_harmonic", "bias_B": [0.1, 0.2, -0.3], "cos1_B": [1.0, 0.0, 0.5], "sin2_B": [0.0, -0.7, 0.2]},
            {"kind": "orbital_harmonic", "sin1_B": [0.3, 0.3, 0.0], "cos2_B": [-0.4, 0.0, 0.9], "bias_B": [0.05, 0.0, 0.0]},
        ]
    ),
    "aero": lambda d: d.update(torque=[{"kind": "aero"}], surface=PLATES),
    "srp": lambda d: d.update(torque=[{"kind": "srp"}], surface=PLATES, sun={"direction_N": [0.2, -0.6, 0.77]}),
}
#: two plates on the hub (mass centre at the origin): one two-sided, one one-sided [m², m]
PLATES = [
    {"area": 30.0, "normal": [0.6, 0.0, 0.8], "centre": [1.0, 4.0, -2.0], "two_sided": True, "specular": 0.3, "diffuse": 0.2},
    {"area": 12.0, "normal": [0.0, 1.0, 0.0], "centre": [-3.0, 0.5, 1.0]},
]


def _u(scene, t):
    o = scene.orbit
    return o.u0 + o.mean_motion * t


def harmonic_reference(scene, t, C_BN, I_O_B):
    """``Σ_entries bias + cos1 cos u + sin1 sin u + cos2 cos 2u + sin2 sin 2u`` [N m]."""
    u = _u(scene, t)
    out = np.zeros(3)
    for e in scene.torque:
        out += np.array(e.bias_B) + np.array(e.cos1_B) * math.cos(u) + np.array(e.sin1_B) * math.sin(u)
        out += np.array(e.cos2_B) * math.cos(2 * u) + np.array(e.sin2_B) * math.sin(2 * u)
    return out


def gravity_gradient_reference(scene, t, C_BN, I_O_B):
    """``3 μ/|R|⁵ R_B × (I R_B)`` with the environment's orbit position (point-mass Earth) [N m]."""
    o = scene.orbit
    R_B = C_BN @ orbit_position_N(_u(scene, t), o.radius_m, o.inclination)
    return 3.0 * o.mu / np.linalg.norm(R_B) ** 5 * np.cross(R_B, I_O_B @ R_B)


def _plates(scene):
    for pl in scene.surface:
        n = np.array(pl.normal) / np.linalg.norm(pl.normal)
        yield n, np.array(pl.centre), pl.area, pl.two_sided, pl.fractions


def aero_reference(scene, t, C_BN, I_O_B):
    """``Σ c × (-½ ρ |v|² A cd cos θ v̂)``, windward faces, air co-rotating with the Earth [N m]."""
    o = scene.orbit
    u, n = _u(scene, t), o.mean_motion
    r_N = orbit_position_N(u, o.radius_m, o.inclination)
    v_N = o.radius_m * n * np.array([-math.sin(u), math.cos(u) * math.cos(o.inclination), math.cos(u) * math.sin(o.inclination)])
    v = C_BN @ (v_N - np.cross([0.0, 0.0, 7.292115e-5], r_N))
    rho = 3.725e-12  # kg/m³, Vallado Table 8-4 at the 400 km base
    out = np.zeros(3)
    for nrm, c, A, two, _ in _plates(scene):
        cos = nrm @ v / np.linalg.norm(v)
        cos = abs(cos) if two else max(cos, 0.0)
        out += np.cross(c, -0.5 * rho * (v @ v) * A * 2.2 * cos * v / np.linalg.norm(v))
    return out


def srp_reference(scene, t, C_BN, I_O_B):
    """``Σ c × (-P A cos θ [(1 - ε_s) ŝ + 2 (ε_s cos θ + ε_d / 3) n̂])``, lit faces, P at 1 AU [N m]."""
    s = C_BN @ (np.array(scene.sun.direction_N) / np.linalg.norm(scene.sun.direction_N))
    out = np.zeros(3)
    for nrm, c, A, two, (_, spec, diff) in _plates(scene):
        if two and nrm @ s < 0:
            nrm = -nrm
        cos = nrm @ s
        if cos > 0:
            out += np.cross(c, -4.56e-6 * A * cos * ((1 - spec) * s + 2 * (spec * cos + diff / 3) * nrm))
    return out


#: independent torque of each symbolic kind, B components [N m]
REFERENCE_TORQUE_B = {"orbital_harmonic": harmonic_reference, "gravity_gradient": gravity_gradient_reference,
                      "aero": aero_reference, "srp": srp_reference}

# -- tolerances -------------------------------------------------------------------------------
#: float64 round-off of a few dozen operations, relative to the torque's scale
ROUND_REL = 1e-12
#: the potential's gradient vs the torque: both round-off level, relative to 3 n² tr(I)
GRADIENT_REL = 1e-10


def scene_with(kind):
    d = copy.deepcopy(RIGID)
    d["body"]["inertia"] = I_HUB_B
    d["orbit"] = dict(ORBIT)
    EXAMPLES[kind](d)
    return scene_from_dict(d)


def bare_scene():
    d = copy.deepcopy(RIGID)
    d["orbit"] = dict(ORBIT)
    return scene_from_dict(d)


def symbolic_torque(scene, kind, t, q_BN):
    """The model's torque of ``kind`` alone, built on symbols as in the equations and evaluated
    with the scene's parameter vector; returns it and the inertia I_O_B it used."""
    cls = TORQUES[kind]
    model = StationModel(Structure.of(scene))
    p = model.params(scene)
    ts, qs, ps = ca.SX.sym("t"), ca.SX.sym("q", 4), ca.SX.sym("p", model.layout.size)
    I_O_B = ca.reshape(ps[model.layout["I0"]], 3, 3).T
    p_k = ps[model.layout[kind]] if cls.n_par else None
    orbit = model.orbit_at(ts, ps)
    env = model.environment(qs, orbit, ps, model.arrays(ts, qs, ca.SX(0, 1), ps)) if cls.needs_env else None
    f = ca.Function("L", [ts, qs, ps], [cls.torque_B(ts, qs, I_O_B, p_k, orbit, env)])
    return np.array(f(t, q_BN, p)).ravel(), np.array(p[model.layout["I0"]]).reshape(3, 3)


def random_q(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_has_an_example(kind):
    """The contract tests below can exercise every registered kind."""
    assert kind in EXAMPLES
    assert not TORQUES[kind].symbolic or kind in REFERENCE_TORQUE_B


@pytest.mark.parametrize("kind", KINDS)
def test_kind_is_found_by_its_scene_name(kind):
    cls = TORQUES[kind]
    assert cls.kind == kind
    assert cls.present(scene_with(kind)) and not cls.present(bare_scene())


def test_scene_torque_models_are_the_registered_kinds():
    """Every ``[[torque]]`` model of the scene has a kind here, with the same orbit requirement."""
    members = typing.get_args(typing.get_args(Torque)[0])  # Annotated[Union[...], discriminator]
    listed = {cls.scene_model: cls for cls in TORQUES.values() if cls.scene_model is not None}
    assert set(members) == set(listed)
    for model, cls in listed.items():
        assert model.needs_orbit == cls.needs_orbit


@pytest.mark.parametrize("kind", KINDS)
def test_structure_holds_the_symbolic_kinds_only(kind):
    """A symbolic kind enters the equations (Structure.torques); a held kind only the input."""
    assert (kind in Structure.of(scene_with(kind)).torques) == TORQUES[kind].symbolic


@pytest.mark.parametrize("kind", [k for k in KINDS if TORQUES[k].n_par])
def test_parameters_round_trip(kind):
    """The kind's numbers land in its own slice of p, unchanged."""
    scene = scene_with(kind)
    model = StationModel(Structure.of(scene))
    p = model.params(scene)
    assert_allclose(p[model.layout[kind]], TORQUES[kind].params(scene), rtol=0, atol=0)
    assert p[model.layout[kind]].shape == (TORQUES[kind].n_par,)


@pytest.mark.parametrize("kind", [k for k in KINDS if TORQUES[k].held])
def test_held_torque_piecewise_constant_with_breakpoints_where_declared(kind, rng):
    """Between two consecutive breakpoints the held torque is constant; it changes only there."""
    scene = scene_with(kind)
    edges = sorted({b for b in torque_breakpoints(scene) if math.isfinite(b)})
    assert edges, "the example declares no breakpoint"
    cuts = [edges[0] - 50.0] + edges + [edges[-1] + 50.0]  # s
    levels = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        inside = [held_torque_B(scene, t) for t in rng.uniform(a, b, 20)] + [held_torque_B(scene, a if a in edges else b - 1e-9)]
        for u in inside:
            assert_allclose(u, inside[0], rtol=0, atol=0)
        levels.append(inside[0])
    for left, right in zip(levels[:-1], levels[1:]):
        assert np.any(left != right)  # each declared breakpoint is a real jump in this example


@pytest.mark.parametrize("kind", [k for k in KINDS if TORQUES[k].symbolic])
def test_symbolic_torque_matches_independent_reference(kind, rng):
    scene = scene_with(kind)
    for _ in range(5):
        t, q_BN = rng.uniform(0.0, 6000.0), random_q(rng)  # s
        L_B, I_O_B = symbolic_torque(scene, kind, t, q_BN)
        ref = REFERENCE_TORQUE_B[kind](scene, t, dcm(q_BN), I_O_B)
        assert np.linalg.norm(ref) > 0
        assert_allclose(L_B, ref, rtol=0, atol=ROUND_REL * max(np.linalg.norm(ref), 1.0))


@pytest.mark.parametrize("kind", [k for k in KINDS if TORQUES[k].conservative])
def test_conservative_torque_is_minus_the_potential_gradient(kind, rng):
    """``L = -∂V/∂θ`` with ``δC_BN = -skew(δθ) C_BN`` (DESIGN §4): what lets hamel take it from V."""
    scene = scene_with(kind)
    cls = TORQUES[kind]
    model = StationModel(Structure.of(scene))
    p = model.params(scene)
    t, q_BN = 1234.5, random_q(rng)  # s
    theta, ts, ps = ca.SX.sym("theta", 3), ca.SX.sym("t"), ca.SX.sym("p", model.layout.size)
    I_O_B = ca.reshape(ps[model.layout["I0"]], 3, 3).T
    V = cls.potential_J(perturbed(ca.SX(dcm(q_BN)), theta), I_O_B, model.orbit_at(ts, ps))
    grad = ca.Function("g", [theta, ts, ps], [orientation_gradient(V, None, theta)])(np.zeros(3), t, p)
    L_B, I_num = symbolic_torque(scene, kind, t, q_BN)
    n = scene.orbit.mean_motion
    assert np.linalg.norm(L_B) > 0
    assert_allclose(-np.array(grad).ravel(), L_B, rtol=0, atol=GRADIENT_REL * 3 * n * n * np.trace(I_num))


@pytest.mark.parametrize(
    "kinds,key",
    [((), "a0o1g0h0js0"), (("gravity_gradient",), "a0o1g1h0js0"), (("gravity_gradient", "orbital_harmonic"), "a0o1g1h1js0")],
    ids=["none", "gg", "gg_harmonic"],
)
def test_structure_key_names_the_same_libraries_as_before_the_registry(kinds, key):
    """The key names the cached library: the registry writes gravity gradient and harmonics as
    the flags ``g``/``h`` it always had."""
    assert Structure(n_app=0, orbit=True, torques=kinds).key == key


def test_structure_refuses_kinds_out_of_registry_order():
    with pytest.raises(ValueError, match="registry order"):
        Structure(n_app=0, orbit=True, torques=("orbital_harmonic", "gravity_gradient"))


def test_symbolic_kinds_have_distinct_key_tags():
    """Each symbolic kind's flag in Structure.key is its own letter (two structures never share
    a key, hence a cached library), distinct from the key's other fields (a, o, j, s, c, f)."""
    tags = [cls.key_tag for cls in TORQUES.values() if cls.symbolic]
    assert all(tags) and len(set(tags)) == len(tags)
    assert not set(tags) & set("aojscf")
