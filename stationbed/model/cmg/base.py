"""The base classes of a CMG cluster kind: :class:`CmgGeometry` (the contract) and
:class:`GimballedGeometry` (everything a gimballed cluster shares: momentum, Jacobian, steering,
limits), so a new gimballed layout writes only its spin axes."""

from __future__ import annotations

import math
from typing import ClassVar

import casadi as ca
import numpy as np

from .steering import rate_limit, singularity_measure, steer

__all__ = ["CmgGeometry", "GimballedGeometry", "HEAD_PAR", "UNIT_TAIL", "RATE_CAP_NONE"]

#: numbers at the head of the cluster's slice of p, before the geometry (limits, steering,
#: saturation)
HEAD_PAR = 8
#: the per-unit numbers at the tail of the cluster's slice of p, one group of ``n_units`` each:
#: ``working`` (1; 0: ``[cmg] failed``, its gimbals held and left out of steering), ``rotor`` (the
#: rotor's momentum as a fraction of ``h_rotor``; 1) and ``rate_cap`` (each of its gimbals' rate
#: clamped to it after the steering law, which does not know it [rad/s]; :data:`RATE_CAP_NONE`)
UNIT_TAIL = ("working", "rotor", "rate_cap")
#: ``rate_cap`` of a healthy gimbal: ``fmin(r, cap)`` is exactly ``r`` for every finite rate
RATE_CAP_NONE = 1e300


