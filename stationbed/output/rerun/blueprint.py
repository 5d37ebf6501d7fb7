"""Blueprints (the viewer's layout), stored in the recording's file as a blueprint store.

A run (issue 24): the 3-D view above the events log (when the rows have a flag it watches), beside one tab per question (attitude;
momentum & CMGs; environment torques; arrays; estimation; thrusters; elastic modes), the most important
panel of each tab large and the others below it, each panel only when its series are logged and
each tab only when it has a panel; the viewer opens on the attitude tab. A check: the formulations' rates and attitudes
overlaid, beside their pairwise differences and the check's tolerances.
"""

from __future__ import annotations

import numpy as np

from ...model.orbit import orbit_numeric
from ...run.trajectory import base_columns
from .events import event_columns
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

    def present(pairs):
        return [plot(name, origin, contents) for name, origin, contents in pairs
                if (contents is None and origin in have) or (contents is not None and contents)]

    def some(ents):
        return [e for e in ents if e in have]

    orbit = scene.orbit is not None
    names = scene.appendage_names
    attitude = present((("attitude error [deg]", "telemetry/control/att_err_deg", None),
                        ("attitude vs LVLH, 3-2-1 [deg]", EULER_LVLH, [EULER_LVLH] if orbit else []),
                        ("omega_BN_B [rad/s]", "telemetry/omega_BN_B", None),
                        ("attitude error per axis (rotation vector, B) [deg]", "telemetry/control/att_err_axes_deg", None)))
    momentum = present((("CMG momentum h_B [N m s]", "telemetry/cmg/h_B", None),
                        ("H_O_N [N m s]", "telemetry/H_O_N", None),
                        ("torque command tau_cmd_B [N m]", "telemetry/control/tau_cmd_B", None),
                        ("gimbal angles [rad]", "telemetry/cmg/gimbal/angle", None),
                        ("gimbal rates [rad/s]", "telemetry/cmg/gimbal/rate", None),
                        ("CMG singularity measure, saturated (0/1)", "telemetry/cmg",
                         some(("telemetry/cmg/singularity", "telemetry/cmg/saturated"))),
                        ("T [J]", "telemetry/T", None)))
    environment = present((("environment torques tau_gg_B, tau_aero_B, tau_srp_B [N m]", "telemetry/environment",
                            some(("telemetry/environment/tau_gg_B", "telemetry/environment/tau_aero_B",
                                  "telemetry/environment/tau_srp_B"))),
                           ("lit fraction of the sun (eclipse)", "telemetry/environment/eclipse", None)))
    arrays = present((("array angles [rad]", "telemetry/arrays",
                       some(f"telemetry/arrays/{n}" for n in names)),
                      ("array sun-tracking error [deg]", "telemetry/arrays",
                       some(f"telemetry/arrays/{n}/track_err_deg" for n in names))))
    estimation = _estimation(plot, have)
    thrusters = present((("thruster firings (total)", "telemetry/thrusters/firings", None),
                         ("propellant [kg] (total)", "telemetry/thrusters/propellant_kg", None),
                         ("momentum dump, thruster-only control (0/1)", "telemetry/thrusters/state", None),
                         ("on-time per thruster [s] (total)", "telemetry/thrusters/on_s", None)))
    elastic = present(tuple((name, "telemetry/modes", some(f"telemetry/modes/{n}/{what}" for n in counts))
                            for name, what in (("modal coordinates eta (beam modes: tip deflection [m])", "eta"),
                                               ("modal rates etadot", "etadot")))
                      + (("strain energy U_strain [J]", "telemetry/modes/U_strain", None),))
    other = [plot("extra", "telemetry/extra")] if unknown and not estimation else []

    view3d = rrb.Spatial3DView(name=f"{scene.name} (N axes, CM at origin)", origin="world", eye_controls=eye)
    events = rrb.TextLogView(name="events (saturation, eclipse, star-tracker dropouts, modes)", origin="events")
    tabs = [(name, views) for name, views in (("attitude", attitude), ("momentum & CMGs", momentum),
                                              ("environment torques", environment), ("arrays", arrays),
                                              ("estimation", estimation), ("thrusters", thrusters),
                                              ("elastic modes", elastic), ("other", other))
            if views]
    left = rrb.Vertical(view3d, events, row_shares=[4, 1]) if event_columns(list(extra)) else view3d
    layout = rrb.Horizontal(left,
                            rrb.Tabs(*(_group(rrb, name, views) for name, views in tabs), active_tab=0),
                            column_shares=[1, 1])
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, playback_speed=max(1.0, duration / 60.0), play_state="paused"),
    )


#: the panels under a tab's first (large) panel: in one row up to this many, else a grid of
#: SMALL_GRID_COLUMNS columns; the large panel gets LARGE_SHARE of the tab's height over one
#: row, half over two, so no panel is shorter than a quarter of the viewer's height (issue 19:
#: 17 stacked panels were ~60 px each)
SMALL_IN_ROW = 2
SMALL_GRID_COLUMNS = 3
LARGE_SHARE = 0.6


def _group(rrb, name, views):
    """One tab: its most important panel (the first) large, the others below it."""
    if len(views) == 1:
        return rrb.Vertical(views[0], name=name)
    big, small = views[0], views[1:]
    if len(small) <= SMALL_IN_ROW:
        return rrb.Vertical(big, rrb.Horizontal(*small), row_shares=[LARGE_SHARE, 1 - LARGE_SHARE], name=name)
    return rrb.Vertical(big, rrb.Grid(*small, grid_columns=min(SMALL_GRID_COLUMNS, len(small) - len(small) // 2)),
                        row_shares=[0.5, 0.5], name=name)


def _estimation(plot, have):
    """The estimation tab (issue 20's columns, when a run has them): the estimation error against
    its 3 sigma large, NEES, bias and the star-tracker heads' valid flags below; each from
    ``telemetry/estimation/`` or, where a series has no entity of its own, ``telemetry/extra/``."""
    est = sorted(e for e in have if e.startswith("telemetry/estimation/"))
    extra = sorted(e for e in have if e.startswith("telemetry/extra/"))
    err = [e for e in est if "/err_" in e] + [e for e in extra if "/est_err_" in e or "/est_3sigma_" in e]
    views = [plot("estimation error vs 3 sigma [deg]", "telemetry", err)] if err else []
    for e in est:
        if e not in err:
            views.append(plot(e.rsplit("/", 1)[1], e))
    if "telemetry/extra/nees" in have:
        views.append(plot("NEES", "telemetry/extra/nees"))
    heads = [e for e in extra if "/st_valid_" in e]
    if heads:
        views.append(plot("star trackers valid (0/1)", "telemetry/extra", heads))
    return views


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
