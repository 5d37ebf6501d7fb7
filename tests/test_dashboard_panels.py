"""What ``stationbed plot`` and the recording say about the new columns (issue 32, item 7 and
item 8's compare file), each against a truth written here, not by the drawing code:

* the estimation panels draw the CSV's error against its ±3σ, NEES beside its χ² facts, and each
  star-tracker head's state, a head's rows before its first valid sample not a dropout (counted
  here from the flag by hand);
* the thruster panel draws the firings and propellant totals with the dump's rows shaded;
* the CMG limit flag is called "momentum saturation" only where the working units' |h| reached
  0.9 x 4 x 4760 N m s (the hold's four DGCMGs, by hand), else "gimbal-rate limit";
* the gravity-gradient column equals ``3 μ/r³ R̂_B × (I R̂_B)`` with R̂ from the circular orbit
  and C_BN from scipy's rotation of the logged quaternion;
* every legend lies inside its axes; two comparisons never write the same default file;
* the recording's thrusters are lit exactly at the rows whose on-time totals grew.
"""

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from stationbed import load_scene
from stationbed.analysis import dashboard as dash
from stationbed.cli import main
from stationbed.core.plotting import legend_inside
from stationbed.loop.flight import st_dropouts
from stationbed.output.rerun.events import Events
from stationbed.run.trajectory import Trajectory

from rrd_helpers import entity_rows

ROOT = Path(__file__).resolve().parents[1]
ESTIMATED = ROOT / "scenarios" / "iss_lvlh_hold_estimated.toml"
HOLD = ROOT / "scenarios" / "iss_lvlh_hold.toml"
THRUST = ROOT / "scenarios" / "iss_cmg_thruster_assist.toml"
EST_S = 300.0  # s: st1 drops out (sun exclusion) at ~130 s, st2 stays valid
MU_M3_S2 = 3.986004418e14  # m³/s², Earth (the scene's default)
R_EARTH_M = 6378137.0  # m, WGS-84 equatorial radius
#: the hold's saturation threshold by hand: saturation_fraction 0.9 (default) x 4 units x 4760 N m s
HOLD_H_SAT_NMS = 0.9 * 4 * 4760.0
#: gravity-gradient column against the hand formula: the torque is ~1e2 N m, computed twice in
#: double precision from the same 17-digit quaternion (a few ulp of the products) [N m]
GG_TOL_NM = 1e-9


@pytest.fixture(scope="module")
def est_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("est") / "est"
    assert main(["run", str(ESTIMATED), "-q", "--out", str(out), "--duration", str(EST_S)]) == 0
    return out


def drawn(monkeypatch, outdir):
    """The dashboard's axes by title (after the layout and the legends' fitting)."""
    got = {}
    real = dash.save_png

    def spy(plt, fig, path, **kw):
        real(SimpleNamespace(close=lambda f: None), fig, path, **kw)  # lays out, fits the legends, writes
        got["fig"] = fig
        got["axes"] = {ax.get_title(): ax for ax in fig.axes if ax.get_visible() and ax.get_title()}
        got["inside"] = {ax.get_title() or f"twin of {i}": legend_inside(ax) for i, ax in enumerate(fig.axes)}
        plt.close(fig)

    monkeypatch.setattr(dash, "save_png", spy)
    dash.dashboard(outdir)
    return got


def copy_run(src, dst, edit=None, summary=None):
    """A run folder at ``dst`` with ``src``'s rows, ``edit(columns dict)`` applied."""
    dst.mkdir(parents=True, exist_ok=True)
    tr = Trajectory.from_csv(src / "trajectory.csv")
    cols = dict(zip(tr.columns, tr.data.T.copy()))
    if edit:
        edit(cols)
    Trajectory(list(cols), np.column_stack(list(cols.values()))).to_csv(dst / "trajectory.csv")
    meta = json.loads((src / "summary.json").read_text())
    if summary:
        meta["summary"].update(summary)
    (dst / "summary.json").write_text(json.dumps(meta))
    return dst


# -- star tracker: no dropout before the first sample -------------------------------------------
@pytest.mark.parametrize("valid, dropout", [([0, 0, 1, 1, 0, 1], [0, 0, 0, 0, 1, 0]),
                                            ([1, 0, 0, 1], [0, 1, 1, 0]),
                                            ([0, 0, 0], [0, 0, 0])], ids=["late_first", "valid_first", "never"])
