"""The CMG cluster drawn in the station: one arrow per unit (its rotor momentum) and the total ``h``.

Entities ``world/station/cmg/units`` (one arrow per unit, from a point out along its gimbal axis)
and ``world/station/cmg/h_B`` (the cluster's total, from the body centre), B components; both at
the same scale, one rotor's momentum drawn ``CMG_ARROW_FRACTION`` of the station's extent.
"""

from __future__ import annotations

import numpy as np

from ...model.cmg import cmg_geometry
from ...run.trajectory import Trajectory
from .geometry import StationGeometry
from .sdk import import_rerun

__all__ = ["CmgArrows", "CMG_ARROW_FRACTION", "CMG_ORIGIN_FRACTION"]

#: One CMG rotor's momentum (h_rotor; ideal cluster: max_momentum, or its first non-zero |h|)
#: is drawn this long, as a fraction of the station's extent; each unit's arrow starts this far
#: out along its (outer) gimbal axis.
CMG_ARROW_FRACTION = 0.25
CMG_ORIGIN_FRACTION = 0.12

RGB_CMG_TOTAL = (230, 90, 200)
RGB_CMG_UNITS = [(200, 60, 160), (60, 180, 200), (150, 110, 230), (240, 130, 60), (90, 200, 120), (200, 200, 80)]

#: Row columns of the cluster's total momentum h, B components [N m s].
H_COLUMNS = ("hx", "hy", "hz")


class CmgArrows:
    """Arrows of the CMG cluster in B: one per unit (its rotor momentum) and the total ``h``.

    Per unit, from the gimbal angles with the geometry the cluster's kind registers in
    :mod:`stationbed.model.cmg` (``unit_momenta_B``, ``mount_axes_B``): e.g. dgcmg
    ``h_i = h_rotor (sin δi e1 + cos δi (cos δo e3 - sin δo e2))``, pyramid
    ``h_i = h_rotor (cos δ s0 + sin δ (g × s0))``; a cluster without units (ideal) draws only
    ``h``. Build it with :meth:`of`, which returns None when the rows lack the columns it needs.

    Parameters
    ----------
    cfg : stationbed.scene.Cmg
        The scene's ``[cmg]`` table.
    geom : StationGeometry
        The station's drawing (extent and body centre).
    """

    def __init__(self, cfg, geom: StationGeometry):
        self.cfg = cfg
        self.geometry = cmg_geometry(cfg)
        self.gimbals = self.geometry.gimbal_names
        L = geom.extent
        center = geom.body_center
        self.n_units = self.geometry.n_units if self.geometry.gimballed else 0
        # one rotor's momentum; an ideal cluster: its limit (None: the first non-zero |h|, fixed when seen)
        self.h_ref = self.geometry.rotor_momentum(cfg) if self.geometry.gimballed else cfg.max_momentum
        axes = self.geometry.mount_axes_B(cfg) if self.n_units else np.zeros((0, 3))
        self.origins = center + CMG_ORIGIN_FRACTION * L * axes
        self.center = center
        self.length = CMG_ARROW_FRACTION * L  # drawn length of h_ref

    @classmethod
    def of(cls, scene, columns, geom: StationGeometry) -> CmgArrows | None:
        """The drawing, or None when the scene has no cluster or the rows lack its columns.

        Parameters
        ----------
        scene : stationbed.scene.Scene
        columns : list of str
            Column names of the rows.
        geom : StationGeometry
        """
        c = scene.cmg
        if c is None or not set(H_COLUMNS) <= set(columns):
            return None
        need = set(cmg_geometry(c).gimbal_names)
        return cls(c, geom) if need <= set(columns) else None

    def unit_momenta(self, rows: Trajectory) -> np.ndarray:
        """Rotor momentum of each unit, B components [N m s].

        Parameters
        ----------
        rows : Trajectory
            k rows with the gimbal angle columns [rad].

        Returns
        -------
        ndarray, shape (k, n_units, 3)
        """
        return self.geometry.unit_momenta_B(self.cfg, rows.cols(*self.gimbals))

    def scale(self, h: np.ndarray) -> float:
        """Drawing scale [m per N m s] (fixes an unlimited ideal cluster's at its first |h| > 0).

        Parameters
        ----------
        h : ndarray, shape (k, 3)
            Cluster momentum, B components [N m s].
        """
        if self.h_ref is None:
            n = np.linalg.norm(h, axis=1)
            if not np.any(n > 0):
                return 0.0
            self.h_ref = float(n[np.argmax(n > 0)])
        return self.length / self.h_ref

    def log_static(self, rec) -> None:
        """Log the arrows' origins, colours and labels (static).

        Parameters
        ----------
        rec : rerun.RecordingStream
        """
        rr = import_rerun()
        if self.n_units:
            rec.log(
                "world/station/cmg/units",
                rr.Arrows3D.from_fields(
                    origins=self.origins,
                    colors=[RGB_CMG_UNITS[i % len(RGB_CMG_UNITS)] for i in range(self.n_units)],
                    labels=[f"CMG {i + 1}" for i in range(self.n_units)],
                    show_labels=False,  # on hover: four labels at one point pile up
                ),
                static=True,
            )
        rec.log(
            "world/station/cmg/h_B",
            rr.Arrows3D.from_fields(origins=[self.center], colors=[RGB_CMG_TOTAL], labels=["h (CMG total)"], show_labels=False),
            static=True,
        )

    def send(self, send, rows: Trajectory) -> None:
        """Send the arrows of ``rows``, B components, scaled to [m].

        Parameters
        ----------
        send : callable
            ``send(entity, columns)``: one ``send_columns`` call on the times of ``rows``.
        rows : Trajectory
            k rows with ``hx, hy, hz`` [N m s] and the gimbal angles [rad].
        """
        rr = import_rerun()
        h = rows.cols(*H_COLUMNS)
        s = self.scale(h)
        k = len(rows)
        if self.n_units:
            units = self.unit_momenta(rows).reshape(-1, 3) * s
            send("world/station/cmg/units", rr.Arrows3D.columns(vectors=units).partition([self.n_units] * k))
        send("world/station/cmg/h_B", rr.Arrows3D.columns(vectors=h * s))
