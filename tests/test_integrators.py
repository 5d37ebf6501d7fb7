"""Integrator contract: every registered integrator meets a closed form; C and Python DOP853
loops agree and the C driver's step-control constants are the Python ones; RK4 converges at
order 4; every Butcher table meets its order conditions (exact rationals) and the one stage
builder applies it as the hand-written step; a fusable integrator's tick step is its generic
step, and its counters book one step per tick on every closed-loop path."""

import copy
import math
import re
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stationbed import INTEGRATORS, simulate
from stationbed.integrators import DOP853, RK4, TABLEAUS, ButcherTableau, FixedStep, StepControl
from stationbed.integrators.rk import explicit_rk_step
from stationbed.integrators.tableau import CLASSICAL_RK4
from stationbed.core.rotation import rotation_angle
from stationbed.scene import scene_from_dict

It, Ia, W1, W3 = 200.0, 350.0, 0.02, 0.05  # kg m², rad/s


def precession_scene(rigid):
    rigid["body"]["inertia"] = [[It, 0, 0], [0, It, 0], [0, 0, Ia]]
    rigid["initial"]["omega_BN_B"] = [W1, 0.0, W3]
    rigid["simulation"]["duration"] = 200.0
    return scene_from_dict(rigid)


def exact_q(t):
    H = np.array([It * W1, 0.0, Ia * W3])
    R = Rotation.from_rotvec(np.outer(np.linalg.norm(H) / It * t, H / np.linalg.norm(H))) * Rotation.from_rotvec(
        np.outer((It - Ia) / It * W3 * t, [0, 0, 1])
    )
    xyzw = R.as_quat()
    return np.c_[xyzw[:, 3], xyzw[:, :3]]


#: the precession's rate |ω0| [rad/s] and duration [s]: ω T ≈ 10.8 rad of motion
OMEGA_RAD_S = math.hypot(W1, W3)
T_PRECESSION_S = 200.0
#: fixed-step methods run at this step [s] (ω h ≈ 0.013 rad)
FIXED_STEP_S = 0.25
#: adaptive methods run at this rtol; their global error stays within a few rtol per radian of
#: motion (measured at rtol 1e-10: 0.05 (dop853) to 1.8 (scipy_bdf) rtol per radian)
ADAPTIVE_RTOL = 1e-11
ADAPTIVE_GAIN = 5.0


def derived_tolerance(cls) -> tuple[dict, float]:
    """Setting and error bound [rad] from what an integrator declares, so a newly registered one
    is covered by the same claim: a fixed-step method of order p at step h has a global error
    below ``(ω h)^p ω T / p!`` (its leading truncation term per step, accumulated over the
    run); an adaptive one below ``ADAPTIVE_GAIN · rtol · ω T``."""
    if cls.adaptive:
        return {"rtol": ADAPTIVE_RTOL}, ADAPTIVE_GAIN * ADAPTIVE_RTOL * OMEGA_RAD_S * T_PRECESSION_S
    p = cls.order
    bound = (OMEGA_RAD_S * FIXED_STEP_S) ** p * OMEGA_RAD_S * T_PRECESSION_S / math.factorial(p)
    return {"step": FIXED_STEP_S}, bound


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_every_integrator_meets_closed_form(rigid_scene_dict, name):
    kw, tol = derived_tolerance(INTEGRATORS[name])
    tr = simulate(precession_scene(rigid_scene_dict), integrator=name, **kw)
    assert rotation_angle(tr.q_BN, exact_q(tr.t)).max() < tol


@pytest.mark.parametrize("name", sorted(n for n, c in INTEGRATORS.items() if not c.adaptive))
def test_fixed_step_cost_is_its_steps_times_its_stages(rigid_scene_dict, name):
    """A fixed-step run makes exactly ceil(T / h) steps of RHS_PER_STEP evaluations each."""
    tr = simulate(precession_scene(rigid_scene_dict), integrator=name, step=FIXED_STEP_S)
    n_steps = math.ceil(T_PRECESSION_S / FIXED_STEP_S)
    assert tr.meta["n_steps"] == n_steps
    assert tr.meta["n_rhs"] >= INTEGRATORS[name].RHS_PER_STEP * n_steps


@pytest.mark.parametrize("name", sorted(n for n, c in INTEGRATORS.items() if c.adaptive))
def test_adaptive_cost_grows_as_the_tolerance_tightens(rigid_scene_dict, name):
    """Step-size control is live: two decades tighter rtol takes more RHS evaluations."""
    loose = simulate(precession_scene(copy.deepcopy(rigid_scene_dict)), integrator=name, rtol=1e-7)
    tight = simulate(precession_scene(rigid_scene_dict), integrator=name, rtol=1e-9)
    assert tight.meta["n_rhs"] > loose.meta["n_rhs"]


