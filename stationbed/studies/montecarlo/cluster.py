"""The local Dask cluster of ``stationbed montecarlo --workers K``: worker processes forked from
the driver after its warm-up, no dashboard.

Why forked: a spawned worker starts a fresh interpreter and imports stationbed, casadi, numpy
and pandas again (~3.5 s for two workers on two cores), then builds the study's casadi graphs
again on its first sample to find the compiled library in the disk cache (~1 s each). A worker
forked from the driver after :func:`.engine._warm` has all of it already (copy-on-write): the
cluster is up in ~0.2 s and the first sample runs at the speed of the others. Forking is
Linux's (``fork`` is unsafe on macOS, absent on Windows): elsewhere the workers are spawned as
Dask does by default. The driver forks with Dask's event-loop thread running, which Dask
supports (``distributed.worker.multiprocessing-method``); the samples' numbers do not depend on
how the worker started (a sample is a pure function of the scene and its index).

Before forking, the driver's objects (~117 000 tracked by the garbage collector: modules,
casadi graphs, the scene) are frozen (``gc.freeze``) so a worker's collections never walk them
(nor copy their pages): the collector's time per sample 0.44 -> 0.10 ms (in one process, 50
samples); the driver unfreezes its own at once.

Why no dashboard: ``dashboard_address=":0"`` imports bokeh and serves pages nobody opens in a
batch run (a user who wants one starts their own scheduler and passes ``--scheduler``).
"""

from __future__ import annotations

import gc
import os
import sys
from contextlib import contextmanager

from ...core import progress

__all__ = ["start_method", "local_cluster"]


#: Dask's periodic work a batch study does not use, off on its own cluster (measured in docs/design.md
#: "The floor at the default"): the workers' statistical profiler (a thread sampling the running task's stack every
#: 10 ms, for the dashboard's profile page) and the scheduler's work stealing (a 100 ms
#: callback; with one thread per worker and at most two chunks each in flight there is little
#: to steal, and a stolen chunk gives the same rows)
#:
#: and the periodic checks Dask runs on every event loop (the driver's scheduler, client and
#: nannies, each worker's), at rates meant for interactive use: the event-loop tick that notices a
#: blocked loop (every 20 ms; at 1 s it still reports a loop blocked for its 3 s limit), the
#: system monitor's psutil samples (every 0.5 s, for the dashboard) and the workers' memory
#: monitor (every 0.1 s; at 1 s it still pauses, spills or restarts a worker past its limits).
#: Idle, a 2-worker cluster spent 71 ms of CPU per second on them (driver 37, each worker 17),
#: 14 with these; on 2 cores that is ~1.3 s of a 1000-sample study's ~45 s wall (docs/design.md
#: "The floor at the default")
QUIET = {"distributed.worker.profile.enabled": False, "distributed.scheduler.work-stealing": False,
         "distributed.admin.tick.interval": "1s", "distributed.admin.system-monitor.interval": "5s",
         "distributed.worker.memory.monitor-interval": "1s"}


#: whether this process is starting (or keeping) a local cluster whose workers it forks
_FORKING = [False]


def _worker_after_fork() -> None:
    """A worker forked by :func:`local_cluster` starts quiet (no progress lines or bars of its
    own on the user's terminal: the driver reports the study)."""
    if _FORKING[0]:
        _FORKING[0] = False
        progress.forked_quiet()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_worker_after_fork)


def start_method() -> str:
    """How local workers start: ``fork`` on Linux, else Dask's default ``spawn``."""
    return "fork" if sys.platform.startswith("linux") else "spawn"


@contextmanager
def local_cluster(workers: int):
    """A local cluster of ``workers`` single-threaded worker processes (under Dask's Nanny, which
    restarts a worker that dies: forked too, the start method is set for the cluster's life),
    yielding its client; closed on exit."""
    import dask  # noqa: PLC0415 - dask only when asked
    from distributed import Client, LocalCluster  # noqa: PLC0415

    _FORKING[0] = True  # for the cluster's life: the Nanny forks a worker it restarts too
    try:
        with dask.config.set({"distributed.worker.multiprocessing-method": start_method(), **QUIET}):
            gc.freeze()  # the driver's objects out of the forked workers' garbage collections
            try:
                # the scheduler's HTTP server (health, metrics) on a free port: with no address it
                # takes 8787 and, when another cluster holds that, warns on stderr; no dashboard
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False})
            finally:
                gc.unfreeze()  # the driver collects its own as before; the workers keep theirs frozen
            with cluster, Client(cluster) as client:
                yield client
    finally:
        _FORKING[0] = False
