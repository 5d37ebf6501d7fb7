"""The thrusters in the closed loop's per-tick executor (issue 21): the actuator's tick on what
the law sees, the integration split at every pulse edge, the row values and the summary.

:class:`ThrustLoop` is what the run's composition holds (``comp.thrust``) when the scene has
``[[thruster]]`` tables; the fused loop (:mod:`.composed`, the thrusters as a block) runs the same
:class:`~stationbed.loop.thrusters.ThrusterCluster` function inlined.
"""

from __future__ import annotations

import math

import numpy as np

from ..loop.actuator import pulse_pieces
from ..loop.thrusters import ThrusterCluster
from ..model.cmg import held_momentum_B
from ..scene import knowledge_scene
from ..scene.thrusters import missing_torque
from .segments import segment_input

__all__ = ["ThrustLoop", "thruster_columns", "thrust_for", "thruster_parts"]


def thruster_columns(scene) -> list[str]:
    """The CSV columns of the thrusters, values at the row's time t: the mode of the tick before
    t (``thr_mode`` 1 = thruster-only control, ``thr_dumping`` 1 = dumping), and totals over
    [0, t]: firings, time in thruster-only control [s], impulse Σ F t_on [N s], propellant
    [kg], and each thruster's on-time [s]."""
    if not scene.thruster:
        return []
    cols = ["thr_mode", "thr_dumping", "thr_firings", "thr_control_s", "thr_impulse_Ns", "thr_propellant_kg"]
    return cols + [f"thr_on_s_{t.name}" for t in scene.thruster]


def thruster_parts(s: dict) -> list[str]:
    """The run summary line's thruster parts (``stationbed run``), none without thrusters."""
    if "propellant_kg" not in s:
        return []
    per = f" ({s['propellant_kg_per_orbit']:.4g} kg per orbit)" if "propellant_kg_per_orbit" in s else ""
    out = [f"thrusters {s['thruster_firings']} firings, impulse {s['thruster_impulse_Ns']:.4g} N s, propellant "
           f"{s['propellant_kg']:.4g} kg{per}, {s['thruster_control_s']:g} s in thruster-only control"]
    if s.get("thruster_no_torque_about"):
        out.append(f"thrusters make no torque about {s['thruster_no_torque_about']}: a dump or hand-over "
                   "there is not delivered")
    if "thrusters_not_fused" in s:
        out.append(f"thrusters flown per tick: {s['thrusters_not_fused']}")
    return out


def thrust_for(scene, ctrl, layout, plant) -> "ThrustLoop | None":
    """The run's thrusters (None without ``[[thruster]]``); ``plant`` is the law's knowledge,
    ``layout`` the measurement's (a Layout: ``measurement.measurement_fields``)."""
    if not scene.thruster:
        return None
    if ctrl.command != "torque":
        raise ValueError(f"controller '{ctrl.name}' commands gimbal rates: thrusters share a torque request "
                         "with the CMGs (use a torque-commanding law)")
    return ThrustLoop(scene, layout, plant)


