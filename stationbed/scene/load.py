"""The whole scene (:class:`Scene`), loading it from TOML or a dict, and changing it by key path,
with one-line errors."""

from __future__ import annotations

import copy
import difflib
import re
import tomllib
import typing
from collections.abc import Mapping
from pathlib import Path

from pydantic import BaseModel, Field, PrivateAttr, ValidationError, model_validator

from .assign import KeyPathError, split_path
from .base import TIME_RESOLUTION, FieldError, SceneError, Strict
from .docking import Event, Port, Vehicle, check_docking
from .fdir import Fdir, ModeCommand, check_fdir
from .knowledge import Knowledge, knowledge_scene
from .magnetorquers import Magnetorquers, check_magnetorquers
from .plan import PlanSpec
from .sensors import MekfEstimator, Sensing, SensorEntry, check_sensing
from .faults import Fault, check_faults
from . import sensor_faults  # noqa: F401,E402 (registers the sensor kinds of [[fault]])
from .thrusters import Thruster, ThrusterOptions, check_thrusters
from .wing import check_plate_faces, wing_surface
from .tables import TAGS, Appendage, Atmosphere, Body, Cmg, ControllerSpec, Initial, MonteCarlo, Orbit, Simulation, Sun, Surface, Torque

__all__ = ["Scene", "load_scene", "scene_from_dict", "sensing_from_dict"]


