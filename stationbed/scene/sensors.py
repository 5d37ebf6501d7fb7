"""Scene tables of the sensors and the estimator (issue 20; physics in ``stationbed/loop/``).

```toml
[[sensor]]
kind = "gyro"              # rate-gyro assembly, discrete Farrenkopf model
name = "rga1"
period = 0.1               # s
sigma_v = 1.454e-6         # rad/s^0.5, angle random walk
sigma_u = 3.162e-10        # rad/s^1.5, rate random walk

[[sensor]]
kind = "star_tracker"
name = "st1"
period = 0.5               # s
boresight_B = [0.0, -0.5, -0.866]   # or q_SB = [w, x, y, z]
nea_cross = 9.7e-6         # rad, 1 sigma, each cross-boresight axis
nea_about = 7.3e-5         # rad, 1 sigma, about the boresight
sun_exclusion = 0.524      # rad

[estimator]
kind = "mekf"
```

The scene holds them as ``Scene.sensor`` and ``Scene.estimator`` (checked against the controller
period there); the closed-loop executors fly them (docs/loop.md). :func:`sensing_from_dict`
validates the tables on their own.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import Discriminator, Field, Tag, ValidationError, model_validator

from ..core.rotation import quat_from_dcm
from .base import COLUMN_STEM, QUAT_NORM_TOL, Direction, FieldError, Mat3, SceneError, Strict, TimeS, Vec3, at_most
from .tables import TAGS

__all__ = ["GyroSensor", "StarTrackerSensor", "SensorEntry", "MekfEstimator", "Sensing",
           "WHOLE_PERIODS_TOL", "SensorName", "check_sensing", "ARW_MAX", "RRW_MAX", "NEA_MAX_RAD"]  # sensing_from_dict: in load.py

#: a latency or period that is a whole number of periods to this relative tolerance is taken as
#: one (the numbers are typed with a few digits; 1e-9 is far below any typing error)
WHOLE_PERIODS_TOL = 1e-9


#: 1 deg/sqrt(h) in rad/s^0.5 (sqrt(3600 s) = 60 sqrt(s)), the unit gyro datasheets quote ARW in
DEG_SQRT_H = math.radians(1.0) / 60.0
#: 1 deg/h/sqrt(h) in rad/s^1.5, the unit of a datasheet's rate random walk
DEG_H_SQRT_H = math.radians(1.0) / 3600.0**1.5
#: 1 arcsec in rad, the unit of a star tracker's noise-equivalent angle
ARCSEC_RAD = math.radians(1.0 / 3600.0)

# The noise figures' upper bounds (issue 32): each above every real sensor's datasheet, and below
# the same figure typed in the datasheet's unit, the usual slip (the message then reads the value
# in that unit). Where the two ranges overlap (a deg/sqrt(h) figure below ARW_MAX) nothing can
# tell them apart.
#: angle random walk [rad/s^0.5]: 6.9 deg/sqrt(h) (0.11 deg/s/sqrt(Hz)), above the noisiest MEMS
#: rate gyros (Analog Devices ADXRS300: 0.1 deg/s/sqrt(Hz)); space IRUs quote 1e-4-0.3 deg/sqrt(h),
#: so 0.005 (deg/sqrt(h)) typed as is reads 17 deg/sqrt(h)
ARW_MAX = 2e-3
#: rate random walk [rad/s^1.5]: 1240 deg/h/sqrt(h), decades above MEMS gyros' (a few to tens)
RRW_MAX = 1e-4
#: noise-equivalent angle [rad]: 1030 arcsec, above the coarsest heads' about-boresight NEA
#: (nanosatellite trackers: a few hundred arcsec); datasheets quote 1-200 arcsec
NEA_MAX_RAD = 5e-3

#: the noise figures' types: >= 0 and at most the bound above
Arw = Annotated[float, Field(ge=0.0), at_most(ARW_MAX, "rad/s^0.5", "noisier than any rate gyro", "deg/sqrt(h)",
                                               DEG_SQRT_H)]
Rrw = Annotated[float, Field(ge=0.0), at_most(RRW_MAX, "rad/s^1.5", "a bias walking faster than any rate gyro's",
                                               "deg/h/sqrt(h)", DEG_H_SQRT_H)]
Nea = Annotated[float, Field(ge=0.0), at_most(NEA_MAX_RAD, "rad", "coarser than any star tracker", "arcsec",
                                               ARCSEC_RAD)]


#: a sensor's name: it becomes a column stem and a layout field (letters, digits, underscores)
SensorName = Annotated[str, Field(pattern=f"^{COLUMN_STEM}$", max_length=40)]


def _whole(ratio: float) -> bool:
    return round(ratio) >= 0 and abs(ratio - round(ratio)) <= WHOLE_PERIODS_TOL * max(1.0, ratio)


def _angle(value: float | None, name: str) -> None:
    if value is not None and not 0.0 <= value <= math.pi:
        raise FieldError(name, f"must be an angle in [0, pi] rad, got {value!r}")


class GyroSensor(Strict):
    """``[[sensor]] kind = "gyro"``: a rate-gyro assembly measuring the body rate on B's axes.

    Output ``omega_B = (E + M) ω̄ + ½(β_k + β_k+1) + noise``, the rate integrated over the
    sample (ω̄ = Δθ/period), with the Farrenkopf bias random walk β (stationbed/loop/gyro.py)."""

    kind: Literal["gyro"]
    name: SensorName
    period: TimeS  # s, sample period
    sigma_v: Arw  # rad/s^0.5, angle random walk (ARW)
    sigma_u: Rrw = 0.0  # rad/s^1.5, rate random walk (bias random walk)
    bias0: Vec3 = [0.0, 0.0, 0.0]  # rad/s, bias at t = 0 (the truth the filter must find)
    scale_factor: Vec3 = [0.0, 0.0, 0.0]  # dimensionless, per axis (0: exact)
    misalignment: Mat3 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]  # dimensionless, zero diagonal
    quantum: float = Field(default=0.0, ge=0.0)  # rad per count of the integrated angle (0: none)
    max_rate: float | None = Field(default=None, gt=0.0)  # rad/s, saturation per axis (none: never)

    @model_validator(mode="after")
    def _physical(self):
        if any(self.misalignment[i][i] != 0.0 for i in range(3)):
            raise FieldError("misalignment", "the diagonal must be zero (give per-axis errors in scale_factor)")
        if any(abs(m) >= 0.1 for row in self.misalignment for m in row) or any(abs(s) >= 0.1 for s in self.scale_factor):
            raise FieldError("misalignment", "scale factor and misalignment are small errors: each below 0.1")
        return self

    @property
    def M(self) -> np.ndarray:
        """(3, 3) scale factor (diagonal) plus misalignment (off-diagonal): output = (E + M) ω."""
        return np.diag(self.scale_factor) + np.asarray(self.misalignment, dtype=float)


class StarTrackerSensor(Strict):
    """``[[sensor]] kind = "star_tracker"``: one head; measures its own attitude ``q_SN``
    (boresight = S's z axis) with noise-equivalent angles across and about the boresight, at
    its period, ``latency`` later; a Sun, Earth-limb or Moon angle below its exclusion drops the
    measurement (output ``valid`` = 0)."""

    kind: Literal["star_tracker"]
    name: SensorName
    period: TimeS  # s, update period
    q_SB: list[float] | None = Field(default=None, min_length=4, max_length=4)  # mounting, scalar first
    boresight_B: Direction | None = None  # unit vector in B (alternative to q_SB), with roll
    roll: float = 0.0  # rad, about the boresight (with boresight_B)
    nea_cross: Nea  # rad, 1 sigma per cross-boresight axis
    nea_about: Nea  # rad, 1 sigma about the boresight
    latency: float = Field(default=0.0, ge=0.0)  # s, a whole number of periods
    sun_exclusion: float | None = None  # rad, half-cone around the Sun (none: never blinded)
    earth_exclusion: float | None = None  # rad, from the Earth's limb (none: never)
    moon_exclusion: float | None = None  # rad, half-cone around the Moon (none: never)

    @model_validator(mode="after")
    def _physical(self):
        if (self.q_SB is None) == (self.boresight_B is None):
            raise FieldError("q_SB", "give exactly one of q_SB or boresight_B")
        if self.q_SB is not None and abs(math.sqrt(sum(v * v for v in self.q_SB)) - 1.0) > QUAT_NORM_TOL:
            raise FieldError("q_SB", f"must be a unit quaternion (|q| within {QUAT_NORM_TOL:g} of 1)")
        if self.roll != 0.0 and self.boresight_B is None:
            raise FieldError("roll", "applies with boresight_B (q_SB holds the roll)")
        for key in ("sun_exclusion", "earth_exclusion", "moon_exclusion"):
            _angle(getattr(self, key), key)
        if not _whole(self.latency / self.period):
            raise FieldError("latency", f"{self.latency:g} s is not a whole number of periods ({self.period:g} s)")
        return self

    @property
    def n_delay(self) -> int:
        """Latency in periods."""
        return int(round(self.latency / self.period))

    def mounting(self) -> np.ndarray:
        """``q_SB`` (scalar first, w >= 0): ``C_SB = dcm(q_SB)`` maps B components to S."""
        if self.q_SB is not None:
            q = np.asarray(self.q_SB, dtype=float)
            q = q / np.linalg.norm(q)
            return q if q[0] >= 0 else -q
        z = np.asarray(self.boresight_B, dtype=float)
        z = z / np.linalg.norm(z)
        ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x0 = ref - ref.dot(z) * z
        x0 /= np.linalg.norm(x0)
        y0 = np.cross(z, x0)
        x = math.cos(self.roll) * x0 + math.sin(self.roll) * y0
        C_SB = np.vstack([x, np.cross(z, x), z])  # rows: S's axes in B components
        return quat_from_dcm(C_SB)


def _sensor_tag(v) -> str:
    kind = v.get("kind") if isinstance(v, dict) else getattr(v, "kind", None)
    return f"kind={kind}" if kind in ("gyro", "star_tracker") else None


#: one ``[[sensor]]`` entry, chosen by its kind (the tags contain '=' so they never match a key)
SensorEntry = Annotated[
    Union[Annotated[GyroSensor, Tag("kind=gyro")], Annotated[StarTrackerSensor, Tag("kind=star_tracker")]],
    Discriminator(_sensor_tag, custom_error_type="unknown_kind",
                  custom_error_message="unknown or missing kind; valid kinds: 'gyro', 'star_tracker'"),
]
TAGS.update({"kind=gyro": GyroSensor, "kind=star_tracker": StarTrackerSensor})


class MekfEstimator(Strict):
    """``[estimator] kind = "mekf"``: the multiplicative EKF (stationbed/loop/mekf.py), tuned from
    the sensors' tables unless a value is given here."""

    kind: Literal["mekf"]
    gyro: str | None = None  # the gyro it propagates with (default: the scene's only gyro)
    star_trackers: list[str] | None = None  # the heads it updates with (default: every head)
    sigma_v: Annotated[Arw, Field(gt=0.0)] | None = None  # rad/s^0.5 (default: the gyro's)
    sigma_u: Annotated[Rrw, Field(gt=0.0)] | None = None  # rad/s^1.5 (default: the gyro's)
    nea_cross: Annotated[Nea, Field(gt=0.0)] | None = None  # rad, every head's it updates with (default: each head's)
    nea_about: Annotated[Nea, Field(gt=0.0)] | None = None  # rad, every head's it updates with (default: each head's)
    sigma_attitude0: float = Field(default=1.0e-3, gt=0.0)  # rad, 1 sigma of the initial estimate per axis
    sigma_bias0: float = Field(default=1.0e-5, gt=0.0)  # rad/s, 1 sigma of the initial bias estimate per axis


class Sensing(Strict):
    """The sensors and the estimator of a scene (``[[sensor]]``, ``[estimator]``)."""

    sensor: list[SensorEntry] = []
    estimator: MekfEstimator | None = None

    @model_validator(mode="after")
    def _consistent(self):
        check_sensing(self.sensor, self.estimator)
        return self


def check_sensing(sensor: list, estimator, period: float | None = None) -> None:
    """The ``[[sensor]]`` tables and ``[estimator]`` agree with each other (and, given the
    controller ``period`` [s], each sensor's period is a whole number of it); FieldError."""
    names = [s.name for s in sensor]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FieldError("sensor", f"names must be unique, repeated: {dup}")
    for i, s in enumerate(sensor):
        if period is not None and not (round(s.period / period) >= 1 and _whole(s.period / period)):
            raise FieldError(f"sensor[{i}].period", f"{s.period:g} s is not a whole number of controller "
                                                    f"periods ({period:g} s)")
    est = estimator
    if est is None:
        return
    gyros = [s.name for s in sensor if s.kind == "gyro"]
    heads = [s.name for s in sensor if s.kind == "star_tracker"]
    if est.gyro is None and len(gyros) != 1:
        raise FieldError("estimator.gyro", f"name the gyro to propagate with (the scene has {len(gyros)}: {gyros})")
    if est.gyro is not None and est.gyro not in gyros:
        raise FieldError("estimator.gyro", f"'{est.gyro}' is not a gyro of [[sensor]] (gyros: {gyros})")
    used = heads if est.star_trackers is None else est.star_trackers
    bad = [h for h in used if h not in heads]
    if bad or not used:
        raise FieldError("estimator.star_trackers", f"must name one or more star trackers of [[sensor]] "
                                                    f"(heads: {heads}), got {bad or used}")
    gyro = next(s for s in sensor if s.name == (est.gyro or gyros[0]))
    # the filter weighs each sample by its noise: a noise-free sensor needs the filter's own figure
    if gyro.sigma_v == 0.0 and est.sigma_v is None:
        raise FieldError(f"sensor[{sensor.index(gyro)}].sigma_v", f"0: the MEKF propagates with gyro '{gyro.name}' and "
                                                                  "weighs it by its noise; give estimator.sigma_v")
    for i, s in enumerate(sensor):
        for key in ("nea_cross", "nea_about"):
            if s.name in used and getattr(s, key) == 0.0 and getattr(est, key) is None:
                raise FieldError(f"sensor[{i}].{key}", f"0: the MEKF updates with head '{s.name}' and weighs it by its "
                                                       f"noise-equivalent angles; give estimator.{key}")
    for s in sensor:
        if s.name in used and not _whole(s.period / gyro.period):
            raise FieldError("estimator.star_trackers", f"head '{s.name}': period {s.period:g} s is not a whole "
                                                        f"number of the gyro's ({gyro.period:g} s)")
