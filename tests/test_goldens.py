"""The shipped scenarios keep their numbers (tests/data/golden/README.md).

The formulations are checked against each other (test_equivalence) and the executors against
each other and against a momentum balance (test_executor_matrix, test_closed_loop_balance); a
change that every formulation and executor share (the loop, an input, a scene default, a metric)
moves them all alike and passes those. Here a fresh ``stationbed run`` of every shipped
scenario but the Monte Carlo ones, at its own duration (each scene's thruster pulses, sensor
samples, faults, docking and plans happen inside it), is compared with its golden, the numbers
committed in ``tests/data/golden/<scene>.json`` by ``make_golden.py``: the CSV's header and row
count, nine rows spread over the run, each column's minimum, maximum and mean over every row,
and ``summary.json``.

Why not byte for byte: CI builds the generated C on another machine. The builds are made for
the same bits (``-ffp-contract=off``, no straight-line vectoriser: stationbed/core/compile.py),
and the per-tick executor gives the same bytes as the fused one here, but libm and the OpenBLAS
kernels (chosen by CPU: numpy's, and casadi's under ipopt) may round differently. Measured on
this machine against the goldens (docs/design.md "Goldens"), with another BLAS kernel
(``OPENBLAS_CORETYPE=Sandybridge``), with casadi's virtual machine in place of the C, and with a
round-off change of the initial rate (1e-16 of its scale, on x, on z): every column within 2e-11
of its scale but the named exceptions below; the tolerances keep >= 50x over what was measured.
A golden that moves for a reason is written again, and the commit says why (the README).
"""

from __future__ import annotations

import json
import math
import re
import tomllib

import pytest

from golden_helpers import GOLDEN_DIR, golden_path, golden_scenarios, record, run_scene

#: a column against its golden, relative to its scale (:func:`column_scale`): round-off carried
#: through a run of 1e3-1e5 steps; measured <= 2e-11 (jeod's T, a round-off change of the initial
#: rate; 1.1e-11 tea's cmg_singularity with another BLAS kernel)
COLUMN_REL = 1e-9
#: a quantity that hardly changes over the run (a conserved momentum or energy: its range is
#: its round-off) is compared with this fraction of its size: 1e-11 of |H| where round-off
#: reaches ~1e-13 (measured <= 7.5e-14 of the size)
SIZE_FLOOR = 1e-2
#: normalised residuals (the MEKF's NEES, the detector's NIS): the square of a small difference
#: of two large quantities over its small variance, so its round-off is relatively large:
#: measured 4.9e-9 of fdir_cmg_nis's range (round-off change of the initial rate), 1.0e-9 with
#: another BLAS kernel; NEES 5.3e-11
RATIO_REL = 1e-6
RATIO_COLUMNS = re.compile(r"nees|.*_nis")
#: a scene whose law runs ipopt in the run (a ``[plan]``: the schedule law plans; the ``mpc``
#: law): ipopt stops at its tolerance (1e-8 on the KKT conditions), and where it stops follows
#: the round-off of its linear algebra: measured 1.9e-4 of a column's range (the ZPM scenes'
#: attitude error) and 1.7e-5 of a summary value with another BLAS kernel; mpc's gimbal rates
#: 1.7e-9 of their scale after a round-off change of the initial rate
SOLVER_REL = 1e-2
#: a summary number against its golden, relative to the largest of its family (:func:`_family`):
#: the law's design figures (the momentum manager's margins and poles, numpy's LAPACK) measured
#: 8.5e-11 with another BLAS kernel, the rest <= 4e-11 (the mean NEES)
SUMMARY_REL = 1e-8

STATS = ("min", "max", "mean")
SCENES = golden_scenarios()


def solver_scene(scene) -> bool:
    """Whether the scene's law solves an optimisation in the run (see :data:`SOLVER_REL`)."""
    d = tomllib.loads(scene.read_text())
    return "plan" in d or d.get("controller", {}).get("name") == "mpc"


def vector_of(name: str) -> str:
    """The vector a column is a component of (``qx`` -> ``q?``, ``tau_gg_y`` -> ``tau_gg_?``,
    ``att_err_z_deg`` -> ``att_err_?_deg``), or the column itself."""
    if re.fullmatch(r"q[wxyz]|(w|h|HN)[xyz]", name):
        return name[:-1] + "?"
    m = re.fullmatch(r"(.+_)[xyz](_.+)?", name)
    return m.group(1) + "?" + (m.group(2) or "") if m else name


