"""The closed loop's executors share one composition and read nothing private of each other
(issue 20 item 1, run/composition.py, docs/loop.md "The composition and its executors").

Claims, read from the source (the AST of each executor module), not from a hand-kept list of
attributes:

* no executor touches a private attribute (``obj._name``) of any object but itself: the fused
  loops, the bulk rows, the thrusters' and the lockstep batch's executors reach the run only
  through ``Composition`` (what it is made of) and ``RunState`` (what they hand back), and the
  per-tick loop's single-tick steps they use are public (the fused loop called
  ``loop._held_row`` before: this test failed on that code). Allowed: the compiled-call
  wrapper's own buffers (:data:`FASTCALL_OWN`, core/compile.py's ``FastCall``), which are not
  an executor's;
* the fused executors do not import the per-tick loop at all;
* a ``Composition`` cannot be changed by an executor (frozen).
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

from stationbed import load_scene
from stationbed.run.prepare import prepare

RUN = Path(__file__).resolve().parents[1] / "stationbed" / "run"
EXECUTORS = ["closed_loop.py", "fused.py", "composed.py", "composed_rows.py", "blocks.py", "lockstep.py",
             "parts.py", "chain.py", "env_block.py", "segments.py", "composition.py"]
#: FastCall's bound C trigger and its per-process buffer cache (core/compile.py): read by the
#: per-tick loop's hot path and the lockstep set-up, part of the compiled-call wrapper
FASTCALL_OWN = {"fc._trigger", "FastCall._cache"}
FUSED = ["fused.py", "composed.py", "composed_rows.py", "blocks.py"]


def _private_reads(path: Path) -> list[str]:
    """``obj._name`` accesses whose object is not ``self`` or ``cls`` (dunders allowed)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")) and ast.unparse(node) not in FASTCALL_OWN:
                out.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
    return out


@pytest.mark.parametrize("module", EXECUTORS)
def test_no_executor_reads_private_attributes(module):
    assert _private_reads(RUN / module) == []


@pytest.mark.parametrize("module", FUSED)
def test_fused_executors_do_not_import_the_per_tick_loop(module):
    tree = ast.parse((RUN / module).read_text())
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m and m.endswith("closed_loop") for m in names)


def test_composition_is_frozen():
    from stationbed.run.closed_loop import ControlLoop
    from stationbed.run.rows import Rows
    from stationbed.run.segments import breakpoints

    scene = load_scene("scenarios/iss_lvlh_hold.toml")
    run = prepare(scene, scene.simulation.formulation, scene.simulation.integrator)
    rows = Rows(scene, run.system, run.p, None, True)
    bps, _ = breakpoints(scene, 60.0)
    loop = ControlLoop(scene, run.system, run.integrator, run.p, run.x0.copy(), rows, 60.0, 10.0, bps,
                       lambda t, x: x, None, True)
    with pytest.raises(dataclasses.FrozenInstanceError):
        loop.comp.period = 1.0
    assert loop.comp.n_cmd == loop.comp.command_layout.size == 3
    assert loop.comp.u_cmg == loop.comp.input_layout.slice("u_cmg")
    assert [a.kind for a in loop.comp.chain] == ["cmg_cluster"]  # no [[thruster]]: the cluster ends the chain alone
