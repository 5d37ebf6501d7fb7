"""The station model in casadi expressions, and the base class of every formulation.

:class:`StationModel` turns a scene's *structure* (how many arrays, orbit or not, which torques)
into symbolic quantities at time ``t``: the total inertia about the composite mass centre O,
each array's ``I_p``, ``omega_p``, ``omega_p_dot`` in B, and the external torque. Numbers
(mass properties, profiles, orbit) enter through one parameter vector ``p`` whose layout is
declared once in :class:`ParamLayout`, so one compiled function serves every scene of the same
structure. Only the effects a scene names are built ("model no more than a scene needs").

A :class:`Formulation` adds the state layout and the equations of motion. Energy and angular
momentum are generic: they need only the formulation's ``omega(t, x, p)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np

from ..appendages import joint_kinematics
from ..environment import C_ON, gravity_gradient_torque, orbit_position_N
from ..massprops import composite_cm, coriolis_matrix, parallel_axis
from ..rotation import dcm, quat_kinematics

__all__ = ["Structure", "ParamLayout", "StationModel", "Formulation", "inv3", "cross"]


def cross(a, b):
    return ca.cross(a, b)


def inv3(A):
    """Inverse of a 3x3 casadi matrix by cofactors (exact, ~40 flops, no pivoting needed for SPD)."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    adj = ca.vertcat(
        ca.horzcat(c00, A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2], A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]),
        ca.horzcat(c01, A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0], A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]),
        ca.horzcat(c02, A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1], A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]),
    )
    return adj / det


@dataclass(frozen=True)
class Structure:
    """What a scene's equations contain; two scenes with equal structure share compiled code.

    ``joints`` has per appendage ``((kind, n_steps) for alpha, (kind, n_steps) for beta)`` with
    kind ``"p"`` (profile with ``n_steps`` rate steps) or ``"s"`` (sun-tracking drive, a state).
    ``cmg`` is ``(kind, n_units, steering)`` or None.
    """

    n_app: int
    orbit: bool
    gravity_gradient: bool
    harmonic: bool
    joints: tuple = ()
    sun: bool = False
    cmg: tuple | None = None
    #: elastic modes per appendage (all 0: a rigid scene, whose equations and key do not change)
    modes: tuple = ()

    @classmethod
    def of(cls, scene) -> "Structure":
        from ..scene import HarmonicTorque

        def joint(j):
            return ("s", 0) if j.tracked else ("p", len(j.rate_step))

        c = scene.cmg
        return cls(
            n_app=len(scene.appendage),
            orbit=scene.orbit is not None,
            gravity_gradient=scene.orbit is not None and scene.orbit.gravity_gradient,
            harmonic=any(isinstance(t, HarmonicTorque) for t in scene.torque),
            joints=tuple((joint(a.alpha), joint(a.beta)) for a in scene.appendage),
            sun=scene.sun is not None,
            cmg=None if c is None else (c.kind, c.n_units, c.steering if c.kind != "ideal" else "none"),
            modes=tuple(len(a.mode) for a in scene.appendage) if any(a.mode for a in scene.appendage) else (),
        )

    @property
    def key(self) -> str:
        j = "".join(f"{k}{n}" for a in self.joints for k, n in a)
        c = "" if self.cmg is None else f"c{self.cmg[0]}{self.cmg[1]}{self.cmg[2]}"
        f = "" if not self.modes else "f" + "_".join(str(n) for n in self.modes)
        return (
            f"a{self.n_app}o{int(self.orbit)}g{int(self.gravity_gradient)}h{int(self.harmonic)}"
            f"j{j}s{int(self.sun)}{c}{f}"
        )

    def n_modes(self, k: int) -> int:
        return self.modes[k] if self.modes else 0


JOINTS = ("alpha", "beta")


