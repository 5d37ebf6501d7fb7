"""The cluster's symbolic model (:class:`CmgModel`) over a geometry from the registry
:data:`CMG_GEOMETRIES`, and numeric casadi Functions of a scene's cluster (:func:`cluster_functions`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .base import CmgGeometry, GimballedGeometry
from .dgcmg import DoubleGimbal
from .ideal import IdealCluster
from .pyramid import Pyramid
from .steering import STEERING_LAWS

__all__ = ["CmgModel", "CMG_GEOMETRIES", "get_geometry", "cmg_geometry", "capacity", "held_momentum_B",
           "cluster_functions"]

#: scene ``[cmg] kind`` -> geometry class
CMG_GEOMETRIES: dict[str, type[CmgGeometry]] = {cls.kind: cls for cls in (IdealCluster, DoubleGimbal, Pyramid)}


def get_geometry(kind: str) -> type[CmgGeometry]:
    """The geometry class registered as ``kind``; ValueError listing the valid names."""
    try:
        return CMG_GEOMETRIES[kind]
    except (KeyError, TypeError):
        raise ValueError(f"unknown CMG kind {kind!r}; valid: {', '.join(CMG_GEOMETRIES)}") from None


def cmg_geometry(cfg) -> CmgGeometry:
    """The geometry of a scene's ``[cmg]`` table (its kind, with its number of units)."""
    return get_geometry(cfg.kind)(cfg.n_units)


def capacity(cfg) -> float:
    """Momentum capacity of a scene's cluster [N m s] (inf without a limit); see the kinds'
    ``_capacity``: ideal ``max_momentum``, dgcmg ``n h_rotor``, pyramid
    ``h_rotor min(2 + 2 cos β, 4 sin β)``, of the working units (``[cmg] failed`` left out)."""
    return cmg_geometry(cfg).capacity(cfg)


def held_momentum_B(cfg) -> np.ndarray:
    """The failed units' (held) rotor momentum of a scene's cluster, B components [N m s], shape
    (3,); ``h`` minus it is the working units' momentum, which :func:`capacity` bounds."""
    return cmg_geometry(cfg).held_momentum_B(cfg)


