"""``mpc``: nonlinear model-predictive slew control with gimbal-rate and momentum constraints.

The law commands the gimbal rates of a gimballed cluster (``sgcmg_pyramid`` or ``dgcmg``)
directly, so the plan itself respects the hardware: no steering law sits between the plan and
the gimbals, and the cluster's rate limit is a bound of the optimisation, never a clip.

Model (a copy of the plant's equations, DESIGN §4, for a rigid station):

    q̇ = ½ q ⊗ (0, ω)                         quaternion kinematics, q = q_BN
    J ω̇ = -A(δ) δ̇ - ω × (J ω + h(δ)) + L_gg   momentum form with the cluster (torque -ḣ - ω × h)
    δ̇ = u                                    the command, held over each control period

with ``J`` = :attr:`Plant.inertia_O_B`, ``h`` and ``A = ∂h/∂δ`` the cluster's own casadi
functions (:attr:`Plant.cmg_functions`: the geometry and parameters flight software believes,
failed units only as ``[knowledge] failed_units`` lists them) and ``L_gg``
the gravity-gradient torque when the scene has an orbit with ``gravity_gradient``. Not
modelled: array motion (the inertia is frozen at t = 0) and the scene's ``[[torque]]``
disturbances: feedback handles them.

Problem solved every period (multiple shooting over ``horizon`` intervals of one controller
period, each integrated with ``substeps`` RK4 steps, so the plan's first interval is exactly the
zero-order hold the simulation applies):

    min  Σ_{k=1..N} [ w_att a(q_k) + w_rate |ω_k/ω_s|² + w_u |u_{k-1}/u_max|² ]
         + w_terminal [ a(q_N) + |ω_N/ω_s|² ]
    s.t. x_{k+1} = RK4(x_k, u_k),  x_0 = the measured state,
         |u_k,i| ≤ u_max = rate_fraction · max_gimbal_rate,
         |h(δ_k)| ≤ momentum_fraction · h_capacity   (k = 1..N)

The attitude error is ``e = vec(conj(q_ref) ⊗ q)``, linear in q, with ``|e| = sin(θ/2)`` for
the principal angle θ to the target and either sign of q; ``a = sqrt(|e|² + ε²) - ε``
(pseudo-Huber, ``ε = att_eps``): it grows like |e| far from the target and like |e|²/2ε near
it, so small errors are not cheap (a quadratic cost made the slew overshoot by ~1 deg and
settle slowly: measured on scenarios/eigenaxis_slew_mpc.toml). The rate term at every node keeps
the plan from swinging through the target between nodes (without it, the station oscillated
about the target with the node attitudes on it). ``ω_s = momentum_fraction · h_capacity /
λ_max(J)`` and ``u_max`` scale the variables so that ipopt sees numbers of order one.

Solver: casadi ``nlpsol`` with ipopt (exact Hessian from the SX graph, MUMPS, adaptive barrier),
warm-started from the previous plan shifted by one period (warm-starting the multipliers too
was measured: more iterations, not fewer). The rate bounds are variable bounds with
``bound_relax_factor = 0``, so every command is inside them: the plant's rate limiter never acts.
When a solve fails, the law plays the next move of the last successful plan (counted in
``mpc_failures``); when that plan is used up it raises :class:`MPCFailure`, and the loop stops
the run with the time and keeps the trajectory.

Design choices (and why):

* gimbal rates, not a torque request: a torque request goes through the steering law, whose
  rate limit scales it down (the plan would not be what is flown) and whose singularities the
  optimiser cannot see; with rates, |δ̇| ≤ limit holds by construction.
* one interval per control period, a long period (10 s in the shipped scenario): the plan holds
  each move for a period exactly as the plant does, so a long period costs no model error, only
  feedback bandwidth, and a 90 deg station slew has time constants of tens of seconds. It keeps
  the run cheap (20-50 ms per solve in casadi's virtual machine on the 2-core test machine,
  ~13 ipopt iterations: the ``mpc_*`` entries of the run summary).
* no C code generation of the NLP: its Hessian is ~1.4e5 operations at horizon 10 and takes
  ~20 s (-O0) to compile, longer than a whole run in the virtual machine.
"""

from __future__ import annotations

import time
from typing import ClassVar

import casadi as ca
import numpy as np
from pydantic import Field

from stationbed.integrators import RK4
from stationbed.run.controller import Controller, ControllerError, ControllerParams, UnitQuaternion
from stationbed.model.environment import gravity_gradient_torque, orbit_position_N
from stationbed.model.orbit import orbit_at, orbit_kind, orbit_params
from stationbed.core.rotation import dcm, quat_kinematics

__all__ = ["MPC", "MPCParams", "MPCFailure"]