class ParamLayout:
    """Names and slices of the parameter vector ``p`` (declared once, owns the indices)."""

    def __init__(self, structure: Structure, cmg_n_par: int = 0):
        self.slices: dict[str, slice] = {}
        n = 0

        def add(name, size):
            nonlocal n
            self.slices[name] = slice(n, n + size)
            n += size

        add("I0", 9)  # hub + all parallel-axis terms, about O, B axes [kg m²]
        for k in range(structure.n_app):
            add(f"J{k}", 9)  # array inertia about its own mass centre, P axes [kg m²]
            for j, (kind, n_steps) in zip(JOINTS, structure.joints[k]):
                # profile: (a0, rate, amp, freq, phase, t1, d1, ...); drive: (max_rate, max_acc, gain, tau)
                add(f"{j}{k}", 5 + 2 * n_steps if kind == "p" else 4)
            if structure.n_modes(k):
                add(f"rho{k}", 3)  # array mass centre from O, B axes [m]
                add(f"modes{k}", 9 * structure.n_modes(k))  # per mode: Φ̄ (3), Ĥ (3), M, K, C (P axes)
        if structure.modes:
            add("mtot", 1)  # total mass [kg]: the hub's recoil when the arrays bend
        if structure.orbit:
            add("orbit", 6)  # radius [m], inclination [rad], u0 [rad], n [rad/s], cos i, sin i
        if structure.harmonic:
            add("harm", 15)  # bias, cos1, sin1, cos2, sin2 (B, N m), summed over torques
        if structure.sun:
            add("sun", 3)  # unit vector to the sun, N components
        if structure.cmg is not None:
            add("cmg", cmg_n_par)
        self.size = n

    def __getitem__(self, name) -> slice:
        return self.slices[name]


