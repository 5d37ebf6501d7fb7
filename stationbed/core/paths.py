"""Where commands write: the default output folder and the check of outputs against inputs.

Every command that writes files (``run``, ``montecarlo``, ``linearize``, ``margins``, ``plot``,
``compare``) builds its default folder with :func:`default_out` and checks its output paths with
:func:`check_outputs` before it opens any of them, so a scene's name can never lead outside
``out/`` and an output can never replace an input (the scene file, a run's CSV) or another output.
"""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from pathlib import Path

__all__ = ["OUT_ROOT", "BadOutput", "WriteFailed", "default_out", "safe_name", "check_outputs", "partial_path",
           "fresh", "writing", "write_bytes", "CSV_NAME", "PARTIAL_CSV", "SUMMARY_NAME"]

#: the folder every default output goes under (relative to the working folder)
OUT_ROOT = Path("out")
#: a run's rows: ``trajectory.partial.csv`` while it runs (and after a failure), then ``trajectory.csv``
CSV_NAME = "trajectory.csv"
PARTIAL_CSV = "trajectory.partial.csv"
SUMMARY_NAME = "summary.json"


class BadOutput(ValueError):
    """An output path that is an input, another output, or a folder (exit 2, nothing written)."""


class WriteFailed(OSError):
    """An output that could not be written (a full disk, a file-size limit): one line naming the
    file and the system's reason (exit 1; what was written before stays)."""

    def __init__(self, path, err: OSError):
        super().__init__(err.errno, err.strerror or str(err), str(path))

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"


def fresh(path) -> Path:
    """``path`` made ready for a new file: a file or a link already there is removed (a link
    itself, never what it points to), so the write that follows creates a file of its own."""
    path = Path(path)
    if path.is_symlink() or path.is_file():
        path.unlink()
    return path


@contextmanager
def writing(path):
    """Write one output at ``path`` (yielded): a new file (:func:`fresh`), and any ``OSError``
    while writing it becomes :class:`WriteFailed` naming it."""
    path = fresh(path)
    try:
        yield path
    except WriteFailed:
        raise
    except OSError as e:
        raise WriteFailed(path, e) from None


def write_bytes(path, data: bytes) -> Path:
    """``data`` as a new file at ``path`` (:func:`writing`)."""
    with writing(path) as p, open(p, "xb") as f:
        f.write(data)
    return p


def safe_name(name: str) -> str:
    """A scene name as one folder name (no separators, no ``..``, never absolute or empty)."""
    clean = re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_")
    return clean or "scene"


def default_out(scene_name: str | None, *parts: str, suffix: str = "") -> Path:
    """``out/<scene name><suffix>/<parts...>`` with the name made one folder name by
    :func:`safe_name` (``../x`` and ``/abs`` stay inside ``out/``)."""
    return OUT_ROOT.joinpath(safe_name(scene_name or "") + suffix, *parts)


def partial_path(path: Path) -> Path:
    """``rec.rrd`` -> ``rec.partial.rrd``: where an output is written until its run ends."""
    path = Path(path)
    return path.with_name(f"{path.stem}.partial{path.suffix}")


def check_outputs(inputs: dict[str, Path], outputs: dict[str, Path]) -> None:
    """Refuse (:class:`BadOutput`, naming the path and the option to change) any output that is
    an input, another output, or an existing folder. Paths are compared after resolving links.

    Parameters
    ----------
    inputs : dict
        What each input is (``"the scene file"``) -> its path.
    outputs : dict
        What each output is (``"--rrd"``, ``"the sample's scene file"``) -> its path.
    """
    seen: dict[str, str] = {}
    for what, p in [*inputs.items(), *outputs.items()]:
        key = os.path.realpath(p)
        if key in seen:
            raise BadOutput(f"{p} is both {seen[key]} and {what}: choose another output path (--out, --rrd, --png)")
        seen[key] = what
        if what in outputs and what not in inputs and Path(key).is_dir():
            raise BadOutput(f"{p} ({what}) is a folder")