#: measured accuracy claims of the shipped integrators at their own settings (the contract above
#: covers every registered one; these keep the tighter numbers measured for each)
SETTINGS = {
    "dop853": ({"rtol": 1e-11}, 1e-9),
    "rk4": ({"step": 0.5}, 1e-7),  # (0.06 rad/s * 0.5 s)^4 / 120 per step * 400 steps ≈ 3e-9
    "lie_rk4": ({"step": 0.5}, 1e-7),  # as rk4 (measured 2.1e-9)
    "lgvi": ({"step": 0.1}, 2e-4),  # 2nd order: (0.06 rad/s * 0.1 s)^2 phase error over 200 s (measured 5.0e-5)
    "radau": ({"step": 0.5}, 1e-9),  # order 5 (measured 1.1e-12)
    "scipy_dop853": ({"rtol": 1e-11}, 1e-9),
    "scipy_rk45": ({"rtol": 1e-10}, 1e-7),
    "scipy_radau": ({"rtol": 1e-10}, 1e-7),
    "scipy_bdf": ({"rtol": 1e-10}, 1e-5),
    "scipy_lsoda": ({"rtol": 1e-10}, 1e-6),
}


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_shipped_integrator_meets_its_measured_accuracy(rigid_scene_dict, name):
    kw, tol = SETTINGS[name]
    tr = simulate(precession_scene(rigid_scene_dict), integrator=name, **kw)
    assert rotation_angle(tr.q_BN, exact_q(tr.t)).max() < tol


def test_c_driver_matches_python_loop(rigid_scene_dict, monkeypatch):
    from scenes import articulated_dict

    scene = scene_from_dict(articulated_dict())
    a = simulate(scene)
    monkeypatch.setattr(DOP853, "force_python", True)
    b = simulate(scene)
    assert a.meta["n_rhs"] == b.meta["n_rhs"]
    np.testing.assert_allclose(a.data, b.data, rtol=1e-12, atol=1e-12)


def test_rk4_order_four(rigid_scene_dict):
    scene = precession_scene(rigid_scene_dict)
    errs = []
    steps = [4.0, 2.0, 1.0]
    for h in steps:
        tr = simulate(scene, integrator="rk4", step=h, output_dt=20.0)
        errs.append(rotation_angle(tr.q_BN, exact_q(tr.t)).max())
    slopes = np.diff(np.log(errs)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 4.0) < 0.3), slopes


def test_unknown_integrator_lists_valid_names(rigid_scene_dict):
    with pytest.raises(ValueError, match="valid: dop853, lgvi, lie_rk4, radau, rk4"):
        simulate(scene_from_dict(rigid_scene_dict), integrator="euler")


# ---------------------------------------------------------------------------------------
# Butcher tables as data: the invariants of every table, the stage builder against them
# ---------------------------------------------------------------------------------------


def rooted_trees(max_order: int) -> dict[int, list[tuple]]:
    """All rooted trees of each order up to ``max_order`` (a tree is the sorted tuple of the
    subtrees at its root; the single node is ``()``), Butcher's order-condition index."""
    by_order = {1: [()]}
    for n in range(2, max_order + 1):
        pool = [(o, t) for o in range(1, n) for t in by_order[o]]

        def forests(rem, i):
            if rem == 0:
                yield ()
                return
            for j in range(i, len(pool)):
                o, t = pool[j]
                if o <= rem:
                    for rest in forests(rem - o, j):
                        yield (t,) + rest

        by_order[n] = sorted({tuple(sorted(f)) for f in forests(n - 1, 0)})
    return by_order


#: number of rooted trees of order 1..6 (OEIS A000081): checks the generator itself
N_TREES = [1, 1, 2, 4, 9, 20]


def test_rooted_tree_counts():
    trees = rooted_trees(len(N_TREES))
    assert [len(trees[n]) for n in range(1, len(N_TREES) + 1)] == N_TREES


def _order(tree) -> int:
    return 1 + sum(_order(c) for c in tree)


def _gamma(tree) -> int:
    return _order(tree) * math.prod(_gamma(c) for c in tree)


def _stage_weights(tab: ButcherTableau, tree) -> list[Fraction]:
    """g_i(tree) = Π over the root's subtrees of Σ_j a_ij g_j(subtree) (1 for the single node)."""
    s = tab.stages
    g = [Fraction(1)] * s
    for child in tree:
        gc = _stage_weights(tab, child)
        g = [g[i] * sum((tab.a[i][j] * gc[j] for j in range(i)), Fraction(0)) for i in range(s)]
    return g


def _elementary_weight(tab: ButcherTableau, tree) -> Fraction:
    return sum((b * g for b, g in zip(tab.b, _stage_weights(tab, tree))), Fraction(0))