@dataclass(frozen=True)
class CmgModel:
    """The cluster's symbolic model for one scene structure ``(kind, n_units, steering)``.

    State ``xc`` (``nx``: the gimbal angles, or ``h`` for a momentum store), held input ``uc``
    (``nu``: gimbal rates, or the torque command) and the cluster's slice ``pc`` of the parameter
    vector (``n_par``: :data:`~stationbed.model.cmg.base.HEAD_PAR` numbers, then the geometry;
    :meth:`params`). The geometry (:attr:`geometry`, from :data:`CMG_GEOMETRIES`) writes the
    kind-specific parts; the methods here check sizes and delegate.

    Parameters
    ----------
    kind : str  A :data:`CMG_GEOMETRIES` name.
    n_units : int  Number of units.
    steering : str  Steering law (``"none"`` for a cluster without gimbals).
    unit_faults : bool  Whether scheduled faults may change a unit's ``rotor`` or ``rate_cap``
        (:attr:`~stationbed.model.cmg.base.CmgGeometry.unit_faults`).
    """

    kind: str
    n_units: int
    steering: str
    unit_faults: bool = True
    geometry: CmgGeometry = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "geometry", get_geometry(self.kind)(self.n_units))
        self.geometry.unit_faults = bool(self.unit_faults)
        if self.geometry.gimballed and self.steering not in STEERING_LAWS:
            raise ValueError(f"unknown steering law {self.steering!r}; valid: {', '.join(STEERING_LAWS)}")

    @classmethod
    def of(cls, cfg) -> "CmgModel":
        """The model of a scene's ``[cmg]`` table."""
        return cls(cfg.kind, cfg.n_units, cfg.steering)

    # -- layout ----------------------------------------------------------------------
    @property
    def gimballed(self) -> bool:
        """Whether the cluster has gimbals (a singularity measure, gimbal-rate commands)."""
        return self.geometry.gimballed

    @property
    def n_gimbals(self) -> int:
        """Number of gimbals (0 for a momentum store)."""
        return self.geometry.n_gimbals

    @property
    def nx(self) -> int:
        """State size: h (momentum store) or the gimbal angles."""
        return self.geometry.nx

    @property
    def nu(self) -> int:
        """Held input size: torque command (momentum store) or gimbal rates."""
        return self.geometry.nu

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the cluster's states (``hx, hy, hz`` or the gimbal names)."""
        return self.geometry.state_names

    @property
    def state_kinds(self) -> tuple[str, ...]:
        """Per state ``"momentum"`` or ``"attitude"`` (the units of its atol)."""
        return (self.geometry.state_kind,) * self.nx

    @property
    def gimbal_names(self) -> list[str]:
        """Gimbal names in state order (the run's columns)."""
        return self.geometry.gimbal_names

    @property
    def n_par(self) -> int:
        """Size of the cluster's slice of p."""
        return self.geometry.n_par

    # -- numbers -----------------------------------------------------------------------
    def params(self, cfg) -> np.ndarray:
        """Numbers of the scene's ``[cmg]`` table in the layout of :attr:`n_par`, shape (n_par,)."""
        return self.geometry.params(cfg)

    def initial_state(self, cfg) -> np.ndarray:
        """The cluster's state at t = 0, shape (nx,)."""
        return self.geometry.initial_state(cfg)

    # -- symbols -----------------------------------------------------------------------
    def _check(self, xc, pc, uc=None) -> None:
        if xc.numel() != self.nx or pc.numel() != self.n_par or (uc is not None and uc.numel() != self.nu):
            raise ValueError(
                f"{self.kind}: state/input/params of sizes {xc.numel()}/{None if uc is None else uc.numel()}/"
                f"{pc.numel()}, expected {self.nx}/{self.nu}/{self.n_par}"
            )

    def h(self, xc, pc):
        """Cluster momentum relative to the body, B components [N m s] (casadi (3, 1))."""
        self._check(xc, pc)
        return self.geometry.h(xc, pc)

    def A_hat(self, xc, pc):
        """Normalised Jacobian ``∂h/∂δ / h_rotor`` (analytic), shape (3, n_gimbals) [1/rad]
        (gimballed kinds)."""
        self._check(xc, pc)
        return self._gimballed().A_hat(xc, pc)

    def singularity(self, xc, pc):
        """Singularity measure ``sqrt(det(Â Âᵀ))`` (gimballed kinds; casadi scalar)."""
        self._check(xc, pc)
        return self._gimballed().singularity(xc, pc)

    def _gimballed(self) -> GimballedGeometry:
        if not self.gimballed:
            raise ValueError(f"CMG kind {self.kind!r} has no gimbals")
        return self.geometry

    def h_dot(self, xc, uc, omega_BN_B, pc):
        """Body-frame derivative of h [N m]: ``-τ - ω × h`` (momentum store) or ``A δ̇``."""
        self._check(xc, pc, uc)
        return self.geometry.h_dot(xc, uc, omega_BN_B, pc)

    def state_dot(self, xc, uc, omega_BN_B, pc):
        """Derivative of the cluster's state (casadi (nx, 1))."""
        self._check(xc, pc, uc)
        return self.geometry.state_dot(xc, uc, omega_BN_B, pc)

    def actuate(self, t, xc, tau_cmd, omega_BN_B, pc, direct_rates=None):
        """The held input for one control period, from a body-torque request (or direct rates).

        Returns ``(u_held, singularity, rate_limited, momentum_saturated)``; the flags are 0/1.
        ``omega_BN_B`` is the body rate at the tick (the ``ω × h`` compensation of the torque
        request). See :meth:`CmgGeometry.actuate`.
        """
        self._check(xc, pc)
        return self.geometry.actuate(t, xc, tau_cmd, omega_BN_B, pc, self.steering, direct_rates)


def cluster_functions(cfg) -> dict[str, ca.Function]:
    """Numeric casadi Functions of a scene's ``[cmg]`` table (for tests and controllers).

    ``h(x) -> h_B`` [N m s]; ``A(x) -> ∂h/∂x`` (gimballed kinds: [N m s/rad]); ``actuate(t, x,
    tau, w) -> (u, m, rate_limited, saturated)``. Parameters are baked in. The Functions of a
    table are built once per process (a Monte Carlo runs thousands of closed loops on a few
    distinct clusters) and shared: casadi Functions are immutable.
    """
    key = cfg.model_dump_json()
    if key not in _CLUSTER_FUNCTIONS:
        if len(_CLUSTER_FUNCTIONS) >= _CLUSTER_FUNCTIONS_MAX:
            _CLUSTER_FUNCTIONS.clear()
        _CLUSTER_FUNCTIONS[key] = _cluster_functions(cfg)
    return dict(_CLUSTER_FUNCTIONS[key])


#: cluster_functions of the tables seen in this process, by the table's JSON
_CLUSTER_FUNCTIONS: dict[str, dict] = {}
_CLUSTER_FUNCTIONS_MAX = 64


def _cluster_functions(cfg) -> dict[str, ca.Function]:
    model = CmgModel.of(cfg)
    p = ca.DM(model.params(cfg))
    x = ca.SX.sym("x", model.nx)
    tau = ca.SX.sym("tau", 3)
    w = ca.SX.sym("w", 3)
    t = ca.SX.sym("t")
    h = model.h(x, p)
    out = {
        "h": ca.Function("h", [x], [h]),
        "actuate": ca.Function("actuate", [t, x, tau, w], list(model.actuate(t, x, tau, w, p))),
    }
    if model.gimballed:
        out["A"] = ca.Function("A", [x], [cfg.h_rotor * model.A_hat(x, p)])
    return out