def test_st_rows_before_the_first_valid_sample_are_no_dropout(valid, dropout):
    mask, seen = st_dropouts(np.array(valid, float))
    assert mask.tolist() == [bool(d) for d in dropout]
    assert seen == any(valid)
    # in batches (a streamed recording): the same rows
    a, s = st_dropouts(np.array(valid[:2], float))
    b, _ = st_dropouts(np.array(valid[2:], float), s)
    assert np.r_[a, b].tolist() == mask.tolist()


def test_recording_events_of_a_head_before_its_first_sample():
    t = np.arange(6) * 10.0  # s
    tr = Trajectory(["t", "st_valid_st1"], np.column_stack([t, [0, 0, 1, 1, 0, 1]]))
    got = Events(tr.columns).changes(tr)
    assert got == [(20.0, "INFO", "star tracker st1 first valid sample"), (40.0, "WARN", "star tracker st1 dropout"),
                   (50.0, "INFO", "star tracker st1 valid again")]


def test_estimation_panels(est_run, monkeypatch):
    got = drawn(monkeypatch, est_run)
    axes = got["axes"]
    tr, _ = dash.load_run(est_run)
    err = next(ax for t, ax in axes.items() if t.startswith("estimation error"))
    lines = {ln.get_label(): ln.get_ydata() for ln in err.get_lines()}
    for a in "xyz":
        assert_allclose(lines[f"{a} error"], tr[f"est_err_{a}_deg"] * 3600.0, rtol=1e-15)  # arcsec
        assert_allclose(lines[f"{a} ±3σ"], tr[f"est_3sigma_{a}_deg"] * 3600.0, rtol=1e-15)
    nees = next(ax for t, ax in axes.items() if t.startswith("NEES"))
    assert_allclose(dict((ln.get_label(), ln.get_ydata()) for ln in nees.get_lines())[f"NEES (mean {np.mean(tr['nees']):.3g})"], tr["nees"])
    assert any(ln.get_label() == "expected 6" and ln.get_ydata()[0] == 6.0 for ln in nees.get_lines())
    st = next(ax for t, ax in axes.items() if t.startswith("star-tracker heads"))
    ticks = [x.get_text() for x in st.get_yticklabels()]
    for k, head in enumerate(("st1", "st2")):
        v = tr[f"st_valid_{head}"]
        assert v[0] == 0.0  # no sample at t = 0 (the head's first comes at t = 1 s)
        first = int(np.argmax(v >= 0.5))
        # dropouts by hand: a valid row followed by an invalid one
        n_drop = sum(1 for i in range(first + 1, len(v)) if v[i] < 0.5 and v[i - 1] >= 0.5)
        assert ticks[k] == f"{head} ({n_drop} dropouts)"
    assert ticks[0] == "st1 (1 dropouts)"  # st1's sun exclusion: the run's one real dropout
    bars = {c.get_label(): c for c in st.collections}
    assert {"valid", "dropout", "no valid sample yet"} <= set(bars)
    t1 = tr.t[int(np.argmax(tr["st_valid_st1"] >= 0.5))]
    for path in bars["dropout"].get_paths():
        assert path.vertices[:, 0].min() >= t1  # no dropout drawn before st1's first valid row


# -- CMG limit: saturation only where the momentum saturated ------------------------------------
def _limit_rows(n):
    """Rows 3..5 flagged with |h| low (rate limit), rows 8..9 flagged with |h| = 0.95 capacity."""
    t = np.arange(n) * 10.0
    h = np.zeros((n, 3))
    h[:, 0] = 1000.0  # N m s
    h[8:10, 0] = 0.95 * 4 * 4760.0  # N m s, above the 0.9 x capacity threshold
    flag = np.zeros(n)
    flag[3:6] = 1.0
    flag[8:10] = 1.0
    return Trajectory(["t", "hx", "hy", "hz", "cmg_saturated"], np.column_stack([t, h, flag]))


