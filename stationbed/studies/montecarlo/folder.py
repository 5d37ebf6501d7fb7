"""A Monte Carlo study's folder: its lock, its identity, and its tagged chunk files.

* ``OUT/study.lock`` is held (``fcntl.flock``, exclusive) while a study runs in ``OUT``: a
  second study started into the same folder is refused at once (the lock goes with the process,
  so a killed study leaves no stale lock).
* The study's identity (:func:`study_identity`) is a hash of the scene without ``montecarlo.n``
  and ``montecarlo.chunk`` (samples do not depend on them: each draws from its own seed) and of
  the controller law's source: the file of its class and every file of its own folder that it
  imports, recursively (:func:`law_sources`). ``study.json`` records the identity and the source
  hashes, so a refused ``--resume`` can say what changed.
* Every chunk file carries the identity in its name, ``chunks/chunk_<study>_<k0>_<k1>.parquet``
  and ``chunks/envelope_<study>_<k0>_<k1>.npy``, and the parquet file in its metadata
  (``stationbed.study``). A resume reads only chunks of its own study and refuses a folder that
  holds chunks of another one; a fresh start removes only files with these names.
"""

from __future__ import annotations

import ast
import errno
import hashlib
import json
import os
import re
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd

from ...scene import SceneError

__all__ = ["StudyStop", "study_identity", "law_sources", "locked", "ChunkFiles", "CHUNK_NAME"]

#: a chunk file this program writes (and the ``.tmp`` it writes first); nothing else is removed
CHUNK_NAME = re.compile(r"^(chunk|envelope)_([0-9a-f]{16})_(\d{10})_(\d{10})\.(parquet|npy)(\.tmp)?$")
#: the parquet metadata key holding the chunk's study
META_KEY = b"stationbed.study"
LOCK_NAME = "study.lock"
STUDY_JSON = "study.json"


def result_files() -> list[str]:
    """The names of the results a study writes at its end (report.finish, charts)."""
    from ...run.metrics import METRICS  # noqa: PLC0415

    return (["samples.parquet", "summary.json", "montecarlo.rrd", "envelope_att_err.png", "envelope_h.png",
             "report.html", "junit.xml"]
            + [f"{kind}_{m}.png" for kind in ("hist", "scatter") for m in METRICS])


class StudyStop(RuntimeError):
    """The study stopped for a reason outside the samples (a full disk, a lost scheduler); the
    message is one line naming the file or address, what is kept and how to resume."""


def _hash_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _local_imports(path: Path) -> list[Path]:
    """The files of ``path``'s own folder that it imports (``import x``, ``from x import y``,
    ``from . import y``, ``from .x import y``): a controller's helpers written beside it."""
    try:
        tree = ast.parse(path.read_text(), str(path))
    except (OSError, SyntaxError, ValueError):
        return []
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            names.append(base)
            if node.level:  # from . import y: y may be a module of the folder
                names += [f"{base}.{a.name}".lstrip(".") for a in node.names]
    found = []
    for name in names:
        if not name:
            continue
        rel = Path(*name.split("."))
        for cand in (path.parent / rel.with_suffix(".py"), path.parent / rel / "__init__.py"):
            if cand.is_file():
                found.append(cand.resolve())
    return found


def law_sources(scene) -> dict[str, str]:
    """``{file: sha256}`` of the controller law's source: the file its class is defined in and
    the files of that folder it imports (recursively). Empty without a controller (or for a
    class without a source file)."""
    spec = scene.controller
    if spec is None:
        return {}
    if getattr(spec, "port", None) is not None:  # a law in another process: no source stationbed can see
        return {}
    if spec.fmu is not None:  # an FMU law: the unit itself is its source (binary and model inside)
        fmu = Path(spec.fmu) if Path(spec.fmu).is_absolute() else Path(scene.folder or ".") / spec.fmu
        fmu = fmu.resolve()
        return {str(fmu): _hash_file(fmu)} if fmu.is_file() else {}
    from ...run.controller import get_controller  # noqa: PLC0415 - loads the law's file

    cls = get_controller(spec.name, base_dir=scene.folder)
    first = getattr(sys.modules.get(cls.__module__), "__file__", None)
    if not first:
        return {}
    todo, seen = [Path(first).resolve()], {}
    while todo:
        p = todo.pop()
        if str(p) in seen or not p.is_file():
            continue
        seen[str(p)] = _hash_file(p)
        todo += _local_imports(p)
    return dict(sorted(seen.items()))


