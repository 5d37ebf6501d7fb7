"""``[plan]``: an optimal attitude-command history between two attitudes (issue 26, the
zero-propellant manoeuvre); :mod:`stationbed.plan` solves it.

The start is the scene's ``[initial]`` state and CMG momentum (``[cmg] h0_B`` of an ideal
cluster, or a gimballed cluster's momentum at its ``gimbal0``); the end conditions, limits,
objective and mesh are here. Attitudes and rates are
relative to ``frame`` (LVLH or inertial), as ``[initial] frame`` states them.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .base import FieldError, Strict, TimeS, Vec3, unit_quaternion

__all__ = ["PlanSpec", "PLAN_OBJECTIVES", "MAX_INTERVALS"]

#: the objectives: the weighted sum, or one of its two terms alone (see PlanSpec)
PLAN_OBJECTIVES = ("weighted", "torque_energy", "peak_momentum")
#: the most Hermite-Simpson intervals a plan takes (plan.intervals, --intervals, --refine): the NLP
#: grows with them (1e6 intervals passed 1.5 GiB in 9 s before IPOPT started)
MAX_INTERVALS = 2000

Quaternion = Annotated[list[float], Field(min_length=4, max_length=4)]


class PlanSpec(Strict):
    """``[plan]``: end conditions, limits, objective, law gains and mesh of a planned slew.

    Keys (SI): ``duration`` [s]; ``frame`` ("lvlh" or "inertial"); ``q_end`` (scalar first,
    body relative to ``frame``); ``omega_end`` [rad/s] (body rate relative to ``frame``, B
    components; default at rest in it); ``h_end_B`` [N m s] (CMG momentum at the end; default
    free); ``max_momentum`` [N m s] (|h| limit; default an ideal cluster's ``max_momentum``);
    ``max_torque`` [N m] (|ḣ| limit; default an ideal cluster's ``max_torque``; both required
    with a gimballed cluster); ``objective``
    ("weighted": ``weight_energy ∫|τ|² dt + weight_peak max|h|²``; "torque_energy"; "peak_momentum");
    ``weight_energy`` [1/(N² m² s)], ``weight_peak`` [1/(N² m² s²)]; ``kp`` [1/s²] and ``kd``
    [1/s]: the ISS-style law ``τ = -J (kp ε + kd ω̃)`` flown inside the optimisation;
    ``intervals``: Hermite-Simpson mesh intervals; ``max_iter``: IPOPT's iteration limit;
    ``tol``: IPOPT's KKT tolerance.
    """

    duration: TimeS
    frame: Literal["lvlh", "inertial"] = "lvlh"
    q_end: Quaternion
    omega_end: Vec3 = [0.0, 0.0, 0.0]
    h_end_B: Vec3 | None = None
    max_momentum: float | None = Field(default=None, gt=0.0)
    max_torque: float | None = Field(default=None, gt=0.0)
    objective: Literal[PLAN_OBJECTIVES] = "weighted"
    weight_energy: float = Field(default=1.0, ge=0.0)
    weight_peak: float = Field(default=0.1, ge=0.0)
    kp: float = Field(default=0.000128, gt=0.0)
    kd: float = Field(default=0.015846, gt=0.0)
    intervals: int = Field(default=60, ge=2, le=MAX_INTERVALS)
    max_iter: int = Field(default=3000, ge=1)
    tol: float = Field(default=1e-8, gt=0.0, lt=1.0)

    @field_validator("q_end")
    @classmethod
    def _unit(cls, q):
        return unit_quaternion(q)

    @model_validator(mode="after")
    def _weights(self):
        if self.objective == "weighted" and self.weight_energy == 0.0 and self.weight_peak == 0.0:
            raise FieldError("weight_energy", "and weight_peak are both 0: nothing to minimise")
        return self
