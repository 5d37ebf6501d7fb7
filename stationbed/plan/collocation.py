"""Direct collocation of a planned slew: Hermite-Simpson (separated form) on casadi's Opti, IPOPT.

The unknowns, on ``N`` intervals of equal length ``Δ = T/N``, are the state ``x = (q_BR, ω̄, h̄)``
and the command ``q_CR`` at the ``2N + 1`` points (nodes and interval midpoints), and the peak
bound ``γ̄``. Scaled: ``ω̄ = ω / ω_s`` (ω_s: the larger of the orbit rate and the mean slew rate),
``h̄ = h / h_max``, ``γ̄ = γ / h_max²``; the objective is divided by its value's scale. Per
interval (points ``i``, ``m``, ``j``):

    x_m = (x_i + x_j)/2 + Δ/8 (f_i - f_j)        (Hermite interpolation at the midpoint)
    x_j = x_i + Δ/6 (f_i + 4 f_m + f_j)          (Simpson quadrature)

At every point: ``|h|² ≤ γ ≤ h_max²`` (the min-max through an auxiliary bound), ``|ḣ| ≤ τ_max``,
``|q_CR| = 1``, and ``||q_BR|² - 1| ≤ QUAT_BAND`` (the dynamics keep ``|q|`` to the
discretisation's accuracy; an equality at every point would over-determine the defects; PSOPT's
example bands it too, at 2e-4; the model reads only ``q / |q|``). Objective: ``w_E ∫|τ|² dt + w_γ γ`` (Simpson's rule).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..core.rotation import quat_conj, quat_mult
from .model import Rotational, rates

__all__ = ["Problem", "Solution", "PlanError", "solve", "QUAT_BAND", "eigenaxis_commands", "simulate_commands"]

#: ``||q|² - 1|`` allowed at the collocation points (PSOPT's example: 2e-4). The model uses
#: ``q / |q|`` everywhere (``dcm`` divides by ``|q|²``, the law normalises), so the band gives the
#: optimiser nothing to gain: it only absorbs Hermite-Simpson's drift of ``|q|``, which on coarse
#: meshes exceeds 1e-6 (a 1 rad slew on 6 intervals: 1e-5) and made such problems infeasible.
QUAT_BAND = 1e-4


class PlanError(ValueError):
    """A plan that could not be made; ``str(err)`` is one line (status, violation, what to relax)."""


@dataclass(frozen=True)
class Problem:
    """A slew to plan, in SI (see :class:`stationbed.scene.PlanSpec` for the keys).

    model : Rotational  The station and the law.
    T : float  Duration [s].
    q0, q1 : (4,)  Start and end attitude relative to R.
    w0, w1 : (3,)  Start and end body rate relative to N, B components [rad/s].
    h0 : (3,)  Start momentum [N m s]; h1 : (3,) or None  End momentum (None: free).
    h_max : float [N m s] ; tau_max : float [N m]  Limits on |h| and |ḣ|.
    w_energy : float ; w_peak : float  Weights of ∫|τ|² dt and of γ = max|h|².
    r_hat_R : callable t -> (3,)  The Earth direction in R at time t (constant in LVLH).
    torque_B : callable t -> (3,)  Other external torque at time t, B components [N m].
    intervals : int ; max_iter : int ; tol : float  Mesh and IPOPT settings.
    """

    model: Rotational
    T: float
    q0: np.ndarray
    q1: np.ndarray
    w0: np.ndarray
    w1: np.ndarray
    h0: np.ndarray
    h1: np.ndarray | None
    h_max: float
    tau_max: float
    w_energy: float
    w_peak: float
    r_hat_R: object
    intervals: int = 60
    max_iter: int = 3000
    tol: float = 1e-8
    #: ρ: a small energy term added to a pure peak objective (many histories share one peak)
    peak_regularisation: float = 0.0
    torque_B: object = None

    def disturbance(self, t) -> np.ndarray:
        """The known external torque (besides gravity gradient) at ``t`` [N m], B components."""
        return np.zeros(3) if self.torque_B is None else np.asarray(self.torque_B(t), float)


@dataclass
class Solution:
    """A solved plan on its ``2N + 1`` points (nodes and midpoints).

    t : (M,) [s] ; q_BR, q_CR : (M, 4) ; omega_BN_B : (M, 3) [rad/s] ; h_B : (M, 3) [N m s] ;
    tau_B, h_dot_B : (M, 3) [N m].  cost: the objective in SI; energy_N2m2s: ∫|τ|² dt;
    peak_h_Nms: max |h| over the points; stats: the solver's numbers.
    """

    t: np.ndarray
    q_BR: np.ndarray
    omega_BN_B: np.ndarray
    h_B: np.ndarray
    q_CR: np.ndarray
    tau_B: np.ndarray
    h_dot_B: np.ndarray
    cost: float
    energy_N2m2s: float
    peak_h_Nms: float
    gamma_N2m2s2: float
    stats: dict = field(default_factory=dict)


def _point_function(p: Problem, w_s: float):
    """casadi Function of one point: scaled state, command, Earth direction -> scaled rates, τ, ḣ."""
    x = ca.SX.sym("x", 10)
    u = ca.SX.sym("u", 4)
    r = ca.SX.sym("r", 3)
    L = ca.SX.sym("L", 3)
    q, w, h = x[0:4], w_s * x[4:7], p.h_max * x[7:10]
    q_dot, w_dot, h_dot, tau = rates(q, w, h, u, r, p.model, L)
    f = ca.vertcat(q_dot, w_dot / w_s, h_dot / p.h_max)
    return ca.Function("point", [x, u, r, L], [f, tau, h_dot])


def _slew_angle(q0, q1) -> float:
    e = np.asarray(quat_mult(quat_conj(q0), q1), float)
    return 2.0 * math.atan2(np.linalg.norm(e[1:4]), abs(e[0]))


def eigenaxis_commands(q0, q1, t, T):
    """The eigenaxis path from ``q0`` to ``q1`` (the short way), with the smooth profile
    ``s = 3τ² - 2τ³`` (τ = t/T): ``q(t) = q0 ⊗ (cos(sθ/2), sin(sθ/2) a)``; shape (len(t), 4)."""
    q1 = q1 if float(np.dot(q0, q1)) >= 0.0 else -q1
    e = np.asarray(quat_mult(quat_conj(q0), q1), float)
    s_half = np.linalg.norm(e[1:4])
    theta = 2.0 * math.atan2(s_half, e[0])
    a = e[1:4] / s_half if s_half > 0 else np.array([1.0, 0.0, 0.0])
    tau = np.clip(np.asarray(t, float) / T, 0.0, 1.0)
    s = 3 * tau**2 - 2 * tau**3
    out = []
    for sk in s:
        d = np.concatenate([[math.cos(0.5 * sk * theta)], math.sin(0.5 * sk * theta) * a])
        out.append(np.asarray(quat_mult(q0, d), float))
    return np.array(out)


def simulate_commands(p: Problem, t, q_CR, substeps: int = 4):
    """The model flown through the command history ``q_CR`` (linear between the points ``t``)
    from the start state, by RK4 with ``substeps`` steps per gap; returns (M, 10) physical states
    ``(q_BR, ω_BN_B, h_B)`` at ``t``."""
    x = ca.SX.sym("x", 10)
    u = ca.SX.sym("u", 4)
    r = ca.SX.sym("r", 3)
    L = ca.SX.sym("L", 3)
    qd, wd, hd, _ = rates(x[0:4], x[4:7], x[7:10], u, r, p.model, L)
    f = ca.Function("f", [x, u, r, L], [ca.vertcat(qd, wd, hd)])
    out = [np.concatenate([p.q0, p.w0, p.h0])]
    xk = out[0].copy()
    def F(k, tt, xx):  # the rates within gap k, the command linear across it
        a = (tt - t[k]) / (t[k + 1] - t[k])
        qc = (1 - a) * q_CR[k] + a * q_CR[k + 1]
        return np.asarray(f(xx, qc / np.linalg.norm(qc), p.r_hat_R(tt), p.disturbance(tt))).ravel()

    for k in range(len(t) - 1):
        dt = (t[k + 1] - t[k]) / substeps
        for j in range(substeps):
            ta = t[k] + j * dt
            k1 = F(k, ta, xk)
            k2 = F(k, ta + dt / 2, xk + dt / 2 * k1)
            k3 = F(k, ta + dt / 2, xk + dt / 2 * k2)
            k4 = F(k, ta + dt, xk + dt * k3)
            xk = xk + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(xk.copy())
    return np.array(out)


#: constraint groups -> (unit, what to relax when it is the one violated)
_RELAX = {
    "momentum limit": ("N m s", "raise plan.max_momentum or lengthen plan.duration"),
    "torque limit": ("N m", "raise plan.max_torque or lengthen plan.duration"),
    "end conditions": ("(scaled units)", "free plan.h_end_B, lengthen plan.duration or raise plan.max_momentum"),
    "dynamics defects": ("(scaled units)", "raise plan.intervals or plan.max_iter"),
    "unit quaternions": ("", "raise plan.intervals"),
}


def solve(p: Problem, guess: Solution | None = None) -> Solution:
    """Plan the slew: build the NLP, warm-start it (``guess``, or the eigenaxis path flown by the
    law), solve it with IPOPT and return the solution at the collocation points.

    Raises
    ------
    PlanError
        IPOPT did not converge: one line with its status, the iterations, the largest constraint
        violation (in physical units where it has them, and which constraint) and what to relax.
    """
    t_start = time.perf_counter()
    N = p.intervals
    M = 2 * N + 1
    T = p.T
    dt = T / N
    t = np.linspace(0.0, T, M)
    theta = _slew_angle(p.q0, p.q1)
    n = float(np.linalg.norm(p.model.w_RN_R))
    w_s = max(n, theta / T, 1e-6)
    q1 = p.q1 if float(np.dot(p.q0, p.q1)) >= 0.0 else -p.q1
    point = _point_function(p, w_s)
    fmap = point.map(M)
    r_hat = np.array([p.r_hat_R(tk) for tk in t]).T  # (3, M)
    L_ext = np.array([p.disturbance(tk) for tk in t]).T  # (3, M)

    opti = ca.Opti()
    X = opti.variable(10, M)
    U = opti.variable(4, M)
    gam = opti.variable()
    F, TAU, HD = fmap(X, U, r_hat, L_ext)
    groups = {}

    def add(name, expr, lb, ub):
        """``lb <= expr <= ub`` (an equality when they are equal, one-sided when lb is None)."""
        if lb is None:
            opti.subject_to(expr <= ub)
        elif lb == ub:
            opti.subject_to(expr == lb)
        else:
            opti.subject_to(opti.bounded(lb, expr, ub))
        groups.setdefault(name, []).append((expr, lb, ub))

    i, m, j = np.arange(0, M - 1, 2), np.arange(1, M, 2), np.arange(2, M, 2)
    Xi, Xm, Xj = X[:, i], X[:, m], X[:, j]
    Fi, Fm, Fj = F[:, i], F[:, m], F[:, j]
    add("dynamics defects", ca.vec(Xm - (0.5 * (Xi + Xj) + dt / 8 * (Fi - Fj))), 0.0, 0.0)
    add("dynamics defects", ca.vec(Xj - Xi - dt / 6 * (Fi + 4 * Fm + Fj)), 0.0, 0.0)
    q2 = ca.sum1(X[0:4, :] ** 2)
    add("unit quaternions", q2.T, 1.0 - QUAT_BAND, 1.0 + QUAT_BAND)
    add("unit quaternions", ca.sum1(U**2).T, 1.0, 1.0)
    add("momentum limit", (ca.sum1(X[7:10, :] ** 2) - gam).T, None, 0.0)
    add("momentum limit", gam, None, 1.0)
    add("torque limit", (ca.sum1(HD**2) / p.tau_max**2).T, None, 1.0)
    end = [X[0:4, 0] - p.q0, X[4:7, 0] - p.w0 / w_s, X[7:10, 0] - p.h0 / p.h_max,
           X[0:4, -1] - q1, X[4:7, -1] - p.w1 / w_s]
    if p.h1 is not None:
        end.append(X[7:10, -1] - p.h1 / p.h_max)
    add("end conditions", ca.vertcat(*end), 0.0, 0.0)

    e_pts = ca.sum1(TAU**2)
    simpson = np.zeros(M)
    simpson[i] += dt / 6
    simpson[j] += dt / 6
    simpson[m] += 4 * dt / 6
    energy = ca.mtimes(e_pts, simpson)
    # the objective's scale: what a torque of τ_max held over the slew and a full store would cost
    scale = p.w_energy * p.tau_max**2 * T + p.w_peak * p.h_max**2
    scale = scale if scale > 0 else 1.0
    # the regularisation: the energy of τ_max held over the slew weighs as ρ full stores
    w_reg = p.peak_regularisation * p.w_peak * p.h_max**2 / (p.tau_max**2 * T)
    J_si = (p.w_energy + w_reg) * energy + p.w_peak * p.h_max**2 * gam
    opti.minimize(J_si / scale)

    # warm start: the eigenaxis path flown by the law, or a given solution (mesh refinement)
    if guess is None:
        q_c = eigenaxis_commands(p.q0, q1, t, T)
        xs = simulate_commands(p, t, q_c)
    else:
        q_c = _interp(guess.t, guess.q_CR, t)
        xs = np.hstack([_interp(guess.t, guess.q_BR, t), _interp(guess.t, guess.omega_BN_B, t),
                        _interp(guess.t, guess.h_B, t)])
    x_guess = np.hstack([xs[:, 0:4], xs[:, 4:7] / w_s, xs[:, 7:10] / p.h_max]).T
    opti.set_initial(X, x_guess)
    opti.set_initial(U, q_c.T)
    opti.set_initial(gam, min(1.0, float(np.max(np.sum(x_guess[7:10] ** 2, axis=0)))))
    opti.solver("ipopt", {"expand": True, "print_time": False},
                {"print_level": 0, "sb": "yes", "max_iter": p.max_iter, "tol": p.tol,
                 "mu_strategy": "adaptive", "linear_solver": "mumps"})
    t_built = time.perf_counter()
    try:
        sol = opti.solve()
        ok, val = True, sol.value
    except RuntimeError:
        ok, val = False, opti.debug.value
    stats = opti.stats()
    t_done = time.perf_counter()
    viol = {name: _violation(val, items, p, name) for name, items in groups.items()}
    worst = max(viol, key=lambda k: viol[k][1])
    its = stats.get("iterations", {})
    info = {
        "status": stats.get("return_status", "unknown"),
        "success": bool(ok and stats.get("success", False)),
        "iterations": int(stats.get("iter_count", -1)),
        "build_s": t_built - t_start,
        "solve_s": t_done - t_built,
        "time_s": t_done - t_start,
        "kkt_tol": p.tol,
        "inf_pr": float(its["inf_pr"][-1]) if its.get("inf_pr") else None,
        "inf_du": float(its["inf_du"][-1]) if its.get("inf_du") else None,
        "constraint_violation": {k: v[0] for k, v in viol.items()},
        "max_defect": viol["dynamics defects"][0],
        "intervals": N,
        "points": M,
        "variables": int(opti.nx),
        "constraints": int(opti.ng),
        "warm_start": "eigenaxis" if guess is None else "solution",
    }
    if not info["success"]:
        raise PlanError(_failure(info, viol, worst, val, X, HD, p))
    Xv = np.asarray(val(X)).T
    Uv = np.asarray(val(U)).T
    gv = float(val(gam))
    _, tau_v, hd_v = (np.asarray(a) for a in fmap(Xv.T, Uv.T, r_hat, L_ext))
    w = Xv[:, 4:7] * w_s
    h = Xv[:, 7:10] * p.h_max
    tau = tau_v.T
    E = float(np.sum(np.sum(tau**2, axis=1) * simpson))
    return Solution(
        t=t, q_BR=Xv[:, 0:4], omega_BN_B=w, h_B=h, q_CR=Uv, tau_B=tau, h_dot_B=hd_v.T,
        cost=p.w_energy * E + p.w_peak * p.h_max**2 * gv, energy_N2m2s=E,
        peak_h_Nms=float(np.max(np.linalg.norm(h, axis=1))), gamma_N2m2s2=p.h_max**2 * gv, stats=info,
    )


#: IPOPT statuses that mean "no point satisfies the constraints" (the request, not the mesh)
INFEASIBLE = ("Infeasible_Problem_Detected", "Restoration_Failed", "Error_In_Step_Computation")
#: a limit counts as reached at IPOPT's last point above this fraction of it
LIMIT_REACHED = 0.99


def _failure(info, viol, worst, val, X, HD, p: Problem) -> str:
    """The one-line reason of a failed solve: status, iterations, the largest violation and its
    constraint group, how close the last point came to the limits, and what to relax."""
    unit, relax = _RELAX[worst]
    h_frac = float(np.max(np.sqrt(np.sum(np.asarray(val(X[7:10, :])) ** 2, axis=0))))
    t_frac = float(np.max(np.sqrt(np.sum(np.asarray(val(HD)) ** 2, axis=0)))) / p.tau_max
    if info["status"] in INFEASIBLE:
        parts = []
        if h_frac >= LIMIT_REACHED:
            parts.append("raise plan.max_momentum")
        if t_frac >= LIMIT_REACHED:
            parts.append("raise plan.max_torque")
        parts.append("lengthen plan.duration")
        if p.h1 is not None:
            parts.append("free plan.h_end_B")
        relax = "the request looks infeasible: " + ", ".join(parts[:-1]) + f" or {parts[-1]}" if len(parts) > 1 \
            else "the request looks infeasible: " + parts[0]
    elif info["status"] == "Maximum_Iterations_Exceeded":
        relax = f"raise plan.max_iter (now {p.max_iter}) or plan.intervals; or {relax}"
    return (f"IPOPT stopped: {info['status']} after {info['iterations']} iterations; largest violation "
            f"{viol[worst][0]:.3g} {unit} in the {worst}; at the last point |h| reaches {100 * h_frac:.0f} % of "
            f"the momentum limit and |h_dot| {100 * t_frac:.0f} % of the torque limit: {relax}").replace("  ", " ")


def _interp(t_from, Y, t_to):
    return np.column_stack([np.interp(t_to, t_from, Y[:, k]) for k in range(Y.shape[1])])


def _violation(val, items, p: Problem, name) -> tuple[float, float]:
    """Largest violation of a constraint group: (in its unit, relative to its scale)."""
    worst = 0.0
    for expr, lb, ub in items:
        v = np.atleast_1d(np.asarray(val(expr), float)).ravel()
        below = np.max(lb - v) if lb is not None else -np.inf
        above = np.max(v - ub) if ub is not None else -np.inf
        worst = max(worst, float(below), float(above))
    if name == "momentum limit":  # |h̄|² - γ̄ <= 0, γ̄ <= 1: back to N m s of |h| past h_max
        return p.h_max * (math.sqrt(1.0 + worst) - 1.0), worst
    if name == "torque limit":
        return p.tau_max * (math.sqrt(1.0 + worst) - 1.0), worst
    return worst, worst
