"""Invariants: without external torque, total angular momentum about the composite CM is
constant in N while the arrays move; kinetic energy is constant when the arrays are locked."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from stationbed import FORMULATIONS, simulate
from stationbed.scene import scene_from_dict
from stationbed.studies.probes import raw_states
from scenes import articulated_dict

FORMS = sorted(FORMULATIONS)
#: Issue #2: ≤ 1e-10 relative at tight tolerance (rtol 1e-12, a few hundred steps).
H_REL_TOL = 1e-10
T_REL_TOL = 1e-10


@pytest.mark.parametrize("form", FORMS)
def test_momentum_conserved_with_moving_arrays(form):
    tr = simulate(scene_from_dict(articulated_dict()), formulation=form)
    H = tr.H_O_N
    drift = np.max(np.linalg.norm(H - H[0], axis=1)) / np.linalg.norm(H[0])
    assert drift < H_REL_TOL
    # and the arrays really do exchange momentum with the hub: the body rate changes a lot
    assert np.ptp(tr.omega_BN_B, axis=0).max() > 1e-3


@pytest.mark.parametrize("form", FORMS)
def test_energy_conserved_with_locked_arrays(form):
    d = articulated_dict()
    for a in d["appendage"]:
        a["alpha"] = {"a0": a["alpha"]["a0"]}
        a["beta"] = {"a0": a["beta"]["a0"]}
    tr = simulate(scene_from_dict(d), formulation=form)
    assert_allclose(tr["T"], tr["T"][0], rtol=T_REL_TOL)
    H = tr.H_O_N
    assert np.max(np.linalg.norm(H - H[0], axis=1)) / np.linalg.norm(H[0]) < H_REL_TOL


@pytest.mark.parametrize("form", FORMS)
def test_moving_arrays_do_work(form):
    """Sanity of the energy bookkeeping: driven arrays change T (the drives do work)."""
    tr = simulate(scene_from_dict(articulated_dict()), formulation=form)
    assert np.ptp(tr["T"]) / tr["T"][0] > 1e-3


#: the integrated Euler parameters drift off the unit sphere like any integration error: within
#: the requested rtol (1e-12 here; measured <= 3e-14 over the 300 s run for every form)
Q_NORM_TOL = 1e-12


@pytest.mark.parametrize("form", FORMS)
def test_integrated_quaternion_stays_unit(form):
    """The integrator's own state, not the trajectory rows (which report q / |q|)."""
    scene = scene_from_dict(articulated_dict())
    assert scene.simulation.rtol <= Q_NORM_TOL
    ts = np.linspace(0.0, scene.simulation.duration, 51)  # s
    x = raw_states(scene, form, "dop853", ts)
    assert np.abs(np.linalg.norm(x[:, 0:4], axis=1) - 1.0).max() < Q_NORM_TOL


@pytest.fixture(scope="module")
def orbit_articulated():
    d = articulated_dict(duration=5000.0)
    d["orbit"] = {"altitude": 4e5, "inclination": 0.9}
    scene = scene_from_dict(d)
    return scene, simulate(scene, formulation="momentum", rtol=1e-14, atol=1e-18)


#: Issue #2's acceptance: every form at rtol 1e-12 within 1e-9 rad of the exact solution; with
#: the DESIGN's default atol = 1e-12 the measured error is ~3e-11 rad, so 1e-10 is the claim.
ACCEPT_ATT_RAD = 1e-10


@pytest.mark.parametrize("form", FORMS)
def test_rtol_1e12_with_default_atol_is_accurate_for_every_form(orbit_articulated, form):
    from stationbed.core.rotation import rotation_angle

    scene, ref = orbit_articulated
    tr = simulate(scene, formulation=form, rtol=1e-12, atol=1e-12)
    assert rotation_angle(tr.q_BN, ref.q_BN).max() < ACCEPT_ATT_RAD