def column_scale(name: str, columns: dict) -> float:
    """A column's scale: the largest range of its vector's components (a component that stays
    near zero, the out-of-plane rate of a planar libration, is measured against the vector), at
    least :data:`SIZE_FLOOR` of their size. ``H_N`` goes with the cluster's ``h`` (a station at
    rest holds its momentum in the cluster: H_N is round-off; stationbed check does the same)."""
    group = {vector_of(name)} | ({"h?"} if vector_of(name) == "HN?" else set())
    scale = 0.0
    for c, ref in columns.items():
        if vector_of(c) in group and ref["min"] is not None:
            size = max(abs(ref["min"]), abs(ref["max"]))
            scale = max(scale, ref["max"] - ref["min"], SIZE_FLOOR * size)
    return scale


def _differ(a, b, tol: float) -> bool:
    if a is None or b is None:  # NaN (null in the file) only where the golden has it
        return (a is None) != (b is None)
    return not abs(a - b) <= tol


def _family(key: str) -> str:
    """The figures a summary number is measured against: a list's entries (the poles, a TEA) and
    the statistics of one quantity (``final_att_err_deg`` with ``max_`` and ``rms_att_err_deg``:
    a converged final error is a small difference, measured against the run's largest)."""
    return re.sub(r"^(summary\.)?(final|max|min|rms|mean)_", r"\1", re.sub(r"(\.\d+)+$", "", key))


def _sibling_scale(key: str, summary: dict) -> float:
    return max(abs(v) for k, v in summary.items()
               if _family(k) == _family(key) and isinstance(v, (int, float)) and not isinstance(v, bool))


def _summary_mismatches(name: str, ref: dict, new: dict, rel: float) -> list[str]:
    out = []
    for key in sorted(set(ref) | set(new)):
        if key not in ref or key not in new:
            out.append(f"{name}: summary {key}: golden {ref.get(key, '(absent)')!r}, now {new.get(key, '(absent)')!r}")
            continue
        a, b = ref[key], new[key]
        if isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
            tol = rel * _sibling_scale(key, ref)
            if _differ(a, b, tol):
                out.append(f"{name}: summary {key}: golden {a!r}, now {b!r} (|diff| {abs(a - b):.3g} > {tol:.3g})")
        elif a != b or type(a) is not type(b):  # counts, flags and names: exactly
            out.append(f"{name}: summary {key}: golden {a!r}, now {b!r}")
    return out


def mismatches(name: str, ref: dict, new: dict, solver: bool = False) -> list[str]:
    """Every difference of a fresh run's record ``new`` from the golden ``ref`` beyond the
    tolerances, one line each naming the scene, the column, the time and both values."""
    if new["header"] != ref["header"]:
        added = [c for c in new["header"] if c not in ref["header"]]
        gone = [c for c in ref["header"] if c not in new["header"]]
        return [f"{name}: the CSV's columns changed: added {added}, removed {gone}"
                + ("" if added or gone else " (the same columns in another order)")]
    if new["n_rows"] != ref["n_rows"]:
        return [f"{name}: {new['n_rows']} rows, golden {ref['n_rows']}"]
    t = ref["columns"]["t"]["rows"]
    out = []
    for col, r in ref["columns"].items():
        f = new["columns"][col]
        rel = SOLVER_REL if solver else RATIO_REL if RATIO_COLUMNS.fullmatch(col) else COLUMN_REL
        scale = column_scale(col, ref["columns"])
        tol = rel * scale
        why = f"> {tol:.3g} = {rel:g} x scale {scale:.3g}"
        for i, (a, b) in enumerate(zip(r["rows"], f["rows"])):
            if _differ(a, b, tol):
                d = "NaN" if a is None or b is None else f"{abs(a - b):.3g}"
                out.append(f"{name}: column {col} at t = {t[i]:g} s: golden {a!r}, now {b!r} (|diff| {d} {why})")
        for stat in STATS:
            a, b = r[stat], f[stat]
            if _differ(a, b, tol):
                d = "NaN" if a is None or b is None else f"{abs(a - b):.3g}"
                out.append(f"{name}: column {col}, its {stat} over t = {t[0]:g}..{t[-1]:g} s: golden {a!r}, "
                           f"now {b!r} (|diff| {d} {why})")
        if r["nan_rows"] != f["nan_rows"]:
            out.append(f"{name}: column {col}: {f['nan_rows']} NaN rows, golden {r['nan_rows']}")
    return out + _summary_mismatches(name, ref["summary"], new["summary"], SOLVER_REL if solver else SUMMARY_REL)


