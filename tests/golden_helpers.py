"""The shipped scenarios' numbers, pinned (tests/data/golden/README.md; tests/test_goldens.py).

What a golden holds, for each shipped scenario that is not a Monte Carlo (a ``[montecarlo]``
table: its runs are other scenes' runs with drawn numbers), run at its own duration through
``stationbed run SCENE --out DIR``:

* the CSV's header (its columns and their order are a contract, DESIGN §6) and its row count;
* :data:`N_ROWS` rows evenly spaced over the run (the first and the last included), every column;
* each column's minimum, maximum and mean over every row, so a change between the sampled rows
  (a thruster pulse, a fault declared a tick later) shows too;
* ``summary.json`` flattened (``summary.fdir_mode_s.hold``), but for the keys that say how the
  run was made rather than what it computed (:data:`NOT_PINNED`).

The comparison's tolerances are named in :mod:`test_goldens`; this module only reads, records
and compares.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np

from scenes import ROOT, SCENARIOS

GOLDEN_DIR = ROOT / "tests" / "data" / "golden"
#: rows kept per scene, evenly spaced over the run
N_ROWS = 9
#: summary.json keys (flattened) that say how or where the run was made, not what it computed:
#: the machine's timings (the build, the run, the mpc law's solves), the evaluator (compiled C,
#: or casadi's virtual machine: the same numbers), the scene file's path, the CSV's file name,
#: and the work counts of a search whose path round-off may tip: an adaptive integrator's steps
#: (a 1e-19 rad/s change of torque_window's initial rate, at rest, moved DOP853's steps by 14 %,
#: its rows by 1e-13) and ipopt's iterations; the rows and the results stay pinned
NOT_PINNED = frozenset({"scene", "wall_s", "build_s", "evaluator", "rows_file", "n_rhs", "n_steps",
                        "summary.mpc_solve_mean_s", "summary.mpc_solve_max_s", "summary.mpc_iter_mean",
                        "summary.mpc_iter_max"})


def golden_scenarios() -> list[Path]:
    """The shipped scenario files that have a golden: all but the Monte Carlo ones."""
    return [p for p in SCENARIOS if "montecarlo" not in tomllib.loads(p.read_text())]


def golden_path(scene: Path) -> Path:
    return GOLDEN_DIR / f"{scene.stem}.json"


def run_scene(scene: Path, out: Path, sets: tuple[str, ...] = ()) -> tuple[list[str], np.ndarray, dict]:
    """``stationbed run SCENE --out OUT [--set K=V ...]`` in this process; returns the CSV's
    header, its rows (float, shape (N, columns)) and ``summary.json``."""
    from stationbed.cli import main

    args = ["-q", "run", str(scene), "--out", str(out)] + [f"--set={s}" for s in sets]
    rc = main(args)
    assert rc == 0, f"stationbed {' '.join(args)} exited {rc}"
    csv = out / "trajectory.csv"
    header = csv.open().readline().strip().split(",")
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    return header, data, json.loads((out / "summary.json").read_text())


def _flat(value, key: str, into: dict) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flat(v, f"{key}.{k}" if key else str(k), into)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _flat(v, f"{key}.{i}", into)
    else:  # JSON has no NaN: null stands for it, as in the columns
        into[key] = None if isinstance(value, float) and math.isnan(value) else value


def flat_summary(summary: dict) -> dict:
    """``summary.json`` as one level of dotted keys, without :data:`NOT_PINNED`."""
    out: dict = {}
    _flat(summary, "", out)
    return {k: v for k, v in out.items() if k not in NOT_PINNED}


def _num(x: float) -> float | None:
    return None if math.isnan(x) else float(x)  # JSON has no NaN: null stands for it


def sampled_rows(n: int) -> np.ndarray:
    """The indices of the kept rows: :data:`N_ROWS` evenly spaced, first and last included."""
    return np.unique(np.linspace(0, n - 1, min(N_ROWS, n)).round().astype(int))


def record(header: list[str], data: np.ndarray, summary: dict) -> dict:
    """The golden of one run (what the JSON file holds)."""
    rows = sampled_rows(len(data))
    cols = {}
    for j, name in enumerate(header):
        col = data[:, j]
        finite = col[~np.isnan(col)]
        stats = (finite.min(), finite.max(), finite.mean()) if finite.size else (math.nan,) * 3
        cols[name] = {"rows": [_num(v) for v in col[rows]], "min": _num(stats[0]), "max": _num(stats[1]),
                      "mean": _num(stats[2]), "nan_rows": int(np.isnan(col).sum())}
    return {"n_rows": len(data), "header": header, "row_index": rows.tolist(), "columns": cols,
            "summary": flat_summary(summary)}


def write_golden(path: Path, rec: dict, scene: Path) -> None:
    """One file per scene, one column per line (a change reads as a diff of the columns it moved)."""
    head = {"scene": f"scenarios/{scene.name}", "made_by": "tests/data/golden/make_golden.py",
            "n_rows": rec["n_rows"], "row_index": rec["row_index"], "header": rec["header"]}
    lines = ["{"] + [f"  {json.dumps(k)}: {json.dumps(v)}," for k, v in head.items()]
    lines.append('  "columns": {')
    items = list(rec["columns"].items())
    lines += [f"    {json.dumps(k)}: {json.dumps(v)}{',' if i < len(items) - 1 else ''}" for i, (k, v) in enumerate(items)]
    lines.append("  },")
    lines.append(f'  "summary": {json.dumps(rec["summary"], indent=4, sort_keys=True)}'.replace("\n}", "\n  }"))
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")
