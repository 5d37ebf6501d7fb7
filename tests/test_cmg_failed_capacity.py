"""A failed CMG unit in the momentum figures (issue 19 A4): capacity, the saturation flag and the
metrics (``max_h_Nms``, ``max_h_fraction``, the Monte Carlo's ``h_fraction`` envelope) follow the
*working* units. A failed unit's gimbals are held, so its rotor momentum ``h_held`` is a constant
vector in B; the working units' momentum is ``h - h_held`` and moves in their own envelope.

Truths, by hand: the double-gimbal envelope is a sphere of radius (working units) x h_rotor; the
pyramid's extent along a body axis is the sum over the working units of the largest component of
each unit's momentum, from Wie's closed-form unit momenta (B. Wie, Space Vehicle Dynamics and
Control, 2nd ed., §7.3; ``wie_pyramid_h`` of test_cmg.py, unit by unit), each ``a cos δ + b sin δ``
at most ``sqrt(a² + b²)``; the default DGCMG layout's unit 2 spins along +x at zero angles
(``DG_SPIN0`` of test_cmg.py).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import load_scene, simulate
from stationbed.model.cmg import capacity, cluster_functions, held_momentum_B
from stationbed.run.working_h import WorkingH
from stationbed.scene import Cmg
from stationbed.studies.montecarlo.samples import EnvelopeSink

H0 = 1000.0  # N m s, rotor momentum
BETA = math.atan2(4.0, 3.0)  # rad, pyramid skew: cos β = 0.6, sin β = 0.8
#: float64 round-off of sums of a few unit vectors times h0
ROUNDOFF = 1e-12 * H0


def wie_unit_extent(unit: int, axis: int, beta=BETA) -> float:
    """Largest component along body axis ``axis`` of pyramid unit ``unit`` (1-based), per h0:
    Wie's unit momenta ``(-cβ s1, c1, sβ s1)``, ``(-c2, -cβ s2, sβ s2)``, ``(cβ s3, -c3, sβ s3)``,
    ``(c4, cβ s4, sβ s4)``, each component ``a cos δ + b sin δ`` (max ``sqrt(a² + b²)``)."""
    cb, sb = math.cos(beta), math.sin(beta)
    ab = {  # (a: coefficient of cos δ, b: of sin δ) per axis
        1: [(0, -cb), (1, 0), (0, sb)],
        2: [(-1, 0), (0, -cb), (0, sb)],
        3: [(0, cb), (-1, 0), (0, sb)],
        4: [(1, 0), (0, cb), (0, sb)],
    }[unit][axis]
    return math.hypot(*ab)


def pyramid_capacity_by_hand(failed) -> float:
    work = [u for u in (1, 2, 3, 4) if u not in failed]
    return H0 * min(sum(wie_unit_extent(u, ax) for u in work) for ax in range(3))


@pytest.mark.parametrize("failed", [[], [2], [1, 3]], ids=["none", "unit2", "units1_3"])
def test_dgcmg_capacity_is_the_working_units(failed):
    c = Cmg(kind="dgcmg", h_rotor=H0, failed=failed)
    assert capacity(c) == pytest.approx((4 - len(failed)) * H0, rel=1e-15)


@pytest.mark.parametrize("failed", [[], [2], [1], [1, 2]], ids=["none", "unit2", "unit1", "units1_2"])
def test_pyramid_capacity_is_the_working_units_envelope(failed):
    """No failure: 3.2 h0 (the closed form min(2 + 2 cos β, 4 sin β)); unit 2 failed:
    min(1 + 2 cos β, 2 + cos β, 3 sin β) = 2.2 h0."""
    c = Cmg(kind="sgcmg_pyramid", h_rotor=H0, skew=BETA, failed=failed)
    assert capacity(c) == pytest.approx(pyramid_capacity_by_hand(failed), rel=1e-14)
    if failed == [2]:
        assert capacity(c) == pytest.approx(2.2 * H0, rel=1e-14)


def test_held_momentum_is_the_failed_units_rotor():
    """Default DGCMG layout at zero angles: unit 2 spins along +x, unit 4 along -x."""
    assert_allclose(held_momentum_B(Cmg(kind="dgcmg", h_rotor=H0, failed=[2])), [H0, 0, 0], atol=ROUNDOFF)
    assert_allclose(held_momentum_B(Cmg(kind="dgcmg", h_rotor=H0, failed=[2, 4])), 0.0, atol=ROUNDOFF)
    assert_allclose(held_momentum_B(Cmg(kind="dgcmg", h_rotor=H0)), 0.0, atol=0)


#: default DGCMG angles (outer, inner per unit) with units 1, 3, 4 spinning along -x, unit 2 at
#: zero (+x): the working units hold 3 h0 along -x, the cluster 2 h0
THREE_ALONG_MINUS_X = np.deg2rad([0.0, -90.0, 0.0, 0.0, 0.0, 90.0, 0.0, 0.0])


def test_saturation_flag_follows_the_working_units():
    """Unit 2 failed: the working units at their full 3 h0 (>= 0.9 x 3 h0) are saturated although
    the cluster's |h| is 2 h0 (below 0.9 of both the working and the four-unit capacity)."""
    c = Cmg(kind="dgcmg", h_rotor=H0, failed=[2])
    f = cluster_functions(c)
    assert_allclose(np.array(f["h"](THREE_ALONG_MINUS_X)).ravel(), [-2 * H0, 0, 0], atol=ROUNDOFF)
    _, _, _, sat = f["actuate"](0.0, THREE_ALONG_MINUS_X, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert float(sat) == 1.0
    f4 = cluster_functions(Cmg(kind="dgcmg", h_rotor=H0))  # all working: |h| = 2 h0 of 4 h0
    _, _, _, sat4 = f4["actuate"](0.0, THREE_ALONG_MINUS_X, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert float(sat4) == 0.0


@pytest.fixture(scope="module")
def failed_run():
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    return simulate(scene.replace({"simulation.duration": 60.0, "cmg.failed": [2]}))


def test_run_metrics_follow_the_working_units(failed_run):
    """iss_lvlh_hold with unit 2 failed: capacity 3 x 4760 N m s, the held momentum 4760 N m s
    along +x, and max_h_Nms = max |h - h_held| over the rows (the working units start holding
    -h_held: the cluster's h is 0 at t = 0)."""
    tr = failed_run
    s = tr.meta["summary"]
    h_rotor = 4760.0  # N m s, the scene's
    assert s["h_capacity_Nms"] == pytest.approx(3 * h_rotor, rel=1e-15)
    assert_allclose(s["h_held_B_Nms"], [h_rotor, 0.0, 0.0], atol=1e-9)
    h = tr.cols("hx", "hy", "hz")
    assert_allclose(h[0], 0.0, atol=1e-9)
    expect = np.linalg.norm(h - [h_rotor, 0.0, 0.0], axis=1).max()
    assert s["max_h_Nms"] == pytest.approx(expect, rel=1e-12)
    assert s["max_h_fraction"] == pytest.approx(expect / (3 * h_rotor), rel=1e-12)
    assert s["max_h_fraction"] >= 1.0 / 3.0


def test_trajectory_metrics_recompute_the_same(failed_run):
    """``trajectory_metrics`` (compare, the dashboard) from the rows and the summary alone."""
    from stationbed.run.metrics import trajectory_metrics

    v = trajectory_metrics(failed_run)
    s = failed_run.meta["summary"]
    assert v["max_h_Nms"] == pytest.approx(s["max_h_Nms"], rel=1e-15)
    assert v["max_h_fraction"] == pytest.approx(s["max_h_fraction"], rel=1e-15)


def test_montecarlo_envelope_fraction_follows_the_working_units():
    """The envelope's h_fraction per row: |h - h_held| / capacity of the working units."""
    cols = ["t", "att_err_deg", "hx", "hy", "hz"]
    rows = np.array([[0.0, 1.0, 0.0, 0.0, 0.0], [10.0, 2.0, -2 * H0, 0.0, 0.0]])
    sink = EnvelopeSink(cols, 10.0, 2, WorkingH(cols, 3 * H0, h_held_B=[H0, 0.0, 0.0]))
    sink.write(rows)
    assert_allclose(sink.values[:, 1], [1.0 / 3.0, 1.0], rtol=1e-15)
