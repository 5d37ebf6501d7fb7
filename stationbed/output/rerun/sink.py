"""Rerun recordings of runs and of cross-formulation checks (DESIGN §2, issue 4).

A recording holds

* an inertial 3-D scene: the world frame is ``N`` translated to the composite mass centre (the
  station sits at the origin, it does not fly round the Earth: attitude motion of a 100 m
  station would be invisible at orbit scale). ``world/station`` carries ``C_NB`` per time,
  each array ``world/station/<name>`` its own ``C_BP`` and mass-centre offset; boxes with the
  principal moments of the body and of each array; the LVLH triad and the Earth (nadir)
  direction; the total angular momentum ``H_O_N`` as an arrow; the orbit as a ring (scaled,
  Earth-centred) with a dot at the station's argument of latitude;
* time series on the ``sim_time`` timeline [s] under ``telemetry/`` (one entity per quantity,
  its components as named series: one ``send_columns`` call per quantity per send);
* a blueprint (3-D view beside stacked plots), stored in the same file as a blueprint store.

:class:`RrdSink` streams: the rows :func:`stationbed.simulate` hands over are sent and flushed
to the file at most ``flush_interval_s`` of wall time after they arrive, and all of them when the
sink closes (which the command line does on every way out, failed runs included), so a run that
fails part-way leaves a complete, verifiable recording up to the failure; a killed process leaves
everything but the last interval. The static parts (geometry, axes, series names, blueprint) are
sent once when the sink opens.

Rotations go to rerun as quaternions ``(x, y, z, w)`` of the matrix that maps the child
entity's components into its parent's (DESIGN §3): ``C_NB`` for the station, ``C_BP`` for an
array, ``C_NO`` for LVLH. Rerun stores them as float32 (~6e-8 resolution); scalars as float64.

With a ``[cmg]`` the station carries one arrow per CMG unit (its rotor momentum, B components,
from the logged gimbal angles and the geometry of :mod:`stationbed.cmg`) and the cluster's total
``h``; with a ``[sun]`` the (inertially fixed) sun direction is drawn. Columns of issue 3 (CMG,
controller, sun tracking) are logged under ``telemetry/cmg``, ``telemetry/control`` and
``telemetry/arrays/<name>/track_err_deg``; any other column under ``telemetry/extra``.

With flexible arrays (issue 6) the modal columns ``eta_<array>_<k>``, ``etadot_<array>_<k>`` are
one entity per array and quantity under ``telemetry/modes/<array>/`` and ``U_strain`` is
``telemetry/modes/U_strain`` (a third column of plots in the blueprint); an array's ``beam``
modes are drawn as its bent centre line, exaggerated, in its own frame (:class:`_ElasticLines`).
A rigid scene's recording has none of these.

Cost: the per-call overhead of the SDK (~0.1 ms per ``send_columns``, ~1 ms per blocking flush)
is what logging costs, so rows are collected and sent at most every ``flush_interval_s`` of wall
time (and on :meth:`RrdSink.close`), not per batch the simulation hands over.
"""

from __future__ import annotations

import itertools
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core.massprops import composite_cm
from ...core.rotation import dcm, quat_from_dcm, rotation_angle
from ...scene import Scene
from ...core.beam import cantilever_shape
from ...model.cmg import dgcmg_triads, pyramid_axes
from ...model.environment import sun_direction_N
from ...run.trajectory import Trajectory, base_columns

__all__ = [
    "APPLICATION_ID",
    "TIMELINE",
    "RrdSink",
    "TeeSink",
    "write_recording",
    "write_check_recording",
    "run_blueprint",
    "check_blueprint",
    "box_half_sizes",
]

APPLICATION_ID = "stationbed"
TIMELINE = "sim_time"  # seconds since the start of the run (a rerun duration timeline)

#: Thinnest box drawn, as a fraction of the box's largest side: a flat array (triangle
#: inequality met with equality, Iz = Ix + Iy) would otherwise have zero thickness.
MIN_BOX_FRACTION = 0.01
#: Drawing lengths as fractions of the station's extent L (largest distance of any box corner
#: from the composite mass centre).
AXES_B_FRACTION = 0.35
AXES_O_FRACTION = 0.6
EARTH_ARROW_FRACTION = 1.0
H_ARROW_FRACTION = 0.8  # |H| of the first row with H != 0 is drawn this long
ORBIT_RING_FRACTION = 1.3
SUN_ARROW_FRACTION = 1.2
#: One CMG rotor's momentum (h_rotor; ideal cluster: max_momentum, or its first non-zero |h|)
#: is drawn this long; each unit's arrow starts this far out along its (outer) gimbal axis.
CMG_ARROW_FRACTION = 0.25
CMG_ORIGIN_FRACTION = 0.12
#: A flexible array's beam is drawn as a line of this many stations, root to tip; its largest
#: tip amplitude at the first row with elastic motion is drawn this fraction of the longest beam.
ELASTIC_POINTS = 21
ELASTIC_FRACTION = 0.2

#: Wall time [s] rows may wait in an RrdSink before they are sent and flushed to the file.
#: Each send costs ~0.1 ms per entity (23 for iss_lvlh_hold) plus the flush; the closed loop
#: hands over 64 rows every ~40 ms, and sending each batch cost 15-18 % of a 3-orbit run against
#: ~5 % when collected (benchmarks/bench_rerun.py, docs/rerun.md). A killed process loses at
#: most this much; a failed run nothing (close sends the rest). 0: send and flush every batch.
FLUSH_INTERVAL_S = 0.5

RGB_X, RGB_Y, RGB_Z = (230, 60, 60), (60, 190, 60), (70, 110, 240)
RGB_BODY, RGB_TRUSS, RGB_ARRAY = (170, 170, 180), (120, 120, 130), (40, 70, 170)
RGB_EARTH, RGB_H, RGB_ORBIT = (40, 150, 220), (250, 170, 20), (120, 160, 200)
RGB_SUN, RGB_CMG_TOTAL = (255, 215, 0), (230, 90, 200)
RGB_ELASTIC = (250, 120, 40)
RGB_CMG_UNITS = [(200, 60, 160), (60, 180, 200), (150, 110, 230), (240, 130, 60), (90, 200, 120), (200, 200, 80)]


