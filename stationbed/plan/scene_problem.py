"""A scene's ``[plan]`` table -> the :class:`~.collocation.Problem` it asks for, and the plan.

The station is flight software's knowledge of it: the composite inertia about the mass centre at
t = 0 (the arrays frozen where they start), the orbit, disturbances and the cluster's limits of the
knowledge scene, as :func:`stationbed.run.closed_loop.plant_facts` gives them to every controller; the start is the scene's ``[initial]`` state and ``[cmg] h0_B``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..core.rotation import dcm
from ..model.cmg import CmgModel, cluster_functions
from ..model.environment import omega_ON_O, orbit_position_N
from ..run.closed_loop import plant_facts
from ..run.prepare import prepare
from ..scene.plan import MAX_INTERVALS
from .collocation import PlanError, Problem, Solution, solve
from .model import Rotational

__all__ = ["scene_problem", "plan_scene", "PEAK_REGULARISATION", "PLANNED_TORQUES"]

#: the ``[[torque]]`` kinds a plan models (known functions of time, B components); the others
#: (aero, srp: functions of the attitude on the scene's surfaces) are not in the plan's model
PLANNED_TORQUES = ("constant", "orbital_harmonic")

#: ρ of a pure peak-momentum objective: many command histories share one peak, so a small energy
#: term picks one; the energy of τ_max held over the slew weighs as ρ full stores. On the 2006
#: case (30 intervals) 1e-6 left IPOPT wandering (3000 iterations), 1e-3 converges in 48 with the
#: peak 1.2e-5 below ρ = 1e-2's; the reported cost leaves the term out
PEAK_REGULARISATION = 1e-3


def start_momentum(cmg) -> np.ndarray:
    """The cluster's momentum at t = 0, B components [N m s]: an ideal store's ``h0_B``, a
    gimballed cluster's ``h`` at its ``gimbal0``."""
    if cmg.kind == "ideal":
        return np.asarray(cmg.h0_B, float)
    return np.asarray(cluster_functions(cmg)["h"](CmgModel.of(cmg).initial_state(cmg)), float).ravel()


def scene_problem(scene, *, intervals: int | None = None) -> Problem:
    """The :class:`Problem` of ``scene.plan`` (``intervals`` overrides ``plan.intervals``)."""
    spec = scene.plan
    if spec is None:
        raise PlanError(f"scene '{scene.name}' has no [plan] table")
    for i, tq in enumerate(scene.torque):
        if tq.kind not in PLANNED_TORQUES:
            raise PlanError(f"torque[{i}]: kind '{tq.kind}' is not in the plan's model (it plans gravity gradient and "
                            f"kinds {', '.join(PLANNED_TORQUES)}): remove it from the scene to plan")
    prep = prepare(scene)
    plant = plant_facts(scene, prep.system, scene.controller.period if scene.controller else 1.0)
    scene = plant.scene  # the plan is flight software's: it plans on knowledge ([knowledge]), not the truth
    J = np.asarray(plant.inertia_O_B, float)
    orbit = scene.orbit
    n = orbit.mean_motion if orbit is not None else 0.0
    gg = orbit is not None and orbit.gravity_gradient
    if spec.frame == "lvlh":
        w_RN_R = omega_ON_O(n)
        nadir = np.array([0.0, 0.0, 1.0])

        def r_hat(t):
            return nadir
    else:
        w_RN_R = np.zeros(3)

        def r_hat(t):
            if orbit is None:
                return np.array([1.0, 0.0, 0.0])
            return np.asarray(orbit_position_N(orbit.u0 + n * t, 1.0, orbit.inclination), float)
    torques = list(scene.torque)

    def torque_B(t):
        L = np.zeros(3)
        for tq in torques:
            if tq.kind == "constant":
                if tq.start <= t < tq.stop:
                    L += np.asarray(tq.torque_B, float)
            else:
                u = orbit.u0 + n * t
                L += (np.asarray(tq.bias_B) + np.asarray(tq.cos1_B) * np.cos(u) + np.asarray(tq.sin1_B) * np.sin(u)
                      + np.asarray(tq.cos2_B) * np.cos(2 * u) + np.asarray(tq.sin2_B) * np.sin(2 * u))
        return L

    q0 = np.asarray(scene.initial.q_BN, float)
    q1 = np.asarray(spec.q_end, float)
    w0 = np.asarray(scene.initial.omega_BN_B, float) + dcm(q0) @ w_RN_R
    w1 = np.asarray(spec.omega_end, float) + dcm(q1) @ w_RN_R
    h0 = start_momentum(scene.cmg)
    h_max = spec.max_momentum or scene.cmg.max_momentum
    tau_max = spec.max_torque or scene.cmg.max_torque
    w_e, w_p, reg = spec.weight_energy, spec.weight_peak, 0.0
    if spec.objective == "torque_energy":
        w_e, w_p = 1.0, 0.0
    elif spec.objective == "peak_momentum":
        w_e, w_p, reg = 0.0, 1.0, PEAK_REGULARISATION
    if float(np.linalg.norm(h0)) > h_max:
        raise PlanError(f"the start momentum |[cmg] h0_B| = {np.linalg.norm(h0):.6g} N m s is above "
                        f"plan.max_momentum = {h_max:.6g} N m s: raise plan.max_momentum")
    if spec.h_end_B is not None and float(np.linalg.norm(spec.h_end_B)) > h_max:
        raise PlanError(f"|plan.h_end_B| = {np.linalg.norm(spec.h_end_B):.6g} N m s is above "
                        f"plan.max_momentum = {h_max:.6g} N m s: raise plan.max_momentum")
    return Problem(
        model=Rotational(J=J, w_RN_R=np.asarray(w_RN_R, float), n2=n * n if gg else 0.0, kp=spec.kp, kd=spec.kd),
        T=spec.duration, q0=q0, q1=q1, w0=w0, w1=w1, h0=h0,
        h1=None if spec.h_end_B is None else np.asarray(spec.h_end_B, float),
        h_max=float(h_max), tau_max=float(tau_max), w_energy=w_e, w_peak=w_p, r_hat_R=r_hat,
        intervals=intervals or spec.intervals, max_iter=spec.max_iter, tol=spec.tol, peak_regularisation=reg,
        torque_B=torque_B if torques else None,
    )


def plan_scene(scene, *, intervals: int | None = None, refine: int | None = None) -> tuple[Problem, Solution]:
    """Plan ``scene.plan``: the problem and its solution.

    With ``refine`` (a finer number of intervals), the plan is solved again on that mesh, warm
    started from the first solution; the returned solution is the fine one, and its stats carry
    ``cost_coarse`` and ``cost_change`` (relative) for the mesh-refinement report.
    """
    for name, v in (("intervals", intervals), ("refine", refine)):  # the NLP's size: plan.intervals' bounds
        if v is not None and not 2 <= v <= MAX_INTERVALS:
            raise PlanError(f"{name} must be between 2 and {MAX_INTERVALS} (plan.intervals' range), got {v}")
    prob = scene_problem(scene, intervals=intervals)
    sol = solve(prob)
    if refine:
        fine = solve(dataclasses.replace(prob, intervals=refine), guess=sol)
        fine.stats["cost_coarse"] = sol.cost
        fine.stats["intervals_coarse"] = prob.intervals
        fine.stats["cost_change"] = (fine.cost - sol.cost) / abs(sol.cost)
        fine.stats["time_s"] += sol.stats["time_s"]
        return dataclasses.replace(prob, intervals=refine), fine
    return prob, sol