#: fractions of each plan interval where |h| ≤ bound is imposed (h is a function of the gimbal
#: angles, which move linearly inside an interval: between these points |h| can only bulge by
#: the curvature of h over a quarter period of gimbal motion)
MOMENTUM_POINTS = (0.25, 0.5, 0.75, 1.0)
#: ipopt statuses accepted as a solution
OK_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


class MPCFailure(RuntimeError):
    """The solver failed and no feasible plan is left to fall back on."""


class MPCParams(ControllerParams):
    q_ref: UnitQuaternion = [1.0, 0.0, 0.0, 0.0]  # target q_BN
    horizon: int = Field(default=10, ge=2, le=200)  # intervals of one controller period
    substeps: int = Field(default=1, ge=1, le=50)  # RK4 steps per interval
    momentum_fraction: float = Field(default=0.7, gt=0.0, le=1.0)  # |h| bound / h_capacity
    rate_fraction: float = Field(default=1.0, gt=0.0, le=1.0)  # |δ̇| bound / max_gimbal_rate
    w_att: float = Field(default=1.0, ge=0.0)  # weight of the attitude error a(q) per node
    att_eps: float = Field(default=1e-3, ge=0.0)  # pseudo-Huber width ε of a(q) (0: quadratic |e|²)
    w_rate: float = Field(default=0.1, ge=0.0)  # weight of |ω/ω_s|² per node
    w_u: float = Field(default=1e-4, gt=0.0)  # weight of |u/u_max|² per interval
    w_terminal: float = Field(default=10.0, ge=0.0)  # weight of the terminal error and rate
    max_iter: int = Field(default=200, ge=1)  # ipopt iterations per solve
    tol: float = Field(default=1e-8, gt=0.0, lt=1.0)  # ipopt tolerance



def _error_vector(r, q):
    """Vector part of ``conj(r) ⊗ q`` (linear in q): ``|e|² = |q|² - (r·q)² = sin²(θ/2)`` for unit q."""
    rw, rx, ry, rz = r[0], r[1], r[2], r[3]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        rw * qx - rx * qw - ry * qz + rz * qy,
        rw * qy + rx * qz - ry * qw - rz * qx,
        rw * qz - rx * qy + ry * qx - rz * qw,
    )


def _rk4(f, x, u, t, h, m):
    """``m`` classical RK4 steps of ``h`` [s] from ``(t, x)`` of ``f(x, u, t)`` (the shared stage
    builder, the model's signature adapted)."""
    for i in range(m):
        ti = t + i * h
        x = RK4.explicit_step(lambda t_s, x_s, u_s, _p: f(x_s, u_s, t_s), ti, x, h, u, None)
    return x