def study_identity(scene) -> tuple[str, dict]:
    """``(id, record)``: the 16-hex identity of the study and what it is made of (for study.json)."""
    data = scene.model_dump(mode="json")
    mc = dict(data["montecarlo"])
    mc.pop("n", None)
    mc.pop("chunk", None)
    # a requirement's id and wording name it in reports: they change no sample and no verdict
    mc["requirement"] = [{k: v for k, v in r.items() if k not in ("id", "text")} for r in mc.get("requirement", [])]
    data["montecarlo"] = mc
    sources = law_sources(scene)
    scene_hash = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
    sid = hashlib.sha256(json.dumps({"scene": scene_hash, "law": sources}, sort_keys=True).encode()).hexdigest()[:16]
    return sid, {"study": sid, "scene_sha256": scene_hash, "law_sources": sources}


def _what_changed(old: dict, new: dict) -> str:
    if "scene_sha256" not in old:
        return "it was written by an earlier version of stationbed, whose chunks are not tagged"
    if old.get("scene_sha256") != new["scene_sha256"]:
        return "the scene changed (a value, a dispersion or a requirement)"
    before, now = old.get("law_sources", {}), new["law_sources"]
    for f in sorted(set(before) | set(now)):
        if before.get(f) != now.get(f):
            return f"the controller law's source {f} changed since its chunks were written"
    return "it was written by another version of stationbed"


#: the study locks this process holds: a forked child (a local Dask worker, .cluster) closes its
#: copies at once, so a worker that outlives its driver cannot keep the folder locked (flock's
#: lock lives until every descriptor of the open file is closed)
_HELD: set = set()


def _close_held_in_child() -> None:
    for fh in list(_HELD):
        try:
            fh.close()
        except OSError:  # pragma: no cover - nothing to release in this process
            pass
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_held_in_child)


@contextmanager
def locked(out: Path):
    """Hold ``out/study.lock`` (exclusive) for the block; SceneError when another study holds it."""
    try:
        import fcntl  # noqa: PLC0415 - POSIX
    except ImportError:  # pragma: no cover - no advisory locks here: run without one
        yield
        return
    path = out / LOCK_NAME
    fh = open(path, "a+")
    _HELD.add(fh)
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            if e.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            fh.seek(0)
            who = fh.read().strip() or "another process"
            raise SceneError(f"{out}: another study is running in this folder ({who}; {path} is locked); "
                             f"wait for it or use another --out") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()}\n")
        fh.flush()
        yield
    finally:
        _HELD.discard(fh)
        fh.close()  # releases the lock


