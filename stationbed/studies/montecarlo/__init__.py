"""Closed-loop Monte Carlo on Dask: dispersions declared in the scene's ``[montecarlo]`` table,
chunks of samples run serially, on a local Dask cluster or on a running ``dask scheduler``,
one row of metrics per sample (Parquet), statistics with coverage/confidence verdicts, charts
and a rerun recording. docs/design.md "Monte Carlo" has the contract.

Modules: :mod:`.dispersions` (drawing a sample), :mod:`.samples` (running samples and chunks),
:mod:`.engine` (the driver), :mod:`.stats`, :mod:`.charts`, :mod:`.report` (files),
:mod:`.replay` (one sample's scene file), :mod:`.cli` (``stationbed montecarlo``).
"""

from __future__ import annotations

from .engine import MonteCarloResult, run_study

__all__ = ["montecarlo", "MonteCarloResult"]


def montecarlo(scene, n: int | None = None, client=None, *, workers: int | None = None, out=None,
               chunk: int | None = None, resume: bool = False, charts: bool = True) -> MonteCarloResult:
    """Run the Monte Carlo study of a scene with a ``[montecarlo]`` table.

    Parameters
    ----------
    scene : Scene or path
    n : int, optional
        Samples (default: the scene's ``montecarlo.n``).
    client : distributed.Client, optional
        Run the chunks on this Dask client's cluster. Without it and without ``workers`` the
        samples run serially in this process (same numbers).
    workers : int, optional
        Start a local Dask cluster of this many worker processes (one thread each) for the run.
    out : str or Path, optional
        Folder for the chunks, ``samples.parquet``, ``summary.json``, charts and recording
        (None: nothing is written; the result holds the table). Locked while the study runs
        (``study.lock``: a second study into it raises SceneError).
    chunk : int, optional
        Samples per task (default: the scene's ``montecarlo.chunk``, or about n / (4 workers);
        with ``resume``, the size the study recorded).
    resume : bool
        Keep the finished chunks already in ``out`` (tagged with this study: same scene, same
        controller source) and run only the missing samples; SceneError for another study's
        chunks or a damaged file.
    charts : bool
        Draw the PNG charts (with ``out``).

    Raises
    ------
    SceneError
        Bad input (nothing run): the scene, an n that cannot fit in memory, another study in ``out``.
    StudyStop
        The study stopped mid-way (a full disk, a lost scheduler); the finished chunks are kept.

    Returns
    -------
    MonteCarloResult
        ``.df`` (pandas, one row per sample), ``.summary`` (statistics and verdicts), envelopes.
    """
    return run_study(scene, n=n, out=out, client=client, workers=workers, chunk=chunk, resume=resume, charts=charts)
