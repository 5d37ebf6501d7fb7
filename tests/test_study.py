"""`stationbed study precision|stability` (stationbed/studies/) through the command line.

Each study runs once per test session in its ``--quick`` form (seconds) and the tests read the
files it wrote: the CSV columns and rows, the PNG charts, and whether each stability verdict is
the one physics demands (an impulse that an ω-state form integrates through changes H; the
momentum form keeps it; a Moore-Penrose law stalls at the pyramid's internal singularity ...).
The independent truths are closed forms written here (the Dzhanibekov flip interval from
Jacobi's elliptic solution of Euler's equations) and invariants of the physics.
"""

from __future__ import annotations

import csv
import fcntl
import math

import numpy as np
import pytest
from scipy.special import ellipk

from scenes import ROOT
from stationbed import FORMULATIONS, INTEGRATORS, simulate
from stationbed.cli import main
from stationbed.scene import scene_from_dict
from stationbed.studies import STABILITY_CASES
from stationbed.studies.precision import QUICK_DIVISIONS, QUICK_RTOLS, TARGETS_RAD
from stationbed.studies.probes import ROUNDOFF_REL, RK4_TABLEAU, flip_times, stability_boundary, stability_function
from stationbed.studies.stability.dzhanibekov import FLIP_SCENE
from stationbed.studies.stability.rate_step import H_JUMP_REL
from stationbed.studies.stability.stiff_modes import QUICK_STIFF_FREQS_HZ, STIFF_TARGET_RAD

#: the quick studies run whole scenarios and sweeps (~25 s warm)
pytestmark = pytest.mark.slow

PRECISION_SCENE = ROOT / "scenarios" / "articulated_stress.toml"
PRECISION_FORMS = ["momentum"]  # one form keeps the cold-cache compile time down (one build per integrator)
PRECISION_ARGS = ["--duration", "60", "--formulations", *PRECISION_FORMS, "--quick"]
PRECISION_COLUMNS = ["formulation", "integrator", "kind", "rtol", "step_s", "status", "att_err_rad",
                     "rate_err_rad_s", "wall_s", "n_rhs", "n_steps"]
SUMMARY_COLUMNS = ["case", "method", "detector", "value", "unit", "verdict"]


def _shared_dir(tmp_path_factory, worker_id, name):
    """One folder per test session, shared by the xdist workers (the study runs once)."""
    base = tmp_path_factory.getbasetemp()
    if worker_id != "master":
        base = base.parent
    return base / name


def _run_once(tmp_path_factory, worker_id, name, argv):
    out = _shared_dir(tmp_path_factory, worker_id, name)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.parent / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the other worker waits for the files, then reads them
        done = out / "exit_code"
        if not done.exists():
            code = main([*argv, "--out", str(out)])
            out.mkdir(parents=True, exist_ok=True)
            done.write_text(str(code))
    return out, int(done.read_text())


@pytest.fixture(scope="module")
def precision_dir(tmp_path_factory, worker_id):
    out, code = _run_once(tmp_path_factory, worker_id, "study_precision",
                          ["study", "precision", str(PRECISION_SCENE), *PRECISION_ARGS])
    assert code == 0
    return out


@pytest.fixture(scope="module")
def stability(tmp_path_factory, worker_id):
    """``stability(case)``: the folder of that case's quick run (one run per case and session,
    so the xdist workers share the cases between them)."""

    def get(case):
        out, code = _run_once(tmp_path_factory, worker_id, f"study_stability_{case}",
                              ["study", "stability", "--quick", "--cases", case])
        assert code == 0
        return out

    return get


def _read(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], [dict(zip(rows[0], r)) for r in rows[1:]]


def _verdicts(out, case):
    _, rows = _read(out / "stability_summary.csv")
    return {r["method"]: r for r in rows if r["case"] == case}


def _png_reads(path):
    """A real chart: a PNG of sensible size with more than one colour in it."""
    import matplotlib.image

    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] >= 400 and img.shape[1] >= 800, img.shape
    assert img[..., :3].std() > 0.05  # not a blank canvas


# ---------------------------------------------------------------------------------------
# precision
# ---------------------------------------------------------------------------------------


