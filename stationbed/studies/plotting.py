"""The studies' charts: matplotlib (extra ``plot``) on the headless Agg backend, imported only
when a chart is drawn, and the colours, markers and line styles the charts share."""

from __future__ import annotations

from ..core.plotting import pyplot as _pyplot
from .common import StudyError

__all__ = ["pyplot", "colours", "MARKERS", "STYLES"]

#: markers and line styles by position (per formulation or method; colours per integrator)
MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]
STYLES = ["-", "--", ":", "-."]


def pyplot():
    """matplotlib's pyplot on the Agg backend (:func:`stationbed.core.plotting.pyplot`); raises
    StudyError, saying how to install it, without matplotlib."""
    return _pyplot(StudyError)


def colours(plt, names) -> dict:
    """One colour per name, in order, from ``tab10`` (``tab20`` above ten names).

    Parameters
    ----------
    plt : module
        ``matplotlib.pyplot`` (from :func:`pyplot`).
    names : list of str

    Returns
    -------
    dict
        Name -> RGBA tuple.
    """
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    return {n: cmap(i % cmap.N) for i, n in enumerate(names)}
