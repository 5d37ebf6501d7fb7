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
    """What a scene's equations contain; two scenes with equal structure share compiled code."""

    n_app: int
    orbit: bool
    gravity_gradient: bool
    harmonic: bool

    @classmethod
    def of(cls, scene) -> "Structure":
        from ..scene import HarmonicTorque

        return cls(
            n_app=len(scene.appendage),
            orbit=scene.orbit is not None,
            gravity_gradient=scene.orbit is not None and scene.orbit.gravity_gradient,
            harmonic=any(isinstance(t, HarmonicTorque) for t in scene.torque),
        )

    @property
    def key(self) -> str:
        return f"a{self.n_app}o{int(self.orbit)}g{int(self.gravity_gradient)}h{int(self.harmonic)}"


class ParamLayout:
    """Names and slices of the parameter vector ``p`` (declared once, owns the indices)."""

    def __init__(self, structure: Structure):
        self.slices: dict[str, slice] = {}
        n = 0

        def add(name, size):
            nonlocal n
            self.slices[name] = slice(n, n + size)
            n += size

        add("I0", 9)  # hub + all parallel-axis terms, about O, B axes [kg m²]
        for k in range(structure.n_app):
            add(f"J{k}", 9)  # array inertia about its own mass centre, P axes [kg m²]
            add(f"alpha{k}", 5)  # profile coefficients (a0, rate, amp, freq, phase)
            add(f"beta{k}", 5)
        if structure.orbit:
            add("orbit", 4)  # radius [m], inclination [rad], u0 [rad], n [rad/s]
        if structure.harmonic:
            add("harm", 15)  # bias, cos1, sin1, cos2, sin2 (B, N m), summed over torques
        self.size = n

    def __getitem__(self, name) -> slice:
        return self.slices[name]


class StationModel:
    """Symbolic station quantities for one :class:`Structure`."""

    def __init__(self, structure: Structure):
        self.structure = structure
        self.layout = ParamLayout(structure)

    # -- numbers ------------------------------------------------------------------------
    def params(self, scene) -> np.ndarray:
        """The numeric parameter vector of ``scene`` (composite mass centre computed here)."""
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
            p[L[f"alpha{k}"]] = a.alpha.coeffs()
            p[L[f"beta{k}"]] = a.beta.coeffs()
        p[L["I0"]] = I0.ravel()
        if self.structure.orbit:
            o = scene.orbit
            p[L["orbit"]] = [o.radius_m, o.inclination, o.u0, o.mean_motion]
        if self.structure.harmonic:
            h = np.zeros(15)
            for t in scene.torque:
                if isinstance(t, HarmonicTorque):
                    h += np.concatenate([t.bias_B, t.cos1_B, t.sin1_B, t.cos2_B, t.sin2_B])
            p[L["harm"]] = h
        return p

    # -- symbols ------------------------------------------------------------------------
    def _mat(self, p, name):
        return ca.reshape(p[self.layout[name]], 3, 3).T  # row-major in p

    def arrays(self, t, p):
        """Per array: ``(I_p, omega_p, omega_p_dot, (alpha, beta), C_PB, J_p, omega_PB_P)`` in B."""
        out = []
        for k in range(self.structure.n_app):
            J = self._mat(p, f"J{k}")
            C_PB, w_P, wd_P, ang = joint_kinematics(t, p[self.layout[f"alpha{k}"]], p[self.layout[f"beta{k}"]])
            C_BP = C_PB.T
            I_p = ca.mtimes([C_BP, J, C_PB])
            out.append((I_p, ca.mtimes(C_BP, w_P), ca.mtimes(C_BP, wd_P), ang, C_PB, J, w_P))
        return out

    def inertia(self, t, p, arrays=None):
        """Total inertia about O, B axes, at time t [kg m²]."""
        arrays = self.arrays(t, p) if arrays is None else arrays
        I = self._mat(p, "I0")
        for a in arrays:
            I = I + a[0]
        return I

    def orbit_u(self, t, p):
        radius, incl, u0, n = (p[self.layout["orbit"]][i] for i in range(4))
        return u0 + n * t

    def external_torque(self, t, q, u, p, I):
        """Sum of the scene's external torques, B components [N m]; ``u`` is the held input."""
        L = u
        s = self.structure
        if s.orbit:
            radius, incl, u0, n = (p[self.layout["orbit"]][i] for i in range(4))
            arg = u0 + n * t
            if s.gravity_gradient:
                R_hat_N = orbit_position_N(arg, 1.0, incl)
                R_hat_B = ca.mtimes(dcm(q), R_hat_N)
                L = L + gravity_gradient_torque(R_hat_B, I, n * n)
            if s.harmonic:
                h = p[self.layout["harm"]]
                L = (
                    L
                    + h[0:3]
                    + h[3:6] * ca.cos(arg)
                    + h[6:9] * ca.sin(arg)
                    + h[9:12] * ca.cos(2 * arg)
                    + h[12:15] * ca.sin(2 * arg)
                )
        return L

    def C_ON(self, t, p):
        radius, incl, u0, n = (p[self.layout["orbit"]][i] for i in range(4))
        return C_ON(u0 + n * t, incl)


