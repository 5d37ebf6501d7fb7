"""The attitude thrusters drawn on the station (issue 21's ``[[thruster]]``), lit while they fire.

Entity ``world/station/thrusters``: one arrow per thruster at its ``position_B`` (relative to the
composite mass centre, as everything under ``world/station``), along its plume ``-direction_B``
(the exhaust leaves opposite to the force on the station), :data:`PLUME_FRACTION` of the
station's extent long, labelled with the thruster's name. A thruster is lit (:data:`RGB_FIRING`)
at a row where its on-time total ``thr_on_s_<name>`` grew since the previous row (it fired in
between), else drawn dark (:data:`RGB_IDLE`); the colours are logged on the time line where they
change (static colours would shadow the changes). A visiting vehicle's thrusters
(``[[vehicle.thruster]]``, one arrow per port it uses) are drawn at their port while the vehicle is
docked there and transparent (:data:`RGBA_AWAY`) while it is not.
"""

from __future__ import annotations

import bisect

import numpy as np

from ...scene.docking import configuration_ports
from ...scene.thrusters import available, flown_thrusters, thruster_owners
from .sdk import TIMELINE, import_rerun

__all__ = ["ThrusterArrows", "PLUME_FRACTION", "RGB_FIRING", "RGB_IDLE", "RGBA_AWAY", "firing_rows"]

#: a plume's drawn length, fraction of the station's extent
PLUME_FRACTION = 0.08
RGB_FIRING, RGB_IDLE = (255, 140, 0), (90, 90, 100)
#: a vehicle's thruster while the vehicle is away from its port: not seen
RGBA_AWAY = (0, 0, 0, 0)


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

    def __init__(self, thrusters, r_cm_B, L, present=None):
        self.names = [t.name for t in thrusters]
        self.columns = [f"thr_on_s_{n}" for n in self.names]
        self.origins = np.array([t.position_B for t in thrusters], float) - np.asarray(r_cm_B, float)
        d = np.array([t.direction_B for t in thrusters], float)
        self.vectors = -PLUME_FRACTION * L * d / np.linalg.norm(d, axis=1, keepdims=True)
        self.L = L
        self._last_on = None  # the previous batch's last totals
        self._lit = None  # the colours last logged
        #: ``present(t)`` -> (n,) 1.0 where a thruster is on the station at t (a vehicle's: docked)
        self.present = present or (lambda t: np.ones(len(self.names)))

    @classmethod
    def of(cls, scene, columns, geom) -> ThrusterArrows | None:
        thr = flown_thrusters(scene) if hasattr(scene, "thruster") else []
        if not thr or not all(f"thr_on_s_{t.name}" in columns for t in thr):
            return None
        owners = thruster_owners(scene)
        present = None
        if any(o is not None for o in owners):  # a vehicle's: the configuration at t (an event's from its time)
            times, wheres = [e.t for e in scene.event if not e.done], configuration_ports(scene)

            def present(t):
                return available(owners, wheres[bisect.bisect_right(times, t + 1e-9)])
        return cls(thr, geom.r_cm_B, geom.extent, present)

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
            here = self.present(float(rows.t[i]))
            lit = tuple(int(f) + 2 * int(h == 0.0) for f, h in zip(fired[i], here))
            if lit != self._lit:
                self._lit = lit
                rec.set_time(TIMELINE, duration=float(rows.t[i]))
                colours = [RGBA_AWAY if f >= 2 else (*(RGB_FIRING if f else RGB_IDLE), 255) for f in lit]
                rec.log(self.ENTITY, rr.Arrows3D.from_fields(colors=colours))
                rec.reset_time()
        return fired
