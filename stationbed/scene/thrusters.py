"""Scene tables of the thrusters (issue 21; physics in :mod:`stationbed.loop.thrusters`).

```toml
[[thruster]]
name = "sm_p1"             # letters, digits, underscores: a column stem
position_B = [-30.0, 3.0, 2.0]   # m, where the force acts, body axes (same origin as [body] cm)
direction_B = [0.0, -1.0, 0.0]   # direction of the force ON THE STATION (the plume goes the other way)
force_N = 130.0            # N, thrust while on
isp_s = 280.0              # s, specific impulse
min_on_s = 0.03            # s, shortest pulse the valve makes (0: any)
group = "sm_aft"           # optional pod name (columns per group as well)

[thrusters]                # options (all optional)
mode = "assist"            # "assist" | "thruster_only" | "off"
mapping = "min_norm_shift" # or "lp" (scipy HiGHS, per-tick loop only)
```

The scene holds them as ``Scene.thruster`` (list) and ``Scene.thrusters`` (options); the closed
loop fires them (docs/loop.md, "Actuators"), with the visiting vehicles' ``[[vehicle.thruster]]``
tables (scene/docking.py), each flown at every port its vehicle uses in the run while it is
docked there (:func:`flown_thrusters`, :func:`available`).

Thrusters push one way only: a set turns the station about an axis when it makes torque both
ways (:func:`torque_authority`, about the composite mass centre, docked vehicles included, in
each configuration the ``[[event]]`` tables make). ``mode = "thruster_only"``
with a set that cannot, or ``"assist"`` with one that makes no torque at all, is refused at
load, naming the directions and the thrusters that make no torque (the classic mistake:
positions from the mass centre, not from the origin of ``[body] cm``); an assist set that
dumps about some axes only is flown, and its run's summary and line say which it lacks
(``thruster_no_torque_about``: a dump or hand-over there is not delivered).
"""

from __future__ import annotations

import functools
import itertools
import math
import re
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from .base import COLUMN_STEM, Direction, FieldError, Strict, ThrusterName, Vec3
from ..core.rotation import dcm
from .docking import configuration_ports, docked_at, mass_centre_B

__all__ = ["Thruster", "ThrusterOptions", "ThrusterName", "check_thrusters", "flown_thrusters", "thruster_owners",
           "available", "torque_arms", "torque_authority",
           "missing_torque", "no_torque_about", "no_torque_parts", "AUTHORITY_ROUNDOFF_REL"]

#: a thruster's torque per newton, or the set's torque authority about an axis, below this fraction
#: of the set's scale (the largest |r_i - c| + 1 m; Σ |(r_i - c) × ĝ_i| F_i) is round-off of the
#: positions' differences: none (a line of action through the mass centre gives 0 to ~1e-16)
AUTHORITY_ROUNDOFF_REL = 1e-9
#: the thrusters a message names at most (then "and N more")
NAMED_MAX = 6
#: a firing of three thrusters found by :func:`_shown` proves a direction when its torque exceeds
#: this fraction of the set's scale: 1e5 x :data:`AUTHORITY_ROUNDOFF_REL`, far above the LP's
#: tolerances (HiGHS: 1e-7 on its rows), so the LP would find at least as much (real sets make
#: ~1e-3 of their scale about an axis; a set that does not shows it to the LP as before)
SHOWN_REL = 1e-4
#: sets of at most this many thrusters look for the firings first (C(n, 3) triples: 9880 at 40)
SHOWN_MAX_THRUSTERS = 40



