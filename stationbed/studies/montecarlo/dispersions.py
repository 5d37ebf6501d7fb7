"""Drawing one Monte Carlo sample: the scene's ``[[montecarlo.disperse]]`` entries applied to its
key paths, from the sample's own random stream.

Sample ``k`` of a study with seed ``s`` draws from ``default_rng(sample_seed(s, k))`` where
:func:`sample_seed` comes from ``SeedSequence(entropy=s, spawn_key=(k,))`` (numpy's spawned
streams, independent of each other): the sample is the same alone, in a batch, serially or on
any worker. The dispersions are drawn in the file's order. A draw the scene refuses (an
inertia that is not positive definite or breaks the triangle inequality, a negative mass, a
non-unit quaternion...) is drawn again from the same stream, at most ``max_redraws`` times;
the number of redraws is recorded, and a sample that exhausts them is *refused* (a row with
status ``refused`` and the scene's reason).

Key paths are the ``--set`` paths (:mod:`stationbed.scene.assign`): ``body.inertia``,
``initial.q_BN``, ``torque[0].cos1_B``, ``appendage.stbd_pair.mass`` (an array entry by index
or by name), ``controller.params.bandwidth``, ``cmg.failed``.

A scale kind may list ``also = [key, ...]``: those values are multiplied by the same factor
(e.g. every coefficient of a disturbance torque by one amplitude factor).

Knowledge (docs/design.md "Knowledge is not truth"): the drawn values are the *truth* flown;
flight software keeps believing the nominal value of every dispersed key path (written to the
sample's ``[knowledge.values]``, so ``plant.scene`` and the law's design see the nominal) unless
the dispersion says ``known = true`` (a calibrated parameter: the law is told the drawn value).
Keys under ``controller.`` other than ``controller.sensor.`` are the law's own settings (its
gains): the law is built with the drawn value, so they are always known. A key path the scene's
``[knowledge.values]`` already gives keeps that belief.

Recorded columns (one per drawn number): a scalar key gives the column ``<key>``; an array
``<key>[i]`` (a matrix ``<key>[i][j]``, the upper triangle for ``inertia``); ``attitude_normal``
records the rotation vector of the draw, ``<key>.rotvec[i]`` [rad], and its angle
``<key>.angle`` [rad]; ``choice`` records the
chosen value ``<key>``: a number when every choice is a number, else the value as text
(:func:`choice_value`: ``cmg.failed`` = ``"[2]"``, the failed unit as the scene names it). Each
column ``C`` has its twin ``told.C``: the same quantity in what the law was told (the sample's
knowledge scene): the nominal value (scale 1, rotation 0, the nominal choice) unless the
dispersion is known.
"""

from __future__ import annotations

import difflib
import json
import math

import numpy as np

from ...run.rate_auto import AUTO, scene_choice
from ...scene import Scene, SceneError, knowledge_scene
from ...scene.assign import split_path
from ...scene.knowledge import NAMED_PATHS
from .faults import is_fault_key, occurrence, occurrence_columns, round_times

__all__ = ["sample_seed", "draw", "Draw", "value_at", "check_keys", "drawn_columns", "TOLD", "law_setting",
           "nominal_rate", "choice_value"]

#: prefix of the columns of what the law was told (``told.<column>``)
TOLD = "told."


def sample_seed(seed: int, k: int) -> int:
    """The seed of sample ``k`` (a 64-bit integer) from the study's ``seed``."""
    return int(np.random.SeedSequence(entropy=seed, spawn_key=(k,)).generate_state(1, np.uint64)[0])


def value_at(data: dict, path: str):
    """The value at a key path in a scene's data (``Scene.model_dump()``), or KeyError naming
    the part that is missing (and the nearest existing name)."""
    node = data
    for key in split_path(path):
        if isinstance(node, list) and isinstance(key, str):
            names = [e.get("name") if isinstance(e, dict) else None for e in node]
            if key not in names:
                raise KeyError(f"no entry named '{key}'{_nearest(key, [x for x in names if x])}")
            key = names.index(key)
        if isinstance(node, list):
            if not 0 <= key < len(node):
                raise KeyError(f"no entry [{key}] (there are {len(node)})")
        elif not isinstance(node, dict) or isinstance(key, int) or key not in node:
            near = _nearest(key, list(node)) if isinstance(node, dict) and isinstance(key, str) else ""
            raise KeyError(f"no key '{key}'{near}")
        node = node[key]
    return node