class _Problem:
    """The NLP of one plant and parameter set (built once; reused by runs with the same key)."""

    def __init__(self, plant, P, period):
        J = np.asarray(plant.inertia_O_B, float)
        ng = plant.n_gimbals
        self.ng, self.N, self.period = ng, P.horizon, period
        self.nz = 7 + ng
        self.h_max = P.momentum_fraction * plant.h_capacity
        self.u_max = P.rate_fraction * plant.max_gimbal_rate
        self.w_s = self.h_max / float(np.linalg.eigvalsh(J).max())
        f_h, f_A = plant.cmg_functions["h"], plant.cmg_functions["A"]
        J_inv = np.linalg.inv(J)
        orbit = plant.scene.orbit
        gg = orbit is not None and orbit.gravity_gradient
        z = ca.SX.sym("z", self.nz)
        v = ca.SX.sym("v", ng)
        t = ca.SX.sym("t")
        q, w, d = z[0:4], z[4:7] * self.w_s, z[7:]
        u = v * self.u_max
        h = f_h(d)
        torque = -ca.mtimes(f_A(d), u) - ca.cross(w, ca.mtimes(J, w) + h)
        if gg and orbit.kepler:  # the orbit model's position at the predicted time
            o = orbit_at(t, ca.DM(orbit_params(orbit)), orbit_kind(orbit))
            torque += gravity_gradient_torque(ca.mtimes(dcm(q), o.r_hat_N), ca.DM(J), o.mu_r3)
        elif gg:
            n = orbit.mean_motion
            r_N = orbit_position_N(orbit.u0 + n * t, 1.0, orbit.inclination)
            torque += gravity_gradient_torque(ca.mtimes(dcm(q), r_N), ca.DM(J), n * n)
        zdot = ca.vertcat(quat_kinematics(q, w), ca.mtimes(J_inv, torque) / self.w_s, u)
        f = ca.Function("f", [z, v, t], [zdot])
        m = P.substeps
        #: one control period of the model: (z, v, t) -> z(t + period), scaled units
        self.step = ca.Function("step", [z, v, t], [_rk4(f, z, v, t, period / m, m)])

        N, nz = self.N, self.nz
        Z = [ca.SX.sym(f"z{k}", nz) for k in range(N + 1)]
        V = [ca.SX.sym(f"v{k}", ng) for k in range(N)]
        p = ca.SX.sym("p", 5)  # t0, q_ref
        t0, r = p[0], p[1:5]
        cost, g = 0, []
        fr = MOMENTUM_POINTS
        for k in range(N):
            g.append(Z[k + 1] - self.step(Z[k], V[k], t0 + k * period))
            # h depends on δ alone, and δ is linear in time inside an interval: the bound is
            # imposed exactly at these fractions of every interval
            for s in fr:
                hk = f_h(Z[k][7:] + s * period * self.u_max * V[k])
                g.append(ca.dot(hk, hk) / self.h_max**2)
            cost += P.w_u * ca.dot(V[k], V[k])
            e = _error_vector(r, Z[k + 1][0:4])
            att = ca.sqrt(ca.dot(e, e) + P.att_eps**2) - P.att_eps if P.att_eps > 0 else ca.dot(e, e)
            rate = ca.dot(Z[k + 1][4:7], Z[k + 1][4:7])
            cost += P.w_att * att + P.w_rate * rate
            if k == N - 1:
                cost += P.w_terminal * (att + rate)
        w_all = []
        for k in range(N):
            w_all += [Z[k], V[k]]
        w_all.append(Z[N])
        self.nw = sum(x.numel() for x in w_all)
        nlp = {"x": ca.vertcat(*w_all), "p": p, "f": cost, "g": ca.vertcat(*g)}
        opts = {
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "print_time": False,
            "ipopt.max_iter": P.max_iter,
            "ipopt.tol": P.tol,
            "ipopt.mu_strategy": "adaptive",
            "ipopt.bound_relax_factor": 0.0,
            "error_on_fail": False,
        }
        self.solver = ca.nlpsol("mpc", "ipopt", nlp, opts)
        # bounds: z_0 fixed per solve; v in the rate box; equality defects; |h|² ≤ 1 (scaled)
        self.stride = nz + ng
        self.lbx = np.full(self.nw, -np.inf)
        self.ubx = np.full(self.nw, np.inf)
        for k in range(N):
            o = k * self.stride + nz
            self.lbx[o : o + ng] = -1.0
            self.ubx[o : o + ng] = 1.0
        ng_k = nz + len(fr)
        self.lbg = np.zeros(N * ng_k)
        self.ubg = np.zeros(N * ng_k)
        for k in range(N):
            self.lbg[k * ng_k + nz : (k + 1) * ng_k] = -np.inf
            self.ubg[k * ng_k + nz : (k + 1) * ng_k] = 1.0

    def unpack(self, w):
        """Plan states (N+1, nz) and moves (N, ng) in scaled units from the decision vector."""
        w = np.asarray(w, float).ravel()
        Z = np.empty((self.N + 1, self.nz))
        V = np.empty((self.N, self.ng))
        for k in range(self.N):
            o = k * self.stride
            Z[k] = w[o : o + self.nz]
            V[k] = w[o + self.nz : o + self.stride]
        Z[self.N] = w[self.N * self.stride :]
        return Z, V

    def pack(self, Z, V):
        w = np.empty(self.nw)
        for k in range(self.N):
            o = k * self.stride
            w[o : o + self.nz] = Z[k]
            w[o + self.nz : o + self.stride] = V[k]
        w[self.N * self.stride :] = Z[self.N]
        return w

    def to_state(self, Z):
        """Scaled plan states -> (q_BN, omega_BN_B [rad/s], gimbal angles [rad]) columns."""
        X = np.array(Z, float)
        X[..., 4:7] *= self.w_s
        return X


#: built problems, keyed by everything they depend on (a `stationbed check` runs three
#: formulations of one plant: one build serves all three)
_PROBLEMS: dict = {}


