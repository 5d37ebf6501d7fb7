"""Scene tables of visiting vehicles, station ports and configuration events (issue 35; physics
in :mod:`stationbed.model.docking`, the contract in docs/design.md "Docking").

```toml
[[port]]
name = "sm_aft"
position = [-40.0, 0.0, 0.0]     # m, the docking interface, body coordinates (as [body] cm)
axis = [-1.0, 0.0, 0.0]          # outward unit normal, B axes (a vehicle closes along -axis)
q_VB = [1.0, 0.0, 0.0, 0.0]      # a docked vehicle's axes V relative to B (scalar first)

[[vehicle]]
name = "progress"
mass = 7200.0                    # kg
inertia = [[1.2e4, 0, 0], [0, 3.0e4, 0], [0, 0, 3.0e4]]   # kg m², about its own mass centre, V axes
cm = [-3.5, 0.0, 0.0]            # m, its mass centre from its docking interface, V axes
port = ""                        # the port it is docked at at t = 0 ("" = free flying)
[[vehicle.surface]]              # as [[surface]] (on = "body"), V axes, centre from its interface
[[vehicle.thruster]]             # as [[thruster]], V axes, position from its interface: flown while docked
name = "rcs_p"
position_V = [-6.0, 1.3, 0.0]    # m, where the force acts, from its docking interface, V axes
direction_V = [0.0, -1.0, 0.0]   # the force's direction on the vehicle (and the station it is docked to)
force_N = 130.0
isp_s = 280.0

[[event]]
kind = "dock"                    # "dock" | "berth" | "undock"
t = 600.0                        # s, a whole number of controller periods
vehicle = "progress"
port = "sm_aft"
rate_VB_B = [0.0, 0.0, 0.0]      # rad/s, the vehicle's rate relative to the station at contact
closing_velocity = 0.1           # m/s, along -axis (dock)
lateral_velocity_B = [0.0, 0.0, 0.0]  # m/s, the misalignment of the approach (its part off the axis)
update_after_s = 60.0            # s after the event the law is told ("never": it is not)
```

Undocking pushes the vehicle off along +axis with ``spring_energy_J`` or ``delta_v`` (the
separation speed relative to the station, m/s). A berth is a dock without contact speeds (the
arm brings the vehicle in at rest relative to the port).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from ..core.massprops import InvalidMassProperties, checked_inertia_rows, composite_cm
from ..core.rotation import dcm
from .base import Direction, FieldError, Mat3, Strict, ThrusterName, UnitDirection, Vec3, unit_quaternion
from .environment import Surface

__all__ = ["Port", "Vehicle", "VehicleThruster", "Event", "EVENT_KINDS", "check_docking", "docked_at", "configuration_changes",
           "configuration_at", "vehicle_in_B", "docked_parts", "mass_centre_B", "configuration_ports"]

#: the event kinds: what each does to the configuration
EVENT_KINDS = ("dock", "berth", "undock")


class Port(Strict):
    """``[[port]]``: a docking or berthing interface on the station."""

    name: str = Field(min_length=1)
    position: Vec3  # m, body coordinates (the origin of [body] cm)
    axis: UnitDirection  # outward normal, B axes (normalised here)
    q_VB: list[float] = Field(default=[1.0, 0.0, 0.0, 0.0], min_length=4, max_length=4)

    @field_validator("q_VB")
    @classmethod
    def _quat(cls, q):
        return unit_quaternion(q)


class VehicleThruster(Strict):
    """``[[vehicle.thruster]]``: one of a vehicle's thrusters, in its axes V, flown while it is
    docked (:func:`~.thrusters.flown_thrusters`: a channel of the station's thrusters at each port
    the vehicle occupies in the run)."""

    name: ThrusterName
    position_V: Vec3  # m, point of application from its docking interface, V axes
    direction_V: Direction  # direction of the force on the vehicle, V axes
    force_N: float = Field(gt=0.0)  # N, thrust while on
    isp_s: float = Field(gt=0.0)  # s, specific impulse
    min_on_s: float = Field(default=0.0, ge=0.0)  # s, minimum pulse
    group: ThrusterName | None = None  # pod


class Vehicle(Strict):
    """``[[vehicle]]``: a visiting vehicle, declared once (its mass properties in its own axes V)."""

    name: str = Field(min_length=1)
    mass: float = Field(ge=0.0)  # kg (0: a vehicle that changes nothing)
    inertia: Mat3  # kg m², about its own mass centre, V axes
    cm: Vec3 = [0.0, 0.0, 0.0]  # m, its mass centre from its docking interface, V axes
    port: str = ""  # docked there at t = 0 ("": free flying)
    surface: list[Surface] = []  # V axes, centres from its docking interface (on = "body")
    thruster: list[VehicleThruster] = []  # V axes, positions from its docking interface (flown while docked)

    @model_validator(mode="after")
    def _physical(self):
        names = [t.name for t in self.thruster]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise FieldError("thruster", f"names must be unique, repeated: {dup}")
        if self.mass == 0.0 and not any(any(r) for r in self.inertia):
            return self  # a massless vehicle (the no-op of the tests)
        try:
            checked_inertia_rows(self.inertia, "inertia")
        except InvalidMassProperties as e:
            raise FieldError("inertia", str(e).removeprefix("inertia: ")) from None
        if self.mass == 0.0:
            raise FieldError("mass", "is 0 but the inertia is not (a massless vehicle has zero inertia)")
        for i, s in enumerate(self.surface):
            if s.on != "body":
                raise FieldError(f"surface[{i}].on", f"a vehicle's surface is on the vehicle: leave 'on' out, got {s.on!r}")
        return self


class Event(Strict):
    """``[[event]]``: a configuration change at time ``t`` (a control tick)."""

    kind: Literal["dock", "berth", "undock"]
    t: float = Field(gt=0.0)  # s
    vehicle: str
    port: str = ""  # dock/berth: where; undock: the port it leaves ("": where it is)
    rate_VB_B: Vec3 = [0.0, 0.0, 0.0]  # rad/s, the vehicle's rate relative to B at contact
    closing_velocity: float = Field(default=0.0, ge=0.0)  # m/s, along -axis
    lateral_velocity_B: Vec3 = [0.0, 0.0, 0.0]  # m/s, off the axis (the approach's misalignment)
    spring_energy_J: float | None = Field(default=None, ge=0.0)  # J, undock
    delta_v: float | None = Field(default=None, ge=0.0)  # m/s, undock: separation speed
    update_after_s: float | Literal["never"] = 0.0  # s after t the law learns the new mass properties
    #: an event already past: the scene is the configuration after it (the vehicles' ``port``
    #: keys say so). :func:`configuration_changes` sets it; kept so that key paths by index
    #: (``event[1]``, a Monte Carlo's knowledge) name the same events in every configuration
    done: bool = False

    @model_validator(mode="after")
    def _kind(self):
        moving = self.closing_velocity != 0.0 or any(self.rate_VB_B) or any(self.lateral_velocity_B)
        if self.kind == "undock":
            if moving:
                raise FieldError("closing_velocity" if self.closing_velocity else "rate_VB_B",
                                 "is a contact condition: an undock separates with spring_energy_J or delta_v")
            if self.spring_energy_J is not None and self.delta_v is not None:
                raise FieldError("delta_v", "give spring_energy_J or delta_v, not both")
        else:
            for key in ("spring_energy_J", "delta_v"):
                if getattr(self, key) is not None:
                    raise FieldError(key, f"is a separation: it belongs to an undock, not a {self.kind}")
            if self.kind == "dock" and not self.port:
                raise FieldError("port", "missing: a dock needs the port")
            if self.kind == "berth" and moving:
                raise FieldError("closing_velocity" if self.closing_velocity else "rate_VB_B",
                                 "a berth brings the vehicle in at rest (use kind = \"dock\" for a contact)")
            if self.kind == "berth" and not self.port:
                raise FieldError("port", "missing: a berth needs the port")
        if isinstance(self.update_after_s, float) and self.update_after_s < 0.0:
            raise FieldError("update_after_s", f"must be >= 0 or \"never\", got {self.update_after_s!r}")
        return self


def _named(names: list[str], name: str, field: str, what: str) -> None:
    import difflib  # noqa: PLC0415

    if name not in names:
        close = difflib.get_close_matches(name, names, n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else (f"; valid: {', '.join(names)}" if names else f"; add a [[{what}]]")
        raise FieldError(field, f"no {what} named '{name}'{hint}")


def docked_at(scene) -> dict[str, str]:
    """Vehicle name -> the port it is docked at in ``scene`` (free vehicles left out)."""
    return {v.name: v.port for v in scene.vehicle if v.port}


def vehicle_in_B(vehicle, port):
    """A vehicle docked at ``port``: mass [kg], mass centre (body coordinates [m], (3,)),
    inertia about its own mass centre in B axes [kg m²] (3, 3) and ``C_BV`` (3, 3).

    The vehicle's axes V are the port's (``q_VB``); its ``cm`` is measured from its docking
    interface, which sits at the port's ``position``."""
    C_VB = dcm(np.asarray(port.q_VB, float))
    C_BV = C_VB.T
    r_B = np.asarray(port.position, float) + C_BV @ np.asarray(vehicle.cm, float)
    I_B = C_BV @ np.asarray(vehicle.inertia, float) @ C_VB
    return float(vehicle.mass), r_B, I_B, C_BV