class ThrustLoop:
    """The thrusters of one closed-loop run: the plug-in (``cluster``, part of the run's
    composition) and its memory (``x`` after the last tick, ``x_row`` before the current one:
    what a row reports), which every executor reads and hands back here."""

    def __init__(self, scene, layout, plant):
        cap = plant.h_capacity if plant.h_capacity is not None else math.inf
        known = knowledge_scene(scene)
        held = held_momentum_B(known.cmg)  # the failed units flight software knows of
        self.cluster = ThrusterCluster(scene, known, cap, held)
        self.lp = self.cluster.opt.mapping == "lp"
        self.x = self.cluster.x0.copy()  # the actuator's memory after the last tick
        self.x_row = self.x.copy()  # ... before the current tick (what a row reports)
        self.on_s = np.zeros(self.cluster.n)
        self.torque_B = np.zeros((3, self.cluster.n))
        # its READS (h_B) in the measurement, by name (with [fdir] it reads the mode manager's
        # memory too: flown fused only, run/fdir_run.py)
        self.reads_at = None if self.cluster.commanded else self.cluster.reads_in(layout)
        self.fused_reason = None  # why the fused loop did not take it (summary)

    def command(self, comp, t: float, y, cmd) -> np.ndarray:
        """Tick at ``t`` on what the law sees ``y``: the thrusters' on-times over ``[t, t + h]``
        and the torque left to the CMGs (returned, B [N m])."""
        h = self.tick_length(comp, t)
        r = y[self.reads_at]
        self.x_row = self.x
        c = self.cluster
        f = c.command_lp if self.lp else c.command
        self.x, rest, self.on_s, self.torque_B, _ = f(t, h, self.x, r, np.asarray(cmd, dtype=float))
        return rest

    @staticmethod
    def tick_length(comp, t: float) -> float:
        """The tick's length [s]: the period, the remainder of the run for the last one (0 at
        the end), as the fused loop's :func:`~.segments.tick_pieces` cuts them."""
        rest = comp.duration - t
        return comp.period if rest >= comp.period * (1 - 1e-12) else max(rest, 0.0)

    def advance(self, comp, res, t0: float, t1: float) -> None:
        """Integrate ``[t0, t1]`` split at the scene's breakpoints and the pulse edges; over each
        piece the thrusters on add their torque to the held external torque (``res.u``, the
        state ``res.x`` advanced in place)."""
        cuts = [(t0 + a, t0 + b, on) for a, b, on in pulse_pieces(self.on_s, t1 - t0)]
        cuts[-1] = (cuts[-1][0], t1, cuts[-1][2])
        inner = [b for b in comp.bps if t0 < b < t1]
        i_ext = comp.input_layout.slice("u_ext")
        for a, b, on in cuts:
            edges = [a] + [e for e in inner if a < e < b] + [b]
            tq = self.torque_B[:, on].sum(axis=1)
            for s0, s1 in zip(edges[:-1], edges[1:]):
                segment_input(comp.scene, comp.model, s0, s1, res.u)
                u = res.u.copy()
                u[i_ext] += tq
                res.x[:] = comp.apply_jump(s1, comp.integ.advance(s0, s1, res.x, u))

    def row_index(self) -> np.ndarray:
        """The indices of the memory's numbers a row reports (:func:`thruster_columns`' order)."""
        self.row(self.x)
        return self._row_idx

    def row(self, x=None) -> list[float]:
        """The row's values (:func:`thruster_columns`) from the actuator state ``x`` before the tick."""
        x = self.x_row if x is None else x
        idx = getattr(self, "_row_idx", None)
        if idx is None:  # the state's numbers a row reports, found once (a row per output sample)
            s = self.cluster.state
            idx = [s.slice(k).start for k in ("mode", "dumping", "firings", "control_s", "impulse_Ns", "propellant_kg")]
            self._row_idx = idx = np.array(idx + list(range(s.size))[s.slice("on_total_s")])
        return np.asarray(x, dtype=float)[idx].tolist()

    def summary(self, comp) -> dict:
        """What the summary adds to the thruster metrics (propellant_kg and the other totals are
        :data:`~.metrics.METRICS`, reduced from the rows' thr_* columns by ``RunMetrics``)."""
        out = {"thruster_mapping": self.cluster.opt.mapping, "thruster_pure_couple": bool(self.cluster.pure)}
        if comp.scene.orbit is not None:  # for trajectory_metrics' propellant_kg_per_orbit
            out["orbit_period_s"] = 2.0 * math.pi / comp.scene.orbit.mean_motion
        if self.fused_reason:
            out["thrusters_not_fused"] = self.fused_reason
        missing = missing_torque(comp.scene) if self.cluster.opt.mode != "off" else []
        if missing:  # an assist set that dumps about some axes only (the scene check refuses the rest)
            out["thruster_no_torque_about"] = ", ".join(missing)
        return out