class CmgGeometry:
    """Base class of a CMG cluster kind (one module per kind, registered in ``CMG_GEOMETRIES``).

    An instance describes a cluster of ``n_units`` units. Its symbolic methods (casadi) take the
    cluster's state ``xc`` (shape (nx, 1)), input ``uc`` (shape (nu, 1)) and its slice ``pc`` of
    the parameter vector (shape (n_par, 1)); its numeric methods take the scene's ``[cmg]``
    table ``cfg`` (a :class:`stationbed.scene.Cmg`) and return numbers. The public methods check
    and call the private ones. Rules for implementers (a gimballed kind derives from
    :class:`GimballedGeometry`, which writes rules 3 and 4 from the spin axes):

    1. Set ``kind`` (the scene's ``[cmg] kind``, the registry key), ``gimbals_per_unit`` (0: a
       momentum store without units, whose state is ``h`` itself and whose input is the torque
       command), ``gimbal_suffixes`` (one name per gimbal of a unit; () for one gimbal per unit),
       ``unit_par`` (geometry numbers per unit in ``pc``), ``state_kind`` (``"momentum"`` or
       ``"attitude"``: the units of the state's atol) and ``state_names`` when the state is not
       the gimbal angles.
    2. Numbers: write ``_head_params(cfg)`` (:data:`HEAD_PAR` numbers: limits, steering constants, saturation),
       ``_geometry_params(cfg)`` (``n_units * unit_par`` numbers), ``_capacity(cfg)`` (the
       momentum envelope [N m s]) and ``_initial_state(cfg)`` (shape (nx,)).
    3. Symbols: write ``_h(xc, pc)`` (the cluster's momentum relative to the body, B components
       [N m s]), ``_h_dot(xc, uc, omega_BN_B, pc)`` (its B-frame derivative [N m]),
       ``_state_dot(xc, uc, omega_BN_B, pc)`` and ``_actuate(t, xc, tau_cmd, omega_BN_B, pc,
       steering, direct_rates)`` (see :meth:`actuate`).
    4. Drawing: write ``_unit_momenta_B(cfg, gimbal_angles)`` (each unit's rotor momentum) and
       ``_mount_axes_B(cfg)`` (the axis each unit is drawn along).

    Parameters
    ----------
    n_units : int  Number of units (0 for a momentum store).
    """

    kind: ClassVar[str] = ""
    gimbals_per_unit: ClassVar[int] = 0
    gimbal_suffixes: ClassVar[tuple[str, ...]] = ()
    unit_par: ClassVar[int] = 0
    state_kind: ClassVar[str] = "attitude"
    #: whether the symbols read the per-unit ``rotor`` and ``rate_cap`` (a scheduled CMG fault
    #: changes them); False for a scene without ``[[fault]]`` (:class:`~stationbed.model.structure.Structure`):
    #: its rotors stay at h_rotor and no gimbal is clamped, so those terms (x 1, a clamp at
    #: RATE_CAP_NONE) are left out of the code, the same numbers
    unit_faults: bool = True

    def __init__(self, n_units: int):
        self.n_units = int(n_units)

    # -- layout ------------------------------------------------------------------------
    @property
    def gimballed(self) -> bool:
        """Whether the cluster has gimbals (then: state = gimbal angles, input = gimbal rates,
        a steering law and a singularity measure)."""
        return self.gimbals_per_unit > 0

    @property
    def n_gimbals(self) -> int:
        """Number of gimbals (state and input size of a gimballed cluster)."""
        return self.n_units * self.gimbals_per_unit

    @property
    def nx(self) -> int:
        """Size of the cluster's state (the gimbal angles, or ``h`` for a momentum store)."""
        return len(self.state_names)

    @property
    def nu(self) -> int:
        """Size of the cluster's held input (the gimbal rates, or the torque command)."""
        return self.nx

    @property
    def gimbal_names(self) -> list[str]:
        """Gimbal names in state order: ``gimbal_<unit>`` or ``gimbal_<unit>_<suffix>``."""
        if not self.gimbal_suffixes:
            return [f"gimbal_{i + 1}" for i in range(self.n_gimbals)]
        return [f"gimbal_{i + 1}_{s}" for i in range(self.n_units) for s in self.gimbal_suffixes]

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the cluster's states (here: the gimbal names)."""
        return tuple(self.gimbal_names)

    @property
    def n_par(self) -> int:
        """Size of the cluster's slice of p: :data:`HEAD_PAR`, the geometry, then :data:`UNIT_TAIL`
        groups of one number per unit (:meth:`unit_index`)."""
        return HEAD_PAR + self.n_units * (self.unit_par + len(UNIT_TAIL))

    def unit_index(self, name: str, unit: int) -> int:
        """Index in the cluster's slice of p of the per-unit number ``name`` (:data:`UNIT_TAIL`)
        of ``unit`` (1-based, as ``[cmg] failed`` counts): what a scheduled step changes."""
        if not 1 <= unit <= self.n_units:
            raise ValueError(f"unit {unit} is not one of 1..{self.n_units}")
        return HEAD_PAR + self.n_units * (self.unit_par + UNIT_TAIL.index(name)) + unit - 1

    # -- numbers (from the scene's [cmg] table) ---------------------------------------
    def _check(self, cfg) -> None:
        if cfg.kind != self.kind or cfg.n_units != self.n_units:
            raise ValueError(f"[cmg] is {cfg.kind} x {cfg.n_units}, this model {self.kind} x {self.n_units}")

    def params(self, cfg) -> np.ndarray:
        """The cluster's numbers in p, shape (n_par,): the head, then the geometry."""
        self._check(cfg)
        working = [0.0 if i + 1 in cfg.failed else 1.0 for i in range(self.n_units)]
        out = np.concatenate([np.asarray(self._head_params(cfg), float), np.asarray(self._geometry_params(cfg), float).ravel(),
                              working, np.ones(self.n_units), np.full(self.n_units, RATE_CAP_NONE)])
        if out.shape != (self.n_par,):
            raise ValueError(f"cmg kind {self.kind!r}: {out.shape[0]} parameters, expected {self.n_par}")
        return out

    def capacity(self, cfg) -> float:
        """Momentum capacity of the cluster's *working* units [N m s] (inf without a limit): what
        the saturation flag and the summary's fraction refer to. A failed unit (``[cmg] failed``)
        is held: the working units' momentum ``h - held_momentum_B`` moves in their envelope."""
        self._check(cfg)
        return float(self._capacity(cfg))

    def held_momentum_B(self, cfg) -> np.ndarray:
        """The failed units' rotor momentum, B components [N m s], shape (3,): constant, as their
        gimbals are held at their initial angles (zero without failed units). The working units'
        momentum is ``h - held_momentum_B``: capacity, saturation and the metrics refer to it."""
        self._check(cfg)
        if not self.gimballed or not cfg.failed:
            return np.zeros(3)
        m = self.unit_momenta_B(cfg, self.initial_state(cfg))
        return m[[u - 1 for u in sorted(cfg.failed)]].sum(axis=0)

    def initial_state(self, cfg) -> np.ndarray:
        """The cluster's state at t = 0, shape (nx,)."""
        self._check(cfg)
        x0 = np.asarray(self._initial_state(cfg), float)
        if x0.shape != (self.nx,):
            raise ValueError(f"cmg kind {self.kind!r}: initial state shape {x0.shape}, expected ({self.nx},)")
        return x0

    def max_torque(self, cfg) -> float:
        """Torque limit of the cluster [N m] (inf when it has none of its own)."""
        return math.inf

    def max_gimbal_rate(self, cfg) -> float:
        """Rate limit of each gimbal [rad/s] (inf without gimbals)."""
        return math.inf

    def rotor_momentum(self, cfg) -> float:
        """Momentum of one rotor [N m s] (0 without units)."""
        return 0.0

    def unit_momenta_B(self, cfg, gimbal_angles) -> np.ndarray:
        """Each unit's rotor momentum, B components [N m s] (numpy, for drawings).

        Parameters
        ----------
        cfg : stationbed.scene.Cmg  The scene's ``[cmg]`` table.
        gimbal_angles : array_like, shape (..., n_gimbals)  Gimbal angles [rad] in
            :attr:`gimbal_names` order.

        Returns
        -------
        ndarray, shape (..., n_units, 3)  Their sum is the cluster's ``h`` (:meth:`h`).
        """
        self._check(cfg)
        d = np.asarray(gimbal_angles, dtype=float)
        if d.shape[-1:] != (self.n_gimbals,):
            raise ValueError(f"gimbal_angles has shape {d.shape}, expected (..., {self.n_gimbals})")
        return self._unit_momenta_B(cfg, d)

    def mount_axes_B(self, cfg) -> np.ndarray:
        """Per unit the body-fixed axis it is mounted on (outer gimbal axis), B components,
        shape (n_units, 3) (numpy, for drawings)."""
        self._check(cfg)
        return np.asarray(self._mount_axes_B(cfg), dtype=float).reshape(self.n_units, 3)

    # -- symbols -----------------------------------------------------------------------
    def h(self, xc, pc):
        """The cluster's momentum relative to the body, B components [N m s] (casadi (3, 1))."""
        return self._h(xc, pc)

    def h_dot(self, xc, uc, omega_BN_B, pc):
        """B-frame derivative of ``h`` [N m] with held input ``uc`` at body rate ``omega_BN_B``."""
        return self._h_dot(xc, uc, omega_BN_B, pc)

    def state_dot(self, xc, uc, omega_BN_B, pc):
        """Derivative of the cluster's state (casadi (nx, 1))."""
        return self._state_dot(xc, uc, omega_BN_B, pc)

    def actuate(self, t, xc, tau_cmd, omega_BN_B, pc, steering: str, direct_rates=None):
        """The held input for one control period, from a body-torque request (or direct rates).

        Parameters
        ----------
        t : casadi SX  Time [s].
        xc : casadi SX, shape (nx, 1)  The cluster's state.
        tau_cmd : casadi SX, shape (3, 1)  Requested torque on the body, B components [N m].
        omega_BN_B : casadi SX, shape (3, 1)  Body rate at the tick [rad/s] (the ``ω × h``
            compensation of the request).
        pc : casadi SX, shape (n_par, 1)  The cluster's slice of p.
        steering : str  The steering law (gimballed kinds).
        direct_rates : casadi SX, shape (n_gimbals, 1), optional  Gimbal rates commanded directly
            [rad/s] (bypass the steering law, not the limits).

        Returns
        -------
        tuple ``(u_held (nu, 1), singularity, rate_or_torque_limited, momentum_saturated)``; the
        flags are 0/1, the singularity measure is dimensionless (1 for a momentum store).
        """
        return self._actuate(t, xc, tau_cmd, omega_BN_B, pc, steering, direct_rates)

    # -- plug-in -----------------------------------------------------------------------
    def _head_params(self, cfg):  # pragma: no cover - abstract
        raise NotImplementedError

    def _geometry_params(self, cfg):
        return np.zeros(0)

    def _capacity(self, cfg):  # pragma: no cover - abstract
        raise NotImplementedError

    def _initial_state(self, cfg):  # pragma: no cover - abstract
        raise NotImplementedError

    def _h(self, xc, pc):  # pragma: no cover - abstract
        raise NotImplementedError

    def _h_dot(self, xc, uc, omega_BN_B, pc):  # pragma: no cover - abstract
        raise NotImplementedError

    def _state_dot(self, xc, uc, omega_BN_B, pc):  # pragma: no cover - abstract
        raise NotImplementedError

    def _actuate(self, t, xc, tau_cmd, omega_BN_B, pc, steering, direct_rates):  # pragma: no cover - abstract
        raise NotImplementedError

    def _unit_momenta_B(self, cfg, gimbal_angles):
        return np.zeros(gimbal_angles.shape[:-1] + (0, 3))

    def _mount_axes_B(self, cfg):
        return np.zeros((0, 3))