class Thruster(Strict):
    """``[[thruster]]``: one thruster, on or off (a valve), its force fixed in the body."""

    name: ThrusterName
    position_B: Vec3  # m, point of application, body axes, same origin as [body] cm
    direction_B: Direction  # direction of the force on the station (normalised here)
    force_N: float = Field(gt=0.0)  # N, thrust while on
    isp_s: float = Field(gt=0.0)  # s, specific impulse (m_dot = F / (isp g0))
    min_on_s: float = Field(default=0.0, ge=0.0)  # s, minimum pulse
    group: ThrusterName | None = None  # pod

    @property
    def unit_B(self) -> list[float]:
        """The force's direction, unit length, body axes."""
        n = math.sqrt(sum(v * v for v in self.direction_B))
        return [v / n for v in self.direction_B]


def _vehicle_ports(scene) -> dict[str, list[str]]:
    """Vehicle name -> the ports it occupies in the run (as it starts, after each event still to
    come, and the ports of the dock and berth events already done), first use first; vehicles
    with ``[[vehicle.thruster]]`` tables only."""
    used = {v.name: [] for v in scene.vehicle if v.thruster}
    seen = [{v.name: v.port for v in scene.vehicle}] + [{e.vehicle: e.port} for e in scene.event if e.done]
    for where in seen + configuration_ports(scene):
        for name, ports in used.items():
            p = where.get(name, "")
            if p and p not in ports:
                ports.append(p)
    return used


def _flown(scene, base=None) -> list[tuple[Thruster, tuple[str, str] | None]]:
    """(thruster in B, owner) of :func:`flown_thrusters` (owner ``(vehicle, port)`` or None)."""
    out = [(t, None) for t in scene.thruster]
    if not any(v.thruster for v in scene.vehicle):
        return out
    used = _vehicle_ports(scene if base is None else base)
    ports = {p.name: p for p in scene.port}
    for v in scene.vehicle:
        for pname in used.get(v.name, []):
            port = ports[pname]
            C_BV = dcm(np.asarray(port.q_VB, float)).T
            for t in v.thruster:
                name = f"{v.name}_{t.name}" if len(used[v.name]) == 1 else f"{v.name}_{pname}_{t.name}"
                r = np.asarray(port.position, float) + C_BV @ np.asarray(t.position_V, float)
                g = C_BV @ np.asarray(t.direction_V, float)
                out.append((Thruster.model_construct(name=name, position_B=r.tolist(), direction_B=g.tolist(),
                                                     force_N=t.force_N, isp_s=t.isp_s, min_on_s=t.min_on_s,
                                                     group=t.group), (v.name, pname)))
    return out


def flown_thrusters(scene, base=None) -> list[Thruster]:
    """The thrusters the run flies, B axes: the scene's ``[[thruster]]`` tables, then each
    ``[[vehicle.thruster]]`` once per port its vehicle occupies in the run (docked at t = 0 or
    by an event), at that port (position ``port.position + C_BV r_V``, direction ``C_BV ĝ_V``),
    named ``<vehicle>_<name>`` (``<vehicle>_<port>_<name>`` when the vehicle uses several ports).
    A vehicle's thrusters fire only while it is docked there (:func:`available`). ``base``: the
    scene whose events say which ports are used (default ``scene``; a configuration of a run
    passes the run's scene, so its channels are the run's)."""
    return [t for t, _ in _flown(scene, base)]


def thruster_owners(scene, base=None) -> list[tuple[str, str] | None]:
    """Per :func:`flown_thrusters` entry its ``(vehicle, port)``, or None for a station thruster."""
    return [o for _, o in _flown(scene, base)]


def available(owners, where: dict) -> np.ndarray:
    """(n,) 1.0 for each thruster that can fire in the configuration ``where`` (vehicle name ->
    port): the station's, and a vehicle's at the port it is docked at; else 0.0."""
    return np.array([1.0 if o is None or where.get(o[0], "") == o[1] else 0.0 for o in owners])


