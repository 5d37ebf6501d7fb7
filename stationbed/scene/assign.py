"""Key paths and ``KEY.PATH=VALUE`` assignments (the command line's ``--set``).

A key path names one value of a scene the way its error messages do: table keys joined by ``.``,
``[i]`` for the i-th entry of an array (counting from 0), and, after an array of named tables,
the entry's ``name`` instead of its index::

    simulation.rtol    appendage[0].alpha.rate    appendage.stbd_array.mode[1].damping
    initial.omega_BN_B[2]    torque[0].stop    controller.params.kp

The value is read as a TOML value: ``1e-10``, ``300``, ``true``, ``[0.0, 1e-3, 0.0]``,
``"rk4"`` (text needs its quotes), ``{altitude = 4e5}`` (a whole table).
:meth:`~stationbed.scene.Scene.replace` applies the assignments and validates the result like a file.
"""

from __future__ import annotations

import functools
import re
import tomllib
from typing import Iterable

from .base import SceneError

__all__ = ["parse_assignment", "parse_assignments", "split_path", "KeyPathError"]

_SEGMENT = re.compile(r"([A-Za-z0-9_-]+)((?:\[[0-9]+\])*)")
_INDEX = re.compile(r"\[([0-9]+)\]")
#: a bare word (no quotes, not a TOML literal): most likely text whose quotes the shell ate
_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.:/+-]*")


class KeyPathError(ValueError):
    """A key path that is not well formed or names no value; ``str(err)`` is one line."""


def split_path(path: str) -> list[str | int]:
    """The keys (``str``) and array indices (``int``) of a key path.

    Raises
    ------
    KeyPathError
        ``path`` is not keys joined by ``.`` with optional ``[i]`` indices.
    """
    return list(_split(path))


@functools.lru_cache(maxsize=4096)
def _split(path: str) -> tuple[str | int, ...]:
    """:func:`split_path` as a tuple, kept per path (a Monte Carlo sample splits the same ~50
    paths: its dispersions' and its knowledge's, issue 25)."""
    keys: list[str | int] = []
    for segment in path.split("."):
        m = _SEGMENT.fullmatch(segment)
        if m is None:
            raise KeyPathError(
                f"{path!r} is not a key path (keys joined by '.', [i] for an array entry: appendage[0].alpha.rate)"
            )
        keys.append(m.group(1))
        keys.extend(int(i) for i in _INDEX.findall(m.group(2)))
    return tuple(keys)


def parse_assignment(text: str, option: str = "--set") -> tuple[str, object]:
    """``"simulation.rtol=1e-10"`` -> ``("simulation.rtol", 1e-10)``: a key path and a TOML value.

    Parameters
    ----------
    text : str
        ``KEY.PATH=VALUE``; spaces around the key and the value are ignored, the value is read
        as TOML (text in quotes, ``true``/``false``, numbers, arrays, inline tables).
    option : str
        The option's name, to start the error message with.

    Raises
    ------
    SceneError
        One line, ``<option> '<text>': <reason>``: no ``=``, a malformed key path or value.
    """
    where = f"{option} {_shorten(text, 60)!r}"
    key, sep, raw = text.partition("=")
    if not sep:
        raise SceneError(f"{where}: expected KEY.PATH=VALUE")
    key, raw = key.strip(), raw.strip()
    try:
        split_path(key)
    except KeyPathError:
        raise SceneError(f"{where}: {key!r} is not a key path (keys joined by '.', [i] for an array entry)") from None
    return key, _toml_value(raw, where, key, option)


def parse_assignments(texts: Iterable[str], option: str = "--set") -> dict[str, object]:
    """Several ``KEY.PATH=VALUE`` texts (a repeated option) -> ``{path: value}`` in their order.

    Raises
    ------
    SceneError
        A malformed text (:func:`parse_assignment`), or the same key path given twice.
    """
    out: dict[str, object] = {}
    for text in texts:
        key, value = parse_assignment(text, option)
        if key in out:
            raise SceneError(f"{option}: {key} given twice")
        out[key] = value
    return out


def _shorten(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def _toml_value(raw: str, where: str, key: str, option: str) -> object:
    """``raw`` read as one TOML value, or a one-line SceneError starting with ``where``."""
    short = _shorten(raw, 40)
    try:
        table = tomllib.loads(f"value = {raw}")
    except RecursionError:
        raise SceneError(f"{where}: {short!r} is not a TOML value (nested too deeply)") from None
    except ValueError:  # TOMLDecodeError, or an integer past Python's digit limit
        hint = f"; text needs quotes: {option} '{key}=\"{raw}\"'" if _BARE_WORD.fullmatch(raw) else ""
        raise SceneError(
            f"{where}: {short!r} is not a TOML value (a number, true/false, \"text\", [array] or {{table}}){hint}"
        ) from None
    if list(table) != ["value"]:
        raise SceneError(f"{where}: {short!r} is not one TOML value")
    return table["value"]