class Formulation:
    """Base class of the equations of motion (DESIGN §7).

    Rules for implementers:

    1. Set ``name`` (the registry/scene name) and ``state_names`` (the state layout; the first
       four entries are always ``qw, qx, qy, qz``, the Euler parameters of B relative to N).
    2. Write ``_rhs(t, x, u, p)`` returning the state derivative as a casadi column, using
       ``self.model`` for inertia, arrays and external torque. ``u`` (3,) is a body torque held
       constant by the caller over each integration segment [N m].
    3. Write ``_omega(t, x, p)`` (omega_BN_B from the state) and ``_state(t, q, omega, p)``
       (the state that has attitude q and rate omega at time t).
    4. Do not report energy or momentum yourself: :meth:`H_O_B` and :meth:`kinetic_energy`
       derive them from ``_omega`` so conservation tests are generic over formulations.
    """

    name: ClassVar[str] = ""
    state_names: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""
    #: per state: "attitude" (dimensionless), "rate" [rad/s] or "momentum" [N m s]; sets the
    #: units in which the scene's dimensionless atol is applied (see :meth:`atol_vector`)
    state_kinds: ClassVar[tuple[str, ...]] = ()

    def __init__(self, model: StationModel):
        self.model = model

    @property
    def nx(self) -> int:
        return len(self.state_names)

    # -- public, checked -----------------------------------------------------------------
    def rhs(self, t, x, u, p):
        xdot = self._rhs(t, x, u, p)
        if xdot.shape != (self.nx, 1):
            raise ValueError(f"{self.name}: _rhs returned shape {xdot.shape}, expected ({self.nx}, 1)")
        return xdot

    def omega(self, t, x, p):
        return self._omega(t, x, p)

    def state(self, t, q, omega, p):
        return self._state(t, q, omega, p)

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

    def momentum_of(self, t, omega, p):
        """Total angular momentum about O, B components, at rate ``omega``: ``I ω + Σ I_p ω_p``."""
        arrays = self.model.arrays(t, p)
        H = ca.mtimes(self.model.inertia(t, p, arrays), omega)
        for I_p, w_p, *_ in arrays:
            H = H + ca.mtimes(I_p, w_p)
        return H

    def H_O_B(self, t, x, p):
        """Total angular momentum about O, B components [N m s]."""
        return self.momentum_of(t, self._omega(t, x, p), p)

    def H_O_N(self, t, x, p):
        return ca.mtimes(dcm(x[0:4]).T, self.H_O_B(t, x, p))

    def kinetic_energy(self, t, x, p):
        """Rotational kinetic energy about O: ``½ωᵀIω + Σ ωᵀI_pω_p + ½ Σ ω_pᵀI_pω_p`` [J]."""
        arrays = self.model.arrays(t, p)
        w = self._omega(t, x, p)
        T = 0.5 * ca.dot(w, ca.mtimes(self.model.inertia(t, p, arrays), w))
        for I_p, w_p, *_ in arrays:
            T = T + ca.dot(w, ca.mtimes(I_p, w_p)) + 0.5 * ca.dot(w_p, ca.mtimes(I_p, w_p))
        return T

    # -- plug-in -------------------------------------------------------------------------
    def _rhs(self, t, x, u, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _omega(self, t, x, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _state(self, t, q, omega, p):  # pragma: no cover - abstract
        raise NotImplementedError


class OmegaStateForm(Formulation):
    """Base of the forms whose state is ``[q_BN, omega_BN_B]`` (TP Eq. 16 and Eq. 27).

    Both read ``I ω̇ = L - ω × I ω - Σ_p a_p``; a subclass writes only the array term
    ``a_p = _array_term(ω, I_p, ω_p, ω̇_p)`` (everything an array adds to the left-hand side
    besides its share of ``I ω̇`` and ``ω × I ω``).
    """

    state_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    state_kinds = ("attitude",) * 4 + ("rate",) * 3

    def _omega(self, t, x, p):
        return x[4:7]

    def _state(self, t, q, omega, p):
        return ca.vertcat(q, omega)

    def _rhs(self, t, x, u, p):
        m = self.model
        arrays = m.arrays(t, p)
        I = m.inertia(t, p, arrays)
        w = x[4:7]
        rhs = m.external_torque(t, x[0:4], u, p, I) - ca.cross(w, ca.mtimes(I, w))
        for I_p, w_p, wd_p, *_ in arrays:
            rhs = rhs - self._array_term(w, I_p, w_p, wd_p)
        return ca.vertcat(quat_kinematics(x[0:4], w), ca.mtimes(inv3(I), rhs))

    def _array_term(self, w, I_p, w_p, wd_p):  # pragma: no cover - abstract
        raise NotImplementedError


__all__ += ["OmegaStateForm", "coriolis_matrix"]