def docked_parts(scene, where: dict | None = None) -> list[tuple]:
    """``(mass, r_B, I_B)`` of every vehicle docked in ``scene``, in ``[[vehicle]]`` order
    (:func:`vehicle_in_B`); a massless vehicle is left out (it changes nothing, bit for bit).
    ``where`` (vehicle name -> port, :func:`configuration_ports`) puts them elsewhere."""
    ports = {p.name: p for p in scene.port}
    out = []
    for v in scene.vehicle:
        port = v.port if where is None else where.get(v.name, "")
        if port and v.mass > 0.0:
            m, r, I_B, _ = vehicle_in_B(v, ports[port])
            out.append((m, r, I_B))
    return out


def mass_centre_B(scene, where: dict | None = None) -> np.ndarray:
    """The composite mass centre [m], body coordinates, shape (3,): ``Σ m r / Σ m`` of the body,
    the appendages (balanced about their axes: it does not move as they turn) and the vehicles
    docked (:func:`docked_parts`, ``where`` as there). The one definition: the model's
    parameters (inertia about it, surfaces from it) and the thrusters' arms use it."""
    vehicles = docked_parts(scene, where)
    masses = [scene.body.mass] + [a.mass for a in scene.appendage] + [m for m, _, _ in vehicles]
    cms = [scene.body.cm] + [a.cm for a in scene.appendage] + [r for _, r, _ in vehicles]
    return composite_cm(masses, cms)


