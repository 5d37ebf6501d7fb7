"""The batched rotation helpers (stationbed/core/rotation_batch.py): the elementwise formulas,
bit for bit, for component-first (4, n) arrays (a law's update_batch must give each sample its
_update's numbers, tests/test_lockstep.py).

Truth: the formulas of DESIGN §3 written out here on the components (numpy elementwise), and
each column through the (4,) path of quat_mult / dcm."""

import numpy as np
import pytest

from stationbed.core.rotation import dcm, quat_mult


def qm_written_out(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw])


def dcm_written_out(q):
    w, x, y, z = q
    s = 2.0 / (w * w + x * x + y * y + z * z)
    return np.array([[1 - s * (y * y + z * z), s * (x * y + w * z), s * (x * z - w * y)],
                     [s * (x * y - w * z), 1 - s * (x * x + z * z), s * (y * z + w * x)],
                     [s * (x * z + w * y), s * (y * z - w * x), 1 - s * (x * x + y * y)]])


def _quats(scale, n=400, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4)) * scale
    q[:3] = 0.0  # zeros and signed zeros: a - b is a + (-b) there too
    q[3:6, 1] = -0.0
    return q.T  # component-first, a strided view as update_batch passes it (meas.q_BN.T)


@pytest.mark.parametrize("scale", [1.0, 1e-9, 1e9], ids=["unit", "tiny", "huge"])
def test_batched_product_is_the_elementwise_one_bit_for_bit(scale):
    p, q = _quats(scale), _quats(1.0, seed=1)
    got = quat_mult(p, q)
    want = qm_written_out(p, q)
    assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
    for k in range(8, 20):  # and each column as the (4,) path computes it
        assert np.array_equal(got[:, k], quat_mult(np.ascontiguousarray(p[:, k]), np.ascontiguousarray(q[:, k])))


@pytest.mark.parametrize("scale", [1.0, 1e-9, 1e9], ids=["unit", "tiny", "huge"])
def test_batched_dcm_is_the_elementwise_one_bit_for_bit(scale):
    q = _quats(scale)[:, 3:]  # (q = 0 has no DCM)
    got = dcm(q)
    assert got.shape == (3, 3, q.shape[1])
    assert np.array_equal(got, dcm_written_out(q))
    for k in range(10):
        assert np.array_equal(got[:, :, k], dcm(np.ascontiguousarray(q[:, k])))
