"""Visiting vehicles in a run recording (issue 35): each drawn at its port while it is docked.

``world/station/vehicle/<name>``: the uniform box of the vehicle's mass properties
(:func:`~.geometry.box_half_sizes`) in its axes V (``C_BV`` of the port, ``q_VB``), centred on its
mass centre relative to the drawing's origin (the composite mass centre of the scene as it
starts, docked vehicles included; an event's move of the true one is the station frame's
translation, drawing.py). It is logged at t = 0
when the vehicle is docked then, at each dock or berth (at that port), and cleared at each undock,
on the time line: the viewer shows it exactly while it is there. A massless vehicle is not drawn.
"""

from __future__ import annotations

import numpy as np

from ...core.rotation import dcm
from .geometry import box_half_sizes
from .sdk import TIMELINE, import_rerun

__all__ = ["VehicleBoxes", "VEHICLE_RGB"]

VEHICLE_RGB = (220, 140, 60)


class VehicleBoxes:
    """The boxes of a scene's vehicles and when each is shown.

    Parameters
    ----------
    scene : stationbed.scene.Scene
    r_cm_B : ndarray, shape (3,)  The drawing's origin in body coordinates [m].
    """

    def __init__(self, scene, r_cm_B):
        ports = {p.name: p for p in scene.port}
        self.changes = []  # (t [s], entity, (centre, half sizes, C_BA) or None: cleared)
        times = [(0.0, v.name, v.port) for v in scene.vehicle if v.port]
        times += [(e.t, e.vehicle, "" if e.kind == "undock" else e.port) for e in scene.event if not e.done]
        vehicles = {v.name: v for v in scene.vehicle}
        for t, name, port in times:
            v = vehicles[name]
            if v.mass == 0.0:
                continue
            box = None
            if port:
                C_BV = dcm(np.asarray(ports[port].q_VB, float)).T
                half, C_VA = box_half_sizes(v.mass, np.asarray(v.inertia, float))
                centre = np.asarray(ports[port].position, float) + C_BV @ np.asarray(v.cm, float) - r_cm_B
                box = (centre, half, C_BV @ C_VA)
            self.changes.append((t, f"world/station/vehicle/{name}", box))

    @classmethod
    def of(cls, scene, r_cm_B):
        """The scene's vehicle boxes, or None when it has no vehicle."""
        return cls(scene, r_cm_B) if scene.vehicle else None

    def log(self, rec, boxes) -> None:
        """Log each change at its time (``boxes``: drawing.py's box archetype maker)."""
        rr = import_rerun()
        for t, ent, box in self.changes:
            rec.set_time(TIMELINE, duration=t)
            if box is None:
                rec.log(ent, rr.Clear(recursive=False))
            else:
                rec.log(ent, boxes([box], VEHICLE_RGB, labels=[ent.rsplit("/", 1)[1]]))
        rec.reset_time()
