"""The Monte Carlo driver: chunks of samples run serially or on Dask, each finished chunk written
as it arrives (``OUT/chunks/``), then the table, statistics, charts and recording.

Work: the samples ``0 .. n-1`` are cut into chunks of ``chunk`` samples (the unit of work, so
task overhead is amortised); a chunk is a pure function of (scene, k0, k1), submitted under a
key naming the study and its range, so Dask re-runs a chunk whose worker died and the result
is the same. Before dispatch the driver builds the scene's compiled system (a short run of the
base scene), so workers load it from the disk cache instead of compiling it each (the workers
of the study's own local cluster are forked after it and have it in memory: :mod:`.cluster`).

Work is generated lazily (the ranges not yet on disk, cut into chunks; a default-sized study's
last chunks shrink so the workers end together, :func:`_gaps`) and at most
:data:`IN_FLIGHT_PER_WORKER` chunks per worker are in flight; an n whose table and envelopes
cannot fit in this process's memory is refused before anything runs (:func:`check_memory`).

Files (``out`` given, :mod:`.folder`): ``study.lock`` (held while the study runs),
``chunks/chunk_<study>_<k0>_<k1>.parquet`` and ``chunks/envelope_<study>_<k0>_<k1>.npy`` per
finished chunk, tagged with the study's identity; ``study.json`` (the identity, the law's
source hashes, the chunk size; a ``resume`` keeps the chunks of its own study, runs the rest
with the recorded chunk size, and refuses another study's); at the end ``samples.parquet``
(every row, by index), ``summary.json``, the charts and ``montecarlo.rrd``. Ctrl-C
(KeyboardInterrupt), a full disk or a lost scheduler (:class:`.folder.StudyStop`) cancel what
is queued and keep every finished chunk.
"""

from __future__ import annotations

import difflib
import json
import logging
import math
import os
import signal
import threading
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ...core import interrupts, progress
from ...core.provenance import provenance
from ...run.metrics import METRICS
from ...run.rate_auto import AUTO, scene_choice
from ...run.simulation import simulate
from ...scene import Scene, SceneError, load_scene
from .cluster import local_cluster
from .dispersions import check_keys, drawn_columns, nominal_rate
from .folder import STUDY_JSON, ChunkFiles, StudyStop, locked, study_identity
from .report import finish
from .samples import ENVELOPE_SERIES, ID_COLUMNS, held_warnings, metric_needs, run_chunk, scene_metrics

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
        the drawn values, then the metrics of :data:`stationbed.run.metrics.METRICS` a run of
        the scene reports (:func:`.samples.scene_metrics`: no estimation column without an
        estimator, no thruster column without thrusters).
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
    reported = scene_metrics(scene)
    for i, r in enumerate(scene.montecarlo.requirement):
        if r.metric not in METRICS:
            close = difflib.get_close_matches(r.metric, list(METRICS), n=1, cutoff=0.5)
            hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(METRICS)}"
            raise SceneError(f"montecarlo.requirement[{i}].metric: unknown metric '{r.metric}'; {hint}")
        if r.metric not in reported:  # every sample would be NaN, so FAIL: refused before anything runs
            raise SceneError(f"montecarlo.requirement[{i}].metric: '{r.metric}' is not reported by a run of scene "
                             f"'{scene.name}': it needs {metric_needs(r.metric)}")
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


def _warm(scene) -> None:
    """Build (or load) the compiled system and the fused loop of ``scene`` in this process, by a
    run of two output steps (the fused loop is compiled per output step): workers then load
    them from the disk cache instead of each compiling them."""
    short = min(scene.simulation.duration, 2 * scene.simulation.output_dt)
    try:
        simulate(scene.replace({"simulation.duration": short}), keep=False)
    except Exception:  # noqa: BLE001 - a failing base scene still runs its samples (and records why)
        pass


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
    df["executor"] = df["executor"].fillna("").astype(str)
    return df


