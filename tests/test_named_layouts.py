"""Named layouts own the indices of the loop's vectors (issue 20 item 1): the state, the held
input, the measurement, the command, and the fused chunks' carry, parameters and info.

Claims:

* no module of the run layer, the formulations or the loop layer slices one of these vectors by
  a literal position (``x[4:7]``, ``par[3 : 3 + ncp]``, ``out[:3]``): a source scan (the AST),
  with a short allow-list, each entry with its reason; the scan finds a planted ``x[4:7]``;
* the measurement's layout (``measurement_fields``) is what the compiled ``meas`` writes: at a
  state, each field read by name is its truth (the attitude and rate of the state, the LVLH
  quaternion whose DCM is the ``C_ON`` field, the unit sun vector), and the older offset dict
  (``measurement_layout``) is the same layout;
* an actuator finds its ``READS`` in the measurement by name (``Actuator.reads_in``);
* the composed chunk's carry and parameters (loop/compose.py) are the sizes of the compiled
  chunk the executor fills;
* a formulation's state parts (``attitude``, ``core_vector``, ``extra``) are its layout's.
"""

from __future__ import annotations

import ast
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from stationbed import load_scene, simulate
from stationbed.core.layout import Layout
from stationbed.core.rotation import dcm
from stationbed.formulations import FORMULATIONS
from stationbed.loop.actuator import Actuator
from stationbed.run.controller import Measurement, measurement_fields, measurement_layout

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "stationbed"
SCANNED = [LIB / "run", LIB / "formulations", LIB / "loop"]
#: names the loop's packed vectors go by in these modules (state, input, measurement, carries,
#: parameters, outputs)
PACKED = {"x", "xs", "X", "x0", "x1", "x_i", "xa", "y", "y0", "yt", "seen", "raw", "parts", "u", "par", "parm",
          "ps_", "bpar", "c", "c0", "co", "cs", "bc", "bq", "rc", "carry", "carries", "r", "info", "out", "res",
          "xs_", "xi", "xc", "yi", "env", "rest", "po", "pb", "est", "y_seen", "y_truth"}
#: (module, expression) -> why a literal there is not a position in a packed vector
ALLOWED = {
    ("batch.py", "xs[:, 1:]"): "axis 1 is time (the samples after the first), not the state",
    ("simulation.py", "xs[:-1]"): "the rows' time axis (the last row dropped), not the state",
}
#: the measurement's fields at a state agree with their truth to round-off
TOL = 1e-12


def _literal_slices(source: str, name: str = "<src>") -> list[str]:
    """``v[...]`` of a packed vector ``v`` whose slice bounds hold an integer literal (constants
    inside a call or a subscript, e.g. ``v.shape[1]``, are not positions)."""
    def literals(e):
        if e is None or isinstance(e, (ast.Call, ast.Subscript, ast.Attribute)):
            return False
        if isinstance(e, ast.Constant):
            return type(e.value) is int
        return any(literals(c) for c in ast.iter_child_nodes(e))

    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in PACKED:
            sl = node.slice
            for it in sl.elts if isinstance(sl, ast.Tuple) else [sl]:
                if isinstance(it, ast.Slice) and (literals(it.lower) or literals(it.upper)):
                    if (name, ast.unparse(node)) not in ALLOWED:
                        out.append(f"{name}:{node.lineno}: {ast.unparse(node)}")
    return out


def test_the_scan_finds_a_positional_slice():
    planted = "def f(x, par, ncp, y):\n    a = x[4:7]\n    b = par[3 : 3 + ncp]\n    c = y[:, y.shape[1]:]\n"
    assert _literal_slices(planted) == ["<src>:2: x[4:7]", "<src>:3: par[3:3 + ncp]"]


@pytest.mark.parametrize("folder", SCANNED, ids=lambda p: p.name)
def test_no_literal_positions_in_packed_vectors(folder):
    found = []
    for path in sorted(folder.glob("*.py")):
        found += _literal_slices(path.read_text(), path.name)
    assert found == []


