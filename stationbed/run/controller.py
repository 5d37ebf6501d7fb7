"""The controller extension point (DESIGN §7): base class, measurement, plant facts, registry.

A controller runs on an integer tick clock at its own ``period``; the simulation holds each
command constant over the period (zero-order hold). Per tick it receives a
:class:`Measurement` and returns a command:

* ``command = "torque"``: a body-torque request ``tau_B`` (3,) [N m] for the CMG steering law
  (the cluster delivers it within its limits; a scene without a CMG applies it directly, as an
  ideal torquer);
* ``command = "gimbal_rates"``: gimbal rates (n_gimbals,) [rad/s], bypassing the steering law
  (the rate limit still applies, and is reported).

Rules for implementers (the scipy ``OdeSolver`` pattern):

1. Set ``name`` (registry name), ``command`` and ``Params``, a pydantic model of the
   parameters (``extra="forbid"`` is inherited from :class:`ControllerParams`: an unknown
   parameter is an error naming it).
2. Write ``_reset(plant)`` (design gains from the :class:`Plant` facts; it runs once per run)
   and ``_update(t, meas)`` returning the command as a sequence of floats.
3. Set ``self.q_ref_BN`` (4,) in ``_update`` when the law has a reference attitude: the run
   logs ``att_err_deg`` against it.
4. ``meas`` arrays are views refreshed in place every tick: copy what you keep.
5. Optionally, for the fused loop (stationbed/run/fused.py: controller and dynamics in one
   compiled loop), write ``symbolic_params()`` (the law's numbers as a flat array, set by
   ``_reset``) and ``symbolic(t, y, cp) -> (command, q_ref_BN)`` with casadi ``t``, ``y`` (the
   measurement vector, offsets from :func:`measurement_layout`) and ``cp``; it must compute
   what ``_update`` computes (a test runs both) and keep no state between ticks.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

__all__ = [
    "Controller",
    "ControllerParams",
    "Measurement",
    "Plant",
    "ControllerError",
    "get_controller",
    "controller_registry",
    "measurement_layout",
    "UnitQuaternion",
]

#: A quaternion typed by a person (~8 digits) is unit to ~1e-8; further off is a mistake.
QUAT_PARAM_TOL = 1e-6


def _unit_quaternion(q: list[float]) -> list[float]:
    n = math.sqrt(sum(v * v for v in q))
    if abs(n - 1.0) > QUAT_PARAM_TOL:
        raise ValueError(f"quaternion norm is {n:.9g}, not 1")
    return [v / n for v in q]


#: A scalar-first unit quaternion parameter (normalised; a norm off by > 1e-6 is an error).
UnitQuaternion = Annotated[list[float], Field(min_length=4, max_length=4), AfterValidator(_unit_quaternion)]


class ControllerError(ValueError):
    """A controller that cannot be built (unknown name, bad parameters)."""


class ControllerParams(BaseModel):
    """Base of every controller's parameter model: unknown keys and NaN/inf are errors."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def measurement_layout(n_gimbals: int, n_app: int) -> dict[str, tuple[int, int]]:
    """Name -> (offset, size) of the measurement vector the compiled ``meas`` function writes."""
    sizes = [
        ("q_BN", 4),
        ("omega_BN_B", 3),
        ("h_B", 3),
        ("gimbal", n_gimbals),
        ("alpha", n_app),
        ("beta", n_app),
        ("r_N", 3),
        ("C_ON", 9),
        ("q_ON", 4),
        ("sun_N", 3),
    ]
    out, n = {}, 0
    for name, k in sizes:
        out[name] = (n, k)
        n += k
    return out


class Measurement:
    """What a controller sees at a tick; every field is a numpy view refreshed in place.

    Attributes
    ----------
    t : float  Time of the tick [s].
    q_BN : (4,)  Attitude quaternion of B relative to N, scalar first.
    omega_BN_B : (3,)  Body rate, B components [rad/s].
    h_B : (3,)  CMG cluster momentum, B components [N m s] (zeros without a cluster).
    gimbal : (n_gimbals,)  Gimbal angles [rad] (dgcmg: outer, inner per unit).
    alpha, beta : (n_arrays,)  Array joint angles [rad].
    r_N : (3,)  Station position, N components [m] (zeros without an orbit).
    C_ON : (3, 3)  DCM from N to LVLH (identity without an orbit).
    q_ON : (4,)  The same as a quaternion, continuous in time (``dcm(q_ON) = C_ON``).
    sun_N : (3,)  Unit vector to the sun, N components (zeros without a [sun] table).
    """

    __slots__ = ("t", "y", "q_BN", "omega_BN_B", "h_B", "gimbal", "alpha", "beta", "r_N", "C_ON", "q_ON", "sun_N")

    def __init__(self, y: np.ndarray, layout: dict[str, tuple[int, int]]):
        self.t = 0.0
        self.y = y
        for name, (o, k) in layout.items():
            v = y[o : o + k]
            setattr(self, name, v.reshape(3, 3) if name == "C_ON" else v)