class Scene(Strict):
    """A validated scene. Build it with :func:`load_scene` or :func:`scene_from_dict`; change it
    with :meth:`replace`."""

    name: str
    description: str = ""
    simulation: Simulation
    initial: Initial = Field(default_factory=Initial)  # (a table of its own per scene: knowledge.py)
    body: Body
    appendage: list[Appendage] = []
    orbit: Orbit | None = None
    torque: list[Torque] = []
    sun: Sun | None = None
    cmg: Cmg | None = None
    controller: ControllerSpec | None = None
    surface: list[Surface] = []
    atmosphere: Atmosphere | None = None
    montecarlo: MonteCarlo | None = None
    plan: PlanSpec | None = None
    sensor: list[SensorEntry] = []  # issue 20: flown by the closed loop (stationbed/loop/)
    estimator: MekfEstimator | None = None
    knowledge: Knowledge | None = None
    thruster: list[Thruster] = []  # issue 21: fired by the closed loop (stationbed/loop/thrusters.py)
    thrusters: ThrusterOptions | None = None
    magnetorquers: Magnetorquers | None = None  # issue 33: stationbed/loop/magnetorquers.py
    fdir: Fdir | None = None  # issue 34: flight software's fault detection (stationbed/loop/fdir.py)
    mode: list[ModeCommand] = []  # issue 34: the mode manager's scheduled commands
    fault: list[Fault] = []  # issue 34: scheduled steps of the truth (stationbed/run/schedule.py)
    port: list[Port] = []  # issue 35: docking ports, visiting vehicles, configuration events (scene/docking.py)
    vehicle: list[Vehicle] = []
    event: list[Event] = []
    _folder: Path | None = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _consistent(self):
        names = [a.name for a in self.appendage]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise FieldError("appendage", f"names must be unique, repeated: {sorted(dup)}")
        if self.orbit is None:
            if self.initial.frame == "lvlh":
                raise FieldError("initial.frame", "'lvlh' needs an [orbit] table")
            for i, t in enumerate(self.torque):
                if t.needs_orbit:
                    raise FieldError(f"torque[{i}].kind", f"'{t.kind}' needs an [orbit] table")
            if self.sun is not None and self.sun.beta is not None:
                raise FieldError("sun.beta", "needs an [orbit] table (or give sun.direction_N)")
        for i, a in enumerate(self.appendage):
            if a.tracks_sun and self.sun is None:
                raise FieldError(f"appendage[{i}]", f"'{a.name}' tracks the sun: add a [sun] table")
        _check_environment(self)
        check_plate_faces(self)
        if self.controller is not None:
            c, sim = self.controller, self.simulation
            if c.period < TIME_RESOLUTION * sim.duration:
                raise FieldError("controller.period", f"{c.period:g} s is below {TIME_RESOLUTION:g} of the duration "
                                                      f"({sim.duration:g} s), finer than the time grid resolves")
            ticks = sim.output_dt / c.period
            if abs(ticks - round(ticks)) > 1e-9 * ticks or round(ticks) < 1:
                raise FieldError("simulation.output_dt", f"{sim.output_dt:g} s is not a whole number of controller "
                                                         f"periods ({c.period:g} s)")
            d = c.sensor.delay / c.period
            if abs(d - round(d)) > 1e-9 * max(d, 1.0):
                raise FieldError("controller.sensor.delay", f"{c.sensor.delay:g} s is not a whole number of "
                                                            f"controller periods ({c.period:g} s)")
        _check_plan(self)
        _check_sensors(self)
        _check_knowledge(self)
        check_docking(self)  # (first: the thrusters' arms are about the mass centre of each configuration)
        check_thrusters(self)
        check_magnetorquers(self)
        check_fdir(self)
        check_faults(self)
        return self

    # -- convenience -------------------------------------------------------------------
    @property
    def folder(self) -> Path | None:
        """The folder of the file the scene was loaded from (relative file names in the scene,
        e.g. ``controller.name = "laws/x.py:X"``, are found there); None when built from a dict."""
        return self._folder

    @property
    def appendage_names(self) -> list[str]:
        """The appendages' names, in the file's order."""
        return [a.name for a in self.appendage]

    @property
    def surfaces(self) -> list[Surface]:
        """The ``[[surface]]`` tables, then each wing's plate (scene/wing.py), in appendage order."""
        return list(self.surface) + [wing_surface(a) for a in self.appendage if a.wing is not None]

    def replace(self, changes: Mapping[str, object] | None = None, /, *, source: str | None = None, **more) -> "Scene":
        """A copy with values changed at key paths, validated as a whole like a file.

        ``scene.replace({"simulation.rtol": 1e-10, "appendage.stbd.mass": 3e3})``; the same
        mapping may be spelled as keywords, ``scene.replace(**{"simulation.rtol": 1e-10})``.

        Parameters
        ----------
        changes : mapping of str to object
            ``{key path: value}`` (see :mod:`stationbed.scene.assign` for the paths:
            ``"simulation.rtol"``, ``"appendage[0].alpha.rate"``, ``"appendage.stbd.mass"``),
            values as TOML gives them (a table as a dict). A table missing from the scene is
            created, as a dotted key in TOML does; an assigned table replaces the old one.
        source : str, optional
            Starts the error message (default: ``scene '<name>'``); the command line gives
            ``"<file> with --set"``.
        **more
            More changes (key paths that are not Python names need ``**{...}``).

        Raises
        ------
        SceneError
            One line naming the field: an unknown key (with the nearest valid one), an entry
            that does not exist, or a value the file would refuse, with the file's message.
        """
        source = source or f"scene {self.name!r}"
        data, defaults = self.model_dump(exclude_unset=True), self.model_dump()
        for path, value in {**(changes or {}), **more}.items():
            try:
                _assign(data, defaults, path, _plain(value))
            except KeyPathError as e:
                raise SceneError(f"{source}: {e}") from None
            except RecursionError:
                raise SceneError(f"{source}: values nested too deeply") from None
        new = _validated(data, source)  # (a dump is plain already, new containers: only the values are made so)
        new._folder = self._folder
        return new


def _check_sensors(scene) -> None:
    """``[[sensor]]`` and ``[estimator]`` agree with each other and with the controller (issue 20)."""
    if not scene.sensor and scene.estimator is None:
        return
    if scene.controller is None:
        raise FieldError("sensor", "sensors are flown by the closed loop: add a [controller] table")
    c = scene.controller
    check_sensing(scene.sensor, scene.estimator, c.period)
    for i, s in enumerate(scene.sensor):
        if getattr(s, "moon_exclusion", None) is not None and (scene.sun is None or scene.sun.epoch is None):
            raise FieldError(f"sensor[{i}].moon_exclusion", "needs [sun] epoch (the Moon's place is computed for a "
                                                            "date: stationbed/model/moon.py)")
    if scene.estimator is not None and (c.sensor.attitude_noise > 0 or c.sensor.rate_noise > 0 or c.sensor.delay > 0):
        raise FieldError("controller.sensor", "with an [estimator] the law flies on the estimate: the ideal "
                                              "measurement's noise and delay must be 0")