class ThrusterOptions(Strict):
    """``[thrusters]``: how the thrusters are commanded (every key optional).

    Fractions of capacity are of the *working* CMG units' momentum capacity as flight software
    knows it (the ``[knowledge]`` scene's cluster, :func:`stationbed.run.closed_loop.plant_facts`).
    """

    mode: Literal["assist", "thruster_only", "off"] = "assist"
    mapping: Literal["min_norm_shift", "lp"] = "min_norm_shift"
    #: Schmitt trigger on a pulse shorter than min_on_s: level = requested / min_on_s; fire min_on_s
    #: at level >= level_on, none at level <= level_off, and in between as the previous tick did
    level_on: float = Field(default=0.75, gt=0.0, le=1.0)
    level_off: float = Field(default=0.25, ge=0.0, lt=1.0)
    remainder: bool = True  # carry the on-time not delivered (or delivered too much) to the next tick
    # CMG thruster assist: dump while |h| / capacity is above assist_on until it falls to dump_stop
    assist_on: float = Field(default=0.8, gt=0.0, le=1.0)
    dump_stop: float = Field(default=0.35, ge=0.0, lt=1.0)
    h_min: float = Field(default=0.3, ge=0.0, lt=1.0)  # dump target |h| as a fraction of capacity
    dump_time_s: float = Field(default=300.0, gt=0.0)  # s: dump torque = ΔH / dump_time_s ...
    max_dump_torque_Nm: float = Field(default=200.0, gt=0.0)  # N m: ... at most this
    # hand-over to thruster-only control at saturation, hand-back below handback
    handover: float = Field(default=0.97, gt=0.0, le=1.5)
    handback: float = Field(default=0.5, ge=0.0, lt=1.5)
    inhibit: list[Annotated[list[float], Field(min_length=2, max_length=2)]] = []  # [start, stop) s: no firing

    @model_validator(mode="after")
    def _order(self):
        if self.level_off >= self.level_on:
            raise FieldError("level_off", f"{self.level_off:g} must be below level_on ({self.level_on:g})")
        if self.dump_stop >= self.assist_on:
            raise FieldError("dump_stop", f"{self.dump_stop:g} must be below assist_on ({self.assist_on:g})")
        if self.h_min > self.dump_stop:
            raise FieldError("h_min", f"{self.h_min:g} must not exceed dump_stop ({self.dump_stop:g}): the dump "
                                      "would stop before reaching it, or never")
        if self.handback >= self.handover:
            raise FieldError("handback", f"{self.handback:g} must be below handover ({self.handover:g})")
        for i, (a, b) in enumerate(self.inhibit):
            if not 0.0 <= a < b:
                raise FieldError(f"inhibit[{i}]", f"[{a:g}, {b:g}] must be a window [start, stop) with 0 <= start < stop")
        return self


def torque_arms(scene, c_B=None, base=None) -> tuple[np.ndarray, np.ndarray]:
    """(D, G), each (3, n): column i the torque per newton ``(r_i - c) × ĝ_i`` [m] and the unit
    force direction ĝ_i of thruster i, c the composite mass centre (B axes) of the body, the
    appendages and the vehicles docked in ``scene`` (:func:`~.docking.mass_centre_B`), or
    ``c_B`` [m] when given (another configuration's). The arrays are balanced about their
    rotation axes (DESIGN §4), so c is the constant ``Σ m r / Σ m`` of the configuration,
    whatever the arrays' angles; a docking or undocking moves it (run/docking.py)."""
    c = mass_centre_B(scene) if c_B is None else np.asarray(c_B, dtype=float)
    thr = flown_thrusters(scene, base)
    G = np.array([t.unit_B for t in thr], dtype=float).reshape(-1, 3).T
    R = np.array([t.position_B for t in thr], dtype=float).reshape(-1, 3).T - c[:, None]
    return np.cross(R.T, G.T).T, G


