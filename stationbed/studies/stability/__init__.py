"""Stability study (``stationbed study stability``): cases where methods fail, each with a
detector, a verdict per method, a CSV and a PNG.

Every case is a function in its own module, registered under its name with
:func:`~.base.stability_case` (rules for a case: :mod:`.base`); the study finds the cases
through :data:`STABILITY_CASES` and runs them in registration order, which is the order of the
imports below. Each case runs over whatever integrators and formulations are registered when
it starts.
"""

from __future__ import annotations

import time
from pathlib import Path

from ...core import progress
from ..common import fmt, write_csv
from ..plotting import pyplot
from .base import STABILITY_CASES, Case, Context, stability_case

# the cases, in the study's order (importing a module registers its case)
from . import rate_step, long_horizon, dzhanibekov, max_step, quat_norm, cmg_singularity, stiff_modes  # noqa: F401

__all__ = ["STABILITY_CASES", "Case", "Context", "stability_case", "stability_study"]


def stability_study(*, out: Path | str, quick: bool = False, cases=None, log=progress.echo) -> list[Case]:
    """Run the stability cases and write their files and a summary of every verdict.

    Parameters
    ----------
    out : path
        Folder for ``stability_<case>.csv`` / ``.png`` per case and ``stability_summary.csv`` /
        ``stability_summary.md`` (created if missing).
    quick : bool
        Shrink every case to seconds (tests, CI).
    cases : list of str, optional
        Names in :data:`STABILITY_CASES` to run, in that order; default all.
    log : callable
        Receives each case's title, detector and verdicts (default: stdout, above any progress
        bar). Progress (per case, and per run inside a case) goes to
        :mod:`stationbed.core.progress`.

    Returns
    -------
    list of Case

    Raises
    ------
    StudyError
        matplotlib is missing, or a case's scenario file is.
    ValueError
        An unknown case name (the message lists the valid ones).
    """
    plt = pyplot()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = list(STABILITY_CASES) if cases is None else list(cases)
    unknown = [c for c in names if c not in STABILITY_CASES]
    if unknown:
        raise ValueError(f"unknown stability case {unknown[0]!r}; valid: {', '.join(STABILITY_CASES)}")
    results = []
    with progress.task("study stability", total=len(names), unit="cases") as bar:
        for i, name in enumerate(names):
            where = f"case {i + 1}/{len(names)} {name}"
            bar.update(i, where)
            t0 = time.perf_counter()

            def note(text: str, i=i, where=where) -> None:
                bar.update(i, f"{where}: {text}")

            case = STABILITY_CASES[name](Context(name, out, quick, plt, log, note))
            log(f"{case.title} ({time.perf_counter() - t0:.1f} s)")
            log(f"  detector: {case.detector}")
            for v in case.verdicts:
                log(f"  {v['method']:<48} {fmt(v['value']) if isinstance(v['value'], float) else v['value']:>10} "
                    f"{v['unit']:<9} {v['verdict']}")
            results.append(case)
        bar.update(len(names), "")
    rows = [[c.name, v["method"], c.detector, v["value"], v["unit"], v["verdict"]] for c in results for v in c.verdicts]
    write_csv(out / "stability_summary.csv", ["case", "method", "detector", "value", "unit", "verdict"], rows)
    md = ["| case | method | value | verdict |", "|---|---|---:|---|"]
    md += [f"| {r[0]} | {r[1]} | {fmt(r[3])} {r[4]} | {r[5]} |" for r in rows]
    (out / "stability_summary.md").write_text("\n".join(md) + "\n")
    return results
