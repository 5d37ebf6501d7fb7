"""Events on the time line and the sensors' drawing (issue 24).

:class:`Events` turns the rows' flags into ``events`` text-log entries at the time they change
(rerun ``TextLog``: the viewer's time panel shows each as a marker, the log view lists them):

* ``cmg_saturated``, named for what it was (:func:`~stationbed.analysis.signals.cmg_limit_kinds`:
  the flag is set for either): "CMG momentum saturation begins" (WARN) / "ends" where the working
  units' |h| reached the saturation threshold (``saturation_fraction`` of their capacity at the
  row: :class:`~stationbed.run.working_h.WorkingH`, a unit a fault holds out of both), else
  "CMG gimbal-rate limit begins" (WARN) / "ends" (an ideal cluster: "CMG torque limit");
* ``eclipse`` (lit fraction of the sun) leaving 1: "eclipse entry", back to 1: "eclipse exit";
* ``st_valid_<head>``: "star tracker <head> first valid sample" (INFO), then 1 -> 0 "star tracker
  <head> dropout" (WARN), 0 -> 1 "<head> valid again"; the rows before the head's first valid
  sample read 0 (no sample yet) and are not a dropout (:func:`~stationbed.loop.flight.st_dropouts`);
* a ``mode`` or ``*_mode`` column: "<column> -> <value>" whenever its value changes (``thr_mode``:
  1 = thruster-only control, issue 21);
* ``thr_dumping`` 0 -> 1 "thruster momentum dump begins", 1 -> 0 "ends" (issue 21);
* ``fdir_cmg_fault`` 0 -> 1 "flight software declares a CMG fault" (WARN, issue 34; the unit and
  time in the ``fdir_cmg_unit``, ``fdir_t_cmg_s`` columns); ``fdir_mode`` changes as any mode.
* ``faults_active`` changing: "faults active: <n>" (WARN when it grows; issue 34).

Rows come in batches (a streamed run): the last value of every flag is kept between batches, and a
run that starts saturated or in shadow logs that at its first row.

:class:`SensorParts` is optional and reads only what is there (``getattr``): a scene with
``[[sensor]]`` star trackers gets each head's boresight and the cone of its sun exclusion, drawn
green while the head is valid, red while it has dropped out and grey before its first valid
sample (``st_valid_<head>``); rows with the
estimation error ``est_err_{x,y,z}_deg`` get the estimated attitude as a ghost triad beside the
true body axes, its error magnified :data:`GHOST_MAGNIFY` times (the errors are arc-seconds).
"""

from __future__ import annotations

import math

import numpy as np

from ...analysis.signals import CMG_MOMENTUM_SATURATED, CMG_RATE_LIMIT, cmg_limit_kinds, cmg_limit_name
from ...core.rotation import dcm
from ...loop.flight import st_dropouts
from .sdk import TIMELINE, import_rerun

__all__ = ["Events", "SensorParts", "event_columns", "GHOST_MAGNIFY", "ECLIPSE_LIT_TOL"]

#: lit fraction above 1 - this is "in the sun" (the eclipse column is exactly 1 when lit; the
#: tolerance only keeps float round-off of the conical model from making spurious entries)
ECLIPSE_LIT_TOL = 1e-9
#: the ghost's rotation from the body axes is the estimation error times this (an error of
#: 1e-3 deg shows as 1 deg)
GHOST_MAGNIFY = 1000.0
#: points on the rim of an exclusion cone
CONE_POINTS = 33
RGB_VALID, RGB_BLIND, RGB_GHOST = (60, 200, 90), (230, 40, 40), (200, 200, 255)
#: a head before its first valid sample (it has measured nothing yet: not blinded)
RGB_NO_SAMPLE = (150, 150, 150)


def event_columns(columns) -> list[str]:
    """The columns :class:`Events` watches, in column order."""
    return [c for c in columns if c in ("cmg_saturated", "eclipse", "thr_dumping", "faults_active", "fdir_cmg_fault")
            or c.startswith("st_valid_") or c == "mode" or c.endswith("_mode")]


def _state(col: str, v: float):
    """The discrete state of a flag's value (None: not a number)."""
    if not math.isfinite(v):
        return None
    if col == "eclipse":
        return v >= 1.0 - ECLIPSE_LIT_TOL  # lit
    if col in ("cmg_saturated", "thr_dumping", "fdir_cmg_fault") or col.startswith("st_valid_"):
        return v >= 0.5
    return v