def test_precision_writes_one_row_per_method_and_setting(precision_dir):
    """Every registered integrator x the chosen formulations appears, with the quick sweep's
    settings (a method that refuses the scene: one 'skipped' row), in the contract columns."""
    header, rows = _read(precision_dir / "precision.csv")
    assert header == PRECISION_COLUMNS
    for integ, cls in INTEGRATORS.items():
        for form in PRECISION_FORMS:
            mine = [r for r in rows if r["integrator"] == integ and r["formulation"] == form]
            if mine and mine[0]["status"].startswith("skipped"):
                assert len(mine) == 1
                continue
            n_settings = len(QUICK_RTOLS if cls.adaptive else QUICK_DIVISIONS)
            assert len(mine) == n_settings, (integ, form)
            assert {r["kind"] for r in mine} == {"adaptive" if cls.adaptive else "fixed"}


def test_precision_errors_fall_as_settings_tighten(precision_dir):
    """Convergence: for every method that ran, the tighter setting (smaller rtol or step) is
    closer to the reference; the rate error is in rad/s, well below the body rate (5e-3 rad/s)."""
    _, rows = _read(precision_dir / "precision.csv")
    groups = {}
    for r in rows:
        if r["status"] == "ok":
            groups.setdefault((r["formulation"], r["integrator"]), []).append(r)
    assert len(groups) >= len(PRECISION_FORMS) * (len(INTEGRATORS) - 1)  # at most one refuses arrays
    for key, rs in groups.items():
        setting = [float(r["rtol"] or r["step_s"]) for r in rs]
        att = [float(r["att_err_rad"]) for r in rs]
        order = np.argsort(setting)[::-1]  # loose -> tight
        assert att[order[-1]] < att[order[0]], key
        assert all(float(r["rate_err_rad_s"]) < 5e-4 for r in rs), key
        assert all(float(r["wall_s"]) > 0 and int(r["n_rhs"]) > 0 for r in rs), key


def test_precision_table_names_the_cheapest_method_per_target(precision_dir):
    """The table has one line per target, and each named method really reached the target."""
    text = (precision_dir / "precision_cheapest.md").read_text()
    _, rows = _read(precision_dir / "precision.csv")
    lines = [ln for ln in text.splitlines() if ln.startswith("| ") and "e-" in ln.split("|")[1]]
    assert len(lines) == len(TARGETS_RAD)
    for ln, target in zip(lines, TARGETS_RAD):
        cells = [c.strip() for c in ln.strip("|").split("|")]
        assert float(cells[0]) == target
        if cells[2] != "none reached it":
            assert float(cells[4].split()[0]) <= target
            assert any(r["integrator"] == cells[2] and r["formulation"] == cells[1] for r in rows)
    assert "cross-check" in text


def test_precision_charts_render(precision_dir):
    for name in ("precision.png", "precision_rate.png"):
        _png_reads(precision_dir / name)


def test_precision_rejects_unknown_integrator(tmp_path, capsys):
    code = main(["study", "precision", str(PRECISION_SCENE), "--integrators", "euler", "--out", str(tmp_path)])
    assert code == 2
    assert "unknown integrator 'euler'" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# stability
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", list(STABILITY_CASES))
def test_stability_case_writes_csv_png_and_verdicts(stability, case):
    out = stability(case)
    header, rows = _read(out / f"stability_{case}.csv")
    assert len(header) >= 3 and len(rows) > 0
    _png_reads(out / f"stability_{case}.png")
    header, rows = _read(out / "stability_summary.csv")
    assert header == SUMMARY_COLUMNS
    assert {r["case"] for r in rows} == {case}
    assert all(r["verdict"] for r in rows)


def test_rate_step_omega_forms_without_jump_lose_the_impulse(stability):
    """Free drift: H_O_N must be constant across an array rate step. The momentum form (H is
    its state) and the ω-state forms with the jump applied keep it; without the jump the
    ω-state forms change H by the impulse Σ I_p Δω_p (3 % of |H| in this scene)."""
    v = _verdicts(stability("rate_step"), "rate_step")
    for form, cls in FORMULATIONS.items():
        if cls.omega_is_state:
            lost = v[f"{form} (no jump handling)"]
            assert lost["verdict"] == "H jumps (impulse lost)"
            assert float(lost["value"]) > 1e4 * H_JUMP_REL  # ~3e-2: the impulse, not noise
            assert v[f"{form} (jump applied)"]["verdict"] == "H continuous"
        else:
            assert v[form]["verdict"] == "H continuous"


