"""The station model in casadi expressions (:class:`StationModel`).

:class:`StationModel` turns a scene's *structure* (how many arrays, orbit or not, which torques)
into symbolic quantities at time ``t``: the total inertia about the composite mass centre O,
each array's ``I_p``, ``omega_p``, ``omega_p_dot`` in B, and the external torque. Numbers
(mass properties, profiles, orbit) enter through one parameter vector ``p`` whose layout is
declared once in :class:`~stationbed.model.structure.ParamLayout`, so one compiled function
serves every scene of the same structure. Only the effects a scene names are built ("model no
more than a scene needs").
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..core.linalg import inv3
from ..core.massprops import composite_cm, parallel_axis
from ..core.rotation import dcm
from .appendages import drive_acceleration, joint_kinematics, profile, sun_targets
from .cmg import CmgModel
from .environment import C_ON, gravity_gradient_torque, sun_direction_N
from .flex import Modes
from ..scene import HarmonicTorque
from .structure import JOINTS, ParamLayout, Structure

__all__ = ["StationModel"]


class StationModel:
    """Symbolic station quantities for one :class:`Structure`.

    Besides the formulation's own seven states (q_BN and one 3-vector), a scene may add
    *extra states*, owned here and appended after them: the CMG cluster's (``h`` or the gimbal
    angles) and, per sun-tracking joint, its angle and rate. The held input ``u`` is the
    external body torque (3) followed by the CMG input (torque command or gimbal rates).
    """

    def __init__(self, structure: Structure):
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
