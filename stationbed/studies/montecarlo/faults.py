"""Scheduled faults in a Monte Carlo study (issue 34 item 4; docs/design.md "Scheduled steps and
faults").

A ``[[fault]]`` key is dispersed like any key path: ``fault.<i or name>.t`` (``uniform``,
``normal``: the drawn time is **rounded to the control tick grid**, ``k * period`` with the
nearest k, so every draw is a valid step time; the column records the rounded time),
``fault.<i>.unit`` and ``fault.<i>.kind`` (``choice``). A fault whose ``probability`` is below 1
occurs in a sample with that probability: one uniform number per such fault, drawn from the
sample's stream after the dispersions, in the file's order; a fault that does not occur stays
in the sample's scene with ``enabled = false`` (its key paths and columns stay the same). Each
sample records per fault ``fault.<id>.occurred`` (1/0; ``<id>`` its name, else its index), and
the drawn values of a fault that did not occur are NaN. Flight software is never told a
fault (no ``told.`` twin, no ``[knowledge.values]`` pin): what it learns is the FDIR's
detection columns.
"""

from __future__ import annotations

import math

from ...scene.assign import split_path

__all__ = ["is_fault_key", "fault_id", "round_times", "occurrence", "occurrence_columns"]


def is_fault_key(key: str) -> bool:
    """Whether a key path is under ``[[fault]]`` (never pinned in knowledge, no ``told.`` twin)."""
    return split_path(key)[0] == "fault"


def fault_id(scene, i: int) -> str:
    """A fault's id in its columns: its name, else its index."""
    f = scene.fault[i]
    return f.name if f.name is not None else str(i)


def round_times(scene, changes: dict, values: dict) -> None:
    """Drawn fault times (``fault.<i>.t`` / ``.until``) rounded to the tick grid in ``changes``
    and their recorded columns in ``values``."""
    if not scene.fault or scene.controller is None:
        return
    period = scene.controller.period
    for key, v in list(changes.items()):
        parts = split_path(key)
        if len(parts) == 3 and parts[0] == "fault" and parts[2] in ("t", "until") and isinstance(v, float):
            changes[key] = round(v / period) * period
            if key in values:
                values[key] = changes[key]


def occurrence(scene, rng, changes: dict, values: dict) -> None:
    """Whether each fault occurs in this sample (its ``probability``; one draw from ``rng`` per
    fault below 1): ``fault[i].enabled = false`` in ``changes`` for those that do not, the
    ``fault.<id>.occurred`` columns, and NaN for the drawn values of a fault that did not occur."""
    for i, f in enumerate(scene.fault):
        occurs = f.probability >= 1.0 or bool(rng.uniform() < f.probability)
        values[f"fault.{fault_id(scene, i)}.occurred"] = float(occurs)
        if not occurs:
            changes[f"fault[{i}].enabled"] = False
            for col in values:
                if col.endswith(".occurred") or not is_fault_key(col):
                    continue
                ref = split_path(col)[1]
                names = [g.name for g in scene.fault]
                if (ref if isinstance(ref, int) else names.index(ref) if ref in names else -1) == i:
                    if isinstance(values[col], float):
                        values[col] = math.nan


def occurrence_columns(scene) -> list[str]:
    """The ``fault.<id>.occurred`` columns (one per fault of the study's scene)."""
    return [f"fault.{fault_id(scene, i)}.occurred" for i in range(len(scene.fault))]