def test_quaternion_norm_drifts_without_projection(stability):
    """Classical RK4 does not preserve |q| = 1 (its error accumulates); projecting after every
    step bounds it by one step's error; integrators that normalise keep |q| = 1 to round-off."""
    v = _verdicts(stability("quat_norm"), "quat_norm")
    rk4 = next(r for m, r in v.items() if m.startswith("rk4 (h"))
    proj = next(r for m, r in v.items() if m.startswith("rk4 + projection"))
    assert float(rk4["value"]) > ROUNDOFF_REL
    assert float(proj["value"]) < float(rk4["value"]) / 10
    for name, cls in INTEGRATORS.items():
        if getattr(cls, "NORMALISE", False):
            r = next(r for m, r in v.items() if m.startswith(f"{name} (h"))
            assert float(r["value"]) < ROUNDOFF_REL, name


def test_cmg_moore_penrose_stalls_and_sr_laws_pass(stability):
    """Wie's pyramid singularity: the Moore-Penrose inverse stalls at h = 2 cos β h0 (no torque
    delivered); singularity-robust and o-DSR pass through and deliver the commanded -100 N m."""
    v = _verdicts(stability("cmg_singularity"), "cmg_singularity")
    assert v["mp"]["verdict"].startswith("stalls")
    assert abs(float(v["mp"]["value"])) < 1.0  # N m
    for law in ("sr", "odsr"):
        assert v[law]["verdict"].startswith("passes through")
        assert float(v[law]["value"]) == pytest.approx(-100.0, rel=0.05)  # N m


def test_long_horizon_has_a_verdict_per_integrator_and_invariant(stability):
    v = _verdicts(stability("long_horizon"), "long_horizon")
    for name in INTEGRATORS:
        for inv in ("energy", "momentum", "Jacobi integral"):
            assert any(m.startswith(f"{name} (") and m.endswith(f"[{inv}]") for m in v), (name, inv)


def test_max_step_and_flip_cases_cover_every_fixed_step_integrator(stability):
    fixed = [n for n, c in INTEGRATORS.items() if not c.adaptive]
    steps = _verdicts(stability("max_step"), "max_step")
    flips = _verdicts(stability("dzhanibekov"), "dzhanibekov")
    for name in fixed:
        assert flips[name]["verdict"]
        assert steps[f"{name}/momentum"]["verdict"]  # --quick: the momentum form only
    # RK4 on articulated_stress: a finite largest step (it does fail on the scan)
    assert 0.0 < float(steps["rk4/momentum"]["value"]) < 600.0


def test_flip_detector_matches_jacobi_elliptic_period():
    """The torque-free rigid body's intermediate-axis rate is ω_y ∝ sn(p t, k) (Landau & Lifshitz
    §37, H² > 2 E I_2): it changes sign every 2 K(k) / p. The study's flip detector on a tight
    reference run recovers that interval."""
    I1, I2, I3 = (FLIP_SCENE["body"]["inertia"][i][i] for i in range(3))  # kg m²
    w = np.array(FLIP_SCENE["initial"]["omega_BN_B"])  # rad/s
    E2 = I1 * w[0] ** 2 + I2 * w[1] ** 2 + I3 * w[2] ** 2  # 2 E [J]
    H2 = (I1 * w[0]) ** 2 + (I2 * w[1]) ** 2 + (I3 * w[2]) ** 2  # |H|² [N² m² s²]
    assert H2 > E2 * I2
    p = math.sqrt((I3 - I2) * (H2 - E2 * I1) / (I1 * I2 * I3))  # 1/s
    m = (I2 - I1) * (E2 * I3 - H2) / ((I3 - I2) * (H2 - E2 * I1))  # k²
    interval = 2 * ellipk(m) / p  # s
    scene = scene_from_dict(FLIP_SCENE)
    tf = flip_times(simulate(scene, integrator="dop853", rtol=1e-12, atol=1e-14))
    assert tf.size >= 4
    # output every 0.5 s, cubic interpolation of ω_y: ~1e-4 s on an interval of ~290 s
    np.testing.assert_allclose(np.diff(tf), interval, rtol=1e-5, atol=0.0)


