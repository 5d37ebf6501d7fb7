"""The attitude thrusters drawn on the station (issue 21's ``[[thruster]]``), lit while they fire.

Entity ``world/station/thrusters``: one arrow per thruster at its ``position_B`` (relative to the
composite mass centre, as everything under ``world/station``), along its plume ``-direction_B``
(the exhaust leaves opposite to the force on the station), :data:`PLUME_FRACTION` of the
station's extent long, labelled with the thruster's name. A thruster is lit (:data:`RGB_FIRING`)
at a row where its on-time total ``thr_on_s_<name>`` grew since the previous row (it fired in
between), else drawn dark (:data:`RGB_IDLE`); the colours are logged on the time line where they
change (static colours would shadow the changes).
"""

from __future__ import annotations

import numpy as np

from ...scene.thrusters import flown_thrusters
from .sdk import TIMELINE, import_rerun

__all__ = ["ThrusterArrows", "PLUME_FRACTION", "RGB_FIRING", "RGB_IDLE", "firing_rows"]

#: a plume's drawn length, fraction of the station's extent
PLUME_FRACTION = 0.08
RGB_FIRING, RGB_IDLE = (255, 140, 0), (90, 90, 100)


def firing_rows(on_s, before: np.ndarray | None = None) -> np.ndarray:
    """Per row (k, n) whether each thruster fired since the previous row: its on-time total
    ``on_s`` (k, n) [s] grew (``before``: the totals of the row before the first; zeros at t = 0)."""
    on_s = np.atleast_2d(np.asarray(on_s, float))
    prev = np.vstack([np.zeros(on_s.shape[1]) if before is None else before, on_s[:-1]])
    return on_s > prev


class ThrusterArrows:
    """The scene's thrusters as arrows in B (see the module docstring); :meth:`of` returns None
    when the scene has none or the rows lack their ``thr_on_s_<name>`` columns.

    Parameters
    ----------
    thrusters : list of stationbed.scene.Thruster
    r_cm_B : ndarray, shape (3,)  The composite mass centre in body coordinates [m].
    L : float  The station's extent [m].
    """

    ENTITY = "world/station/thrusters"

    def __init__(self, thrusters, r_cm_B, L):
        self.names = [t.name for t in thrusters]
        self.columns = [f"thr_on_s_{n}" for n in self.names]
        self.origins = np.array([t.position_B for t in thrusters], float) - np.asarray(r_cm_B, float)
        d = np.array([t.direction_B for t in thrusters], float)
        self.vectors = -PLUME_FRACTION * L * d / np.linalg.norm(d, axis=1, keepdims=True)
        self.L = L
        self._last_on = None  # the previous batch's last totals
        self._lit = None  # the colours last logged

    @classmethod
    def of(cls, scene, columns, geom) -> ThrusterArrows | None:
        thr = flown_thrusters(scene) if hasattr(scene, "thruster") else []
        if not thr or not all(f"thr_on_s_{t.name}" in columns for t in thr):
            return None
        return cls(thr, geom.r_cm_B, geom.extent)

    def log_static(self, rec) -> None:
        rr = import_rerun()
        rec.log(self.ENTITY, rr.Arrows3D(vectors=self.vectors, origins=self.origins, labels=self.names,
                                         show_labels=False, radii=0.006 * self.L), static=True)

    def send(self, rec, rows) -> np.ndarray:
        """Log the thrusters' colours where they change in ``rows``; returns the rows' firing (k, n)."""
        rr = import_rerun()
        fired = firing_rows(rows.cols(*self.columns), self._last_on)
        if len(rows):
            self._last_on = rows.cols(*self.columns)[-1].copy()
        for i in range(len(rows)):
            lit = tuple(bool(f) for f in fired[i])
            if lit != self._lit:
                self._lit = lit
                rec.set_time(TIMELINE, duration=float(rows.t[i]))
                rec.log(self.ENTITY, rr.Arrows3D.from_fields(colors=[RGB_FIRING if f else RGB_IDLE for f in lit]))
                rec.reset_time()
        return fired
