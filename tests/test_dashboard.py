"""``stationbed plot`` and ``compare`` (issue 19, items 15, 16 and 18), each against a truth that
does not come from the dashboard code:

* the body rate relative to LVLH equals ``ω_BN_B - C_BO (0, -n, 0)`` with LVLH built here from the
  circular orbit's position and normal, and ``C_BN`` from scipy's rotation of the logged quaternion;
* the delivered CMG torque equals the torque an ideal cluster with a torque limit can deliver
  (the command clipped to the limit), and ``-(dh/dt + ω × h)`` of an analytic momentum history;
* ``compare --settle`` equals the reductions of the CSV's own rows at ``t >= settle`` (numpy here);
* bad and partial run folders give one ``stationbed: error:`` line naming the file (exit 2) or a
  labelled chart of the rows kept, and nothing else on stderr.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from stationbed.analysis import compare as compare_mod
from stationbed.analysis import dashboard as dash
from stationbed.analysis.signals import delivered_torque, h_fraction, rate_of_change, relative_rate
from stationbed.cli import main
from stationbed.run.trajectory import Trajectory

ROOT = Path(__file__).resolve().parents[1]
STATIONBED = Path(sys.executable).parent / "stationbed"
HOLD = ROOT / "scenarios" / "iss_lvlh_hold.toml"
HOLD_S = 600.0  # s: the initial transient of the LVLH hold
MU_M3_S2 = 3.986004418e14  # m³/s², Earth (the scene's default)
R_EARTH_M = 6378137.0  # m, WGS-84 equatorial radius (the scene's altitude is above it)
#: relative-rate truth: the reference is LVLH on a circular orbit, which turns at a constant rate
#: about a fixed axis, so the rows' rotation over a step is exact; what is left is the round-off of
#: rebuilding q_RN from 17-digit CSV values, divided by the 20 s step [rad/s]
REL_RATE_TOL_RAD_S = 1e-12
#: an ideal cluster's delivered torque from rows 10 s apart: h grows linearly while the command
#: is constant and ω stays ~1e-7 rad/s, so central differences are exact to round-off [N m]
DELIVERED_TOL_NM = 1e-6


def run_cli(*args):
    return subprocess.run([str(STATIONBED), *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def hold_run(tmp_path_factory):
    """The shipped LVLH hold, its first 10 minutes (pd, DGCMGs, sun-tracking arrays)."""
    out = tmp_path_factory.mktemp("plot") / "hold"
    assert main(["run", str(HOLD), "-q", "--out", str(out), "--duration", str(HOLD_S)]) == 0
    return out


@pytest.fixture(scope="module")
def open_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("open")
    for name, scene in (("a", "torque_window.toml"), ("b", "power_tower_free_drift.toml")):
        assert main(["run", str(ROOT / "scenarios" / scene), "-q", "--out", str(base / name), "--duration", "1200"]) == 0
    return base / "a", base / "b"


def lvlh_rate_truth(tr):
    """ω_BO_B from first principles: the circular orbit of iss_lvlh_hold (400 km, i = 0.9006, u0 = 0)."""
    r = R_EARTH_M + 400e3
    n = math.sqrt(MU_M3_S2 / r**3)
    inc = 0.9006
    out = []
    for t, q, w in zip(tr.t, tr.cols("qw", "qx", "qy", "qz"), tr.cols("wx", "wy", "wz")):
        u = n * t
        R = np.array([math.cos(u), math.sin(u) * math.cos(inc), math.sin(u) * math.sin(inc)])
        normal = np.array([0.0, -math.sin(inc), math.cos(inc)])  # R × V direction
        z, y = -R, -normal
        C_ON = np.array([np.cross(y, z), y, z])  # rows: O axes in N
        C_BN = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix().T
        out.append(w - C_BN @ C_ON.T @ np.array([0.0, -n, 0.0]))
    return np.array(out), n


def test_relative_rate_is_the_rate_relative_to_lvlh(hold_run):
    tr, _ = dash.load_run(hold_run)
    truth, n = lvlh_rate_truth(tr)
    got = relative_rate(tr)
    assert_allclose(got, truth, rtol=0, atol=REL_RATE_TOL_RAD_S)
    # what it shows that the inertial rate hides: the transient is far below the orbital rate
    assert np.abs(got).max() < 0.05 * n and np.abs(tr.cols("wx", "wy", "wz")).max() > 0.9 * n


def test_open_loop_has_no_reference_rate(open_runs):
    tr, _ = dash.load_run(open_runs[0])
    assert relative_rate(tr) is None


def test_dashboard_panels_of_a_closed_loop_run(hold_run, monkeypatch):
    """The drawn dashboard: the rate panel is relative to the reference, the |h| panel is the
    fraction of capacity with its axis from 0, and the torque panel has command and delivered."""
    drawn = {}
    real_save = dash.save_png

    def spy(plt, fig, path, **kw):
        drawn.update({ax.get_title(): ax for ax in fig.axes if ax.get_visible()})
        drawn["_lines"] = {ax.get_title(): [(ln.get_label(), ln.get_ydata()) for ln in ax.get_lines()] for ax in fig.axes}
        real_save(plt, fig, path, **kw)

    monkeypatch.setattr(dash, "save_png", spy)
    png = dash.dashboard(hold_run)
    assert png.stat().st_size > 0
    titles = [t for t in drawn if t != "_lines"]
    assert any("relative to the reference" in t for t in titles) and not any("ω_BN_B" in t for t in titles)
    frac_title = next(t for t in titles if "|h| / capacity" in t)
    assert drawn[frac_title].get_ylim()[0] == 0.0
    tr, meta = dash.load_run(hold_run)
    cap = meta["summary"]["h_capacity_Nms"]
    y = dict(drawn["_lines"][frac_title])["|h| / capacity"]
    assert (y >= 0).all()
    assert_allclose(y, np.linalg.norm(tr.cols("hx", "hy", "hz"), axis=1) / cap, rtol=1e-15)
    torque = next(t for t in titles if "command" in t and "delivered" in t)
    labels = [lab for lab, _ in drawn["_lines"][torque]]
    assert {f"{a} command" for a in "xyz"} | {f"{a} delivered" for a in "xyz"} <= set(labels)


def test_h_fraction_is_a_norm_over_capacity():
    tr = Trajectory(["t", "hx", "hy", "hz"], np.array([[0.0, -3.0, -4.0, 0.0], [1.0, 0.0, 0.0, -10.0]]))
    assert_allclose(h_fraction(tr, {"h_capacity_Nms": 10.0}), [0.5, 1.0])
    assert h_fraction(tr, {}) is None and h_fraction(tr, {"h_capacity_Nms": math.inf}) is None


def test_delivered_torque_of_an_analytic_momentum_history():
    """h(t) = a sin(w t) about a body turning at constant ω: -(ḣ + ω × h) in closed form; central
    differences of rows dt apart err by (w dt)²/6 of ḣ."""
    w, dt = 0.01, 0.5  # rad/s, s
    t = np.arange(0.0, 200.0 + dt / 2, dt)
    a = np.array([30.0, -10.0, 5.0])  # N m s
    omega = np.array([1e-3, -2e-3, 5e-4])  # rad/s
    h = np.sin(w * t)[:, None] * a
    cols = ["t", "wx", "wy", "wz", "hx", "hy", "hz"]
    tr = Trajectory(cols, np.column_stack([t, np.tile(omega, (len(t), 1)), h]))
    truth = -(w * np.cos(w * t)[:, None] * a + np.cross(omega, h))
    got = delivered_torque(tr)
    tol = (w * dt) ** 2 / 6 * w * np.abs(a).max() * 1.01
    assert_allclose(got[1:-1], truth[1:-1], rtol=0, atol=tol)
    assert_allclose(rate_of_change(t, h)[[0, -1]], (w * np.cos(w * t)[:, None] * a)[[0, -1]], rtol=0, atol=w * dt * w * np.abs(a).max())


def test_delivered_torque_is_the_limited_one(tmp_path):
    """An ideal cluster limited to 5 N m asked for 20 N m: the command column says 20, the
    delivered torque is 5 (deep space, rigid body from rest)."""
    scene = tmp_path / "s.toml"
    scene.write_text("""
