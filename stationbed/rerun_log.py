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
  its components as named series: one ``send_columns`` call per quantity per batch);
* a blueprint (3-D view beside stacked plots), stored in the same file as a blueprint store.

:class:`RrdSink` streams: it writes each batch of rows the moment :func:`stationbed.simulate`
hands it over and flushes, so a run that dies part-way leaves a readable recording. The static
parts (geometry, axes, series names, blueprint) are sent once when the sink opens.

Rotations go to rerun as quaternions ``(x, y, z, w)`` of the matrix that maps the child
entity's components into its parent's (DESIGN §3): ``C_NB`` for the station, ``C_BP`` for an
array, ``C_NO`` for LVLH. Rerun stores them as float32 (~6e-8 resolution); scalars as float64.

A fixed inertial sun vector is not part of the core scene yet, so none is drawn.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .massprops import composite_cm
from .rotation import dcm, rotation_angle
from .scene import Scene
from .trajectory import Trajectory, base_columns

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

RGB_X, RGB_Y, RGB_Z = (230, 60, 60), (60, 190, 60), (70, 110, 240)
RGB_BODY, RGB_TRUSS, RGB_ARRAY = (170, 170, 180), (120, 120, 130), (40, 70, 170)
RGB_EARTH, RGB_H, RGB_ORBIT = (40, 150, 220), (250, 170, 20), (120, 160, 200)


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
    """Rerun quaternion(s) ``(x, y, z, w)`` of rotation matrix(es) ``C`` (child -> parent)."""
    return Rotation.from_matrix(C).as_quat()


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
        :func:`~stationbed.trajectory.base_columns` of the scene. Columns beyond those are logged
        under ``telemetry/extra/<column>``.
    duration : float, optional
        Run length [s], for the blueprint only: the plots' time axis and the playback speed
        (default: the scene's ``simulation.duration``).

    Notes
    -----
    Every :meth:`write` sends one chunk per entity (``send_columns``) and flushes the stream to
    the file, so the file is readable up to the last batch even if the process is killed
    (without the footer/manifest then, which :meth:`close` writes). Use as a context manager or
    call :meth:`close`.
    """

    def __init__(self, scene: Scene, path, columns, *, duration: float | None = None):
        rr = _rr()
        self.rr = rr
        self.scene = scene
        self.path = Path(path)
        self.columns = list(columns)
        base = base_columns(scene.appendage_names)
        if self.columns[: len(base)] != base:
            raise ValueError(f"rows must start with columns {base}, got {self.columns[: len(base)]}")
        self.extra = self.columns[len(base) :]
        self._j = {c: j for j, c in enumerate(self.columns)}
        self._jq = np.array([self._j[c] for c in ("qw", "qx", "qy", "qz")])
        self.geom = _Geometry(scene)
        self._H_scale = None  # [m per N m s], fixed at the first row with H != 0
        self.n_rows = 0
        self.t_last = None
        self._closed = False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(APPLICATION_ID)
        self.rec.save(self.path)
        self.rec.send_recording_name(scene.name)
        self.rec.send_property("scene", rr.AnyValues(name=scene.name, description=scene.description))
        self.rec.send_blueprint(run_blueprint(scene, self.extra, duration), make_active=True, make_default=True)
        self._log_static()
        self.rec.flush()

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
        rec.log("world/H_O_N", rr.Arrows3D.from_fields(colors=[RGB_H], labels=["H_O_N"]), static=True)
        # series names (static, once)
        names = {
            "telemetry/omega_BN_B": ["x", "y", "z"],
            "telemetry/H_O_N": ["x", "y", "z", "|H|"],
            "telemetry/T": ["T"],
        }
        if scene.orbit is not None:
            names["telemetry/euler_lvlh_deg"] = ["roll", "pitch", "yaw"]
        for name in scene.appendage_names:
            names[f"telemetry/arrays/{name}"] = [f"{name} alpha", f"{name} beta"]
        for c in self.extra:
            names[f"telemetry/extra/{c}"] = [c]
        for path, n in names.items():
            rec.log(path, rr.SeriesLines(names=n), static=True)

    # -- streaming
    def write(self, rows: np.ndarray) -> None:
        """Log a batch of rows (shape (k, len(columns))) and flush it to the file."""
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        if rows.shape[0] == 0:
            return
        if self._closed:
            raise ValueError("RrdSink is closed")
        rr, rec, g, scene = self.rr, self.rec, self.geom, self.scene
        col = lambda c: rows[:, self._j[c]]  # noqa: E731
        t = col("t")
        k = rows.shape[0]

        def send(path, columns):
            rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=columns)

        def scalars(path, values):
            send(path, rr.Scalars.columns(scalars=values))

        # 3-D scene
        send("world/station", rr.Transform3D.columns(quaternion=rows[:, self._jq[[1, 2, 3, 0]]]))
        for name, r, _, _ in g.arrays:
            q = _xyzw_C_BP(col(f"alpha_{name}"), col(f"beta_{name}"))
            send(f"world/station/{name}", rr.Transform3D.columns(translation=np.tile(r, (k, 1)), quaternion=q))
        H = rows[:, [self._j["HNx"], self._j["HNy"], self._j["HNz"]]]
        H_norm = np.linalg.norm(H, axis=1)
        if self._H_scale is None and np.any(H_norm > 0):
            self._H_scale = H_ARROW_FRACTION * g.extent / float(H_norm[np.argmax(H_norm > 0)])
        send("world/H_O_N", rr.Arrows3D.columns(vectors=H * (self._H_scale or 0.0)))
        if scene.orbit is not None:
            o = scene.orbit
            u = o.u0 + o.mean_motion * t
            send("world/lvlh", rr.Transform3D.columns(quaternion=_xyzw_C_NO(u, o.inclination)))
            R_hat_N = _unit_R_N(u, o.inclination)
            send("world/orbit/station", rr.Points3D.columns(positions=ORBIT_RING_FRACTION * g.extent * R_hat_N))
            scalars("telemetry/euler_lvlh_deg", np.degrees(_euler_321_lvlh(rows[:, self._jq], u, o.inclination)))
        # time series
        scalars("telemetry/omega_BN_B", rows[:, [self._j["wx"], self._j["wy"], self._j["wz"]]])
        scalars("telemetry/H_O_N", np.column_stack([H, H_norm]))
        scalars("telemetry/T", col("T"))
        for name in scene.appendage_names:
            scalars(f"telemetry/arrays/{name}", rows[:, [self._j[f"alpha_{name}"], self._j[f"beta_{name}"]]])
        for c in self.extra:
            scalars(f"telemetry/extra/{c}", col(c))
        rec.flush()
        self.n_rows += k
        self.t_last = float(t[-1])

    def close(self) -> None:
        """Flush, write the file's footer and release it (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.rec.flush()
        self.rec.disconnect()


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
    """3-D station view beside stacked time-series panels."""
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

    def plot(name, origin):
        return rrb.TimeSeriesView(name=name, origin=origin, axis_x=whole_run)

    plots = [plot("omega_BN_B [rad/s]", "telemetry/omega_BN_B")]
    if scene.orbit is not None:
        plots.append(plot("attitude vs LVLH, 3-2-1 [deg]", "telemetry/euler_lvlh_deg"))
    plots.append(plot("H_O_N [N m s]", "telemetry/H_O_N"))
    plots.append(plot("T [J]", "telemetry/T"))
    if scene.appendage:
        plots.append(plot("array angles [rad]", "telemetry/arrays"))
    if extra:
        plots.append(plot("extra", "telemetry/extra"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name=f"{scene.name} (N axes, CM at origin)", origin="world", eye_controls=eye),
            rrb.Vertical(*plots),
            column_shares=[3, 2],
        ),
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
