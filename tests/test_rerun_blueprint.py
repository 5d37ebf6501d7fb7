"""The closed-loop recording's layout (issue 19, item 18): the time-series panels are grouped in
tabs, none shorter than a third of the viewer's height, every panel reachable from the viewport,
and a closed-loop run opens on its control tab. Read back from the recording's blueprint store
(rerun 0.41 ContainerBlueprint / ViewBlueprint components), not from the code that built it."""

import math
from pathlib import Path

import pytest

from stationbed import load_scene, simulate
from stationbed.output.rerun.recording import write_recording

rerun_chunk = pytest.importorskip("rerun.chunk")

ROOT = Path(__file__).resolve().parents[1]
#: ContainerKind of rerun's blueprint (rerun/blueprint/components/container_kind.py)
TABS, HORIZONTAL, VERTICAL, GRID = 1, 2, 3, 4
#: The smallest share of the viewer's height a panel may get (was 1/10: ten stacked panels); a
#: tab's first panel, the one that answers its question, gets at least LARGE_HEIGHT_SHARE
MIN_HEIGHT_SHARE = 1 / 4
LARGE_HEIGHT_SHARE = 1 / 2


def blueprint_tree(path):
    """(root id, containers {id: dict}, views {id: name}) of a recording's blueprint store."""
    reader = rerun_chunk.RrdReader(path)
    (bp,) = reader.blueprints()
    containers, views, root = {}, {}, None
    for c in reader.stream(store=bp).to_chunks():
        rb = c.to_record_batch()
        ent = c.entity_path.lstrip("/")
        cols = rb.schema.names

        def one(name):
            return rb.column(name).to_pylist()[0] if name in cols else None

        if "ContainerBlueprint:container_kind" in cols:
            containers[ent] = {"kind": one("ContainerBlueprint:container_kind")[0],
                               "contents": one("ContainerBlueprint:contents") or [],
                               "name": (one("ContainerBlueprint:display_name") or [None])[0],
                               "active": (one("ContainerBlueprint:active_tab") or [None])[0],
                               "grid_columns": (one("ContainerBlueprint:grid_columns") or [None])[0],
                               "row_shares": one("ContainerBlueprint:row_shares")}
        if "ViewBlueprint:class_identifier" in cols:
            views[ent] = (one("ViewBlueprint:class_identifier")[0], one("ViewBlueprint:display_name")[0])
        if "ViewportBlueprint:root_container" in cols:
            root_bytes = bytes(one("ViewportBlueprint:root_container")[0])
            h = root_bytes.hex()
            root = f"container/{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"
    return root, containers, views


def height_shares(node, containers, share=1.0, out=None, tabs=None):
    """{view id: share of the viewer's height} of every view under ``node``; every tab is taken as
    shown (each in turn fills its container). ``tabs`` collects (tab name, number of views)."""
    out = {} if out is None else out
    if node.startswith("view/"):
        out[node] = share
        return out
    c = containers[node]
    kids = c["contents"]
    if c["kind"] == VERTICAL:
        w = c["row_shares"] or [1.0] * len(kids)
        for k, wk in zip(kids, w):
            height_shares(k, containers, share * wk / sum(w), out, tabs)
    elif c["kind"] == GRID:
        rows = math.ceil(len(kids) / (c["grid_columns"] or math.ceil(math.sqrt(len(kids)))))
        for k in kids:
            height_shares(k, containers, share / rows, out, tabs)
    else:  # HORIZONTAL: side by side; TABS: one at a time, all the height
        for k in kids:
            if c["kind"] == TABS and tabs is not None:
                tabs.append(containers[k]["name"] if k in containers else k)
            height_shares(k, containers, share, out, tabs)
    return out


@pytest.fixture(scope="module")
def hold_rrd(tmp_path_factory):
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml")
    return write_recording(simulate(scene, duration=20.0), scene, tmp_path_factory.mktemp("bp") / "hold.rrd")


def test_hold_panels_are_grouped_in_tabs_none_too_short(hold_rrd):
    root, containers, views = blueprint_tree(hold_rrd)
    tabs = []
    shares = height_shares(root, containers, tabs=tabs)
    series = {v for v, (cls, _) in views.items() if cls == "TimeSeries"}
    assert len(series) >= 15  # the closed loop's panels, all of them ...
    assert series <= set(shares)  # ... reachable from the viewport
    assert min(shares[v] for v in series) >= MIN_HEIGHT_SHARE
    assert ["attitude", "momentum & CMGs", "environment torques", "arrays"] == tabs[:4]
    (tab_box,) = [c for c in containers.values() if c["kind"] == TABS]
    assert containers[tab_box["active"]]["name"] == "attitude"  # opens on the attitude tab
    first = {}  # tab name -> its first (large) panel
    for k in tab_box["contents"]:
        node = containers[k]["contents"][0]
        first[containers[k]["name"]] = node
        assert shares[node] >= LARGE_HEIGHT_SHARE
    assert views[first["attitude"]][1] == "attitude error [deg]"
    assert views[first["momentum & CMGs"]][1] == "CMG momentum h_B [N m s]"
    assert views[first["environment torques"]][1].startswith("environment torques")
    assert views[first["arrays"]][1] == "array angles [rad]"
    logs = [v for v, (cls, _) in views.items() if cls == "TextLog"]
    assert len(logs) == 1 and logs[0] in shares  # the events, always in view beside the tabs


def test_open_loop_opens_on_its_attitude_tab(tmp_path):
    scene = load_scene(ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml")
    path = write_recording(simulate(scene, duration=20.0), scene, tmp_path / "ol.rrd")
    root, containers, views = blueprint_tree(path)
    tabs = []
    shares = height_shares(root, containers, tabs=tabs)
    assert tabs == ["attitude", "momentum & CMGs", "environment torques", "arrays"]  # gravity gradient's tau_gg_B (issue 32)
    (tab_box,) = [c for c in containers.values() if c["kind"] == TABS]
    assert containers[tab_box["active"]]["name"] == "attitude"
    assert {v for v, (cls, _) in views.items() if cls == "TimeSeries"} <= set(shares)