def _fresh(scene, out):
    return record(*run_scene(scene, out))


def _assert_keeps(scene, new):
    ref = json.loads(golden_path(scene).read_text())
    bad = mismatches(scene.stem, ref, new, solver_scene(scene))
    assert not bad, (f"{len(bad)} differences from {golden_path(scene).relative_to(GOLDEN_DIR.parents[2])} "
                     f"(if the change is meant, tests/data/golden/README.md):\n" + "\n".join(bad[:20]))


def test_every_scenario_has_its_golden():
    """A scenario added without a golden, or a golden left behind by a removed scenario, fails."""
    assert sorted(p.name for p in GOLDEN_DIR.glob("*.json")) == sorted(golden_path(s).name for s in SCENES)


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES, ids=[s.stem for s in SCENES])
def test_scenario_keeps_its_numbers(scene, tmp_path):
    _assert_keeps(scene, _fresh(scene, tmp_path))


#: the checker's own test: the torque window's torque, 10 N m, made 1e-6 larger in a copy of the
#: scene (the kind of change an input shared by every formulation makes)
PERTURBED = ("torque_window", "torque_B = [10.0, 0.0, 0.0]", "torque_B = [10.00001, 0.0, 0.0]")


def test_checker_fails_a_scene_changed_by_one_part_in_a_million(tmp_path):
    """The comparison is sensitive: a copy of ``torque_window`` whose torque is 1e-6 larger
    fails it, and the message names the scene, the column, the time and both values."""
    stem, old, new = PERTURBED
    src = next(s for s in SCENES if s.stem == stem)
    copy = tmp_path / src.name
    text = src.read_text()
    assert text.count(old) == 1
    copy.write_text(text.replace(old, new))
    ref = json.loads(golden_path(src).read_text())
    bad = mismatches(stem, ref, _fresh(copy, tmp_path / "out"))
    # H_N changes only inside the window (1000-2000 s), by 1e-6 of the window's impulse
    assert any(m.startswith(f"{stem}: column HNx at t = 2250 s: golden ") for m in bad), bad
    line = next(m for m in bad if m.startswith(f"{stem}: column HNx at t = 2250 s"))
    golden, now = re.search(r"golden (\S+), now (\S+)", line).groups()
    assert math.isclose(float(now) - float(golden), 1e-5 * 1000.0, rel_tol=1e-3)  # N m s: 1e-5 N m over 1000 s


def test_mismatch_names_scene_column_time_and_both_values():
    """The checker on a golden with one value moved by 10x its tolerance, a column renamed and a
    summary count changed (no run)."""
    ref = json.loads(golden_path(next(s for s in SCENES if s.stem == "iss_lvlh_hold")).read_text())
    new = json.loads(json.dumps(ref))
    scale = column_scale("qx", ref["columns"])
    new["columns"]["qx"]["rows"][3] += 10 * COLUMN_REL * scale
    bad = mismatches("iss_lvlh_hold", ref, new)
    t3 = ref["columns"]["t"]["rows"][3]
    assert len(bad) == 1 and bad[0].startswith(
        f"iss_lvlh_hold: column qx at t = {t3:g} s: golden {ref['columns']['qx']['rows'][3]!r}, "
        f"now {new['columns']['qx']['rows'][3]!r}"), bad
    new = json.loads(json.dumps(ref))
    new["summary"]["summary.ticks"] += 1
    assert mismatches("iss_lvlh_hold", ref, new) == [
        f"iss_lvlh_hold: summary summary.ticks: golden {ref['summary']['summary.ticks']}, "
        f"now {ref['summary']['summary.ticks'] + 1}"]
    new = json.loads(json.dumps(ref))
    new["header"] = [("q_x" if c == "qx" else c) for c in ref["header"]]
    assert mismatches("iss_lvlh_hold", ref, new) == [
        "iss_lvlh_hold: the CSV's columns changed: added ['q_x'], removed ['qx']"]


@pytest.mark.parametrize("name, vector", [("qw", "q?"), ("wz", "w?"), ("HNy", "HN?"), ("hx", "h?"),
                                          ("tau_gg_x", "tau_gg_?"), ("att_err_y_deg", "att_err_?_deg"),
                                          ("att_err_deg", "att_err_deg"), ("T", "T"), ("gimbal_1_outer", "gimbal_1_outer"),
                                          ("mtq_m_z", "mtq_m_?"), ("thr_mode", "thr_mode"), ("eclipse", "eclipse")])
def test_columns_are_scaled_by_their_vector(name, vector):
    assert vector_of(name) == vector
