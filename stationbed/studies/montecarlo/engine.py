"""The Monte Carlo driver: chunks of samples run serially or on Dask, each finished chunk written
as it arrives (``OUT/chunks/``), then the table, statistics, charts and recording.

Work: the samples ``0 .. n-1`` are cut into chunks of ``chunk`` samples (the unit of work, so
task overhead is amortised); a chunk is a pure function of (scene, k0, k1), submitted under a
key naming the study and its range, so Dask re-runs a chunk whose worker died and the result
is the same. Before dispatch the driver builds the scene's compiled system (a short run of the
base scene), so workers load it from the disk cache instead of compiling it each.

Files (``out`` given): ``chunks/chunk_<k0>_<k1>.parquet`` and ``chunks/envelope_<k0>_<k1>.npy``
per finished chunk; ``study.json`` (what the chunks belong to: a re-run with ``resume`` skips
the chunks already on disk only when it matches); at the end ``samples.parquet`` (every row,
by index), ``summary.json``, the charts and ``montecarlo.rrd``. Ctrl-C (KeyboardInterrupt)
cancels what is queued and keeps every finished chunk.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ...core import progress
from ...run.metrics import METRICS
from ...run.simulation import simulate
from ...scene import Scene, SceneError, load_scene
from .dispersions import check_keys, drawn_columns
from .report import finish
from .samples import ID_COLUMNS, run_chunk

__all__ = ["MonteCarloResult", "run_study", "study_scene", "chunk_size", "envelope_times"]

#: chunks per worker when the scene does not say (a few per worker balances the load)
CHUNKS_PER_WORKER = 4
#: largest default chunk [samples]
MAX_CHUNK = 50


@dataclass
class MonteCarloResult:
    """A finished (or partial) Monte Carlo study.

    Attributes
    ----------
    df : pandas.DataFrame
        One row per sample, by index: ``index, seed, status, reason, redraws, stopped_at_s``,
        the drawn values, then every metric of :data:`stationbed.run.metrics.METRICS`.
    summary : dict
        What ``summary.json`` holds: counts, per-metric statistics, requirement verdicts.
    envelope_t : ndarray, shape (T,)
        Envelope times [s] (empty without envelopes).
    envelope : ndarray, shape (n, T, 2) or None
        Per sample the attitude error [deg] and |h| / capacity at ``envelope_t``.
    out : Path or None
        The study's folder.
    """

    df: pd.DataFrame
    summary: dict
    envelope_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    envelope: np.ndarray | None = None
    out: Path | None = None


def study_scene(scene, n: int | None = None) -> Scene:
    """The scene with its ``[montecarlo]`` table checked (and ``n`` overridden)."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if scene.montecarlo is None:
        raise SceneError(f"scene '{scene.name}': no [montecarlo] table (n, seed, [[montecarlo.disperse]] ...)")
    if n is not None:
        scene = scene.replace({"montecarlo.n": n})
    check_keys(scene)
    for i, r in enumerate(scene.montecarlo.requirement):
        if r.metric not in METRICS:
            close = difflib.get_close_matches(r.metric, list(METRICS), n=1, cutoff=0.5)
            hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(METRICS)}"
            raise SceneError(f"montecarlo.requirement[{i}].metric: unknown metric '{r.metric}'; {hint}")
    return scene


def chunk_size(scene, workers: int) -> int:
    """The scene's ``montecarlo.chunk``, or about n / (CHUNKS_PER_WORKER workers), capped."""
    mc = scene.montecarlo
    if mc.chunk:
        return mc.chunk
    return max(1, min(MAX_CHUNK, math.ceil(mc.n / (CHUNKS_PER_WORKER * max(1, workers)))))


def envelope_times(scene) -> int:
    """Number of envelope times ``0, dt, ...`` within the run (0: no envelopes)."""
    dt = scene.montecarlo.envelope_dt
    if dt is None:
        return 0
    out_dt = scene.simulation.output_dt
    ratio = dt / out_dt
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise SceneError(f"montecarlo.envelope_dt: {dt:g} s is not a whole number of output steps "
                         f"(simulation.output_dt = {out_dt:g} s)")
    return int(math.floor(scene.simulation.duration / dt + 1e-9)) + 1