def test_recording_names_the_rate_limit_and_the_saturation():
    tr = _limit_rows(12)
    ev = Events.of(load_scene(HOLD), tr.columns)
    assert ev._cmg[1] * ev._cmg[2].capacity_Nms == pytest.approx(HOLD_H_SAT_NMS, rel=1e-15)
    got = [(t, text) for t, _, text in ev.changes(tr)]
    assert got == [(30.0, "CMG gimbal-rate limit begins"), (60.0, "CMG gimbal-rate limit ends"),
                   (80.0, "CMG momentum saturation begins"), (100.0, "CMG momentum saturation ends")]


def test_dashboard_names_the_rate_limit_and_the_saturation(est_run, tmp_path, monkeypatch):
    def edit(cols):
        n = len(cols["t"])
        cols["cmg_saturated"] = np.zeros(n)
        cols["cmg_saturated"][3:6] = 1.0  # |h| of the run: ~20 % of capacity
        cols["cmg_saturated"][8:10] = 1.0
        cols["hx"][8:10], cols["hy"][8:10], cols["hz"][8:10] = 0.95 * 4 * 4760.0, 0.0, 0.0  # N m s

    run = copy_run(est_run, tmp_path / "r", edit, summary={"h_saturation_Nms": HOLD_H_SAT_NMS, "rate_limited_ticks": 5,
                                                            "momentum_saturated_ticks": 3})
    got = drawn(monkeypatch, run)
    first = next(iter(got["axes"].values()))
    marks = {ln.get_label(): ln.get_xdata() for ln in first.get_lines() if ln.get_marker() == "|"}
    tr, _ = dash.load_run(run)
    assert_allclose(marks["CMG gimbal-rate limit"], tr.t[3:6])
    assert_allclose(marks["CMG momentum saturation"], tr.t[8:10])
    # the shipped estimated run never saturates: no "saturation" anywhere in its dashboard
    got = drawn(monkeypatch, est_run)
    assert not any("saturation" in ln.get_label() for ax in got["axes"].values() for ln in ax.get_lines()
                   if ln.get_marker() == "|")


# -- thrusters -------------------------------------------------------------------------------
def test_thruster_panel(est_run, tmp_path, monkeypatch):
    dump = slice(10, 16)

    def edit(cols):
        n = len(cols["t"])
        cols["thr_dumping"] = np.zeros(n)
        cols["thr_dumping"][dump] = 1.0
        cols["thr_mode"] = np.zeros(n)
        cols["thr_firings"] = np.cumsum(cols["thr_dumping"] * 2.0)
        cols["thr_propellant_kg"] = cols["thr_firings"] * 130.0 * 0.03 / (280.0 * 9.80665)  # F t_on / (Isp g0)

    run = copy_run(est_run, tmp_path / "r", edit)
    got = drawn(monkeypatch, run)
    title = next(t for t in got["axes"] if t.startswith("thrusters"))
    ax = got["axes"][title]
    tr, _ = dash.load_run(run)
    assert_allclose(dict((ln.get_label(), ln.get_ydata()) for ln in ax.get_lines())["firings"], tr["thr_firings"])
    twin = [a for a in got["fig"].axes if a is not ax and a.bbox.bounds == ax.bbox.bounds]
    assert_allclose(dict((ln.get_label(), ln.get_ydata()) for ln in twin[0].get_lines())["propellant [kg]"],
                    tr["thr_propellant_kg"])
    span = [p for p in ax.patches if p.get_label() == "momentum dump"]
    assert len(span) == 1
    x0 = span[0].get_x()
    assert_allclose([x0, x0 + span[0].get_width()], [tr.t[dump.start - 1], tr.t[dump.stop - 1]])  # rows since the previous row


# -- legends inside their axes ----------------------------------------------------------------
def test_every_legend_is_inside_its_axes(est_run, tmp_path, monkeypatch):
    """Six entries in six columns (the attitude error with both kinds of limit ticks, the torque's
    command and delivered per axis) were wider than their panels: drawn without
    :func:`~stationbed.core.plotting.fit_legends`, three legends of this run stick out."""
    def edit(cols):
        cols["cmg_saturated"][3:6] = 1.0
        cols["cmg_saturated"][8:10] = 1.0
        cols["hx"][8:10], cols["hy"][8:10], cols["hz"][8:10] = 0.95 * 4 * 4760.0, 0.0, 0.0  # N m s

    run = copy_run(est_run, tmp_path / "r", edit, summary={"h_saturation_Nms": HOLD_H_SAT_NMS, "rate_limited_ticks": 5,
                                                            "momentum_saturated_ticks": 3})
    for folder in (est_run, run):
        got = drawn(monkeypatch, folder)
        assert all(got["inside"].values()), [t for t, ok in got["inside"].items() if not ok]