TABLE_IDS = [t.name for t in TABLEAUS]


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_table_is_explicit_and_rows_sum_to_c(tab):
    assert len(tab.a) == len(tab.c) == tab.stages
    assert all(len(row) == i for i, row in enumerate(tab.a))  # strictly lower triangular
    assert [sum(row, Fraction(0)) for row in tab.a] == list(tab.c)


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_table_weights_sum_to_one(tab):
    assert sum(tab.b, Fraction(0)) == 1


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_table_meets_order_conditions_up_to_its_order(tab):
    """Φ(τ) = 1/γ(τ) for every rooted tree τ with |τ| <= order (exact rationals)."""
    for n, trees in rooted_trees(tab.order).items():
        for tree in trees:
            assert _elementary_weight(tab, tree) == Fraction(1, _gamma(tree)), (n, tree)


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_table_order_is_not_higher_than_declared(tab):
    trees = rooted_trees(tab.order + 1)[tab.order + 1]
    assert any(_elementary_weight(tab, tree) != Fraction(1, _gamma(tree)) for tree in trees)


WITH_TABLE = sorted(n for n, c in INTEGRATORS.items() if hasattr(c, "TABLEAU"))


@pytest.mark.parametrize("name", WITH_TABLE)
def test_integrator_declares_its_tables_order_and_stages(name):
    cls = INTEGRATORS[name]
    assert (cls.order, cls.RHS_PER_STEP) == (cls.TABLEAU.order, cls.TABLEAU.stages)


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_builder_step_on_linear_ode_is_the_taylor_polynomial(tab):
    """On ẋ = λx an explicit s-stage method of order p = s multiplies by Σ_k≤p (hλ)^k / k!
    (exact in rationals: the builder applies the table as written)."""
    lam, h = Fraction(-3, 7), Fraction(5, 4)
    x1 = explicit_rk_step(tab, lambda t, x, u, p: lam * x, Fraction(0), Fraction(1), h, None, None)
    assert tab.order == tab.stages
    assert x1 == sum(Fraction((h * lam) ** k, math.factorial(k)) for k in range(tab.order + 1))


@pytest.mark.parametrize("tab", TABLEAUS, ids=TABLE_IDS)
def test_builder_step_integrates_polynomials_in_time_exactly(tab):
    """ẋ = t^k: the step is the quadrature Σ b_i (t0 + c_i h)^k, exact for k < order."""
    t0, h = Fraction(2, 3), Fraction(1, 5)
    for k in range(tab.order):
        x1 = explicit_rk_step(tab, lambda t, x, u, p: t**k, t0, Fraction(0), h, None, None)
        assert x1 == ((t0 + h) ** (k + 1) - t0 ** (k + 1)) / (k + 1), k


def _c_source(f: ca.Function) -> str:
    cg = ca.CodeGenerator("f.c", {"with_header": False})
    cg.add(f)
    return cg.dump()


def test_rk4_builder_is_the_hand_written_step():
    """The builder makes the graph of the hand-written classical step, so the generated C of
    every step, tick and fused loop (and the hash naming its cached library) is unchanged."""
    t, h, x, u, p = ca.SX.sym("t"), ca.SX.sym("h"), ca.SX.sym("x", 3), ca.SX.sym("u", 2), ca.SX.sym("p")
    rhs = ca.Function("rhs", [t, x, u, p], [ca.vertcat(x[1] * ca.sin(t), p * x[0] * u[0], x[2] * u[1] - t)])
    k1 = rhs(t, x, u, p)
    k2 = rhs(t + h / 2, x + h / 2 * k1, u, p)
    k3 = rhs(t + h / 2, x + h / 2 * k2, u, p)
    k4 = rhs(t + h, x + h * k3, u, p)
    hand = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    built = explicit_rk_step(CLASSICAL_RK4, rhs, t, x, h, u, p)
    args = [t, x, h, u, p]
    assert _c_source(ca.Function("step", args, [built])) == _c_source(ca.Function("step", args, [hand]))


# ---------------------------------------------------------------------------------------
# fusable: a declared capability; the counters stay the integrator's own
# ---------------------------------------------------------------------------------------

FUSABLE = sorted(n for n, c in INTEGRATORS.items() if c.fusable)


