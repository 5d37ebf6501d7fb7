"""Where a run is cut: output times, the scene's discontinuities (where a torque kind's held part
jumps, array rate steps), and the input held over each smooth segment."""

from __future__ import annotations

import math

import numpy as np

from ..model import StationModel
from ..model.torques import held_torque_B, torque_breakpoints
from ..scene import Scene

__all__ = ["output_times", "breakpoints", "held_torque", "segment_input"]


def output_times(duration: float, dt: float) -> np.ndarray:
    """Output times [s]: 0, every ``dt``, and ``duration`` (appended when it is not a multiple)."""
    n = int(math.floor(duration / dt + 1e-9))
    ts = np.arange(n + 1) * dt
    if duration - ts[-1] > 1e-9 * max(1.0, duration):
        ts = np.append(ts, duration)
    else:
        ts[-1] = min(ts[-1], duration)
    return ts


def breakpoints(scene: Scene, duration: float) -> tuple[list[float], set[float]]:
    """Times where the scene is discontinuous, and the subset where array rates step (impulses)."""
    bps, steps = set(), set()
    for b in torque_breakpoints(scene):
        if 0.0 < b < duration:
            bps.add(float(b))
    for a in scene.appendage:
        for j in (a.alpha, a.beta):
            if not j.tracked:
                for st in j.rate_step:
                    if st.t < duration:
                        bps.add(float(st.t))
                        steps.add(float(st.t))
    return sorted(bps), steps


def held_torque(scene: Scene, t_mid: float) -> np.ndarray:
    """The external torque held over the segment whose mid time is ``t_mid`` [s], B components
    [N m], shape (3,): every torque kind's held part (:func:`~stationbed.model.torques.held_torque_B`)."""
    return held_torque_B(scene, t_mid)


def segment_input(scene: Scene, model: StationModel, a: float, b: float, u: np.ndarray) -> None:
    """Set the held input of the smooth segment [a, b] in place: the external torque held over it
    and, when the scene has array rate steps, the segment's time that decides their side."""
    t_mid = 0.5 * (a + b)
    u[0:3] = held_torque(scene, t_mid)
    if model.has_steps:
        u[-1] = t_mid