class GimballedGeometry(CmgGeometry):
    """A cluster of CMG units whose rotors (momentum ``h_rotor`` each) the gimbals turn.

    ``h = h_rotor Σ_i s_i(δ)``, ``ḣ = A(δ) δ̇`` with ``A = ∂h/∂δ = h_rotor Â`` (written
    analytically by the geometry); state: the gimbal angles δ; held input: the gimbal rates.
    The torque request becomes ``ḣ_cmd = -τ - ω × h``, steered to rates by the scene's law
    (:func:`~stationbed.model.cmg.steering.steer`), then rate limited.

    Head of ``pc``: ``h_rotor`` [N m s], ``max_gimbal_rate`` [rad/s], the saturation threshold
    ``saturation_fraction * capacity`` [N m s], ``sr_lambda0``, ``sr_mu``, ``dither_eps0``,
    ``dither_omega`` [rad/s]; then ``unit_par`` numbers per unit.

    Rules for implementers (besides ``kind``, ``gimbals_per_unit``, ``gimbal_suffixes``,
    ``unit_par`` and ``_capacity``): write

    * ``_geometry_params(cfg)``: the per-unit axes (``n_units * unit_par`` numbers);
    * ``_unit_spin(angles, geo)``: from one unit's gimbal angles (casadi, ``gimbals_per_unit``)
      and its geometry numbers (``unit_par``), the unit's spin axis (B, unit vector) and its
      derivatives by each of the unit's gimbal angles (a list);
    * ``_unit_spins_B(cfg, gimbal_angles)``: the same spin axes in numpy, shape (..., n_units, 3)
      (the contract test holds the two equal through :meth:`h` = Σ :meth:`unit_momenta_B`);
    * ``_unit_reach(geo)``: from a unit's geometry numbers, the largest component its spin axis
      can take along body x, y and z (casadi (3, 1)): the envelope of :meth:`envelope`, which
      the contract test holds equal to ``capacity / h_rotor`` for every set of failed units;
    * ``_mount_axes_B(cfg)``.
    """

    state_kind = "attitude"

    # -- numbers -----------------------------------------------------------------------
    def _head_params(self, cfg):
        return [
            cfg.h_rotor,
            cfg.max_gimbal_rate,
            cfg.saturation_fraction * self.capacity(cfg),
            cfg.sr_lambda0,
            cfg.sr_mu,
            cfg.dither_eps0,
            cfg.dither_omega,
            cfg.saturation_fraction * cfg.h_rotor,
        ]

    def _initial_state(self, cfg):
        return cfg.gimbal0 if cfg.gimbal0 is not None else np.zeros(self.n_gimbals)

    def max_gimbal_rate(self, cfg) -> float:
        """``max_gimbal_rate`` [rad/s]."""
        return cfg.max_gimbal_rate

    def rotor_momentum(self, cfg) -> float:
        """``h_rotor`` [N m s]."""
        return cfg.h_rotor

    def _unit_momenta_B(self, cfg, gimbal_angles):
        return cfg.h_rotor * self._unit_spins_B(cfg, gimbal_angles)

    def rotor_capacity(self, cfg, rotors) -> float:
        """The capacity [N m s] of the units with each rotor at its fraction ``rotors[i]`` of
        ``h_rotor`` (0: the unit out): :meth:`envelope` times ``h_rotor``, what the saturation
        flag weighs a scheduled fault's units by. With every fraction 0 or 1 it is
        :meth:`capacity` with the 0s failed (the contract test), which a caller should use then."""
        self._check(cfg)
        pc = ca.DM(self.params(cfg))
        return float(cfg.h_rotor * self.envelope(pc, [float(r) for r in rotors]))

    # -- symbols -----------------------------------------------------------------------
    def spins(self, xc, pc) -> list:
        """Per unit ``(s_i, [∂s_i/∂δ_j for the unit's gimbals])``, B components (casadi)."""
        geo = pc[HEAD_PAR:]
        g, k = self.gimbals_per_unit, self.unit_par
        return [self._unit_spin(xc[g * i : g * i + g], geo[k * i : k * i + k]) for i in range(self.n_units)]

    def A_hat(self, xc, pc):
        """Normalised Jacobian ``∂h/∂δ / h_rotor`` (analytic), shape (3, n_gimbals) [1/rad]."""
        return ca.horzcat(*[d for _, ds in self.spins(xc, pc) for d in ds])

    def singularity(self, xc, pc):
        """The singularity measure ``sqrt(det(Â Âᵀ))`` at ``xc`` (casadi scalar)."""
        return singularity_measure(self.A_hat(xc, pc))

    def envelope(self, pc, weights):
        """The capacity of units weighted by ``weights`` (one per unit: 0 out, a rotor's
        fraction of ``h_rotor``), over ``h_rotor`` (casadi scalar): along each body axis the sum
        of the weighted units' :meth:`_unit_reach`, the least of the three (the capacity's
        definition: ``_capacity`` with the units of weight 0 failed, times ``h_rotor``)."""
        geo, k = pc[HEAD_PAR:], self.unit_par
        reach = [self._unit_reach(geo[k * i: k * i + k]) for i in range(self.n_units)]
        along = sum((weights[i] * reach[i] for i in range(1, self.n_units)), weights[0] * reach[0])
        return ca.fmin(along[0], ca.fmin(along[1], along[2]))

    def _tail(self, pc, name: str) -> list:
        """The per-unit numbers ``name`` (:data:`UNIT_TAIL`) from ``pc``, one per unit (casadi)."""
        i0 = self.unit_index(name, 1)
        return [pc[i0 + i] for i in range(self.n_units)]

    def _h(self, xc, pc):
        # each rotor at its fraction of h_rotor (1: x 1 is exact, the healthy cluster's numbers)
        spins = [s for s, _ in self.spins(xc, pc)]
        if self.unit_faults:
            spins = [r * s for r, s in zip(self._tail(pc, "rotor"), spins)]
        return pc[0] * sum(spins[1:], spins[0])

    def _h_dot(self, xc, uc, omega_BN_B, pc):
        if not self.unit_faults:  # every rotor at h_rotor: the healthy cluster's Jacobian
            return pc[0] * ca.mtimes(self.A_hat(xc, pc), uc)
        rotor = self._tail(pc, "rotor")
        A = ca.horzcat(*[d * rotor[i] for i, (_, ds) in enumerate(self.spins(xc, pc)) for d in ds])
        return pc[0] * ca.mtimes(A, uc)

    def _state_dot(self, xc, uc, omega_BN_B, pc):
        return uc

    def working(self, pc):
        """Per gimbal 1 (its unit works) or 0 (its unit failed: ``[cmg] failed``), casadi
        (n_gimbals, 1), from the tail of ``pc``."""
        w = self._tail(pc, "working")
        return ca.vertcat(*[w[i] for i in range(self.n_units) for _ in range(self.gimbals_per_unit)])

    def _actuate(self, t, xc, tau_cmd, omega_BN_B, pc, steering, direct_rates):
        h_rotor, max_rate, h_sat, lam0, mu, eps0, om, h_sat_unit = (pc[i] for i in range(HEAD_PAR))
        # a failed unit's gimbals are held (rate 0): its rotor keeps its momentum, and steering
        # and the singularity measure see only the working units' Jacobian columns
        working = self.working(pc)
        A_hat = ca.mtimes(self.A_hat(xc, pc), ca.diag(working))
        if direct_rates is None:
            hdot_cmd = -tau_cmd - ca.cross(omega_BN_B, self.h(xc, pc))
            rates = steer(steering, A_hat, hdot_cmd / h_rotor, t, lam0, mu, eps0, om)
        else:
            rates = direct_rates
        rates, limited = rate_limit(rates * working, max_rate)
        # a gimbal the hardware clamps (a scheduled fault: stuck = 0, a degraded limit), after the
        # steering law, which does not know it; healthy: RATE_CAP_NONE, the rates exactly as
        # they were (a NaN rate too: if_else, not fmin/fmax, which would turn it into a number)
        if self.unit_faults:
            cap = self._tail(pc, "rate_cap")
            cap = ca.vertcat(*[cap[i] for i in range(self.n_units) for _ in range(self.gimbals_per_unit)])
            clamped = ca.if_else(rates > cap, cap, ca.if_else(rates < -cap, -cap, rates))
            limited = ca.fmax(limited, ca.if_else(ca.mmax(ca.fabs(rates) - cap) > 0.0, 1.0, 0.0))
            rates = clamped
        # saturation of the working units: their momentum (the failed units' is held) against
        # their capacity (h_sat = saturation_fraction x capacity of the working units)
        w_unit = self._tail(pc, "working")
        if self.unit_faults:  # a unit whose gimbals a fault holds (rate_cap 0) is out too, and a
            # rotor counts at its fraction: the units that move, against their own envelope
            cap, rotor = self._tail(pc, "rate_cap"), self._tail(pc, "rotor")
            w_unit = [w_unit[i] * ca.if_else(cap[i] > 0.0, 1.0, 0.0) * rotor[i] for i in range(self.n_units)]
            h_sat = h_sat_unit * self.envelope(pc, w_unit)
        spins = [s for s, _ in self.spins(xc, pc)]
        h_work = h_rotor * sum((w_unit[i] * spins[i] for i in range(1, self.n_units)), w_unit[0] * spins[0])
        sat = ca.if_else(ca.norm_2(h_work) >= h_sat, 1.0, 0.0)
        return rates, singularity_measure(A_hat), limited, sat

    # -- plug-in -----------------------------------------------------------------------
    def _unit_spin(self, angles, geo):  # pragma: no cover - abstract
        raise NotImplementedError

    def _unit_spins_B(self, cfg, gimbal_angles):  # pragma: no cover - abstract
        raise NotImplementedError

    def _unit_reach(self, geo):  # pragma: no cover - abstract
        raise NotImplementedError
