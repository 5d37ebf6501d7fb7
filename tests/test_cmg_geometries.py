"""One contract for every registered CMG geometry (stationbed/model/cmg/, ``CMG_GEOMETRIES``).

Each test is parametrized over the registry (gimballed or momentum-store kinds by their declared
``gimbals_per_unit``), so a new geometry is checked the moment it is registered, with the scene's
defaults (``Cmg(kind=...)``) or the example in ``EXAMPLES``. The independent truths of each
geometry (Wie's pyramid, scipy rotations for the DGCMG) are in tests/test_cmg.py.

Claims: the cluster's h is the sum of its units' momenta (the symbolic model and the numpy
drawing agree); each rotor's momentum has the constant magnitude h_rotor; the Jacobian is the
derivative of h; the capacity is positive and no larger than all rotors aligned; the gimbal names
match the gimbal count the scene validates against; the registry and the scene's kinds agree.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed.model.cmg import CMG_GEOMETRIES, CmgModel, cluster_functions, cmg_geometry
from stationbed.run.rows import trajectory_columns
from stationbed.scene import CMG_KINDS, Cmg, scene_from_dict
from scenes import RIGID

H_ROTOR = 500.0  # N m s
#: per kind a non-default table (user axes, another skew); kinds not listed use the defaults
EXAMPLES = {
    "ideal": dict(max_momentum=800.0, h0_B=[10.0, -20.0, 5.0]),
    "dgcmg": dict(h_rotor=H_ROTOR, count=3, outer_axes_B=[[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.3, -0.5, 0.8]]),
    "sgcmg_pyramid": dict(h_rotor=H_ROTOR, skew=math.radians(40.0)),
}
KINDS = list(CMG_GEOMETRIES)
GIMBALLED = [k for k in KINDS if CMG_GEOMETRIES[k].gimbals_per_unit]
STORES = [k for k in KINDS if not CMG_GEOMETRIES[k].gimbals_per_unit]

# -- tolerances -------------------------------------------------------------------------------
#: float64 round-off of a few dozen trig/products, relative to h_rotor
ROUNDOFF_REL = 1e-12
#: central differences, step 1e-6 rad: truncation ~ε²/6, round-off ~1e-16/ε, relative to h_rotor
FD_STEP_RAD = 1e-6
FD_REL = 1e-8


def cfg(kind):
    return Cmg(kind=kind, **EXAMPLES.get(kind, {}))


def num(x):
    return np.array(x, dtype=float).ravel()


@pytest.mark.parametrize("kind", GIMBALLED)
def test_h_is_the_sum_of_the_unit_momenta(kind, rng):
    """The compiled model's h (casadi) equals Σ unit_momenta_B (numpy, what the drawing shows)."""
    c = cfg(kind)
    geo, f = cmg_geometry(c), cluster_functions(c)
    angles = rng.uniform(-math.pi, math.pi, (10, geo.n_gimbals))
    units = geo.unit_momenta_B(c, angles)
    assert units.shape == (10, geo.n_units, 3)
    for x, u in zip(angles, units):
        assert_allclose(num(f["h"](x)), u.sum(axis=0), rtol=0, atol=ROUNDOFF_REL * c.h_rotor)


@pytest.mark.parametrize("kind", GIMBALLED)
def test_each_rotor_keeps_its_momentum_magnitude(kind, rng):
    """Gimbals only turn a rotor: |h_i| = h_rotor at every angle."""
    c = cfg(kind)
    geo = cmg_geometry(c)
    units = geo.unit_momenta_B(c, rng.uniform(-math.pi, math.pi, (20, geo.n_gimbals)))
    assert_allclose(np.linalg.norm(units, axis=-1), c.h_rotor, rtol=ROUNDOFF_REL)


