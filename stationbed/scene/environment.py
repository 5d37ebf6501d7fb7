"""Scene tables of the environment (DESIGN §5, docs/design.md "Orbits" and "Environment torques"):
orbit (circular, two-body, elements), external torques, surfaces, atmosphere and sun."""

from __future__ import annotations

import datetime
import math
from typing import Annotated, ClassVar, Literal, Union

from pydantic import ConfigDict, Field, field_validator, model_validator

from ..core.constants import MU_EARTH_M3_S2, R_EARTH_M
from ..core.kepler import KEPLER_MAX_E, elements_from_rv
from .base import Direction, FieldError, Strict, Vec3, unit_hint

__all__ = [
    "Orbit", "Elements", "ConstantTorque", "HarmonicTorque", "AeroTorque", "SrpTorque", "Torque",
    "Surface", "Atmosphere", "SURFACE_FRACTIONS_DEFAULT", "Sun", "SUN_EPOCH_RANGE", "ALTITUDE_MIN_M",
]

#: Lowest circular orbit a scene may give [m] over R_EARTH_M (issue 32): the Karman line. Below it
#: the air brings an orbit down within a revolution (the lowest flown, JAXA's SLATS, held 167 km),
#: and the aero torque of a station's surfaces there leaves the state not finite; an altitude
#: typed in km (400 for the ISS) lands far below it, and the message reads it in km.
ALTITUDE_MIN_M = 100.0e3
#: 1 km in m, for the hint
KM_M = 1000.0
#: the Earth's Hill sphere [m] (Sun-Earth, ~1.5 million km): no Earth orbit reaches beyond it
HILL_SPHERE_M = 1.5e9


def _km_hint(value_m: float, lowest_m: float) -> str:
    """The "did you mean ... km" hint when ``value_m`` read in km is an Earth orbit's (from
    ``lowest_m`` to the Hill sphere), else ''."""
    return unit_hint(value_m, "km", KM_M, "m", ".10g") if lowest_m <= value_m * KM_M <= HILL_SPHERE_M else ""


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
            lowest = R_EARTH_M + ALTITUDE_MIN_M
            if self.radius is not None and self.radius <= R_EARTH_M:
                raise FieldError("radius", f"{self.radius:.10g} m is inside the Earth (equatorial radius {R_EARTH_M:.10g} m): "
                                           f"give the distance from the Earth's centre, or 'altitude'{_km_hint(self.radius, lowest)}")
            if self.radius is not None and self.radius < lowest:
                raise FieldError("radius", f"{self.radius:.10g} m is {self.radius - R_EARTH_M:.6g} m above the Earth, below "
                                           f"the lowest orbit ({ALTITUDE_MIN_M / KM_M:g} km up: the air brings it down)")
            if self.altitude is not None and self.altitude < ALTITUDE_MIN_M:
                raise FieldError("altitude", f"{self.altitude:g} m is below the lowest orbit ({ALTITUDE_MIN_M:g} m, "
                                             f"{ALTITUDE_MIN_M / KM_M:g} km: the air brings it down)"
                                             f"{_km_hint(self.altitude, ALTITUDE_MIN_M)}")
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
            km = _km_hint(a, R_EARTH_M / (1.0 - e)) if self.elements is not None else ""
            raise FieldError(where, f"perigee radius {a * (1.0 - e):.10g} m is inside the Earth (equatorial radius "
                                    f"{R_EARTH_M:.10g} m){km.replace('; did you mean', '; did you mean elements.a =')}")
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
    normal: Direction | None = None
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


#: The range of dates the sun model is stated for: the Astronomical Almanac's low-precision solar
#: coordinates (stationbed/model/sun.py), 0.01 deg "between 1950 and 2050"; an epoch outside it
#: is refused rather than computed with an error nobody has bounded. [first day, day after the last)
SUN_EPOCH_RANGE = (datetime.datetime(1950, 1, 1, tzinfo=datetime.timezone.utc),
                   datetime.datetime(2051, 1, 1, tzinfo=datetime.timezone.utc))


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
    direction_N: Direction | None = None
    epoch: str | None = None
    eclipse: Literal["none", "cylindrical", "conical"] = "none"

    @field_validator("epoch")
    @classmethod
    def _iso(cls, epoch):
        if epoch is not None:
            try:
                when = datetime.datetime.fromisoformat(epoch.replace("Z", "+00:00"))
            except ValueError:
                raise ValueError(f"'{epoch}' is not an ISO 8601 date and time (e.g. 2024-03-20T03:06:00Z)") from None
            if when.tzinfo is None:
                when = when.replace(tzinfo=datetime.timezone.utc)
            first, end = SUN_EPOCH_RANGE
            if not first <= when < end:
                raise ValueError(f"'{epoch}' is outside {first.year}-{end.year - 1}, the range the sun model is stated "
                                 "for (Astronomical Almanac low-precision formulas, 0.01 deg)")
        return epoch

    @field_validator("beta")
    @classmethod
    def _elevation(cls, beta):
        return beta if beta is None else _angle_within(beta, -math.pi / 2, math.pi / 2, "[-pi/2, pi/2]")

    @model_validator(mode="after")
    def _one(self):
        if sum(x is not None for x in (self.beta, self.direction_N, self.epoch)) != 1:
            raise ValueError("give exactly one of 'beta' (with u_noon), 'direction_N' or 'epoch'")
        return self


