"""Whole recordings written at once: a run's trajectory, and a cross-formulation check."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from ...core.rotation import rotation_angle
from ...run.trajectory import Trajectory
from .blueprint import check_blueprint
from .sdk import APPLICATION_ID, TIMELINE, import_rerun, saving
from .sink import RrdSink

__all__ = ["write_recording", "write_check_recording"]


def write_recording(traj: Trajectory, scene, path) -> Path:
    """Write a whole (or partial) trajectory of ``scene`` as a recording at ``path``.

    Parameters
    ----------
    traj : Trajectory
        Rows with at least the scene's base columns (as :class:`~.sink.RrdSink` takes them).
    scene : stationbed.scene.Scene
    path : str or Path
        The ``.rrd`` file (parent folders are created).

    Returns
    -------
    Path
        ``path``. The blueprint's time axis spans the trajectory.
    """
    duration = float(traj.t[-1]) if len(traj) else None
    with RrdSink(scene, path, traj.columns, duration=duration) as sink:
        sink.write(traj.data)
    return Path(path)


def write_check_recording(res, scene, path) -> Path:
    """All formulations of a :class:`~stationbed.studies.check.CheckResult` in one recording.

    ``check/<formulation>/{omega_BN_B, q_BN}`` per formulation, the pairwise differences
    ``check/diff/<a>_vs_<b>/{attitude_rad, rate, H}`` per time (principal angle [rad],
    ``|Δω|`` [rad/s], ``|ΔH_O_N|`` [N m s]) and the check's tolerances ``check/tolerance/...``.

    Parameters
    ----------
    res : stationbed.studies.check.CheckResult
        Trajectories per formulation (same times) and the tolerances.
    scene : stationbed.scene.Scene
    path : str or Path
        The ``.rrd`` file (parent folders are created).

    Returns
    -------
    Path
    """
    rr = import_rerun()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(res.trajectories)
    pairs = list(itertools.combinations(names, 2))
    rec = rr.RecordingStream(APPLICATION_ID)
    with saving(rec, path):  # a full disk: WriteFailed naming the file, never a hang
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
    return path
