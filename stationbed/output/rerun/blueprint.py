"""Blueprints (the viewer's layout), stored in the recording's file as a blueprint store.

A run: the 3-D view beside one tab per group of time-series panels (motion; control; CMG;
environment and array tracking; elastic modes), each panel only when its series are logged and
each tab only when it has a panel; a closed-loop run opens on its control tab. A check: the formulations' rates and attitudes
overlaid, beside their pairwise differences and the check's tolerances.
"""

from __future__ import annotations

import numpy as np

from ...model.orbit import orbit_numeric
from ...run.trajectory import base_columns
from .geometry import StationGeometry
from .sdk import TIMELINE
from .series import EULER_LVLH, mode_counts, telemetry_series

__all__ = ["run_blueprint", "check_blueprint"]


def run_blueprint(scene, extra=(), duration: float | None = None):
    """3-D station view beside tabs of time-series panels (a tab per group, see the module docstring).

    Parameters
    ----------
    scene : stationbed.scene.Scene
    extra : sequence of str, optional
        Row columns beyond :func:`~stationbed.run.trajectory.base_columns`: the control, CMG and
        environment tabs appear when their columns are there, the modal coordinates, rates and
        strain energy of flexible arrays in a tab of their own.
    duration : float, optional
        Run length [s]: the plots' time axis and the playback speed (default: the scene's
        ``simulation.duration``).

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    import rerun.blueprint as rrb

    L = StationGeometry(scene).extent
    if scene.orbit is not None:  # camera: behind along-track, above the orbit plane and zenith, zenith up
        x_O, y_O, z_O = orbit_numeric(scene.orbit, 0.0).C_ON  # rows: the LVLH axes in N at t = 0
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
    counts = mode_counts(scene)
    series, unknown = telemetry_series(base + [c for c in extra if c not in base], scene.appendage_names, counts)
    have = {s.entity for s in series}

    def plot(name, origin, contents=None):
        if contents is None:
            return rrb.TimeSeriesView(name=name, origin=origin, axis_x=whole_run)
        return rrb.TimeSeriesView(name=name, origin=origin, contents=[f"/{c}" for c in contents], axis_x=whole_run)

    state = [plot("omega_BN_B [rad/s]", "telemetry/omega_BN_B")]
    if scene.orbit is not None:
        state.append(plot("attitude vs LVLH, 3-2-1 [deg]", EULER_LVLH))
    state.append(plot("H_O_N [N m s]", "telemetry/H_O_N"))
    state.append(plot("T [J]", "telemetry/T"))
    if scene.appendage:  # the angles only, not the tracking errors below them
        state.append(plot("array angles [rad]", "telemetry/arrays", [f"telemetry/arrays/{n}" for n in scene.appendage_names]))
    if unknown:
        state.append(plot("extra", "telemetry/extra"))

    def present(pairs):
        return [plot(name, origin) for name, origin in pairs if origin in have]

    control = present((("attitude error [deg]", "telemetry/control/att_err_deg"),
                       ("attitude error per axis (rotation vector, B) [deg]", "telemetry/control/att_err_axes_deg"),
                       ("torque command tau_cmd_B [N m]", "telemetry/control/tau_cmd_B")))
    cmg = present((("CMG momentum h_B [N m s]", "telemetry/cmg/h_B"),
                   ("gimbal angles [rad]", "telemetry/cmg/gimbal/angle"),
                   ("gimbal rates [rad/s]", "telemetry/cmg/gimbal/rate")))
    flags = [e for e in ("telemetry/cmg/singularity", "telemetry/cmg/saturated") if e in have]
    if flags:
        cmg.append(plot("CMG singularity measure, saturated (0/1)", "telemetry/cmg", flags))
    environment = []
    env = [e for e in ("telemetry/environment/tau_aero_B", "telemetry/environment/tau_srp_B") if e in have]
    if env:
        environment.append(plot("environment torques tau_aero_B, tau_srp_B [N m]", "telemetry/environment", env))
    if "telemetry/environment/eclipse" in have:
        environment.append(plot("lit fraction of the sun (eclipse)", "telemetry/environment/eclipse"))
    track = [f"telemetry/arrays/{n}/track_err_deg" for n in scene.appendage_names]
    track = [e for e in track if e in have]
    if track:
        environment.append(plot("array sun-tracking error [deg]", "telemetry/arrays", track))

    elastic = []
    for name, what in (("modal coordinates eta (beam modes: tip deflection [m])", "eta"), ("modal rates etadot", "etadot")):
        ents = [f"telemetry/modes/{n}/{what}" for n in counts if f"telemetry/modes/{n}/{what}" in have]
        if ents:
            elastic.append(plot(name, "telemetry/modes", ents))
    if "telemetry/modes/U_strain" in have:
        elastic.append(plot("strain energy U_strain [J]", "telemetry/modes/U_strain"))

    view3d = rrb.Spatial3DView(name=f"{scene.name} (N axes, CM at origin)", origin="world", eye_controls=eye)
    tabs = [(name, views) for name, views in (("motion", state), ("control", control), ("CMG", cmg),
                                              ("environment", environment), ("elastic modes", elastic)) if views]
    names = [name for name, _ in tabs]
    active = names.index("control") if control else 0  # (rerun 0.41 matches a str active_tab to views only)
    layout = rrb.Horizontal(view3d, rrb.Tabs(*(_group(rrb, name, views) for name, views in tabs), active_tab=active),
                            column_shares=[1, 1])
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, playback_speed=max(1.0, duration / 60.0), play_state="paused"),
    )


#: panels in one tab stacked in a column; more are laid out in a grid of two columns, so no panel
#: is shorter than a quarter of the viewer's height (issue 19: 17 stacked panels were ~60 px each)
MAX_STACKED = 3


def _group(rrb, name, views):
    """One tab: its panels stacked (up to :data:`MAX_STACKED`), else in a two-column grid."""
    if len(views) <= MAX_STACKED:
        return rrb.Vertical(*views, name=name)
    return rrb.Grid(*views, grid_columns=2, name=name)


def check_blueprint(names, pairs):
    """Formulations' rates overlaid, beside their pairwise differences.

    Parameters
    ----------
    names : list of str
        The formulations (entities ``check/<name>/...``).
    pairs : list of tuple of str
        The compared pairs ``(a, b)`` (entities ``check/diff/<a>_vs_<b>/...``).

    Returns
    -------
    rerun.blueprint.Blueprint
    """
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