def _rr():
    import rerun as rr  # deferred: importing rerun costs ~0.3 s, paid only when recording

    return rr


# -- geometry ---------------------------------------------------------------------------------
def box_half_sizes(mass: float, inertia) -> tuple[np.ndarray, np.ndarray]:
    """Uniform box with the same mass and principal moments.

    For a box of sides ``a, b, c`` along its principal axes ``Ix = m (b² + c²) / 12`` etc., so
    ``a² = 6 (Iy + Iz - Ix) / m`` (and cyclic).

    Parameters
    ----------
    mass : float
        [kg]
    inertia : array_like, shape (3, 3)
        About the mass centre, in the frame the box is drawn in [kg m²].

    Returns
    -------
    half_sizes : ndarray, shape (3,)
        Half side lengths along the principal axes [m], at least ``MIN_BOX_FRACTION`` of the
        largest.
    C_FA : ndarray, shape (3, 3)
        Columns are the principal axes in the frame F of ``inertia`` (a proper rotation, maps
        principal-axis components into F components).
    """
    moments, C_FA = np.linalg.eigh(np.asarray(inertia, dtype=float))
    if np.linalg.det(C_FA) < 0:
        C_FA[:, 2] *= -1.0
    Ix, Iy, Iz = moments
    sides_sq = 6.0 / mass * np.array([Iy + Iz - Ix, Ix + Iz - Iy, Ix + Iy - Iz])
    sides = np.sqrt(np.clip(sides_sq, 0.0, None))
    sides = np.maximum(sides, MIN_BOX_FRACTION * sides.max())
    return 0.5 * sides, C_FA


def _xyzw(C: np.ndarray) -> np.ndarray:
    """Rerun quaternion ``(x, y, z, w)`` of the rotation matrix ``C`` (child -> parent).

    ``quat_from_dcm(C_BN)`` is the ``q`` with ``dcm(q) = C_BN``, i.e. whose active rotation is
    ``C_BN.T``; so ``C``'s quaternion is ``quat_from_dcm(C.T)``. (Not scipy's ``Rotation``: its
    import, ~0.3 s, would delay the recording process of ``stationbed run --rrd``.)
    """
    return quat_from_dcm(np.asarray(C, dtype=float).T)[[1, 2, 3, 0]]


def _corners_extent(center, half_sizes, C_FA) -> float:
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    return float(np.max(np.linalg.norm(center + (signs * half_sizes) @ C_FA.T, axis=1)))


class _Geometry:
    """Static drawing of a scene in B, about the composite mass centre."""

    def __init__(self, scene: Scene):
        body, apps = scene.body, scene.appendage
        masses = [body.mass] + [a.mass for a in apps]
        cms = [body.cm] + [a.cm for a in apps]
        self.r_cm_B = composite_cm(masses, cms)
        self.body_center = np.asarray(body.cm, float) - self.r_cm_B
        self.body_half, self.body_C = box_half_sizes(body.mass, body.inertia)
        extent = _corners_extent(self.body_center, self.body_half, self.body_C)
        self.arrays = []  # (name, r_P_B about the composite CM, half sizes, C_PA)
        for a in apps:
            half, C_PA = box_half_sizes(a.mass, a.inertia)
            r = np.asarray(a.cm, float) - self.r_cm_B
            self.arrays.append((a.name, r, half, C_PA))
            extent = max(extent, float(np.linalg.norm(r)) + float(np.linalg.norm(half)))
        # truss: the box spanning the arrays' mass centres (or body -> single array)
        pts = [r for _, r, _, _ in self.arrays]
        if len(pts) == 1:
            pts.append(self.body_center)
        self.truss = None
        if len(pts) >= 2:
            pts = np.array(pts)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            thick = max(0.02 * float(np.max(hi - lo)), 0.25)  # m
            self.truss = (0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 0.5 * thick))
        # mast: body centre -> truss centre, when the truss centre is outside the body box
        self.mast = None
        if self.truss is not None:
            d = self.truss[0] - self.body_center
            if np.any(np.abs(self.body_C.T @ d) > self.body_half):
                z = d / np.linalg.norm(d)
                x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
                x /= np.linalg.norm(x)
                C = np.column_stack([x, np.cross(z, x), z])
                self.mast = (self.body_center + 0.5 * d, np.array([0.5 * thick, 0.5 * thick, 0.5 * np.linalg.norm(d)]), C)
        self.extent = extent  # L [m]


# -- telemetry layout -------------------------------------------------------------------------
_GIMBAL_COLUMN = re.compile(r"gimbal_\d+(_outer|_inner)?")


@dataclass(frozen=True)
class _Series:
    """One telemetry entity: ``columns`` of the rows as named series (plus their norm)."""

    entity: str
    columns: tuple[str, ...]
    names: tuple[str, ...]
    norm: bool = False  # append the Euclidean norm of the columns as the last series