def configuration_ports(scene) -> list[dict[str, str]]:
    """Vehicle name -> port (``""`` free) in each configuration of ``scene``: as it starts, then
    after each of its ``[[event]]`` tables still to come (an event ``done`` is history: the
    scene's ports already say so). A valid scene's (:func:`check_docking`)."""
    where = {v.name: v.port for v in scene.vehicle}
    out = [dict(where)]
    for e in scene.event:
        if e.done:
            continue
        where[e.vehicle] = "" if e.kind == "undock" else e.port
        out.append(dict(where))
    return out


def check_docking(scene) -> None:
    """``[[port]]``, ``[[vehicle]]`` and ``[[event]]`` agree (one-line FieldError naming the key):
    unique names, known ports and vehicles, one vehicle per port, events in time order inside
    the run on controller ticks, each a change the configuration allows at its time."""
    ports = [p.name for p in scene.port]
    vehicles = [v.name for v in scene.vehicle]
    for what, names in (("port", ports), ("vehicle", vehicles)):
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise FieldError(what, f"names must be unique, repeated: {sorted(dup)}")
    where = {}
    for i, v in enumerate(scene.vehicle):
        if v.port:
            _named(ports, v.port, f"vehicle[{i}].port", "port")
            if v.port in where.values():
                raise FieldError(f"vehicle[{i}].port", f"'{v.port}' is taken by another vehicle at t = 0")
            where[v.name] = v.port
    if not scene.event:
        return
    if scene.appendage and any(a.mode for a in scene.appendage):
        raise FieldError("event", "flexible arrays through a configuration change are not modelled (the capture "
                                  "jump is the rigid one): give the arrays no [[appendage.mode]]")
    c = scene.controller
    last = 0.0
    for i, e in enumerate(scene.event):
        _named(vehicles, e.vehicle, f"event[{i}].vehicle", "vehicle")
        if e.done:  # history: the vehicles' ports are the configuration after it
            if any(not f.done for f in scene.event[:i]):
                raise FieldError(f"event[{i}].done", "a past event follows one still to come: list them in order")
            continue
        if e.t < last:
            raise FieldError(f"event[{i}].t", f"{e.t:g} s is before the previous event's {last:g} s: list them in order")
        last = e.t
        if e.t >= scene.simulation.duration:
            raise FieldError(f"event[{i}].t", f"{e.t:g} s is not inside the run ({scene.simulation.duration:g} s)")
        if c is not None:
            k = e.t / c.period
            if abs(k - round(k)) > 1e-9 * max(k, 1.0):
                raise FieldError(f"event[{i}].t", f"{e.t:g} s is not a whole number of controller periods ({c.period:g} s)")
        if e.kind == "undock":
            if e.vehicle not in where:
                raise FieldError(f"event[{i}].vehicle", f"'{e.vehicle}' is not docked at {e.t:g} s")
            if e.port and e.port != where[e.vehicle]:
                raise FieldError(f"event[{i}].port", f"'{e.vehicle}' is docked at '{where[e.vehicle]}', not '{e.port}'")
            del where[e.vehicle]
        else:
            _named(ports, e.port, f"event[{i}].port", "port")
            if e.vehicle in where:
                raise FieldError(f"event[{i}].vehicle", f"'{e.vehicle}' is already docked (at '{where[e.vehicle]}') at {e.t:g} s")
            if e.port in where.values():
                raise FieldError(f"event[{i}].port", f"'{e.port}' is taken at {e.t:g} s")
            where[e.vehicle] = e.port


