"""``hamel``: Quinn's Boltzmann–Hamel equation (seed 000, Eq. 20) from energies, by casadi AD.

The user-facing model is two scalars, written as casadi expressions:

``T(ω, C, t, xe) = ½ ωᵀ I ω + Σ_p (ωᵀ I_p ω_p + ½ ω_pᵀ I_p ω_p) + ωᵀ h``

(body and arrays about O; ``h`` the CMG momentum relative to the body; the rotor-only energy
does not depend on ω or C and drops out), and the gravity-gradient potential of a point-mass
Earth on a circular orbit (Quinn Eq. 27–28 with ``I = tr(J) E - J``, constants dropped),

``V(C) = (3/2) n² R̂_Nᵀ C_BNᵀ I C_BN R̂_N``,  ``n² = μ/|R|³``.

The rotation obeys Quinn Eq. 20 (his tilde is the transpose of :func:`skew`, so
``ω̃ᵀ p = ω × p``)::

    d/dt(∂T/∂ω) + ω × ∂T/∂ω - ∂T/∂C + ∂V/∂C = M

with ``∂f/∂C`` the orientation gradient of DESIGN §4: ``δf = gᵀ δθ`` for
``δC_BN = -skew(δθ) C_BN``; computed here by AD of ``f((E - skew(θ)) C_BN)`` at ``θ = 0``
(for ``f = bᵀ C n`` it is ``b × (C n)``, Quinn Eq. 13–19). Since ``Ċ_BN = -skew(ω) C_BN``,
``δθ = ω dt`` along the motion, and the total derivative of ``p = ∂T/∂ω`` is

``ṗ = (∂p/∂ω) ω̇ + ∂p/∂t + (∂p/∂xe) ẋe + (∂p/∂θ) ω``,

``ẋe`` being the model's extra-state dynamics (CMG state, driven joints), which never depend on
ω̇. ``∂p/∂ω = ∂²T/∂ω²`` is the inertia about O, so

``ω̇ = (∂²T/∂ω²)⁻¹ [M - ω × p + ∂T/∂C - ∂V/∂C - ∂p/∂t - (∂p/∂xe) ẋe - (∂p/∂θ) ω]``.

``M`` is every external torque of the scene *except* gravity gradient, which enters only
through ``V``: the model's torque is taken from a twin model whose structure has
``gravity_gradient=False`` (same parameter layout). State ``[q_BN (4), omega_BN_B (3)]``.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from ..rotation import dcm, quat_kinematics, skew
from .base import Formulation, StationModel, inv3


def orientation_gradient(f, C, theta):
    """``∂f/∂C`` (DESIGN §4) of ``f`` built on ``(E - skew(θ)) C``: AD in θ, at θ = 0.

    ``f`` must be a casadi expression of ``theta`` (an SX symbol, 3); returns the 3-vector
    expression still containing ``theta`` (substitute 0 by the caller).
    """
    return ca.gradient(f, theta)


def perturbed(C, theta):
    """``(E - skew(θ)) C``: the attitude matrix after a small rotation ``θ`` (B components)."""
    return ca.mtimes(ca.SX.eye(3) - skew(theta), C)


class HamelForm(Formulation):
    name = "hamel"
    core_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    core_kinds = ("attitude",) * 4 + ("rate",) * 3
    description = "Quinn 1990 Eq. 20: Boltzmann-Hamel form, equations by AD of T and V"
    omega_is_state = True

    def __init__(self, model: StationModel):
        super().__init__(model)
        s = model.structure
        # every external torque but gravity gradient (which V carries); same parameter layout
        self._torque_model = model
        if s.gravity_gradient:
            self._torque_model = StationModel(dataclasses.replace(s, gravity_gradient=False))
            assert self._torque_model.layout.slices == model.layout.slices
        self._terms = self._build_terms()

    # -- the user-facing energies ---------------------------------------------------------
    def kinetic(self, t, q, C, w, xe, p, u=None):
        """``T(ω, C, t, xe)`` [J] (array kinematics without ω do not depend on q or C)."""
        m = self.model
        arrays = m.arrays(t, q, xe, p, u=u)
        I = m.inertia(t, p, arrays)
        T = 0.5 * ca.dot(w, ca.mtimes(I, w)) + ca.dot(w, m.h(xe, p))
        for I_p, w_p, *_ in arrays:
            T = T + ca.dot(w, ca.mtimes(I_p, w_p)) + 0.5 * ca.dot(w_p, ca.mtimes(I_p, w_p))
        return T

    def potential(self, t, q, C, xe, p, u=None):
        """Gravity-gradient potential ``(3/2) n² R̂_Bᵀ I R̂_B``, ``R̂_B = C R̂_N`` [J] (0 off orbit)."""
        m = self.model
        if not m.structure.gravity_gradient:
            return ca.SX(0)
        radius, incl, u0, n, ci, si = (p[m.layout["orbit"]][i] for i in range(6))
        arg = u0 + n * t
        R_hat_N = ca.vertcat(ca.cos(arg), ca.sin(arg) * ci, ca.sin(arg) * si)
        R_hat_B = ca.mtimes(C, R_hat_N)
        I = m.inertia(t, p, m.arrays(t, q, xe, p, u=u))
        return 1.5 * n * n * ca.dot(R_hat_B, ca.mtimes(I, R_hat_B))

    # -- equations by AD ----------------------------------------------------------------
    def _build_terms(self) -> ca.Function:
        """The partials of T and V as one SX Function (inlined into the RHS when called)."""
        m = self.model
        w = ca.SX.sym("w", 3)
        t = ca.SX.sym("t")
        q = ca.SX.sym("q", 4)
        Cs = ca.SX.sym("C", 3, 3)
        xe = ca.SX.sym("xe", len(m.extra_names))
        p = ca.SX.sym("p", m.layout.size)
        u = ca.SX.sym("u", m.nu)
        theta = ca.SX.sym("theta", 3)
        C = perturbed(Cs, theta)
        T = self.kinetic(t, q, C, w, xe, p, u)
        V = self.potential(t, q, C, xe, p, u)
        mom = ca.gradient(T, w)  # p = ∂T/∂ω
        outs = [
            mom,
            ca.jacobian(mom, w),  # ∂²T/∂ω²: the inertia about O
            ca.jacobian(mom, t),
            ca.jacobian(mom, xe),
            ca.jacobian(mom, theta),
            orientation_gradient(T, Cs, theta),
            orientation_gradient(V, Cs, theta),
        ]
        f = ca.Function("hamel_terms", [w, t, q, Cs, xe, p, u, theta], outs)
        return f

    def terms(self, t, q, w, xe, p, u):
        """``(p, ∂p/∂ω, ∂p/∂t, ∂p/∂xe, ∂p/∂θ, ∂T/∂C, ∂V/∂C)`` at the state, θ = 0."""
        u = np.zeros(self.model.nu) if u is None else u
        return self._terms(w, t, q, dcm(q), xe, p, u, np.zeros(3))

    def _rhs(self, t, x, u, p):
        m = self.model
        q, w, xe = x[0:4], x[4:7], x[7:]
        mom, I, dp_dt, dp_dxe, dp_dth, gT, gV = self.terms(t, q, w, xe, p, u)
        xe_dot = m.extra_dot(t, q, xe, u, w, p)
        M = self._torque_model.external_torque(t, q, u, p, I)
        rhs = M - ca.cross(w, mom) + gT - gV - dp_dt - ca.mtimes(dp_dxe, xe_dot) - ca.mtimes(dp_dth, w)
        return ca.vertcat(quat_kinematics(q, w), ca.mtimes(inv3(I), rhs)), w

    def _omega(self, t, x, p):
        return x[4:7]

    def _core(self, t, q, omega, xe, p):
        return omega
