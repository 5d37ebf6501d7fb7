"""The sensor kinds of ``[[fault]]`` (issue 34 item 1), registered in
:data:`~stationbed.scene.faults.FAULT_KINDS`; what they do: :mod:`stationbed.loop.sensor_faults`
(numbers of the sensor's own step, gated by the sample time: no step of the plant).

```toml
[[fault]]
kind = "gyro_bias_step"     # gyro_bias_step | gyro_frozen | gyro_dropout | st_blinded | st_dropout
unit = "gyro"               # the [[sensor]] name
t = 600.0                   # s
bias_x = 1.0e-5             # rad/s (gyro_bias_step: bias_x, bias_y, bias_z, default 0)
# until = 900.0             # s: the window's end (not for gyro_bias_step)
```
"""

from __future__ import annotations

import math

from .faults import FaultKind, FaultParam, register_fault_kind

__all__ = ["SENSOR_FAULT_KINDS"]

_BIAS = FaultParam(0.0, -math.inf, math.inf, "rad/s, the bias step about this body axis")

SENSOR_FAULT_KINDS = (
    FaultKind("gyro_bias_step", "gyro", {"bias_x": _BIAS, "bias_y": _BIAS, "bias_z": _BIAS}, windowed=False,
              doc="a gyro's output gains a bias (rad/s, B axes) from t on"),
    FaultKind("gyro_frozen", "gyro", doc="a gyro's output held at its last value over [t, until)"),
    FaultKind("gyro_dropout", "gyro", doc="a gyro gives no valid output (zeros) over [t, until)"),
    FaultKind("st_blinded", "star_tracker", doc="a star-tracker head blinded: no valid output over [t, until)"),
    FaultKind("st_dropout", "star_tracker", doc="a star-tracker head silent: no valid output over [t, until)"),
)
for _k in SENSOR_FAULT_KINDS:
    register_fault_kind(_k)
