"""Mass properties: validity checks, the Coriolis matrix, and the TP-2511 Appendix A identity."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed.core.massprops import InvalidMassProperties, check_inertia, composite_cm, coriolis_matrix, parallel_axis

REL = 1e-12  # float64 sums over a few hundred points


def cloud(rng, n=200):
    m = rng.uniform(0.5, 2.0, size=n)  # kg
    r = rng.normal(size=(n, 3)) * [3.0, 1.0, 0.2]  # m, a flat-ish plate
    r -= m @ r / m.sum()  # about its own mass centre
    return m, r


def inertia_of(m, r):
    return sum(mi * (ri @ ri * np.eye(3) - np.outer(ri, ri)) for mi, ri in zip(m, r))


def test_coriolis_matrix_is_twice_second_moment(rng):
    """C*_p = tr(I_p) E - 2 I_p equals 2 ∫ l lᵀ dm (TP Eq. 13/42) on point clouds."""
    for _ in range(5):
        m, r = cloud(rng)
        second_moment = sum(mi * np.outer(ri, ri) for mi, ri in zip(m, r))
        assert_allclose(coriolis_matrix(inertia_of(m, r)), 2 * second_moment, rtol=REL, atol=REL * second_moment.max())


@pytest.mark.parametrize("case", range(20))
def test_appendix_a_identity(rng, case):
    """TP-2511 Appendix A: ω_p × I_p ω - I_p(ω_p × ω) + ω × I_p ω_p = (C*_p ω) × ω_p."""
    m, r = cloud(rng, 50)
    I_p = inertia_of(m, r)
    # rotate into a random B orientation so I_p is full
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    I_p = Q @ I_p @ Q.T
    w, w_p = rng.normal(size=(2, 3))
    lhs = np.cross(w_p, I_p @ w) - I_p @ np.cross(w_p, w) + np.cross(w, I_p @ w_p)
    rhs = np.cross(coriolis_matrix(I_p) @ w, w_p)
    assert_allclose(lhs, rhs, atol=REL * np.abs(I_p).max() * 10)


def test_parallel_axis_matches_point_sum(rng):
    m, r = cloud(rng)
    d = np.array([1.0, -2.0, 5.0])
    assert_allclose(inertia_of(m, r + d), inertia_of(m, r) + parallel_axis(m.sum(), d), rtol=1e-12)


def test_composite_cm():
    assert_allclose(composite_cm([1.0, 3.0], [[0, 0, 0], [4, 0, 0]]), [3.0, 0, 0])


def test_valid_inertia_passes(rng):
    m, r = cloud(rng)
    J = inertia_of(m, r)
    assert_allclose(check_inertia(J), J)


@pytest.mark.parametrize(
    "J, words",
    [
        ([[1, 0, 0], [0, 1, 0], [0, 0, 3]], "triangle inequality"),
        ([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "not symmetric"),
        ([[1, 0, 0], [0, -1, 0], [0, 0, 1]], "not positive definite"),
        ([[1, 2, 0], [2, 1, 0], [0, 0, 1]], "not positive definite"),
        ([[1, 0, 0], [0, np.nan, 0], [0, 0, 1]], "NaN"),
        ([[1, 0], [0, 1]], "3x3"),
    ],
    ids=["triangle", "asymmetric", "negative", "indefinite", "nan", "shape"],
)
def test_nonphysical_inertia_rejected(J, words):
    with pytest.raises(InvalidMassProperties, match=words):
        check_inertia(np.array(J, dtype=float))


def test_checked_inertia_rows_are_check_inertias_bit_for_bit_and_new_each_time():
    """The scene's inertia check kept per matrix (issue 25): the same symmetrised rows as
    ``check_inertia`` (a matrix seen before included, -0.0 and 0.0 told apart), new lists each
    call (no two scenes share one), the same refusal each time."""
    import math

    from stationbed.core.massprops import checked_inertia_rows

    J = [[100.0, -1.0 / 3.0, 0.0], [-1.0 / 3.0 + 1e-14, 200.0, -0.0], [0.0, 0.0, 250.0]]
    flipped = [[v if v else -v for v in row] for row in J]  # the zeros' signs flipped
    for K in (J, flipped, J):
        got = checked_inertia_rows(K)
        want = check_inertia(np.array(K)).tolist()
        assert got == want
        assert all(math.copysign(1.0, a) == math.copysign(1.0, b) for r, w in zip(got, want) for a, b in zip(r, w))
    a, b = checked_inertia_rows(J), checked_inertia_rows(J)
    assert a == b and a is not b and a[0] is not b[0]
    bad = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]]  # I1 + I2 < I3
    for _ in range(2):
        with pytest.raises(InvalidMassProperties, match="triangle inequality"):
            checked_inertia_rows(bad)