@pytest.mark.parametrize("kind", GIMBALLED)
def test_jacobian_is_the_derivative_of_h(kind, rng):
    c = cfg(kind)
    f = cluster_functions(c)
    n = c.n_gimbals
    for x in rng.uniform(-math.pi, math.pi, (3, n)):
        A_fd = np.column_stack(
            [(num(f["h"](x + FD_STEP_RAD * e)) - num(f["h"](x - FD_STEP_RAD * e))) / (2 * FD_STEP_RAD) for e in np.eye(n)]
        )
        assert_allclose(np.array(f["A"](x)), A_fd, rtol=0, atol=FD_REL * c.h_rotor)


@pytest.mark.parametrize("kind", GIMBALLED)
def test_capacity_positive_and_at_most_all_rotors_aligned(kind):
    c = cfg(kind)
    assert 0.0 < cmg_geometry(c).capacity(c) <= c.n_units * c.h_rotor * (1 + ROUNDOFF_REL)


@pytest.mark.parametrize("kind", STORES)
def test_momentum_store_capacity_is_its_limit_and_its_state_is_h(kind):
    c = cfg(kind)
    model = CmgModel.of(c)
    assert model.geometry.capacity(c) == c.max_momentum > 0.0
    x = model.initial_state(c)
    assert_allclose(num(cluster_functions(c)["h"](x)), c.h0_B, rtol=0, atol=0)


@pytest.mark.parametrize("kind", KINDS)
def test_gimbal_names_match_the_gimbal_count(kind):
    """As many distinct gimbal names as gimbals (the scene's count), and they are the run's columns."""
    c = cfg(kind)
    model = CmgModel.of(c)
    names = model.gimbal_names
    assert len(names) == len(set(names)) == model.n_gimbals == c.n_gimbals
    cols = trajectory_columns(scene_from_dict(dict(RIGID, cmg=c.model_dump())))
    assert all(n in cols and f"{n}_rate" in cols for n in names)


@pytest.mark.parametrize("kind", KINDS)
def test_parameters_and_initial_state_fill_the_declared_layout(kind):
    """params has n_par numbers and the symbolic h reads the geometry from them (h(x0) finite)."""
    c = cfg(kind)
    model = CmgModel.of(c)
    p = model.params(c)
    x0 = model.initial_state(c)
    assert p.shape == (model.n_par,) and x0.shape == (model.nx,)
    h0 = num(ca.evalf(model.h(ca.DM(x0), ca.DM(p))))
    assert np.all(np.isfinite(h0))


@pytest.mark.parametrize("kind", GIMBALLED)
def test_mount_axes_are_unit_vectors_one_per_unit(kind):
    c = cfg(kind)
    axes = cmg_geometry(c).mount_axes_B(c)
    assert axes.shape == (c.n_units, 3)
    assert_allclose(np.linalg.norm(axes, axis=1), 1.0, rtol=ROUNDOFF_REL)


def test_registry_and_scene_know_the_same_kinds():
    """The scene validates exactly the kinds the model has, with the same gimbals per unit."""
    assert set(CMG_GEOMETRIES) == set(CMG_KINDS)
    for kind, cls in CMG_GEOMETRIES.items():
        assert cls.gimbals_per_unit == CMG_KINDS[kind].gimbals


@pytest.mark.parametrize("kind", GIMBALLED)
def test_envelope_of_the_units_left_is_the_capacity_with_the_others_failed(kind):
    """``envelope(pc, weights)`` (the saturation flag's capacity of the units that move, symbolic)
    times h_rotor is the kind's ``capacity`` of the scene with the units of weight 0 failed, for
    every set of failed units but all."""
    import itertools  # noqa: PLC0415

    c = cfg(kind)
    geo = cmg_geometry(c)
    pc = geo.params(c)
    for k in range(geo.n_units):
        for failed in itertools.combinations(range(1, geo.n_units + 1), k):
            w = [0.0 if i + 1 in failed else 1.0 for i in range(geo.n_units)]
            got = float(geo.envelope(ca.DM(pc), w)) * c.h_rotor
            assert got == pytest.approx(geo.capacity(c.model_copy(update={"failed": list(failed)})), rel=ROUNDOFF_REL)