def test_allow_list_entries_still_exist():
    for (module, expr) in ALLOWED:
        src = next(p for d in SCANNED for p in d.glob(module))
        exprs = {ast.unparse(n) for n in ast.walk(ast.parse(src.read_text())) if isinstance(n, ast.Subscript)}
        assert expr in exprs, f"{module}: {expr} is gone: drop it from ALLOWED"


# -- the measurement ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hold_system():
    from stationbed.run.prepare import prepare

    return prepare(load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml"))


def test_measurement_fields_are_their_truth(hold_system):
    pr = hold_system
    system = pr.system
    form = system.formulation
    ng, n_app = form.model.cmg.n_gimbals, form.model.structure.n_app
    lay = measurement_fields(ng, n_app)
    x = np.array(pr.x0, dtype=float)
    rng = np.random.default_rng(3)
    x[form.state_layout.slice("q_BN")] = (q := rng.normal(size=4)) / np.linalg.norm(q)
    t = 1234.5
    y = np.asarray(system.funcs["meas"](t, x, pr.p)).ravel()
    assert y.size == lay.size
    M = Measurement(y, lay)
    assert np.array_equal(M.q_BN, form.attitude(x))
    w = np.asarray(system.funcs["out"](t, x, pr.p)).ravel()[system.out_layout["omega_BN_B"]]
    assert np.allclose(M.omega_BN_B, w, rtol=0, atol=TOL)
    assert np.array_equal(M.gimbal, form.state_layout.get(x, "x_cmg")[:ng])
    assert np.allclose(dcm(M.q_ON), M.C_ON, rtol=0, atol=TOL)  # C_ON stored row by row
    assert np.allclose(M.C_ON @ M.C_ON.T, np.eye(3), rtol=0, atol=TOL)
    assert abs(np.linalg.norm(M.sun_N) - 1.0) < TOL
    assert M.alpha.shape == M.beta.shape == (n_app,)


def test_measurement_layout_is_the_named_layouts_offsets():
    for ng, n_app in ((0, 0), (8, 2)):
        lay = measurement_fields(ng, n_app)
        offsets = measurement_layout(ng, n_app)
        assert offsets == {n: (lay.slice(n).start, lay.shape(n)[0]) for n in lay.names}
        y = np.arange(float(lay.size))
        a, b = Measurement(y, lay), Measurement(y, offsets)  # (older code passes the dict)
        for name in lay.names:
            assert np.array_equal(getattr(a, name), getattr(b, name))
            assert np.shares_memory(getattr(a, name), y) or getattr(a, name).size == 0  # views, refreshed in place
    part = Measurement(np.arange(8.0), {"q_BN": (0, 4), "h_B": (5, 3)})  # an older partial dict: read as always
    assert part.h_B.tolist() == [5.0, 6.0, 7.0]


# -- the actuators' reads ------------------------------------------------------------------------
class _Reader(Actuator):
    kind = "_test_reader"
    STATE, PARAMS, OUTPUTS = Layout(), Layout(), Layout()

    def __init__(self, reads: Layout):
        self.READS = reads
        super().__init__()

    def _params(self):
        return {}

    def _initial(self):
        return {}


def test_actuator_finds_its_reads_by_name():
    meas = measurement_fields(4, 2)
    assert _Reader(Layout(h_B=3)).reads_in(meas) == meas.slice("h_B")
    idx = _Reader(Layout(h_B=3, q_BN=4)).reads_in(meas)  # not contiguous: the indices, in READS order
    y = np.arange(float(meas.size))
    assert np.array_equal(y[idx], np.concatenate([meas.get(y, "h_B"), meas.get(y, "q_BN")]))
    with pytest.raises(KeyError, match="nope"):
        _Reader(Layout(nope=1)).reads_in(meas)
    with pytest.raises(ValueError, match="h_B"):
        _Reader(Layout(h_B=2)).reads_in(meas)


# -- the fused chunk's vectors -------------------------------------------------------------------
@pytest.mark.parametrize("name", ["iss_lvlh_hold", "iss_lvlh_hold_estimated", "iss_full_flight_loop"])
def test_composed_chunk_vectors_are_their_layouts_sizes(name, monkeypatch):
    """The composed loop's chunk, row and rows' call (run/composed.py, issue 33) are the sizes of
    the composition's layouts, which the executor fills by name: the carry (``i``, ``x``,
    ``counts``, each block's memory under its name, of its layout's size), the parameters (each
    block's numbers), the draws (each block's per tick, a row's ticks), the row's values."""
    from stationbed.run import composed

    monkeypatch.setattr(composed, "_CHUNKS", {})
    sc = load_scene(ROOT / "scenarios" / f"{name}.toml")
    tr = simulate(sc, duration=30.0, fused=True)
    assert tr.meta["summary"]["fused"]
    fns = list(composed._CHUNKS.values())[-1]  # (the run's; the default rate's probe may come first)
    cm, n = fns["cm"], sc.simulation.output_dt / sc.controller.period
    c0, par, w = fns["chunk"].args
    assert (c0.size, par.size, w.size) == (cm.carry.size, cm.par.size, cm.noise.size * round(n))
    assert fns["row"].res[0].size == cm.row_layout.size
    for b in cm.blocks:
        assert cm.carry.shape(b.name)[0] == b.state.size and cm.par.shape(b.name)[0] == b.params.size, b.name
    if cm.env is not None:
        assert cm.carry.shape(cm.env.name)[0] == cm.env.state.size
    R = max(fns["rows"])
    assert fns["rows"][R].args[0].size == cm.carry.size and fns["rows"][R].args[2].size == cm.par.size


def test_flight_takes_the_measurement_layout():
    """``Flight`` reads the measurement's Layout; an offset dict (older code) is the same flight
    (same tick key, same layout), a partial dict's gaps named apart."""
    from stationbed.loop import Flight

    sc = load_scene(ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml")
    lay = measurement_fields(4, 2)
    a, b = Flight(sc, sc.controller.period, lay, seed=0), Flight(sc, sc.controller.period, lay.offsets(), seed=0)
    assert a.meas == b.meas == lay and a.key == b.key and a.ny == lay.size
    part = Flight(sc, sc.controller.period, {"q_BN": (0, 4), "r_N": (7, 3)}, seed=0)
    assert part.meas.slice("r_N") == slice(7, 10) and part.ny == 10


@pytest.mark.parametrize("name", sorted(FORMULATIONS))
def test_formulation_state_parts_are_its_layout(name, hold_system):
    from stationbed.model import StationModel
    from stationbed.run.prepare import prepare

    structure = hold_system.system.formulation.model.structure
    form = FORMULATIONS[name](StationModel(structure))
    xl = form.state_layout
    x = ca.SX.sym("x", form.nx)
    assert ca.is_equal(form.attitude(x), xl.get(x, "q_BN"))
    assert ca.is_equal(form.core_vector(x), xl.get(x, form.rate_field))
    rest = [n for n in xl.names if n not in ("q_BN", form.rate_field)]
    assert ca.is_equal(form.extra(x), ca.vertcat(*(xl.get(x, n) for n in rest)))
    assert form.extra(x).numel() == form.nx - 7


@pytest.mark.parametrize("issue,least", [(20, 30), (33, 20)])
def test_issue_tables_cite_tests_that_exist(issue, least):
    """docs/loop.md's issue-20 and issue-33 tables name the test of each bullet: every one they
    name exists."""
    import re

    text = (ROOT / "docs" / "loop.md").read_text()
    table = text[text.index(f"## Issue {issue}, bullet by bullet"):]
    cited, missing, module = 0, [], None
    for m in re.finditer(r"(tests/test_\w+\.py)|::(test_\w+)", table):
        if m.group(1):
            module = m.group(1)
            continue
        cited += 1
        tree = ast.parse((ROOT / module).read_text())
        if m.group(2) not in {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}:
            missing.append(f"{module}::{m.group(2)}")
    assert cited > least and missing == []
