"""``stationbed study precision`` on a closed-loop scene (issue 25): the loop's own choices
against a tight reference of the same loop.

Truths: RK4's convergence (halving the step inside each tick cuts the error against the DOP853
reference of the same zero-order-hold loop, by at least 2x across the drives' limit switches);
the reference's
cross-check (RK4 at 8 sub-steps) far below the errors it judges; each choice recorded as run.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from stationbed.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenarios" / "iss_lvlh_hold.toml"
DURATION_S = 120.0  # s: 1200 ticks, the initial 0.55 deg transient under way
#: RK4 is 4th order on a smooth right-hand side (16x per halving), but the array drives' clipped
#: acceleration (model/appendages.py: a kink in the right-hand side at each limit switch, all in
#: the first 10 s of SARJ spin-up) leaves a step error ~c(theta) h^2 per kink, c depending on where
#: the kink falls inside the step, which moves as the step halves: 4x per halving only as an
#: envelope, a single halving's gain varies (measured 2.8x then 5.4x with the wings facing their
#: plates, issue 32; 4.4x then 1.4x on the earlier arrays). The claim kept, on the first halving at
#: this duration: at least 2x (1x if sub-steps changed nothing, the fault this guards)
RK4_HALVING_GAIN = 2.0


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("loop_precision")
    code = main(["study", "precision", str(SCENE), "--quick", "--duration", str(DURATION_S), "--formulations", "momentum",
                 "--out", str(out)])
    assert code == 0
    with open(out / "precision_loop.csv") as fh:
        rows = list(csv.DictReader(fh))
    return out, rows


@pytest.mark.slow
def test_files_and_choices(study):
    out, rows = study
    for name in ("precision_loop.csv", "precision_loop.png", "precision_loop_cheapest.md"):
        assert (out / name).stat().st_size > 0
    got = {(r["substeps"], r["environment_rate"], r["fused"]) for r in rows if r["status"] == "ok"}
    assert got == {("1", "0", "True"), ("2", "0", "False"), ("1", "10", "True")}
    assert "1e-06" in (out / "precision_loop_cheapest.md").read_text()


@pytest.mark.slow
def test_substeps_converge(study):
    _, rows = study
    err = {r["substeps"]: float(r["att_err_rad"]) for r in rows if r["environment_rate"] == "0"}
    assert err["1"] / err["2"] >= RK4_HALVING_GAIN


@pytest.mark.slow
def test_held_environment_costs_no_accuracy_at_this_rate(study):
    """Every 10 ticks the held environment's difference (~1e-11 rad per orbit, docs/design.md)
    is far below RK4's own error against the reference: the two agree to 1 %."""
    _, rows = study
    err = {(r["substeps"], r["environment_rate"]): float(r["att_err_rad"]) for r in rows}
    assert abs(err[("1", "10")] - err[("1", "0")]) <= 0.01 * err[("1", "0")]


def test_integrators_option_refused_on_a_closed_loop_scene(tmp_path, capsys):
    """The loop's study has no integrator to choose: naming some is bad input, said in one line."""
    code = main(["study", "precision", str(SCENE), "--integrators", "rk4", "--quick", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("stationbed: error: --integrators:") and err.count("\n") == 1
