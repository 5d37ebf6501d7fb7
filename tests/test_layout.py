"""The package layout keeps its rule (docs/design.md, "Where things go").

Claims, each read from the source itself (the AST of every module, function-level imports
included), not from a hand-kept list of modules:

* a module imports only from its own folder and the folders below it:
  core < scene < model < formulations, integrators < loop < run < analysis, plan < controllers < output < studies
  < plugins (`stationbed list`) < cli;
* the modules of the package import each other without a cycle;
* nothing in the library imports the shipped controllers (they are plug-ins, found through
  their entry points);
* every package folder is installed (listed in pyproject.toml), and ``controllers/`` is
  installed as ``stationbed.controllers``, never as a top-level ``controllers``;
* no library module grows past :data:`MAX_LINES`.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "stationbed"
CONTROLLERS = ROOT / "controllers"

#: the layers, lowest first; a module's layer is its first folder under stationbed/ (or its
#: file name for the top-level modules); formulations and integrators share a rank
LAYERS = {
    "core": 0,
    "scene": 1,
    "model": 2,
    "formulations": 3,
    "integrators": 3,
    "loop": 4,
    "run": 5,
    "analysis": 6,
    "plan": 6,  # planned slews: the simulator's plant facts (run) below, the schedule law above
    "controllers": 7,
    "output": 8,
    "studies": 9,
    "plugins": 10,  # stationbed list: reads every registry
    "cli": 11,
}
#: the package's own __init__ only names what it loads lazily (PEP 562): it sits above everything
TOP = "__init__"
#: "no file in stationbed/ above ~600 lines" (issue 11)
MAX_LINES = 600


def _module_name(path: Path) -> str:
    if path.is_relative_to(CONTROLLERS):
        rel = ("controllers",) + path.relative_to(CONTROLLERS).with_suffix("").parts
    else:
        rel = path.relative_to(PACKAGE).with_suffix("").parts
    parts = ["stationbed", *rel]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _sources() -> dict[str, Path]:
    files = sorted(PACKAGE.rglob("*.py")) + sorted(CONTROLLERS.rglob("*.py"))
    return {_module_name(p): p for p in files}


SOURCES = _sources()


def _imports(name: str, path: Path) -> set[str]:
    """Every stationbed module ``name`` imports, anywhere in the file (functions included)."""
    tree = ast.parse(path.read_text(), str(path))
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            # `from pkg import sub` imports the submodule when there is one
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in SOURCES else mod for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in SOURCES and "." in t:
                t = t.rsplit(".", 1)[0]
            if t in SOURCES and t.startswith("stationbed") and t != "stationbed":
                found.add(t)
    return found


GRAPH = {name: _imports(name, path) for name, path in SOURCES.items()}


def _layer(name: str) -> tuple[str, int]:
    parts = name.split(".")
    if len(parts) == 1:
        return TOP, max(LAYERS.values()) + 1
    key = parts[1]
    return key, LAYERS[key]


def test_every_module_has_a_layer():
    unknown = sorted(n for n in SOURCES if n != "stationbed" and n.split(".")[1] not in LAYERS)
    assert not unknown, f"modules outside the layer map (add their folder to LAYERS and docs/design.md): {unknown}"


@pytest.mark.parametrize("name", sorted(GRAPH), ids=sorted(GRAPH))
def test_imports_only_from_its_folder_or_below(name):
    folder, rank = _layer(name)
    bad = sorted(t for t in GRAPH[name] if _layer(t)[0] != folder and _layer(t)[1] >= rank)
    assert not bad, f"{name} ({folder}) imports from its own layer's sibling or a higher layer: {bad}"


def test_no_import_cycles():
    """Tarjan's strongly connected components over the import graph: every component is one module."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in GRAPH[v]:
                cycles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_the_rule_test_sees_function_level_and_relative_imports():
    """The graph is not vacuous: known edges are found (a top-level relative import, a package
    import through its __init__, and the CLI's function-level imports)."""
    assert "stationbed.core.rotation" in GRAPH["stationbed.model.environment"]
    assert "stationbed.run.simulation" in GRAPH["stationbed.cli"]
    assert "stationbed.run.controller" in GRAPH["stationbed.controllers.pd"]


def test_library_never_imports_the_shipped_controllers():
    users = sorted(n for n, deps in GRAPH.items() if not n.startswith("stationbed.controllers")
                   and any(d.startswith("stationbed.controllers") for d in deps))
    assert not users, f"the shipped laws are plug-ins (entry points), not imports: {users}"


def test_every_package_folder_is_installed():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    on_disk = {_module_name(p) for p in PACKAGE.rglob("__init__.py")} | {"stationbed.controllers"}
    assert on_disk == listed
    assert cfg["package-dir"] == {"stationbed.controllers": "controllers"}
    assert not any(p == "controllers" or p.startswith("controllers.") for p in listed)


@pytest.mark.parametrize("name", sorted(n for n in SOURCES if not n.startswith("stationbed.controllers")))
def test_module_stays_small(name):
    n = len(SOURCES[name].read_text().splitlines())
    assert n <= MAX_LINES, f"{name} has {n} lines: split it by concept"


# -- what an installation holds ---------------------------------------------------------------

import subprocess  # noqa: E402
import sys  # noqa: E402
import zipfile  # noqa: E402

from stationbed.run.controller import ENTRY_POINT_GROUP, controller_registry  # noqa: E402


@pytest.mark.slow
def test_wheel_installs_only_the_stationbed_package(tmp_path):
    """``pip install .`` gets one top-level package: no ``controllers`` beside it; the shipped laws,
    the DOP853 C driver and the controller entry points are inside."""
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", str(ROOT), "-w", str(tmp_path)],
        check=True, capture_output=True, timeout=300,
    )
    (wheel,) = tmp_path.glob("stationbed-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"stationbed", wheel.name.split("-py3")[0] + ".dist-info"}
    assert "stationbed/controllers/pd.py" in names
    assert "stationbed/integrators/dop853_driver.c" in names
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert f"[{ENTRY_POINT_GROUP}]" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_users_controllers_package_does_not_shadow_the_shipped_laws(tmp_path):
    """A user's own top-level ``controllers`` package (first on sys.path) is not what a scene's
    ``name = "pd"`` finds."""
    own = tmp_path / "controllers"
    own.mkdir()
    (own / "__init__.py").write_text("raise ImportError('the user package was imported')\n")
    (own / "pd.py").write_text("raise ImportError('the user pd was imported')\n")
    code = "from stationbed.run.controller import get_controller; print(get_controller('pd').__module__)"
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "stationbed.controllers.pd"


def test_every_registered_controller_is_named_as_its_entry_point():
    reg = controller_registry()
    assert {"pd", "lqr", "momentum_manager", "mpc", "torque_command", "example_hold"} <= set(reg)
    assert all(cls.name == name for name, cls in reg.items())
