"""The gain interval of each loop (issue 19 A3): ``margins`` reports the gains ``k`` (lower and upper
gain margins) over which the loop closed as ``1 + k L`` stays stable, also when the plant is
unstable open loop (gravity gradient) and the stability is lost *below* the nominal gain.

Truth, written here without the margin code: the closed-loop matrix ``A(k)`` built for a sweep of
gains, its eigenvalues' largest real part, and the gains where it crosses 0, refined by
bisection on the eigenvalues. Loops: a rigid station holding LVLH with ``pd`` (no cluster: the
plant is θ, δω), the shipped iss_lvlh_hold (sun-tracking joints at rest give the loops poles at
exactly 0, where python-control's transfer-function margins divided 0 by 0, dropped the crossing
and warned), and synthetic loops with finite bounds on both sides. Warnings are errors here.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scenes import ROOT
from stationbed import load_scene
from stationbed.analysis.margins import loop_analysis, loop_margins, siso_margins
from stationbed.scene import scene_from_dict

pytestmark = pytest.mark.filterwarnings("error")

JEOD_I = [[1.02e8, -6.96e6, -5.48e6], [-6.96e6, 0.91e8, 5.9e5], [-5.48e6, 5.9e5, 1.64e8]]  # kg m²: pitch unstable in LVLH
#: the bisection's end (relative) and the margin code's ω -> 0 limit (s = 1e-6 of the grid's
#: lowest frequency: L(s) - L(0) ~ s L'(0), ~1e-9 relative) and Brent's tolerance
GAIN_RTOL = 1e-6
#: a pole at Re > this is unstable: round-off of eigenvalues of ~1e-2 rad/s matrices is ~1e-17;
#: poles at exactly 0 (joints at rest, no feedback) do not move with k and are not counted
UNSTABLE_RE = 1e-12


def sweep_interval(Acl, k_grid=np.logspace(-5, 5, 201)):
    """(k_lo, k_hi) around k = 1 where ``max Re eig(Acl(k)) <= UNSTABLE_RE``, by a sweep of the
    grid and bisection on the eigenvalues (0 / inf when the grid's end is still stable)."""
    def stable(k):
        return np.linalg.eigvals(Acl(k)).real.max() <= UNSTABLE_RE

    assert stable(1.0)
    below = [k for k in k_grid if k < 1.0 and not stable(k)]
    above = [k for k in k_grid if k > 1.0 and not stable(k)]

    def bisect(a, b):  # stable(a) != stable(b)
        sa = stable(a)
        while b / a - 1.0 > 1e-10:
            m = math.sqrt(a * b)
            if stable(m) == sa:
                a = m
            else:
                b = m
        return math.sqrt(a * b)

    lo = bisect(max(below), min([k for k in k_grid if k > max(below)] + [1.0])) if below else 0.0
    hi = bisect(max([k for k in k_grid if k < min(above)] + [1.0]), min(above)) if above else math.inf
    return lo, hi


def rigid_pd_scene():
    return scene_from_dict({
        "name": "gg_pd",
        "simulation": {"duration": 10.0, "integrator": "rk4", "step": 0.1},
        "initial": {"frame": "lvlh"},
        "body": {"mass": 4.0e5, "inertia": JEOD_I, "cm": [0.0, 0.0, 0.0]},
        "orbit": {"altitude": 400000.0, "inclination": 0.9006, "u0": 0.3, "gravity_gradient": True},
        "controller": {"name": "pd", "period": 0.1,
                       "params": {"reference": "lvlh", "bandwidth": 0.003, "damping": 0.8}},
    })


@pytest.mark.parametrize("channel", [0, 1, 2], ids=["x", "y", "z"])
def test_rigid_station_gain_interval_is_where_the_closed_loop_eigenvalues_cross(channel):
    """A gravity-gradient-unstable station (JEOD inertia, pitch unstable in LVLH) under a slow
    PD: each channel has a lower gain margin > 0 (the one the old report showed as 0) and none
    above; both equal the eigenvalue sweep of ``A + Σ_{j≠i} B_j K_j + k B_i K_i``."""
    la = loop_analysis(rigid_pd_scene())
    A, Bv, K = la.plant.A, la.plant.B[:, 0:3], la.K
    others = [j for j in range(3) if j != channel]
    A_o = A + Bv[:, others] @ K[others, :]
    lo, hi = sweep_interval(lambda k: A_o + k * Bv[:, [channel]] @ K[[channel], :])
    c = la.channels[channel]
    assert lo > 1e-3  # the loop needs a minimum gain: open loop is unstable
    assert_allclose(c["gain_margin_down"], lo, rtol=GAIN_RTOL)
    assert c["gain_margin_up"] == hi == math.inf


@pytest.mark.slow
def test_iss_lvlh_hold_lower_gain_margins():
    """The shipped scene of the issue (joints on their tracking state at t = 0): lower margins ~0.14 (x),
    ~0.10 (y), ~0.005 (z), none above,
    by the eigenvalue sweep of each loop's own closed-loop matrix ``A_L - k B_L C_L``."""
    la = loop_analysis(load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml"))
    for L, c in zip(la.loops, la.channels):
        lo, hi = sweep_interval(lambda k: L.A - k * L.B @ L.C)
        assert_allclose(c["gain_margin_down"], lo, rtol=GAIN_RTOL)
        assert c["gain_margin_up"] == hi
    # issue 32: the wings facing their plates and the joints on their tracking state at t (0.142,
    # 0.104, 0.005 before either)
    assert [round(c["gain_margin_down"], 3) for c in la.channels] == [0.143, 0.102, 0.006]


def synthetic_loop(n_fixed_zero: int):
    """``L(s) = 6 (s + 2) / ((s - 1)(s² + 2 s + 5))`` (open-loop unstable; stable for gains in a
    finite interval), in companion form, with ``n_fixed_zero`` extra states at exactly 0 that the
    input does not reach (as joints at rest): they do not change L."""
    import control

    L = control.ss(control.tf([6.0, 12.0], np.polymul([1.0, -1.0], [1.0, 2.0, 5.0])))
    n = L.A.shape[0]
    A = np.zeros((n + n_fixed_zero, n + n_fixed_zero))
    A[:n, :n] = L.A
    A[:n, n:] = 0.3  # the fixed states drive the loop's states (observable, not controllable)
    B = np.vstack([L.B, np.zeros((n_fixed_zero, 1))])
    C = np.hstack([L.C, np.ones((1, n_fixed_zero))])
    return control.ss(A, B, C, np.zeros((1, 1)))


@pytest.mark.parametrize("n_fixed_zero", [0, 2], ids=["minimal", "with_zero_poles"])
def test_synthetic_loop_interval_on_both_sides(n_fixed_zero):
    """A loop that needs a minimum gain (ω = 0 crossing) and tolerates a maximum (a phase
    crossover at ω > 0): both bounds equal the eigenvalue sweep, with or without poles at 0."""
    L = synthetic_loop(n_fixed_zero)
    A, B, C = L.A, L.B, L.C
    Acl = lambda k: A - k * B @ C  # noqa: E731
    # the sweep needs fixed zero poles left out: they sit at exactly 0 for every k
    lo, hi = sweep_interval(Acl)
    mg = siso_margins(L)
    assert 0.0 < lo < 1.0 < hi < math.inf
    assert_allclose([mg["gain_margin_down"], mg["gain_margin_up"]], [lo, hi], rtol=GAIN_RTOL)
    assert mg["phase_crossover_down_rad_s"] == 0.0 and mg["phase_crossover_rad_s"] > 0.0


def test_lqr_margins_use_the_same_interval():
    """``loop_margins`` (the lqr's and momentum_manager's report) has the same bounds: a state
    feedback ``u = -K x`` that stabilises a pitch-unstable plant has a lower margin (the LQR
    guarantee: at most 1/2)."""
    from stationbed.analysis.design import design_linearization
    from controllers.lqr import bryson, design_lqr

    n = 1.1e-3  # rad/s
    lin = design_linearization(np.array(JEOD_I), n, "lvlh")
    A, B = lin.ss.A, lin.ss.B[:, 0:3]
    K, _ = design_lqr(A, B, bryson([0.01] * 3 + [1e-4] * 3), bryson([5.0] * 3))
    for i, mg in enumerate(loop_margins(A, B, K)):
        others = [j for j in range(3) if j != i]
        lo, hi = sweep_interval(lambda k: A - B[:, others] @ K[others, :] - k * B[:, [i]] @ K[[i], :])
        assert_allclose(mg["gain_margin_down"], lo, rtol=GAIN_RTOL, atol=1e-12)
        assert mg["gain_margin_up"] == hi == math.inf
        assert mg["gain_margin_down"] <= 0.5


def test_upper_margin_at_a_lightly_damped_mode():
    """``L(s) = g (s + a) ω0² / (s (s + 1) (s² + 2 ζ ω0 s + ω0²))`` with ζ = 0.00265: the phase
    crosses -180 deg within a fraction of a percent of ω0; the upper bound is found there and
    equals the eigenvalue sweep (no lower bound: L has an integrator)."""
    import control

    w0, zeta, g, a = 4.69, 0.00265, 0.00726, 1.9  # rad/s, -, 1/s, rad/s
    L = control.ss(control.tf(np.polymul([g, g * a], [w0**2]), np.polymul([1.0, 1.0, 0.0], [1.0, 2 * zeta * w0, w0**2])))
    lo, hi = sweep_interval(lambda k: L.A - k * L.B @ L.C)
    mg = siso_margins(L)
    assert lo == 0.0 and 1.0 < hi < math.inf
    assert mg["gain_margin_down"] == 0.0
    assert_allclose(mg["gain_margin_up"], hi, rtol=GAIN_RTOL)
    assert abs(mg["phase_crossover_rad_s"] / w0 - 1.0) < 0.05
