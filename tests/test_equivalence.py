"""Every formulation against every other on every shipped scenario (CI's equivalence check)."""

import itertools

import casadi as ca
import pytest

from scenes import SCENARIOS, scenario_ids
from stationbed import FORMULATIONS, load_scene
from stationbed.studies.check import check_scene, compare, compare_modes
from stationbed.formulations.dalembert import DAlembertForm
from stationbed.core.massprops import coriolis_matrix

#: every shipped scenario through every formulation (~60 s warm)
pytestmark = pytest.mark.slow

PAIRS = list(itertools.combinations(sorted(FORMULATIONS), 2))


@pytest.fixture(scope="module", params=SCENARIOS, ids=scenario_ids())
def checked(request):
    return check_scene(load_scene(request.param))


@pytest.mark.parametrize("pair", PAIRS, ids=[f"{a}-vs-{b}" for a, b in PAIRS])
def test_formulations_agree(checked, pair):
    a, b = pair
    att, rate, H = compare(checked.trajectories[a], checked.trajectories[b])
    assert att <= checked.tol_att_rad, f"attitude differs by {att:.3e} rad"
    assert rate <= checked.tol_rate, f"rate differs by {rate:.3e} rad/s"
    assert H <= checked.tol_H, f"H_O_N differs by {H:.3e} N m s"
    if checked.tol_eta is not None:  # flexible scene: the modal coordinates agree too
        eta = compare_modes(checked.trajectories[a], checked.trajectories[b])
        assert eta <= checked.tol_eta, f"modal coordinates differ by {eta:.3e}"


class WrongSignCoriolis(DAlembertForm):
    """The D'Alembert form with the Coriolis term's sign flipped: a plausible scan misreading."""

    name = "wrong_sign_coriolis"

    def _array_term(self, w, I_p, w_p, wd_p):
        coriolis = ca.cross(ca.mtimes(coriolis_matrix(I_p), w), w_p)
        return -coriolis + ca.mtimes(I_p, wd_p) + ca.cross(w_p, ca.mtimes(I_p, w_p))


def test_check_catches_a_sign_error():
    """The check is not vacuous: one flipped sign in Cp* fails it by orders of magnitude."""
    scene = load_scene([p for p in SCENARIOS if p.stem == "articulated_stress"][0])
    res = check_scene(scene, formulations=["momentum", WrongSignCoriolis])
    assert not res.ok
    assert res.pairs[0].att_rad > 1e4 * res.tol_att_rad
