"""The 3-D scene of a run recording, in N translated to the composite mass centre.

The station sits at the origin (it does not fly round the Earth: attitude motion of a 100 m
station would be invisible at orbit scale). ``world/station`` carries ``C_NB`` per time, each
array ``world/station/<name>`` its own ``C_BP`` and mass-centre offset; boxes with the principal
moments of the body and of each array (:mod:`.geometry`); the LVLH triad ``world/lvlh`` (``C_NO``)
and the Earth (nadir) direction; the total angular momentum ``H_O_N`` as an arrow; the orbit as a
ring (scaled, Earth-centred) with a dot at the station's argument of latitude; the (inertially
fixed) sun direction with a ``[sun]``; the CMG cluster's arrows (:mod:`.cmg_arrows`) and the bent
centre lines of flexible arrays (:mod:`.elastic`); the attitude thrusters, lit while they fire
(:mod:`.thruster_arrows`). Rerun stores the rotations as float32
quaternions (~6e-8 resolution).

The origin is the composite mass centre of the scene as it starts, docked vehicles included
(:attr:`.geometry.StationGeometry.r_cm_B`): the station's parts are drawn in B about it. A docking
event moves the true mass centre c(t) in B (the vehicle's mass joins or leaves); the parts stay
where they are in B and ``world/station`` gets the translation ``-C_NB (c(t) - c(0))`` from the
event's time on, so the world origin (where ``H_O_N`` and the LVLH triad start) stays the mass
centre the station turns about. Without such an event the transform is a rotation alone.
"""

from __future__ import annotations

import math

import numpy as np

from ...core.rotation import dcm
from ...run.trajectory import Trajectory
from ...scene.docking import configuration_ports, mass_centre_B
from .cmg_arrows import CmgArrows
from .elastic import ElasticLines
from .events import Events, SensorParts
from .frames import R_N_over_a, sun_vector_N, xyzw, xyzw_C_BP, xyzw_C_NO, xyzw_of_dcm
from .geometry import StationGeometry
from .sdk import TIMELINE, import_rerun
from .surfaces import drawn_surfaces
from .thruster_arrows import ThrusterArrows
from .vehicles import VehicleBoxes

__all__ = ["StationDrawing"]

#: Drawing lengths as fractions of the station's extent L (largest distance of any box corner
#: from the composite mass centre).
AXES_B_FRACTION = 0.35
AXES_O_FRACTION = 0.6
EARTH_ARROW_FRACTION = 1.0
H_ARROW_FRACTION = 0.8  # |H| of the first row with H != 0 is drawn this long
ORBIT_RING_FRACTION = 1.3
SUN_ARROW_FRACTION = 1.2
#: Points on the orbit ring.
ORBIT_RING_POINTS = 181

RGB_X, RGB_Y, RGB_Z = (230, 60, 60), (60, 190, 60), (70, 110, 240)
RGB_BODY, RGB_TRUSS, RGB_ARRAY = (170, 170, 180), (120, 120, 130), (40, 70, 170)
RGB_EARTH, RGB_H, RGB_ORBIT = (40, 150, 220), (250, 170, 20), (120, 160, 200)
RGB_SUN, RGB_SUN_SHADOW, RGB_RAM = (255, 215, 0), (90, 90, 100), (255, 120, 200)
RGB_SURFACE_BODY, RGB_SURFACE_ARRAY = (190, 190, 200), (50, 90, 200)
RAM_ARROW_FRACTION = 0.9


