"""Every plug-in kind a scene can name, one untruncated line each (``stationbed list``, issue 37).

Each group is read from its registry (never from a list kept here), and each line's description
from the class's docstring: its first sentence, or the module's when the class has none of its
own or defers to it ("see the module docstring"). Reading the registries means a kind registered
tomorrow is listed without an edit here; tests/test_plugins_list.py checks every entry appears.
"""

from __future__ import annotations

import inspect
import re
import sys
import typing

__all__ = ["plugin_groups", "describe", "format_listing"]

#: words that end in a full stop without ending a sentence ("TP-2511 Eq. 17", "e.g. a")
_ABBREVIATIONS = ("Eq", "Eqs", "e.g", "i.e", "cf", "et al", "vs", "Fig", "No")


def _plain(text: str) -> str:
    """Docstring markup to plain text: ``x`` -> x, :func:`~a.b.c` -> c, one line."""
    text = re.sub(r":\w+:`~?([^`]*)`", lambda m: m.group(1).rsplit(".", 1)[-1] if "~" in m.group(0) else m.group(1), text)
    text = text.replace("``", "")
    return " ".join(text.split())


def _first_sentence(paragraph: str) -> str:
    for m in re.finditer(r"\.(\s+)(?=[A-Z(])", paragraph):
        before = paragraph[: m.start()]
        if not before.endswith(_ABBREVIATIONS):
            return before + "."
    return paragraph


def _summary(doc: str | None) -> str:
    """The first sentence of a docstring's first paragraph, with a leading ``kind = "x":`` (the
    scene line the class implements, already said by the listing's name column) left out."""
    para = _plain(inspect.cleandoc(doc or "").split("\n\n")[0])
    para = re.sub(r'^\[?[\w\[\]. ]*kind = "\w+"\]?:\s*', "", para)
    para = re.sub(r"^\[orbit\] \w+ = \w+:\s*", "", para)
    return _first_sentence(para).strip()


def describe(cls) -> str:
    """One line saying what ``cls`` is: its own docstring's first sentence, or its module's."""
    own = cls.__dict__.get("__doc__")
    if own and not re.search(r"\bsee the module docstring", own.split("\n\n")[0]):
        return _summary(own)
    module = cls.__module__.rsplit(".", 1)[-1]
    return re.sub(rf"^{module}:\s*", "", _summary(sys.modules[cls.__module__].__doc__))


def _estimators() -> dict[str, str]:
    """``[estimator] kind`` -> description, from the scene's estimator tables (a union of them)."""
    from .scene import Scene

    out = {}
    for model in typing.get_args(Scene.model_fields["estimator"].annotation) or (Scene.model_fields["estimator"].annotation,):
        if model is type(None) or "kind" not in getattr(model, "model_fields", {}):
            continue
        for kind in typing.get_args(model.model_fields["kind"].annotation):
            out[kind] = _summary(model.__doc__)
    return out


def _steering_laws() -> dict[str, str]:
    """``[cmg] steering`` -> its name in the steering module's docstring list (``* ``mp`` Moore-Penrose: ...``)."""
    from .model.cmg import steering

    doc = steering.__doc__ or ""
    out = {}
    for name in steering.STEERING_LAWS:
        m = re.search(rf"^\* ``{name}``\s+(.*?):", doc, re.M)
        out[name] = m.group(1) if m else ""
    return out


def plugin_groups() -> list[tuple[str, dict[str, str]]]:
    """(group heading, {name: one-line description}) for every kind a scene can name."""
    from .formulations import FORMULATIONS
    from .integrators import INTEGRATORS
    from .loop import cmg_cluster, thrusters  # noqa: F401  (they register their actuator kinds)
    from .loop.actuator import ACTUATORS
    from .loop.registry import SENSORS
    from .model.cmg.cluster import CMG_GEOMETRIES
    from .model.torques import TORQUES
    from .run.controller import controller_registry
    from .scene.faults import FAULT_KINDS
    from .scene.montecarlo import DISPERSION_KIND_DOCS, DISPERSION_KINDS

    laws = {}
    for name, cls in sorted(controller_registry().items()):
        laws[name] = f"[{cls.command}] {describe(cls)}"
    return [
        ('attitude laws: [controller] name (or "module:Class", "path/file.py:Class", fmu = "law.fmu")', laws),
        ("sensors: [[sensor]] kind", {n: describe(c) for n, c in SENSORS.items()}),
        ("estimators: [estimator] kind", _estimators()),
        ("actuators (from [cmg], [[thruster]] or neither)", {n: describe(c) for n, c in ACTUATORS.items()}),
        ("CMG geometries: [cmg] kind", {n: describe(c) for n, c in CMG_GEOMETRIES.items()}),
        ("CMG steering laws: [cmg] steering", _steering_laws()),
        ("torque kinds: [[torque]] kind (gravity_gradient: [orbit] gravity_gradient)", {n: describe(c) for n, c in TORQUES.items()}),
        ("formulations: [simulation] formulation", {n: c.description for n, c in FORMULATIONS.items()}),
        ("integrators: [simulation] integrator", {n: describe(c) for n, c in INTEGRATORS.items()}),
        ("dispersion kinds: [[montecarlo.disperse]] kind", {n: DISPERSION_KIND_DOCS[n] for n in DISPERSION_KINDS}),
        ("fault kinds: [[fault]] kind (unit: its target)", {n: f"[{k.target}] {k.doc}" for n, k in FAULT_KINDS.items()}),
    ]


def format_listing(groups=None) -> str:
    """The listing as printed: a heading per group, then ``  name  description`` per kind, each on
    one line whatever the terminal's width (a narrow terminal wraps it; nothing is cut)."""
    groups = plugin_groups() if groups is None else groups
    lines = []
    for heading, entries in groups:
        lines.append(f"{heading}:")
        width = max((len(n) for n in entries), default=0)
        lines += [f"  {name:<{width}}  {text}".rstrip() for name, text in entries.items()]
    return "\n".join(lines)
