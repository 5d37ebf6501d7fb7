"""Sensor faults on a schedule (issue 34 item 1): what a ``[[fault]]`` of a sensor kind does to
its sensor's numbers.

A sensor fault is not a step of the plant's parameters: it is a number of the sensor's own step
(its first and last sample times, its size), compared with the sample time inside the casadi
step (:func:`in_window`), so a faulted run is the same compiled code as a healthy one, fused,
and a fault's time or size disperses like any number. The kinds (scene tables:
:mod:`stationbed.scene.sensor_faults`):

* ``gyro_bias_step`` (``bias_x``, ``bias_y``, ``bias_z`` [rad/s]): the gyro's output gains that
  bias from ``t`` on (``until`` not allowed: a bias step stays);
* ``gyro_frozen``: the output held at its last value over ``[t, until)`` (no ``until``: to the end);
* ``gyro_dropout``: no valid output over ``[t, until)`` (the assembly's packets empty: zeros);
* ``st_blinded``, ``st_dropout``: a star-tracker head gives no valid output (``valid = 0``)
  over ``[t, until)``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["NEVER_S", "in_window", "SENSOR_FAULTS", "apply_sensor_faults"]

#: a time no run reaches [s]: a window or a step there never starts (healthy)
NEVER_S = 1.0e300


def in_window(t, window, dt):
    """1 when the sample at ``t`` [s] lies in ``window = (on, off)`` [s]: ``on - dt/2 <= t < off -
    dt/2`` (samples are ``dt`` apart: half a period of margin keeps round-off off the edges)."""
    return ca.logic_and(t >= window[0] - 0.5 * dt, t < window[1] - 0.5 * dt)


def _window(fault) -> list[float]:
    return [float(fault.t), NEVER_S if fault.until is None else float(fault.until)]


def _bias(fault, p: dict) -> None:
    p["fault_bias_B"] = np.asarray(p["fault_bias_B"], float) + [fault.param(k) for k in ("bias_x", "bias_y", "bias_z")]
    p["t_bias"] = min(float(np.ravel(p["t_bias"])[0]), float(fault.t))


def _set(field: str):
    def write(fault, p: dict) -> None:
        p[field] = _window(fault)
    return write


#: kind -> (the sensor kind it targets, how it writes that sensor's parameters (a dict by field))
SENSOR_FAULTS = {
    "gyro_bias_step": ("gyro", _bias),
    "gyro_frozen": ("gyro", _set("frozen")),
    "gyro_dropout": ("gyro", _set("dropout")),
    "st_blinded": ("star_tracker", _set("blinded")),
    "st_dropout": ("star_tracker", _set("dropout")),
}


def apply_sensor_faults(sensors, faults) -> dict[str, np.ndarray]:
    """The parameters of each sensor a fault of :data:`SENSOR_FAULTS` targets (by the sensor's
    name: ``fault.unit``), its faults written in; the other faults are not a sensor's (skipped).
    Two windows of one kind on one sensor: the scene refuses them (one window per field)."""
    by = {s.name: s for s in sensors}
    out: dict[str, dict] = {}
    for f in faults or ():
        spec = SENSOR_FAULTS.get(f.kind)
        if spec is None:
            continue
        s = by.get(f.unit)
        if s is None or s.kind != spec[0]:
            raise ValueError(f"fault kind {f.kind!r}: unit {f.unit!r} is not a {spec[0]} sensor")
        p = out.setdefault(s.name, s.param_layout.split(s.params.copy()))
        spec[1](f, p)
    return {name: by[name].param_layout.pack(p) for name, p in out.items()}