class StationModel:
    """Symbolic station quantities for one :class:`Structure`.

    Besides the formulation's own seven states (q_BN and one 3-vector), a scene may add
    *extra states*, owned here and appended after them: the CMG cluster's (``h`` or the gimbal
    angles) and, per sun-tracking joint, its angle and rate. The held input ``u`` is the
    external body torque (3) followed by the CMG input (torque command or gimbal rates).
    """

    def __init__(self, structure: Structure):
        from ..cmg import CmgModel

        self.structure = structure
        self.cmg = None if structure.cmg is None else CmgModel(*structure.cmg)
        self.layout = ParamLayout(structure, 0 if self.cmg is None else self.cmg.n_par)
        names, kinds = [], []
        if self.cmg is not None:
            names += list(self.cmg.state_names)
            kinds += ["momentum" if self.cmg.kind == "ideal" else "attitude"] * self.cmg.nx
        self.driven = []  # (appendage index, joint name, offset of its angle in the extra states)
        for k in range(structure.n_app):
            for j, (kind, _) in zip(JOINTS, structure.joints[k]):
                if kind == "s":
                    self.driven.append((k, j, len(names)))
                    names += [f"{j}{k}", f"{j}{k}_rate"]
                    kinds += ["attitude", "rate"]
        self.extra_names = tuple(names)
        self.extra_kinds = tuple(kinds)
        self.n_extra = len(names)
        #: flexible arrays: (appendage index, slice of the modal coordinates); the modal states
        #: (η, then the formulation's second modal state) follow the extra states
        self.flexible = []
        n = 0
        for k in range(structure.n_app):
            if structure.n_modes(k):
                self.flexible.append((k, slice(n, n + structure.n_modes(k))))
                n += structure.n_modes(k)
        self.n_modes = n
        self.eta_names = tuple(f"eta{k}_{j + 1}" for k, sl in self.flexible for j in range(sl.stop - sl.start))
        self.nu_cmg = 0 if self.cmg is None else self.cmg.nu
        #: profiles with rate steps: u ends with the segment's mid time, which decides the side of
        #: a step for every stage (a step on a segment edge is then exact for any integrator)
        self.has_steps = any(n > 0 for a in structure.joints for _, n in a)
        self.nu = 3 + self.nu_cmg + (1 if self.has_steps else 0)

    # -- numbers ------------------------------------------------------------------------
    def params(self, scene) -> np.ndarray:
        """The numeric parameter vector of ``scene`` (composite mass centre computed here)."""
        from ..environment import sun_direction_N
        from ..scene import HarmonicTorque

        L = self.layout
        p = np.zeros(L.size)
        masses = [scene.body.mass] + [a.mass for a in scene.appendage]
        cms = [scene.body.cm] + [a.cm for a in scene.appendage]
        r_O = composite_cm(masses, cms)
        I0 = np.array(scene.body.inertia) + parallel_axis(scene.body.mass, np.array(scene.body.cm) - r_O)
        for k, a in enumerate(scene.appendage):
            I0 += parallel_axis(a.mass, np.array(a.cm) - r_O)
            p[L[f"J{k}"]] = np.array(a.inertia).ravel()
            for j in JOINTS:
                jt = getattr(a, j)
                if jt.tracked:
                    p[L[f"{j}{k}"]] = [jt.max_rate, jt.max_acc, jt.gain, jt.rate_tau]
                else:
                    steps = [v for st in jt.rate_step for v in (st.t, st.delta)]
                    p[L[f"{j}{k}"]] = jt.coeffs() + steps
        p[L["I0"]] = I0.ravel()
        if self.structure.orbit:
            o = scene.orbit
            i = o.inclination  # cos/sin of a parameter: computed once here, not per RHS stage
            p[L["orbit"]] = [o.radius_m, i, o.u0, o.mean_motion, math.cos(i), math.sin(i)]
        if self.structure.harmonic:
            h = np.zeros(15)
            for t in scene.torque:
                if isinstance(t, HarmonicTorque):
                    h += np.concatenate([t.bias_B, t.cos1_B, t.sin1_B, t.cos2_B, t.sin2_B])
            p[L["harm"]] = h
        if self.structure.sun:
            incl = scene.orbit.inclination if scene.orbit is not None else 0.0
            p[L["sun"]] = sun_direction_N(scene.sun, incl)
        if self.cmg is not None:
            p[L["cmg"]] = self.cmg.params(scene.cmg)
        if self.flexible:
            p[L["mtot"]] = sum(masses)
        for k, _ in self.flexible:
            a = scene.appendage[k]
            p[L[f"rho{k}"]] = np.array(a.cm) - r_O
            vals = []
            for mode in a.mode:
                phi_bar, H_hat, M = mode.integrals(a.mass)
                w = mode.omega
                vals += list(phi_bar) + list(H_hat) + [M, w * w * M, 2.0 * mode.damping * w * M]
            p[L[f"modes{k}"]] = vals
        return p

    def initial_extra(self, scene, q_BN, p) -> np.ndarray:
        """Extra states at t = 0 (CMG state; driven joints start on target unless ``a0`` is given),
        then the modal coordinates and rates ``η, η̇`` (the formulation converts η̇ to its state)."""
        from ..appendages import sun_targets

        xe = np.zeros(self.n_extra + 2 * self.n_modes)
        for k, sl in self.flexible:
            modes = scene.appendage[k].mode
            xe[self.n_extra + sl.start : self.n_extra + sl.stop] = [m.eta0 for m in modes]
            xe[self.n_extra + self.n_modes + sl.start : self.n_extra + self.n_modes + sl.stop] = [m.eta_rate0 for m in modes]
        if self.cmg is not None:
            xe[: self.cmg.nx] = self.cmg.initial_state(scene.cmg)
        if self.driven:
            s_B = dcm(np.asarray(q_BN, float)) @ p[self.layout["sun"]]
        for k, j, off in self.driven:
            jt = getattr(scene.appendage[k], j)
            if jt.a0 is not None:
                angle = jt.a0
            else:
                alpha = xe[off - 2] if (j == "beta" and self.structure.joints[k][0][0] == "s") else None
                if alpha is None:
                    alpha = scene.appendage[k].alpha.a0 if not scene.appendage[k].alpha.tracked else 0.0
                a_star, b_star = sun_targets(s_B, alpha)
                angle = a_star if j == "alpha" else b_star
            xe[off] = angle
            xe[off + 1] = jt.rate0
        return xe

    # -- symbols ------------------------------------------------------------------------
    def _mat(self, p, name):
        return ca.reshape(p[self.layout[name]], 3, 3).T  # row-major in p

    def sun_B(self, q, p):
        return ca.mtimes(dcm(q), p[self.layout["sun"]])

    def _driven_targets(self, k, q, xe, p, w, alpha, alpha_rate):
        """Sun-tracking targets of array k and their rates (analytic, ṡ_B = -ω × s_B)."""
        s_B = self.sun_B(q, p)
        sd = -ca.cross(w, s_B)
        den_a = ca.fmax(s_B[0] ** 2 + s_B[2] ** 2, 1e-12)
        a_star_rate = (s_B[2] * sd[0] - s_B[0] * sd[2]) / den_a
        ca_, sa_ = ca.cos(alpha), ca.sin(alpha)
        v = ca.vertcat(ca_ * s_B[0] - sa_ * s_B[2], s_B[1], sa_ * s_B[0] + ca_ * s_B[2])
        vd = ca.vertcat(
            (-sa_ * s_B[0] - ca_ * s_B[2]) * alpha_rate + ca_ * sd[0] - sa_ * sd[2],
            sd[1],
            (ca_ * s_B[0] - sa_ * s_B[2]) * alpha_rate + sa_ * sd[0] + ca_ * sd[2],
        )
        b_star_rate = (-v[2] * vd[1] + v[1] * vd[2]) / ca.fmax(v[1] ** 2 + v[2] ** 2, 1e-12)
        # targets as (Y, X) with θ* = atan2(Y, X): the drive wraps the error with one atan2
        return ((s_B[0], s_B[2]), a_star_rate), ((-v[1], v[2]), b_star_rate)

    def t_switch(self, u):
        """The time that decides which side of a rate step a stage is on (None: t itself)."""
        return u[self.nu - 1] if (self.has_steps and u is not None) else None

    def joint_states(self, t, q, xe, p, w=None, u=None):
        """Per array ``[(angle, rate, accel) or None for alpha, ... for beta]``; accel needs ``w``."""
        from ..appendages import drive_acceleration, profile

        out = [[None, None] for _ in range(self.structure.n_app)]
        for k, j, off in self.driven:
            out[k][JOINTS.index(j)] = [xe[off], xe[off + 1], None]
        if w is not None:
            for k in {k for k, _, _ in self.driven}:
                ja, jb = out[k]
                if ja is None:
                    c = p[self.layout[f"alpha{k}"]]
                    alpha, alpha_rate, _ = profile(t, c, self.structure.joints[k][0][1], self.t_switch(u))
                else:
                    alpha, alpha_rate = ja[0], ja[1]
                targets = self._driven_targets(k, q, xe, p, w, alpha, alpha_rate)
                for i, js in enumerate(out[k]):
                    if js is not None:
                        js[2] = drive_acceleration(js[0], js[1], *targets[i], p[self.layout[f"{JOINTS[i]}{k}"]])
        return out

    def arrays(self, t, q, xe, p, w=None, u=None):
        """Per array: ``(I_p, omega_p, omega_p_dot, (alpha, beta), C_PB, J_p, omega_PB_P)`` in B.

        ``omega_p_dot`` of a sun-tracking array needs ``w`` (its drive follows a target that
        moves with the body); without it that entry is None. ``u`` (the held input) places
        rate steps by the segment time (see :meth:`t_switch`); without it a step is
        right-continuous in t.
        """
        states = self.joint_states(t, q, xe, p, w, u)
        out = []
        for k in range(self.structure.n_app):
            J = self._mat(p, f"J{k}")
            (_, na), (_, nb) = self.structure.joints[k]
            C_PB, w_P, wd_P, ang = joint_kinematics(
                t, p[self.layout[f"alpha{k}"]], p[self.layout[f"beta{k}"]], (na, nb), tuple(states[k]), self.t_switch(u)
            )
            C_BP = C_PB.T
            I_p = ca.mtimes([C_BP, J, C_PB])
            wd_p = None if wd_P is None else ca.mtimes(C_BP, wd_P)
            out.append((I_p, ca.mtimes(C_BP, w_P), wd_p, ang, C_PB, J, w_P))
        return out

    def kinetic_energy(self, t, q, w, xe, p, u=None, h_coupling=False):
        """``T = ½ωᵀIω + Σ (ωᵀI_pω_p + ½ω_pᵀI_pω_p) + T_e`` [J] at rate ``w`` (``xe`` with ``η̇``,
        as for :meth:`Formulation.state`); ``T_e`` the arrays' elastic kinetic energy
        (:meth:`stationbed.flex.Modes.kinetic`). ``h_coupling`` adds ``ωᵀh``, the only part of
        the CMG rotors' energy that depends on ω (what the ``hamel`` form differentiates)."""
        arrays = self.arrays(t, q, xe, p, u=u)
        T = 0.5 * ca.dot(w, ca.mtimes(self.inertia(t, p, arrays), w))
        if h_coupling:
            T = T + ca.dot(w, self.h(xe, p))
        for I_p, w_p, *_ in arrays:
            T = T + ca.dot(w, ca.mtimes(I_p, w_p)) + 0.5 * ca.dot(w_p, ca.mtimes(I_p, w_p))
        modal = self.modal(arrays, p)
        if modal is not None:
            T = T + modal.kinetic(w, self.modal_state(xe))
        return T

    # -- flexible arrays ----------------------------------------------------------------
    def eta(self, xe):
        """The modal coordinates ``η`` from the extra states ``xe`` (= x[7:])."""
        return xe[self.n_extra : self.n_extra + self.n_modes]

    def modal_state(self, xe):
        """The formulation's second modal state (``η̇``, or ``p_η`` in the momentum form)."""
        return xe[self.n_extra + self.n_modes : self.n_extra + 2 * self.n_modes]

    def modal(self, arrays, p):
        """The :class:`~stationbed.flex.Modes` of the flexible arrays (None for a rigid scene)."""
        from ..flex import Modes

        if not self.flexible:
            return None
        L = self.layout
        modes = Modes(p[L["mtot"]][0])
        for k, _ in self.flexible:
            modes.add(arrays[k][4], arrays[k][1], p[L[f"rho{k}"]], p[L[f"modes{k}"]], wd_p=arrays[k][2])
        return modes.done()

    def velocities(self, H, p_eta, arrays, modal, I, xe, p):
        """``(ω, η̇)`` from the total momentum ``H`` about O and the modal momenta ``p_η``.

        Solves ``[I Δ; Δᵀ M_eff] [ω; η̇] = [H - Σ I_p ω_p - h; p_η - Dᵀ ω_p]`` by the Schur
        complement on the modal block: ``(I - Δ M_eff⁻¹ Δᵀ) ω = ...`` (``M_eff⁻¹`` by
        :meth:`~stationbed.flex.Modes.solve`).
        """
        rest = H - self.h(xe, p)
        for I_p, w_p, *_ in arrays:
            rest = rest - ca.mtimes(I_p, w_p)
        if modal is None:
            return ca.mtimes(inv3(I), rest), ca.SX(0, 1)
        sol = modal.solve(ca.horzcat(p_eta - modal.D_wp, modal.Delta.T))  # M_eff⁻¹ [b, Δᵀ]
        b, MD = sol[:, 0], sol[:, 1:4]
        w = ca.mtimes(inv3(I - ca.mtimes(modal.Delta, MD)), rest - ca.mtimes(modal.Delta, b))
        return w, b - ca.mtimes(MD, w)

    def inertia(self, t, p, arrays):
        """Total inertia about O, B axes, at time t [kg m²]."""
        I = self._mat(p, "I0")
        for a in arrays:
            I = I + a[0]
        return I

    # -- CMG cluster --------------------------------------------------------------------
    def _cmg_x(self, xe):
        return xe[0 : self.cmg.nx]

    def h(self, xe, p):
        """CMG momentum relative to the body, B components [N m s] (0 without a cluster)."""
        if self.cmg is None:
            return ca.SX.zeros(3)
        return self.cmg.h(self._cmg_x(xe), p[self.layout["cmg"]])

    def h_dot(self, xe, u, w, p):
        """Body-frame derivative of the CMG momentum [N m]."""
        if self.cmg is None:
            return ca.SX.zeros(3)
        return self.cmg.h_dot(self._cmg_x(xe), u[3 : 3 + self.nu_cmg], w, p[self.layout["cmg"]])

    def extra_dot(self, t, q, xe, u, w, p):
        """Derivative of the extra states (CMG state, driven joint angles and rates)."""
        parts = []
        if self.cmg is not None:
            parts.append(self.cmg.state_dot(self._cmg_x(xe), u[3 : 3 + self.nu_cmg], w, p[self.layout["cmg"]]))
        if self.driven:
            states = self.joint_states(t, q, xe, p, w, u)
            for k, j, off in self.driven:
                _, rate, acc = states[k][JOINTS.index(j)]
                parts += [rate, acc]
        return ca.vertcat(*parts) if parts else ca.SX(0, 1)

    def orbit_u(self, t, p):
        radius, incl, u0, n = (p[self.layout["orbit"]][i] for i in range(4))
        return u0 + n * t

    def external_torque(self, t, q, u, p, I):
        """Sum of the scene's external torques, B components [N m]; ``u[0:3]`` is the held torque."""
        L = u[0:3]
        s = self.structure
        if s.orbit:
            radius, incl, u0, n, ci, si = (p[self.layout["orbit"]][i] for i in range(6))
            arg = u0 + n * t
            cu, su = ca.cos(arg), ca.sin(arg)
            if s.gravity_gradient:
                R_hat_N = ca.vertcat(cu, su * ci, su * si)  # orbit_position_N(arg, 1, incl)
                R_hat_B = ca.mtimes(dcm(q), R_hat_N)
                L = L + gravity_gradient_torque(R_hat_B, I, n * n)
            if s.harmonic:
                h = p[self.layout["harm"]]
                L = (
                    L
                    + h[0:3]
                    + h[3:6] * cu
                    + h[6:9] * su
                    + h[9:12] * (cu * cu - su * su)  # cos 2u
                    + h[12:15] * (2 * su * cu)  # sin 2u
                )
        return L

    def C_ON(self, t, p):
        radius, incl, u0, n = (p[self.layout["orbit"]][i] for i in range(4))
        return C_ON(u0 + n * t, incl)


