"""One sample on its own: its exact scene as a TOML file (the drawn values filled in) and a
single run of it, whose metrics equal the sample's row of the study bit for bit (the same
scene, the same run, the same :class:`~stationbed.run.metrics.RunMetrics`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from ...scene import Scene, SceneError, load_scene
from .dispersions import draw, sample_seed

__all__ = ["sample_scene", "scene_toml", "write_sample_scene"]


def sample_scene(scene: Scene, k: int) -> Scene:
    """The scene of sample ``k`` (SceneError when the sample is refused)."""
    mc = scene.montecarlo
    if not 0 <= k < mc.n:
        raise SceneError(f"--sample {k}: the study has samples 0..{mc.n - 1}")
    s, _, _, refused = draw(scene, k)
    if s is None:
        raise SceneError(f"sample {k} is refused: {refused}")
    return s


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError("a scene holds no NaN or inf")
        return repr(v)  # shortest repr: reads back to the same double
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string is a JSON string for these characters
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)


def _table(lines: list, name: str, data: dict, array: bool = False) -> None:
    simple = {k: v for k, v in data.items() if not _is_table(v) and not _is_table_array(v)}
    lines.append(f"\n[[{name}]]" if array else f"\n[{name}]")
    lines += [f"{_key(k)} = {_value(v)}" for k, v in simple.items()]
    for k, v in data.items():
        if _is_table(v):
            _table(lines, f"{name}.{_key(k)}", v)
        elif _is_table_array(v):
            for e in v:
                _table(lines, f"{name}.{_key(k)}", e, array=True)


def _is_table(v) -> bool:
    return isinstance(v, dict)


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(e, dict) for e in v)


def scene_toml(scene: Scene, header: str = "") -> str:
    """``scene`` as a TOML file that loads back to an equal scene (its own keys only)."""
    data = scene.model_dump(exclude_unset=True)
    lines = [f"# {h}" for h in header.splitlines()]
    top = {k: v for k, v in data.items() if not _is_table(v) and not _is_table_array(v)}
    lines += [f"{_key(k)} = {_value(v)}" for k, v in top.items()]
    for k, v in data.items():
        if _is_table(v):
            _table(lines, _key(k), v)
        elif _is_table_array(v):
            for e in v:
                _table(lines, _key(k), e, array=True)
    return "\n".join(lines) + "\n"


def write_sample_scene(scene: Scene, k: int, path: Path) -> Scene:
    """Write sample ``k``'s scene to ``path`` and return it as loaded back from the file (so a
    run of the return value is a run of the file). The ``[montecarlo]`` table stays (its
    ``settle_s`` defines the windows of ``rms_att_err_deg`` and the estimation metrics) without its
    dispersions."""
    s = sample_scene(scene, k)
    mc = scene.montecarlo
    changes = {"montecarlo.disperse": []}
    c = s.controller
    if c is not None and ":" in c.name and scene.folder is not None:  # a controller file, found
        module, _, cls = c.name.rpartition(":")                         # from the new file's folder
        if (module.endswith(".py") or "/" in module) and not Path(module).expanduser().is_absolute():
            changes["controller.name"] = f"{(scene.folder / module).resolve()}:{cls}"
    if c is not None and c.fmu is not None and scene.folder is not None and not Path(c.fmu).expanduser().is_absolute():
        changes["controller.fmu"] = str((scene.folder / c.fmu).resolve())  # an FMU law, likewise
    if c is not None and c.fmu is None and scene.folder is not None:  # a law's files (schedule's plan)
        from ...run.controller import get_controller

        for p in get_controller(c.name, base_dir=scene.folder).file_params:
            if isinstance(c.params.get(p), str) and not Path(c.params[p]).expanduser().is_absolute():
                changes[f"controller.params.{p}"] = str((scene.folder / c.params[p]).resolve())
    s = s.replace(changes)
    header = (f"sample {k} of the Monte Carlo study of '{scene.name}' (seed {mc.seed}, sample seed "
              f"{sample_seed(mc.seed, k)}): the drawn values are filled in\n"
              f"written by: stationbed montecarlo --sample {k}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scene_toml(s, header))
    back = load_scene(path)
    if back.model_dump() != s.model_dump():
        raise SceneError(f"{path}: the written scene does not read back equal (a bug: please report it)")
    return back
