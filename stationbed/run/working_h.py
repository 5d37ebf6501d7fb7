"""The CMG cluster's working units' momentum ``|h|`` and their capacity at each output row: the
one per-row definition behind the run's ``max_h_Nms`` and ``max_h_fraction``
(:class:`~.metrics.RunMetrics`) and what a person sees of them: the Monte Carlo's ``h_fraction``
envelope (its PNG and recording), the dashboard's and ``compare``'s "|h| / capacity" panel and
the naming of the ``cmg_saturated`` flag (dashboard ticks, the recording's events). So the
summary's ``max_h_fraction`` is the largest value of the series the charts draw.

A row's working momentum is ``h - h_held_B - Σ held`` (the measured cluster momentum less the
rotor momentum of the units failed from the start, ``[cmg] failed``, and of each unit whose
gimbals a scheduled ``gimbal_stuck`` holds, over its window, or a ``cmg_failed`` from its time,
its rotor at the fraction the faults left it: :func:`~.faults.held_units`); its capacity the
working units' (:func:`~stationbed.model.cmg.capacity`) with the units a fault takes out at that
row and a dropped rotor at its fraction (:func:`~.faults.capacity_steps`: ``cmg_failed``,
``gimbal_stuck``, ``wheel_speed_drop``). Without a fault: ``|h - h_held_B| / capacity``, as before.

The facts come from the scene (:meth:`WorkingH.of_scene`, what a run uses) or from a finished
run's summary (:meth:`WorkingH.of_summary`: ``h_capacity_Nms``, ``h_held_B_Nms``,
``h_held_units_Nms``, ``h_capacity_steps_Nms``).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.linalg import row_norms

__all__ = ["WorkingH", "HELD_T_TOL_S", "summary_capacity_Nms"]

#: a row at a scheduled fault's time belongs to its window: the rows' times are ticks times the
#: period, the fault's on the same grid (round-off ~1e-12 s; a tick is at least a millisecond)
HELD_T_TOL_S = 1e-6


def summary_capacity_Nms(summary: dict) -> float | None:
    """The working units' capacity at the start [N m s] a run's summary reports (``h_capacity_Nms``;
    a summary written before it was kept: ``max_h_Nms / max_h_fraction``); None without a finite one."""
    cap = summary.get("h_capacity_Nms")
    if cap is None and summary.get("max_h_fraction"):
        cap = summary["max_h_Nms"] / summary["max_h_fraction"]
    return float(cap) if cap is not None and math.isfinite(cap) and cap > 0 else None


class WorkingH:
    """The working units' ``|h|`` and capacity per output row, fed the rows in time order
    (batch by batch: a held unit's momentum is taken from the first row of its window).

    Parameters
    ----------
    columns : list of str  The run's columns.
    capacity_Nms : float or None  The working units' capacity at the start [N m s] (None or not
        finite: no fraction); may be set later (:attr:`capacity_Nms`).
    h_held_B : array_like, shape (3,), optional  The units failed from the start: their held rotor
        momentum, B [N m s] (:func:`~stationbed.model.cmg.held_momentum_B`).
    held_units : list of (t_s, until_s, h_B), optional  Units whose gimbals a scheduled fault holds
        over ``[t_s, until_s)``: their rotor momentum ``h_B`` (B [N m s], shape (3,)), or a callable
        giving it from the window's first row (then kept: :attr:`held_units` is what the summary records).
    capacity_steps : list of (t_s, capacity_Nms), optional  The working units' capacity from
        ``t_s`` on (None: the start's), in time order (:func:`~.faults.capacity_steps`).
    """

    def __init__(self, columns, capacity_Nms: float | None = None, h_held_B=None, held_units=None,
                 capacity_steps=None):
        col = {c: i for i, c in enumerate(columns)}
        self.capacity_Nms = capacity_Nms
        self.h_held_B = None if h_held_B is None else np.asarray(h_held_B, dtype=float).reshape(3)
        self.held_units = [[float(a), float(b), h if callable(h) else np.asarray(h, dtype=float).reshape(3)]
                           for a, b, h in held_units or ()]
        self.capacity_steps = [(float(a), None if c is None else float(c)) for a, c in capacity_steps or ()]
        self._t = col.get("t", 0)
        self._h = [col[c] for c in ("hx", "hy", "hz")] if "hx" in col else None

    @classmethod
    def of_scene(cls, scene, columns, capacity_Nms: float | None = None) -> WorkingH:
        """The facts of a run of ``scene`` (its truth's ``[cmg]`` and scheduled faults)."""
        from ..model.cmg import cmg_geometry
        from .faults import capacity_steps, held_units

        cfg = getattr(scene, "cmg", None)
        if cfg is None:
            return cls(columns, capacity_Nms)
        geo = cmg_geometry(cfg)
        held = geo.held_momentum_B(cfg) if cfg.failed else None
        return cls(columns, capacity_Nms, h_held_B=held, held_units=held_units(scene, geo, columns),
                   capacity_steps=capacity_steps(scene, geo))

    @classmethod
    def of_summary(cls, columns, summary: dict) -> WorkingH:
        """The facts a finished run's summary records (module docstring)."""
        return cls(columns, summary_capacity_Nms(summary), h_held_B=summary.get("h_held_B_Nms"),
                   held_units=[(u["t"], math.inf if u["until"] is None else u["until"], u["h_B"])
                               for u in summary.get("h_held_units_Nms", ())],
                   capacity_steps=[(u["t"], u["capacity_Nms"]) for u in summary.get("h_capacity_steps_Nms", ())])

    @property
    def has_h(self) -> bool:
        """The rows have the cluster's momentum (``hx, hy, hz``)."""
        return self._h is not None

    def norms(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(|h_work|, capacity)`` of each row of ``rows`` (k, len(columns)), (k,) each [N m s]:
        the capacity NaN where it is the start's (:attr:`capacity_Nms`, which may be set later).
        Needs the ``h`` columns (:attr:`has_h`)."""
        t = rows[:, self._t]
        hb = rows[:, self._h] if self.h_held_B is None else rows[:, self._h] - self.h_held_B
        for u in self.held_units:  # units held by a scheduled fault, over their window
            on = (t >= u[0] - HELD_T_TOL_S) & (t < u[1] - HELD_T_TOL_S)
            if on.any():
                if callable(u[2]):
                    u[2] = np.asarray(u[2](rows[np.argmax(on)]), dtype=float).reshape(3)
                hb[on] -= u[2]
        cap = np.full(len(rows), math.nan)
        for a, c in self.capacity_steps:
            cap[t >= a - HELD_T_TOL_S] = math.nan if c is None else c
        return row_norms(hb), cap

    def fraction(self, rows: np.ndarray) -> np.ndarray | None:
        """``|h_work| / capacity`` of each row (k,), or None without ``h`` columns or a finite
        start capacity."""
        cap0 = self.capacity_Nms
        if self._h is None or not cap0 or not math.isfinite(cap0):
            return None
        hn, cap = self.norms(np.asarray(rows, dtype=float))
        return hn / np.where(np.isnan(cap), cap0, cap)
