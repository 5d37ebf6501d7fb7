"""The tables of a scene file (DESIGN §5): simulation, initial state, body, appendages and their
joints and modes, orbit, torques, sun, CMG cluster, controller and sensor."""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal, NamedTuple, Union

import numpy as np
from pydantic import Discriminator, Field, PrivateAttr, Tag, field_validator, model_validator

from ..core.constants import MU_EARTH_M3_S2, R_EARTH_M
from ..core.beam import beam_inertia_derivative, beam_mode, check_participation
from ..core.massprops import InvalidMassProperties, checked_inertia_rows
from .base import TIME_RESOLUTION, Atol, Direction, FieldError, Mat3, Rtol, Strict, TimeS, Vec3, unit_quaternion
from .environment import (  # noqa: F401  (re-exported: the scene's tables are all here)
    SURFACE_FRACTIONS_DEFAULT, AeroTorque, Atmosphere, ConstantTorque, Elements, HarmonicTorque, Orbit, SrpTorque, Sun,
    Surface, Torque,
)
from .wing import AxisName, Wing, WingBending, wing_beam
from .montecarlo import DISPERSION_KINDS, Dispersion, MonteCarlo, Requirement  # noqa: F401

__all__ = [
    "RateStep", "Profile", "SunTrack", "Joint", "Simulation", "Initial", "Body", "Beam", "Mode", "Appendage",
    "Orbit", "Elements", "ConstantTorque", "HarmonicTorque", "Torque", "Sun", "CmgKind", "CMG_KINDS", "UNIT_KEYS", "Cmg",
    "Sensor", "ControllerSpec", "PYRAMID_SKEW_RAD", "PARTICIPATION_TOL", "MU_EARTH_M3_S2", "R_EARTH_M", "TAGS",
    "AeroTorque", "SrpTorque", "Surface", "Atmosphere", "SURFACE_FRACTIONS_DEFAULT",
    "Dispersion", "Requirement", "MonteCarlo", "DISPERSION_KINDS", "Wing", "WingBending",
]

class RateStep(Strict):
    """An instantaneous change of a joint rate by ``delta`` [rad/s] at time ``t`` [s] (an impulse)."""

    t: float = Field(gt=0.0)
    delta: float


class Profile(Strict):
    """Joint-angle profile ``a0 + rate t + amp sin(freq t + phase) + Σ delta_k max(0, t - t_k)``.

    Units: rad, rad/s, rad, rad/s, rad; ``rate_step`` lists instantaneous rate changes.
    """

    a0: float = 0.0
    rate: float = 0.0
    amp: float = 0.0
    freq: float = 0.0
    phase: float = 0.0
    rate_step: list[RateStep] = []

    tracked: ClassVar[bool] = False

    def coeffs(self) -> list[float]:
        """``[a0, rate, amp, freq, phase]`` as the model's parameter vector takes them."""
        return [self.a0, self.rate, self.amp, self.freq, self.phase]


class SunTrack(Strict):
    """Closed-loop sun tracking of one joint (SARJ ``alpha`` or BGA ``beta``).

    Drive law: ``rate_cmd = clip(gain * wrap(θ* - θ) + θ̇*, ±max_rate)``,
    ``θ̈ = clip((rate_cmd - θ̇) / rate_tau, ±max_acc)``: rate and acceleration stay bounded.
    """

    track: Literal["sun"]
    a0: float | None = None  # rad; default: start on the target angle
    rate0: float = 0.0  # rad/s
    max_rate: float = Field(default=0.01, gt=0.0)  # rad/s
    max_acc: float = Field(default=1.0e-4, gt=0.0)  # rad/s²
    gain: float = Field(default=0.05, gt=0.0)  # 1/s, angle loop
    rate_tau: float = Field(default=5.0, gt=0.0)  # s, rate loop time constant
    # in eclipse: keep tracking the sun, or turn edge-on to the flow (needs [sun] eclipse)
    night: Literal["track", "glider"] = "track"

    tracked: ClassVar[bool] = True


def _joint_tag(v) -> str:
    if isinstance(v, dict):
        return "track" if "track" in v else "profile"
    return "track" if getattr(v, "tracked", False) else "profile"


Joint = Annotated[
    Union[Annotated[SunTrack, Tag("track")], Annotated[Profile, Tag("profile")]], Discriminator(_joint_tag)
]
#: pydantic's union tags -> the model they select (tags are not user keys)
TAGS = {}