@dataclass
class Plant:
    """Facts about the plant a controller may design with (from the scene, at t = 0).

    inertia_O_B : (3, 3)  Total inertia about the composite mass centre, B axes [kg m²].
    mean_motion : float or None  Orbital rate n [rad/s]; None in deep space.
    cmg_kind : str or None  "ideal", "dgcmg", "sgcmg_pyramid" or None.
    h_capacity : float  Cluster momentum capacity [N m s] (inf without a limit).
    max_torque : float  Torque limit of an ideal cluster [N m] (inf when none).
    n_gimbals : int ; max_gimbal_rate : float [rad/s] ; h_rotor : float [N m s]
    cmg_functions : dict of casadi Functions ``h``, ``A``, ``actuate`` (see cmg.cluster_functions)
    period : float  Controller period [s].
    """

    scene: Any
    inertia_O_B: np.ndarray
    mean_motion: float | None
    period: float
    cmg_kind: str | None = None
    h_capacity: float = math.inf
    max_torque: float = math.inf
    n_gimbals: int = 0
    max_gimbal_rate: float = math.inf
    h_rotor: float = 0.0
    cmg_functions: dict = field(default_factory=dict)


class Controller:
    """Base class of attitude laws; see the module docstring for the contract."""

    name: ClassVar[str] = ""
    command: ClassVar[str] = "torque"
    Params: ClassVar[type[ControllerParams]] = ControllerParams

    def __init__(self, period: float = 0.1, **params):
        if not (period > 0 and math.isfinite(period)):
            raise ControllerError(f"controller period must be a positive number of seconds, got {period}")
        self.period = float(period)
        try:
            self.params = self.Params(**params)
        except ValidationError as e:
            err = e.errors()[0]
            where = ".".join(str(x) for x in err["loc"])
            if err["type"] == "extra_forbidden":
                valid = ", ".join(self.Params.model_fields) or "(none)"
                raise ControllerError(
                    f"controller '{self.name}': unknown parameter '{where}'; valid: {valid}"
                ) from None
            field = f"params.{where}" if where else "params"
            msg = err["msg"].removeprefix("Value error, ")
            raise ControllerError(f"controller '{self.name}': {field}: {msg}") from None
        self.q_ref_BN: np.ndarray | None = None
        self.n_updates = 0
        self.plant: Plant | None = None

    def reset(self, plant: Plant) -> None:
        """Prepare for a run (design gains); called once before the first tick."""
        self.plant = plant
        self.n_updates = 0
        self.q_ref_BN = None
        self._reset(plant)

    def update(self, t: float, meas: Measurement):
        """The command for the period starting at ``t`` [s] (counted in ``n_updates``).

        Parameters
        ----------
        t : float  Time of the tick [s].
        meas : Measurement  What the controller sees (views refreshed in place).

        Returns
        -------
        sequence of float  ``tau_B`` (3,) [N m] or gimbal rates (n_gimbals,) [rad/s], per ``command``.
        """
        self.n_updates += 1
        return self._update(t, meas)

    def count_compiled_updates(self, n: int) -> None:
        """Count ``n`` updates that the controller's :meth:`symbolic` form made inside a compiled
        loop (the fused loop of :mod:`stationbed.run.fused`), where :meth:`update` is not called."""
        self.n_updates += int(n)

    def summary(self) -> dict:
        """Design facts to report (poles, margins...); empty by default."""
        return {}

    # -- plug-in -------------------------------------------------------------------------
    def _reset(self, plant: Plant) -> None:
        pass

    def _update(self, t: float, meas: Measurement):  # pragma: no cover - abstract
        raise NotImplementedError


#: Entry-point group of controllers: the shipped laws (pyproject.toml) and any installed package's.
ENTRY_POINT_GROUP = "stationbed.controllers"


def _entry_points():
    return {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}


def _load(ep) -> type[Controller]:
    cls = ep.load()
    if not (isinstance(cls, type) and issubclass(cls, Controller)):
        raise ControllerError(f"controller entry point '{ep.name}' ({ep.value}) is not a Controller subclass")
    return cls


def controller_registry() -> dict[str, type[Controller]]:
    """Every registered controller by scene name (entry points of :data:`ENTRY_POINT_GROUP`)."""
    return {name: _load(ep) for name, ep in sorted(_entry_points().items())}


def get_controller(name: str) -> type[Controller]:
    """A controller class from a registry name or ``module:Class``."""
    if ":" in name:
        mod_name, _, cls_name = name.partition(":")
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as e:
            raise ControllerError(f"controller '{name}': cannot import module '{mod_name}' ({e})") from None
        cls = getattr(mod, cls_name, None)
        if not (isinstance(cls, type) and issubclass(cls, Controller)):
            raise ControllerError(f"controller '{name}': '{cls_name}' is not a Controller subclass in '{mod_name}'")
        return cls
    eps = _entry_points()
    if name not in eps:
        raise ControllerError(f"unknown controller '{name}'; valid: {', '.join(sorted(eps))} or module:Class")
    return _load(eps[name])