def configuration_changes(scene, n_events: int) -> dict:
    """The key path -> value changes that give the configuration after the first ``n_events``
    events, for :meth:`Scene.replace`: the vehicles' ``port`` keys, and those events marked
    ``done`` (the scene a split run re-seeds)."""
    where = {v.name: v.port for v in scene.vehicle}
    for e in scene.event[:n_events]:
        if e.done:
            continue
        where[e.vehicle] = "" if e.kind == "undock" else e.port
    changes: dict = {f"vehicle[{i}].port": where[v.name] for i, v in enumerate(scene.vehicle) if where[v.name] != v.port}
    changes.update({f"event[{i}].done": True for i in range(n_events) if not scene.event[i].done})
    return changes


def configuration_at(scene, which: str):
    """The scene in a named configuration: ``"before"`` (as it starts), ``"after"`` (after every
    event), or ``"<n>"`` (after event n, 0-based); ValueError naming ``--config`` otherwise."""
    n_ev = len(scene.event)
    if which == "before":
        n = 0
    elif which == "after":
        n = n_ev
    else:
        try:
            n = int(which) + 1
        except ValueError:
            n = -1
        if not 1 <= n <= n_ev:
            valid = "before, after" + (f", 0..{n_ev - 1} (after that event)" if n_ev else " (the scene has no [[event]])")
            raise ValueError(f"--config: {which!r} is no configuration of {scene.name!r}; valid: {valid}")
    return scene if n == 0 else scene.replace(configuration_changes(scene, n), source=f"--config {which}")
