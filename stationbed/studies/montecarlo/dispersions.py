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

Recorded columns (one per drawn number): a scalar key gives the column ``<key>``; an array
``<key>[i]`` (a matrix ``<key>[i][j]``, the upper triangle for ``inertia``); ``attitude_normal``
records the rotation vector of the draw, ``<key>.rotvec[i]`` [rad], and its angle
``<key>.angle`` [rad]; ``choice`` records the
chosen value when every choice is a number, else its index ``<key>.choice``.
"""

from __future__ import annotations

import difflib
import math

import numpy as np

from ...scene import Scene, SceneError
from ...scene.assign import split_path

__all__ = ["sample_seed", "draw", "Draw", "value_at", "check_keys", "drawn_columns"]


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
        Column name -> the recorded number (:mod:`this module's <.dispersions>` column rules).
    """

    def __init__(self):
        self.changes: dict = {}
        self.values: dict[str, float] = {}


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
        numeric = all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in d.choices)
        if numeric:
            draw.values[key] = float(d.choices[i])
        else:
            draw.values[f"{key}.choice"] = float(i)
    elif kind == "seed":
        s = int(rng.integers(0, 2**31 - 1))
        draw.changes[key] = s
        draw.values[key] = float(s)
    else:  # pragma: no cover - the scene's Literal refuses it
        raise ValueError(f"unknown dispersion kind {kind!r}")


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


def draw(scene: Scene, k: int) -> tuple[Scene | None, Draw, int, str | None]:
    """The scene of sample ``k``.

    Returns
    -------
    scene : Scene or None
        The drawn scene (None: refused).
    draw : Draw
        The accepted (or last refused) draw's changes and recorded values.
    redraws : int
        Draws the scene refused before this one.
    reason : str or None
        Why the sample was refused (the scene's last message), None when accepted.
    """
    mc = scene.montecarlo
    rng = np.random.default_rng(sample_seed(mc.seed, k))
    data = scene.model_dump()
    last = None
    for redraws in range(mc.max_redraws + 1):
        dr = Draw()
        for d in mc.disperse:
            _draw_one(d, data, rng, dr)
        try:
            return scene.replace(dr.changes, source=f"sample {k}"), dr, redraws, None
        except SceneError as e:
            last = str(e)
    return None, dr, mc.max_redraws, f"no valid draw in {mc.max_redraws + 1} tries; last: {last}"


def drawn_columns(scene: Scene) -> list[str]:
    """The recorded columns of every sample (sample 0's draw; they are the same for all)."""
    mc = scene.montecarlo
    data = scene.model_dump()
    dr = Draw()
    rng = np.random.default_rng(sample_seed(mc.seed, 0))
    for d in mc.disperse:
        _draw_one(d, data, rng, dr)
    return list(dr.values)