def _nearest(key: str, names: list[str]) -> str:
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


#: what each kind changes: "number" (a number or an array of numbers, any shape), or a shape
KIND_NEEDS = {"normal": "number", "uniform": "number", "scale_normal": "number", "scale_uniform": "number",
              "inertia": (3, 3), "attitude_normal": (4,)}


def _numeric_shape(value):
    """The shape of a number or a rectangular array of numbers (booleans are not numbers), else None."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return None
    if isinstance(value, (int, float)):
        return ()
    if isinstance(value, list):
        shapes = {_numeric_shape(v) for v in value}
        if len(shapes) == 1 and None not in shapes:
            return (len(value), *shapes.pop())
        if not value:
            return (0,)
    return None


class Draw:
    """One sample's drawn scene changes and recorded values.

    Attributes
    ----------
    changes : dict
        Key path -> new value (for :meth:`Scene.replace`).
    values : dict
        Column name -> the recorded number, or text for a non-numeric choice (:mod:`this module's
        <.dispersions>` column rules).
    """

    def __init__(self):
        self.changes: dict = {}
        self.values: dict[str, float | str] = {}


def _record_array(values: dict, key: str, arr) -> None:
    a = np.asarray(arr, dtype=float)
    if a.ndim == 0:
        values[key] = float(a)
    elif a.ndim == 1:
        for i, v in enumerate(a):
            values[f"{key}[{i}]"] = float(v)
    else:
        for i in range(a.shape[0]):
            for j in range(a.shape[1]):
                values[f"{key}[{i}][{j}]"] = float(a[i, j])


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def _draw_one(d, data: dict, rng: np.random.Generator, draw: Draw) -> None:
    key, kind = d.key, d.kind
    base = value_at(data, key)
    bases = [base] + [value_at(data, k) for k in d.also]
    if kind in ("normal", "uniform"):
        v = np.asarray(base, dtype=float)
        off = rng.normal(d.mean, d.sigma, v.shape) if kind == "normal" else rng.uniform(d.low, d.high, v.shape)
        new = v + off
        draw.changes[key] = new.tolist() if new.ndim else float(new)
        _record_array(draw.values, key, new)
    elif kind in ("scale_normal", "scale_uniform"):
        f = 1.0 + (rng.normal(0.0, d.sigma) if kind == "scale_normal" else rng.uniform(d.low, d.high))
        for k, b in zip([key, *d.also], bases):
            new = np.asarray(b, dtype=float) * f
            draw.changes[k] = new.tolist() if new.ndim else float(new)
        draw.values[f"{key}.scale"] = float(f)
    elif kind == "inertia":
        I = np.asarray(base, dtype=float)
        if I.shape != (3, 3):
            raise SceneError(f"kind 'inertia' needs a 3x3 matrix at '{key}', got shape {I.shape}")
        new = I.copy()
        diag = np.diag(I) * (1.0 + rng.normal(0.0, d.sigma, 3))
        new[np.diag_indices(3)] = diag
        for i, j in ((0, 1), (0, 2), (1, 2)):
            off = rng.normal(0.0, d.sigma_products) * math.sqrt(abs(diag[i] * diag[j]))
            new[i, j] = new[j, i] = I[i, j] + off
        draw.changes[key] = new.tolist()
        for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
            draw.values[f"{key}[{i}][{j}]"] = float(new[i, j])
    elif kind == "attitude_normal":
        q = np.asarray(base, dtype=float)
        if q.shape != (4,):
            raise SceneError(f"kind 'attitude_normal' needs a quaternion at '{key}', got shape {q.shape}")
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.normal(0.0, d.sigma)
        dq = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
        new = _quat_mul(q, dq)  # turned about a body axis
        draw.changes[key] = (new / np.linalg.norm(new)).tolist()
        _record_array(draw.values, f"{key}.rotvec", angle * axis)
        draw.values[f"{key}.angle"] = abs(float(angle))
    elif kind == "choice":
        w = None if d.weights is None else np.asarray(d.weights, float) / sum(d.weights)
        i = int(rng.choice(len(d.choices), p=w))
        draw.changes[key] = d.choices[i]
        draw.values[key] = choice_value(d.choices, d.choices[i])
    elif kind == "seed":
        s = int(rng.integers(0, 2**31 - 1))
        draw.changes[key] = s
        draw.values[key] = float(s)
    else:  # pragma: no cover - the scene's Literal refuses it
        raise ValueError(f"unknown dispersion kind {kind!r}")


def choice_value(choices: list, value):
    """The recorded value of a ``choice``: a number when every choice is a number, else the value
    as text, as the scene writes it (``cmg.failed``: ``"[]"``, ``"[2]"``; a string as itself), so
    the table names what was flown rather than its place in the list."""
    if all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in choices):
        return float(value)
    return value if isinstance(value, str) else json.dumps(value)


def law_setting(key: str) -> bool:
    """Whether a key path is the law's own setting (``controller.params...``, its name, period):
    the law is built with the drawn value, so flight software knows it."""
    return key.startswith("controller.") and not key.startswith("controller.sensor")


def _pins(scene: Scene, data: dict, dr: Draw) -> dict:
    """``[knowledge.values]`` of a sample: the file's own, then per dispersed key path the nominal
    value (or, ``known``, the drawn one), except the law's settings and paths the file gives."""
    own = dict(scene.knowledge.values) if scene.knowledge is not None else {}
    pins = dict(own)
    for d in scene.montecarlo.disperse:
        for key in [d.key, *d.also]:
            if law_setting(key) or key in own or is_fault_key(key):  # (faults: never told, FDIR's to learn)
                continue
            pins[key] = dr.changes[key] if d.known else value_at(data, key)
    return pins