class StationDrawing:
    """The station, its frames and vectors as rerun entities under ``world/``.

    Parameters
    ----------
    scene : stationbed.scene.Scene
    columns : list of str
        Column names of the rows; the CMG arrows and elastic lines are drawn only when the rows
        have their columns.

    Attributes
    ----------
    geom : StationGeometry
    cmg : CmgArrows or None
    elastic : ElasticLines or None
    """

    def __init__(self, scene, columns):
        self.scene = scene
        self.geom = StationGeometry(scene)
        self.cmg = CmgArrows.of(scene, columns, self.geom)
        self.elastic = ElasticLines.of(scene, columns, self.geom.extent)
        self.surfaces = drawn_surfaces(scene, self.geom)
        self.events = Events.of(scene, columns)
        self.sensors = SensorParts.of(scene, columns, self.geom.extent)
        self.thrusters = ThrusterArrows.of(scene, columns, self.geom)
        self.vehicles = VehicleBoxes.of(scene, self.geom.r_cm_B)  # docked vehicles, while docked (issue 35)
        self._H_scale = None  # [m per N m s], fixed at the first row with H != 0
        self._moved = _origin_moves(scene, self.geom.r_cm_B)  # the mass centre after each event, or None

    def log_static(self, rec) -> None:
        """Log the parts that do not move relative to their entity (static): boxes, axes, the
        orbit ring, the sun, colours and labels.

        Parameters
        ----------
        rec : rerun.RecordingStream
        """
        rr = import_rerun()
        g, scene = self.geom, self.scene
        L = g.extent
        on = {s.on for s in self.surfaces}
        for s in self.surfaces:  # the scene's [[surface]] tables, at their sizes and places
            ent = "world/station/surfaces" if s.on == "body" else f"world/station/{s.on}/surfaces"
            color = RGB_SURFACE_BODY if s.on == "body" else RGB_SURFACE_ARRAY
            rec.log(f"{ent}/{s.name}", _boxes([(s.center, s.half_sizes, s.C)], color, labels=[s.name]), static=True)
        if "body" not in on:  # no body surface: the equivalent box of the mass properties
            rec.log("world/station/body", _boxes([(g.body_center, g.body_half, g.body_C)], RGB_BODY), static=True)
            if g.truss is not None:
                boxes = [(g.truss[0], g.truss[1], np.eye(3))] + ([g.mast] if g.mast is not None else [])
                rec.log("world/station/truss", _boxes(boxes, RGB_TRUSS), static=True)
        rec.log(
            "world/station/axes_B",
            rr.Arrows3D(
                vectors=AXES_B_FRACTION * L * np.eye(3),
                colors=[RGB_X, RGB_Y, RGB_Z],
                labels=["x_B", "y_B", "z_B"],
                show_labels=False,
            ),
            static=True,
        )
        for name, _, half, C_PA in g.arrays:  # centred on the entity's origin, the array's mass centre
            if name not in on:  # an array without a surface: its equivalent box
                rec.log(f"world/station/{name}", _boxes([(None, half, C_PA)], RGB_ARRAY, labels=[name]), static=True)
        if self.sensors is not None:
            self.sensors.log_static(rec)
        if self.thrusters is not None:
            self.thrusters.log_static(rec)
        if self.vehicles is not None:
            self.vehicles.log(rec, _boxes)
        if self.elastic is not None:
            self.elastic.log_static(rec)
        if scene.orbit is not None:
            rec.log(
                "world/lvlh/axes",
                rr.Arrows3D(
                    vectors=AXES_O_FRACTION * L * np.eye(3),
                    colors=[RGB_X, RGB_Y, RGB_Z],
                    labels=["x_O (velocity)", "y_O (-orbit normal)", "z_O (nadir)"],
                    show_labels=False,
                    radii=0.004 * L,
                ),
                static=True,
            )
            rec.log(
                "world/lvlh/earth",
                rr.Arrows3D(vectors=[[0.0, 0.0, EARTH_ARROW_FRACTION * L]], colors=[RGB_EARTH], labels=["Earth"],
                            radii=0.006 * L),
                static=True,
            )
            rec.log(  # ram: the flight direction (x_O of a circular orbit), where the drag comes from
                "world/lvlh/ram",
                rr.Arrows3D(vectors=[[RAM_ARROW_FRACTION * L, 0.0, 0.0]], colors=[RGB_RAM], labels=["ram"], radii=0.006 * L),
                static=True,
            )
            t_ring = np.linspace(0.0, 2.0 * math.pi / scene.orbit.mean_motion, ORBIT_RING_POINTS)  # one revolution
            rec.log(
                "world/orbit/track",
                rr.LineStrips3D([ORBIT_RING_FRACTION * L * R_N_over_a(scene.orbit, t_ring)], colors=[RGB_ORBIT]),
                static=True,
            )
            rec.log("world/orbit/station", rr.Points3D.from_fields(colors=[RGB_ORBIT], radii=0.02 * L), static=True)
        if scene.sun is not None:
            rec.log(
                "world/sun",
                rr.Arrows3D(vectors=[SUN_ARROW_FRACTION * L * sun_vector_N(scene)], labels=["sun"], radii=0.006 * L),
                static=True,
            )
            rec.set_time(TIMELINE, duration=0.0)  # the colour on the timeline: it greys out in the Earth's shadow
            rec.log("world/sun", rr.Arrows3D.from_fields(colors=[RGB_SUN]))  # (static would shadow the changes)
            rec.reset_time()
        rec.log("world/H_O_N", rr.Arrows3D.from_fields(colors=[RGB_H], labels=["H_O_N"], show_labels=False), static=True)
        if self.cmg is not None:
            self.cmg.log_static(rec)

    def send(self, rec, send, rows: Trajectory) -> None:
        """Send the moving parts of ``rows``: ``C_NB``, each array's ``C_BP``, the elastic lines,
        ``H_O_N``, ``C_NO``, the orbit dot and the CMG arrows.

        Parameters
        ----------
        rec : rerun.RecordingStream
            Takes the labels fixed on the way (static).
        send : callable
            ``send(entity, columns)``: one ``send_columns`` call on the times of ``rows``.
        rows : Trajectory
            k rows with at least the base columns (:func:`~stationbed.run.trajectory.base_columns`).
        """
        rr = import_rerun()
        g, scene = self.geom, self.scene
        k = len(rows)
        if self._moved is None:
            send("world/station", rr.Transform3D.columns(quaternion=xyzw(rows.q_BN)))
        else:  # the station's points r drawn at C_NB (r - c(t)): its frame put at -C_NB (c(t) - c(0))
            times, dc_B = self._moved
            dc = dc_B[np.searchsorted(times, np.asarray(rows.t, float) + 1e-9, side="right")]  # (k, 3)
            C_BN = dcm(np.asarray(rows.q_BN, dtype=float).T)  # (3, 3, k)
            send("world/station", rr.Transform3D.columns(translation=-np.einsum("jik,kj->ki", C_BN, dc),
                                                         quaternion=xyzw(rows.q_BN)))
        for name, r, _, _ in g.arrays:
            q = xyzw_C_BP(rows[f"alpha_{name}"], rows[f"beta_{name}"])
            send(f"world/station/{name}", rr.Transform3D.columns(translation=np.tile(r, (k, 1)), quaternion=q))
        if self.elastic is not None:
            self.elastic.send(rec, send, rows)
        H = rows.H_O_N
        if self._H_scale is None:
            H_norm = np.linalg.norm(H, axis=1)
            if np.any(H_norm > 0):
                self._H_scale = H_ARROW_FRACTION * g.extent / float(H_norm[np.argmax(H_norm > 0)])
        send("world/H_O_N", rr.Arrows3D.columns(vectors=H * (self._H_scale or 0.0)))
        if scene.orbit is not None:
            o = scene.orbit
            send("world/lvlh", rr.Transform3D.columns(quaternion=xyzw_C_NO(o, rows.t)))
            send("world/orbit/station", rr.Points3D.columns(positions=ORBIT_RING_FRACTION * g.extent * R_N_over_a(o, rows.t)))
        if self.cmg is not None:
            self.cmg.send(send, rows)
        if self.sensors is not None:
            self.sensors.send(rec, send, rows)
        if self.thrusters is not None:
            self.thrusters.send(rec, rows)
        for t, _, text in self.events.send(rec, rows):  # the sun's arrow greys out in the Earth's shadow
            if scene.sun is not None and text in ("eclipse entry", "eclipse exit"):
                rec.set_time(TIMELINE, duration=t)
                rec.log("world/sun", rr.Arrows3D.from_fields(colors=[RGB_SUN_SHADOW if text == "eclipse entry" else RGB_SUN]))
                rec.reset_time()