def _check_knowledge(scene) -> None:
    """``[knowledge]`` describes a plant the scene accepts (one-line FieldError naming it)."""
    k = scene.knowledge
    if k is None:
        return
    for name in ("failed_units", "cmg", "failure_detected_after_s"):
        if getattr(k, name) is not None and scene.cmg is None:
            raise FieldError(f"knowledge.{name}", "needs a [cmg] table")
    try:
        knowledge_scene(scene)
    except SceneError as e:
        raise FieldError("knowledge", f"the plant it believes is refused: {str(e).removeprefix('[knowledge]: ')}") from None


def _check_plan(scene) -> None:
    """``[plan]`` agrees with the rest of the scene (one-line FieldError)."""
    plan = scene.plan
    if plan is None:
        return
    orbit = scene.orbit
    if orbit is not None and orbit.kepler:
        raise FieldError("plan", "plans on a circular orbit ('radius' or 'altitude'), not a two-body one")
    if plan.frame == "lvlh" and orbit is None:
        raise FieldError("plan.frame", "'lvlh' needs an [orbit] table")
    if scene.initial.frame != plan.frame:
        raise FieldError("plan.frame", f"'{plan.frame}' differs from initial.frame '{scene.initial.frame}': "
                                       "state both attitudes in one frame")
    cmg = scene.cmg
    if cmg is None:
        raise FieldError("plan", "needs a [cmg] table: a plan keeps the CMG momentum within its limits")
    ideal = cmg.kind == "ideal"
    where = "[cmg] max_momentum" if ideal else f"a gimballed cluster ({cmg.kind}): its usable |h| is a choice"
    if plan.max_momentum is None and not (ideal and cmg.max_momentum is not None):
        raise FieldError("plan.max_momentum", f"missing: give it ({where})")
    where = "[cmg] max_torque" if ideal else f"a gimballed cluster ({cmg.kind}): its torque follows its gimbal rates"
    if plan.max_torque is None and not (ideal and cmg.max_torque is not None):
        raise FieldError("plan.max_torque", f"missing: give it ({where})")


def _check_environment(scene) -> None:
    """The environment keys of issue 14 agree with each other (one-line FieldError)."""
    kinds = [t.kind for t in scene.torque]
    for kind in ("aero", "srp"):
        if kinds.count(kind) > 1:
            raise FieldError("torque", f"kind '{kind}' given {kinds.count(kind)} times (once models it)")
    if "srp" in kinds and scene.sun is None:
        raise FieldError("torque", "kind 'srp' needs a [sun] table")
    if scene.atmosphere is not None and "aero" not in kinds:
        raise FieldError("atmosphere", "has no effect without a [[torque]] kind = 'aero'")
    if scene.surface and not {"aero", "srp"} & set(kinds):
        raise FieldError("surface", f"{len(scene.surface)} surface(s) but no [[torque]] uses them: they have no effect "
                                    "without kind = 'aero' or 'srp' (add one, or remove the [[surface]] tables: --set surface=[])")
    if scene.atmosphere is not None and scene.atmosphere.model == "msis" and (scene.sun is None or scene.sun.epoch is None):
        raise FieldError("atmosphere.model", "'msis' needs [sun] epoch (the date of the density)")
    if scene.sun is not None and scene.sun.eclipse != "none" and scene.orbit is None:
        raise FieldError("sun.eclipse", "needs an [orbit] table")
    names = scene.appendage_names
    for i, s in enumerate(scene.surface):
        if s.on != "body" and s.on not in names:
            close = difflib.get_close_matches(s.on, names + ["body"], n=1, cutoff=0.5)
            hint = f"; did you mean '{close[0]}'?" if close else f"; valid: body, {', '.join(names)}"
            raise FieldError(f"surface[{i}].on", f"no appendage named '{s.on}'{hint}")
    for i, a in enumerate(scene.appendage):
        for j in ("alpha", "beta"):
            jt = getattr(a, j)
            if jt.tracked and jt.night == "glider" and (scene.sun is None or scene.sun.eclipse == "none"):
                raise FieldError(f"appendage[{i}].{j}.night", "'glider' needs [sun] eclipse = 'cylindrical' or 'conical'")


# ---------------------------------------------------------------------------------------
# changing a scene's data by key path
# ---------------------------------------------------------------------------------------


