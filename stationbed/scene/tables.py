"""The tables of a scene file (DESIGN §5): simulation, initial state, body, appendages and their
joints and modes, orbit, torques, sun, CMG cluster, controller and sensor."""

from __future__ import annotations

import datetime
import math
from typing import Annotated, Any, ClassVar, Literal, NamedTuple, Union

import numpy as np
from pydantic import ConfigDict, Discriminator, Field, Tag, field_validator, model_validator

from ..core.constants import MU_EARTH_M3_S2, R_EARTH_M
from ..core.kepler import KEPLER_MAX_E, elements_from_rv
from ..core.beam import beam_inertia_derivative, beam_mode, check_participation
from ..core.massprops import InvalidMassProperties, check_inertia
from .base import QUAT_NORM_TOL, TIME_RESOLUTION, Atol, FieldError, Mat3, Rtol, Strict, TimeS, Vec3

__all__ = [
    "RateStep", "Profile", "SunTrack", "Joint", "Simulation", "Initial", "Body", "Beam", "Mode", "Appendage",
    "Orbit", "Elements", "ConstantTorque", "HarmonicTorque", "Torque", "Sun", "CmgKind", "CMG_KINDS", "UNIT_KEYS", "Cmg",
    "Sensor", "ControllerSpec", "PYRAMID_SKEW_RAD", "PARTICIPATION_TOL", "MU_EARTH_M3_S2", "R_EARTH_M", "TAGS",
    "AeroTorque", "SrpTorque", "Surface", "Atmosphere", "SURFACE_FRACTIONS_DEFAULT",
    "Dispersion", "Requirement", "MonteCarlo", "DISPERSION_KINDS",
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
        n = math.sqrt(sum(x * x for x in q))
        if abs(n - 1.0) > QUAT_NORM_TOL:
            raise ValueError(f"quaternion norm is {n:.9g}, not 1 (tolerance {QUAT_NORM_TOL:g})")
        return [x / n for x in q]


class Body(Strict):
    """``[body]``: mass [kg], inertia about its own mass centre [kg m²] (B axes), mass centre ``cm`` in B [m]."""
    mass: float = Field(gt=0.0)
    inertia: Mat3
    cm: Vec3 = [0.0, 0.0, 0.0]

    @field_validator("inertia")
    @classmethod
    def _physical(cls, J):
        try:
            return check_inertia(np.array(J), "inertia").tolist()
        except InvalidMassProperties as e:
            raise ValueError(str(e).removeprefix("inertia: ")) from None


AxisName = Literal["x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z"]


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
    translation: Vec3 | None = None
    rotation: Vec3 | None = None
    modal_mass: float | None = Field(default=None, gt=0.0)
    inertia_derivative: Mat3 | None = None  # ∂J/∂η [kg m], P axes, symmetric
    eta0: float = 0.0  # initial modal coordinate
    eta_rate0: float = 0.0  # initial modal rate [1/s x coordinate]

    @model_validator(mode="after")
    def _one_shape(self):
        direct = self.translation is not None or self.rotation is not None or self.modal_mass is not None
        if (self.beam is None) == (not direct):
            raise ValueError("give a mode either 'beam' or 'translation'/'rotation' (with 'modal_mass')")
        if direct and self.modal_mass is None:
            raise ValueError("a mode given by 'translation'/'rotation' needs 'modal_mass' [kg]")
        if self.inertia_derivative is not None:
            if self.beam is not None:
                raise ValueError("'inertia_derivative' is computed from 'beam'; give it only with 'translation'/'rotation'")
            D = np.array(self.inertia_derivative)
            if np.abs(D - D.T).max() > 1e-9 * max(np.abs(D).max(), 1e-300):
                raise ValueError("inertia_derivative: must be symmetric")
        return self

    def integrals(self, array_mass: float):
        """``(Φ̄, Ĥ, M)`` in P axes (Quinn Eq. 24a, 24b, 24e)."""
        if self.beam is not None:
            b = self.beam
            return beam_mode(b.n, b.length, b.mass or array_mass, b.root, b.span, b.deflection)
        zero = [0.0, 0.0, 0.0]
        return np.array(self.translation or zero), np.array(self.rotation or zero), float(self.modal_mass)

    def inertia_derivative_P(self, array_mass: float) -> np.ndarray:
        """``∂J/∂η`` [kg m], (3, 3), P axes: the first-order change of the array's inertia about its
        mass centre per unit of η (from the beam, or as given; zero when not given)."""
        if self.beam is not None:
            b = self.beam
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
    ``alpha``/``beta`` joint profiles or sun tracking, optional elastic modes)."""
    name: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
    alpha: Joint = Profile()
    beta: Joint = Profile()
    mode: list[Mode] = []

    @property
    def tracks_sun(self) -> bool:
        """Whether either joint tracks the sun."""
        return self.alpha.tracked or self.beta.tracked

    @model_validator(mode="after")
    def _participation(self):
        if self.mode:
            left = check_participation(self.mass, np.array(self.inertia), [m.integrals(self.mass) for m in self.mode])
            if left < -PARTICIPATION_TOL:
                raise ValueError(
                    f"modes of '{self.name}' take more than its mass or inertia (effective-mass residual "
                    f"{left:.3g} < 0): lower translation/rotation, raise modal_mass, or check the beam's mass and root"
                )
        return self


def _angle_within(angle: float, low: float, high: float, text: str) -> float:
    """``angle`` [rad] if it lies in [low, high]; else a ValueError that suspects degrees."""
    if not low <= angle <= high:
        raise ValueError(f"must be within {text} rad, got {angle:g} (an angle in degrees?)")
    return angle


class Elements(Strict):
    """``[orbit] elements``: classical elements (semi-major axis [m], eccentricity, inclination,
    RAAN, argument of perigee, true anomaly at t = 0 [rad])."""
    a: float = Field(gt=0.0)
    e: float = Field(ge=0.0, lt=1.0)
    i: float
    raan: float
    argp: float
    nu: float

    @field_validator("i")
    @classmethod
    def _inclination(cls, i):
        return _angle_within(i, 0.0, math.pi, "[0, pi]")


class Orbit(Strict):
    """``[orbit]``: circular orbit (radius or altitude [m], inclination and u0 [rad], mu [m³/s²]),
    or a two-body orbit from its inertial state at t = 0 (``r_N`` [m], ``v_N`` [m/s]) or its
    classical ``elements``, optionally with J2 secular drift (``j2``); gravity gradient on or off."""
    radius: float | None = Field(default=None, gt=0.0)
    altitude: float | None = Field(default=None, gt=0.0)
    inclination: float = 0.0  # in [0, pi]
    u0: float = 0.0
    mu: float = Field(default=MU_EARTH_M3_S2, gt=0.0)
    gravity_gradient: bool = True
    r_N: Vec3 | None = None
    v_N: Vec3 | None = None
    elements: Elements | None = None
    j2: bool = False

    @field_validator("inclination")
    @classmethod
    def _inclination(cls, i):
        return _angle_within(i, 0.0, math.pi, "[0, pi]")

    @model_validator(mode="after")
    def _one_size(self):
        forms = [self.radius is not None or self.altitude is not None,
                 self.r_N is not None or self.v_N is not None, self.elements is not None]
        if sum(forms) != 1:
            raise ValueError("give exactly one of 'radius'/'altitude' (circular), 'r_N' and 'v_N', or 'elements'")
        if forms[0]:
            if self.radius is not None and self.altitude is not None:
                raise ValueError("give exactly one of 'radius' or 'altitude'")
            if self.radius is not None and self.radius <= R_EARTH_M:
                raise FieldError("radius", f"{self.radius:.10g} m is inside the Earth (equatorial radius {R_EARTH_M:.10g} m): "
                                           "give the distance from the Earth's centre, or 'altitude'")
            if self.j2:
                raise FieldError("j2", "needs a two-body orbit ('r_N' and 'v_N', or 'elements'), not the circular form")
            return self
        for name in ("inclination", "u0"):
            if name in self.model_fields_set:
                raise FieldError(name, "belongs to the circular form; a two-body orbit takes it from 'r_N'/'v_N' or 'elements'")
        if forms[1]:
            if self.r_N is None or self.v_N is None:
                raise FieldError("v_N" if self.v_N is None else "r_N", "give both 'r_N' and 'v_N'")
            try:
                a, e, *_ = elements_from_rv(self.r_N, self.v_N, self.mu)
            except ValueError as err:
                raise FieldError("v_N", str(err)) from None
            where = "v_N"
        else:
            a, e = self.elements.a, self.elements.e
            where = "elements.e"
        if a * (1.0 - e) <= R_EARTH_M:
            raise FieldError(where, f"perigee radius {a * (1.0 - e):.10g} m is inside the Earth (equatorial radius "
                                    f"{R_EARTH_M:.10g} m)")
        if e > KEPLER_MAX_E:
            raise FieldError(where, f"eccentricity {e:.6g} above {KEPLER_MAX_E}, where the Kepler solver is proven")
        return self

    @property
    def kepler(self) -> bool:
        """Whether this is a two-body (Kepler) orbit rather than the circular form."""
        return self.radius is None and self.altitude is None

    @property
    def elements_rad(self) -> tuple[float, float, float, float, float, float]:
        """``(a, e, i, raan, argp, nu)`` at t = 0 ([m], -, [rad] x 4) of a two-body orbit."""
        if self.elements is not None:
            el = self.elements
            return el.a, el.e, el.i, el.raan, el.argp, el.nu
        return elements_from_rv(self.r_N, self.v_N, self.mu)

    @property
    def radius_m(self) -> float:
        """Orbit radius [m] (from ``altitude`` over the WGS-84 equatorial radius when given); the
        semi-major axis of a two-body orbit."""
        if self.kepler:
            return self.elements_rad[0]
        return self.radius if self.radius is not None else R_EARTH_M + self.altitude

    @property
    def mean_motion(self) -> float:
        """Orbital rate n = sqrt(mu / R³) [rad/s] (R: the radius, or the semi-major axis)."""
        return math.sqrt(self.mu / self.radius_m**3)


class ConstantTorque(Strict):
    """``torque_B`` [N m] (B components) held on ``start <= t < stop`` [s]."""

    kind: Literal["constant"]
    torque_B: Vec3
    start: float = -math.inf
    stop: float = math.inf

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=True)
    #: whether the kind needs an [orbit] table (stationbed.model.torques has its physics)
    needs_orbit: ClassVar[bool] = False

    @field_validator("torque_B")
    @classmethod
    def _finite(cls, v):
        if not all(math.isfinite(x) for x in v):
            raise ValueError("contains NaN or inf")
        return v

    @field_validator("start", "stop")
    @classmethod
    def _no_nan(cls, v):
        if math.isnan(v):
            raise ValueError("is NaN")
        return v

    @model_validator(mode="after")
    def _ordered(self):
        if not self.stop > self.start:
            raise ValueError(f"stop ({self.stop}) must be after start ({self.start})")
        return self


class HarmonicTorque(Strict):
    """``bias + Σ_k cos_k cos(k u) + sin_k sin(k u)``, u the argument of latitude (k = 1, 2)."""

    kind: Literal["orbital_harmonic"]
    bias_B: Vec3 = [0.0, 0.0, 0.0]
    cos1_B: Vec3 = [0.0, 0.0, 0.0]
    sin1_B: Vec3 = [0.0, 0.0, 0.0]
    cos2_B: Vec3 = [0.0, 0.0, 0.0]
    sin2_B: Vec3 = [0.0, 0.0, 0.0]

    needs_orbit: ClassVar[bool] = True


class AeroTorque(Strict):
    """Free-molecular aerodynamic torque on the scene's ``[[surface]]`` plates (issue 14)."""

    kind: Literal["aero"]

    needs_orbit: ClassVar[bool] = True