name = "limited"
[simulation]
duration = 200.0
integrator = "rk4"
step = 0.1
output_dt = 10.0
[body]
mass = 1.0e5
inertia = [[4.0e7, 0.0, 0.0], [0.0, 5.0e7, 0.0], [0.0, 0.0, 6.0e7]]
cm = [0.0, 0.0, 0.0]
[cmg]
kind = "ideal"
max_torque = 5.0
[controller]
name = "torque_command"
period = 0.1
[controller.params]
torque_B = [20.0, 0.0, 0.0]
""")
    assert main(["run", str(scene), "-q", "--out", str(tmp_path / "o")]) == 0
    tr, _ = dash.load_run(tmp_path / "o")
    assert_allclose(tr["tau_cmd_x"], 20.0)
    assert_allclose(delivered_torque(tr), np.tile([5.0, 0.0, 0.0], (len(tr), 1)), rtol=0, atol=DELIVERED_TOL_NM)


# -- compare --settle -------------------------------------------------------------------------
def _trapezoid(f, t) -> float:
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(t)))


def test_compare_settle_applies_to_every_row_metric(hold_run, capsys):
    settle = 300.0  # s
    assert main(["compare", str(hold_run), "--settle", str(settle), "--png", str(hold_run.parent / "c.png")]) == 0
    table = capsys.readouterr().out
    rows = {line.split()[0]: line for line in table.splitlines()[1:] if line and not line.startswith("wrote")}
    tr, meta = dash.load_run(hold_run)
    late = tr.t >= settle
    truth = {
        "max_att_err_deg": np.nanmax(tr["att_err_deg"][late]),
        # a time mean (trapezoid between rows, issue 32)
        "rms_att_err_deg": math.sqrt(_trapezoid(tr["att_err_deg"][late] ** 2, tr.t[late]) / (tr.t[-1] - tr.t[late][0])),
        "max_h_Nms": np.linalg.norm(tr.cols("hx", "hy", "hz")[late], axis=1).max(),
        "min_singularity": tr["cmg_singularity"][late].min(),
        "max_torque_cmd_Nm": np.linalg.norm(tr.cols("tau_cmd_x", "tau_cmd_y", "tau_cmd_z")[late], axis=1).max(),
    }
    assert truth["max_att_err_deg"] < np.nanmax(tr["att_err_deg"])  # the settle time matters here
    for key, v in truth.items():
        assert f"t >= {settle:g} s" in rows[key]
        assert float(rows[key].split()[-1]) == pytest.approx(v, rel=1e-3)  # the table's 4 digits
    for key in ("rate_limited_ticks", "momentum_saturated_ticks"):
        assert "all ticks" in rows[key]
    assert "last row" in rows["final_att_err_deg"]


@pytest.mark.parametrize("settle", ["1e6", "nan", "-1"], ids=["after_the_end", "nan", "negative"])
def test_compare_settle_that_cannot_apply_is_refused(hold_run, settle):
    res = run_cli("compare", hold_run, "--settle", settle, "--png", hold_run.parent / "x.png")
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("stationbed: error: ") and "--settle" in res.stderr
    assert not (hold_run.parent / "x.png").exists()


def test_compare_of_two_open_loop_runs(open_runs, tmp_path):
    res = run_cli("compare", *open_runs, "--png", tmp_path / "c.png")
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    assert "no run metric applies" in res.stdout
    assert (tmp_path / "c.png").stat().st_size > 0


# -- bad and partial run folders --------------------------------------------------------------
def test_plot_of_a_cut_csv_names_the_file_and_line(hold_run, tmp_path):
    text = (hold_run / "trajectory.csv").read_text()
    (tmp_path / "trajectory.csv").write_text(text[: len(text) // 2])  # cut mid-row
    n_line = text[: len(text) // 2].count("\n") + 1
    for cmd in (["plot", tmp_path], ["compare", hold_run, tmp_path]):
        res = run_cli(*cmd)
        assert res.returncode == 2
        assert res.stderr.count("\n") == 1
        assert res.stderr.startswith(f"stationbed: error: {tmp_path / 'trajectory.csv'}: line {n_line} has ")
        assert "cut" in res.stderr


@pytest.mark.parametrize("text, words", [("", "no header"), ("t,qw\n1.0,abc\n", "line 2, column 2: 'abc'"),
                                         ("t,qw,qx\n", "no rows")], ids=["empty", "text", "header_only"])
def test_plot_of_a_bad_csv_is_one_line(tmp_path, text, words):
    (tmp_path / "trajectory.csv").write_text(text)
    res = run_cli("plot", tmp_path)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("stationbed: error: ") and words in res.stderr


@pytest.fixture(scope="module")
def failed_run(tmp_path_factory):
    """The LVLH hold whose law raises at t = 100 s: its rows are in trajectory.partial.csv."""
    base = tmp_path_factory.mktemp("failed")
    (base / "boom.py").write_text(
        "import numpy as np\nfrom stationbed import Controller\n"
        "class Boom(Controller):\n    name = 'boom'\n"
        "    def _update(self, t, meas):\n"
        "        if t > 100.0:\n            raise RuntimeError('boom')\n"
        "        self.q_ref_BN = meas.q_ON.copy()\n        return np.zeros(3)\n")
    text = HOLD.read_text()
    (base / "boom.toml").write_text(text[: text.index("\n[controller]\n") + 1] + '[controller]\nname = "boom.py:Boom"\nperiod = 0.1\n')
    assert main(["run", str(base / "boom.toml"), "-q", "--out", str(base / "run"), "--duration", "300"]) == 1
    assert not (base / "run" / "trajectory.csv").exists()
    return base / "run"


def test_plot_of_a_failed_run_draws_its_partial_rows(failed_run, monkeypatch, capsys):
    titles = []
    real_save = dash.save_png
    monkeypatch.setattr(dash, "save_png", lambda plt, fig, path, **kw: (titles.append(fig._suptitle.get_text()),
                                                                      real_save(plt, fig, path, **kw)))
    assert main(["plot", str(failed_run)]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "trajectory.partial.csv" in out
    assert (failed_run / "dashboard.png").stat().st_size > 0
    tr, meta = dash.load_run(failed_run)
    assert meta["partial"] and meta["rows_file"] == "trajectory.partial.csv" and tr.t[-1] == pytest.approx(100.0)
    assert "failed run: rows to t = 100.1 s in trajectory.partial.csv" in titles[0]


def test_plot_of_a_killed_run_drops_its_torn_last_row(hold_run, tmp_path, capsys):
    """A run killed mid-write (SIGKILL) may leave trajectory.partial.csv ending inside a row: its
    whole rows are drawn, the torn one is dropped and the title says so. The same cut in a
    finished trajectory.csv stays an error (test_plot_of_a_cut_csv_names_the_file_and_line)."""
    text = (hold_run / "trajectory.csv").read_text()
    cut = text.index("\n", len(text) // 2) + 1 + 40  # 40 characters into a row
    (tmp_path / "trajectory.partial.csv").write_text(text[:cut])
    tr, meta = dash.load_run(tmp_path)
    whole = text[:cut].count("\n") - 1
    assert meta["partial"] and meta["torn_rows"] == 1 and len(tr) == whole
    assert_array_equal(tr.data, Trajectory.from_csv(hold_run / "trajectory.csv").data[:whole])
    assert "unfinished run: rows in trajectory.partial.csv, its torn last row dropped" == dash.run_state(meta)
    assert main(["plot", str(tmp_path)]) == 0
    assert capsys.readouterr().err == ""


def test_compare_with_a_failed_run_labels_it(failed_run, hold_run, tmp_path):
    res = run_cli("compare", hold_run, failed_run, "--png", tmp_path / "c.png")
    assert res.returncode == 0 and res.stderr == ""
    assert "[partial]" in res.stdout and "failed run: rows to t = 100.1 s" in res.stdout


def test_summary_of_another_run_is_not_used(hold_run, tmp_path):
    """summary.json names trajectory.partial.csv (its run failed) but only trajectory.csv is there:
    the rows are drawn without that summary's facts."""
    (tmp_path / "trajectory.csv").write_text((hold_run / "trajectory.csv").read_text())
    (tmp_path / "summary.json").write_text(json.dumps({"status": "failed", "rows_file": "trajectory.partial.csv",
                                                       "summary": {"controller": "other"}}))
    tr, meta = dash.load_run(tmp_path)
    assert meta == {"rows_file": "trajectory.csv", "partial": False, "torn_rows": 0}


def test_plot_writes_nothing_to_stderr(hold_run, tmp_path):
    """Rows without a reference or a torque (NaN) are gaps: no numpy or matplotlib warning."""
    tr, _ = dash.load_run(hold_run)
    data = tr.data.copy()
    for c in ("att_err_deg", "att_err_x_deg", "att_err_y_deg", "att_err_z_deg", "tau_cmd_x", "tau_cmd_y", "tau_cmd_z"):
        data[:5, tr.columns.index(c)] = np.nan
    data[:, tr.columns.index("att_err_deg")] = np.nan
    Trajectory(tr.columns, data).to_csv(tmp_path / "trajectory.csv")
    (tmp_path / "summary.json").write_text((hold_run / "summary.json").read_text().replace('"trajectory.csv"', '"trajectory.csv"'))
    res = run_cli("plot", tmp_path)
    assert res.returncode == 0 and res.stderr == ""
    res = run_cli("compare", hold_run, tmp_path, "--png", tmp_path / "c.png", "--settle", "100")
    assert res.returncode == 0 and res.stderr == ""