class Formulation:
    """Base class of the equations of motion (DESIGN §7).

    Rules for implementers:

    1. Set ``name`` (the registry/scene name), ``core_names`` (seven states: ``qw, qx, qy, qz``,
       the Euler parameters of B relative to N, then one 3-vector) and ``core_kinds``. The
       model's extra states (CMG, driven array joints) follow; the base class integrates them.
       A scene with flexible arrays adds the modal coordinates ``η`` and a second modal state
       (``η̇``; a form may choose another, e.g. the modal momenta, see ``modal_state_prefix``).
    2. Write ``_rhs(t, x, u, p)`` returning ``(d/dt of the seven core states, omega_BN_B)`` as
       casadi columns, using ``self.model`` for inertia, arrays (:meth:`arrays`), CMG momentum
       ``h`` / ``ḣ`` and external torque. ``u`` is held constant by the caller over each
       integration segment: ``u[0:3]`` a body torque [N m], then the CMG input. A form that
       models elastic modes returns a third item, the derivative of the modal states.
    3. Write ``_omega(t, x, p)`` (omega_BN_B from the state) and ``_core(t, q, omega, xe, p)``
       (the 3-vector core state that has rate ``omega`` at time t with extra states ``xe``,
       whose modal part is ``η, η̇``). A form whose second modal state is not ``η̇`` also writes
       ``modal_rates`` and ``_modal_state``.
    4. Do not report energy or momentum yourself: :meth:`H_O_B` and :meth:`kinetic_energy`
       derive them from ``_omega`` so conservation tests are generic over formulations.
    """

    name: ClassVar[str] = ""
    core_names: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""
    #: per core state: "attitude" (dimensionless), "rate" [rad/s] or "momentum" [N m s]; sets the
    #: units in which the scene's dimensionless atol is applied (see :meth:`atol_vector`)
    core_kinds: ClassVar[tuple[str, ...]] = ()
    #: whether omega_BN_B is a state (then an impulsive array-rate step needs a jump, see
    #: :meth:`jump`); the momentum form recovers omega algebraically and needs none
    omega_is_state: ClassVar[bool] = False
    #: state-name prefix of the second modal state (``etadot``: η̇)
    modal_state_prefix: ClassVar[str] = "etadot"

    def __init__(self, model: StationModel):
        self.model = model
        second = tuple(n.replace("eta", self.modal_state_prefix, 1) for n in model.eta_names)
        self.state_names = tuple(self.core_names) + model.extra_names + model.eta_names + second
        self.state_kinds = tuple(self.core_kinds) + model.extra_kinds + ("attitude",) * (2 * model.n_modes)

    @property
    def nx(self) -> int:
        return len(self.state_names)

    # -- helpers for implementers --------------------------------------------------------
    def arrays(self, t, x, p, w=None, u=None):
        return self.model.arrays(t, x[0:4], x[7:], p, w, u)

    def modal_rates(self, t, x, p):
        """``η̇`` from the state (here: the second modal state itself)."""
        return self.model.modal_state(x[7:])

    def physical_extra(self, t, x, p):
        """``x[7:]`` with its second modal state replaced by ``η̇`` (what :meth:`state` takes)."""
        m = self.model
        xe = x[7:]
        if not m.n_modes:
            return xe
        return ca.vertcat(xe[0 : m.n_extra + m.n_modes], self.modal_rates(t, x, p))

    @staticmethod
    def modal_momenta(modal, w, eta_dot):
        """``p_η`` of the flexible arrays (none for a rigid scene)."""
        return ca.SX(0, 1) if modal is None else modal.momentum(w, eta_dot)

    # -- public, checked -----------------------------------------------------------------
    def rhs(self, t, x, u, p):
        out = self._rhs(t, x, u, p)
        core_dot, w = out[0], out[1]
        if core_dot.shape != (7, 1):
            raise ValueError(f"{self.name}: _rhs returned shape {core_dot.shape}, expected (7, 1)")
        parts = [core_dot, self.model.extra_dot(t, x[0:4], x[7:], u, w, p)]
        if self.model.n_modes:
            if len(out) < 3:
                raise ValueError(f"formulation {self.name!r} does not model flexible arrays (elastic modes)")
            parts.append(out[2])
        return ca.vertcat(*parts)

    def omega(self, t, x, p):
        return self._omega(t, x, p)

    def state(self, t, q, omega, xe, p):
        """The state with attitude ``q``, rate ``omega`` and extra states ``xe`` at time ``t``
        (``xe``: the model's extra states, then ``η`` and ``η̇`` of flexible arrays)."""
        m = self.model
        parts = [q, self._core(t, q, omega, xe, p), xe[0 : m.n_extra]]
        if m.n_modes:
            parts += [m.eta(xe), self._modal_state(t, q, omega, xe, p)]
        return ca.vertcat(*parts)

    def _modal_state(self, t, q, omega, xe, p):
        return self.model.modal_state(xe)

    def jump(self, t_minus, t_plus, x, p):
        """State just after an impulsive change of the array rates at ``t``: H is continuous.

        The total momentum (and the modal momenta ``p_η``, whose rate ``-Kη - Cη̇`` is bounded)
        are taken with the arrays at ``t_minus`` and the rates recovered with the arrays at
        ``t_plus``. For the momentum form this is the identity (H and p_η are its states).
        """
        m = self.model
        q, xe = x[0:4], x[7:]
        xp = self.physical_extra(t_minus, x, p)
        w = self._omega(t_minus, x, p)
        H = self.momentum_of(t_minus, q, w, xp, p)
        p_eta = self.modal_momenta(m.modal(m.arrays(t_minus, q, xe, p), p), w, m.modal_state(xp))
        arrays = m.arrays(t_plus, q, xe, p)
        w_plus, eta_dot = m.velocities(H, p_eta, arrays, m.modal(arrays, p), m.inertia(t_plus, p, arrays), xe, p)
        xe_plus = ca.vertcat(xe[0 : m.n_extra + m.n_modes], eta_dot) if m.n_modes else xe
        return self.state(t_plus, q, w_plus, xe_plus, p)

    def atol_vector(self, atol: float, rate_scale: float, momentum_scale: float) -> np.ndarray:
        """Absolute tolerance per state component.

        A scene's ``atol`` is dimensionless: it applies as given to the Euler parameters and,
        for rate or momentum states, in units of the scene's characteristic rate [rad/s] or
        momentum [N m s]. So every formulation controls the same physical accuracy: without this,
        atol = 1e-12 is 1e-12 *relative* on an H state of 1e5 N m s but 1e-9 relative on an
        ω state of 1e-3 rad/s, and the ω-state forms would be a thousand times less accurate.
        """
        unit = {"attitude": 1.0, "rate": rate_scale, "momentum": momentum_scale}
        return np.array([atol * unit[k] for k in self.state_kinds])

    def momentum_of(self, t, q, omega, xe, p):
        """Total angular momentum about O, B components, at rate ``omega``:
        ``I ω + Σ I_p ω_p + h + Σ Δ η̇`` (``xe`` with ``η̇``, as for :meth:`state`)."""
        m = self.model
        arrays = m.arrays(t, q, xe, p)
        H = ca.mtimes(m.inertia(t, p, arrays), omega) + m.h(xe, p)
        for I_p, w_p, *_ in arrays:
            H = H + ca.mtimes(I_p, w_p)
        modal = m.modal(arrays, p)
        if modal is not None:
            H = H + ca.mtimes(modal.Delta, m.modal_state(xe))
        return H

    def H_O_B(self, t, x, p):
        """Total angular momentum about O (CMG momentum included), B components [N m s]."""
        return self.momentum_of(t, x[0:4], self._omega(t, x, p), self.physical_extra(t, x, p), p)

    def H_O_N(self, t, x, p):
        return ca.mtimes(dcm(x[0:4]).T, self.H_O_B(t, x, p))

    def kinetic_energy(self, t, x, p):
        """Kinetic energy about O of the structure (body, arrays and their elastic motion; CMG
        rotors excluded) [J]: :meth:`StationModel.kinetic_energy` at the state's rates."""
        return self.model.kinetic_energy(t, x[0:4], self._omega(t, x, p), self.physical_extra(t, x, p), p)

    def strain_energy(self, t, x, p):
        """Elastic strain energy of the arrays ``½ ηᵀ K η`` [J] (0 for a rigid scene)."""
        m = self.model
        if not m.n_modes:
            return ca.SX(0)
        return m.modal(self.arrays(t, x, p), p).strain(m.eta(x[7:]))

    # -- plug-in -------------------------------------------------------------------------
    def _rhs(self, t, x, u, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _omega(self, t, x, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _core(self, t, q, omega, xe, p):  # pragma: no cover - abstract
        raise NotImplementedError


class OmegaStateForm(Formulation):
    """Base of the forms whose core state is ``[q_BN, omega_BN_B]`` (TP Eq. 16 and Eq. 27).

    Both read ``I ω̇ = L - ω × (I ω + h) - ḣ - Σ_p a_p``; a subclass writes only the array term
    ``a_p = _array_term(ω, I_p, ω_p, ω̇_p)`` (everything an array adds to the left-hand side
    besides its share of ``I ω̇`` and ``ω × I ω``).

    Flexible arrays (the same for both forms: the modal terms are not where they differ) add
    ``Δ η̈ + Δ̇ η̇ + ω × Δ η̇`` to the left-hand side (the rate of ``Δ η̇`` in H), and Lagrange's
    equation of the modes ``M_eff η̈ + Ṁ_eff η̇ + Δᵀ ω̇ + Δ̇ᵀ ω + Dᵀ ω̇_p + C η̇ + K η = 0``; the
    two are solved together by the Schur complement on the modal block (``M_eff⁻¹`` by the
    Woodbury identity, :meth:`stationbed.flex.Modes.solve`).
    """

    core_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    core_kinds = ("attitude",) * 4 + ("rate",) * 3
    omega_is_state = True

    def _omega(self, t, x, p):
        return x[4:7]

    def _core(self, t, q, omega, xe, p):
        return omega

    def _rhs(self, t, x, u, p):
        m = self.model
        w = x[4:7]
        xe = x[7:]
        arrays = self.arrays(t, x, p, w, u)
        I = m.inertia(t, p, arrays)
        h = m.h(xe, p)
        rhs = m.external_torque(t, x[0:4], u, p, I) - ca.cross(w, ca.mtimes(I, w) + h) - m.h_dot(xe, u, w, p)
        for I_p, w_p, wd_p, *_ in arrays:
            rhs = rhs - self._array_term(w, I_p, w_p, wd_p)
        if not m.n_modes:
            return ca.vertcat(quat_kinematics(x[0:4], w), ca.mtimes(inv3(I), rhs)), w
        eta, eta_dot = m.eta(xe), m.modal_state(xe)
        f = m.modal(arrays, p)
        rhs = rhs - ca.mtimes(f.Delta_dot, eta_dot) - ca.cross(w, ca.mtimes(f.Delta, eta_dot))
        r_eta = f.momentum_rate(eta, eta_dot) - ca.mtimes(f.Delta_dot.T, w) - f.D_wdp - f.mass_rate_times(eta_dot)
        sol = f.solve(ca.horzcat(r_eta, f.Delta.T))  # M_eff⁻¹ [r_η, Δᵀ]
        w_dot = ca.mtimes(inv3(I - ca.mtimes(f.Delta, sol[:, 1:4])), rhs - ca.mtimes(f.Delta, sol[:, 0]))
        eta_ddot = sol[:, 0] - ca.mtimes(sol[:, 1:4], w_dot)
        return ca.vertcat(quat_kinematics(x[0:4], w), w_dot), w, ca.vertcat(eta_dot, eta_ddot)

    def _array_term(self, w, I_p, w_p, wd_p):  # pragma: no cover - abstract
        raise NotImplementedError


__all__ += ["OmegaStateForm", "coriolis_matrix", "JOINTS"]
