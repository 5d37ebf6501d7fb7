"""Geometric integrators keep what the geometry says they keep.

- ``lie_rk4`` and ``lgvi`` step the attitude by products of unit quaternions: |q| = 1 to
  round-off over long runs (the method itself, without its round-off renormalisation, leaves
  the sphere only by a rounding random walk, while rk4's truncation error moves it 1e-6);
  ``radau`` projects after each step.
- ``lgvi`` is symplectic and momentum-preserving: on a torque-free rigid body its energy error
  stays bounded (here: at round-off, the discrete free rigid body conserves kinetic energy
  exactly) over many periods while rk4's grows steadily; H_O_N is constant to round-off.
- ``lgvi`` refuses, with the reason, systems that are not a rigid body in the momentum form.
"""

import copy
import math

import numpy as np
import pytest

from scenes import RIGID, ROOT, articulated_dict
from stationbed import simulate
from stationbed.model import Structure
from stationbed.integrators import LGVI, LieRK4
from stationbed.scene import load_scene, scene_from_dict
from stationbed.run.initial import initial_state
from stationbed.run.system import build_system

#: |q| - 1 for the geometric integrators (the issue's acceptance)
NORM_TOL = 1e-14
EPS = np.finfo(float).eps
LONG_STEPS = 200_000  # 1 s steps: ~3000 nutation periods of the test body


class LieRK4Raw(LieRK4):
    """lie_rk4 without its round-off renormalisation: the method alone."""

    name = "lie_rk4_raw"
    NORMALISE = False


class LGVIRaw(LGVI):
    name = "lgvi_raw"
    NORMALISE = False


@pytest.fixture(scope="module")
def tumbling():
    """Triaxial rigid body with products of inertia, torque-free, |ω| ≈ 0.09 rad/s."""
    d = copy.deepcopy(RIGID)
    d["body"]["inertia"] = [[100.0, 5.0, -3.0], [5.0, 200.0, 4.0], [-3.0, 4.0, 250.0]]  # kg m²
    d["initial"]["omega_BN_B"] = [0.05, -0.01, 0.08]  # rad/s
    return scene_from_dict(d)


def raw_states(scene, integrator, step_s, ts):
    """States (unnormalised q) straight from the integrator: trajectories show q/|q|."""
    system = build_system(Structure.of(scene), "momentum", integrator)
    model = system.formulation.model
    p = model.params(scene)
    q0, w0 = initial_state(scene)
    x0 = np.array(system.funcs["init"](0.0, q0, w0, np.zeros(0), p)).ravel()
    integ = system.integrator_cls(system.funcs, p, system.formulation.nx, rtol=1e-12, atol=1e-14, step=step_s)
    xs = integ.integrate(ts, x0, np.zeros(model.nu))
    assert integ.n_steps == LONG_STEPS
    return xs


def norm_error(xs):
    return np.abs(np.linalg.norm(xs[:, 0:4], axis=1) - 1.0).max()


@pytest.fixture(scope="module")
def long_ts():
    return np.linspace(0.0, LONG_STEPS * 1.0, 101)  # s


@pytest.mark.parametrize("name", ["lie_rk4", "lgvi", "radau"])
def test_quaternion_stays_unit(tumbling, long_ts, name):
    assert norm_error(raw_states(tumbling, name, 1.0, long_ts)) < NORM_TOL


@pytest.mark.parametrize("cls", [LieRK4Raw, LGVIRaw], ids=["lie_rk4", "lgvi"])
def test_exp_map_leaves_sphere_only_by_rounding(tumbling, long_ts, cls):
    """Without renormalisation: a random walk of a few eps per step, ~sqrt(N) eps (measured
    4e-14 and 6e-14 over 2e5 steps), where rk4's truncation moves |q| by 1e-6."""
    walk = 4 * math.sqrt(LONG_STEPS) * EPS  # 4e-13
    assert norm_error(raw_states(tumbling, cls, 1.0, long_ts)) < walk
    assert norm_error(raw_states(tumbling, "rk4", 1.0, long_ts)) > 1e3 * walk


#: the lgvi's energy and momentum errors: round-off over 1e4 steps (measured 1.5e-14, 1.7e-14)
LGVI_ROUNDOFF = 1e-12


@pytest.fixture(scope="module")
def free_runs(tumbling):
    """rk4 and lgvi, same 2 s step (h |ω| = 0.19 rad), 20000 s ≈ 100 nutation periods."""
    return {n: simulate(tumbling, integrator=n, step=2.0, duration=20_000.0, output_dt=10.0) for n in ("rk4", "lgvi")}


def energy_error(tr):
    T = tr["T"]
    return np.abs(T / T[0] - 1.0)


def test_lgvi_energy_bounded_where_rk4_drifts(free_runs):
    lg, rk = energy_error(free_runs["lgvi"]), energy_error(free_runs["rk4"])
    k = len(lg) // 10
    assert lg.max() < LGVI_ROUNDOFF
    # rk4: dissipative drift, linear in time (measured 3.0e-6 in the first tenth, 2.7e-5 in the last)
    assert rk[-k:].max() > 5.0 * rk[:k].max()
    assert rk[-k:].max() > 1e4 * LGVI_ROUNDOFF


def test_lgvi_conserves_inertial_momentum(free_runs):
    H = free_runs["lgvi"].H_O_N
    assert np.linalg.norm(H - H[0], axis=1).max() < LGVI_ROUNDOFF * np.linalg.norm(H[0])


def test_lgvi_refuses_articulated_arrays():
    with pytest.raises(ValueError, match="lgvi.*inertia changes with time"):
        simulate(scene_from_dict(articulated_dict(duration=10.0)), integrator="lgvi")


def test_lgvi_refuses_cmg():
    scene = load_scene(ROOT / "scenarios" / "sgcmg_singularity.toml")
    with pytest.raises(ValueError, match="lgvi.*extra states \\(CMG"):
        simulate(scene, integrator="lgvi", duration=1.0)


def test_lgvi_refuses_omega_state_formulation(tumbling):
    with pytest.raises(ValueError, match="lgvi.*ω-state formulation"):
        simulate(tumbling, formulation="dalembert", integrator="lgvi", duration=1.0)