def torque_authority(D: np.ndarray, f_max) -> np.ndarray:
    """(3, 2): the largest torque [N m] the thrusters make about ``-e_k`` (column 0) and ``+e_k``
    (column 1) of B with no torque about the other two axes, each force in ``[0, f_max_i]``
    (scipy HiGHS LP). A zero entry: no combination of firings turns the station that way.

    Parameters
    ----------
    D : ndarray, shape (3, n)  Torque per newton of each thruster [m] (:func:`torque_arms`).
    f_max : ndarray, shape (n,)  Thrust of each thruster while on [N].
    """
    from scipy.optimize import linprog  # noqa: PLC0415 - a second's import, only for scenes with thrusters

    f_max = np.asarray(f_max, dtype=float)
    out = np.zeros((3, 2))
    for k in range(3):
        others = [j for j in range(3) if j != k]
        for col, sign in enumerate((-1.0, 1.0)):
            res = linprog(-sign * D[k], A_eq=D[others], b_eq=np.zeros(2), bounds=list(zip(np.zeros_like(f_max), f_max)),
                          method="highs")
            out[k, col] = max(-res.fun, 0.0) if res.status == 0 else 0.0
    return out


def _named(names: list[str]) -> str:
    more = len(names) - NAMED_MAX
    return ", ".join(names[:NAMED_MAX]) + (f" and {more} more" if more > 0 else "")


def missing_torque(scene, c_B=None, avail=None) -> list[str]:
    """The directions of B (``"-x"``, ``"+y"``, ...) the thrusters cannot turn the station about
    (about its mass centre, or ``c_B`` as :func:`torque_arms`): :func:`torque_authority` at
    round-off (:data:`AUTHORITY_ROUNDOFF_REL`). ``avail`` ((n,), :func:`available`): those that
    can fire (default: the station's and those of the vehicles docked in ``scene``)."""
    D, _ = torque_arms(scene, c_B)
    f_max = np.array([t.force_N for t in flown_thrusters(scene)])
    if avail is None:
        avail = available(thruster_owners(scene), docked_at(scene))
    keep = np.asarray(avail) > 0.0
    if not keep.any():
        return [f"{sg}{ax}" for ax in "xyz" for sg in "-+"]
    return list(_missing(np.ascontiguousarray(D[:, keep]).tobytes(), np.ascontiguousarray(f_max[keep]).tobytes()))


def no_torque_about(scene, where: dict) -> str:
    """The summary's ``thruster_no_torque_about`` of the configuration ``where`` (vehicle name
    -> port, :func:`~.docking.configuration_ports`) of ``scene``'s thrusters
    (:func:`flown_thrusters`): :func:`missing_torque` about that configuration's mass centre with
    the thrusters that can fire there, as ``"-y, +y"``; ``""`` about every axis; all six when
    none can fire (a vehicle's set away: the CMGs alone)."""
    c, avail = mass_centre_B(scene, where), available(thruster_owners(scene), where)
    return ", ".join(missing_torque(scene, c, avail))


def no_torque_parts(s: dict) -> list[str]:
    """The run line's parts on what the thrusters cannot turn the station about: as it starts
    (``thruster_no_torque_about``), then, when some configuration lacks an axis, after each
    docking event (the summary's ``events`` entries carrying the key, with their times)."""
    start = s.get("thruster_no_torque_about", "")
    after = [e for e in s.get("events", []) if "thruster_no_torque_about" in e]
    out = [f"thrusters make no torque about {start}: a dump or hand-over there is not delivered"] if start else []
    if any(e["thruster_no_torque_about"] for e in after):
        def say(m: str) -> str:
            return "every axis" if not m else "none can fire" if m.count(",") == 5 else f"none about {m}"
        out.append("thruster torque after " + "; ".join(f"event[{e['event']}] at {e['t']:g} s: "
                                                         f"{say(e['thruster_no_torque_about'])}" for e in after))
    return out


