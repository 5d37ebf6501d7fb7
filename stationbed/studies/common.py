"""What every study shares: its error, the methods it sweeps, one guarded run, and its CSV files.

Both studies run over whatever is registered in :data:`stationbed.integrators.INTEGRATORS` and
:data:`stationbed.formulations.FORMULATIONS` when they start (not at import), so a newly
registered method appears in every chart without a change here. Tolerances are dimensionless
as in scene files (``atol`` in units of the scene's characteristic rate or momentum,
docs/design.md): the sweeps use ``atol = rtol``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..formulations import FORMULATIONS
from ..integrators import INTEGRATORS
from ..run.simulation import SimulationError, simulate
from ..run.trajectory import Trajectory

__all__ = [
    "StudyError", "SCENARIOS", "scenario", "registered_integrators", "registered_formulations", "sweep_setting",
    "try_simulate", "one_line", "write_csv", "fmt",
]

#: the scenario files shipped with a stationbed checkout (some stability cases run them)
SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


class StudyError(RuntimeError):
    """A study could not run (missing optional dependency, missing scenario file)."""


def scenario(name: str) -> Path:
    """The path of a shipped scenario file.

    Parameters
    ----------
    name : str
        File name in ``scenarios/``, e.g. ``"articulated_stress.toml"``.

    Returns
    -------
    Path

    Raises
    ------
    StudyError
        The file is not there (the study is not run from a stationbed checkout).
    """
    p = SCENARIOS / name
    if not p.is_file():
        raise StudyError(f"the stability study needs {p} (run it from a stationbed checkout)")
    return p


def registered_integrators(names=None) -> dict:
    """The registered integrators (now, not at import), or the named subset in that order.

    Parameters
    ----------
    names : list of str, optional

    Returns
    -------
    dict
        Registry name -> :class:`~stationbed.integrators.Integrator` subclass.

    Raises
    ------
    ValueError
        A name is not registered (the message lists the valid ones).
    """
    if names is None:
        return dict(INTEGRATORS)
    unknown = [n for n in names if n not in INTEGRATORS]
    if unknown:
        raise ValueError(f"unknown integrator {unknown[0]!r}; valid: {', '.join(sorted(INTEGRATORS))}")
    return {n: INTEGRATORS[n] for n in names}


def registered_formulations(names=None) -> list[str]:
    """The registered formulations' names (now, not at import), or the named subset in that order.

    Parameters
    ----------
    names : list of str, optional

    Returns
    -------
    list of str

    Raises
    ------
    ValueError
        A name is not registered (the message lists the valid ones).
    """
    if names is None:
        return list(FORMULATIONS)
    unknown = [n for n in names if n not in FORMULATIONS]
    if unknown:
        raise ValueError(f"unknown formulation {unknown[0]!r}; valid: {', '.join(sorted(FORMULATIONS))}")
    return list(names)


def sweep_setting(cls, value) -> dict:
    """The :func:`~stationbed.run.simulation.simulate` keywords of one sweep point.

    Parameters
    ----------
    cls : type[Integrator]
    value : float
        ``rtol`` (= ``atol``, dimensionless) of an adaptive integrator, the step [s] of a
        fixed-step one.

    Returns
    -------
    dict
        ``{"rtol": value, "atol": value}`` or ``{"step": value}``.
    """
    return {"rtol": value, "atol": value} if cls.adaptive else {"step": value}


def try_simulate(scene, form, integ, **kw) -> tuple[Trajectory | None, str]:
    """One run whose failure is a result: :func:`~stationbed.run.simulation.simulate` guarded.

    Parameters
    ----------
    scene : Scene
    form, integ : str or None
        Formulation and integrator (None: the scene's).
    **kw
        Further :func:`~stationbed.run.simulation.simulate` keywords.

    Returns
    -------
    trajectory : Trajectory or None
        The run's rows (the partial ones of a run that failed part-way; None when it refused
        or broke down before any).
    status : str
        ``"ok"``, ``"skipped: why"`` (the method refuses the scene: ``ValueError`` or
        ``NotImplementedError``) or ``"failed: why"``.
    """
    try:
        tr = simulate(scene, formulation=form, integrator=integ, **kw)
    except (ValueError, NotImplementedError) as e:
        return None, f"skipped: {one_line(e)}"
    except SimulationError as e:
        return e.trajectory, f"failed: {one_line(e)}"
    except (ArithmeticError, RuntimeError, np.linalg.LinAlgError) as e:  # a method that breaks down
        return None, f"failed: {type(e).__name__}: {one_line(e)}"
    if not np.all(np.isfinite(tr.data[:, :12])):  # t, q, ω, H_O_N, T (att_err_deg may be NaN)
        return tr, "failed: non-finite output"
    return tr, "ok"


def one_line(e) -> str:
    """An exception's message on one line, at most 200 characters (for CSV cells and logs)."""
    s = " ".join(str(e).split())
    return s[:200]


def write_csv(path: Path, header: list[str], rows: list) -> None:
    """Write a CSV file: ``header``, then ``rows`` with their floats through :func:`fmt`."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([fmt(v) for v in r])


def fmt(v):
    """A CSV cell: floats to 6 significant digits, NaN as an empty cell, anything else as is."""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return v
