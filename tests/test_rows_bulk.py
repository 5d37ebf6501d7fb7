"""The output rows in bulk (stationbed/run/rows.py, issue 25): ``Rows.make``'s placing (two
gathers instead of one assignment per compiled output group), the row norms it uses, and
``Rows.hold_many`` (rows made and checked per call, their attitude error, sink and metrics once
per :data:`BULK_ROWS`).

Truths: each group of the compiled outputs placed in its own columns one by one (``Rows.plan``:
the group's columns, its slice of ``out_map``'s result, in degrees or not), ``out_map`` called
through casadi itself (not the zero-copy buffer), and ``np.linalg.norm``: bit for bit. For
``hold_many``: the same rows held one at a time (``Rows.hold``, its own attitude error per
batch) give the sink the same rows, the metrics the same values; a non-finite row stops both at
the same row; a sink that fails takes the same rows.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenes import ROOT
from stationbed import load_scene
from stationbed.core.linalg import row_norms
from stationbed.run.prepare import prepare
from stationbed.integrators import IntegrationError
from stationbed.run.rows import BULK_ROWS, ROW_BATCH, Rows, SinkError


def test_make_places_every_output_group_as_the_plan_says():
    """iss_lvlh_hold (tracking arrays: their track errors in degrees, environment torques, CMGs):
    70 rows of perturbed states (two compiled calls' worth), each value in its named column."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    run = prepare(scene)
    rows = Rows(scene, run.system, run.p, None, True)
    rng = np.random.default_rng(5)
    k = 70
    ts = np.linspace(0.0, 600.0, k)
    xs = run.x0[None, :] * (1.0 + 1e-3 * rng.normal(size=(k, len(run.x0))))
    held = rng.normal(size=(k, len(rows.held_columns)))
    got = rows.make(ts, xs, held)
    out_map = run.system.funcs["out_map"]  # (t[1 x m], x[nx x m], p) -> out[n_out x m]: a column per row
    m = out_map.size2_in(0)
    pad = (-k) % m
    t_in, x_in = np.pad(ts, (0, pad)), np.pad(xs, ((0, pad), (0, 0)))
    comp = np.vstack([np.asarray(out_map(t_in[a:a + m][None, :], x_in[a:a + m].T, run.p)).T
                      for a in range(0, k + pad, m)])[:k]
    want = np.zeros_like(got)
    want[:, 0] = ts
    q = xs[:, rows._q]
    want[:, rows.q_cols] = q / np.linalg.norm(q, axis=1, keepdims=True)
    for cols, sl, degrees in rows.plan:
        want[:, cols] = np.rad2deg(comp[:, sl]) if degrees else comp[:, sl]
    want[:, rows.gimbal_cols] = xs[:, rows._gimbals]
    want[:, rows.held_cols] = held
    assert any(d for _, _, d in rows.plan) and len(rows.plan) > 5
    assert np.array_equal(got, want)


def test_row_norms_are_numpys_bit_for_bit():
    """Magnitudes from 1e-200 to 1e200 in one array, overflow to inf, NaN, zero rows."""
    rng = np.random.default_rng(3)
    cases = [rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-200, 200, (500, 1)), rng.normal(size=(64, 4)),
             np.array([[np.inf, 1.0, 2.0], [np.nan, 0.0, 0.0], [1e300, 1e300, 0.0], [0.0, 0.0, 0.0]])]
    with np.errstate(over="ignore"):
        for x in cases:
            assert np.array_equal(row_norms(x), np.linalg.norm(x, axis=1), equal_nan=True)
            assert np.array_equal(row_norms(x, keepdims=True), np.linalg.norm(x, axis=1, keepdims=True), equal_nan=True)


class _Sink:
    """Keeps every batch; fails (SinkError) at batch ``fail_at`` (0-based) when given."""

    def __init__(self, fail_at=None):
        self.batches, self.fail_at = [], fail_at

    def write(self, rows):
        if self.fail_at is not None and len(self.batches) == self.fail_at:
            raise SinkError("memory", float(rows[0, 0]), OSError(28, "No space left on device"))
        self.batches.append(rows.copy())


