"""Telemetry: the rows' columns as time series under ``telemetry/`` (one entity per quantity).

Each entity holds its columns as named series (:class:`Series`), sent with one ``send_columns``
call per quantity per send. Base columns (DESIGN §6) and those of issue 3 (CMG, controller, sun
tracking) have entities of their own (``telemetry/cmg``, ``telemetry/control``,
``telemetry/arrays/<name>/track_err_deg``), as do the modal columns of flexible arrays (issue 6:
``telemetry/modes/<array>/{eta, etadot}``, ``telemetry/modes/U_strain``), as do the environment
torques of issue 14 (``telemetry/environment/{tau_aero_B, tau_srp_B, eclipse}``); any other column goes
under ``telemetry/extra/<column>``. With an orbit the attitude relative to LVLH is added as
``telemetry/euler_lvlh_deg`` (3-2-1 roll, pitch, yaw [deg]).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ...run.trajectory import Trajectory
from .frames import euler_321_lvlh
from .sdk import import_rerun

__all__ = ["Series", "telemetry_series", "mode_counts", "Telemetry", "EULER_LVLH"]

_GIMBAL_COLUMN = re.compile(r"gimbal_\d+(_outer|_inner)?")
#: Entity of the attitude relative to LVLH (orbiting scenes only).
EULER_LVLH = "telemetry/euler_lvlh_deg"


@dataclass(frozen=True)
class Series:
    """One telemetry entity: ``columns`` of the rows as named series (plus their norm).

    Attributes
    ----------
    entity : str
        Entity path, ``telemetry/...``.
    columns : tuple of str
        Row columns, in series order.
    names : tuple of str
        Series names shown in the plot legend (one more than ``columns`` when ``norm``).
    norm : bool
        Append the Euclidean norm of the columns as the last series.
    """

    entity: str
    columns: tuple[str, ...]
    names: tuple[str, ...]
    norm: bool = False


def mode_counts(scene) -> dict[str, int]:
    """Number of elastic modes per array (issue 6), for the arrays that have any.

    Parameters
    ----------
    scene : stationbed.scene.Scene

    Returns
    -------
    dict of str to int
        Array name -> number of its ``[[appendage.mode]]`` tables.
    """
    return {a.name: len(a.mode) for a in scene.appendage if a.mode}


def telemetry_series(columns, appendage_names, modes=None) -> tuple[list[Series], list[str]]:
    """The telemetry entities of rows with ``columns``, and the columns left for ``extra/``.

    Base columns (DESIGN §6) and those of issue 3 (CMG, controller, sun tracking) get their own
    entity; a group is taken only when all its columns are present. ``modes`` maps an array's
    name to its number of elastic modes (issue 6): its ``eta_<array>_<k>`` and
    ``etadot_<array>_<k>`` are one entity each under ``telemetry/modes/<array>/``, ``U_strain``
    is ``telemetry/modes/U_strain``.

    Parameters
    ----------
    columns : list of str
        Column names of the rows.
    appendage_names : list of str
        The scene's arrays.
    modes : dict of str to int, optional
        :func:`mode_counts` of the scene.

    Returns
    -------
    series : list of Series
        Every entity, ``telemetry/extra/<column>`` ones last.
    extra : list of str
        The columns no named entity took (each is one ``telemetry/extra`` entity).
    """
    present, used = set(columns), set()
    out: list[Series] = []

    def take(entity, cols, names=None, norm=False):
        cols = tuple(cols)
        if cols and all(c in present and c not in used for c in cols):
            out.append(Series(entity, cols, tuple(names or cols), norm))
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
    take("telemetry/control/att_err_axes_deg", ["att_err_x_deg", "att_err_y_deg", "att_err_z_deg"], ["x", "y", "z"])
    for n in appendage_names:
        take(f"telemetry/arrays/{n}/track_err_deg", [f"track_err_deg_{n}"], [n])
    modes = {n: m for n, m in (modes or {}).items() if m}
    for n, m in modes.items():
        ks = range(1, m + 1)
        take(f"telemetry/modes/{n}/eta", [f"eta_{n}_{k}" for k in ks], [f"{n} eta_{k}" for k in ks])
        take(f"telemetry/modes/{n}/etadot", [f"etadot_{n}_{k}" for k in ks], [f"{n} etadot_{k}" for k in ks])
    if modes:
        take("telemetry/modes/U_strain", ["U_strain"])
    for kind in ("gg", "aero", "srp"):  # environment torques (issue 14; gravity gradient), B components [N m]
        take(f"telemetry/environment/tau_{kind}_B", [f"tau_{kind}_{c}" for c in "xyz"], ["x", "y", "z"])
    take("telemetry/environment/eclipse", ["eclipse"], ["lit fraction"])
    # sensors and estimator (issue 20): error and its 3 sigma side by side per axis, bias, NEES, heads
    for a in "xyz":
        take(f"telemetry/estimation/err_{a}_deg", [f"est_err_{a}_deg", f"est_3sigma_{a}_deg"],
             [f"{a} error", f"{a} 3 sigma"])
    take("telemetry/estimation/bias_B", ["est_bias_x", "est_bias_y", "est_bias_z"], ["x", "y", "z"])
    take("telemetry/estimation/nees", ["nees"])
    heads = [c for c in columns if c.startswith("st_valid_")]
    take("telemetry/estimation/st_valid", heads, [c.removeprefix("st_valid_") for c in heads])
    # thrusters (issue 21): totals since t = 0, the dump and thruster-only flags, each one's on-time
    take("telemetry/thrusters/firings", ["thr_firings"], ["firings"])
    take("telemetry/thrusters/propellant_kg", ["thr_propellant_kg"], ["propellant [kg]"])
    take("telemetry/thrusters/impulse_Ns", ["thr_impulse_Ns"], ["impulse [N s]"])
    take("telemetry/thrusters/control_s", ["thr_control_s"], ["thruster-only control [s]"])
    take("telemetry/thrusters/state", ["thr_dumping", "thr_mode"], ["dumping (0/1)", "thruster-only control (0/1)"])
    on = [c for c in columns if c.startswith("thr_on_s_")]
    take("telemetry/thrusters/on_s", on, [c.removeprefix("thr_on_s_") for c in on])
    # fault detection and modes (issue 34): the mode manager's mode, the CMG residual's chi-squared
    take("telemetry/fdir/mode", ["fdir_mode"], ["mode (0 hold, 1 assist, 2 thruster_only, 3 drift)"])
    take("telemetry/fdir/cmg_nis", ["fdir_cmg_nis"], ["CMG residual chi-squared"])
    take("telemetry/fdir/cmg", ["fdir_cmg_fault", "fdir_cmg_unit", "fdir_t_cmg_s"], ["declared (0/1)", "unit", "at [s]"])
    extra = [c for c in columns if c not in used]
    for c in extra:
        out.append(Series(f"telemetry/extra/{c}", (c,), (c,)))
    return out, extra


class Telemetry:
    """The time series of a run's rows: their names once (static), their values per batch.

    Parameters
    ----------
    scene : stationbed.scene.Scene
    columns : list of str
        Column names of the rows.

    Attributes
    ----------
    series : list of Series
        The entities of :func:`telemetry_series`.
    extra : list of str
        The columns logged under ``telemetry/extra``.
    """

    def __init__(self, scene, columns):
        self.orbit = scene.orbit
        self.series, self.extra = telemetry_series(list(columns), scene.appendage_names, mode_counts(scene))

    def log_static(self, rec) -> None:
        """Log every entity's series names (static).

        Parameters
        ----------
        rec : rerun.RecordingStream
        """
        rr = import_rerun()
        names = {s.entity: list(s.names) for s in self.series}
        if self.orbit is not None:
            names[EULER_LVLH] = ["roll", "pitch", "yaw"]
        for path, n in names.items():
            rec.log(path, rr.SeriesLines(names=n), static=True)

    def send(self, send, rows: Trajectory) -> None:
        """Send every series of ``rows``.

        Parameters
        ----------
        send : callable
            ``send(entity, columns)``: one ``send_columns`` call on the times of ``rows``.
        rows : Trajectory
            k rows with the columns of :attr:`series` (and ``t``, ``q_BN`` with an orbit).
        """
        rr = import_rerun()

        def scalars(path, values):
            send(path, rr.Scalars.columns(scalars=values))

        if self.orbit is not None:
            scalars(EULER_LVLH, np.degrees(euler_321_lvlh(rows.q_BN, self.orbit, rows.t)))
        for s in self.series:
            v = rows.cols(*s.columns)
            if s.norm:
                v = np.column_stack([v, np.linalg.norm(v, axis=1)])
            scalars(s.entity, v)