class SrpTorque(Strict):
    """Solar radiation pressure torque on the scene's ``[[surface]]`` plates (issue 14); needs [sun]."""

    kind: Literal["srp"]

    needs_orbit: ClassVar[bool] = False


Torque = Annotated[Union[ConstantTorque, HarmonicTorque, AeroTorque, SrpTorque], Field(discriminator="kind")]

#: (absorbed, specular, diffuse) fractions of a surface that names none of them
SURFACE_FRACTIONS_DEFAULT = (0.8, 0.1, 0.1)


class Surface(Strict):
    """``[[surface]]``: a flat plate (``area`` [m²], ``normal``) or a box (``size`` [m], three edge
    lengths along the axes) with its ``centre`` [m], on the body or on a named appendage (``on``).

    On the body: B axes, ``centre`` in the coordinates of ``body.cm``. On an appendage: P axes,
    ``centre`` relative to the appendage's mass centre (on its joint axes), so the plate turns
    with C_PB. A plate is one-sided (the side its normal points to) unless ``two_sided``; a box
    is its six one-sided outward faces. ``cd`` is the drag coefficient; ``absorbed``,
    ``specular``, ``diffuse`` are the fractions of incident sunlight (sum 1; give two or none)."""

    name: str = ""
    on: str = "body"
    area: float | None = Field(default=None, gt=0.0)
    normal: Vec3 | None = None
    size: Vec3 | None = None
    centre: Vec3 = [0.0, 0.0, 0.0]
    two_sided: bool = False
    cd: float = Field(default=2.2, gt=0.0)
    absorbed: float | None = Field(default=None, ge=0.0, le=1.0)
    specular: float | None = Field(default=None, ge=0.0, le=1.0)
    diffuse: float | None = Field(default=None, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _shape(self):
        plate = self.area is not None or self.normal is not None
        if plate == (self.size is not None):
            raise ValueError("give a plate ('area' and 'normal') or a box ('size')")
        if plate and (self.area is None or self.normal is None):
            raise FieldError("area" if self.area is None else "normal", "a plate needs both 'area' and 'normal'")
        if plate and math.sqrt(sum(x * x for x in self.normal)) < 1e-12:
            raise FieldError("normal", "must be a non-zero vector")
        if self.size is not None and min(self.size) <= 0.0:
            raise FieldError("size", "edge lengths must be positive")
        if self.size is not None and self.two_sided:
            raise FieldError("two_sided", "applies to a plate, not a box")
        given = [x for x in (self.absorbed, self.specular, self.diffuse) if x is not None]
        if len(given) == 1:
            raise ValueError("give two of 'absorbed', 'specular', 'diffuse' (or all three, or none)")
        if len(given) == 3 and abs(sum(given) - 1.0) > 1e-9:
            raise ValueError(f"absorbed + specular + diffuse must be 1, got {sum(given):.9g}")
        if len(given) == 2 and sum(given) > 1.0 + 1e-9:
            raise ValueError(f"the two fractions given sum to {sum(given):.9g} > 1")
        return self

    @property
    def fractions(self) -> tuple[float, float, float]:
        """``(absorbed, specular, diffuse)``, the missing one completed to a sum of 1."""
        a, s, d = self.absorbed, self.specular, self.diffuse
        if a is None and s is None and d is None:
            return SURFACE_FRACTIONS_DEFAULT
        if a is None:
            a = 1.0 - s - d
        elif s is None:
            s = 1.0 - a - d
        elif d is None:
            d = 1.0 - a - s
        return (a, s, d)


class Atmosphere(Strict):
    """``[atmosphere]``: density model of the aerodynamic torque. ``exponential`` (embedded table,
    Vallado 2013 Table 8-4) or ``msis`` (NRLMSIS 2.0 through the optional pymsis, with ``f107``,
    ``f107a`` [sfu] and ``ap`` at the [sun] epoch); ``density_scale`` multiplies the density."""

    model: Literal["exponential", "msis"] = "exponential"
    density_scale: float = Field(default=1.0, gt=0.0)
    f107: float = Field(default=150.0, gt=0.0)
    f107a: float = Field(default=150.0, gt=0.0)
    ap: float = Field(default=15.0, ge=0.0)


class Sun(Strict):
    """Sun direction, fixed in N over a run (it moves ~1 deg/day).

    Either ``beta`` (solar beta angle: sun elevation above the orbit plane [rad]) and ``u_noon``
    (argument of latitude at which the sun's projection lies in the orbit plane [rad]), which
    need an [orbit]; or ``direction_N`` (any non-zero vector, normalised); or ``epoch`` (UTC,
    ISO 8601: the sun of that date, stationbed.model.sun). ``eclipse`` chooses the Earth's shadow
    model ("none": always lit).
    """

    beta: float | None = None  # in [-pi/2, pi/2]
    u_noon: float = 0.0
    direction_N: Vec3 | None = None
    epoch: str | None = None
    eclipse: Literal["none", "cylindrical", "conical"] = "none"

    @field_validator("epoch")
    @classmethod
    def _iso(cls, epoch):
        if epoch is not None:
            try:
                datetime.datetime.fromisoformat(epoch.replace("Z", "+00:00"))
            except ValueError:
                raise ValueError(f"'{epoch}' is not an ISO 8601 date and time (e.g. 2024-03-20T03:06:00Z)") from None
        return epoch

    @field_validator("beta")
    @classmethod
    def _elevation(cls, beta):
        return beta if beta is None else _angle_within(beta, -math.pi / 2, math.pi / 2, "[-pi/2, pi/2]")

    @model_validator(mode="after")
    def _one(self):
        if sum(x is not None for x in (self.beta, self.direction_N, self.epoch)) != 1:
            raise ValueError("give exactly one of 'beta' (with u_noon), 'direction_N' or 'epoch'")
        if self.direction_N is not None and math.sqrt(sum(x * x for x in self.direction_N)) < 1e-12:
            raise ValueError("direction_N must be a non-zero vector")
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
    outer_axes_B: list[Vec3] | None = None  # dgcmg outer-gimbal axes (unit vectors, B)
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
            for a in self.outer_axes_B:
                if math.sqrt(sum(x * x for x in a)) < 1e-9:
                    raise ValueError("outer_axes_B contains a zero vector")
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
    """``[controller]``: a registry name (controllers/) or ``module:Class``, its period and parameters."""

    name: str
    period: TimeS = 0.1  # s
    params: dict[str, Any] = {}
    sensor: Sensor = Sensor()


#: discriminator tags -> tables (the error messages name the right table's keys)
TAGS.update(constant=ConstantTorque, orbital_harmonic=HarmonicTorque, track=SunTrack, profile=Profile,
            aero=AeroTorque, srp=SrpTorque)


#: ``[[montecarlo.disperse]] kind`` -> the keys it needs (docs/design.md "Monte Carlo")
DISPERSION_KINDS = {
    "normal": ("sigma",),  # value + N(mean, sigma), per element
    "uniform": ("low", "high"),  # value + U(low, high), per element
    "scale_normal": ("sigma",),  # value * (1 + N(0, sigma)), one factor for the whole value
    "scale_uniform": ("low", "high"),  # value * (1 + U(low, high)), one factor
    "inertia": ("sigma",),  # 3x3: I_ii (1 + N(0, sigma)); I_ij += N(0, sigma_products) sqrt(I_ii I_jj)
    "attitude_normal": ("sigma",),  # quaternion turned by N(0, sigma) rad about a uniform random axis
    "choice": ("choices",),  # one of choices (weights optional)
    "seed": (),  # a fresh non-negative integer (e.g. controller.sensor.seed)
}


class Dispersion(Strict):
    """One ``[[montecarlo.disperse]]`` entry: a scene key path and how it is drawn."""

    key: str
    kind: Literal[tuple(DISPERSION_KINDS)]
    also: list[str] = []  # scale kinds: more key paths multiplied by the same factor
    sigma: float | None = Field(default=None, ge=0.0)
    mean: float = 0.0
    low: float | None = None
    high: float | None = None
    sigma_products: float = Field(default=0.0, ge=0.0)
    choices: list[Any] | None = None
    weights: list[float] | None = None

    @model_validator(mode="after")
    def _consistent(self):
        for k in DISPERSION_KINDS[self.kind]:
            if getattr(self, k) is None:
                raise FieldError(k, f"kind = '{self.kind}' needs '{k}'")
        if self.low is not None and self.high is not None and not self.low <= self.high:
            raise FieldError("high", f"must be >= low ({self.low:g}), got {self.high:g}")
        if self.also and not self.kind.startswith("scale_"):
            raise FieldError("also", f"applies to the scale kinds (one factor for several keys), not '{self.kind}'")
        if self.choices is not None and not self.choices:
            raise FieldError("choices", "must not be empty")
        if self.weights is not None:
            if self.choices is None or len(self.weights) != len(self.choices):
                raise FieldError("weights", "needs one weight per entry of choices")
            if min(self.weights) < 0 or sum(self.weights) <= 0:
                raise FieldError("weights", "must be >= 0 with a positive sum")
        return self


class Requirement(Strict):
    """One ``[[montecarlo.requirement]]``: a metric bounded by ``max`` (or ``min``) in at least
    ``coverage`` of the cases, shown with ``confidence``."""

    metric: str
    max: float | None = None
    min: float | None = None
    coverage: float = Field(default=0.9973, gt=0.0, lt=1.0)
    confidence: float = Field(default=0.9, gt=0.0, lt=1.0)

    @model_validator(mode="after")
    def _consistent(self):
        if (self.max is None) == (self.min is None):
            raise FieldError("max", "give exactly one of max or min")
        return self


class MonteCarlo(Strict):
    """``[montecarlo]``: samples, seed, dispersions, requirements (stationbed/studies/montecarlo/)."""

    n: int = Field(default=100, ge=1)
    seed: int = Field(default=0, ge=0)
    chunk: int | None = Field(default=None, ge=1)  # samples per task (default: about n / (8 workers))
    settle_s: float | None = Field(default=None, ge=0.0)  # s, rms_att_err_deg counts t >= settle_s
    envelope_dt: float | None = Field(default=60.0, gt=0.0)  # s, per-sample trajectory for envelopes; none: omit
    max_redraws: int = Field(default=100, ge=0)  # draws refused by the scene's checks before a sample is refused
    disperse: list[Dispersion] = []
    requirement: list[Requirement] = []
