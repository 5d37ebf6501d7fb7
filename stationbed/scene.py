"""Scene files (TOML, SI, radians) -> validated, frozen :class:`Scene` objects.

The schema is DESIGN §5. Parsing is ``tomllib``; validation is pydantic (``extra="forbid"``,
no NaN/inf). Every failure becomes a :class:`SceneError` whose message is one line naming the
file, the field path and the reason, with the nearest valid key suggested for typos.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .massprops import InvalidMassProperties, check_inertia

__all__ = ["Scene", "SceneError", "load_scene", "scene_from_dict"]

MU_EARTH_M3_S2 = 3.986004418e14  # IERS 2010 / WGS-84 GM
R_EARTH_M = 6378137.0  # WGS-84 equatorial radius
#: A quaternion typed in a file with ~8 digits is unit to ~1e-8; anything further off is a mistake.
QUAT_NORM_TOL = 1e-6


class SceneError(ValueError):
    """A scene that cannot be run; ``str(err)`` is a one-line reason naming the field."""


Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Profile(_Strict):
    """Joint-angle profile ``a0 + rate t + amp sin(freq t + phase)`` [rad, rad/s, rad, rad/s, rad]."""

    a0: float = 0.0
    rate: float = 0.0
    amp: float = 0.0
    freq: float = 0.0
    phase: float = 0.0

    def coeffs(self) -> list[float]:
        return [self.a0, self.rate, self.amp, self.freq, self.phase]


class Simulation(_Strict):
    duration: float = Field(gt=0.0)
    formulation: str = "momentum"
    integrator: str = "dop853"
    rtol: float = Field(default=1e-9, gt=0.0, lt=1.0)
    atol: float = Field(default=1e-12, gt=0.0)
    output_dt: float = Field(default=10.0, gt=0.0)
    step: float | None = Field(default=None, gt=0.0)  # fixed-step integrators [s]
    max_step: float | None = Field(default=None, gt=0.0)  # adaptive integrators [s]


class Initial(_Strict):
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


class Body(_Strict):
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


class Appendage(Body):
    name: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
    alpha: Profile = Profile()
    beta: Profile = Profile()


class Orbit(_Strict):
    radius: float | None = Field(default=None, gt=0.0)
    altitude: float | None = Field(default=None, gt=0.0)
    inclination: float = 0.0
    u0: float = 0.0
    mu: float = Field(default=MU_EARTH_M3_S2, gt=0.0)
    gravity_gradient: bool = True

    @model_validator(mode="after")
    def _one_size(self):
        if (self.radius is None) == (self.altitude is None):
            raise ValueError("give exactly one of 'radius' or 'altitude'")
        return self

    @property
    def radius_m(self) -> float:
        return self.radius if self.radius is not None else R_EARTH_M + self.altitude

    @property
    def mean_motion(self) -> float:
        """Orbital rate n = sqrt(mu / R³) [rad/s]."""
        return math.sqrt(self.mu / self.radius_m**3)


class ConstantTorque(_Strict):
    kind: Literal["constant"]
    torque_B: Vec3
    start: float = -math.inf
    stop: float = math.inf

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=True)

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


class HarmonicTorque(_Strict):
    """``bias + Σ_k cos_k cos(k u) + sin_k sin(k u)``, u the argument of latitude (k = 1, 2)."""

    kind: Literal["orbital_harmonic"]
    bias_B: Vec3 = [0.0, 0.0, 0.0]
    cos1_B: Vec3 = [0.0, 0.0, 0.0]
    sin1_B: Vec3 = [0.0, 0.0, 0.0]
    cos2_B: Vec3 = [0.0, 0.0, 0.0]
    sin2_B: Vec3 = [0.0, 0.0, 0.0]


Torque = Annotated[Union[ConstantTorque, HarmonicTorque], Field(discriminator="kind")]


class Scene(_Strict):
    """A validated scene. Build it with :func:`load_scene` or :func:`scene_from_dict`."""

    name: str
    description: str = ""
    simulation: Simulation
    initial: Initial = Initial()
    body: Body
    appendage: list[Appendage] = []
    orbit: Orbit | None = None
    torque: list[Torque] = []

    @model_validator(mode="after")
    def _consistent(self):
        names = [a.name for a in self.appendage]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"appendage names must be unique, repeated: {sorted(dup)}")
        if self.orbit is None:
            if self.initial.frame == "lvlh":
                raise ValueError("initial.frame = 'lvlh' needs an [orbit] table")
            if any(isinstance(t, HarmonicTorque) for t in self.torque):
                raise ValueError("torque kind 'orbital_harmonic' needs an [orbit] table")
        return self

    # -- convenience -------------------------------------------------------------------
    @property
    def appendage_names(self) -> list[str]:
        return [a.name for a in self.appendage]

    def replace(self, **changes) -> "Scene":
        """A copy with dotted-path changes, e.g. ``replace(**{"simulation.rtol": 1e-12})``.

        The copy is re-validated, so a bad value raises :class:`SceneError`.
        """
        data = self.model_dump()
        for path, value in changes.items():
            node = data
            keys = path.split(".")
            for k in keys[:-1]:
                node = node[k]
            node[keys[-1]] = value
        return scene_from_dict(data, source=f"scene {self.name!r}")


# ---------------------------------------------------------------------------------------
# error formatting
# ---------------------------------------------------------------------------------------


def _valid_keys(model: type[BaseModel]) -> list[str]:
    return list(model.model_fields)


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The pydantic model class that owns the field at ``loc[:-1]`` (for key suggestions)."""
    model: type[BaseModel] | None = Scene
    for part in loc[:-1]:
        if model is None:
            return None
        if isinstance(part, int):
            continue
        if part in ("constant", "orbital_harmonic"):
            model = ConstantTorque if part == "constant" else HarmonicTorque
            continue
        field = model.model_fields.get(part)
        if field is None:
            return None
        model = _inner_model(field.annotation)
    return model


def _inner_model(annotation) -> type[BaseModel] | None:
    import typing

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        m = _inner_model(arg)
        if m is not None:
            return m
    return None


def _path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("constant", "orbital_harmonic"):
            continue  # pydantic's discriminator tag, not a user key
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _one_line(err: ValidationError) -> str:
    e = err.errors()[0]
    loc = tuple(e["loc"])
    path = _path(loc)
    etype = e["type"]
    if etype == "extra_forbidden":
        model = _model_at(loc)
        hint = ""
        if model is not None:
            close = difflib.get_close_matches(str(loc[-1]), _valid_keys(model), n=1, cutoff=0.5)
            hint = f"; did you mean '{close[0]}'?" if close else f"; valid keys: {', '.join(_valid_keys(model))}"
        return f"{path}: unknown key{hint}"
    if etype == "missing":
        return f"{path}: missing required key"
    if etype == "finite_number":
        return f"{path}: must be a finite number, not NaN or inf"
    if etype in ("too_short", "too_long"):
        return f"{path}: wrong length ({e['msg'].lower()})"
    msg = e["msg"].removeprefix("Value error, ")
    more = f" (and {len(err.errors()) - 1} more problem(s))" if len(err.errors()) > 1 else ""
    return f"{path}: {msg}{more}"


def scene_from_dict(data: dict, source: str = "scene") -> Scene:
    """Validate a scene given as a dict (the parsed TOML)."""
    try:
        return Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(f"{source}: {_one_line(err)}") from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file; raises :class:`SceneError` with a one-line reason."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: malformed TOML ({e})") from None
    return scene_from_dict(data, source=str(path))
