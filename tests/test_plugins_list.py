"""``stationbed list`` names every plug-in kind a scene can name, one untruncated line each (issue 37).

Truths, read from the registries themselves (not from the listing's own groups, so a group the
listing forgot fails): every registered law, sensor, estimator, actuator, CMG geometry, steering
law, torque kind, formulation, integrator and Monte Carlo dispersion kind has exactly one line
``  name  description`` with a non-empty description; nothing is cut ("..."), and a narrow
terminal (COLUMNS=40) prints the very same lines.
"""

import typing

import pytest

from stationbed.cli import main
from stationbed.formulations import FORMULATIONS
from stationbed.integrators import INTEGRATORS
from stationbed.loop import cmg_cluster, thrusters  # noqa: F401  (register their actuators)
from stationbed.loop.actuator import ACTUATORS
from stationbed.loop.registry import SENSORS
from stationbed.model.cmg.cluster import CMG_GEOMETRIES
from stationbed.model.cmg.steering import STEERING_LAWS
from stationbed.model.torques import TORQUES
from stationbed.run.controller import controller_registry
from stationbed.scene import Scene
from stationbed.scene.montecarlo import DISPERSION_KINDS

ESTIMATORS = [
    k
    for m in typing.get_args(Scene.model_fields["estimator"].annotation)
    if m is not type(None)
    for k in typing.get_args(m.model_fields["kind"].annotation)
]

REGISTRIES = {
    "laws": sorted(controller_registry()),
    "sensors": sorted(SENSORS),
    "estimators": ESTIMATORS,
    "actuators": sorted(ACTUATORS),
    "cmg geometries": sorted(CMG_GEOMETRIES),
    "steering laws": list(STEERING_LAWS),
    "torque kinds": sorted(TORQUES),
    "formulations": sorted(FORMULATIONS),
    "integrators": sorted(INTEGRATORS),
    "dispersion kinds": sorted(DISPERSION_KINDS),
}
ENTRIES = [(group, name) for group, names in REGISTRIES.items() for name in names]


def listing(monkeypatch, capsys, columns: int) -> list[str]:
    monkeypatch.setenv("COLUMNS", str(columns))
    assert main(["list"]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.fixture
def lines(monkeypatch, capsys):
    return listing(monkeypatch, capsys, 200)


def test_registries_are_not_empty():
    """Guard: the truths above are read from live registries (an empty one would pass vacuously)."""
    assert all(REGISTRIES.values()), {g: n for g, n in REGISTRIES.items() if not n}
    assert "mekf" in ESTIMATORS and "thrusters" in ACTUATORS


@pytest.mark.parametrize("group, name", ENTRIES, ids=[f"{g}:{n}" for g, n in ENTRIES])
def test_every_registered_kind_has_a_described_line(lines, group, name):
    mine = [ln for ln in lines if ln.startswith("  ") and ln.split()[0] == name]
    assert mine, f"{group} {name!r} is not listed"
    described = [ln.split(None, 1)[1] for ln in mine if len(ln.split(None, 1)) == 2]
    assert described and all(len(d.strip()) >= 3 for d in described), f"{name!r} has no description: {mine}"


def test_nothing_is_cut(lines):
    cut = [ln for ln in lines if "..." in ln or "…" in ln or ln.rstrip().endswith((",", "(", "-"))]
    assert not cut, cut


def test_narrow_terminal_prints_the_same_lines(monkeypatch, capsys, lines):
    assert listing(monkeypatch, capsys, 40) == lines