def _telemetry_series(columns, appendage_names, modes=None) -> tuple[list[_Series], list[str]]:
    """The telemetry entities of rows with ``columns``, and the columns left for ``extra/``.

    Base columns (DESIGN §6) and those of issue 3 (CMG, controller, sun tracking) get their own
    entity; a group is taken only when all its columns are present. ``modes`` maps an array's
    name to its number of elastic modes (issue 6): its ``eta_<array>_<k>`` and
    ``etadot_<array>_<k>`` are one entity each under ``telemetry/modes/<array>/``, ``U_strain``
    is ``telemetry/modes/U_strain``.
    """
    present, used = set(columns), set()
    out: list[_Series] = []

    def take(entity, cols, names=None, norm=False):
        cols = tuple(cols)
        if cols and all(c in present and c not in used for c in cols):
            out.append(_Series(entity, cols, tuple(names or cols), norm))
            used.update(cols)

    take("telemetry/omega_BN_B", ["wx", "wy", "wz"], ["x", "y", "z"])
    take("telemetry/H_O_N", ["HNx", "HNy", "HNz"], ["x", "y", "z", "|H|"], norm=True)
    take("telemetry/T", ["T"])
    for n in appendage_names:
        take(f"telemetry/arrays/{n}", [f"alpha_{n}", f"beta_{n}"], [f"{n} alpha", f"{n} beta"])
    used.update(c for c in ("t", "qw", "qx", "qy", "qz") if c in present)
    take("telemetry/cmg/h_B", ["hx", "hy", "hz"], ["x", "y", "z", "|h|"], norm=True)
    gimbals = [c for c in columns if _GIMBAL_COLUMN.fullmatch(c)]
    take("telemetry/cmg/gimbal/angle", gimbals)
    take("telemetry/cmg/gimbal/rate", [f"{g}_rate" for g in gimbals])
    take("telemetry/cmg/singularity", ["cmg_singularity"], ["singularity measure"])
    take("telemetry/cmg/saturated", ["cmg_saturated"], ["saturated (0/1)"])
    take("telemetry/control/tau_cmd_B", ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z"], ["x", "y", "z"])
    take("telemetry/control/att_err_deg", ["att_err_deg"])
    for n in appendage_names:
        take(f"telemetry/arrays/{n}/track_err_deg", [f"track_err_deg_{n}"], [n])
    modes = {n: m for n, m in (modes or {}).items() if m}
    for n, m in modes.items():
        ks = range(1, m + 1)
        take(f"telemetry/modes/{n}/eta", [f"eta_{n}_{k}" for k in ks], [f"{n} eta_{k}" for k in ks])
        take(f"telemetry/modes/{n}/etadot", [f"etadot_{n}_{k}" for k in ks], [f"{n} etadot_{k}" for k in ks])
    if modes:
        take("telemetry/modes/U_strain", ["U_strain"])
    extra = [c for c in columns if c not in used]
    for c in extra:
        out.append(_Series(f"telemetry/extra/{c}", (c,), (c,)))
    return out, extra


class _CmgDrawing:
    """Arrows of the CMG cluster in B: one per unit (its rotor momentum) and the total ``h``.

    Per unit, from the gimbal angles with the geometry of :mod:`stationbed.cmg`:
    dgcmg ``h_i = h_rotor (sin δi e1 + cos δi (cos δo e3 - sin δo e2))`` (:func:`dgcmg_triads`),
    pyramid ``h_i = h_rotor (cos δ s0 + sin δ (g × s0))`` (:func:`pyramid_axes`); the ideal
    cluster has no units, only ``h``. Built only when the rows have the columns it needs.
    """

    def __init__(self, cfg, columns, geom: _Geometry):
        j = {c: i for i, c in enumerate(columns)}
        self.kind = cfg.kind
        self.j_h = [j[c] for c in ("hx", "hy", "hz")]
        L = geom.extent
        center = geom.body_center
        if cfg.kind == "ideal":
            self.n_units = 0
            self.h_ref = cfg.max_momentum  # None: the first non-zero |h| (fixed when seen)
            self.origins = np.zeros((0, 3))
        else:
            self.n_units = cfg.n_units
            self.h_ref = cfg.h_rotor
            if cfg.kind == "dgcmg":
                self.triads = dgcmg_triads(cfg.outer_axes_B)  # (n, 3, 3): e1, e2, e3
                self.j_g = [(j[f"gimbal_{i + 1}_outer"], j[f"gimbal_{i + 1}_inner"]) for i in range(self.n_units)]
                axes = self.triads[:, 0]
            else:
                self.g, self.s0 = pyramid_axes(cfg.skew)
                self.gxs0 = np.cross(self.g, self.s0)
                self.j_g = [j[f"gimbal_{i + 1}"] for i in range(self.n_units)]
                axes = self.g
            self.origins = center + CMG_ORIGIN_FRACTION * L * axes
        self.center = center
        self.length = CMG_ARROW_FRACTION * L  # drawn length of h_ref

    @classmethod
    def of(cls, scene: Scene, columns, geom: _Geometry):
        """The drawing, or None when the scene has no cluster or the rows lack its columns."""
        c = scene.cmg
        if c is None or not {"hx", "hy", "hz"} <= set(columns):
            return None
        if c.kind == "dgcmg":
            need = {f"gimbal_{i + 1}_{w}" for i in range(c.n_units) for w in ("outer", "inner")}
        elif c.kind == "sgcmg_pyramid":
            need = {f"gimbal_{i + 1}" for i in range(c.n_units)}
        else:
            need = set()
        return cls(c, list(columns), geom) if need <= set(columns) else None

    def unit_momenta(self, rows: np.ndarray) -> np.ndarray:
        """Rotor momentum of each unit, B components [N m s], shape (k, n_units, 3)."""
        if self.kind == "dgcmg":
            jo, ji = (list(x) for x in zip(*self.j_g))
            do, di = rows[:, jo][..., None], rows[:, ji][..., None]
            e1, e2, e3 = (self.triads[None, :, m] for m in range(3))
            spin = np.sin(di) * e1 + np.cos(di) * (np.cos(do) * e3 - np.sin(do) * e2)
        else:
            d = rows[:, self.j_g][..., None]
            spin = np.cos(d) * self.s0[None] + np.sin(d) * self.gxs0[None]
        return self.h_ref * spin

    def scale(self, h: np.ndarray) -> float:
        """Drawing scale [m per N m s] (fixes an unlimited ideal cluster's at its first |h| > 0)."""
        if self.h_ref is None:
            n = np.linalg.norm(h, axis=1)
            if not np.any(n > 0):
                return 0.0
            self.h_ref = float(n[np.argmax(n > 0)])
        return self.length / self.h_ref


def _mode_counts(scene: Scene) -> dict[str, int]:
    """Number of elastic modes per array (issue 6), for arrays that have any."""
    return {a.name: len(a.mode) for a in scene.appendage if a.mode}


class _ElasticLines:
    """The deflected centre line of each flexible array's beam modes, in P, exaggerated.

    Modes given by a ``beam`` (:class:`~stationbed.scene.Beam`) with the same root, span and
    length are one beam: its points ``a(s) = root + s e_span`` (s in [0, L], ``ELASTIC_POINTS``
    stations) are drawn at ``a(s) + k Σ_m η_m ψ_m(s) e_defl,m`` with ψ_m the tip-normalised
    cantilever shape (:func:`stationbed.flex.cantilever_shape`, the one the model's integrals come
    from), one strip per beam, in the array's entity (so ``C_BP`` turns it with the array).
    Modes given by their integrals alone have no shape to draw (their η are plotted all the same).

    ``k`` (the exaggeration, one for the whole scene) is fixed at the first row with any motion:
    the largest free-vibration tip amplitude ``Σ_m sqrt(η_m² + (η̇_m/ω_m)²)`` of a beam there is
    drawn ``ELASTIC_FRACTION`` of the longest beam. Built only when the rows have the columns.
    """

    def __init__(self, scene: Scene, columns):
        j = {c: i for i, c in enumerate(columns)}
        self.arrays = []  # (name, base points (g, n, 3), eta index (m,), psi (g, m, n), e_defl (g, m, 3))
        amp_idx, amp_omega = [], []
        self.longest = 0.0
        for a in scene.appendage:
            groups: dict[tuple, list] = {}
            for k, mode in enumerate(a.mode, start=1):
                b = mode.beam
                if b is not None:
                    groups.setdefault((tuple(b.root), b.span, b.length), []).append((k, mode))
            if not groups:
                continue
            m_all = len(a.mode)
            s = np.linspace(0.0, 1.0, ELASTIC_POINTS)
            base, psi, e_d = [], np.zeros((len(groups), m_all, ELASTIC_POINTS)), np.zeros((len(groups), m_all, 3))
            for g, ((root, span, length), modes) in enumerate(groups.items()):
                e_s = _axis_vector(span)
                base.append(np.asarray(root, float) + (length * s)[:, None] * e_s)
                for k, mode in modes:
                    psi[g, k - 1] = cantilever_shape(mode.beam.n, length * s, length)
                    e_d[g, k - 1] = _axis_vector(mode.beam.deflection)
                    amp_idx.append((j[f"eta_{a.name}_{k}"], j[f"etadot_{a.name}_{k}"], len(self.arrays), g))
                    amp_omega.append(2.0 * math.pi * mode.frequency_hz)
                self.longest = max(self.longest, float(length))
            eta_idx = np.array([j[f"eta_{a.name}_{k}"] for k in range(1, m_all + 1)])
            self.arrays.append((a.name, np.array(base), eta_idx, psi, e_d))
        self._amp_idx = amp_idx
        self._amp_omega = np.array(amp_omega)
        self.scale = None  # drawn metres per metre of deflection, fixed at the first motion

    @classmethod
    def of(cls, scene: Scene, columns):
        """The drawing, or None when no array has beam modes or the rows lack their columns."""
        counts = _mode_counts(scene)
        if not any(m.beam is not None for a in scene.appendage for m in a.mode):
            return None
        need = {f"{w}_{n}_{k}" for n, c in counts.items() for k in range(1, c + 1) for w in ("eta", "etadot")}
        return cls(scene, columns) if need <= set(columns) else None

    def fix_scale(self, rows: np.ndarray) -> bool:
        """Fix the exaggeration at the first row with motion; True when it was fixed now."""
        if self.scale is not None:
            return False
        amp = np.zeros((rows.shape[0], len(self.arrays), max(len(x[1]) for x in self.arrays)))
        for (je, jd, i, g), w in zip(self._amp_idx, self._amp_omega):
            amp[:, i, g] += np.hypot(rows[:, je], rows[:, jd] / w)
        peak = amp.reshape(rows.shape[0], -1).max(axis=1)
        moving = np.flatnonzero(peak > 0.0)
        if not len(moving):
            return False
        self.scale = ELASTIC_FRACTION * self.longest / float(peak[moving[0]])
        return True

    def strips(self, rows: np.ndarray):
        """Per array: ``(name, points)``, points of shape (k * g, n, 3) in P [m], g beams."""
        k = self.scale or 0.0
        for name, base, eta_idx, psi, e_d in self.arrays:
            eta = rows[:, eta_idx]  # (rows, m)
            u = np.einsum("rm,gmn,gmi->rgni", eta, psi, e_d)  # deflection (rows, g, n, 3)
            yield name, (base[None] + k * u).reshape(-1, *base.shape[1:])


def _axis_vector(name: str) -> np.ndarray:
    """Unit vector of an axis name like ``"y"`` or ``"-z"`` (scene's ``Beam``)."""
    e = np.zeros(3)
    e["xyz".index(name.lstrip("+-")[0])] = -1.0 if name.startswith("-") else 1.0
    return e


# -- sinks ------------------------------------------------------------------------------------
class TeeSink:
    """Hands every batch of rows to several sinks (e.g. a :class:`~stationbed.trajectory.CsvSink`
    and an :class:`RrdSink`); :meth:`close` closes those that have a ``close`` method."""

    def __init__(self, *sinks):
        self.sinks = sinks
        self.columns = getattr(sinks[0], "columns", None) if sinks else None

    def write(self, rows: np.ndarray) -> None:
        for s in self.sinks:
            s.write(rows)

    def close(self) -> None:
        errors = []
        for s in self.sinks:
            close = getattr(s, "close", None)
            if close is not None:
                try:
                    close()
                except Exception as e:  # close the others, then report the first failure
                    errors.append(e)
        if errors:
            raise errors[0]


class RrdSink:
    """Streams trajectory rows of ``scene`` into a rerun recording at ``path``.

    Parameters
    ----------
    scene : Scene
    path : str or Path
        The ``.rrd`` file (parent folders are created).
    columns : list of str
        Column names of the rows :meth:`write` receives; must start with
        :func:`~stationbed.trajectory.base_columns` of the scene. The CMG, controller and sun
        columns of :func:`~stationbed.simulate.trajectory_columns` get their own entities
        (``telemetry/cmg/...``, ``telemetry/control/...``,
        ``telemetry/arrays/<name>/track_err_deg``), and so do the modal columns of flexible
        arrays (``telemetry/modes/...``); any other column is logged under
        ``telemetry/extra/<column>``.
    duration : float, optional
        Run length [s], for the blueprint only: the plots' time axis and the playback speed
        (default: the scene's ``simulation.duration``).
    flush_interval_s : float, optional
        Rows handed to :meth:`write` are collected and sent (one chunk per entity,
        ``send_columns``) and flushed to the file once this much wall time [s] has passed since
        the last send; :meth:`flush` and :meth:`close` send what is left. Default
        :data:`FLUSH_INTERVAL_S`; 0 sends and flushes every batch at once.

    Notes
    -----
    Whatever has been sent is on disk: the file is readable up to the last send even if the
    process is killed (without the footer/manifest then, which :meth:`close` writes). Use as a
    context manager or call :meth:`close`.
    """

    def __init__(self, scene: Scene, path, columns, *, duration: float | None = None,
                 flush_interval_s: float = FLUSH_INTERVAL_S):
        rr = _rr()
        self.rr = rr
        self.scene = scene
        self.path = Path(path)
        self.columns = list(columns)
        base = base_columns(scene.appendage_names)
        if self.columns[: len(base)] != base:
            raise ValueError(f"rows must start with columns {base}, got {self.columns[: len(base)]}")
        self.series, self.extra = _telemetry_series(self.columns, scene.appendage_names, _mode_counts(scene))
        self._j = {c: j for j, c in enumerate(self.columns)}
        self._jq = np.array([self._j[c] for c in ("qw", "qx", "qy", "qz")])
        self._series_idx = [
            (s.entity, np.array([self._j[c] for c in s.columns]), s.norm) for s in self.series
        ]
        self.geom = _Geometry(scene)
        self.cmg = _CmgDrawing.of(scene, self.columns, self.geom)
        self.elastic = _ElasticLines.of(scene, self.columns)
        self.flush_interval_s = float(flush_interval_s)
        self._H_scale = None  # [m per N m s], fixed at the first row with H != 0
        self._pending: list[np.ndarray] = []
        self.n_rows = 0  # rows sent to the file
        self.t_last = None  # time of the last row sent [s]
        self._closed = False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(APPLICATION_ID)
        self.rec.save(self.path)
        self.rec.send_recording_name(scene.name)
        self.rec.send_property("scene", rr.AnyValues(name=scene.name, description=scene.description))
        self.rec.send_blueprint(run_blueprint(scene, self.columns[len(base) :], duration), make_active=True, make_default=True)
        self._log_static()
        self.rec.flush(timeout_sec=0.0)  # start writing the static parts, do not wait
        self._t_sent = time.monotonic()

    # -- context manager
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _log_static(self) -> None:
        rr, rec, g, scene = self.rr, self.rec, self.geom, self.scene
        L = g.extent
        rec.log(
            "world/station/body",
            rr.Boxes3D(
                centers=[g.body_center],
                half_sizes=[g.body_half],
                quaternions=[_xyzw(g.body_C)],
                colors=[RGB_BODY],
                fill_mode="solid",
            ),
            static=True,
        )
        if g.truss is not None:
            boxes = [(g.truss[0], g.truss[1], np.eye(3))] + ([g.mast] if g.mast is not None else [])
            rec.log(
                "world/station/truss",
                rr.Boxes3D(
                    centers=[b[0] for b in boxes],
                    half_sizes=[b[1] for b in boxes],
                    quaternions=[_xyzw(b[2]) for b in boxes],
                    colors=[RGB_TRUSS],
                    fill_mode="solid",
                ),
                static=True,
            )
        rec.log(
            "world/station/axes_B",
            rr.Arrows3D(
                vectors=AXES_B_FRACTION * L * np.eye(3),
                colors=[RGB_X, RGB_Y, RGB_Z],
                labels=["x_B", "y_B", "z_B"],
            ),
            static=True,
        )
        for name, _, half, C_PA in g.arrays:
            rec.log(
                f"world/station/{name}",
                rr.Boxes3D(
                    half_sizes=[half],
                    quaternions=[_xyzw(C_PA)],
                    colors=[RGB_ARRAY],
                    fill_mode="solid",
                    labels=[name],
                ),
                static=True,
            )
        if self.elastic is not None:
            for name, *_ in self.elastic.arrays:
                rec.log(f"world/station/{name}/elastic_line",
                        rr.LineStrips3D.from_fields(colors=[RGB_ELASTIC], radii=0.003 * L), static=True)
        if scene.orbit is not None:
            rec.log(
                "world/lvlh/axes",
                rr.Arrows3D(
                    vectors=AXES_O_FRACTION * L * np.eye(3),
                    colors=[RGB_X, RGB_Y, RGB_Z],
                    labels=["x_O (velocity)", "y_O (-orbit normal)", "z_O (nadir)"],
                    radii=0.004 * L,
                ),
                static=True,
            )
            rec.log(
                "world/lvlh/earth",
                rr.Arrows3D(vectors=[[0.0, 0.0, EARTH_ARROW_FRACTION * L]], colors=[RGB_EARTH], labels=["Earth"]),
                static=True,
            )
            o = scene.orbit
            u = np.linspace(0.0, 2.0 * math.pi, 181)
            rec.log(
                "world/orbit/track",
                rr.LineStrips3D([ORBIT_RING_FRACTION * L * _unit_R_N(u, o.inclination)], colors=[RGB_ORBIT]),
                static=True,
            )
            rec.log("world/orbit/station", rr.Points3D.from_fields(colors=[RGB_ORBIT], radii=0.02 * L), static=True)
        if scene.sun is not None:
            rec.log(
                "world/sun",
                rr.Arrows3D(vectors=[SUN_ARROW_FRACTION * L * _sun_vector_N(scene)], colors=[RGB_SUN], labels=["sun"],
                            radii=0.006 * L),
                static=True,
            )
        rec.log("world/H_O_N", rr.Arrows3D.from_fields(colors=[RGB_H], labels=["H_O_N"]), static=True)
        cmg = self.cmg
        if cmg is not None:
            if cmg.n_units:
                rec.log(
                    "world/station/cmg/units",
                    rr.Arrows3D.from_fields(
                        origins=cmg.origins,
                        colors=[RGB_CMG_UNITS[i % len(RGB_CMG_UNITS)] for i in range(cmg.n_units)],
                        labels=[f"CMG {i + 1}" for i in range(cmg.n_units)],
                    ),
                    static=True,
                )
            rec.log(
                "world/station/cmg/h_B",
                rr.Arrows3D.from_fields(origins=[cmg.center], colors=[RGB_CMG_TOTAL], labels=["h (CMG total)"]),
                static=True,
            )
        # series names (static, once)
        names = {s.entity: list(s.names) for s in self.series}
        if scene.orbit is not None:
            names["telemetry/euler_lvlh_deg"] = ["roll", "pitch", "yaw"]
        for path, n in names.items():
            rec.log(path, rr.SeriesLines(names=n), static=True)

    # -- streaming
    def write(self, rows: np.ndarray) -> None:
        """Take a batch of rows (shape (k, len(columns))); send it once ``flush_interval_s`` has
        passed since the last send."""
        if self._closed:
            raise ValueError("RrdSink is closed")
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        if rows.shape[0] == 0:
            return
        self._pending.append(rows)
        if self.flush_interval_s <= 0.0:
            self.flush()
        elif time.monotonic() - self._t_sent >= self.flush_interval_s:
            self._send_pending()
            self.rec.flush(timeout_sec=0.0)  # the SDK's writer thread puts it on disk meanwhile

    def flush(self) -> None:
        """Send the rows collected so far and wait until they are in the file."""
        self._send_pending()
        self.rec.flush()

    def _send_pending(self) -> None:
        if self._pending:
            rows = self._pending[0] if len(self._pending) == 1 else np.vstack(self._pending)
            self._pending = []
            self._send(rows)
        self._t_sent = time.monotonic()

    def _send(self, rows: np.ndarray) -> None:
        rr, rec, g, scene = self.rr, self.rec, self.geom, self.scene
        j = self._j
        t = rows[:, j["t"]]
        k = rows.shape[0]
        index = [rr.TimeColumn(TIMELINE, duration=t)]

        def send(path, columns):
            rec.send_columns(path, indexes=index, columns=columns)

        def scalars(path, values):
            send(path, rr.Scalars.columns(scalars=values))

        # 3-D scene
        send("world/station", rr.Transform3D.columns(quaternion=rows[:, self._jq[[1, 2, 3, 0]]]))
        for name, r, _, _ in g.arrays:
            q = _xyzw_C_BP(rows[:, j[f"alpha_{name}"]], rows[:, j[f"beta_{name}"]])
            send(f"world/station/{name}", rr.Transform3D.columns(translation=np.tile(r, (k, 1)), quaternion=q))
        el = self.elastic
        if el is not None:
            if el.fix_scale(rows):
                for name, *_ in el.arrays:
                    rec.log(f"world/station/{name}/elastic_line",
                            rr.LineStrips3D.from_fields(labels=[f"{name} deflection x{el.scale:.3g}"]), static=True)
            for name, pts in el.strips(rows):
                n_beams = pts.shape[0] // k
                send(f"world/station/{name}/elastic_line", rr.LineStrips3D.columns(strips=pts).partition([n_beams] * k))
        H = rows[:, [j["HNx"], j["HNy"], j["HNz"]]]
        if self._H_scale is None:
            H_norm = np.linalg.norm(H, axis=1)
            if np.any(H_norm > 0):
                self._H_scale = H_ARROW_FRACTION * g.extent / float(H_norm[np.argmax(H_norm > 0)])
        send("world/H_O_N", rr.Arrows3D.columns(vectors=H * (self._H_scale or 0.0)))
        if scene.orbit is not None:
            o = scene.orbit
            u = o.u0 + o.mean_motion * t
            send("world/lvlh", rr.Transform3D.columns(quaternion=_xyzw_C_NO(u, o.inclination)))
            R_hat_N = _unit_R_N(u, o.inclination)
            send("world/orbit/station", rr.Points3D.columns(positions=ORBIT_RING_FRACTION * g.extent * R_hat_N))
            scalars("telemetry/euler_lvlh_deg", np.degrees(_euler_321_lvlh(rows[:, self._jq], u, o.inclination)))
        cmg = self.cmg
        if cmg is not None:
            h = rows[:, cmg.j_h]
            s = cmg.scale(h)
            if cmg.n_units:
                units = cmg.unit_momenta(rows).reshape(-1, 3) * s
                send("world/station/cmg/units", rr.Arrows3D.columns(vectors=units).partition([cmg.n_units] * k))
            send("world/station/cmg/h_B", rr.Arrows3D.columns(vectors=h * s))
        # time series
        for entity, idx, norm in self._series_idx:
            v = rows[:, idx]
            if norm:
                v = np.column_stack([v, np.linalg.norm(v, axis=1)])
            scalars(entity, v)
        self.n_rows += k
        self.t_last = float(t[-1])

    def close(self) -> None:
        """Send what is left, write the file's footer and release it (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._send_pending()
        finally:
            self.rec.disconnect()  # flushes everything, writes the footer, closes the file


def _sun_vector_N(scene: Scene) -> np.ndarray:
    """Unit sun direction of ``scene``'s ``[sun]`` table, N components (as the model sees it)."""
    incl = scene.orbit.inclination if scene.orbit is not None else 0.0
    return sun_direction_N(scene.sun, incl)


def _unit_R_N(u, inclination) -> np.ndarray:
    """Unit orbit position ``R_N / radius``, shape (n, 3), at arguments of latitude ``u``."""
    u = np.asarray(u, dtype=float)
    ci, si = math.cos(inclination), math.sin(inclination)
    return np.column_stack([np.cos(u), np.sin(u) * ci, np.sin(u) * si])


def _O_axes_N(u, inclination) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LVLH axes ``x_O, y_O, z_O`` in N, each (n, 3): the rows of ``environment.C_ON``."""
    u = np.asarray(u, dtype=float)
    cu, su = np.cos(u), np.sin(u)
    ci, si = math.cos(inclination), math.sin(inclination)
    x_O = np.column_stack([-su, cu * ci, cu * si])  # along velocity
    y_O = np.broadcast_to(np.array([0.0, si, -ci]), x_O.shape)  # minus the orbit normal
    z_O = np.column_stack([-cu, -su * ci, -su * si])  # nadir
    return x_O, y_O, z_O


#: ``C_NO`` at u = 0, i = 0 maps x_O -> y_N, y_O -> -z_N, z_O -> -x_N; its quaternion (w, x, y, z).
_Q_O0 = np.array([0.5, -0.5, -0.5, 0.5])


def _xyzw_C_NO(u, inclination) -> np.ndarray:
    """Quaternions ``(x, y, z, w)`` of ``C_NO = R_x(i) R_z(u) C_NO(0, 0)`` (active rotations).

    The orbit position is ``R_x(i) R_z(u) e_x``, so LVLH is the u = 0, i = 0 triad turned by
    ``R_z(u)`` then ``R_x(i)``: ``q = q_x(i) ⊗ q_z(u) ⊗ q_O0`` (checked against ``C_ON``).
    """
    u = np.asarray(u, dtype=float)
    c1, s1 = math.cos(0.5 * inclination), math.sin(0.5 * inclination)
    c2, s2 = np.cos(0.5 * u), np.sin(0.5 * u)
    # q_x(i) ⊗ q_z(u) = (c1 c2, s1 c2, -s1 s2, c1 s2)
    w1, x1, y1, z1 = c1 * c2, s1 * c2, -s1 * s2, c1 * s2
    w2, x2, y2, z2 = _Q_O0
    return np.column_stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ]
    )


def _euler_321_lvlh(q_BN, u, inclination) -> np.ndarray:
    """``(roll, pitch, yaw)`` [rad], (n, 3), of ``C_BO = C_BN C_ON.T`` (``rotation.euler_321``).

    ``C_BO[i, j] = b_i · o_j`` with ``b_i`` the rows of ``C_BN = dcm(q_BN)`` and ``o_j`` the
    LVLH axes in N; only the five elements the angles need are formed.
    """
    C_BN = dcm(np.asarray(q_BN, dtype=float).T)  # (3, 3, n); C_BN[i].T is B axis i in N, (n, 3)
    x_O, y_O, z_O = _O_axes_N(u, inclination)
    c00, c01, c02 = (np.einsum("ni,ni->n", C_BN[0].T, o) for o in (x_O, y_O, z_O))
    c12 = np.einsum("ni,ni->n", C_BN[1].T, z_O)
    c22 = np.einsum("ni,ni->n", C_BN[2].T, z_O)
    roll = np.arctan2(c12, c22)
    pitch = -np.arcsin(np.clip(c02, -1.0, 1.0))
    yaw = np.arctan2(c01, c00)
    return np.column_stack([roll, pitch, yaw])


def _xyzw_C_BP(alpha, beta) -> np.ndarray:
    """Quaternions ``(x, y, z, w)`` of ``C_BP = Ap(alpha, beta).T = Ay(alpha).T Ax(beta).T``.

    ``Ay(a).T`` is the active rotation by ``a`` about y, ``Ax(b).T`` by ``b`` about x, so the
    quaternion is ``q_y(alpha) ⊗ q_x(beta)`` (Hamilton product, checked against ``Ap`` in the
    tests).
    """
    ca_, sa = np.cos(0.5 * alpha), np.sin(0.5 * alpha)
    cb, sb = np.cos(0.5 * beta), np.sin(0.5 * beta)
    return np.column_stack([ca_ * sb, sa * cb, -sa * sb, ca_ * cb])


# -- blueprints -------------------------------------------------------------------------------
def run_blueprint(scene: Scene, extra=(), duration: float | None = None):
    """3-D station view beside stacked time-series panels.

    ``extra`` are the row columns beyond the base ones: the CMG, controller and sun-tracking
    panels appear (in a second column of plots) when their columns are there, the modal
    coordinates, rates and strain energy of flexible arrays in a column of their own.
    """
    import rerun.blueprint as rrb

    g = _Geometry(scene)
    L = g.extent
    if scene.orbit is not None:  # camera: behind along-track, above the orbit plane and zenith, zenith up
        o = scene.orbit
        x_O, y_O, z_O = (a[0] for a in _O_axes_N([o.u0], o.inclination))
        eye = rrb.EyeControls3D(position=L * (2.0 * x_O - 1.4 * y_O - 1.4 * z_O), look_target=[0, 0, 0], eye_up=-z_O)
    else:
        eye = rrb.EyeControls3D(position=L * np.array([2.0, -2.0, 1.4]), look_target=[0, 0, 0], eye_up=[0, 0, 1])
    duration = scene.simulation.duration if duration is None else duration
    whole_run = rrb.TimeAxis(
        view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=0.0), end=rrb.TimeRangeBoundary.absolute(seconds=duration)
        )
    )
    base = base_columns(scene.appendage_names)
    counts = _mode_counts(scene)
    series, unknown = _telemetry_series(base + [c for c in extra if c not in base], scene.appendage_names, counts)
    have = {s.entity for s in series}

    def plot(name, origin, contents=None):
        if contents is None:
            return rrb.TimeSeriesView(name=name, origin=origin, axis_x=whole_run)
        return rrb.TimeSeriesView(name=name, origin=origin, contents=[f"/{c}" for c in contents], axis_x=whole_run)

    state = [plot("omega_BN_B [rad/s]", "telemetry/omega_BN_B")]
    if scene.orbit is not None:
        state.append(plot("attitude vs LVLH, 3-2-1 [deg]", "telemetry/euler_lvlh_deg"))
    state.append(plot("H_O_N [N m s]", "telemetry/H_O_N"))
    state.append(plot("T [J]", "telemetry/T"))
    if scene.appendage:  # the angles only, not the tracking errors below them
        state.append(plot("array angles [rad]", "telemetry/arrays", [f"telemetry/arrays/{n}" for n in scene.appendage_names]))
    if unknown:
        state.append(plot("extra", "telemetry/extra"))

    control = []
    for name, origin in (
        ("attitude error [deg]", "telemetry/control/att_err_deg"),
        ("torque command tau_cmd_B [N m]", "telemetry/control/tau_cmd_B"),
        ("CMG momentum h_B [N m s]", "telemetry/cmg/h_B"),
        ("gimbal angles [rad]", "telemetry/cmg/gimbal/angle"),
        ("gimbal rates [rad/s]", "telemetry/cmg/gimbal/rate"),
    ):
        if origin in have:
            control.append(plot(name, origin))
    flags = [e for e in ("telemetry/cmg/singularity", "telemetry/cmg/saturated") if e in have]
    if flags:
        control.append(plot("CMG singularity measure, saturated (0/1)", "telemetry/cmg", flags))
    track = [f"telemetry/arrays/{n}/track_err_deg" for n in scene.appendage_names]
    track = [e for e in track if e in have]
    if track:
        control.append(plot("array sun-tracking error [deg]", "telemetry/arrays", track))

    elastic = []
    for name, what in (("modal coordinates eta (beam modes: tip deflection [m])", "eta"), ("modal rates etadot", "etadot")):
        ents = [f"telemetry/modes/{n}/{what}" for n in counts if f"telemetry/modes/{n}/{what}" in have]
        if ents:
            elastic.append(plot(name, "telemetry/modes", ents))
    if "telemetry/modes/U_strain" in have:
        elastic.append(plot("strain energy U_strain [J]", "telemetry/modes/U_strain"))

    view3d = rrb.Spatial3DView(name=f"{scene.name} (N axes, CM at origin)", origin="world", eye_controls=eye)
    columns = [rrb.Vertical(*c) for c in (state, control, elastic) if c]
    if len(columns) > 1:
        layout = rrb.Horizontal(view3d, *columns, column_shares=[2] + [1] * len(columns))
    else:
        layout = rrb.Horizontal(view3d, *columns, column_shares=[3, 2])
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, playback_speed=max(1.0, duration / 60.0), play_state="paused"),
    )


def check_blueprint(names, pairs):
    """Formulations' rates overlaid, beside their pairwise differences."""
    import rerun.blueprint as rrb

    diff = [f"check/diff/{a}_vs_{b}" for a, b in pairs]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(name="omega_BN_B [rad/s], all formulations", origin="check",
                                   contents=[f"check/{n}/omega_BN_B" for n in names]),
                rrb.TimeSeriesView(name="q_BN, all formulations", origin="check",
                                   contents=[f"check/{n}/q_BN" for n in names]),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="attitude difference [rad]", origin="check",
                                   contents=[f"{d}/attitude_rad" for d in diff] + ["check/tolerance/attitude_rad"]),
                rrb.TimeSeriesView(name="|omega difference| [rad/s]", origin="check",
                                   contents=[f"{d}/rate" for d in diff] + ["check/tolerance/rate"]),
                rrb.TimeSeriesView(name="|H_O_N difference| [N m s]", origin="check",
                                   contents=[f"{d}/H" for d in diff] + ["check/tolerance/H"]),
            ),
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE),
    )