@contextmanager
def _ctrl_c_kept():
    """Ctrl-C that is never lost: yields a list that becomes non-empty at SIGINT.

    The handler raises KeyboardInterrupt as Python's own does, and also records it: a signal
    that lands while casadi's SWIG layer converts an argument is swallowed there (seen: a study
    ran to its end after Ctrl-C), so the engine checks the record between chunks too. Only in
    the main thread and over Python's default handler (a caller's own handler is left alone)."""
    seen: list[int] = []
    before = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or \
            before not in (signal.default_int_handler, interrupts.handler):  # (the CLI's: the same, counted)
        yield seen
        return

    def handler(signum, frame):
        seen.append(signum)
        interrupts.handler(signum, frame)

    signal.signal(signal.SIGINT, handler)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, before)


#: guided tail (:func:`_gaps`): a default chunk is at most the samples left / (TAIL_SPLIT x workers) ...
TAIL_SPLIT = 2
#: ... and at least the default size // TAIL_MIN_DIV
TAIL_MIN_DIV = 5
#: chunks in flight per worker (submitted, not yet back): enough to keep every worker busy
IN_FLIGHT_PER_WORKER = 2
#: the study keeps its table and envelopes in this process until the statistics; an n whose
#: estimate (x this factor: pandas' copies when the chunks are joined and written) exceeds the
#: memory available is refused before anything runs
MEMORY_FACTOR = 3.0
#: bytes per sample besides its numbers (status and reason strings, pandas' per-row share)
ROW_OVERHEAD_B = 200


def _available_memory() -> int | None:
    """Memory available to this process now [bytes]: Linux's MemAvailable (free memory plus
    what the page cache would give back), else the physical memory; None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _gib(b: float) -> str:
    for unit, f in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if b >= f:
            return f"{b / f:.3g} {unit}"
    return f"{b / 2**10:.3g} KiB"


def check_memory(n: int, n_columns: int, n_env: int, available: int | None) -> None:
    """SceneError when ``n`` samples' table and envelopes cannot fit in ``available`` bytes."""
    if available is None:
        return
    per = 8 * n_columns + ROW_OVERHEAD_B + 8 * len(ENVELOPE_SERIES) * n_env
    need = MEMORY_FACTOR * per * n
    if need > available:
        fit = int(available / (MEMORY_FACTOR * per))
        raise SceneError(f"montecarlo.n = {n}: the table and envelopes of the study need ~{_gib(need)} in this "
                         f"process ({_gib(per)} per sample, kept for the statistics), more than the {_gib(available)} "
                         f"of memory available; about {fit} samples fit: run fewer (several studies with "
                         f"other seeds), or keep fewer envelope times (a larger montecarlo.envelope_dt)")


def in_flight(items, submit, wait_first, limit: int, pending: set):
    """Yield finished futures in the order they finish, with at most ``limit`` drawn from
    ``items`` and not yet handed back (the one being handed back included); ``items`` is
    consumed only as room frees up. ``pending`` (a set, filled here)
    holds what is in flight, for the caller to cancel."""
    it = iter(items)
    for item in it:
        pending.add(submit(item))
        if len(pending) >= limit:
            break
    while pending:
        done, _ = wait_first(set(pending))
        for fut in done:
            pending.discard(fut)
            yield fut
            while len(pending) < limit:  # refill once the caller is done with it
                nxt = next(it, None)
                if nxt is None:
                    break
                pending.add(submit(nxt))