def _study_id(scene, chunk: int) -> str:
    text = json.dumps({"scene": scene.model_dump(mode="json"), "chunk": chunk}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _warm(scene) -> None:
    """Build (or load) the compiled system and the fused loop of ``scene`` in this process, by a
    run of two output steps (the fused loop is compiled per output step): workers then load
    them from the disk cache instead of each compiling them."""
    short = min(scene.simulation.duration, 2 * scene.simulation.output_dt)
    try:
        simulate(scene.replace({"simulation.duration": short}), keep=False)
    except Exception:  # noqa: BLE001 - a failing base scene still runs its samples (and records why)
        pass


def _write_atomic(path: Path, write) -> None:
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    os.replace(tmp, path)


def _frame(rows: list[dict], columns: list[str]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    for c in columns:
        if c not in df:
            df[c] = np.nan
    df = df[columns]
    df["index"] = df["index"].astype("int64")
    df["seed"] = df["seed"].astype("uint64")
    df["redraws"] = df["redraws"].astype("int64")
    df["status"] = df["status"].astype(str)
    df["reason"] = df["reason"].astype(str)
    return df


@contextmanager
def _ctrl_c_kept():
    """Ctrl-C that is never lost: yields a list that becomes non-empty at SIGINT.

    The handler raises KeyboardInterrupt as Python's own does, and also records it: a signal
    that lands while casadi's SWIG layer converts an argument is swallowed there (seen: a study
    ran to its end after Ctrl-C), so the engine checks the record between chunks too. Only in
    the main thread and over Python's default handler (a caller's own handler is left alone)."""
    seen: list[int] = []
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield seen
        return

    def handler(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def run_study(scene, *, n=None, out=None, client=None, workers=None, chunk=None, resume=False,
              charts=True, scheduler=None) -> MonteCarloResult:
    """Run a Monte Carlo study (see :func:`stationbed.montecarlo`)."""
    scene = study_scene(scene, n)
    mc = scene.montecarlo
    n = mc.n
    n_env = envelope_times(scene)
    own_cluster = None
    if client is None and scheduler is not None:
        from distributed import Client  # noqa: PLC0415

        client = Client(scheduler, timeout="30s")
        own_cluster = client
    n_workers = workers or (len(client.scheduler_info().get("workers", {})) if client is not None else 1) or 1
    size = chunk or chunk_size(scene, n_workers)
    ranges = [(k0, min(k0 + size, n)) for k0 in range(0, n, size)]
    columns = ID_COLUMNS + drawn_columns(scene) + list(METRICS)
    study = _study_id(scene, size)
    done: dict[int, tuple[pd.DataFrame, np.ndarray | None]] = {}
    chunks_dir = None
    if out is not None:
        out = Path(out)
        chunks_dir = out / "chunks"
        chunks_dir.mkdir(parents=True, exist_ok=True)
        meta = out / "study.json"
        info = {"study": study, "scene": scene.name, "n": n, "chunk": size}
        if resume and meta.exists():
            if json.loads(meta.read_text()).get("study") != study:
                raise SceneError(f"{out}: --resume: the chunks there belong to another study (scene, n or chunk "
                                 f"changed); use another --out or drop --resume")
            for k0, k1 in ranges:
                p = chunks_dir / f"chunk_{k0:07d}_{k1:07d}.parquet"
                if p.exists():
                    env_p = chunks_dir / f"envelope_{k0:07d}_{k1:07d}.npy"
                    done[k0] = (pd.read_parquet(p), np.load(env_p) if n_env and env_p.exists() else None)
        elif not resume:
            for p in chunks_dir.glob("*_*_*.*"):
                p.unlink()
        meta.write_text(json.dumps(info, indent=2) + "\n")

    def keep(res):
        df = _frame(res["rows"], columns)
        env = res["envelope"]
        k0, k1 = res["k0"], res["k1"]
        if chunks_dir is not None:
            if env is not None:
                _write_atomic(chunks_dir / f"envelope_{k0:07d}_{k1:07d}.npy", lambda p: np.save(open(p, "wb"), env))
            _write_atomic(chunks_dir / f"chunk_{k0:07d}_{k1:07d}.parquet", lambda p: df.to_parquet(p, index=False))
        done[k0] = (df, env)

    todo = [(k0, k1) for k0, k1 in ranges if k0 not in done]
    wall0 = time.perf_counter()
    failures = sum(int((d["status"] != "ok").sum()) for d, _ in done.values())
    with progress.task(f"montecarlo {scene.name}", total=n, unit="sample") as bar, _ctrl_c_kept() as ctrl_c:
        n_done = sum(len(d) for d, _ in done.values())
        n_resumed = n_done

        def show():
            ran = n_done - n_resumed
            eta = (time.perf_counter() - wall0) / ran * (n - n_done) if ran else math.nan
            bar.update(n_done, f"{n_done}/{n} samples, {failures} failed" + (f", ETA {eta:.0f} s" if ran else ""))

        show()
        cluster = None
        try:
            if todo:
                _warm(scene)
            if todo and client is None and workers:
                from distributed import Client, LocalCluster  # noqa: PLC0415 - dask only when asked

                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
                client = Client(cluster)
            if client is None:
                for k0, k1 in todo:
                    res = run_chunk(scene, k0, k1, n_env)
                    keep(res)
                    n_done += k1 - k0
                    failures += sum(r["status"] != "ok" for r in res["rows"])
                    show()
                    if ctrl_c:  # a Ctrl-C that casadi swallowed
                        raise KeyboardInterrupt
            elif todo:
                from distributed import as_completed  # noqa: PLC0415

                sc = client.scatter(scene, broadcast=True)
                futures = [client.submit(run_chunk, sc, k0, k1, n_env, key=f"montecarlo-{study}-{k0}-{k1}",
                                         retries=2) for k0, k1 in todo]
                try:
                    for fut in as_completed(futures):
                        res = fut.result()
                        keep(res)
                        n_done += res["k1"] - res["k0"]
                        failures += sum(r["status"] != "ok" for r in res["rows"])
                        show()
                        fut.release()
                        if ctrl_c:
                            raise KeyboardInterrupt
                except BaseException:
                    client.cancel(futures)
                    raise
        finally:
            if cluster is not None:
                client.close()
                cluster.close()
            if own_cluster is not None:
                own_cluster.close()
    wall = time.perf_counter() - wall0
    order = sorted(done)
    df = pd.concat([done[k][0] for k in order], ignore_index=True)
    env = np.concatenate([done[k][1] for k in order]) if n_env else None
    env_t = np.arange(n_env) * mc.envelope_dt if n_env else np.zeros(0)
    result = MonteCarloResult(df=df, summary={}, envelope_t=env_t, envelope=env, out=out)
    finish(scene, result, wall_s=wall, workers=n_workers if client is not None else 0, chunk=size,
           draw_charts=charts and out is not None)
    return result
