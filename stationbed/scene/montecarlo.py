"""Scene tables of ``[montecarlo]`` (docs/design.md "Monte Carlo (issue 13): the contract")."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from .base import FieldError, Strict

__all__ = ["Dispersion", "Requirement", "MonteCarlo", "DISPERSION_KINDS", "DISPERSION_KIND_DOCS"]


#: ``[[montecarlo.disperse]] kind`` -> the keys it needs (docs/design.md "Monte Carlo")
DISPERSION_KINDS = {
    "normal": ("sigma",),
    "uniform": ("low", "high"),
    "scale_normal": ("sigma",),
    "scale_uniform": ("low", "high"),
    "inertia": ("sigma",),
    "attitude_normal": ("sigma",),
    "choice": ("choices",),
    "seed": (),
}
#: kind -> what it draws (``stationbed list``; every kind has one, tests/test_plugins_list.py)
DISPERSION_KIND_DOCS = {
    "normal": "value + N(mean, sigma), per element",
    "uniform": "value + U(low, high), per element",
    "scale_normal": "value * (1 + N(0, sigma)), one factor for the whole value",
    "scale_uniform": "value * (1 + U(low, high)), one factor",
    "inertia": "3x3: I_ii (1 + N(0, sigma)); I_ij += N(0, sigma_products) sqrt(I_ii I_jj)",
    "attitude_normal": "quaternion turned by N(0, sigma) rad about a uniform random axis",
    "choice": "one of choices (weights optional)",
    "seed": "a fresh non-negative integer (e.g. controller.sensor.seed)",
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
    known: bool = False  # flight software is told the drawn value (a calibrated parameter); else it believes the nominal

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
    ``coverage`` of the cases, shown with ``confidence``; ``id`` and ``text`` (optional) are the
    requirement's identifier and wording in a specification, carried to summary.json, the JUnit
    XML and the HTML report."""

    metric: str
    id: str | None = Field(default=None, min_length=1)  # e.g. "SSP-41162 3.2.1.4"
    text: str | None = Field(default=None, min_length=1)  # the requirement as the specification words it
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
    settle_s: float | None = Field(default=None, ge=0.0)  # s, rms_att_err_deg and the estimation metrics count t >= settle_s
    envelope_dt: float | None = Field(default=60.0, gt=0.0)  # s, per-sample trajectory for envelopes; none: omit
    max_redraws: int = Field(default=100, ge=0)  # draws refused by the scene's checks before a sample is refused
    disperse: list[Dispersion] = []
    requirement: list[Requirement] = []
