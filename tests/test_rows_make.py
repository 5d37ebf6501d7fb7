"""The output rows' placing (stationbed/run/rows.py ``Rows.make``, issue 25: two gathers instead of
one assignment per compiled output group) and the row norms it uses.

Truths: each group of the compiled outputs placed in its own columns one by one (``Rows.plan``:
the group's columns, its slice of ``out_map``'s result, in degrees or not), ``out_map`` called
through casadi itself (not the zero-copy buffer), and ``np.linalg.norm``: bit for bit.
"""

from __future__ import annotations

import numpy as np

from scenes import ROOT
from stationbed import load_scene
from stationbed.core.linalg import row_norms
from stationbed.run.prepare import prepare
from stationbed.run.rows import Rows


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