def _rotvec(q_from, q_to) -> np.ndarray:
    """The rotation vector [rad] of ``q_from⁻¹ ⊗ q_to`` (shortest way)."""
    q0 = np.asarray(q_from, float)
    dq = _quat_mul(np.array([q0[0], -q0[1], -q0[2], -q0[3]]), np.asarray(q_to, float))
    dq = dq / np.linalg.norm(dq) * (1.0 if dq[0] >= 0 else -1.0)
    s = float(np.linalg.norm(dq[1:]))
    return np.zeros(3) if s == 0.0 else dq[1:] / s * 2.0 * math.atan2(s, dq[0])


def _told_one(d, known: dict, nominal: dict, values: dict) -> None:
    """The ``told.`` columns of dispersion ``d`` from the knowledge scene's data ``known``
    (``nominal``: the study's scene), named as :func:`_draw_one` names the truth's."""
    key, kind, t = d.key, d.kind, TOLD
    if is_fault_key(key):  # flight software is never told a fault (montecarlo/faults.py)
        return
    v = value_at(known, key)
    if kind in ("normal", "uniform"):
        _record_array(values, t + key, v)
    elif kind in ("scale_normal", "scale_uniform"):
        b, a = np.asarray(value_at(nominal, key), float).ravel(), np.asarray(v, float).ravel()
        i = int(np.argmax(np.abs(b))) if b.size else 0
        values[f"{t}{key}.scale"] = float(a[i] / b[i]) if b.size and b[i] != 0.0 else math.nan
    elif kind == "inertia":
        J = np.asarray(v, float)
        for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
            values[f"{t}{key}[{i}][{j}]"] = float(J[i, j])
    elif kind == "attitude_normal":
        r = _rotvec(value_at(nominal, key), v)
        _record_array(values, f"{t}{key}.rotvec", r)
        values[f"{t}{key}.angle"] = float(np.linalg.norm(r))
    elif kind == "choice":
        values[t + key] = choice_value(d.choices, v)
    elif kind == "seed":
        values[t + key] = float(v)


def told(scene: Scene, sample: Scene, nominal: dict | None = None) -> dict[str, float]:
    """The ``told.`` columns of a drawn ``sample`` of ``scene``: what its law was told
    (``nominal``: ``scene.model_dump()``, when the caller has it)."""
    known, values = knowledge_scene(sample).model_dump(), {}
    nominal = scene.model_dump() if nominal is None else nominal
    for d in scene.montecarlo.disperse:
        _told_one(d, known, nominal, values)
    return values