def _text(col: str, state, first: bool, prev=None):
    """(level, text) of a flag entering ``state`` from ``prev`` (None: nothing to say)."""
    if col == "eclipse":
        return (None if first else ("INFO", "eclipse exit")) if state else ("INFO", "eclipse entry")
    if col == "thr_dumping":
        return ("INFO", "thruster momentum dump begins") if state else (None if first else ("INFO", "thruster momentum dump ends"))
    if col == "fdir_cmg_fault":
        return ("WARN", "flight software declares a CMG fault") if state else None
    if col == "faults_active":  # scheduled faults (issue 34): the count at each change
        return None if first and state == 0 else ("WARN" if state > (prev or 0) else "INFO", f"faults active: {state:g}")
    if col.startswith("st_valid_"):  # state: "none" (no valid sample yet), "valid", "dropout"
        head = col.removeprefix("st_valid_")
        return {"none": None, "dropout": ("WARN", f"star tracker {head} dropout"),
                "valid": None if first else ("INFO", f"star tracker {head} "
                                                     + ("first valid sample" if prev == "none" else "valid again"))}[state]
    return None if first else ("INFO", f"{col} -> {state:g}")


def _limit_text(prev: str | None, state: str, first: bool) -> list:
    """The entries of the CMG limit flag going from ``prev`` to ``state`` ("" no limit, else its
    name): the old one ends, the new one begins."""
    out = []
    if prev and not first:
        out.append(("INFO", f"{prev} ends"))
    if state:
        out.append(("WARN", f"{state} begins"))
    return out


class Events:
    """Text-log entries at the rows' flag changes, entity ``events``.

    Parameters
    ----------
    columns : list of str
        The rows' columns.
    cmg : (gimballed, saturation_fraction or None, WorkingH), optional
        The cluster's facts that name its limit flag (:meth:`of` reads them from the scene):
        the flag is momentum saturation where the working units' |h| over their capacity at the
        row (:meth:`WorkingH.fraction <stationbed.run.working_h.WorkingH.fraction>`) reaches
        ``saturation_fraction``; without them every flag is a rate limit.

    Attributes
    ----------
    watched : list of str
        :func:`event_columns` of ``columns``.
    log : list of tuple
        ``(t, level, text)`` of every entry sent so far.
    """

    ENTITY = "events"

    def __init__(self, columns, cmg=None):
        self.watched = event_columns(columns)
        self._last = {}
        self.log = []
        self._seen = {}  # a head's valid sample came in an earlier batch
        self._h_last = math.nan  # the working units' |h| / capacity of the previous batch's last row
        self._cmg = cmg

    @classmethod
    def of(cls, scene, columns) -> Events:
        """The events of a scene's rows: the cluster's saturation threshold and working units
        (failed and stuck units' held momentum, the capacity's steps) name its limit flag."""
        cfg = getattr(scene, "cmg", None)
        if cfg is None:
            return cls(columns)
        from ...model.cmg import capacity, cmg_geometry
        from ...run.working_h import WorkingH

        cap = capacity(cfg)
        return cls(columns, cmg=(cmg_geometry(cfg).gimballed, cfg.saturation_fraction if math.isfinite(cap) else None,
                                 WorkingH.of_scene(scene, columns, cap)))

    def _states(self, col: str, rows) -> list:
        """The state of ``col`` at each row (None: not a number)."""
        v = rows[col]
        if col == "cmg_saturated":  # named for what it was: momentum saturation or the rate limit
            gimballed, h_sat, working = self._cmg or (True, None, None)
            h = None if working is None else working.fraction(rows.data)
            if h is None:
                h = np.full(len(v), math.nan)
            kinds = cmg_limit_kinds(np.nan_to_num(v), h, h_sat, h_before=self._h_last)
            if len(h):
                self._h_last = float(h[-1])
            names = {CMG_MOMENTUM_SATURATED: "CMG momentum saturation", CMG_RATE_LIMIT: f"CMG {cmg_limit_name(gimballed)}"}
            return [None if not math.isfinite(x) else names.get(int(k), "") for x, k in zip(v, kinds)]
        if col.startswith("st_valid_"):
            drop, self._seen[col] = st_dropouts(np.nan_to_num(v), self._seen.get(col, False))
            return [None if not math.isfinite(x) else ("valid" if x >= 0.5 else "dropout" if d else "none")
                    for x, d in zip(v, drop)]
        return [_state(col, float(x)) for x in v]

    def changes(self, rows) -> list[tuple[float, str, str]]:
        """The entries of ``rows`` (a Trajectory), in time order; updates the kept states."""
        out = []
        t = rows.t
        for col in self.watched:
            for i, s in enumerate(self._states(col, rows)):
                if s is None:
                    continue
                first = col not in self._last
                prev = self._last.get(col)
                if first or s != prev:
                    said = _limit_text(prev, s, first) if col == "cmg_saturated" else [_text(col, s, first, prev)]
                    out += [(float(t[i]), *e) for e in said if e is not None]
                    self._last[col] = s
        out.sort(key=lambda e: e[0])
        return out

    def send(self, rec, rows) -> list[tuple[float, str, str]]:
        """Log the entries of ``rows`` on ``sim_time``; returns them."""
        rr = import_rerun()
        out = self.changes(rows)
        for t, level, text in out:
            rec.set_time(TIMELINE, duration=t)
            rec.log(self.ENTITY, rr.TextLog(text, level=level))
        if out:
            rec.reset_time()
        self.log += out
        return out