# -- gravity gradient in the disturbance panel ------------------------------------------------
GG_SCENE = """
name = "gg_tumble"
[simulation]
duration = 600.0
output_dt = 20.0
[initial]
q_BN = [0.9, 0.3, -0.3, 0.1]
omega_BN_B = [0.002, -0.001, 0.003]   # rad/s
[body]
mass = 4.0e5                          # kg
inertia = [[1.02e8, 2.0e6, 0.0], [2.0e6, 0.91e8, 0.0], [0.0, 0.0, 1.64e8]]  # kg m²
cm = [0.0, 0.0, 0.0]
[orbit]
altitude = 400000.0                   # m
inclination = 0.9006                  # rad
u0 = 0.3                              # rad
gravity_gradient = true
"""


def test_gravity_gradient_column_is_the_hand_torque(tmp_path, monkeypatch):
    (tmp_path / "gg.toml").write_text(GG_SCENE)
    out = tmp_path / "o"
    assert main(["run", str(tmp_path / "gg.toml"), "-q", "--out", str(out)]) == 0
    tr, _ = dash.load_run(out)
    r = R_EARTH_M + 400e3
    n = math.sqrt(MU_M3_S2 / r**3)
    inc, I = 0.9006, np.array([[1.02e8, 2.0e6, 0.0], [2.0e6, 0.91e8, 0.0], [0.0, 0.0, 1.64e8]])
    truth = []
    for t, q in zip(tr.t, tr.cols("qw", "qx", "qy", "qz")):
        u = 0.3 + n * t
        R_N = np.array([math.cos(u), math.sin(u) * math.cos(inc), math.sin(u) * math.sin(inc)])
        C_BN = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix().T
        R_B = C_BN @ R_N
        truth.append(3.0 * MU_M3_S2 / r**3 * np.cross(R_B, I @ R_B))
    got = tr.cols("tau_gg_x", "tau_gg_y", "tau_gg_z")
    assert np.abs(got).max() > 1.0  # N m: a real torque, not zeros
    assert_allclose(got, np.array(truth), rtol=0, atol=GG_TOL_NM)
    ax = next(ax for t, ax in drawn(monkeypatch, out)["axes"].items() if t.startswith("disturbance"))
    lines = dict((ln.get_label(), ln.get_ydata()) for ln in ax.get_lines())
    for i, a in enumerate("xyz"):
        assert_allclose(lines[f"gravity gradient {a}"], got[:, i], rtol=1e-15)


# -- compare: one file per comparison ---------------------------------------------------------
def test_two_comparisons_write_two_files(est_run, tmp_path, capsys):
    a, b, c = (copy_run(est_run, tmp_path / n) for n in ("a", "b", "c"))
    other = copy_run(est_run, tmp_path / "elsewhere" / "b")  # the same name in another folder
    pngs = []
    for pair in ((a, b), (a, c), (a, other), (a, b)):
        assert main(["compare", *map(str, pair)]) == 0
        pngs.append(Path(capsys.readouterr().out.strip().splitlines()[-1].removeprefix("wrote ")))
    assert len(set(pngs[:3])) == 3 and pngs[3] == pngs[0]  # the same comparison: its own file again
    assert all(p.parent == tmp_path and p.is_file() for p in pngs)
    assert pngs[0].name.startswith("compare_a_vs_b_") and pngs[1].name.startswith("compare_a_vs_c_")
    assert not (tmp_path / "compare.png").exists()


# -- thrusters in the recording ----------------------------------------------------------------
@pytest.fixture(scope="module")
def thr_run(tmp_path_factory):
    """The thruster-assist scene's first 100 s (no firing yet: the test puts firings in)."""
    out = tmp_path_factory.mktemp("thr") / "thr"
    assert main(["run", str(THRUST), "-q", "--out", str(out), "--duration", "100"]) == 0
    return out