def _gaps(n: int, size: int, done: dict, tail_workers: int = 0):
    """The chunk ranges ``(k0, k1)`` of at most ``size`` samples that cover what ``done``
    (``{k0: (k1, ...)}``) does not, in order, generated lazily.

    With ``tail_workers`` (the workers of a default-sized study), the chunks shrink at the end
    (guided scheduling): none is longer than the samples still to cut over
    ``TAIL_SPLIT x tail_workers``, nor shorter than ``size // TAIL_MIN_DIV``; so the workers run
    out of work within about one short chunk of each other instead of one idling while another
    finishes a full chunk. A pure function of its arguments: the same study cuts the same
    chunks (a sample's numbers do not depend on its chunk anyway)."""
    left = n - sum(v[0] - a for a, v in done.items())
    floor = max(1, size // TAIL_MIN_DIV)
    k = 0
    for a in sorted(done) + [n]:
        while k < a:
            step = size if not tail_workers else max(floor, min(size, math.ceil(left / (TAIL_SPLIT * tail_workers))))
            k1 = min(k + step, a)
            yield k, k1
            left -= k1 - k
            k = k1
        if a < n:
            k = done[a][0]


def _connect(scheduler: str, timeout_s: float):
    from distributed import Client  # noqa: PLC0415

    try:
        return Client(scheduler, timeout=f"{timeout_s}s")
    except (OSError, TimeoutError) as e:
        raise StudyStop(f"no dask scheduler answered at {scheduler} within {timeout_s:g} s "
                        f"({str(e).splitlines()[0] if str(e) else type(e).__name__}); nothing was run: start it "
                        f"(dask scheduler), check the address, or wait longer with --connect-timeout") from None


@contextmanager
def _distributed_logs_quiet():
    """distributed's own log lines (a reconnect's traceback when the scheduler goes away) off
    while this process drives a study: the study says what happened in one line."""
    names = [n for n in list(logging.Logger.manager.loggerDict) if n.split(".")[0] in ("distributed", "tornado")]
    logs = [logging.getLogger(n) for n in ["distributed", "tornado", *names]]  # children may set their own level
    before = [g.level for g in logs]
    for g in logs:
        g.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for g, lv in zip(logs, before):
            g.setLevel(lv)


def _lost(where: str, e: BaseException, chunks_dir, n_kept: int, client) -> StudyStop:
    """One line for a study Dask stopped: the scheduler gone (the client is no longer
    connected), or a chunk Dask cancelled while it still answers."""
    what = f"{type(e).__name__}" + (f": {str(e).splitlines()[0]}" if str(e) else "")
    kept = (f"the {n_kept} finished chunks in {chunks_dir} are kept: run the same command again with --resume"
            if chunks_dir is not None else "nothing was written (no --out)")
    if getattr(client, "status", "running") in ("running", "newly-created") and \
            not isinstance(e, (OSError, TimeoutError)):
        return StudyStop(f"{where} cancelled a chunk ({what}); {kept}")
    return StudyStop(f"{where} stopped answering mid-study ({what}); {kept}")


def run_study(scene, *, n=None, out=None, client=None, workers=None, chunk=None, resume=False,
              charts=True, scheduler=None, connect_timeout_s: float = 10.0, invocation=None) -> MonteCarloResult:
    """Run a Monte Carlo study (see :func:`stationbed.montecarlo`); ``invocation`` (the command
    line's scene file, ``--n`` and ``--set``) goes into study.json with the provenance, so a
    report can print the command that replays a sample."""
    scene = study_scene(scene, n)
    mc = scene.montecarlo
    n = mc.n
    n_env = envelope_times(scene)
    columns = ID_COLUMNS + drawn_columns(scene) + scene_metrics(scene)  # only what the scene can report
    check_memory(n, len(columns), n_env, _available_memory())
    study, record = study_identity(scene)
    record["provenance"] = provenance()
    if invocation:
        record["invocation"] = invocation
    if scene.simulation.environment_rate == AUTO:  # resolved once here, not by each worker
        record["environment_rate"] = {"asked": AUTO, **scene_choice(scene)}
        scene = scene.replace(nominal_rate(scene))
    own_client = None
    if client is None and scheduler is not None:
        client = own_client = _connect(scheduler, connect_timeout_s)
    try:
        if out is None:
            return _run(scene, study, record, columns, n_env, None, client, workers, chunk, resume, charts,
                        scheduler)
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        with locked(out):
            return _run(scene, study, record, columns, n_env, out, client, workers, chunk, resume, charts,
                        scheduler)
    finally:
        if own_client is not None:
            with _distributed_logs_quiet():
                own_client.close(timeout=2)


def _run(scene, study, record, columns, n_env, out, client, workers, chunk, resume, charts, scheduler):
    mc = scene.montecarlo
    n = mc.n
    n_workers = workers or (len(client.scheduler_info().get("workers", {})) if client is not None else 1) or 1
    done: dict[int, tuple[int, pd.DataFrame, np.ndarray | None]] = {}
    files = None
    recorded = None
    if out is not None:
        files = ChunkFiles(out, study, record)
        if resume:
            recorded = _recorded_chunk(out)
            done = files.resume(n, n_env)
        else:
            files.start()
    size = chunk or recorded or chunk_size(scene, n_workers)
    guided = not (chunk or recorded or mc.chunk)  # a default size: its tail shrinks (_gaps)
    if files is not None:
        files.write_record({**record, "scene": scene.name, "n": n, "chunk": size})
    said: set[str] = set()  # warnings said in this study (here, or by a worker): each once
    seen = _Seen(said)
    logging.getLogger(progress.LOGGER).addFilter(seen)
    try:
        return _run_chunks(scene, study, columns, n_env, out, client, workers, size, n_workers, files, done, charts,
                           scheduler, guided)
    finally:
        logging.getLogger(progress.LOGGER).removeFilter(seen)


class _Seen(logging.Filter):
    """Notes the warnings this process says, so a worker's copy of one is not said again."""

    def __init__(self, said: set):
        super().__init__()
        self.said = said

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            msg = record.getMessage()
            if msg in self.said:
                return False
            self.said.add(msg)
        return True


def _run_chunks(scene, study, columns, n_env, out, client, workers, size, n_workers, files, done, charts, scheduler,
                guided=False):
    mc = scene.montecarlo
    n = mc.n

    def keep(res):
        df = _frame(res["rows"], columns)
        env = res["envelope"]
        k0, k1 = res["k0"], res["k1"]
        if files is not None:
            files.write(k0, k1, df, env)
        done[k0] = (k1, df, env)
        for r in res["rows"]:
            kinds[r.get("executor", "")] = kinds.get(r.get("executor", ""), 0) + 1
        for w in res.get("warnings", ()):  # _Seen drops the ones said before
            logging.getLogger(progress.LOGGER).warning(w)

    todo = _gaps(n, size, done, tail_workers=n_workers if guided and n_workers > 1 else 0)
    has_todo = sum(k1 - k0 for k0, (k1, _, _) in done.items()) < n
    wall0 = time.perf_counter()
    failures = sum(int((d["status"] != "ok").sum()) for _, d, _ in done.values())
    chunks_dir = files.dir if files is not None else None
    with progress.task(f"montecarlo {scene.name}", total=n, unit="sample") as bar, _ctrl_c_kept() as ctrl_c:
        n_done = sum(len(d) for _, d, _ in done.values())
        n_resumed = n_done
        kinds: dict[str, int] = {}  # samples per executor (fused, batch, per-tick)

        def show():
            ran = n_done - n_resumed
            eta = (time.perf_counter() - wall0) / ran * (n - n_done) if ran else math.nan
            how = ", ".join(f"{k} {v}" for k, v in kinds.items() if k)
            bar.update(n_done, f"{n_done}/{n} samples, {failures} failed" + (f" ({how})" if how else "")
                       + (f", ETA {eta:.0f} s" if ran else ""))

        show()
        cluster = ExitStack()
        own = False  # whether this study started its own local cluster
        try:
            if has_todo:
                with held_warnings(log=False) as said:
                    _warm(scene)
                for w in said:
                    logging.getLogger(progress.LOGGER).warning(w)
            if has_todo and client is None and workers:  # workers forked after the warm-up (.cluster)
                client, own = cluster.enter_context(local_cluster(workers)), True
            if client is None:
                for k0, k1 in todo:
                    res = run_chunk(scene, k0, k1, n_env)
                    keep(res)
                    n_done += k1 - k0
                    failures += sum(r["status"] != "ok" for r in res["rows"])
                    show()
                    if ctrl_c:  # a Ctrl-C that casadi swallowed
                        raise KeyboardInterrupt
            elif has_todo:
                from distributed import wait  # noqa: PLC0415

                where = (f"the dask scheduler at {scheduler}" if scheduler else
                         "the local Dask cluster" if own else
                         f"the dask scheduler at {getattr(client.scheduler, 'address', '?')}")
                pending: set = set()
                with _distributed_logs_quiet():
                    try:
                        # the scene goes with each task (~7 kB), not scattered: a scattered value whose
                        # holders die cannot be recomputed, and Dask then cancels the tasks needing it
                        submit = lambda r: client.submit(run_chunk, scene, r[0], r[1], n_env, True,  # noqa: E731
                                                         key=f"montecarlo-{study}-{r[0]}-{r[1]}", retries=2)
                        wait_first = lambda fs: wait(fs, return_when="FIRST_COMPLETED")  # noqa: E731
                        for fut in in_flight(todo, submit, wait_first, IN_FLIGHT_PER_WORKER * n_workers, pending):
                            res = fut.result()
                            keep(res)
                            n_done += res["k1"] - res["k0"]
                            failures += sum(r["status"] != "ok" for r in res["rows"])
                            show()
                            fut.release()
                            if ctrl_c:
                                raise KeyboardInterrupt
                    except BaseException as e:  # Ctrl-C, a full disk, a lost scheduler: cancel what is queued
                        if pending:
                            try:
                                client.cancel(list(pending))
                            except Exception:  # noqa: BLE001 - the scheduler is gone: nothing to cancel
                                pass
                        if isinstance(e, Exception) and not isinstance(e, StudyStop) and _is_lost(e, client):
                            # a future's result() or wait() raises when the scheduler went away
                            raise _lost(where, e, chunks_dir, len(done), client) from None
                        raise
        finally:
            with _distributed_logs_quiet():
                cluster.close()
    wall = time.perf_counter() - wall0
    order = sorted(done)
    df = pd.concat([done[k][1] for k in order], ignore_index=True)
    env = np.concatenate([done[k][2] for k in order]) if n_env else None
    env_t = np.arange(n_env) * mc.envelope_dt if n_env else np.zeros(0)
    result = MonteCarloResult(df=df, summary={}, envelope_t=env_t, envelope=env, out=out)
    try:
        finish(scene, result, wall_s=wall, workers=n_workers if client is not None else 0, chunk=size,
               draw_charts=charts and out is not None)
    except OSError as e:  # a full disk at the end: every chunk is on disk already
        raise StudyStop(f"cannot write {e.filename or out}: {e.strerror or e}; all {len(done)} chunks in "
                        f"{chunks_dir} are kept: free the disk and run the same command again with --resume "
                        f"(it only writes the results)") from e
    return result


def _recorded_chunk(out: Path) -> int | None:
    """The chunk size study.json recorded (a resume keeps it, whatever the workers now)."""
    try:
        v = json.loads((out / STUDY_JSON).read_text()).get("chunk")
    except (OSError, ValueError, AttributeError):
        return None
    return v if isinstance(v, int) and v > 0 else None


def _is_lost(e: BaseException, client) -> bool:
    """Whether ``e`` (from a future or the client) stops the study: the scheduler gone, or a
    chunk cancelled (a chunk's own error is not: run_chunk records a sample's failure)."""
    from concurrent.futures import CancelledError  # noqa: PLC0415

    status = getattr(client, "status", "running")
    return isinstance(e, (CancelledError, OSError, TimeoutError)) or status not in ("running", "newly-created")