def _rotvec_xyzw(phi) -> np.ndarray:
    """Quaternions (x, y, z, w) of rotation vectors ``phi`` (k, 3) [rad]."""
    phi = np.atleast_2d(phi)
    ang = np.linalg.norm(phi, axis=1)
    half = 0.5 * ang
    k = np.where(ang > 0, np.sin(half) / np.where(ang > 0, ang, 1.0), 0.5)
    return np.column_stack([phi * k[:, None], np.cos(half)])


def _cone(axis, half_angle, length) -> list[np.ndarray]:
    """Line strips of a cone of ``half_angle`` about unit ``axis`` from the origin: its rim and
    four generators."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, ref)
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    th = np.linspace(0.0, 2.0 * math.pi, CONE_POINTS)
    rim = length * (math.cos(half_angle) * a + math.sin(half_angle) * (np.outer(np.cos(th), u) + np.outer(np.sin(th), v)))
    return [rim] + [np.array([np.zeros(3), rim[j]]) for j in range(0, CONE_POINTS - 1, (CONE_POINTS - 1) // 4)]


class SensorParts:
    """Star-tracker heads and the estimated attitude, when the scene and rows have them.

    Use :meth:`of`: None when there is nothing to draw.

    Parameters
    ----------
    heads : list of tuple
        ``(name, boresight_B, sun_exclusion or None)``.
    columns : list of str
    L : float
        The station's extent [m] (drawing scale).
    """

    def __init__(self, heads, columns, L):
        self.heads = heads
        self.L = L
        self.ghost = all(f"est_err_{a}_deg" in columns for a in "xyz")
        self.valid_cols = {n: f"st_valid_{n}" for n, _, _ in heads if f"st_valid_{n}" in columns}
        self._valid = {}
        self._seen = {}  # a head's valid sample came in an earlier batch

    @classmethod
    def of(cls, scene, columns, L) -> SensorParts | None:
        heads = []
        for s in getattr(scene, "sensor", None) or []:
            if getattr(s, "kind", None) != "star_tracker":
                continue
            C_SB = np.asarray(dcm(s.mounting()), float)
            heads.append((s.name, C_SB.T @ np.array([0.0, 0.0, 1.0]), getattr(s, "sun_exclusion", None)))
        parts = cls(heads, list(columns), L)
        return parts if heads or parts.ghost else None

    def log_static(self, rec) -> None:
        rr = import_rerun()
        for name, b, excl in self.heads:
            ent = f"world/station/sensors/{name}"
            # colours static only when no valid flag changes them (static data would shadow the changes)
            color = {} if name in self.valid_cols else {"colors": [RGB_VALID]}
            rec.log(f"{ent}/boresight", rr.Arrows3D(vectors=[0.9 * self.L * b], labels=[name], radii=0.004 * self.L,
                                                    show_labels=False, **color), static=True)
            if excl is not None:
                rec.log(f"{ent}/exclusion", rr.LineStrips3D(_cone(b, excl, 0.6 * self.L), radii=0.002 * self.L,
                                                            **color), static=True)
        if self.ghost:
            rec.log("world/station/estimate/axes",
                    rr.Arrows3D(vectors=0.45 * self.L * np.eye(3), colors=[RGB_GHOST] * 3,
                                labels=[f"{a} estimated (error x{GHOST_MAGNIFY:g})" for a in ("x_B", "y_B", "z_B")],
                                show_labels=False, radii=0.003 * self.L), static=True)

    def send(self, rec, send, rows) -> None:
        rr = import_rerun()
        if self.ghost:  # q = q_hat ⊗ δq(δα): the estimate is the body turned by -δα (B axes)
            err = np.radians(np.column_stack([rows[f"est_err_{a}_deg"] for a in "xyz"]))
            send("world/station/estimate", rr.Transform3D.columns(quaternion=_rotvec_xyzw(-GHOST_MAGNIFY * err)))
        for name, col in self.valid_cols.items():
            v = rows[col]
            drop, self._seen[name] = st_dropouts(np.nan_to_num(v), self._seen.get(name, False))
            for i in range(len(v)):
                state = RGB_VALID if v[i] >= 0.5 else RGB_BLIND if drop[i] else RGB_NO_SAMPLE
                if self._valid.get(name) != state:
                    self._valid[name] = state
                    color = state
                    rec.set_time(TIMELINE, duration=float(rows.t[i]))
                    ent = f"world/station/sensors/{name}"
                    rec.log(f"{ent}/boresight", rr.Arrows3D.from_fields(colors=[color]))
                    if any(h[0] == name and h[2] is not None for h in self.heads):
                        rec.log(f"{ent}/exclusion", rr.LineStrips3D.from_fields(colors=[color]))
                    rec.reset_time()

