"""Flexible arrays drawn as the bent centre lines of their beam modes (issue 6), exaggerated.

One entity ``world/station/<array>/elastic_line`` per array with beam modes, in the array's frame
P (so ``C_BP`` turns it with the array's box); its label carries the exaggeration.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...core.beam import axis_vector, cantilever_shape
from ...run.trajectory import Trajectory
from .sdk import import_rerun

__all__ = ["ElasticLines", "ArrayBeams", "ELASTIC_POINTS", "ELASTIC_FRACTION"]

#: A flexible array's beam is drawn as a line of this many stations, root to tip; its largest
#: tip amplitude at the first row with elastic motion is drawn this fraction of the longest beam.
ELASTIC_POINTS = 21
ELASTIC_FRACTION = 0.2
#: Line width as a fraction of the station's extent.
ELASTIC_RADIUS_FRACTION = 0.003
RGB_ELASTIC = (250, 120, 40)


class ArrayBeams(NamedTuple):
    """The beams of one flexible array, g of them, and its m modes."""

    name: str
    base: np.ndarray  # (g, n, 3): the beams' rigid centre lines, P components [m]
    eta_columns: tuple[str, ...]  # the array's m modal coordinates, eta_<array>_<k>
    psi: np.ndarray  # (g, m, n): tip-normalised shape of each mode along each beam (0: not that beam's)
    e_defl: np.ndarray  # (g, m, 3): deflection direction of each mode, P components


class ElasticLines:
    """The deflected centre line of each flexible array's beam modes, in P, exaggerated.

    Modes given by a ``beam`` (:class:`~stationbed.scene.Beam`) with the same root, span and
    length are one beam: its points ``a(s) = root + s e_span`` (s in [0, L], ``ELASTIC_POINTS``
    stations) are drawn at ``a(s) + k Σ_m η_m ψ_m(s) e_defl,m`` with ψ_m the tip-normalised
    cantilever shape (:func:`stationbed.core.beam.cantilever_shape`, the one the model's integrals
    come from), one strip per beam, in the array's entity (so ``C_BP`` turns it with the array).
    Modes given by their integrals alone have no shape to draw (their η are plotted all the same).

    ``k`` (the exaggeration, one for the whole scene) is fixed at the first row with any motion:
    the largest free-vibration tip amplitude ``Σ_m sqrt(η_m² + (η̇_m/ω_m)²)`` of a beam there is
    drawn ``ELASTIC_FRACTION`` of the longest beam. Build it with :meth:`of`, which returns None
    when there is nothing to draw.

    Parameters
    ----------
    scene : stationbed.scene.Scene
    extent : float
        The station's drawing length ``L`` [m] (line width).

    Attributes
    ----------
    arrays : list of ArrayBeams
        One per array with beam modes.
    scale : float or None
        Drawn metres per metre of deflection; None until the first row with motion.
    """

    def __init__(self, scene, extent: float):
        self.extent = extent
        self.arrays = []
        amp_cols, amp_omega = [], []
        self.longest = 0.0
        for a in scene.appendage:
            groups: dict[tuple, list] = {}
            for k, mode in enumerate(a.mode, start=1):
                b = mode.shape_beam
                if b is not None:
                    groups.setdefault((tuple(b.root), b.span, b.length), []).append((k, mode))
            if not groups:
                continue
            m_all = len(a.mode)
            s = np.linspace(0.0, 1.0, ELASTIC_POINTS)
            base, psi, e_d = [], np.zeros((len(groups), m_all, ELASTIC_POINTS)), np.zeros((len(groups), m_all, 3))
            for g, ((root, span, length), modes) in enumerate(groups.items()):
                e_s = axis_vector(span)
                base.append(np.asarray(root, float) + (length * s)[:, None] * e_s)
                for k, mode in modes:
                    psi[g, k - 1] = cantilever_shape(mode.shape_beam.n, length * s, length)
                    e_d[g, k - 1] = axis_vector(mode.shape_beam.deflection)
                    amp_cols.append((f"eta_{a.name}_{k}", f"etadot_{a.name}_{k}", len(self.arrays), g))
                    amp_omega.append(2.0 * math.pi * mode.frequency_hz)
                self.longest = max(self.longest, float(length))
            eta_cols = tuple(f"eta_{a.name}_{k}" for k in range(1, m_all + 1))
            self.arrays.append(ArrayBeams(a.name, np.array(base), eta_cols, psi, e_d))
        self._amp_cols = amp_cols
        self._amp_omega = np.array(amp_omega)
        self.scale = None  # drawn metres per metre of deflection, fixed at the first motion

    @classmethod
    def of(cls, scene, columns, extent: float) -> ElasticLines | None:
        """The drawing, or None when no array has beam modes or the rows lack their columns.

        Parameters
        ----------
        scene : stationbed.scene.Scene
        columns : list of str
            Column names of the rows.
        extent : float
            The station's drawing length ``L`` [m].
        """
        if not any(m.shape_beam is not None for a in scene.appendage for m in a.mode):
            return None
        need = {f"{w}_{a.name}_{k}" for a in scene.appendage for k in range(1, len(a.mode) + 1) for w in ("eta", "etadot")}
        return cls(scene, extent) if need <= set(columns) else None

    def fix_scale(self, rows: Trajectory) -> bool:
        """Fix the exaggeration at the first row with motion; True when it was fixed now.

        Parameters
        ----------
        rows : Trajectory
            k rows with the modal columns ``eta_<array>_<k>`` [m], ``etadot_<array>_<k>`` [m/s].
        """
        if self.scale is not None:
            return False
        k = len(rows)
        amp = np.zeros((k, len(self.arrays), max(len(x.base) for x in self.arrays)))
        for (eta, etadot, i, g), w in zip(self._amp_cols, self._amp_omega):
            amp[:, i, g] += np.hypot(rows[eta], rows[etadot] / w)
        peak = amp.reshape(k, -1).max(axis=1)
        moving = np.flatnonzero(peak > 0.0)
        if not len(moving):
            return False
        self.scale = ELASTIC_FRACTION * self.longest / float(peak[moving[0]])
        return True

    def strips(self, rows: Trajectory):
        """The drawn lines of ``rows``.

        Parameters
        ----------
        rows : Trajectory
            k rows with the modal columns ``eta_<array>_<k>`` [m].

        Yields
        ------
        name : str
            The array.
        points : ndarray, shape (k * g, n, 3)
            One strip of n points per beam (g of them) and row, P components [m].
        """
        k = self.scale or 0.0
        for a in self.arrays:
            eta = rows.cols(*a.eta_columns)  # (rows, m)
            u = np.einsum("rm,gmn,gmi->rgni", eta, a.psi, a.e_defl)  # deflection (rows, g, n, 3)
            yield a.name, (a.base[None] + k * u).reshape(-1, *a.base.shape[1:])

    def log_static(self, rec) -> None:
        """Log the lines' colour and width (static).

        Parameters
        ----------
        rec : rerun.RecordingStream
        """
        rr = import_rerun()
        for a in self.arrays:
            rec.log(f"world/station/{a.name}/elastic_line",
                    rr.LineStrips3D.from_fields(colors=[RGB_ELASTIC], radii=ELASTIC_RADIUS_FRACTION * self.extent),
                    static=True)

    def send(self, rec, send, rows: Trajectory) -> None:
        """Send the lines of ``rows``; label the exaggeration once it is fixed.

        Parameters
        ----------
        rec : rerun.RecordingStream
            Takes the label (static).
        send : callable
            ``send(entity, columns)``: one ``send_columns`` call on the times of ``rows``.
        rows : Trajectory
            k rows with the modal columns.
        """
        rr = import_rerun()
        if self.fix_scale(rows):
            for a in self.arrays:
                rec.log(f"world/station/{a.name}/elastic_line",
                        rr.LineStrips3D.from_fields(labels=[f"{a.name} deflection x{self.scale:.3g}"]), static=True)
        k = len(rows)
        for name, pts in self.strips(rows):
            n_beams = pts.shape[0] // k
            send(f"world/station/{name}/elastic_line", rr.LineStrips3D.columns(strips=pts).partition([n_beams] * k))