def _assign(data: dict, defaults: dict, path: str, value) -> None:
    """Put ``value`` at ``path`` in ``data`` (a scene's own keys; ``defaults`` has every key).

    Keys are checked against the tables (an unknown one gets the nearest valid key, as in a
    file); below a free-form table (``controller.params``) or a choice of tables (a joint, a
    torque) the final validation checks them. A missing table is created, a missing array is
    taken from ``defaults``."""
    if not isinstance(path, str):
        raise KeyPathError(f"{path!r} is not a key path")
    keys = split_path(path)
    model: type[BaseModel] | None = Scene  # the table class at ``node``, when there is exactly one
    node, full, where = data, defaults, ""
    for n, key in enumerate(keys):
        here = f"{where}[{key}]" if isinstance(key, int) else (f"{where}.{key}" if where else key)
        if isinstance(node, list):
            if isinstance(key, str):
                key = _index_by_name(node, key, where, here)
            if not 0 <= key < len(node):
                raise KeyPathError(f"{here}: no such entry ({where} has {len(node)})")
        elif isinstance(node, dict):
            if isinstance(key, int):
                raise KeyPathError(f"{here}: {where} is a table, not an array")
            if model is not None and key not in model.model_fields and model.model_config.get("extra") != "allow":
                raise KeyPathError(f"{here}: {_unknown_key(model, key)}")
        else:
            raise KeyPathError(f"{here}: {where} is a value, not {'an array' if isinstance(key, int) else 'a table'}")
        if n == len(keys) - 1:
            node[key] = value
            return
        if isinstance(key, str) and model is not None:
            model = _inner_model(model.model_fields[key].annotation)
        full = _child(full, key)
        child = _child(node, key)
        if child is None:  # not in the file: a table is created, an array starts as its default
            child = copy.deepcopy(full) if isinstance(full, list) else {}
            node[key] = child
        node, where = child, here


def _child(node, key):
    if isinstance(node, dict):
        return node.get(key)
    if isinstance(node, list) and isinstance(key, int) and 0 <= key < len(node):
        return node[key]
    return None


def _index_by_name(entries: list, name: str, where: str, here: str) -> int:
    names = [e.get("name") if isinstance(e, dict) else None for e in entries]
    if not any(isinstance(x, str) for x in names):
        raise KeyPathError(f"{here}: {where} entries have no names; use {where}[i]")
    if name in names:
        return names.index(name)
    close = difflib.get_close_matches(name, [x for x in names if isinstance(x, str)], n=1, cutoff=0.5)
    hint = f"; did you mean '{close[0]}'?" if close else f"; names: {', '.join(x for x in names if isinstance(x, str))}"
    raise KeyPathError(f"{here}: no {where} named '{name}'{hint}")


# ---------------------------------------------------------------------------------------
# error formatting
# ---------------------------------------------------------------------------------------

#: what a field of each strict type takes, for "must be ..., got ..." messages
_EXPECTED = {
    "float_type": "a number", "int_type": "an integer", "bool_type": "true or false", "string_type": "a string",
    "list_type": "an array", "dict_type": "a table", "model_type": "a table", "model_attributes_type": "a table",
}
#: pydantic's bound checks -> (words, ctx key), the bound printed with %g ("1e-06", not "0.000001")
_BOUNDS = {
    "greater_than": ("greater than", "gt"), "greater_than_equal": ("greater than or equal to", "ge"),
    "less_than": ("less than", "lt"), "less_than_equal": ("less than or equal to", "le"),
}
#: longest rendering of a given value in a message [characters]
_GIVEN_CHARS = 40