def _boxes(boxes, color, labels=None):
    """Solid boxes of one colour.

    Parameters
    ----------
    boxes : list of tuple
        ``(center, half_sizes, C)`` per box: centre in the entity's frame [m] (None: all at its
        origin), half sizes along the box's axes [m] and the rotation box -> entity, (3, 3).
    color : tuple of int
        RGB.
    labels : list of str, optional

    Returns
    -------
    rerun.Boxes3D
    """
    rr = import_rerun()
    kw = {} if labels is None else {"labels": labels, "show_labels": False}  # names on hover, not piled up
    if boxes[0][0] is not None:
        kw["centers"] = [b[0] for b in boxes]
    return rr.Boxes3D(half_sizes=[b[1] for b in boxes], quaternions=[xyzw_of_dcm(b[2]) for b in boxes], colors=[color],
                      fill_mode="solid", **kw)


def _origin_moves(scene, c0_B) -> tuple[np.ndarray, np.ndarray] | None:
    """``(times [s], dc_B (n + 1, 3) [m])``: the events still to come and the composite mass centre
    of each configuration (:func:`~stationbed.scene.docking.mass_centre_B`) less the drawing's
    origin ``c0_B`` (the start's), B axes; None when no event moves it (nothing is translated)."""
    events = [e.t for e in getattr(scene, "event", None) or [] if not e.done]
    if not events:
        return None
    dc = np.array([mass_centre_B(scene, w) for w in configuration_ports(scene)]) - np.asarray(c0_B, float)
    return (np.array(events, float), dc) if np.any(dc) else None