def _bulk_case(bad_row=None):
    """iss_lvlh_hold's rows for 3 BULK_ROWS + 40 output times in calls of 64 (a fused loop's),
    the states perturbed about the initial one, references turning slowly; ``bad_row``: a NaN rate."""
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    run = prepare(scene)
    rng = np.random.default_rng(9)
    k = 3 * BULK_ROWS + 40
    ts = np.arange(k) * 10.0
    xs = run.x0[None, :] * (1.0 + 1e-3 * rng.normal(size=(k, len(run.x0))))
    if bad_row is not None:
        xs[bad_row, 4] = np.nan  # a rate component: the row's core values are not finite
    q_refs = xs[:, 0:4] + 1e-2 * rng.normal(size=(k, 4))
    return scene, run, ts, xs, q_refs


def _held(rows, k):
    return np.random.default_rng(1).normal(size=(k, len(rows.held_columns)))


def _one_by_one(scene, run, ts, xs, q_refs, sink):
    rows = Rows(scene, run.system, run.p, sink, True)
    held = _held(rows, len(ts))

    def go():
        for i in range(len(ts)):
            rows.hold(ts[i], xs[i], list(held[i]), q_refs[i])
        rows.flush()
    return rows, go


def _in_bulk(scene, run, ts, xs, q_refs, sink):
    rows = Rows(scene, run.system, run.p, sink, True)
    held = _held(rows, len(ts))

    def go():
        for a in range(0, len(ts), 64):
            rows.hold_many(ts[a:a + 64], xs[a:a + 64], held[a:a + 64], q_refs[a:a + 64])
        rows.flush()
    return rows, go


def _ran(make, case, sink):
    """The Rows and the IntegrationError its run raised (None)."""
    rows, go = make(*case, sink)
    try:
        go()
    except IntegrationError as e:
        return rows, e
    return rows, None


def _rows_seen(sink):
    return np.vstack(sink.batches)


@pytest.mark.parametrize("bad_row", [None, BULK_ROWS + 70], ids=["finite", "nan_in_a_later_bulk"])
def test_bulk_rows_are_the_rows_held_one_by_one(bad_row):
    """Same rows to the sink (in batches of at most ROW_BATCH), same rows kept, same metrics;
    a non-finite row: the rows before it handed on by both, the same IntegrationError time."""
    case = _bulk_case(bad_row)
    one, e_one = _ran(_one_by_one, case, _Sink())
    bulk, e_bulk = _ran(_in_bulk, case, _Sink())
    assert np.array_equal(_rows_seen(bulk.sink), _rows_seen(one.sink), equal_nan=True)
    assert max(len(b) for b in bulk.sink.batches) <= ROW_BATCH
    assert np.array_equal(bulk.trajectory({}).data, one.trajectory({}).data, equal_nan=True)
    assert bulk.summary.values() == one.summary.values() and bulk.summary.n_rows == one.summary.n_rows
    if bad_row is None:
        assert e_one is None and e_bulk is None and bulk.summary.n_rows == len(case[2])
    else:
        assert e_one.t == e_bulk.t == case[2][bad_row] and bulk.summary.n_rows == bad_row


def test_bulk_rows_wait_for_bulk_rows_then_go_in_batches():
    """Nothing reaches the sink before BULK_ROWS rows wait; then all of them, in ROW_BATCH rows."""
    scene, run, ts, xs, q_refs = _bulk_case()
    rows = Rows(scene, run.system, run.p, _Sink(), True)
    held = _held(rows, len(ts))
    for a in range(0, BULK_ROWS - 64, 64):
        rows.hold_many(ts[a:a + 64], xs[a:a + 64], held[a:a + 64], q_refs[a:a + 64])
    assert rows.sink.batches == [] and rows.summary.n_rows == 0
    a = BULK_ROWS - 64
    rows.hold_many(ts[a:a + 64], xs[a:a + 64], held[a:a + 64], q_refs[a:a + 64])
    assert [len(b) for b in rows.sink.batches] == [ROW_BATCH] * (BULK_ROWS // ROW_BATCH)
    assert rows.summary.n_rows == BULK_ROWS


def test_a_failing_sink_takes_the_same_rows_in_bulk():
    """The sink fails at its third batch: the rows it took before are the ones counted, the same
    as one by one (the batch it failed on is not counted)."""
    case = _bulk_case()
    seen = []
    for make in (_one_by_one, _in_bulk):
        rows, go = make(*case, _Sink(fail_at=2))
        with pytest.raises(SinkError):
            go()
        seen.append((_rows_seen(rows.sink), rows.summary.n_rows))
    (a, n_a), (b, n_b) = seen
    assert np.array_equal(a, b) and n_a == n_b == len(a) == 2 * ROW_BATCH