def check_keys(scene: Scene) -> None:
    """Every ``[[montecarlo.disperse]] key`` names a value of the scene that its kind can draw
    (numbers for the numeric kinds), else SceneError naming the entry (checked before any
    sample runs)."""
    data = scene.model_dump()
    for i, d in enumerate(scene.montecarlo.disperse):
        for j, key in enumerate([d.key, *d.also]):
            where = f"montecarlo.disperse[{i}]." + ("key" if j == 0 else f"also[{j - 1}]")
            try:
                split_path(key)
                value = value_at(data, key)
            except (KeyError, ValueError) as e:
                msg = e.args[0] if e.args else str(e)
                raise SceneError(f"{where}: '{key}' names no value of the scene ({msg})") from None
            need = KIND_NEEDS.get(d.kind)
            if need is None:
                continue
            shape = _numeric_shape(value)
            if shape is None or (need != "number" and shape != need):
                what = (f"holds {type(value).__name__} {value!r}" if shape is None else f"has shape {shape}")
                wants = "a number or an array of numbers" if need == "number" else f"an array of shape {need}"
                raise SceneError(f"{where}: '{key}' {what}; kind '{d.kind}' needs {wants}"
                                 + ("; 'choice' draws among listed values of any type" if shape is None else ""))
        _check_known(scene, d, f"montecarlo.disperse[{i}].known")


def _check_known(scene: Scene, d, where: str) -> None:
    """A ``known`` dispersion must not contradict a belief the scene's ``[knowledge]`` states."""
    k = scene.knowledge
    if not d.known or k is None:
        return
    for key in [d.key, *d.also]:
        if key in k.values:
            raise SceneError(f"{where}: '{key}' is given by [knowledge.values]: the scene would state two beliefs")
        for name, path in NAMED_PATHS.items():
            if getattr(k, name) is not None and (key == path or key.startswith(path + ".")):
                raise SceneError(f"{where}: '{key}' is given by [knowledge] {name}: the scene would state two beliefs")


def draw(scene: Scene, k: int, data: dict | None = None) -> tuple[Scene | None, Draw, int, str | None]:
    """The scene of sample ``k`` (``data``: ``scene.model_dump()``, when the caller has it: a
    chunk's samples share it, read only).

    Returns
    -------
    scene : Scene or None
        The drawn scene (None: refused).
    draw : Draw
        The accepted (or last refused) draw's changes and recorded values (the truth drawn and,
        ``told.``, what the law was told; NaN when refused).
    redraws : int
        Draws the scene refused before this one.
    reason : str or None
        Why the sample was refused (the scene's last message), None when accepted.
    """
    mc = scene.montecarlo
    rng = np.random.default_rng(sample_seed(mc.seed, k))
    data = scene.model_dump() if data is None else data
    last = None
    fixed = nominal_rate(scene)  # "auto": the nominal scene's environment rate for every sample
    for redraws in range(mc.max_redraws + 1):
        dr = Draw()
        for d in mc.disperse:
            _draw_one(d, data, rng, dr)
        round_times(scene, dr.changes, dr.values)  # fault times on the tick grid (montecarlo/faults.py)
        pins = _pins(scene, data, dr)
        occurrence(scene, rng, dr.changes, dr.values)
        try:
            s = scene.replace({**dr.changes, **({"knowledge.values": pins} if pins else {}), **fixed},
                              source=f"sample {k}")
        except SceneError as e:
            last = str(e)
            continue
        dr.values.update(told(scene, s, data))
        return s, dr, redraws, None
    dr.values.update({TOLD + c: math.nan for c in list(dr.values) if not is_fault_key(c)})
    return None, dr, mc.max_redraws, f"no valid draw in {mc.max_redraws + 1} tries; last: {last}"


def nominal_rate(scene: Scene) -> dict:
    """``{"simulation.environment_rate": N}`` when ``scene`` asks ``"auto"``: the bound's choice
    for the nominal scene (run/rate_auto.py), which every sample flies (one probe per study,
    not one per sample; docs/design.md "Effects at their own rate"); else ``{}``."""
    if scene.simulation.environment_rate != AUTO:
        return {}
    return {"simulation.environment_rate": scene_choice(scene)["ticks"]}


def drawn_columns(scene: Scene) -> list[str]:
    """The recorded columns of every sample (sample 0's draw; they are the same for all)."""
    mc = scene.montecarlo
    data = scene.model_dump()
    dr = Draw()
    rng = np.random.default_rng(sample_seed(mc.seed, 0))
    for d in mc.disperse:
        _draw_one(d, data, rng, dr)
    return (list(dr.values) + occurrence_columns(scene)
            + [TOLD + c for c in dr.values if not is_fault_key(c)])
