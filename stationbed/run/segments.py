"""Where a run is cut: output times, the scene's discontinuities (torque-window edges, array rate
steps), and the input held over each smooth segment."""

from __future__ import annotations

import math

import numpy as np

from ..model import StationModel
from ..scene import ConstantTorque, Scene

__all__ = ["output_times", "breakpoints", "held_torque", "segment_input"]


def output_times(duration: float, dt: float) -> np.ndarray:
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
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque):
            for b in (trq.start, trq.stop):
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
    u = np.zeros(3)
    for trq in scene.torque:
        if isinstance(trq, ConstantTorque) and trq.start <= t_mid < trq.stop:
            u += np.array(trq.torque_B)
    return u


def segment_input(scene: Scene, model: StationModel, a: float, b: float, u: np.ndarray) -> None:
    """Set the held input of the smooth segment [a, b] in place: the external torque held over it
    and, when the scene has array rate steps, the segment's time that decides their side."""
    t_mid = 0.5 * (a + b)
    u[0:3] = held_torque(scene, t_mid)
    if model.has_steps:
        u[-1] = t_mid