class Simulation(Strict):
    """``[simulation]``: duration [s], formulation, integrator, rtol, atol (dimensionless), output_dt [s],
    step [s] for fixed-step integrators.

    Times are at least ``MIN_TIME_S`` and the intervals at least ``TIME_RESOLUTION`` of the
    duration; ``rtol`` lies in [``RTOL_MIN``, 1), ``atol`` is at least ``ATOL_MIN`` (see base.py
    for the reasons)."""
    duration: TimeS
    formulation: str = "momentum"
    integrator: str = "dop853"
    rtol: Rtol = 1e-9
    atol: Atol = 1e-12
    output_dt: TimeS = 10.0
    step: TimeS | None = None  # fixed-step integrators [s]
    max_step: TimeS | None = None  # adaptive integrators [s]
    # at an array-rate step (impulse), re-initialise omega-state formulations so that H is
    # continuous (omega jumps); false integrates through it (the stability study's failure case)
    impulse_jump: bool = True
    # the environment torques (aero, SRP; kinds with needs_env) evaluated once every this many
    # control ticks in the fused loop, held at their extrapolated mid-block value; 0 = at every
    # integrator stage; "auto" = the largest rate whose proven bound is inside 1e-6 rad
    # (run/rate_auto.py; docs/design.md "Effects at their own rate")
    environment_rate: Any = "auto"  # "auto" or int >= 0 (checked below: one message, not a union's two)

    @field_validator("environment_rate", mode="before")
    @classmethod
    def _rate(cls, v):
        if v == "auto" or (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
            return v
        raise ValueError(f'must be "auto" or a whole number of ticks >= 0 (0: every stage), got {v!r}')

    @model_validator(mode="after")
    def _resolved(self):
        for key in ("output_dt", "step", "max_step"):
            dt = getattr(self, key)
            if dt is not None and dt < TIME_RESOLUTION * self.duration:
                raise FieldError(key, f"{dt:g} s is below {TIME_RESOLUTION:g} of the duration ({self.duration:g} s), "
                                      "finer than the time grid resolves")
        return self


class Initial(Strict):
    """``[initial]``: ``q_BN`` (scalar first) and ``omega_BN_B`` [rad/s], relative to N or to LVLH
    (``frame = "lvlh"``)."""
    q_BN: Annotated[list[float], Field(min_length=4, max_length=4)] = [1.0, 0.0, 0.0, 0.0]
    omega_BN_B: Vec3 = [0.0, 0.0, 0.0]
    frame: Literal["inertial", "lvlh"] = "inertial"

    @field_validator("q_BN")
    @classmethod
    def _unit(cls, q):
        return unit_quaternion(q)


class Body(Strict):
    """``[body]``: mass [kg], inertia about its own mass centre [kg m²] (B axes), mass centre ``cm`` in B [m]."""
    mass: float = Field(gt=0.0)
    inertia: Mat3
    cm: Vec3 = [0.0, 0.0, 0.0]

    @field_validator("inertia")
    @classmethod
    def _physical(cls, J):
        if J is None:  # an appendage's wing gives it (Appendage)
            return J
        try:
            return checked_inertia_rows(J, "inertia")
        except InvalidMassProperties as e:
            raise ValueError(str(e).removeprefix("inertia: ")) from None


class Beam(Strict):
    """A uniform Euler–Bernoulli cantilever standing for the array in one mode (P axes).

    It runs from ``root`` (m, relative to the array's mass centre) a ``length`` along ``span``
    and bends along ``deflection``; ``n`` is the mode number (1..6); ``mass`` defaults to the
    array's. The shape is normalised to 1 at the tip, so the mode's coordinate is the tip
    deflection [m]."""

    length: float = Field(gt=0.0)
    span: AxisName
    deflection: AxisName
    root: Vec3 = [0.0, 0.0, 0.0]
    n: int = Field(default=1, ge=1, le=6)
    mass: float | None = Field(default=None, gt=0.0)

    @model_validator(mode="after")
    def _axes(self):
        if self.span.lstrip("+-") == self.deflection.lstrip("+-"):
            raise ValueError(f"span ({self.span}) and deflection ({self.deflection}) must be different axes")
        return self


class Mode(Strict):
    """One elastic mode of an array (Quinn Eq. 22–24): its clamped frequency, damping ratio and
    shape, given either by a ``beam`` or by the participation integrals directly:
    ``translation`` = ∫Φ dm [kg], ``rotation`` = ∫ a × Φ dm about the array's mass centre
    [kg m] (P axes), ``modal_mass`` = ∫ΦᵀΦ dm [kg] and, optionally, ``inertia_derivative`` =
    ∂J/∂η = ∫(2 a·Φ E - aΦᵀ - Φaᵀ) dm [kg m] (symmetric, P axes; default 0: the array's own
    inertia then does not change with η, while its mass centre's shift by ``translation`` η / m
    still counts)."""

    frequency_hz: float = Field(gt=0.0)
    damping: float = Field(default=0.0, ge=0.0, lt=1.0)
    beam: Beam | None = None
    wing: WingBending | None = None  # a wing's bending: the beam from the appendage's wing (scene/wing.py)
    translation: Vec3 | None = None
    rotation: Vec3 | None = None
    modal_mass: float | None = Field(default=None, gt=0.0)
    inertia_derivative: Mat3 | None = None  # ∂J/∂η [kg m], P axes, symmetric
    eta0: float = 0.0  # initial modal coordinate
    eta_rate0: float = 0.0  # initial modal rate [1/s x coordinate]
    _wing_beam: Beam | None = PrivateAttr(default=None)  # the beam of ``wing``, set by its Appendage

    @model_validator(mode="after")
    def _one_shape(self):
        direct = self.translation is not None or self.rotation is not None or self.modal_mass is not None
        if (self.beam is not None) + (self.wing is not None) + direct != 1:
            raise ValueError("give a mode one of 'beam', 'wing' or 'translation'/'rotation' (with 'modal_mass')")
        if direct and self.modal_mass is None:
            raise ValueError("a mode given by 'translation'/'rotation' needs 'modal_mass' [kg]")
        if self.inertia_derivative is not None:
            if not direct:
                raise ValueError("'inertia_derivative' is computed from the beam; give it only with 'translation'/'rotation'")
            D = np.array(self.inertia_derivative)
            if np.abs(D - D.T).max() > 1e-9 * max(np.abs(D).max(), 1e-300):
                raise ValueError("inertia_derivative: must be symmetric")
        return self

    @property
    def shape_beam(self) -> Beam | None:
        """The mode's beam: ``beam``, or the one derived from the appendage's wing (``wing``)."""
        return self.beam if self.beam is not None else self._wing_beam

    def integrals(self, array_mass: float):
        """``(Φ̄, Ĥ, M)`` in P axes (Quinn Eq. 24a, 24b, 24e)."""
        if self.shape_beam is not None:
            b = self.shape_beam
            return beam_mode(b.n, b.length, b.mass or array_mass, b.root, b.span, b.deflection)
        zero = [0.0, 0.0, 0.0]
        return np.array(self.translation or zero), np.array(self.rotation or zero), float(self.modal_mass)

    def inertia_derivative_P(self, array_mass: float) -> np.ndarray:
        """``∂J/∂η`` [kg m], (3, 3), P axes: the first-order change of the array's inertia about its
        mass centre per unit of η (from the beam, or as given; zero when not given)."""
        if self.shape_beam is not None:
            b = self.shape_beam
            return beam_inertia_derivative(b.n, b.length, b.mass or array_mass, b.root, b.span, b.deflection)
        return np.zeros((3, 3)) if self.inertia_derivative is None else np.array(self.inertia_derivative)

    @property
    def omega(self) -> float:
        """Clamped circular frequency [rad/s]."""
        return 2.0 * math.pi * self.frequency_hz


#: the modes may take all of an array's mass or inertia in some direction, not more (see
#: :func:`stationbed.core.beam.check_participation`; rounding of typed numbers allowed)
PARTICIPATION_TOL = 1e-9


class Appendage(Body):
    """``[[appendage]]``: an articulated array (mass, inertia about its mass centre in P, ``cm`` in B,
    ``alpha``/``beta`` joint profiles or sun tracking, optional elastic modes).

    Exactly one of ``inertia`` and ``wing``: a wing pair (scene/wing.py) derives the inertia
    (:attr:`inertia_P`), its ``[[surface]]`` plate and the beams of its ``mode.wing`` modes."""
    name: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
    inertia: Mat3 | None = None
    wing: Wing | None = None
    _J_P: tuple | None = PrivateAttr(default=None)  # rows (a tuple: scenes compare equal by value)
    alpha: Joint = Field(default_factory=Profile)  # (a table of its own per scene: scene/knowledge.py)
    beta: Joint = Field(default_factory=Profile)
    mode: list[Mode] = []

    @property
    def tracks_sun(self) -> bool:
        """Whether either joint tracks the sun."""
        return self.alpha.tracked or self.beta.tracked

    @property
    def inertia_P(self) -> np.ndarray:
        """The inertia about its mass centre [kg m²], P axes, (3, 3): ``inertia`` or the wing's."""
        return np.array(self._J_P, float)

    @model_validator(mode="after")
    def _derived(self):
        if (self.inertia is None) == (self.wing is None):
            raise FieldError("wing" if self.wing is not None else "inertia",
                             "give 'inertia' (P axes) or 'wing' (the array once: its inertia, plate and beams "
                             "derived), " + ("not both" if self.wing is not None else "one of them is missing"))
        J = np.array(self.inertia, float) if self.wing is None else self.wing.inertia_P(self.mass)
        self._J_P = tuple(map(tuple, J.tolist()))
        for i, m in enumerate(self.mode):
            if m.wing is not None:
                if self.wing is None:
                    raise FieldError(f"mode[{i}].wing", f"bends a wing: '{self.name}' declares none (add wing = {{...}})")
                m._wing_beam = Beam(**wing_beam(self.wing, m.wing, self.mass))
        if self.mode:
            left = check_participation(self.mass, J, [m.integrals(self.mass) for m in self.mode])
            if left < -PARTICIPATION_TOL:
                raise ValueError(
                    f"modes of '{self.name}' take more than its mass or inertia (effective-mass residual "
                    f"{left:.3g} < 0): lower translation/rotation, raise modal_mass, or check the beam's mass and root"
                )
        return self


#: Default skew of the four-CMG pyramid, atan(4/3) = 53.13 deg (Wie) [rad].
PYRAMID_SKEW_RAD = math.atan2(4.0, 3.0)


class CmgKind(NamedTuple):
    """What the schema knows of one ``[cmg] kind`` (its physics: ``stationbed.model.cmg``, one
    module per kind, whose registry must list the same kinds)."""

    #: fixed number of units (0: a momentum store without units); None: ``count``, default 4
    units: int | None
    #: gimbals per unit
    gimbals: int
    #: which of the unit keys (``UNIT_KEYS``) apply to the kind
    keys: tuple[str, ...]


#: the optional keys that describe a cluster's units; each kind says which apply to it
UNIT_KEYS = ("count", "outer_axes_B", "gimbal0")
CMG_KINDS = {
    "ideal": CmgKind(units=0, gimbals=0, keys=()),
    "dgcmg": CmgKind(units=None, gimbals=2, keys=("count", "outer_axes_B", "gimbal0")),
    "sgcmg_pyramid": CmgKind(units=4, gimbals=1, keys=("count", "gimbal0")),
}


class Cmg(Strict):
    """The CMG cluster (issue 3). See stationbed/model/cmg/ for the models and steering laws."""

    kind: Literal[tuple(CMG_KINDS)]
    # ideal: a momentum store h driven by the torque command
    max_torque: float | None = Field(default=None, gt=0.0)  # N m, |tau| limit (ideal)
    max_momentum: float | None = Field(default=None, gt=0.0)  # N m s, |h| limit (ideal)
    h0_B: Vec3 = [0.0, 0.0, 0.0]  # N m s, initial momentum (ideal)
    # gimballed kinds
    count: int | None = Field(default=None, ge=1, le=12)  # dgcmg units (default 4; pyramid is 4)
    h_rotor: float = Field(default=4760.0, gt=0.0)  # N m s per unit (ISS CMG)
    max_gimbal_rate: float = Field(default=0.0175, gt=0.0)  # rad/s, per gimbal
    skew: float = Field(default=PYRAMID_SKEW_RAD, gt=0.0, lt=math.pi / 2)  # rad, pyramid
    outer_axes_B: list[Direction] | None = None  # dgcmg outer-gimbal axes (unit vectors, B)
    gimbal0: list[float] | None = None  # rad, initial gimbal angles (default: zero momentum)
    steering: Literal["mp", "sr", "odsr"] = "sr"
    sr_lambda0: float = Field(default=0.01, ge=0.0)  # SR / o-DSR gain scale (Wie 2005)
    sr_mu: float = Field(default=10.0, ge=0.0)  # λ = λ0 exp(-μ det(Â Âᵀ))
    dither_eps0: float = Field(default=0.01, ge=0.0)  # o-DSR off-diagonal amplitude
    dither_omega: float = Field(default=math.pi / 2, gt=0.0)  # rad/s, o-DSR dither frequency
    saturation_fraction: float = Field(default=0.9, gt=0.0, le=1.0)  # |h| / capacity flagged saturated
    failed: list[int] = []  # failed units (1-based, as in gimbal_<unit>_...): gimbals held, no steering

    @model_validator(mode="after")
    def _consistent(self):
        spec = CMG_KINDS[self.kind]
        if spec.units and self.count not in (None, spec.units):
            raise ValueError(f"{self.kind} has exactly {spec.units} units")
        for key in UNIT_KEYS:
            if getattr(self, key) is not None and key not in spec.keys:
                where = " or ".join(f"'{k}'" for k, other in CMG_KINDS.items() if key in other.keys)
                raise ValueError(f"'{key}' applies to kind = {where}, not kind = '{self.kind}'")
        if self.outer_axes_B is not None:
            if len(self.outer_axes_B) != self.n_units:
                raise ValueError(f"outer_axes_B needs {self.n_units} axes, got {len(self.outer_axes_B)}")
        if self.failed and (CMG_KINDS[self.kind].gimbals == 0 or len(set(self.failed)) != len(self.failed)
                            or not all(1 <= u <= self.n_units for u in self.failed)):
            raise FieldError("failed", f"must be distinct unit numbers 1..{self.n_units} of a gimballed cluster, "
                                       f"got {self.failed}")
        if self.gimbal0 is not None and len(self.gimbal0) != self.n_gimbals:
            raise ValueError(
                f"gimbal0 needs {self.n_gimbals} angles for {self.kind} x {self.n_units}, got {len(self.gimbal0)}"
            )
        return self

    @property
    def n_units(self) -> int:
        """Number of CMG units of the cluster (0 for an ideal momentum store)."""
        units = CMG_KINDS[self.kind].units
        return units if units is not None else (self.count or 4)

    @property
    def n_gimbals(self) -> int:
        """Number of gimbals of the cluster."""
        return self.n_units * CMG_KINDS[self.kind].gimbals


class Sensor(Strict):
    """Measurement errors seen by the controller (truth is logged unchanged)."""

    attitude_noise: float = Field(default=0.0, ge=0.0)  # rad, 1 sigma per axis (small rotation)
    rate_noise: float = Field(default=0.0, ge=0.0)  # rad/s, 1 sigma per axis
    delay: float = Field(default=0.0, ge=0.0)  # s, whole controller periods
    seed: int = Field(default=0, ge=0)  # numpy's random generator takes a non-negative integer


class ControllerSpec(Strict):
    """``[controller]``: a registry name (controllers/) or ``module:Class``, an FMI
    co-simulation unit (``fmu``, issue 23) or a law in another process (``port``, issue 36:
    docs/socket_law.md), its period and parameters."""

    name: str = ""
    fmu: str | None = None  # path of a co-simulation FMU, relative to the scene file's folder
    port: str | None = None  # "host:port" (or "port": 127.0.0.1) of a law process (run/socket_law.py)
    command: Literal["torque", "gimbal_rates"] | None = None  # a socket law's command (default torque)
    timeout: TimeS = 5.0  # s: a socket law's reply later than this stops the run
    variables: dict[str, str] = {}  # FMU laws: loop name -> FMU variable (stationbed/run/fmu.py)
    period: TimeS = 0.1  # s
    params: dict[str, Any] = {}
    sensor: Sensor = Field(default_factory=Sensor)  # (a table of its own per scene: scene/knowledge.py)

    @model_validator(mode="after")
    def _law(self):
        given = [(k, v) for k, v in (("name", self.name or None), ("fmu", self.fmu), ("port", self.port)) if v is not None]
        if not given:
            raise FieldError("name", "give the law: name = \"pd\" (or module:Class), fmu = \"path/law.fmu\" "
                             "or port = \"127.0.0.1:5555\"")
        if len(given) > 1:
            raise FieldError(given[1][0], f"give {' or '.join(f'{k} = {v!r}' for k, v in given)}, not both")
        if self.port is not None and not self.port.strip():
            raise FieldError("port", "is empty: give the law process's \"host:port\"")
        if self.command is not None and self.port is None:
            raise FieldError("command", "is a socket law's command kind: set controller.port (a Python or FMU law "
                             "declares its own)")
        if self.fmu is not None and not self.fmu.strip():
            raise FieldError("fmu", "is empty: give the path of a co-simulation FMU")
        if self.variables and self.fmu is None:
            raise FieldError("variables", "maps the variables of an FMU law: set controller.fmu")
        return self


#: discriminator tags -> tables (the error messages name the right table's keys)
TAGS.update(constant=ConstantTorque, orbital_harmonic=HarmonicTorque, track=SunTrack, profile=Profile,
            aero=AeroTorque, srp=SrpTorque)