# ---------------------------------------------------------------------------------------
# stiff array modes
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stiff(stability):
    """``stiff(part, integrator=None)``: rows of the stiff-modes case's CSV (its quick run)."""
    _, rows = _read(stability("stiff_modes") / "stability_stiff_modes.csv")

    def get(part, integrator=None):
        return [r for r in rows if r["part"] == part and (integrator is None or r["integrator"] == integrator)]

    return get


def test_rk4_stability_boundary_on_the_imaginary_axis_is_two_root_two():
    """Classical RK4 on ẋ = iωx multiplies by R(iy) = 1 - y²/2 + y⁴/24 + i(y - y³/6) per step
    (y = ωh); |R(iy)|² = 1 - y⁶/72 + y⁸/576 equals 1 at y = 2√2 (Hairer & Wanner IV.2)."""
    R = stability_function(*RK4_TABLEAU)
    assert stability_boundary(R, 1j) == pytest.approx(2 * math.sqrt(2), rel=1e-9)
    assert abs(R(2j)) < 1.0 < abs(R(3j))


@pytest.mark.parametrize("name", ["rk4", "lie_rk4"])
def test_stiff_mode_sets_the_explicit_fixed_step_at_two_root_two_over_omega(stiff, name):
    """An explicit RK4 step is stable on a lightly damped mode only while ω h <= 2√2: the
    largest stable step the scan finds, times the stiff mode's clamped circular frequency, is
    2√2 at every frequency (coupling raises ω by 0.5 %, damping the boundary by 0.4 %; the
    bisection brackets the limit to 2^(1/64) = 1.1 %), and the first failing step is beyond it."""
    rows = stiff("fixed", name)
    assert rows, "no fixed-step rows"
    for f in QUICK_STIFF_FREQS_HZ:
        mine = [r for r in rows if float(r["f_hi_hz"]) == f]
        omega = 2 * math.pi * f  # rad/s, clamped
        h_ok = max(float(r["step_s"]) for r in mine if r["passed"] == "1")
        h_bad = min(float(r["step_s"]) for r in mine if r["passed"] == "0")
        assert 0.97 * 2 * math.sqrt(2) < omega * h_ok <= omega * h_bad, f
        assert 2 * math.sqrt(2) * 0.99 < omega * h_bad < 2 * math.sqrt(2) * 1.03, f


def test_stiff_mode_leaves_radau_stable_and_its_newton_converged(stiff):
    """Radau IIA is A-stable (|R(z)| <= 1 on the left half-plane): no step makes a damped mode
    grow. Its simplified Newton iteration uses the exact Jacobian at the step's start, which
    solves a linear mode's stage equations at once: the defect stays far below the tolerance at
    every step, 100x past rk4's limit, while the nonlinear rigid tumble (|ω| h ~ 0.7) defeats it."""
    tol = INTEGRATORS["radau"].DEFECT_TOL
    rows = stiff("fixed", "radau")
    assert rows and all(r["passed"] == "1" for r in rows)
    f_hi = QUICK_STIFF_FREQS_HZ[-1]
    h_rk4 = max(float(r["step_s"]) for r in stiff("fixed", "rk4") if r["passed"] == "1" and float(r["f_hi_hz"]) == f_hi)
    assert max(float(r["step_s"]) for r in rows if float(r["f_hi_hz"]) == f_hi) > 100 * h_rk4
    assert max(float(r["newton_defect"]) for r in stiff("newton", "radau")) < 0.1 * tol  # ~8e-3 measured
    assert max(float(r["newton_defect"]) for r in stiff("newton_rigid_tumble", "radau")) > tol


def test_stiff_mode_sets_the_cost_of_explicit_adaptive_methods_only(stiff):
    """For the same attitude accuracy an explicit adaptive method pays for the stiff mode (its
    step is held at the stability boundary, h ∝ 1/ω: 20x the frequency, several times the RHS
    evaluations), an L-stable implicit one does not."""
    f_lo, f_hi = QUICK_STIFF_FREQS_HZ[0], QUICK_STIFF_FREQS_HZ[-1]

    def cost(name, f):
        ok = [r for r in stiff("adaptive", name) if float(r["f_hi_hz"]) == f and r["status"] == "ok"
              and float(r["att_err_rad"]) <= STIFF_TARGET_RAD]
        return int(ok[0]["n_rhs"])

    assert cost("dop853", f_hi) > 5 * cost("dop853", f_lo)
    assert cost("scipy_radau", f_hi) < 2 * cost("scipy_radau", f_lo)
