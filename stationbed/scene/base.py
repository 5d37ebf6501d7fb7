"""The scene's base pieces: the error types, the strict pydantic base, vector and matrix types, and
the floors below which a run cannot honour a tolerance or a time."""

from __future__ import annotations

import math

from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field


__all__ = [
    "SceneError", "FieldError", "Strict", "Vec3", "Mat3", "QUAT_NORM_TOL", "RTOL_MIN", "ATOL_MIN", "MIN_TIME_S",
    "TIME_RESOLUTION", "Rtol", "Atol", "TimeS", "at_most", "unit_hint", "DIRECTION_NORM_MIN", "Direction",
    "UnitDirection", "ThrusterName",
]

#: A quaternion typed in a file with ~8 digits is unit to ~1e-8; anything further off is a mistake.
QUAT_NORM_TOL = 1e-6

#: Smallest relative tolerance: 45 machine epsilons. Below it the integrators' error estimates are
#: the roundoff of their own stage sums, and steps shrink until "step size underflow" (scipy's
#: solve_ivp raises any rtol below 100 eps to 100 eps for the same reason).
RTOL_MIN = 1e-14

#: Smallest absolute tolerance [state units, SI]. A state that starts at zero is then weighted by
#: atol alone; measured on the tests' articulated scene (rtol 1e-10), DOP853 stops at t = 0 with
#: "step size underflow" for atol = 1e-25 and runs for 1e-20. The smallest state a station scene
#: holds that matters is far above 1e-20 (1e-20 rad/s of rate is 3e-13 rad over a year).
ATOL_MIN = 1e-20

#: Shortest duration, output step, integration step or controller period [s]. The adaptive
#: integrators stop at a step of 1e-12 max(1 s, t) (DOP853's UNDERFLOW_RTOL) and the output grid
#: merges times 1e-9 max(1 s, t) apart, so a run shorter than ~1e-9 s returns only its first row;
#: a microsecond keeps three decades above both, and nothing in a station moves faster.
MIN_TIME_S = 1e-6

#: Finest fraction of the duration an output step, integration step or controller period may be:
#: the output grid and the integrators tell times apart only to ~1e-9 (above), and a run cut
#: finer than a billion pieces would not end in any useful time.
TIME_RESOLUTION = 1e-9


class SceneError(ValueError):
    """A scene that cannot be run; ``str(err)`` is a one-line reason naming the field."""


class FieldError(ValueError):
    """Raised by a table's cross-field check to name the field at fault.

    Parameters
    ----------
    field : str
        The field's path below the table that raises it (``"step"`` in ``[simulation]``,
        ``"simulation.output_dt"`` in the whole scene).
    reason : str
        What is wrong, without the field's name (``"0.3 s is not a whole number of periods"``).
    """

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


def unit_quaternion(q: list[float]) -> list[float]:
    """``q`` normalised (a scene quaternion: rounding in the file is forgiven); ValueError when its
    norm is off 1 by more than :data:`QUAT_NORM_TOL`."""
    n = math.sqrt(sum(x * x for x in q))
    if abs(n - 1.0) > QUAT_NORM_TOL:
        raise ValueError(f"quaternion norm is {n:.9g}, not 1 (tolerance {QUAT_NORM_TOL:g})")
    return [x / n for x in q]


def _at_least(floor: float, unit: str, why: str) -> AfterValidator:
    """A check that a number is at least ``floor``, whose message gives the reason."""

    def check(value: float) -> float:
        if not value >= floor:
            raise ValueError(f"must be at least {floor:g}{unit}, got {value!r} ({why})")
        return value

    return AfterValidator(check)


def unit_hint(value: float, unit: str, si_per_unit: float, si: str, fmt: str = ".4g") -> str:
    """``; did you mean 15 arcsec = 7.272e-05 rad?``: ``value`` read in the ``unit`` people
    use, converted to the scene's SI ``si`` (``si_per_unit``: one ``unit`` in ``si``), printed
    with ``fmt``."""
    return f"; did you mean {value:g} {unit} = {value * si_per_unit:{fmt}} {si}?"


def at_most(limit: float, si: str, why: str, unit: str, si_per_unit: float) -> AfterValidator:
    """A check that a number is at most ``limit`` [``si``], whose message gives the reason and
    reads the value in the ``unit`` people type by mistake (:func:`unit_hint`)."""

    def check(value: float) -> float:
        if not value <= limit:
            raise ValueError(f"{value:g} {si} is above {limit:g} {si} ({why})"
                             f"{unit_hint(value, unit, si_per_unit, si)}")
        return value

    return AfterValidator(check)


#: a relative tolerance in [RTOL_MIN, 1)
Rtol = Annotated[float, Field(lt=1.0), _at_least(RTOL_MIN, "", "a double's roundoff stops finer error control")]
#: an absolute tolerance of at least ATOL_MIN
Atol = Annotated[float, _at_least(ATOL_MIN, "", "a state at zero would be held to roundoff noise")]
#: a duration or interval of at least MIN_TIME_S [s]
TimeS = Annotated[float, _at_least(MIN_TIME_S, " s", "shorter than the integrators and the output grid resolve")]

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]

#: A direction (a thruster's force, a plate's normal, a port's axis, a boresight, a gimbal axis,
#: the sun's) shorter than this is the zero vector typed with rounding noise, not a direction
#: [its own units]: the floor of the three checks that had the smaller one, so every scene that
#: loaded still loads (the other three refused below 1e-9).
DIRECTION_NORM_MIN = 1e-12


def _norm(v: list[float]) -> float:
    return math.sqrt(sum(x * x for x in v))


def _direction(v: list[float]) -> list[float]:
    """``v`` unchanged; ValueError when it is the zero vector (:data:`DIRECTION_NORM_MIN`). NaN
    and inf are refused before, by :class:`Strict` (``allow_inf_nan``)."""
    if not _norm(v) >= DIRECTION_NORM_MIN:
        raise ValueError("must be a non-zero vector")
    return v


def _unit(v: list[float]) -> list[float]:
    n = _norm(v)
    return [x / n for x in v]


#: a direction: three finite numbers, not all zero (its length is the user's: each reader of it
#: normalises); one line naming the field otherwise
Direction = Annotated[Vec3, AfterValidator(_direction)]
#: a :data:`Direction` stored normalised to unit length
UnitDirection = Annotated[Direction, AfterValidator(_unit)]
#: a name that becomes a column stem: a letter, then letters, digits, underscores
COLUMN_STEM = r"[A-Za-z][A-Za-z0-9_]*"
#: a thruster's or group's name: it becomes a column stem
ThrusterName = Annotated[str, Field(pattern=f"^{COLUMN_STEM}$", max_length=40)]


class Strict(BaseModel):
    """Base of every scene table: unknown keys, NaN and inf are errors; frozen once valid.

    Types are strict: a number field takes an integer or a float but not ``true`` or ``"100"``,
    a boolean field only ``true``/``false``, an integer field only an integer, a string field
    only a string (pydantic's strict mode)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)