@pytest.mark.parametrize("name", FUSABLE)
def test_fusable_tick_step_is_the_generic_step(name):
    """What the fused tick composes (``explicit_step``) is the step the generic path compiles
    (``_step``), and the class has the fixed step and RHS count the loop books with."""
    cls = INTEGRATORS[name]
    assert issubclass(cls, FixedStep) and cls.RHS_PER_STEP > 0
    nx, nu, npar = 3, 2, 1
    t, h, x, u, p = ca.SX.sym("t"), ca.SX.sym("h"), ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("p", npar)
    tol = ca.SX.sym("tol", 1 + nx)
    rhs = ca.Function("rhs", [t, x, u, p], [ca.vertcat(x[1] * ca.cos(t), -p * x[0] + u[0], x[2] * u[1])])
    tick = cls.explicit_step(rhs, t, x, h, u, p)
    generic, _ = cls._step(rhs, t, x, h, u, p, tol)
    args = [t, x, h, u, p]
    assert _c_source(ca.Function("s", args, [tick])) == _c_source(ca.Function("s", args, [generic]))


class RK4NotFusable(RK4):
    """RK4 declared not fusable: the closed loop integrates each period by ``advance``."""

    fusable = False


PERIOD_S = 0.1  # s, controller period = RK4 step
LOOP_DURATION_S = 2.0  # s: 20 ticks
#: (simulate keywords, whether the fused loop runs) per path
PATHS = {
    "fused_loop": ({}, True),
    "fused_tick": ({"fused": False}, False),
    "generic": ({"integrator": RK4NotFusable}, False),
}


@pytest.mark.parametrize("path", list(PATHS))
def test_counters_book_one_rk4_step_per_tick_on_every_path(rigid_scene_dict, path):
    """One control period is one RK4 step of 4 RHS evaluations, whichever path took it (the
    fused paths book their steps with ``Integrator.count_steps``)."""
    d = rigid_scene_dict
    d["initial"]["omega_BN_B"] = [0.01, -0.02, 0.005]  # rad/s
    d["simulation"].update(duration=LOOP_DURATION_S, integrator="rk4", step=PERIOD_S, output_dt=0.5)
    d["controller"] = {"name": "pd", "period": PERIOD_S, "params": {"reference": "inertial"}}
    kw, fused = PATHS[path]
    tr = simulate(scene_from_dict(d), **kw)
    ticks = round(LOOP_DURATION_S / PERIOD_S)
    assert tr.meta["summary"]["fused"] is fused
    assert (tr.meta["n_steps"], tr.meta["n_rhs"]) == (ticks, RK4.RHS_PER_STEP * ticks)


# ---------------------------------------------------------------------------------------
# DOP853 step control: one set of rules, the C driver's copy of its constants
# ---------------------------------------------------------------------------------------

NUM = r"([-+0-9.eE]+)"
#: (C statement as a regex with the constants as groups, the StepControl / DOP853 values)
C_RULES = {
    "grow": (
        rf"factor = \(err == 0\.0\) \? {NUM} : fmin\({NUM}, {NUM} \* pow\(err, {NUM} / {NUM}\)\);",
        lambda g: (g[0], g[1], g[2], g[3] / g[4]),
        (StepControl.MAX_FACTOR, StepControl.MAX_FACTOR, StepControl.SAFETY, StepControl.ERROR_EXPONENT),
    ),
    "shrink": (
        rf"\*h_io = h \* fmax\({NUM}, {NUM} \* pow\(err, {NUM} / {NUM}\)\);",
        lambda g: (g[0], g[1], g[2] / g[3]),
        (StepControl.MIN_FACTOR, StepControl.SAFETY, StepControl.ERROR_EXPONENT),
    ),
    "land": (rf"clipped = h >= remaining \* \(1\.0 - {NUM}\);", lambda g: g, (StepControl.LAND_RTOL,)),
    "split": (
        rf"else if \(h > {NUM} \* remaining\) h = {NUM} \* remaining;",
        lambda g: g,
        (StepControl.SPLIT, StepControl.SPLIT),
    ),
    "underflow": (rf"if \(h <= {NUM} \* fmax\(1\.0, fabs\(t\)\)\)", lambda g: g, (StepControl.UNDERFLOW_RTOL,)),
    "accept": (rf"if \(err <= {NUM}\) \{{", lambda g: g, (StepControl.ACCEPT_ERR,)),
    "rhs_count": (
        rf"info\[0\] \+= {NUM} \+ \(dense \? {NUM} : 0\);",
        lambda g: g,
        (DOP853.N_STAGES, DOP853.N_DENSE_STAGES),
    ),
}


@pytest.mark.parametrize("rule", list(C_RULES))
def test_c_driver_constants_are_the_python_ones(rule):
    """``dop853_driver.c`` keeps its own copy of the step-control constants (its bytes are part
    of the cached library's hash): each must equal StepControl's (read from the C text)."""
    pattern, values, expected = C_RULES[rule]
    found = re.findall(pattern, DOP853.extra_c)
    assert len(found) == 1, f"{rule}: the C statement changed shape"
    groups = found[0] if isinstance(found[0], tuple) else (found[0],)
    assert tuple(values([float(g) for g in groups])) == expected