@functools.lru_cache(maxsize=64)
def _missing(D_bytes: bytes, f_bytes: bytes) -> tuple[str, ...]:
    """:func:`missing_torque` of the arms and forces as bytes: kept, since each scene a Monte Carlo
    draws or ``replace`` makes is checked again (6 LPs: ~25 ms) and most share their set's."""
    f_max = np.frombuffer(f_bytes)
    D = np.frombuffer(D_bytes).reshape(3, len(f_max))
    scale = float(np.linalg.norm(D, axis=0) @ f_max)
    if _shown(D, f_max, SHOWN_REL * scale):  # (6 LPs: ~10 ms a Monte Carlo sample, whose mass centre is drawn)
        return ()
    auth = torque_authority(D, f_max)
    return tuple(f"{'-+'[col]}{'xyz'[k]}" for k in range(3) for col in range(2)
                 if auth[k, col] <= AUTHORITY_ROUNDOFF_REL * scale)


def _shown(D: np.ndarray, f_max: np.ndarray, floor: float) -> bool:
    """Whether firings prove that the set turns the station both ways about every axis of B by
    more than ``floor`` [N m], :func:`torque_authority`'s question asked of three thrusters at a
    time: thrusters i, j, l with arms ``a, b, c`` about the two other axes make no torque there
    at forces ``v = (det(b, c), det(c, a), det(a, b))`` (``a v_i + b v_j + c v_l = 0``), a firing
    when they share a sign, scaled to the largest within each ``f_max``. Every direction the set
    has is made by at most three thrusters (Caratheodory in the 3-D torque space), so a set with
    some authority each way is shown; False (not shown) leaves the answer to the LP."""
    n = len(f_max)
    if not 3 <= n <= SHOWN_MAX_THRUSTERS:
        return False
    tri = np.array(list(itertools.combinations(range(n), 3)))
    F = f_max[tri]
    for k in range(3):
        A, B = D[[j for j in range(3) if j != k]][:, tri]  # (m, 3) arms about the other two axes
        v = np.stack([A[:, 1] * B[:, 2] - A[:, 2] * B[:, 1], A[:, 2] * B[:, 0] - A[:, 0] * B[:, 2],
                      A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0]], axis=1)
        v *= np.where(v.sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
        ok = np.all(v >= 0.0, axis=1) & np.any(v > 0.0, axis=1)
        if not ok.any():
            return False
        v, F_ok = v[ok], F[ok]
        t = np.min(np.where(v > 0.0, F_ok / np.where(v > 0.0, v, 1.0), np.inf), axis=1)
        torque = np.einsum("ij,ij->i", D[k][tri[ok]], v) * t
        if not (torque.max() > floor and torque.min() < -floor):
            return False
    return True


def _configurations(scene) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(where, c, avail)`` of each configuration the scene flies with a mass centre or a set of
    thrusters that can fire of its own: as it starts (``where`` ""), then after each
    ``[[event]]`` still to come (``" after event[i] (kind vehicle)"``), c [m] in body
    coordinates (:func:`~.docking.mass_centre_B`), avail (:func:`available`)."""
    owners = thruster_owners(scene)
    todo = [(i, e) for i, e in enumerate(scene.event) if not e.done]
    labels = [""] + [f" after event[{i}] ({e.kind} {e.vehicle})" for i, e in todo]
    out = []
    for label, where in zip(labels, configuration_ports(scene)):
        c, avail = mass_centre_B(scene, where), available(owners, where)
        if not any(np.array_equal(c, c0) and np.array_equal(avail, a0) for _, c0, a0 in out):
            out.append((label, c, avail))
    return out


def _check_authority(scene, mode: str) -> None:
    """Refuse a set that cannot deliver what ``mode`` asks of it at every tick, in every
    configuration (:func:`_configurations`: a docked vehicle moves the mass centre the arms are
    about, and its thrusters fire only while it is docked): thruster-only control needs torque
    both ways about each axis; assist needs some torque to dump with (a set that dumps about some
    axes only is flown, and its run's summary says which it lacks; a configuration with no
    thruster that can fire, a vehicle's set while it is away, is flown by the CMGs alone). The
    message names the directions, the configuration and the thrusters that make no torque at all."""
    thr = flown_thrusters(scene)
    for where, c, avail in _configurations(scene):
        if mode == "assist" and not avail.any():
            continue
        missing = missing_torque(scene, c, avail)
        if not missing or (mode == "assist" and len(missing) < 6):
            continue
        D, _ = torque_arms(scene, c)
        on = [i for i in range(len(thr)) if avail[i]]
        size_m = 1.0 + max((np.linalg.norm(np.asarray(thr[i].position_B) - c) for i in on), default=0.0)
        none = [thr[i].name for i in on if np.linalg.norm(D[:, i]) <= AUTHORITY_ROUNDOFF_REL * size_m]
        who = (f"; {_named(none)} make no torque at all (their lines of action pass through the mass centre: "
               "position_B is from the origin of [body] cm, not from the mass centre)") if none else ""
        who += "" if on else "; no thruster can fire (a vehicle's fire only while it is docked)"
        why = "dumps momentum" if mode == "assist" else "controls attitude about every axis"
        at = ", ".join(f"{v:.6g}" for v in c)
        raise FieldError("thruster", f"the set makes no torque about {', '.join(missing)} of B (about the composite "
                                     f"mass centre [{at}] m{where}), and mode '{mode}' {why}{who}")


def check_thrusters(scene) -> None:
    """``[[thruster]]``, ``[[vehicle.thruster]]`` and ``[thrusters]`` agree with each other and
    the rest of the scene."""
    for i, v in enumerate(scene.vehicle):
        if v.thruster and not re.fullmatch(COLUMN_STEM, v.name):
            raise FieldError(f"vehicle[{i}].name", f"'{v.name}' names its thrusters' columns (<vehicle>_<name>): "
                                                   "letters, digits, underscores")
    for i, p in enumerate(scene.port):
        if not re.fullmatch(COLUMN_STEM, p.name) and any(
                p.name in ports and len(ports) > 1 for ports in _vehicle_ports(scene).values()):
            raise FieldError(f"port[{i}].name", f"'{p.name}' names a vehicle's thrusters' columns "
                                                "(<vehicle>_<port>_<name>): letters, digits, underscores")
    thr = flown_thrusters(scene)
    if not thr:
        if scene.thrusters is not None:
            raise FieldError("thrusters", "options without any [[thruster]]")
        return
    names = [t.name for t in thr]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FieldError("thruster", f"names must be unique (a vehicle's are <vehicle>_<name>), repeated: {dup}")
    if scene.controller is None:
        raise FieldError("thruster", "thrusters are fired by the closed loop: add a [controller] table")
    if scene.cmg is None:
        raise FieldError("thruster", "thrusters assist a CMG cluster (and take over from it): add a [cmg] table")
    opt = scene.thrusters or ThrusterOptions()
    if opt.mode == "assist" and scene.cmg.kind == "ideal" and scene.cmg.max_momentum is None:
        raise FieldError("thrusters.mode", "'assist' acts on |h| as a fraction of the CMG capacity: give "
                                           "cmg.max_momentum (kind 'ideal' has no capacity otherwise)")
    period = scene.controller.period
    if opt.mapping == "lp" and len(thr) > len(scene.thruster):
        raise FieldError("thrusters.mapping", "'lp' is not flown with a vehicle's thrusters (they come and go): "
                                              "use 'min_norm_shift'")
    tables = [(f"thruster[{i}]", t) for i, t in enumerate(scene.thruster)]
    tables += [(f"vehicle[{i}].thruster[{j}]", t) for i, v in enumerate(scene.vehicle) for j, t in enumerate(v.thruster)]
    for where, t in tables:
        if t.min_on_s > period:
            raise FieldError(f"{where}.min_on_s", f"{t.min_on_s:g} s is longer than the controller period "
                                                  f"({period:g} s): a pulse is cut at the period")
    if opt.mode != "off":
        _check_authority(scene, opt.mode)