def _models_in(annotation) -> list[type[BaseModel]]:
    """The table classes an annotation holds (``list[Appendage]``, ``Orbit | None``, a union ...)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_in(arg) if m]


def _inner_model(annotation) -> type[BaseModel] | None:
    """The one table class an annotation holds, or None (none, or a choice of several)."""
    models = set(_models_in(annotation))
    return models.pop() if len(models) == 1 else None


def _model_at(loc: tuple, root: type[BaseModel] | None = None) -> type[BaseModel] | None:
    """The pydantic model class that owns the field at ``loc[:-1]`` below ``root`` (default: the
    scene) (for key suggestions)."""
    model: type[BaseModel] | None = root or Scene
    for part in loc[:-1]:
        if part in TAGS:  # pydantic's tag of the table chosen in a union
            model = TAGS[part]
            continue
        if isinstance(part, int):  # an entry of a list (of one table, or of a union: a tag follows)
            continue
        if model is None:
            return None
        field = model.model_fields.get(part)
        if field is None:
            return None
        model = _inner_model(field.annotation)
    return model


def _unknown_key(model: type[BaseModel], key: str) -> str:
    """``unknown key; did you mean '<nearest>'?`` (or the valid keys) for ``key`` in ``model``."""
    valid = list(model.model_fields)
    close = difflib.get_close_matches(str(key), valid, n=1, cutoff=0.5)
    return f"unknown key; did you mean '{close[0]}'?" if close else f"unknown key; valid keys: {', '.join(valid)}"


#: an entry name that can stand in a key path for its index (``sensor.st1``; assign.split_path)
_KEY_NAME = re.compile(r"[A-Za-z0-9_-]+")


def _entry_name(entries, i: int) -> str | None:
    """The name of array entry ``i`` when it can name it in a key path (a string, unique in the
    array, a key-path word), else None."""
    if not isinstance(entries, list) or not 0 <= i < len(entries) or not isinstance(entries[i], dict):
        return None
    name = entries[i].get("name")
    names = [e.get("name") for e in entries if isinstance(e, dict)]
    ok = isinstance(name, str) and _KEY_NAME.fullmatch(name) and names.count(name) == 1
    return name if ok else None


def _path(loc, data=None) -> str:
    """The key the user wrote for ``loc`` (pydantic's location, or a check's field path split):
    an array entry that has a name is named, as ``--set`` names it (``sensor.st1.nea``), else it
    is indexed (``torque[0]``); pydantic's union tags are left out. ``data``: the scene's input."""
    out = ""
    node = data
    for part in loc:
        if isinstance(part, int):
            name = _entry_name(node, part)
            out += f".{name}" if name is not None else f"[{part}]"
            node = node[part] if isinstance(node, list) and 0 <= part < len(node) else None
        elif part in TAGS:
            continue  # pydantic's discriminator tag, not a user key
        else:
            out += ("." if out else "") + str(part)
            node = node.get(part) if isinstance(node, dict) else None
    return out


def _field_path(loc: tuple, field: str, data) -> str:
    """The key of a check's :class:`FieldError` ``field`` (``sensor[2].period``) below ``loc``,
    entries named as :func:`_path` names them."""
    try:
        parts = split_path(field)
    except KeyPathError:  # not a key path: as the check wrote it
        return f"{_path(loc, data) + '.' if loc else ''}{field}"
    return _path((*loc, *parts), data)


def _did_you_mean(given, valid: list[str]) -> str:
    """``; did you mean '<nearest>'?`` for a misspelt ``given`` among ``valid`` (else "")."""
    close = difflib.get_close_matches(given, valid, n=1, cutoff=0.6) if isinstance(given, str) else []
    return f"; did you mean '{close[0]}'?" if close else ""


def _quoted(text: str) -> list[str]:
    """The values quoted in pydantic's list of choices (``"'ideal', 'dgcmg' or 'sgcmg'"``)."""
    return re.findall(r"'([^']*)'", text or "")


def _unknown_kind(e, path: str) -> str | None:
    """A table whose ``kind`` chooses no table of a union (``[[torque]]``, ``[[sensor]]``): the
    kind the user wrote, the nearest valid one and the valid ones; None when it is not that."""
    given = e.get("input")
    kind = given.get("kind") if isinstance(given, dict) else None
    valid = _quoted(e.get("ctx", {}).get("expected_tags") if e["type"] == "union_tag_invalid" else e["msg"])
    valid = [v.removeprefix("kind=") for v in valid]
    if not isinstance(kind, str) or not valid:
        return None
    return f"{path}.kind: unknown kind '{kind}'{_did_you_mean(kind, valid)} (valid: {', '.join(valid)})"


