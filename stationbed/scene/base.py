"""The scene's base pieces: the error type, the strict pydantic base, vector and matrix types."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field


__all__ = ["SceneError", "Strict", "Vec3", "Mat3", "QUAT_NORM_TOL"]

#: A quaternion typed in a file with ~8 digits is unit to ~1e-8; anything further off is a mistake.
QUAT_NORM_TOL = 1e-6


class SceneError(ValueError):
    """A scene that cannot be run; ``str(err)`` is a one-line reason naming the field."""


Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


class Strict(BaseModel):
    """Base of every scene table: unknown keys, NaN and inf are errors; frozen once valid."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
