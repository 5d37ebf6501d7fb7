"""The station model in casadi expressions (:class:`StationModel`).

:class:`StationModel` turns a scene's *structure* (how many arrays, orbit or not, which torques)
into symbolic quantities at time ``t``: the total inertia about the composite mass centre O,
each array's ``I_p_B``, ``omega_p_B``, ``omega_p_dot_B`` (:class:`ArrayState`), the CMG
cluster's momentum and the external torque. Numbers (mass properties, profiles, orbit) enter
through one parameter vector ``p`` whose layout is declared once in
:class:`~stationbed.model.structure.ParamLayout`, so one compiled function serves every scene of
the same structure. Only the effects a scene names are built ("model no more than a scene
needs").

Conventions of the symbolic methods: ``t`` time [s]; ``q_BN`` (4, 1) Euler parameters of B
relative to N, scalar first; ``omega_BN_B`` (3, 1) body rate [rad/s]; ``xe`` the extra states
(``x[7:]``: CMG state, driven joints, then the modal states); ``u`` (nu, 1) the held input;
``p`` (layout.size, 1) the parameter vector. All return casadi SX.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from ..core.layout import Layout
from ..core.linalg import inv3
from ..core.massprops import parallel_axis
from ..core.rotation import dcm
from ..scene.docking import docked_parts, mass_centre_B
from .appendages import drive_acceleration, drive_from_error, glider_error, joint_kinematics, profile, sun_targets
from .cmg import CmgModel
from .environment import sun_direction_N
from .flex import Modes
from .orbit import OrbitAt, orbit_at, orbit_params, orbit_plane
from .structure import JOINTS, ParamLayout, Structure
from .sun import SHADOW_MODELS, sun_distance_m
from .surfaces import plates_B, surface_origin_params
from .torques import TORQUES, Environment, v_rel_B

__all__ = ["StationModel", "ArrayState"]


class ArrayState(NamedTuple):
    """One articulated array at time t (casadi SX).

    Unpacks as a tuple: ``for I_p_B, omega_p_B, *_ in arrays``.
    """

    #: inertia about its own mass centre, B axes [kg m²], (3, 3)
    I_p_B: Any
    #: rate of the array relative to B, B components [rad/s], (3, 1)
    omega_p_B: Any
    #: B-frame derivative of omega_p_B [rad/s²], (3, 1); None when not computed
    omega_p_dot_B: Any
    #: joint angles (alpha, beta) [rad]
    angles: tuple
    #: DCM from B to the array frame P, (3, 3)
    C_PB: Any
    #: inertia about its own mass centre, P axes [kg m²], (3, 3)
    J_p_P: Any
    #: rate of P relative to B, P components [rad/s], (3, 1)
    omega_PB_P: Any


class StationModel:
    """Symbolic station quantities for one :class:`~stationbed.model.structure.Structure`.

    Besides the formulation's own seven states (q_BN and one 3-vector), a scene may add
    *extra states*, owned here and appended after them: the CMG cluster's (``h`` or the gimbal
    angles) and, per sun-tracking joint, its angle and rate; flexible arrays add the modal
    states after those. The held input ``u`` is the held external body torque (3) followed by
    the CMG input (torque command or gimbal rates) and, with array rate steps, the segment's
    mid time.

    Parameters
    ----------
    structure : Structure  What the equations contain.
    """

    def __init__(self, structure: Structure):
        self.structure = structure
        self.cmg = None if structure.cmg is None else CmgModel(*structure.cmg)
        #: the symbolic external-torque kinds, in registry (= equation) order
        self.torques = tuple(TORQUES[k] for k in structure.torques)
        self.layout = ParamLayout(structure)
        names, kinds = [], []
        if self.cmg is not None:
            names += list(self.cmg.state_names)
            kinds += list(self.cmg.state_kinds)
        self.driven = []  # (appendage index, joint name, offset of its angle in the extra states)
        for k in range(structure.n_app):
            for j, (kind, _) in zip(JOINTS, structure.joints[k]):
                if kind in ("s", "g"):
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
        #: the held input ``u`` by name (its indices are owned here): ``u_ext`` the external
        #: torque held over a segment (B, N m), ``u_cmg`` the CMG cluster's held input (its
        #: actuator's command), ``t_step`` the segment's mid time (only with rate steps)
        self.input_layout = Layout(u_ext=3, **({"u_cmg": self.nu_cmg} if self.nu_cmg else {}),
                                   **({"t_step": 1} if self.has_steps else {}))
        #: whether a torque kind reads the arrays and the sun (external_torque needs ``arrays``)
        self.needs_arrays = any(k.needs_env for k in self.torques)

    # -- numbers ------------------------------------------------------------------------
    def params(self, scene) -> np.ndarray:
        """The numeric parameter vector of ``scene``, shape (layout.size,) (composite mass centre
        computed here)."""

        L = self.layout
        p = np.zeros(L.size)
        masses = [scene.body.mass] + [a.mass for a in scene.appendage]
        vehicles = docked_parts(scene)  # issue 35: docked vehicles are rigid parts of the body
        r_O = mass_centre_B(scene)
        I0 = np.array(scene.body.inertia) + parallel_axis(scene.body.mass, np.array(scene.body.cm) - r_O)
        for m_v, r_v, I_v in vehicles:
            I0 += I_v + parallel_axis(m_v, r_v - r_O)
        for k, a in enumerate(scene.appendage):
            I0 += parallel_axis(a.mass, np.array(a.cm) - r_O)
            p[L[f"J{k}"]] = a.inertia_P.ravel()
            for j in JOINTS:
                jt = getattr(a, j)
                if jt.tracked:
                    p[L[f"{j}{k}"]] = [jt.max_rate, jt.max_acc, jt.gain, jt.rate_tau]
                else:
                    steps = [v for st in jt.rate_step for v in (st.t, st.delta)]
                    p[L[f"{j}{k}"]] = jt.coeffs() + steps
        p[L["I0"]] = I0.ravel()
        if self.structure.orbit:
            p[L["orbit"]] = orbit_params(scene.orbit)
        for kind in self.torques:
            if kind.n_par:
                p[L[kind.kind]] = kind.params(scene)
        if self.structure.sun:
            p[L["sun"]] = sun_direction_N(scene.sun, *orbit_plane(scene.orbit))
        if self.structure.surfaces:
            p[L["surf_O"]] = surface_origin_params(scene)
        if self.structure.eclipse:
            p[L["shadow"]] = sun_distance_m(scene.sun)
        if self.cmg is not None:
            p[L["cmg"]] = self.cmg.params(scene.cmg)
        if self.flexible:
            p[L["mtot"]] = sum(masses) + sum(m for m, _, _ in vehicles)
        for k, _ in self.flexible:
            a = scene.appendage[k]
            p[L[f"rho{k}"]] = np.array(a.cm) - r_O
            vals = []
            for mode in a.mode:
                phi_bar, H_hat, M = mode.integrals(a.mass)
                w = mode.omega
                dJ = mode.inertia_derivative_P(a.mass)
                vals += list(phi_bar) + list(H_hat) + [M, w * w * M, 2.0 * mode.damping * w * M]
                vals += [dJ[0, 0], dJ[1, 1], dJ[2, 2], dJ[0, 1], dJ[0, 2], dJ[1, 2]]
            p[L[f"modes{k}"]] = vals
        return p

    def initial_extra(self, scene, q_BN, p) -> np.ndarray:
        """Extra states at t = 0 (CMG state; driven joints start on target unless ``a0`` is given),
        then the modal coordinates and rates ``η, η̇`` (the formulation converts η̇ to its state).

        Parameters
        ----------
        scene : Scene
        q_BN : array_like, shape (4,)  Initial attitude (Euler parameters, scalar first).
        p : ndarray, shape (layout.size,)  :meth:`params` of the scene.

        Returns
        -------
        ndarray, shape (n_extra + 2 n_modes,)
        """
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
                alpha = xe[off - 2] if (j == "beta" and self.structure.joints[k][0][0] in ("s", "g")) else None
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

    def sun_B(self, q_BN, p):
        """Unit vector to the sun, B components, (3, 1)."""
        return ca.mtimes(dcm(q_BN), p[self.layout["sun"]])

    def _driven_targets(self, k, q_BN, xe, p, omega_BN_B, alpha, alpha_rate):
        """Sun-tracking targets of array k and their rates (analytic, ṡ_B = -ω × s_B)."""
        s_B = self.sun_B(q_BN, p)
        s_dot_B = -ca.cross(omega_BN_B, s_B)
        den_a = ca.fmax(s_B[0] ** 2 + s_B[2] ** 2, 1e-12)
        a_star_rate = (s_B[2] * s_dot_B[0] - s_B[0] * s_dot_B[2]) / den_a
        ca_, sa_ = ca.cos(alpha), ca.sin(alpha)
        v = ca.vertcat(ca_ * s_B[0] - sa_ * s_B[2], s_B[1], sa_ * s_B[0] + ca_ * s_B[2])
        vd = ca.vertcat(
            (-sa_ * s_B[0] - ca_ * s_B[2]) * alpha_rate + ca_ * s_dot_B[0] - sa_ * s_dot_B[2],
            s_dot_B[1],
            (ca_ * s_B[0] - sa_ * s_B[2]) * alpha_rate + sa_ * s_dot_B[0] + ca_ * s_dot_B[2],
        )
        b_star_rate = (-v[2] * vd[1] + v[1] * vd[2]) / ca.fmax(v[1] ** 2 + v[2] ** 2, 1e-12)
        # targets as (Y, X) with θ* = atan2(Y, X): the drive wraps the error with one atan2
        return ((s_B[0], s_B[2]), a_star_rate), ((-v[1], v[2]), b_star_rate)

    def t_switch(self, u):
        """The time that decides which side of a rate step a stage is on (None: t itself)."""
        return u[self.nu - 1] if (self.has_steps and u is not None) else None

    def joint_states(self, t, q_BN, xe, p, omega_BN_B=None, u=None):
        """The driven (sun-tracking) joints' states.

        Parameters
        ----------
        t, q_BN, xe, p, u : see the module docstring.
        omega_BN_B : casadi SX, shape (3, 1), optional  Body rate [rad/s]; needed for the
            accelerations (the target moves with the body).

        Returns
        -------
        list  Per array ``[alpha, beta]``, each ``[angle [rad], rate [rad/s], accel [rad/s²] or
        None]`` for a driven joint, None for a profile joint.
        """
        out = [[None, None] for _ in range(self.structure.n_app)]
        for k, j, off in self.driven:
            out[k][JOINTS.index(j)] = [xe[off], xe[off + 1], None]
        if omega_BN_B is not None:
            for k in {k for k, _, _ in self.driven}:
                ja, jb = out[k]
                if ja is None:
                    c = p[self.layout[f"alpha{k}"]]
                    alpha, alpha_rate, _ = profile(t, c, self.structure.joints[k][0][1], self.t_switch(u))
                else:
                    alpha, alpha_rate = ja[0], ja[1]
                targets = self._driven_targets(k, q_BN, xe, p, omega_BN_B, alpha, alpha_rate)
                for i, js in enumerate(out[k]):
                    if js is None:
                        continue
                    drive = p[self.layout[f"{JOINTS[i]}{k}"]]
                    if self.structure.joints[k][i][0] == "g":
                        js[2] = self._glider_acceleration(t, q_BN, p, i, alpha, js, targets[i], drive)
                    else:
                        js[2] = drive_acceleration(js[0], js[1], *targets[i], drive)
        return out

    def _glider_acceleration(self, t, q_BN, p, i, alpha, js, target, drive):
        """Drive law of a night-glider joint: the sun target while lit (ν >= 1/2), edge-on to the
        flow in eclipse (array normal perpendicular to the air-relative velocity, the nearer of
        the two such angles, no rate feed-forward: the flow is fixed in an LVLH-holding body)."""
        orbit = self.orbit_at(t, p)
        v_B = v_rel_B(dcm(q_BN), orbit)
        if i == 1:  # BGA: the flow in the frame turned by the SARJ, Ay(alpha) v_B
            ca_, sa_ = ca.cos(alpha), ca.sin(alpha)
            v_B = ca.vertcat(ca_ * v_B[0] - sa_ * v_B[2], v_B[1], sa_ * v_B[0] + ca_ * v_B[2])
        (Y, X), rate_sun = target
        c, s = ca.cos(js[0]), ca.sin(js[0])
        err_sun = ca.atan2(Y * c - X * s, X * c + Y * s)
        err_night = glider_error(js[0], v_B, i)
        dark = self.shadow(orbit, p) < 0.5
        return drive_from_error(ca.if_else(dark, err_night, err_sun), js[1], ca.if_else(dark, 0.0, rate_sun), drive)

    def arrays(self, t, q_BN, xe, p, omega_BN_B=None, u=None) -> list[ArrayState]:
        """Per array its :class:`ArrayState` at time t.

        Parameters
        ----------
        t, q_BN, xe, p, u : see the module docstring.
        omega_BN_B : casadi SX, shape (3, 1), optional  Body rate [rad/s].

        Returns
        -------
        list of ArrayState  One per appendage, in scene order.

        Notes
        -----
        ``omega_p_dot_B`` of a sun-tracking array needs ``omega_BN_B`` (its drive follows a target
        that moves with the body); without it that entry is None. ``u`` (the held input) places
        rate steps by the segment time (see :meth:`t_switch`); without it a step is
        right-continuous in t.
        """
        states = self.joint_states(t, q_BN, xe, p, omega_BN_B, u)
        out = []
        for k in range(self.structure.n_app):
            J_p_P = self._mat(p, f"J{k}")
            (_, na), (_, nb) = self.structure.joints[k]
            C_PB, omega_PB_P, omega_PB_P_dot, angles = joint_kinematics(
                t, p[self.layout[f"alpha{k}"]], p[self.layout[f"beta{k}"]], (na, nb), tuple(states[k]), self.t_switch(u)
            )
            C_BP = C_PB.T
            I_p_B = ca.mtimes([C_BP, J_p_P, C_PB])
            omega_p_dot_B = None if omega_PB_P_dot is None else ca.mtimes(C_BP, omega_PB_P_dot)
            out.append(ArrayState(I_p_B, ca.mtimes(C_BP, omega_PB_P), omega_p_dot_B, angles, C_PB, J_p_P, omega_PB_P))
        return out

    def kinetic_energy(self, t, q_BN, omega_BN_B, xe, p, u=None, h_coupling=False):
        """Kinetic energy of the structure about O [J] at body rate ``omega_BN_B`` [rad/s], (3, 1).

        Parameters
        ----------
        t, q_BN, xe, p, u : see the module docstring (``xe`` with ``η̇``).
        omega_BN_B : casadi SX, shape (3, 1)  Body rate [rad/s].
        h_coupling : bool  Add ``ωᵀh`` (see below).

        Notes
        -----
        ``T = ½ωᵀIω + Σ (ωᵀI_pω_p + ½ω_pᵀI_pω_p) + T_e``; ``xe`` with ``η̇`` (as for
        :meth:`Formulation.state`); ``T_e`` the arrays' elastic kinetic energy
        (:meth:`stationbed.model.flex.Modes.kinetic`) plus the first-order deformation-dependent
        inertia's ``T₁`` (:meth:`~stationbed.model.flex.Modes.first_order_kinetic`).
        ``h_coupling`` adds ``ωᵀh``, the only part of the CMG rotors' energy that depends on ω
        (what the ``hamel`` form differentiates).
        """
        arrays = self.arrays(t, q_BN, xe, p, u=u)
        T = 0.5 * ca.dot(omega_BN_B, ca.mtimes(self.inertia(t, p, arrays), omega_BN_B))
        if h_coupling:
            T = T + ca.dot(omega_BN_B, self.h(xe, p))
        for I_p_B, omega_p_B, *_ in arrays:
            T = T + ca.dot(omega_BN_B, ca.mtimes(I_p_B, omega_p_B)) + 0.5 * ca.dot(omega_p_B, ca.mtimes(I_p_B, omega_p_B))
        modal = self.modal(arrays, p)
        if modal is not None:
            T = T + modal.kinetic(omega_BN_B, self.modal_state(xe)) + modal.first_order_kinetic(self.eta(xe), omega_BN_B)
        return T

    # -- flexible arrays ----------------------------------------------------------------
    def eta(self, xe):
        """The modal coordinates ``η`` (n_modes, 1) from the extra states ``xe`` (= x[7:])."""
        return xe[self.n_extra : self.n_extra + self.n_modes]

    def modal_state(self, xe):
        """The formulation's second modal state (``η̇``, or ``p_η`` in the momentum form)."""
        return xe[self.n_extra + self.n_modes : self.n_extra + 2 * self.n_modes]

    def modal(self, arrays, p):
        """The :class:`~stationbed.model.flex.Modes` of the flexible arrays (None for a rigid scene)."""
        if not self.flexible:
            return None
        L = self.layout
        modes = Modes(p[L["mtot"]][0])
        for k, _ in self.flexible:
            a = arrays[k]
            modes.add(a.C_PB, a.omega_p_B, p[L[f"rho{k}"]], p[L[f"modes{k}"]], wd_p=a.omega_p_dot_B)
        return modes.done()

    def velocities(self, H_O_B, p_eta, arrays, modal, I_O_B, xe, p):
        """``(omega_BN_B, η̇)`` from the total momentum about O and the modal momenta.

        Parameters
        ----------
        H_O_B : casadi SX, shape (3, 1)  Total angular momentum about O, B components [N m s].
        p_eta : casadi SX, shape (n_modes, 1)  Modal momenta ``p_η``.
        arrays : list of ArrayState  :meth:`arrays` at the same time.
        modal : Modes or None  :meth:`modal` of ``arrays``.
        I_O_B : casadi SX, shape (3, 3)  :meth:`inertia` [kg m²].
        xe, p : see the module docstring.

        Returns
        -------
        omega_BN_B : casadi SX, shape (3, 1)  [rad/s]
        eta_dot : casadi SX, shape (n_modes, 1)

        Notes
        -----
        Solves ``[I + δI Δ; Δᵀ M_eff] [ω; η̇] = [H - Σ I_p ω_p - h - h₁; p_η - Dᵀ ω_p]`` by the
        Schur complement on the modal block: ``(I + δI - Δ M_eff⁻¹ Δᵀ) ω = ...`` (``M_eff⁻¹`` by
        :meth:`~stationbed.model.flex.Modes.solve`; ``δI``, ``h₁`` the first-order inertia terms at
        ``η``: :meth:`~stationbed.model.flex.Modes.inertia_delta`, ``joint_momentum``).
        """
        rest = H_O_B - self.h(xe, p)
        for I_p_B, omega_p_B, *_ in arrays:
            rest = rest - ca.mtimes(I_p_B, omega_p_B)
        if modal is None:
            return ca.mtimes(inv3(I_O_B), rest), ca.SX(0, 1)
        eta = self.eta(xe)
        rest = rest - modal.joint_momentum(eta)
        sol = modal.solve(ca.horzcat(p_eta - modal.D_wp, modal.Delta.T))  # M_eff⁻¹ [b, Δᵀ]
        b, MD = sol[:, 0], sol[:, 1:4]
        I_eff = I_O_B + modal.inertia_delta(eta) - ca.mtimes(modal.Delta, MD)
        omega_BN_B = ca.mtimes(inv3(I_eff), rest - ca.mtimes(modal.Delta, b))
        return omega_BN_B, b - ca.mtimes(MD, omega_BN_B)

    def inertia(self, t, p, arrays):
        """Total inertia about O, B axes, at time t: ``I0 + Σ I_p_B`` [kg m²], (3, 3).

        Parameters
        ----------
        t, p : see the module docstring.
        arrays : list of ArrayState  :meth:`arrays` at time t.
        """
        I_O_B = self._mat(p, "I0")
        for a in arrays:
            I_O_B = I_O_B + a.I_p_B
        return I_O_B

    # -- CMG cluster --------------------------------------------------------------------
    def _cmg_x(self, xe):
        return xe[0 : self.cmg.nx]

    def h(self, xe, p):
        """CMG momentum relative to the body, ``h_B``, B components [N m s], (3, 1) (0 without a
        cluster), from the extra states ``xe`` and ``p``."""
        if self.cmg is None:
            return ca.SX.zeros(3)
        return self.cmg.h(self._cmg_x(xe), p[self.layout["cmg"]])

    def h_dot(self, xe, u, omega_BN_B, p):
        """Body-frame derivative of the CMG momentum [N m], (3, 1) (0 without a cluster), with the
        held input ``u`` at body rate ``omega_BN_B`` [rad/s]."""
        if self.cmg is None:
            return ca.SX.zeros(3)
        return self.cmg.h_dot(self._cmg_x(xe), u[3 : 3 + self.nu_cmg], omega_BN_B, p[self.layout["cmg"]])

    def extra_dot(self, t, q_BN, xe, u, omega_BN_B, p):
        """Derivative of the extra states (CMG state, driven joint angles and rates), (n_extra, 1)."""
        parts = []
        if self.cmg is not None:
            parts.append(self.cmg.state_dot(self._cmg_x(xe), u[3 : 3 + self.nu_cmg], omega_BN_B, p[self.layout["cmg"]]))
        if self.driven:
            states = self.joint_states(t, q_BN, xe, p, omega_BN_B, u)
            for k, j, off in self.driven:
                _, rate, acc = states[k][JOINTS.index(j)]
                parts += [rate, acc]
        return ca.vertcat(*parts) if parts else ca.SX(0, 1)

    # -- orbit and external torque ------------------------------------------------------
    def orbit_at(self, t, p) -> OrbitAt:
        """The orbit at time t (:func:`stationbed.model.orbit.orbit_at`: position, velocity, LVLH)."""
        return orbit_at(t, p[self.layout["orbit"]], self.structure.orbit_kind)

    def shadow(self, orbit, p):
        """Fraction of the sun's disc seen at the station, ν (casadi; 1 without an eclipse model)."""
        if not self.structure.eclipse:
            return ca.SX(1.0)
        return SHADOW_MODELS[self.structure.eclipse](orbit.r_N, p[self.layout["sun"]], p[self.layout["shadow"]][0])

    def environment(self, q_BN, orbit, p, arrays) -> Environment:
        """The :class:`~stationbed.model.torques.Environment` of the kinds with ``needs_env``."""
        sun_N = p[self.layout["sun"]] if self.structure.sun else None
        nu = self.shadow(orbit, p) if orbit is not None else ca.SX(1.0)
        return Environment(arrays, sun_N, nu, dcm(q_BN), plates_B(self.structure.surfaces, arrays, p[self.layout["surf_O"]] if self.structure.surfaces else None))

    def external_torque(self, t, q_BN, u, p, I_O_B, with_potential=True, arrays=None):
        """Sum of the scene's external torques, B components [N m], (3, 1).

        Parameters
        ----------
        t, q_BN, u, p : see the module docstring.
        I_O_B : casadi SX, shape (3, 3)  Total inertia about O, B axes [kg m²] (gravity gradient).
        with_potential : bool  Include the conservative kinds.
        arrays : list of ArrayState, optional  The arrays at t; needed when a kind reads them
            (:attr:`needs_arrays`: surfaces that turn with the arrays).

        Notes
        -----
        ``u[0:3]`` is the held torque; then each symbolic kind's terms are added in registry order
        (:mod:`stationbed.model.torques`). ``with_potential=False`` leaves out the conservative
        kinds (the energy-based form takes them from their potential).
        """
        L_B = u[0:3]
        orbit = self.orbit_at(t, p) if self.structure.orbit else None
        env = None
        if self.needs_arrays:
            if arrays is None:
                raise ValueError("external_torque: the scene's surfaces need the arrays at t")
            env = self.environment(q_BN, orbit, p, arrays)
        for kind in self.torques:
            if with_potential or not kind.conservative:
                p_k = p[self.layout[kind.kind]] if kind.n_par else None
                for term in kind.terms_B(t, q_BN, I_O_B, p_k, orbit, env):
                    L_B = L_B + term
        return L_B

    def environment_outputs(self, t, q_BN, xe, p) -> list:
        """``(name, casadi)`` pairs for the trajectory: each kind's torque with an ``output`` stem
        (B components [N m]; gravity gradient with the rigid total inertia about O, :meth:`inertia`)
        and, with an eclipse model, the shadow fraction ``eclipse``."""
        outs = []
        orbit = self.orbit_at(t, p) if self.structure.orbit else None
        shown = [k for k in self.torques if k.output]
        if shown:
            arrays = self.arrays(t, q_BN, xe, p)
            env = self.environment(q_BN, orbit, p, arrays) if self.needs_arrays else None
            I_O_B = self.inertia(t, p, arrays)  # the rigid total about O (gravity gradient)
            for kind in shown:
                p_k = p[self.layout[kind.kind]] if kind.n_par else None
                outs.append((kind.output, kind.torque_B(t, q_BN, I_O_B, p_k, orbit, env)))
        if self.structure.eclipse:
            outs.append(("eclipse", self.shadow(orbit, p)))
        return outs

    def potential(self, t, C_BN, I_O_B, p):
        """Potential energy of the conservative torque kinds [J] (0 when none).

        Parameters
        ----------
        t, p : see the module docstring.
        C_BN : casadi SX, shape (3, 3)  Attitude, DCM from N to B.
        I_O_B : casadi SX, shape (3, 3)  Total inertia about O, B axes [kg m²].
        """
        V = ca.SX(0)
        orbit = self.orbit_at(t, p) if self.structure.orbit else None
        for kind in self.torques:
            if kind.conservative:
                V = V + kind.potential_J(C_BN, I_O_B, orbit)
        return V

    def C_ON(self, t, p):
        """DCM from N to LVLH at time t, (3, 3)."""
        return self.orbit_at(t, p).C_ON
