"""The sensor registry: scene name (``[[sensor]] kind``) -> plug-in class."""

from __future__ import annotations

from .gyro import RateGyro
from .sensor import Sensor
from .star_tracker import StarTracker

__all__ = ["SENSORS", "get_sensor", "build_sensors"]

#: ``[[sensor]] kind`` -> its class; a new kind is one file in loop/ and one line here
SENSORS: dict[str, type[Sensor]] = {cls.kind: cls for cls in (RateGyro, StarTracker)}


def get_sensor(kind: str | type[Sensor]) -> type[Sensor]:
    """The class of a sensor kind, by its scene name or the class itself (any subclass)."""
    if isinstance(kind, type) and issubclass(kind, Sensor):
        return kind
    try:
        return SENSORS[kind]
    except (KeyError, TypeError):
        raise ValueError(f"unknown sensor kind {kind!r}; valid kinds: {', '.join(sorted(SENSORS))}") from None


def build_sensors(entries) -> list[Sensor]:
    """One sensor per scene table (``Sensing.sensor``), in file order (the order of their noise
    streams, :func:`~stationbed.loop.sensor.noise_rng`)."""
    return [get_sensor(e.kind)(e) for e in entries]
