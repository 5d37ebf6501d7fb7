"""The whole scene (:class:`Scene`), and loading it from TOML or a dict with one-line errors."""

from __future__ import annotations

import difflib
import tomllib
from pathlib import Path

from pydantic import BaseModel, PrivateAttr, ValidationError, model_validator

from .base import SceneError, Strict
from .tables import TAGS, Appendage, Body, Cmg, ControllerSpec, Initial, Orbit, Simulation, Sun, Torque

__all__ = ["Scene", "load_scene", "scene_from_dict"]


class Scene(Strict):
    """A validated scene. Build it with :func:`load_scene` or :func:`scene_from_dict`."""

    name: str
    description: str = ""
    simulation: Simulation
    initial: Initial = Initial()
    body: Body
    appendage: list[Appendage] = []
    orbit: Orbit | None = None
    torque: list[Torque] = []
    sun: Sun | None = None
    cmg: Cmg | None = None
    controller: ControllerSpec | None = None
    _folder: Path | None = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _consistent(self):
        names = [a.name for a in self.appendage]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"appendage names must be unique, repeated: {sorted(dup)}")
        if self.orbit is None:
            if self.initial.frame == "lvlh":
                raise ValueError("initial.frame = 'lvlh' needs an [orbit] table")
            for t in self.torque:
                if t.needs_orbit:
                    raise ValueError(f"torque kind '{t.kind}' needs an [orbit] table")
            if self.sun is not None and self.sun.beta is not None:
                raise ValueError("sun.beta needs an [orbit] table (or give sun.direction_N)")
        tracking = [a.name for a in self.appendage if a.tracks_sun]
        if tracking and self.sun is None:
            raise ValueError(f"appendage '{tracking[0]}' tracks the sun: add a [sun] table")
        if self.controller is not None:
            c = self.controller
            ticks = self.simulation.output_dt / c.period
            if abs(ticks - round(ticks)) > 1e-9 * ticks or round(ticks) < 1:
                raise ValueError(
                    f"simulation.output_dt ({self.simulation.output_dt} s) must be a whole number of "
                    f"controller periods ({c.period} s)"
                )
            d = c.sensor.delay / c.period
            if abs(d - round(d)) > 1e-9 * max(d, 1.0):
                raise ValueError(f"controller.sensor.delay ({c.sensor.delay} s) must be a whole number of periods")
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

    def replace(self, **changes) -> "Scene":
        """A copy with dotted-path changes, e.g. ``replace(**{"simulation.rtol": 1e-12})``.

        The copy is re-validated, so a bad value raises :class:`SceneError`.
        """
        data = self.model_dump()
        for path, value in changes.items():
            node = data
            keys = path.split(".")
            for k in keys[:-1]:
                node = node[k]
            node[keys[-1]] = value
        new = scene_from_dict(data, source=f"scene {self.name!r}")
        new._folder = self._folder
        return new


# ---------------------------------------------------------------------------------------
# error formatting
# ---------------------------------------------------------------------------------------



def _valid_keys(model: type[BaseModel]) -> list[str]:
    return list(model.model_fields)


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The pydantic model class that owns the field at ``loc[:-1]`` (for key suggestions)."""
    model: type[BaseModel] | None = Scene
    for part in loc[:-1]:
        if model is None:
            return None
        if isinstance(part, int):
            continue
        if part in TAGS:
            model = TAGS[part]
            continue
        field = model.model_fields.get(part)
        if field is None:
            return None
        model = _inner_model(field.annotation)
    return model


def _inner_model(annotation) -> type[BaseModel] | None:
    import typing

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        m = _inner_model(arg)
        if m is not None:
            return m
    return None


def _path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in TAGS:
            continue  # pydantic's discriminator tag, not a user key
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _one_line(err: ValidationError) -> str:
    errors = err.errors()
    # a typo'd key also makes the intended key "missing": name the typo, it is the cause
    e = next((x for x in errors if x["type"] == "extra_forbidden"), errors[0])
    loc = tuple(e["loc"])
    path = _path(loc)
    etype = e["type"]
    if etype == "extra_forbidden":
        model = _model_at(loc)
        hint = ""
        if model is not None:
            close = difflib.get_close_matches(str(loc[-1]), _valid_keys(model), n=1, cutoff=0.5)
            hint = f"; did you mean '{close[0]}'?" if close else f"; valid keys: {', '.join(_valid_keys(model))}"
        return f"{path}: unknown key{hint}"
    if etype == "missing":
        return f"{path}: missing required key"
    if etype == "finite_number":
        return f"{path}: must be a finite number, not NaN or inf"
    if etype in ("too_short", "too_long"):
        return f"{path}: wrong length ({e['msg'].lower()})"
    msg = e["msg"].removeprefix("Value error, ")
    more = f" (and {len(err.errors()) - 1} more problem(s))" if len(err.errors()) > 1 else ""
    return f"{path}: {msg}{more}"


def scene_from_dict(data: dict, source: str = "scene") -> Scene:
    """Validate a scene given as a dict (the parsed TOML)."""
    try:
        return Scene.model_validate(data)
    except ValidationError as err:
        raise SceneError(f"{source}: {_one_line(err)}") from None


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
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: malformed TOML ({e})") from None
    scene = scene_from_dict(data, source=str(path))
    scene._folder = path.resolve().parent
    return scene