def _given(value) -> str:
    """``value`` as a TOML file writes it, shortened for a one-line message."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        try:
            text = str(value)
        except ValueError:  # past Python's digit limit for int -> str
            return "an integer of over 4300 digits"
        return text if len(text) <= 20 else f"an integer of {len(text.lstrip('-'))} digits"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        text = repr(value)[1:-1].replace('"', '\\"')
        return f'"{text}"' if len(text) <= _GIVEN_CHARS else f'"{text[:_GIVEN_CHARS - 3]}..."'
    if isinstance(value, (dict, BaseModel)):
        return "a table"
    if isinstance(value, list):
        inner = ", ".join(_given(v) if not isinstance(v, (list, dict)) else "[...]" for v in value[:4])
        text = f"[{inner}{', ...' if len(value) > 4 else ''}]"
        return text if len(text) <= _GIVEN_CHARS else f"an array of {len(value)}"
    if hasattr(value, "isoformat"):  # TOML dates and times
        return value.isoformat()
    return type(value).__name__


def _one_line(err: ValidationError, root: type[BaseModel] | None = None, data=None) -> str:
    """The first problem of ``err`` as one line starting with the key the user wrote (``data``:
    the input, to name array entries by their names)."""
    errors = err.errors()
    # a typo'd key also makes the intended key "missing": name the typo, it is the cause
    e = next((x for x in errors if x["type"] == "extra_forbidden"), errors[0])
    loc = tuple(e["loc"])
    path = _path(loc, data)
    etype = e["type"]
    if etype in ("union_tag_invalid", "unknown_kind"):
        kind = _unknown_kind(e, path)
        if kind is not None:
            return kind
    more = f" (and {len(errors) - 1} more problem(s))" if len(errors) > 1 else ""
    if etype == "extra_forbidden":
        model = _model_at(loc, root)
        return f"{path}: {_unknown_key(model, loc[-1]) if model is not None else 'unknown key'}"
    if etype == "missing":
        return f"{path}: missing required key"
    if etype == "finite_number":
        return f"{path}: must be a finite number, not NaN or inf"
    if etype in ("too_short", "too_long"):
        return f"{path}: wrong length ({e['msg'].lower()})"
    given = e.get("input")
    if etype == "float_type" and isinstance(given, int) and not isinstance(given, bool):
        return f"{path}: must be a finite number, got {_given(given)}"  # an integer too large for a double
    if etype in _EXPECTED:
        return f"{path}: must be {_EXPECTED[etype]}, got {_given(given)}{more}"
    if etype in _BOUNDS:
        words, key = _BOUNDS[etype]
        return f"{path}: must be {words} {e['ctx'][key]:g}, got {_given(given)}{more}"
    cause = e.get("ctx", {}).get("error")
    if isinstance(cause, FieldError):  # a table's cross-field check naming its field
        return f"{_field_path(loc, cause.field, data)}: {cause.reason}{more}"
    msg = e["msg"].removeprefix("Value error, ")
    if etype in ("value_error", "unknown_kind"):  # the scene's own checks say what they found
        return f"{path or '(top level)'}: {msg}{more}"
    msg = msg.replace("Input should be", "must be", 1)
    hint = _did_you_mean(given, _quoted(e.get("ctx", {}).get("expected"))) if etype == "literal_error" else ""
    return f"{path or '(top level)'}: {msg}, got {_given(given)}{hint}{more}"


def _plain(value):
    """``value`` as TOML would give it: tuples and numpy arrays as lists, numpy scalars as Python
    numbers (a scene built in Python); everything else unchanged, for the strict types to judge."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):
        return _plain(value.tolist())
    return value


def scene_from_dict(data: dict, source: str = "scene") -> Scene:
    """Validate a scene given as a dict (the parsed TOML, or built in Python: tuples and numpy
    values are taken as TOML arrays and numbers); raises :class:`SceneError` with a one-line
    reason starting with ``source``."""
    try:
        data = _plain(data)
    except RecursionError:
        raise SceneError(f"{source}: values nested too deeply") from None
    return _validated(data, source)


def _validated(data: dict, source: str) -> Scene:
    """:func:`scene_from_dict` of data already as TOML gives it (:func:`_plain`)."""
    try:
        return Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(f"{source}: {_one_line(err, data=data)}") from None
    except RecursionError:
        raise SceneError(f"{source}: values nested too deeply") from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file; raises :class:`SceneError` with a one-line reason."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file") from None
    except RecursionError:
        raise SceneError(f"{path}: malformed TOML (arrays or tables nested too deeply)") from None
    except ValueError as e:  # TOMLDecodeError, or an integer past Python's digit limit
        reason = str(e).split(";")[0].splitlines()[0]
        raise SceneError(f"{path}: malformed TOML ({reason})") from None
    scene = scene_from_dict(data, source=str(path))
    scene._folder = path.resolve().parent
    return scene


def sensing_from_dict(data: dict, source: str = "scene") -> Sensing:
    """Validate ``{"sensor": [...], "estimator": {...}}`` (the parsed TOML); raises
    :class:`SceneError` with a one-line reason starting with ``source``."""
    data = _plain(data)
    try:
        return Sensing.model_validate(data)
    except ValidationError as err:
        raise SceneError(f"{source}: {_one_line(err, root=Sensing, data=data)}") from None