class ChunkFiles:
    """The chunk files of one study in ``out/chunks`` (tagged with the study's identity)."""

    def __init__(self, out: Path, study: str, record: dict):
        self.out, self.study, self.record = out, study, record
        self.dir = out / "chunks"

    def chunk_path(self, k0: int, k1: int) -> Path:
        return self.dir / f"chunk_{self.study}_{k0:010d}_{k1:010d}.parquet"

    def envelope_path(self, k0: int, k1: int) -> Path:
        return self.dir / f"envelope_{self.study}_{k0:010d}_{k1:010d}.npy"

    def _ours(self) -> list[tuple[Path, re.Match]]:
        if not self.dir.is_dir():
            return []
        return [(p, m) for p in sorted(self.dir.iterdir()) if (m := CHUNK_NAME.match(p.name))]

    def start(self) -> None:
        """A fresh study: remove the chunk files this program wrote (any study's) and the last
        study's results (:func:`result_files`), so nothing of it mixes with this one; nothing else."""
        self.dir.mkdir(parents=True, exist_ok=True)
        for p, _ in self._ours():
            p.unlink()
        for name in result_files():
            (self.out / name).unlink(missing_ok=True)

    def write_record(self, record: dict) -> None:
        """``study.json``: the identity (and what it is made of), scene name, n and chunk size."""
        path = self.out / STUDY_JSON
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(record, indent=2) + "\n")
        os.replace(tmp, path)

    def resume(self, n: int, n_env: int) -> dict[int, tuple[int, pd.DataFrame, np.ndarray | None]]:
        """The finished chunks of this study within ``0 .. n-1``: ``{k0: (k1, table, envelope)}``.
        SceneError (one line naming the file, what is kept, how to go on) for a folder of another
        study, a damaged study.json or chunk."""
        self.dir.mkdir(parents=True, exist_ok=True)
        meta = self.out / STUDY_JSON
        kept = f"the chunks in {self.dir} are kept"
        if meta.exists():
            try:
                old = json.loads(meta.read_text())
                if not isinstance(old, dict):
                    raise ValueError("not a JSON object")
            except (ValueError, UnicodeDecodeError) as e:
                raise SceneError(f"{meta} is damaged ({e}); {kept} (each is tagged with its study): delete "
                                 f"{meta} and run again with --resume") from None
            if old.get("study") != self.study:
                raise SceneError(f"{self.out}: --resume: the chunks there belong to another study: "
                                 f"{_what_changed(old, self.record)}; use another --out, or drop --resume to "
                                 f"start over") from None
        others = sorted({m.group(2) for _, m in self._ours() if m.group(2) != self.study})
        if others:
            raise SceneError(f"{self.dir}: --resume: it holds chunk files of another study ({', '.join(others)}) "
                             f"beside this one's; a study never mixes them: move them away or use another --out")
        done: dict = {}
        for p, m in self._ours():
            if m.group(1) != "chunk" or m.group(6):
                continue
            k0, k1 = int(m.group(3)), int(m.group(4))
            if k1 > n:
                continue  # beyond this run's n
            df = self._read_chunk(p, k0, k1)
            env = None
            if n_env:
                env = self._read_envelope(self.envelope_path(k0, k1), k1 - k0, n_env)
            if any(a < k1 and k0 < done[a][0] for a in done):
                raise SceneError(f"{p} overlaps another chunk of this study; {kept}: remove one and run again "
                                 f"with --resume")
            done[k0] = (k1, df, env)
        return done

    def _damaged(self, p: Path, why: str) -> SceneError:
        return SceneError(f"{p} is damaged ({why}); the other chunks in {self.dir} are kept: delete it and run "
                          f"again with --resume (its samples run again)")

    def _read_chunk(self, p: Path, k0: int, k1: int) -> pd.DataFrame:
        import pyarrow.parquet as pq  # noqa: PLC0415

        try:
            table = pq.read_table(p)
        except Exception as e:  # noqa: BLE001 - pyarrow's errors for a truncated or foreign file
            raise self._damaged(p, f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}") from None
        tag = (table.schema.metadata or {}).get(META_KEY, b"").decode(errors="replace")
        if tag != self.study:
            raise self._damaged(p, f"its content is tagged with study '{tag or 'none'}', not {self.study}")
        df = table.to_pandas()
        if "index" not in df or list(df["index"]) != list(range(k0, k1)):
            raise self._damaged(p, f"it does not hold samples {k0}..{k1 - 1}")
        return df

    def _read_envelope(self, p: Path, rows: int, n_env: int) -> np.ndarray:
        try:
            env = np.load(p, allow_pickle=False)
        except FileNotFoundError:
            raise self._damaged(p, "missing beside its chunk") from None
        except (OSError, ValueError, EOFError) as e:
            raise self._damaged(p, f"{type(e).__name__}: {e}") from None
        if env.ndim != 3 or env.shape[:2] != (rows, n_env):
            raise self._damaged(p, f"shape {env.shape}, expected ({rows}, {n_env}, 2)")
        return env

    def write(self, k0: int, k1: int, df: pd.DataFrame, env: np.ndarray | None) -> None:
        """Write one finished chunk (envelope first: the parquet file marks it finished).
        StudyStop naming the file when the disk refuses (full, read-only)."""
        import pyarrow as pa  # noqa: PLC0415
        import pyarrow.parquet as pq  # noqa: PLC0415

        def atomic(path, write):
            tmp = path.with_name(path.name + ".tmp")
            try:
                write(tmp)
                os.replace(tmp, path)
            except OSError as e:
                tmp.unlink(missing_ok=True)
                n_kept = sum(1 for _, m in self._ours() if m.group(1) == "chunk" and not m.group(6))
                raise StudyStop(f"cannot write {path}: {e.strerror or e}; the {n_kept} finished chunks in {self.dir} "
                                f"are kept: free the disk and run the same command again with --resume") from e

        if env is not None:
            def save_env(tmp):
                with open(tmp, "wb") as fh:
                    np.save(fh, env)
            atomic(self.envelope_path(k0, k1), save_env)
        table = pa.Table.from_pandas(df, preserve_index=False)
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), META_KEY: self.study.encode()})
        atomic(self.chunk_path(k0, k1), lambda tmp: pq.write_table(table, tmp))
