"""Linear plants of a scene for python-control (:func:`linearize`), from the simulator's own equations.

The plant is the scene's formulation (``Formulation.rhs``, the expression the simulator compiles)
written in *analysis coordinates* relative to a reference frame R, and differentiated exactly by
casadi (``ca.jacobian``; no finite differences):

* ``R``: fixed in LVLH (``q_RN(t) = q_ON(t) ⊗ q_RO``, turning at ``ω_RN_R = C_RO (0, -n, 0)``, LVLH z
  nadir, y minus the orbit normal); without an orbit, fixed in N (``q_RN = q_RO``, ``ω_RN = 0``);
* states ``z``: attitude error ``θ = 2 vec(q_BR)`` [rad] (the small rotation angles about B's
  axes; exact for any rotation below 180 deg), rate of B relative to R
  ``δω = ω_BN_B - C_BR ω_RN_R`` [rad/s], then the model's own extra states (CMG: ``h`` [N m s] of an
  ideal cluster, gimbal angles [rad] of a gimballed one; sun-tracking joint angles and rates), then
  the flexible arrays' modal coordinates ``η`` and rates ``η̇``;
* inputs: the control (body-torque command ``tau_cmd_*`` [N m] through the CMG steering law when
  the scene has a cluster, or ``gimbal_rate*`` [rad/s] with ``command="gimbal_rates"``; a scene
  without a cluster applies the torque directly, as the simulator does), then the disturbance
  torque ``tau_dist_*`` [N m] (the held external torque ``u[0:3]`` of the model);
* outputs: ``att_err_*`` (θ) [rad], ``rate_err_*`` (δω) [rad/s], and ``h_*`` [N m s] with a cluster.

Kinematics of the coordinates: ``q_BN = q_RN ⊗ q_BR(θ)``, ``ω_BN_B = δω + C_BR ω_RN_R``,
``θ̇ = q_w δω + (θ/2) × δω`` and ``δω̇ = ω̇ + δω × (C_BR ω_RN_R)`` (R turns at a constant rate: a
circular orbit), ``ω̇ = ∂ω/∂x ẋ + ∂ω/∂t`` from the formulation's ``omega(t, x)``.

Time-varying terms (arrays turning, orbital harmonics, the orbit's position) are **frozen at the
chosen time** ``t``: the plant is the tangent of the equations at that instant, not an average.
Every torque the scene flies is in the point: the symbolic kinds (gravity gradient, harmonics,
aero, SRP) are in the equations; the *held* kinds (``constant`` windows) enter as the disturbance
input's operating value ``d0 = held_torque_B(scene, t)``, so the trim cancels them and the TEA
balances them (:func:`held_over_orbit`: a held torque that switches inside the orbit the TEA
averages over is refused, naming the kind and the time, since a TEA needs torques that repeat
every orbit).
The torque-equilibrium attitude (``about="tea"``) is the root of the external and gyroscopic torque
``Ḣ_B = L - ω × H`` averaged over one orbit (24 instants) with zero rates relative to LVLH and the
extra states at their values at ``t`` (the modal coordinates solved with it); it is found by Newton
on the same expressions, not assumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..core.paths import safe_name
from ..core.rotation import Ay, dcm, quat_mult
from ..model import Structure
from ..model.appendages import glider_error, profile
from ..model.environment import q_ON
from ..model.torques import get_torque, held_torque_B, v_rel_B
from ..run.system import build_system

__all__ = [
    "OperatingPoint",
    "Linearization",
    "linearize",
    "linearization",
    "plant_functions",
    "tea_search",
    "held_over_orbit",
]

#: Largest TEA offset from LVLH the Newton search accepts [rad]: beyond it the "nearest"
#: equilibrium is another principal-axis alignment, not a TEA a station would fly.
TEA_MAX_RAD = math.radians(60.0)
#: Newton's residual at the TEA, ``|δω̇| / n²`` (gravity-gradient terms are ~ΔI/I ~ 0.1-1 in these
#: units): float64 round-off of ~1e-16 relative, with margin.
TEA_RESIDUAL = 1e-10
#: Instants of one orbit over which the TEA's torque is averaged (24: every 15 deg of argument of
#: latitude; harmonics up to the 11th per orbit average exactly on this grid).
TEA_SAMPLES = 24


@dataclass(frozen=True)
class OperatingPoint:
    """An explicit linearisation point: the attitude and rate at time ``t``.

    ``q_BN`` (4,) and ``omega_BN_B`` (3,) [rad/s]; R is fixed in LVLH at that attitude (fixed in N
    without an orbit), so the plant's ``θ`` and ``δω`` are measured from it; ``xe`` the extra and
    modal states (``η``, ``η̇``), default the scene's initial ones.
    """

    q_BN: tuple
    omega_BN_B: tuple = (0.0, 0.0, 0.0)
    t: float = 0.0
    xe: tuple | None = None


@dataclass
class Linearization:
    """A linearised plant with its point: ``ss`` (control.StateSpace, named signals) and the
    numbers it was taken at."""

    ss: object
    t: float
    q_RO: np.ndarray  # R relative to LVLH (relative to N without an orbit), scalar first
    z0: np.ndarray  # the analysis state at the point
    u0: np.ndarray  # the inputs at the point (control trim, then the held kinds' torque at t)
    zdot0: np.ndarray  # ż at (z0, u0): zero at an equilibrium
    trim_torque: np.ndarray | None  # the body torque that holds R (torque command only) [N m]
    #: the actuator could not deliver trim_torque (a CMG limit): linearised at zero command instead
    trim_limited: bool = False
    tea_theta: np.ndarray | None = None  # about="tea": θ of the TEA relative to LVLH [rad]
    modal_states: list = field(default_factory=list)  # indices of η, η̇ in z


def _structure_key(scene, command):
    return (Structure.of(scene), scene.simulation.formulation, command)


_PLANTS: dict = {}


def plant_functions(scene, command: str = "torque"):
    """The casadi Functions of the analysis plant for a scene's structure (built once, cached).

    ``F(t, z, v, d, q_RO, p) -> ż`` and ``jac(...) -> (ż, A, B_v, B_d, C, y)``; the names of
    the states, inputs and outputs. Built on the scene's own formulation, from the same
    ``System`` the simulator compiles (``build_system``; the symbolic expressions are its
    formulation's).
    """
    key = _structure_key(scene, command)
    if key in _PLANTS:
        return _PLANTS[key]
    system = build_system(Structure.of(scene), scene.simulation.formulation, scene.simulation.integrator)
    form = system.formulation
    model = form.model
    st = model.structure
    cmg = model.cmg
    ng = 0 if cmg is None else cmg.n_gimbals
    if command == "gimbal_rates" and ng == 0:
        raise ValueError("command = 'gimbal_rates' needs a gimballed [cmg]")
    ne, nm = model.n_extra, model.n_modes
    nz = 6 + ne + 2 * nm
    nv = ng if command == "gimbal_rates" else 3
    t = ca.SX.sym("t")
    z = ca.SX.sym("z", nz)
    v = ca.SX.sym("v", nv)
    d = ca.SX.sym("d", 3)
    q_RO = ca.SX.sym("q_RO", 4)
    p = ca.SX.sym("p", model.layout.size)
    th, dw = z[0:3], z[3:6]
    e = th / 2
    qw = ca.sqrt(1.0 - ca.dot(e, e))
    q_BR = ca.vertcat(qw, e)
    C_BR = dcm(q_BR)
    if st.orbit:
        radius, incl, u0, n = (p[model.layout["orbit"]][i] for i in range(4))
        q_RN = quat_mult(q_ON(u0 + n * t, incl), q_RO)
        w_RN_R = ca.mtimes(dcm(q_RO), ca.vertcat(0.0, -n, 0.0))
    else:
        q_RN = q_RO
        w_RN_R = ca.SX.zeros(3)
    q_BN = quat_mult(q_RN, q_BR)
    w_R_B = ca.mtimes(C_BR, w_RN_R)
    w = dw + w_R_B
    xe = z[6:]
    x = form.state(t, q_BN, w, xe, p)
    limited = ca.SX(0.0)
    if cmg is None:
        u = d + v
    else:
        fname = "actuate_rates" if command == "gimbal_rates" else "actuate"
        act = system.sx[fname](t, x, v, p)
        limited = act[model.nu_cmg + 1]  # (u, singularity, limited, saturated): the limited flag
        u = ca.vertcat(d, act[0 : model.nu_cmg])
    if model.has_steps:
        u = ca.vertcat(u, t)
    # ẋ and the total time derivatives of ω(t, x) and η̇(t, x), on plain symbols, then evaluated
    # at x(z) (casadi differentiates with respect to symbols only)
    xs, us = ca.SX.sym("xs", form.nx), ca.SX.sym("us", u.numel())
    xdot_s = form.rhs(t, xs, us, p)
    w_s = form.omega(t, xs, p)
    derivs = [xdot_s, ca.jtimes(w_s, xs, xdot_s) + ca.jacobian(w_s, t)]
    if nm:
        etad = form.modal_rates(t, xs, p)
        derivs.append(ca.jtimes(etad, xs, xdot_s) + ca.jacobian(etad, t))
    H_s = form.H_O_B(t, xs, p)
    derivs.append(ca.jtimes(H_s, xs, xdot_s) + ca.jacobian(H_s, t))  # Ḣ_B: external + gyroscopic only
    D = ca.Function("derivs", [t, xs, us, p], derivs)(t, x, u, p)
    track = _tracking_extras(model, t, q_BN, w, xe[0:ne], p)
    xdot, w_dot, H_dot = D[0], D[1], D[-1]
    parts = [qw * dw + ca.cross(e, dw), w_dot + ca.cross(dw, w_R_B), xdot[7 : 7 + ne + nm]]
    if nm:
        parts.append(D[2])
    zdot = ca.vertcat(*parts)
    y = [th, dw]
    if cmg is not None:
        y.append(model.h(x[7:], p))
    y = ca.vertcat(*y)
    F = ca.Function("plant", [t, z, v, d, q_RO, p], [zdot], {"cse": True})
    x_of_z = ca.Function("x_of_z", [t, z, q_RO, p], [x])
    jac = ca.Function(
        "plant_jac", [t, z, v, d, q_RO, p],
        [zdot, ca.jacobian(zdot, z), ca.jacobian(zdot, v), ca.jacobian(zdot, d), ca.jacobian(y, z), y], {"cse": True},
    )
    # the TEA residual: the mean of δω̇ (and η̈) over given instants, zero rates, as a function of θ (and η)
    names_z = ["att_err_x", "att_err_y", "att_err_z", "rate_err_x", "rate_err_y", "rate_err_z"]
    names_z += list(model.extra_names) + list(model.eta_names) + [f"{n}_rate" for n in model.eta_names]
    if command == "gimbal_rates":
        names_v = [f"gimbal_rate{k}" for k in range(ng)]
    else:
        names_v = ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z"]
    names_d = ["tau_dist_x", "tau_dist_y", "tau_dist_z"]
    names_y = names_z[0:6] + (["h_x", "h_y", "h_z"] if cmg is not None else [])
    out = {
        "F": F, "jac": jac, "system": system, "states": names_z, "controls": names_v, "disturbances": names_d,
        "outputs": names_y, "x_of_z": x_of_z,
        "limited": ca.Function("limited", [t, z, v, q_RO, p], [limited]),
        "H_dot": ca.Function("H_dot", [t, z, v, d, q_RO, p], [H_dot]),
        "inertia": ca.Function("inertia", [t, z, q_RO, p], [system.sx["inertia"](t, x, p)]), "nz": nz, "ne": ne, "nm": nm, "model": model,
        # the extra states with the sun-tracking joints on their targets at (t, q_BN(z), ω(z)), and
        # their time derivative as the station moves with R (the targets' rates and accelerations)
        "track": ca.Function("track", [t, z, q_RO, p], [track, ca.jacobian(track, t)]),
    }
    _PLANTS[key] = out
    return out


#: Newton iterations that put each drive on its steady tracking state (the angle lag at which its
#: law accelerates the joint as its target accelerates): the drive laws are linear below their
#: limits, so one step solves it and a second checks it.
DRIVE_NEWTON = 3


def _default_z0(scene, pf, p, t: float = 0.0, q_RO=(1.0, 0.0, 0.0, 0.0), omega=None):
    """The analysis state at the point: θ = 0, δω (``omega``: that giving ω_BN_B, default 0), the
    scene's CMG state and modal coordinates at t = 0, and every sun-tracking joint on its steady
    tracking state at ``t``, not on the run's initial joint state, which a drive first spins up
    from (a transient of ~100 N m per array at the drives' acceleration limit, not the holding
    torque of the point). The steady tracking state: the rate the target's, the angle the
    target's less the lag at which the drive's law accelerates the joint as the target
    accelerates (``pf["track"]``: the targets and their time derivative as the station moves with
    R; a Newton solve on the drives' own acceleration, :data:`DRIVE_NEWTON`). The held torque's
    input is at zero: the drives do not read it."""
    model = pf["model"]
    z0 = np.zeros(pf["nz"])
    ne = pf["ne"]
    xe = model.initial_extra(scene, np.array([1.0, 0.0, 0.0, 0.0]), p)
    z0[6 : 6 + ne] = xe[0:ne]
    q_RO = np.asarray(q_RO, float)
    if omega is not None:
        n = 0.0 if scene.orbit is None else scene.orbit.mean_motion
        z0[3:6] = np.asarray(omega, float) - dcm(q_RO) @ np.array([0.0, -n, 0.0])
    if not model.driven:
        return z0
    target, target_dot = (np.array(m).ravel() for m in pf["track"](t, z0, q_RO, p))
    z0[6 : 6 + ne] = target
    ang = np.array([6 + off for _, _, off in model.driven])  # the joints' angle, then rate, states
    nv = len(pf["controls"])
    for _ in range(DRIVE_NEWTON):
        zd, A = (np.array(m) for m in pf["jac"](t, z0, np.zeros(nv), np.zeros(3), q_RO, p)[0:2])
        res = zd.ravel()[ang + 1] - target_dot[ang - 6 + 1]  # joint acceleration - the target's
        z0[ang] += np.linalg.lstsq(A[np.ix_(ang + 1, ang)], -res, rcond=None)[0]
    return z0


def _tracking_extras(model, t, q_BN, w_BN_B, ext, p):
    """The extra states ``ext`` with every sun-tracking joint on its target (angle, and the
    target's rate as the body turns at ``w_BN_B``) for a station at ``q_BN`` at time ``t``
    (casadi): the steady state the drives follow (their law's acceleration is then zero). A
    night-glider joint in the Earth's shadow (ν < 1/2, as its drive decides) is parked instead:
    edge-on to the flow at the angle nearer its sun target, at rest."""
    ext = [ext[i] for i in range(ext.numel())]
    if not model.driven:
        return ca.vertcat(*ext) if ext else ca.SX(0, 1)
    xe = ca.vertcat(*ext)
    joints = model.structure.joints
    if any(kind == "g" for a in joints for kind, _ in a):
        orbit = model.orbit_at(t, p)
        dark, v_B = model.shadow(orbit, p) < 0.5, v_rel_B(dcm(q_BN), orbit)

    def on_target(k, i, Y, X, rate, alpha):
        angle = ca.atan2(Y, X)
        if joints[k][i][0] != "g":
            return angle, rate
        v = v_B if i == 0 else ca.mtimes(Ay(alpha), v_B)  # the BGA's flow: in the frame the SARJ turned
        return ca.if_else(dark, angle + glider_error(angle, v, i), angle), ca.if_else(dark, 0.0, rate)

    for k in sorted({k for k, _, _ in model.driven}):
        offs = {j: off for kk, j, off in model.driven if kk == k}
        if "alpha" in offs:
            ((Y, X), a_rate), _ = model._driven_targets(k, q_BN, xe, p, w_BN_B, 0.0, 0.0)  # α* needs no α
            alpha, a_rate = on_target(k, 0, Y, X, a_rate, 0.0)
            ext[offs["alpha"]], ext[offs["alpha"] + 1] = alpha, a_rate
        else:
            alpha, a_rate, _ = profile(t, p[model.layout[f"alpha{k}"]], joints[k][0][1])
        if "beta" in offs:
            _, ((Yb, Xb), b_rate) = model._driven_targets(k, q_BN, xe, p, w_BN_B, alpha, a_rate)
            ext[offs["beta"]], ext[offs["beta"] + 1] = on_target(k, 1, Yb, Xb, b_rate, alpha)
    return ca.vertcat(*ext)


def tea_search(pf, scene, p, z0, t, q_RO=(1.0, 0.0, 0.0, 0.0)):
    """θ of the torque-equilibrium attitude relative to LVLH [rad] (Newton from LVLH), and the
    modal coordinates η there.

    A station fixed in LVLH whose motion is periodic over the orbit has a periodic ``H_B``: the
    mean of ``Ḣ_B = L - ω × H`` over the orbit is zero. That is the residual (the formulation's
    ``H_O_B`` differentiated along its own ``ẋ``: external and gyroscopic torques only, so array
    drives and other internal exchanges, which average out, do not bias it), with zero rates
    relative to LVLH and zero control, at :data:`TEA_SAMPLES` instants of one orbit from ``t``,
    scaled by ``I⁻¹ / n²`` (dimensionless); the modal accelerations ``η̈ / n²`` (averaged) give η.
    Sun-tracking joints sit on their targets at each instant (:func:`_tracking_extras`), so the
    arrays turn over the orbit as they do in flight; the other extra states keep their values.
    """
    if scene.orbit is None:
        raise ValueError("about = 'tea' needs an [orbit] (a torque-equilibrium attitude is relative to LVLH)")
    ne, nm = pf["ne"], pf["nm"]
    q_RO = ca.DM(q_RO)
    if "tea_G" not in pf:  # the residual as a function of (θ, η; t, extras, p, I⁻¹), built once
        model = pf["model"]
        unk = ca.SX.sym("unk", 3 + nm)
        t0, ext0 = ca.SX.sym("t0"), ca.SX.sym("ext0", ne)
        d_k = ca.SX.sym("d_k", 3, TEA_SAMPLES)  # the held torque at each instant, B [N m]
        pp, I_inv = ca.SX.sym("p", model.layout.size), ca.SX.sym("I_inv", 3, 3)
        n = pp[model.layout["orbit"]][3]
        nv = len(pf["controls"])
        res = 0
        for k in range(TEA_SAMPLES):
            tk = t0 + k * (2 * math.pi / TEA_SAMPLES) / n
            zs = ca.vertcat(unk[0:3], ca.SX.zeros(3), ext0, unk[3:], ca.SX.zeros(nm))
            zs = ca.vertcat(zs[0:6], pf["track"](tk, zs, q_RO, pp)[0], zs[6 + ne :])
            args = (tk, zs, ca.SX.zeros(nv), d_k[:, k], q_RO, pp)
            parts = [ca.mtimes(I_inv, pf["H_dot"](*args)) / n**2]
            if nm:
                parts.append(pf["F"](*args)[6 + ne + nm :] / n**2)
            res = res + ca.vertcat(*parts)
        res = res / TEA_SAMPLES
        pf["tea_G"] = ca.Function("tea_G", [unk, t0, ext0, pp, I_inv, d_k], [res, ca.jacobian(res, unk)],
                                  {"cse": True})
    I_inv = np.linalg.inv(np.array(pf["inertia"](t, z0, q_RO, ca.DM(p))))
    held = held_over_orbit(scene, t)
    G = lambda x: pf["tea_G"](x, t, z0[6 : 6 + ne], p, I_inv, held)  # noqa: E731
    xk = np.zeros(3 + nm)
    for _ in range(60):
        g, Jg = (np.array(v) for v in G(xk))
        step = np.linalg.lstsq(Jg, -g.ravel(), rcond=None)[0]
        s = float(np.linalg.norm(step[0:3]))
        if s > 0.2:  # stay in the valid range of θ = 2 vec(q)
            step *= 0.2 / s
        xk = xk + step
        if float(np.linalg.norm(step)) < 1e-13:
            break
    g = np.array(G(xk)[0]).ravel()
    if not np.all(np.isfinite(xk)) or np.linalg.norm(g[0:3]) > TEA_RESIDUAL or np.linalg.norm(xk[0:3]) > TEA_MAX_RAD:
        raise ValueError(
            f"no torque-equilibrium attitude within {math.degrees(TEA_MAX_RAD):.0f} deg of LVLH "
            f"(Newton ended at {np.degrees(xk[0:3]).round(2).tolist()} deg, residual {np.linalg.norm(g):.3g})"
        )
    return xk[0:3], xk[3:]


def held_over_orbit(scene, t: float) -> np.ndarray:
    """The held torque (every held kind's, e.g. ``constant`` windows) at the TEA's
    :data:`TEA_SAMPLES` instants of the orbit from ``t``, B components [N m], shape (3, TEA_SAMPLES).

    Raises ValueError naming the kind, its entry and the time when a held torque switches inside
    that orbit: the TEA balances torques that repeat every orbit, and a window that opens or
    closes inside it does not (linearise at a ``t`` where it is on, or off, for a whole orbit)."""
    n = scene.orbit.mean_motion
    t_end = t + 2 * math.pi / n
    for i, entry in enumerate(scene.torque):
        kind = get_torque(entry.kind)
        for b in kind.breakpoints(entry):
            if t < b < t_end:
                raise ValueError(
                    f"torque[{i}] (kind = {kind.kind!r}) switches at t = {b:g} s, inside the orbit the TEA "
                    f"averages over (t = {t:g} .. {t_end:.6g} s): a torque-equilibrium attitude needs torques "
                    "that repeat every orbit; choose a time when it is on (or off) for a whole orbit"
                )
    times = t + np.arange(TEA_SAMPLES) * (2 * math.pi / TEA_SAMPLES) / n
    return np.column_stack([held_torque_B(scene, tk) for tk in times])


def linearization(scene, about="lvlh", *, t: float = 0.0, q_ref=(1.0, 0.0, 0.0, 0.0), command: str = "torque",
                  trim: bool = True, v0=None) -> Linearization:
    """The linear plant of ``scene`` and its operating point (see :func:`linearize`); ``v0``: the
    control input at the point (overrides ``trim``)."""
    pf = plant_functions(scene, command)
    model = pf["model"]
    p = model.params(scene)
    q_RO = np.asarray(q_ref, float)
    q_RO = q_RO / np.linalg.norm(q_RO)
    tea = None
    z0 = None
    if isinstance(about, OperatingPoint):
        t = float(about.t)
        q_BN = np.asarray(about.q_BN, float)
        q_BN = q_BN / np.linalg.norm(q_BN)
        if scene.orbit is not None:
            o = scene.orbit
            q_RO = quat_mult_np(quat_conj_np(np.asarray(q_ON(o.u0 + o.mean_motion * t, o.inclination), float)), q_BN)
        else:
            q_RO = q_BN
        z0 = _default_z0(scene, pf, p, t, q_RO, omega=about.omega_BN_B)
        if about.xe is not None:
            z0[6:] = np.asarray(about.xe, float)
    elif about == "tea":
        q_RO = np.array([1.0, 0.0, 0.0, 0.0])
        z0 = _default_z0(scene, pf, p, t, q_RO)
        tea, eta = tea_search(pf, scene, p, z0, t)
        z0[0:3] = tea
        ne = pf["ne"]  # the sun-tracking joints on their targets at t, as in the search
        z0[6 : 6 + ne] = np.array(pf["track"](t, z0, q_RO, p)[0]).ravel()
        z0[6 + pf["ne"] : 6 + pf["ne"] + pf["nm"]] = eta
    elif about == "lvlh":
        z0 = _default_z0(scene, pf, p, t, q_RO)
    else:
        raise ValueError(f"about = {about!r}: expected 'lvlh', 'tea' or an OperatingPoint")
    nv = len(pf["controls"])
    given = v0 is not None
    v0 = np.zeros(nv) if v0 is None else np.asarray(v0, float).ravel()
    d0 = held_torque_B(scene, t)  # the held kinds' torque at t (the symbolic kinds are in the equations)
    args = lambda v: (t, z0, v, d0, q_RO, p)  # noqa: E731
    zd, A, Bv, Bd, C, _ = (np.array(m) for m in pf["jac"](*args(v0)))
    trim_torque = None
    trim_limited = False
    if trim and command == "torque" and not given:
        # the body torque that holds the point: δω̇ is affine in the torque (the steering law
        # delivers the command to the body), one Newton step solves it
        v_trim = -np.linalg.solve(Bv[3:6], zd.ravel()[3:6])
        trim_torque = v_trim.copy()
        if float(pf["limited"](t, z0, v_trim, q_RO, p)) > 0.5:
            trim_limited = True  # the limit's scaling is not the plant's small-signal gain: stay at 0
        else:
            v0 = v_trim
            zd, A, Bv, Bd, C, _ = (np.array(m) for m in pf["jac"](*args(v0)))
    import control

    B = np.hstack([Bv, Bd])
    D = np.zeros((C.shape[0], B.shape[1]))
    ss = control.ss(A, B, C, D, states=pf["states"], inputs=pf["controls"] + pf["disturbances"], outputs=pf["outputs"],
                    name=f"{safe_name(scene.name)}_plant")
    nmod = pf["nm"]
    modal = list(range(6 + pf["ne"], 6 + pf["ne"] + 2 * nmod))
    return Linearization(ss, t, q_RO, z0, np.r_[v0, d0], zd.ravel(), trim_torque, trim_limited, tea, modal)


def modal_poles(A, modal_states) -> np.ndarray:
    """The poles of ``A`` that belong to the flexible arrays: for each eigenvalue of the modal block
    alone (the arrays on a clamped hub) in the upper half plane, the nearest pole of ``A`` (the
    hub's freedom moves it from the clamped to the free-hub frequency) and its conjugate."""
    if not modal_states:
        return np.zeros(0, complex)
    poles = list(np.linalg.eigvals(A))
    out = []
    for lam in np.linalg.eigvals(A[np.ix_(modal_states, modal_states)]):
        if lam.imag <= 0 or not poles:
            continue
        j = int(np.argmin([abs(p - lam) for p in poles]))
        p = poles.pop(j)
        out += [p, np.conj(p)]
    return np.array(out)


def quat_conj_np(q):
    return np.array([q[0], -q[1], -q[2], -q[3]])


def quat_mult_np(a, b):
    return np.asarray(quat_mult(np.asarray(a, float), np.asarray(b, float)), float).ravel()


def linearize(scene, about="lvlh", *, t: float = 0.0, q_ref=(1.0, 0.0, 0.0, 0.0), command: str = "torque",
              dt: float | None = None, trim: bool = True):
    """The scene's plant linearised about a reference, as a python-control ``StateSpace``.

    Parameters
    ----------
    scene : Scene
    about : "lvlh", "tea" or OperatingPoint
        ``"lvlh"``: R fixed in LVLH at ``q_ref`` (R = N without an orbit); ``"tea"``: R = LVLH, the
        point at the torque-equilibrium attitude (found by Newton, :func:`tea_search`); an
        :class:`OperatingPoint`: that attitude and rate at its time.
    t : float  The instant the time-varying terms are frozen at [s] (ignored for an OperatingPoint).
    q_ref : (4,)  R relative to LVLH (or N), scalar first (``"lvlh"`` only).
    command : "torque" or "gimbal_rates"  The control input.
    dt : float, optional  A controller period [s]: return the zero-order-hold discrete plant
        (python-control's ``c2d(..., "zoh")``, same signal names).
    trim : bool  Linearise at the control torque that holds the point (``"torque"`` only).

    Returns
    -------
    control.StateSpace  States, inputs (control, then disturbance) and outputs named (see the
    module docstring); ``sys.linearization`` is the :class:`Linearization` (point, trim torque).
    """
    lin = linearization(scene, about, t=t, q_ref=q_ref, command=command, trim=trim)
    sys = lin.ss
    if dt is not None:
        import control

        sys = control.c2d(sys, float(dt), method="zoh")
    sys.linearization = lin
    return sys
