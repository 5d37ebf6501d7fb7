"""Measurements the studies make on runs and on the compiled system.

On trajectories: the error against a reference (:func:`max_errors`), the Jacobi integral of a
rigid body in orbit, the growth of an invariant's error (secular drift or bounded), the
Dzhanibekov flip times, the modal energies. On the compiled system, with the same set-up as a
run (:func:`stationbed.run.prepare.prepare`): the integrator's own states (q not normalised),
the eigenvalues of the right-hand side's Jacobian and the Newton defect of one implicit step.
On Runge-Kutta methods: the stability function and its boundary along a ray of the complex plane.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.compile import FastCall
from ..core.rotation import dcm, rotation_angle
from ..integrators import INTEGRATORS
from ..integrators.tableau import CLASSICAL_RK4, ButcherTableau
from ..model.environment import C_ON
from ..run.prepare import prepare
from ..run.trajectory import Trajectory
from ..scene import Scene

__all__ = [
    "max_errors", "jacobi_integral", "DRIFT_SLOPE", "ROUNDOFF_REL", "growth", "growth_verdict", "flip_times",
    "modal_energy", "raw_states", "rhs_eigenvalues", "NEWTON_STATES", "newton_defects", "RK4_TABLEAU",
    "explicit_tableaus", "stability_function", "stability_boundary", "predicted_step",
]


# ---------------------------------------------------------------------------------------
# on trajectories
# ---------------------------------------------------------------------------------------


def max_errors(tr: Trajectory, ref: Trajectory) -> tuple[float, float]:
    """Largest attitude and rate errors of a run against a reference on the same output rows.

    Parameters
    ----------
    tr, ref : Trajectory
        The run and the reference, with the same output times.

    Returns
    -------
    att : float
        Largest rotation angle between ``q_BN`` of the two [rad].
    rate : float
        Largest ``|omega_BN_B - omega_BN_B,ref|`` [rad/s].
        Both ``inf`` when the rows do not match (a run that stopped early).
    """
    n = min(len(tr), len(ref))
    if n == 0 or len(tr) != len(ref) or not np.allclose(tr.t[:n], ref.t[:n], rtol=0, atol=1e-9 * max(1.0, ref.t[-1])):
        return math.inf, math.inf
    att = rotation_angle(tr.q_BN, ref.q_BN)
    rate = np.linalg.norm(tr.omega_BN_B - ref.omega_BN_B, axis=1)
    return float(att.max()), float(rate.max())


def jacobi_integral(scene: Scene, tr: Trajectory) -> np.ndarray:
    """The Jacobi integral of a rigid body in a circular orbit with gravity gradient.

    In LVLH (rotating at ω_ON = -n y_O) the energy of the relative motion is conserved:
    ``J = ½ ω_BOᵀ I ω_BO - ½ n² y_Bᵀ I y_B + (3/2) n² z_Bᵀ I z_B`` (kinetic energy of the motion
    relative to LVLH, the centrifugal term about the orbit normal y_O, the gravity-gradient
    potential along the radial z_O; y_B, z_B the LVLH axes in B). Rigid body only.

    Parameters
    ----------
    scene : Scene
        A rigid-body scene with a circular ``orbit``.
    tr : Trajectory
        A run of it.

    Returns
    -------
    ndarray, shape (len(tr),)
        J at every row [J].
    """
    o = scene.orbit
    if o is None or o.kepler:
        raise ValueError("the Jacobi integral needs a circular orbit (on a two-body orbit LVLH turns at a varying rate)")
    n = o.mean_motion
    I = np.array(scene.body.inertia)
    J = np.empty(len(tr))
    for k, (t, q, w) in enumerate(zip(tr.t, tr.q_BN, tr.omega_BN_B)):
        C_BO = dcm(q) @ C_ON(o.u0 + n * t, o.inclination).T
        w_BO = w - C_BO @ np.array([0.0, -n, 0.0])
        y_B, z_B = C_BO[:, 1], C_BO[:, 2]
        J[k] = 0.5 * w_BO @ I @ w_BO - 0.5 * n**2 * y_B @ I @ y_B + 1.5 * n**2 * z_B @ I @ z_B
    return J


#: log-log slope of the error's running maximum above which an error grows secularly (linear
#: drift gives 1, a bounded oscillating error ~0, round-off's random walk ~0.5)
DRIFT_SLOPE = 0.7
#: relative errors below this are float64 round-off over ~10⁵ steps (eps sqrt(N) x a few)
ROUNDOFF_REL = 1e-12


def growth(t: np.ndarray, err: np.ndarray) -> tuple[float, float]:
    """How an error grows: the detector of secular drift.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times [s] (any unit: only the log-log slope is taken).
    err : ndarray, shape (n,)
        The error at those times (any unit).

    Returns
    -------
    slope : float
        Log-log slope of the running maximum of ``|err|`` over the last 90 % of the run
        (0 with fewer than three rows there).
    final : float
        The running maximum at the end.
    """
    env = np.maximum.accumulate(np.maximum(np.abs(err), 1e-300))
    sel = t >= 0.1 * t[-1]
    sel &= env > 0
    if sel.sum() < 3:
        return 0.0, float(env[-1])
    p = np.polyfit(np.log(t[sel]), np.log(np.maximum(env[sel], 1e-30)), 1)[0]
    return float(p), float(env[-1])


def growth_verdict(slope: float, final: float) -> str:
    """The verdict on a relative error from :func:`growth`: at round-off, drifts or bounded.

    Parameters
    ----------
    slope : float
        Log-log slope (``DRIFT_SLOPE`` separates drift from a bounded error).
    final : float
        Final relative error [-] (below ``ROUNDOFF_REL``: at round-off).

    Returns
    -------
    str
    """
    if final < ROUNDOFF_REL:
        return "at round-off"
    return f"drifts (slope {slope:.2f})" if slope > DRIFT_SLOPE else f"bounded (slope {slope:.2f})"


def flip_times(tr: Trajectory) -> np.ndarray:
    """Times at which the intermediate-axis rate ω_y changes sign (one per Dzhanibekov flip).

    Parameters
    ----------
    tr : Trajectory
        A run with the column ``wy`` [rad/s].

    Returns
    -------
    ndarray
        The roots of a cubic spline through ``wy`` [s], ascending (rounded to 1e-9 s, unique).
    """
    from scipy.interpolate import CubicSpline

    roots = CubicSpline(tr.t, tr["wy"]).roots(extrapolate=False)
    return np.unique(np.round(roots[np.isfinite(roots)], 9))


def modal_energy(scene: Scene, tr: Trajectory) -> np.ndarray:
    """``η̇² + ω_k² η²`` of every elastic mode at every row: twice the mode's energy per unit
    modal mass, constant for a free undamped mode.

    Parameters
    ----------
    scene : Scene
        The scene run (its appendages' modes give the columns and ω_k).
    tr : Trajectory
        A run with the columns ``eta_<array>_<k>`` [m] and ``etadot_<array>_<k>`` [m/s].

    Returns
    -------
    ndarray, shape (len(tr), n_modes)
        [m²/s²], columns in the scene's order of arrays and modes.
    """
    cols = []
    for a in scene.appendage:
        for k, m in enumerate(a.mode, start=1):
            eta, eta_dot = tr[f"eta_{a.name}_{k}"], tr[f"etadot_{a.name}_{k}"]
            cols.append(eta_dot**2 + (m.omega * eta) ** 2)
    return np.column_stack(cols)


# ---------------------------------------------------------------------------------------
# on the compiled system
# ---------------------------------------------------------------------------------------


def raw_states(
    scene: Scene,
    formulation: str,
    integrator: str,
    ts: np.ndarray,
    project: bool = False,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    step: float | None = None,
) -> np.ndarray:
    """The integrator's own states at ``ts`` (a trajectory normalises q; this does not).

    Smooth scenes only (no controller, no discontinuity): the set-up of a run
    (:func:`~stationbed.run.prepare.prepare`) and one call of the integrator over ``ts``.

    Parameters
    ----------
    scene : Scene
    formulation, integrator : str
    ts : ndarray, shape (n,)
        Increasing output times [s], ``ts[0] = 0``.
    project : bool
        Advance one fixed step at a time and normalise q after every step (``step`` needed);
        the rows then hold q *before* that projection.
    rtol, atol, step : float, optional
        As :func:`~stationbed.run.simulation.simulate` (default: the scene's).

    Returns
    -------
    ndarray, shape (n, nx)
        The formulation's state at ``ts``.
    """
    run = prepare(scene, formulation, integrator, rtol=rtol, atol=atol, step=step)
    integ, x = run.integrator, run.x0
    u = np.zeros(run.system.formulation.model.nu)
    if not project:
        return integ.integrate(ts, x, u)
    if step is None:
        raise ValueError("raw_states(project=True) needs a fixed step")
    out = np.empty((ts.size, x.size))
    out[0] = x
    for i in range(1, ts.size):
        n = max(1, math.ceil((ts[i] - ts[i - 1]) / step - 1e-9))
        for k in range(n):
            t0 = ts[i - 1] + (ts[i] - ts[i - 1]) * k / n
            t1 = ts[i - 1] + (ts[i] - ts[i - 1]) * (k + 1) / n
            x = integ.advance(t0, t1, x, u)
            q_before = x[:4].copy()
            x[:4] /= np.linalg.norm(x[:4])
        out[i] = x
        out[i, :4] = q_before
    return out


def rhs_eigenvalues(scene: Scene, formulation: str = "momentum") -> np.ndarray:
    """Eigenvalues of the right-hand side's Jacobian at t = 0 (central differences on the
    compiled RHS, u = 0).

    An elastic mode appears as ``-ζω ± iω√(1-ζ²)``, ω its frequency in the coupled system
    (above the clamped one: the station moves with the array).

    Parameters
    ----------
    scene : Scene
    formulation : str

    Returns
    -------
    ndarray, shape (nx,), complex
        [1/s].
    """
    run = prepare(scene, formulation, "dop853")
    p, x0 = run.p, run.x0
    f = FastCall.of(run.system.funcs["rhs"])
    f.args[0][0] = 0.0
    f.args[2][:] = 0.0
    f.args[3][:] = p

    def rhs(x):
        f.args[1][:] = x
        f()
        return f.res[0].copy()

    J = np.empty((x0.size, x0.size))
    for j in range(x0.size):
        e = np.zeros(x0.size)
        e[j] = 1e-6 * max(1.0, abs(x0[j]))
        J[:, j] = (rhs(x0 + e) - rhs(x0 - e)) / (2 * e[j])
    return np.linalg.eigvals(J)


#: states along the run from which :func:`newton_defects` takes one step
NEWTON_STATES = 12


def newton_defects(scene: Scene, integrator: str, hs, *, formulation: str = "momentum", n_states: int = NEWTON_STATES):
    """Largest defect of one step of a fixed-step implicit integrator at each step size.

    The step is the compiled single step ``<name>_one`` of the
    :class:`~stationbed.integrators.FixedStep` driver, called directly from ``n_states``
    states along the run (DOP853 at rtol 1e-10) with the scene's tolerances and u = 0.
    Smooth scenes only (no controller, no torque).

    Parameters
    ----------
    scene : Scene
    integrator : str
        A :class:`~stationbed.integrators.FixedStep` integrator.
    hs : list of float
        Step sizes [s].
    formulation : str
    n_states : int

    Returns
    -------
    list of float
        Per step size, the largest defect in the integrator's ``DEFECT_TOL`` units (above it
        the run stops); ``inf`` when a step is not finite.
    """
    run = prepare(scene, formulation, integrator)
    p = run.p
    tol = np.concatenate([[run.rtol], run.atol])
    ts = np.linspace(0.0, scene.simulation.duration, n_states + 1)
    xs = raw_states(scene, formulation, "dop853", ts, rtol=1e-10, atol=1e-12)
    one = FastCall.of(run.system.funcs[f"{integrator}_one"])
    txd, hup = one.args
    hup[:] = 0.0
    hup[hup.size - p.size - tol.size : hup.size - tol.size] = p
    hup[hup.size - tol.size :] = tol
    out = []
    for h in hs:
        hup[0] = h
        worst = 0.0
        for t, x in zip(ts[:-1], xs[:-1]):
            txd[0] = t
            txd[1:-1] = x
            txd[-1] = 0.0
            one()
            d = float(one.res[0][-1])
            worst = max(worst, d) if math.isfinite(d) else math.inf
        out.append(worst)
    return out


# ---------------------------------------------------------------------------------------
# linear stability of Runge-Kutta methods
# ---------------------------------------------------------------------------------------

def square_tableau(tab: ButcherTableau) -> tuple[list[list[float]], list[float]]:
    """An explicit table as the square ``(A, b)`` of floats the linear analysis takes."""
    s = tab.stages
    return [row + [0.0] * (s - len(row)) for row in tab.a_float()], tab.b_float()


#: classical RK4's Butcher table ``(A, b)`` (the integrators' own table)
RK4_TABLEAU = square_tableau(CLASSICAL_RK4)


def explicit_tableaus() -> dict:
    """Butcher tables of the registered explicit methods whose stability boundary the stiff-modes
    case predicts (RKMK4 is classical RK4 on the non-attitude states).

    Returns
    -------
    dict
        Integrator name -> ``(A, b)``.
    """
    from scipy.integrate import DOP853 as _D

    tables = {name: square_tableau(cls.TABLEAU) for name, cls in INTEGRATORS.items() if getattr(cls, "TABLEAU", None) is not None}
    tables["dop853"] = (_D.A[: _D.n_stages, : _D.n_stages], _D.B)
    return tables


def stability_function(A, b):
    """The Runge-Kutta method's growth factor per step on ``ẋ = λ x`` (Hairer & Wanner IV.3).

    Parameters
    ----------
    A : array_like, shape (s, s)
    b : array_like, shape (s,)
        Butcher table.

    Returns
    -------
    callable
        ``R(z) = 1 + z bᵀ (E - z A)⁻¹ 1`` with ``z = hλ`` (complex -> complex).
    """
    A = np.asarray(A, dtype=complex)
    b = np.asarray(b, dtype=complex)
    E, one = np.eye(b.size), np.ones(b.size)
    return lambda z: complex(1.0 + z * (b @ np.linalg.solve(E - z * A, one)))


def stability_boundary(R, lam: complex, s_max: float = 20.0) -> float:
    """The largest ``h |λ|`` with ``|R(h λ)| <= 1`` for every smaller step.

    For classical RK4 and λ on the imaginary axis this is 2√2.

    Parameters
    ----------
    R : callable
        Stability function (:func:`stability_function`).
    lam : complex
        The eigenvalue (only its direction matters) [1/s].
    s_max : float
        Largest ``h |λ|`` searched.

    Returns
    -------
    float
        [-]; ``inf`` when ``|R| <= 1`` up to ``s_max``.
    """
    u = lam / abs(lam)
    ds = 0.01
    hi = next((k * ds for k in range(1, int(s_max / ds) + 1) if abs(R(k * ds * u)) > 1.0 + 1e-12), None)
    if hi is None:
        return math.inf
    lo = hi - ds
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if abs(R(mid * u)) > 1.0 + 1e-12 else (mid, hi)
    return lo


def predicted_step(R, lams: np.ndarray) -> float:
    """The largest stable fixed step of a method on these eigenvalues.

    The slow eigenvalues (|λ| below 1e-3 of the fastest) never bind here and are left out.

    Parameters
    ----------
    R : callable
        Stability function (:func:`stability_function`).
    lams : ndarray, complex
        Eigenvalues of the right-hand side's Jacobian [1/s] (:func:`rhs_eigenvalues`).

    Returns
    -------
    float
        [s].
    """
    lam_max = float(np.max(np.abs(lams)))
    return min(stability_boundary(R, lam) / abs(lam) for lam in lams if abs(lam) > 1e-3 * lam_max)
