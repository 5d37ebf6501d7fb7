"""The base class of every formulation (DESIGN §7).

A :class:`Formulation` adds the state layout and the equations of motion to a
:class:`~stationbed.model.StationModel`. Energy and angular momentum are generic: they need only
the formulation's ``omega(t, x, p)``.

Conventions (every method, casadi SX): ``t`` time [s]; ``x`` the state, shape (nx, 1):
``q_BN`` (4), the form's 3-vector, then the model's extra states and modal states, by the
form's :attr:`~Formulation.state_layout` (:meth:`~Formulation.attitude`, :meth:`~Formulation.core_vector`,
:meth:`~Formulation.extra`);
``u`` the held input (nu, 1); ``p`` the parameter vector (layout.size, 1).
"""

from __future__ import annotations

from typing import ClassVar

import casadi as ca
import numpy as np

from ..core.layout import Layout
from ..core.linalg import inv3
from ..core.rotation import dcm, quat_kinematics
from ..model import StationModel

__all__ = ["Formulation", "OmegaStateForm"]


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
    3. Write ``_omega(t, x, p)`` (omega_BN_B from the state) and ``_core(t, q_BN, omega_BN_B, xe, p)``
       (the 3-vector core state that has rate ``omega_BN_B`` at time t with extra states ``xe``,
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
        """
        Parameters
        ----------
        model : StationModel  The symbolic station the equations are written for.
        """
        self.model = model
        second = tuple(n.replace("eta", self.modal_state_prefix, 1) for n in model.eta_names)
        self.state_names = tuple(self.core_names) + model.extra_names + model.eta_names + second
        self.state_kinds = tuple(self.core_kinds) + model.extra_kinds + ("attitude",) * (2 * model.n_modes)

    @property
    def nx(self) -> int:
        """Size of the state."""
        return len(self.state_names)

    @property
    def state_layout(self) -> Layout:
        """The state ``x`` by name (its indices are owned here): ``q_BN`` (4), the form's rate
        state (``omega_BN_B``, or ``H_O_B`` for the momentum form: :attr:`rate_field`), then the
        model's extra states: ``x_cmg`` (the CMG cluster's), ``joints`` (driven array joints),
        ``eta`` and the second modal state (those the scene has)."""
        m = self.model
        n_cmg = 0 if m.cmg is None else m.cmg.nx
        fields = {"q_BN": 4, self.rate_field: 3}
        for name, n in (("x_cmg", n_cmg), ("joints", m.n_extra - n_cmg), ("eta", m.n_modes),
                        (self.modal_state_prefix, m.n_modes)):
            if n:
                fields[name] = n
        return Layout(**fields)

    @property
    def rate_field(self) -> str:
        """The name of the form's second core state: ``omega_BN_B`` when it is the body rate."""
        return "omega_BN_B" if self.omega_is_state else "H_O_B"

    # -- the state's parts, by the state layout (casadi or numpy; nobody writes x[4:7]) ----------
    def _slices(self) -> tuple[slice, slice, slice]:
        sl = self.__dict__.get("_state_slices")
        if sl is None:
            xl = self.state_layout
            rate = xl.slice(self.rate_field)
            sl = self.__dict__["_state_slices"] = (xl.slice("q_BN"), rate, slice(rate.stop, None))
        return sl

    def attitude(self, x):
        """``q_BN`` of the state ``x``."""
        return x[self._slices()[0]]

    def core_vector(self, x):
        """The form's second core state of ``x`` (:attr:`rate_field`: ``omega_BN_B`` or ``H_O_B``)."""
        return x[self._slices()[1]]

    def extra(self, x):
        """The model's extra and modal states of ``x`` (after the core: ``x_cmg``, ``joints``,
        ``eta`` and the second modal state, those the scene has)."""
        return x[self._slices()[2]]

    # -- helpers for implementers --------------------------------------------------------
    def arrays(self, t, x, p, omega_BN_B=None, u=None):
        """The arrays' :class:`~stationbed.model.ArrayState` at state ``x`` (see
        :meth:`StationModel.arrays`)."""
        return self.model.arrays(t, self.attitude(x), self.extra(x), p, omega_BN_B, u)

    def modal_rates(self, t, x, p):
        """``η̇`` from the state (here: the second modal state itself)."""
        return self.model.modal_state(self.extra(x))

    def physical_extra(self, t, x, p):
        """The extra states (:meth:`extra`) with the second modal state replaced by ``η̇`` (what :meth:`state` takes)."""
        m = self.model
        xe = self.extra(x)
        if not m.n_modes:
            return xe
        return ca.vertcat(xe[0 : m.n_extra + m.n_modes], self.modal_rates(t, x, p))

    @staticmethod
    def modal_momenta(modal, omega_BN_B, eta_dot):
        """``p_η`` of the flexible arrays (none for a rigid scene)."""
        return ca.SX(0, 1) if modal is None else modal.momentum(omega_BN_B, eta_dot)

    # -- public, checked -----------------------------------------------------------------
    def rhs(self, t, x, u, p):
        """``dx/dt`` (nx, 1): the form's seven core states, then the model's extra states and the
        modal states."""
        out = self._rhs(t, x, u, p)
        core_dot, omega_BN_B = out[0], out[1]
        if core_dot.shape != (7, 1):
            raise ValueError(f"{self.name}: _rhs returned shape {core_dot.shape}, expected (7, 1)")
        parts = [core_dot, self.model.extra_dot(t, self.attitude(x), self.extra(x), u, omega_BN_B, p)]
        if self.model.n_modes:
            if len(out) < 3:
                raise ValueError(f"formulation {self.name!r} does not model flexible arrays (elastic modes)")
            parts.append(out[2])
        return ca.vertcat(*parts)

    def omega(self, t, x, p):
        """omega_BN_B, the body rate relative to N, B components [rad/s], (3, 1)."""
        return self._omega(t, x, p)

    def state(self, t, q_BN, omega_BN_B, xe, p):
        """The state with a given attitude, rate and extra states at time ``t``.

        Parameters
        ----------
        t : casadi SX  Time [s].
        q_BN : casadi SX, shape (4, 1)  Euler parameters of B relative to N (scalar first).
        omega_BN_B : casadi SX, shape (3, 1)  Body rate, B components [rad/s].
        xe : casadi SX  The model's extra states, then ``η`` and ``η̇`` of flexible arrays.
        p : casadi SX  The parameter vector.

        Returns
        -------
        casadi SX, shape (nx, 1)
        """
        m = self.model
        parts = [q_BN, self._core(t, q_BN, omega_BN_B, xe, p), xe[0 : m.n_extra]]
        if m.n_modes:
            parts += [m.eta(xe), self._modal_state(t, q_BN, omega_BN_B, xe, p)]
        return ca.vertcat(*parts)

    def _modal_state(self, t, q_BN, omega_BN_B, xe, p):
        return self.model.modal_state(xe)

    def jump(self, t_minus, t_plus, x, p):
        """State just after an impulsive change of the array rates: H is continuous.

        Parameters
        ----------
        t_minus, t_plus : casadi SX  Times [s] just before and after the step (the side each
            array's rate is taken on).
        x : casadi SX, shape (nx, 1)  State just before.
        p : casadi SX  The parameter vector.

        Returns
        -------
        casadi SX, shape (nx, 1)  State just after.

        Notes
        -----
        The total momentum (and the modal momenta ``p_η``, whose rate ``-Kη - Cη̇`` is bounded)
        are taken with the arrays at ``t_minus`` and the rates recovered with the arrays at
        ``t_plus``. For the momentum form this is the identity (H and p_η are its states).
        """
        return self.step_jump(t_minus, t_plus, x, p, p)

    def step_jump(self, t_minus, t_plus, x, p_minus, p_plus):
        """State just after a step of the parameters from ``p_minus`` to ``p_plus`` at a
        scheduled step (run/schedule.py: a CMG rotor stopped, mass properties changed), or of
        the array rates (:meth:`jump`, one p): the total angular momentum about O, B components
        (the CMG rotors' included) and the modal momenta are continuous; the attitude and the
        other states are kept; the rates are recovered with ``p_plus``. The rotor momentum a
        step takes away goes to the body (it leaves through the bearing: the system's H is kept).
        For the momentum form (H and p_η are its states) this is the identity."""
        m = self.model
        q_BN, xe = self.attitude(x), self.extra(x)
        xp = self.physical_extra(t_minus, x, p_minus)
        omega_BN_B = self._omega(t_minus, x, p_minus)
        H_O_B = self.momentum_of(t_minus, q_BN, omega_BN_B, xp, p_minus)
        p_eta = self.modal_momenta(m.modal(m.arrays(t_minus, q_BN, xe, p_minus), p_minus), omega_BN_B, m.modal_state(xp))
        arrays = m.arrays(t_plus, q_BN, xe, p_plus)
        omega_plus_B, eta_dot = m.velocities(
            H_O_B, p_eta, arrays, m.modal(arrays, p_plus), m.inertia(t_plus, p_plus, arrays), xe, p_plus
        )
        xe_plus = ca.vertcat(xe[0 : m.n_extra + m.n_modes], eta_dot) if m.n_modes else xe
        return self.state(t_plus, q_BN, omega_plus_B, xe_plus, p_plus)

    def atol_vector(self, atol: float, rate_scale: float, momentum_scale: float) -> np.ndarray:
        """Absolute tolerance per state component.

        Parameters
        ----------
        atol : float  The scene's dimensionless atol.
        rate_scale : float  Characteristic rate [rad/s].
        momentum_scale : float  Characteristic momentum [N m s].

        Returns
        -------
        ndarray, shape (nx,)

        Notes
        -----
        A scene's ``atol`` is dimensionless: it applies as given to the Euler parameters and,
        for rate or momentum states, in units of the scene's characteristic rate [rad/s] or
        momentum [N m s]. So every formulation controls the same physical accuracy: without this,
        atol = 1e-12 is 1e-12 *relative* on an H state of 1e5 N m s but 1e-9 relative on an
        ω state of 1e-3 rad/s, and the ω-state forms would be a thousand times less accurate.
        """
        unit = {"attitude": 1.0, "rate": rate_scale, "momentum": momentum_scale}
        return np.array([atol * unit[k] for k in self.state_kinds])

    def momentum_of(self, t, q_BN, omega_BN_B, xe, p):
        """Total angular momentum about O, ``I ω + Σ I_p ω_p + h + Σ Δ η̇ + H₁`` (``H₁`` the
        first-order deformation-dependent inertia's,
        :meth:`~stationbed.model.flex.Modes.first_order_momentum`).

        Parameters
        ----------
        t, q_BN, omega_BN_B, xe, p : as for :meth:`state` (``xe`` with ``η̇``).

        Returns
        -------
        casadi SX, shape (3, 1)  ``H_O_B``, B components [N m s].
        """
        m = self.model
        arrays = m.arrays(t, q_BN, xe, p)
        H_O_B = ca.mtimes(m.inertia(t, p, arrays), omega_BN_B) + m.h(xe, p)
        for I_p_B, omega_p_B, *_ in arrays:
            H_O_B = H_O_B + ca.mtimes(I_p_B, omega_p_B)
        modal = m.modal(arrays, p)
        if modal is not None:
            H_O_B = H_O_B + ca.mtimes(modal.Delta, m.modal_state(xe)) + modal.first_order_momentum(m.eta(xe), omega_BN_B)
        return H_O_B

    def H_O_B(self, t, x, p):
        """Total angular momentum about O (CMG momentum included), B components [N m s]."""
        return self.momentum_of(t, self.attitude(x), self._omega(t, x, p), self.physical_extra(t, x, p), p)

    def H_O_N(self, t, x, p):
        """Total angular momentum about O (CMG momentum included), N components [N m s]."""
        return ca.mtimes(dcm(self.attitude(x)).T, self.H_O_B(t, x, p))

    def kinetic_energy(self, t, x, p):
        """Kinetic energy about O of the structure (body, arrays and their elastic motion; CMG
        rotors excluded) [J]: :meth:`StationModel.kinetic_energy` at the state's rates."""
        return self.model.kinetic_energy(t, self.attitude(x), self._omega(t, x, p), self.physical_extra(t, x, p), p)

    def strain_energy(self, t, x, p):
        """Elastic strain energy of the arrays ``½ ηᵀ K η`` [J] (0 for a rigid scene)."""
        m = self.model
        if not m.n_modes:
            return ca.SX(0)
        return m.modal(self.arrays(t, x, p), p).strain(m.eta(self.extra(x)))

    # -- plug-in -------------------------------------------------------------------------
    def _rhs(self, t, x, u, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _omega(self, t, x, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _core(self, t, q_BN, omega_BN_B, xe, p):  # pragma: no cover - abstract
        raise NotImplementedError


class OmegaStateForm(Formulation):
    """Base of the forms whose core state is ``[q_BN, omega_BN_B]`` (TP Eq. 16 and Eq. 27).

    Both read ``I ω̇ = L - ω × (I ω + h) - ḣ - Σ_p a_p``; a subclass writes only the array term
    ``a_p = _array_term(omega_BN_B, I_p_B, omega_p_B, omega_p_dot_B)`` (everything an array adds to the left-hand side
    besides its share of ``I ω̇`` and ``ω × I ω``).

    Flexible arrays (the same for both forms: the modal terms are not where they differ) add
    ``Δ η̈ + Δ̇ η̇ + ω × Δ η̇`` to the left-hand side (the rate of ``Δ η̇`` in H) and, for the
    first-order deformation-dependent inertia's ``H₁ = δI ω + …``, ``δI ω̇ + ω × H₁`` plus the rest
    of its rate (:meth:`~stationbed.model.flex.Modes.first_order_rate`); Lagrange's equation of
    the modes reads ``M_eff η̈ + Ṁ_eff η̇ + Δᵀ ω̇ + Δ̇ᵀ ω + Dᵀ ω̇_p + C η̇ + K η = ∂T₁/∂η``. The
    two are solved together by the Schur complement on the modal block (``M_eff⁻¹`` by the
    Woodbury identity, :meth:`stationbed.model.flex.Modes.solve`).
    """

    core_names = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")
    core_kinds = ("attitude",) * 4 + ("rate",) * 3
    omega_is_state = True

    def _omega(self, t, x, p):
        return self.core_vector(x)

    def _core(self, t, q_BN, omega_BN_B, xe, p):
        return omega_BN_B

    def _rhs(self, t, x, u, p):
        m = self.model
        q_BN, omega_BN_B = self.attitude(x), self.core_vector(x)
        xe = self.extra(x)
        arrays = self.arrays(t, x, p, omega_BN_B, u)
        I_O_B = m.inertia(t, p, arrays)
        h_B = m.h(xe, p)
        rhs = (
            m.external_torque(t, q_BN, u, p, I_O_B, arrays=arrays)
            - ca.cross(omega_BN_B, ca.mtimes(I_O_B, omega_BN_B) + h_B)
            - m.h_dot(xe, u, omega_BN_B, p)
        )
        for I_p_B, omega_p_B, omega_p_dot_B, *_ in arrays:
            rhs = rhs - self._array_term(omega_BN_B, I_p_B, omega_p_B, omega_p_dot_B)
        if not m.n_modes:
            return ca.vertcat(quat_kinematics(q_BN, omega_BN_B), ca.mtimes(inv3(I_O_B), rhs)), omega_BN_B
        eta, eta_dot = m.eta(xe), m.modal_state(xe)
        f = m.modal(arrays, p)
        H_1 = f.first_order_momentum(eta, omega_BN_B)
        rhs = (rhs - ca.mtimes(f.Delta_dot, eta_dot) - ca.cross(omega_BN_B, ca.mtimes(f.Delta, eta_dot) + H_1)
               - f.first_order_rate(eta, eta_dot, omega_BN_B))
        r_eta = f.momentum_rate(eta, eta_dot, omega_BN_B) - ca.mtimes(f.Delta_dot.T, omega_BN_B) - f.D_wdp - f.mass_rate_times(eta_dot)
        sol = f.solve(ca.horzcat(r_eta, f.Delta.T))  # M_eff⁻¹ [r_η, Δᵀ]
        I_eff = I_O_B + f.inertia_delta(eta) - ca.mtimes(f.Delta, sol[:, 1:4])
        omega_dot_B = ca.mtimes(inv3(I_eff), rhs - ca.mtimes(f.Delta, sol[:, 0]))
        eta_ddot = sol[:, 0] - ca.mtimes(sol[:, 1:4], omega_dot_B)
        return ca.vertcat(quat_kinematics(q_BN, omega_BN_B), omega_dot_B), omega_BN_B, ca.vertcat(eta_dot, eta_ddot)

    def _array_term(self, omega_BN_B, I_p_B, omega_p_B, omega_p_dot_B):  # pragma: no cover - abstract
        """What one array adds to the left-hand side [N m], (3, 1)."""
        raise NotImplementedError