class MPC(Controller):
    """Nonlinear MPC slew law commanding gimbal rates; see the module docstring."""

    name = "mpc"
    command = "gimbal_rates"
    Params = MPCParams
    #: build cache size
    CACHE: ClassVar[int] = 4

    def _reset(self, plant):
        if plant.n_gimbals == 0:
            raise ControllerError(
                f"controller 'mpc' commands gimbal rates: the scene needs a gimballed [cmg] "
                f"(e.g. kind = 'sgcmg_pyramid' or 'dgcmg'), got {plant.cmg_kind!r}"
            )
        if plant.period != self.period:
            raise ControllerError(
                f"controller 'mpc': its period ({self.period} s) differs from the scene's controller period "
                f"({plant.period} s); its model holds each move for one period"
            )
        P = self.params
        key = (
            np.asarray(plant.inertia_O_B, float).tobytes(),
            repr(plant.scene.cmg),
            repr(plant.scene.orbit),
            self.period,
            P.model_dump_json(exclude={"q_ref"}),
        )
        prob = _PROBLEMS.get(key)
        if prob is None:
            prob = _Problem(plant, P, self.period)
            if len(_PROBLEMS) >= self.CACHE:
                _PROBLEMS.pop(next(iter(_PROBLEMS)))
            _PROBLEMS[key] = prob
        self.prob = prob
        self.q_ref = np.array(P.q_ref)
        self.q_ref_BN = tuple(P.q_ref)
        self.p = np.concatenate([[0.0], self.q_ref])
        self.w0 = None  # warm start (decision vector)
        self._Z = None  # last successful plan (scaled)
        self._V = None
        self._age = 0  # periods since that plan was made
        self.plan = None
        self.solve_s: list[float] = []
        self.iterations: list[int] = []
        self.failures = 0
        self.failure_statuses: dict[str, int] = {}

    # -- one solve -------------------------------------------------------------------------
    def _solve(self, t, z0):
        """Solve from the scaled state ``z0`` at ``t``; returns ``(ok, status, w)``."""
        pr = self.prob
        lbx, ubx = pr.lbx.copy(), pr.ubx.copy()
        lbx[: pr.nz] = z0
        ubx[: pr.nz] = z0
        self.p[0] = t
        args = dict(x0=self.w0, p=self.p, lbx=lbx, ubx=ubx, lbg=pr.lbg, ubg=pr.ubg)
        solver = pr.solver
        sol = solver(**args)
        st = solver.stats()
        self.iterations.append(int(st.get("iter_count", -1)))
        status = st["return_status"]
        return status in OK_STATUSES, status, sol["x"].full().ravel()

    def _initial_guess(self, z0):
        pr = self.prob
        if self._Z is None:
            Z = np.tile(z0, (pr.N + 1, 1))
            V = np.zeros((pr.N, pr.ng))
        else:
            k = min(self._age, pr.N - 1)
            Z = np.vstack([self._Z[k:], np.tile(self._Z[-1], (k, 1))])
            V = np.vstack([self._V[k:], np.zeros((k, pr.ng))])
            Z[0] = z0
            if np.dot(Z[1, 0:4], z0[0:4]) < 0:  # keep the plan on the measured quaternion's sign
                Z[1:, 0:4] *= -1
        return pr.pack(Z, V)

    def _update(self, t, meas):
        pr = self.prob
        if self._Z is not None:
            self._age += 1  # the last plan was made this many periods ago
        z0 = np.concatenate([meas.q_BN, meas.omega_BN_B / pr.w_s, meas.gimbal])
        self.w0 = self._initial_guess(z0)
        t_start = time.perf_counter()
        ok, status, w = self._solve(t, z0)
        self.solve_s.append(time.perf_counter() - t_start)
        if ok:
            self._Z, self._V = pr.unpack(w)
            self._age = 0
            self.plan = {
                "t": t + pr.period * np.arange(pr.N + 1),
                "x": pr.to_state(self._Z),
                "gimbal_rates": self._V * pr.u_max,
            }
            return tuple(float(v) for v in self._V[0] * pr.u_max)
        self.failures += 1
        self.failure_statuses[status] = self.failure_statuses.get(status, 0) + 1
        if self._Z is None or self._age >= pr.N:
            raise MPCFailure(
                f"ipopt failed ({status}) at t = {t:.6g} s and no feasible plan is left to fall back on "
                f"({self.failures} failed solves)"
            )
        return tuple(float(v) for v in self._V[self._age] * pr.u_max)

    def summary(self):
        """Solve statistics: count, failures (fallbacks) by ipopt status, wall time, iterations."""
        solve_s = getattr(self, "solve_s", None) or [0.0]
        iters = getattr(self, "iterations", None) or [0]
        prob = getattr(self, "prob", None)
        return {
            "mpc_solves": len(getattr(self, "solve_s", [])),
            "mpc_failures": getattr(self, "failures", 0),
            "mpc_failure_statuses": dict(getattr(self, "failure_statuses", {})),
            "mpc_solve_mean_s": float(np.mean(solve_s)),
            "mpc_solve_max_s": float(np.max(solve_s)),
            "mpc_iter_mean": float(np.mean(iters)),
            "mpc_iter_max": int(np.max(iters)),
            "mpc_horizon_s": None if prob is None else prob.N * prob.period,
        }