def test_recording_lights_the_thrusters_that_fired(thr_run, tmp_path):
    pytest.importorskip("rerun.chunk")
    from stationbed.output.rerun.recording import write_recording

    scene = load_scene(THRUST)
    tr = Trajectory.from_csv(thr_run / "trajectory.csv")
    names = [t.name for t in scene.thruster]
    cols = dict(zip(tr.columns, tr.data.T.copy()))
    on = np.zeros((len(tr), len(names)))
    on[3:, 0] = 0.03  # s: aft_p_1 fires once between rows 2 and 3
    on[5:, 5] = 0.03
    on[6:, 5] = 0.06  # aft_m_6 fires between rows 4-5 and 5-6
    on[5:, 12] = 0.03
    for k, n in enumerate(names):
        cols[f"thr_on_s_{n}"] = on[:, k]
    tr = Trajectory(list(cols), np.column_stack(list(cols.values())))
    path = write_recording(tr, scene, tmp_path / "t.rrd")
    lit_by_hand = np.vstack([on[:1] > 0, np.diff(on, axis=0) > 0])
    static, rows = entity_rows(path, "world/station/thrusters")
    colors = {round(t, 6): row["Arrows3D:colors"] for t, row in rows}
    assert static["Arrows3D:labels"] == names
    # the station's arrays balance about y: the composite mass centre is the body's origin
    assert_allclose(static["Arrows3D:origins"], [t.position_B for t in scene.thruster], atol=1e-5)
    d = np.array([t.direction_B for t in scene.thruster])
    v = np.array(static["Arrows3D:vectors"])
    assert_allclose(v / np.linalg.norm(v, axis=1, keepdims=True), -d, atol=1e-6)  # the plumes
    # the colours as of each row (the last change at or before it) match the firing by hand
    times = sorted(colors)
    for i, t in enumerate(tr.t):
        latest = colors[max(s for s in times if s <= t + 1e-9)]
        fired = np.array([(int(col) >> 24 & 0xFF, int(col) >> 16 & 0xFF, int(col) >> 8 & 0xFF) == (255, 140, 0)
                          for col in latest])
        assert fired.tolist() == lit_by_hand[i].tolist(), (t, fired, lit_by_hand[i])


def test_recording_of_the_estimated_run_before_the_first_sample(est_run, tmp_path):
    """The shipped estimated run, recorded: at t = 0 (no sample yet) the heads are grey and no
    dropout is logged; st1's one dropout (the sun exclusion) is red and logged at its row."""
    rerun_chunk = pytest.importorskip("rerun.chunk")
    from stationbed.output.rerun.events import RGB_BLIND, RGB_NO_SAMPLE, RGB_VALID
    from stationbed.output.rerun.recording import write_recording

    tr = Trajectory.from_csv(est_run / "trajectory.csv")
    path = write_recording(tr, load_scene(ESTIMATED), tmp_path / "est.rrd")
    rows = {}
    for c in rerun_chunk.RrdReader(path).stream().to_chunks():
        ent = c.entity_path.lstrip("/")
        if c.is_static or not (ent == "events" or ent.endswith("/boresight")):
            continue
        rb = c.to_record_batch()
        for i, t in enumerate(rb.column("sim_time").cast("int64").to_pylist()):
            comp = {n: rb.column(n)[i].as_py() for n in rb.schema.names if ":" in n}
            rows.setdefault(ent, []).append((t * 1e-9, comp))
    texts = sorted((t, c["TextLog:text"][0]) for t, c in rows["events"])
    v1, v2 = tr["st_valid_st1"], tr["st_valid_st2"]
    first = [tr.t[int(np.argmax(v >= 0.5))] for v in (v1, v2)]
    drop1 = tr.t[int(np.argmax((np.arange(len(v1)) > np.argmax(v1 >= 0.5)) & (v1 < 0.5)))]  # by hand
    st = [(t, x) for t, x in texts if x.startswith("star tracker")]
    assert st == sorted([(first[0], "star tracker st1 first valid sample"), (first[1], "star tracker st2 first valid sample"),
                         (drop1, "star tracker st1 dropout")])

    def rgb(c):
        col = c["Arrows3D:colors"][0]
        return ((col >> 24) & 0xFF, (col >> 16) & 0xFF, (col >> 8) & 0xFF)

    got = sorted((t, rgb(c)) for t, c in rows["world/station/sensors/st1/boresight"])
    assert got == [(0.0, RGB_NO_SAMPLE), (first[0], RGB_VALID), (drop1, RGB_BLIND)]