# -- one-shot writers -------------------------------------------------------------------------
def write_recording(traj: Trajectory, scene: Scene, path) -> Path:
    """Write a whole (or partial) trajectory of ``scene`` as a recording at ``path``."""
    duration = float(traj.t[-1]) if len(traj) else None
    with RrdSink(scene, path, traj.columns, duration=duration) as sink:
        sink.write(traj.data)
    return Path(path)


def write_check_recording(res, scene: Scene, path) -> Path:
    """All formulations of a :class:`~stationbed.check.CheckResult` in one recording.

    ``check/<formulation>/{omega_BN_B, q_BN}`` per formulation, the pairwise differences
    ``check/diff/<a>_vs_<b>/{attitude_rad, rate, H}`` per time (principal angle [rad],
    ``|Δω|`` [rad/s], ``|ΔH_O_N|`` [N m s]) and the check's tolerances ``check/tolerance/...``.
    """
    rr = _rr()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(res.trajectories)
    pairs = list(itertools.combinations(names, 2))
    rec = rr.RecordingStream(APPLICATION_ID)
    rec.save(path)
    try:
        rec.send_recording_name(f"{scene.name} check")
        rec.send_blueprint(check_blueprint(names, pairs), make_active=True, make_default=True)

        def send(entity, t, values, series):
            rec.log(entity, rr.SeriesLines(names=series), static=True)
            rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=rr.Scalars.columns(scalars=values))

        for n, tr in res.trajectories.items():
            send(f"check/{n}/omega_BN_B", tr.t, tr.omega_BN_B, [f"{n} x", f"{n} y", f"{n} z"])
            send(f"check/{n}/q_BN", tr.t, tr.q_BN, [f"{n} w", f"{n} x", f"{n} y", f"{n} z"])
        for a, b in pairs:
            ta, tb = res.trajectories[a], res.trajectories[b]
            d = f"check/diff/{a}_vs_{b}"
            send(f"{d}/attitude_rad", ta.t, rotation_angle(ta.q_BN, tb.q_BN), [f"{a} vs {b}"])
            send(f"{d}/rate", ta.t, np.linalg.norm(ta.omega_BN_B - tb.omega_BN_B, axis=1), [f"{a} vs {b}"])
            send(f"{d}/H", ta.t, np.linalg.norm(ta.H_O_N - tb.H_O_N, axis=1), [f"{a} vs {b}"])
        t_end = np.array([res.trajectories[names[0]].t[0], res.trajectories[names[0]].t[-1]])
        for what, tol in (("attitude_rad", res.tol_att_rad), ("rate", res.tol_rate), ("H", res.tol_H)):
            send(f"check/tolerance/{what}", t_end, np.full(2, tol), ["tolerance"])
        rec.flush()
    finally:
        rec.disconnect()
    return path