def test_gravity_gradient_column_of_the_fused_closed_loop_with_arrays(est_run):
    """The estimated hold (fused flight loop, two sun-tracking arrays): ``tau_gg`` is the hand
    torque with the inertia about O of the body and both arrays at their logged joint angles,
    ``I = I_body + Σ (C_BP I_P C_BPᵀ + m (|r|² E - r rᵀ))``, ``C_BP`` the active rotation by α
    about y then by β about x (TP-2511 Eq. 35-38); the arrays' products of inertia are most of
    this torque, so leaving them out misses by ~3 N m."""
    tr = Trajectory.from_csv(est_run / "trajectory.csv")
    r = R_EARTH_M + 400e3
    n2 = MU_M3_S2 / r**3
    inc = 0.9006  # rad, u0 = 0
    I_body = np.diag([1.02e8, 0.91e8, 1.64e8])  # kg m²
    # each pair's wing (the scene's wing table): two plates of span L = 35 m along P x from o = 2 m
    # out on either side of the gimbal, chord c = 24 m along P y, facing P z; uniform thin plates
    m_P, L, o, c = 2200.0, 35.0, 2.0, 24.0  # kg per array pair, m
    I_x, I_y = m_P * c**2 / 12.0, m_P * ((o + L) ** 3 - o**3) / (3.0 * L)  # kg m²: ∫y² dm, ∫x² dm
    I_P = np.diag([I_x, I_y, I_x + I_y])
    truth = []
    for k, (t, q) in enumerate(zip(tr.t, tr.cols("qw", "qx", "qy", "qz"))):
        I = I_body.copy()
        for name, y in (("stbd_pair", 38.0), ("port_pair", -38.0)):  # m, the pairs' mass centres on y_B
            C_BP = (Rotation.from_rotvec([0.0, tr[f"alpha_{name}"][k], 0.0]).as_matrix()
                    @ Rotation.from_rotvec([tr[f"beta_{name}"][k], 0.0, 0.0]).as_matrix())
            rv = np.array([0.0, y, 0.0])
            I += C_BP @ I_P @ C_BP.T + m_P * (rv @ rv * np.eye(3) - np.outer(rv, rv))
        u = math.sqrt(n2) * t
        R_N = np.array([math.cos(u), math.sin(u) * math.cos(inc), math.sin(u) * math.sin(inc)])
        R_B = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix().T @ R_N
        truth.append(3.0 * n2 * np.cross(R_B, I @ R_B))
    got = tr.cols("tau_gg_x", "tau_gg_y", "tau_gg_z")
    assert np.abs(got).max() > 1.0  # N m
    assert_allclose(got, np.array(truth), rtol=0, atol=GG_TOL_NM)


def test_recording_has_a_thrusters_tab_and_no_thruster_column_left_over(thr_run, tmp_path):
    """The thr_* columns get entities of their own (none in ``telemetry/extra``) shown in a
    "thrusters" tab, the firings total large; the logged totals equal the CSV's."""
    pytest.importorskip("rerun.chunk")
    from test_rerun import read_temporal
    from test_rerun_blueprint import TABS, blueprint_tree

    from stationbed.output.rerun.recording import write_recording

    scene = load_scene(THRUST)
    tr = Trajectory.from_csv(thr_run / "trajectory.csv")
    path = write_recording(tr, scene, tmp_path / "t.rrd")
    data = read_temporal(path)
    assert not [e for e in data if e.startswith("telemetry/extra/thr_")]
    assert_allclose(data["telemetry/thrusters/propellant_kg"]["Scalars:scalars"].ravel(), tr["thr_propellant_kg"], rtol=0, atol=0)
    assert_allclose(data["telemetry/thrusters/on_s"]["Scalars:scalars"],
                    tr.cols(*(f"thr_on_s_{t.name}" for t in scene.thruster)), rtol=0, atol=0)
    root, containers, views = blueprint_tree(path)
    (tab_box,) = [c for c in containers.values() if c["kind"] == TABS]
    tabs = {containers[k]["name"]: containers[k] for k in tab_box["contents"]}
    assert "thrusters" in tabs and "other" not in tabs
    assert views[tabs["thrusters"]["contents"][0]][1] == "thruster firings (total)"
