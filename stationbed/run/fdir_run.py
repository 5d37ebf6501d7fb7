"""Flight software's fault detection in a run (issue 34): the ``[fdir]`` block's memory as the
rows' ``fdir_*`` columns, the detections in the summary, each compared with the truth's fault
schedule there (never inside the loop: the block knows nothing of the truth).

:class:`FdirLoop` is what the composition holds (``comp.fdir``); the block itself is
:func:`stationbed.loop.fdir.fdir_block`, composed as the chain's last actuator (run/blocks.py).
A run with ``[fdir]`` flies fused (the block has no per-tick form): one that cannot is refused.
"""

from __future__ import annotations

import numpy as np

from ..loop.fdir import MODE_NUMBERS, FdirSpec, false_alarms_per_hour, fdir_block
from ..loop.sensor_faults import NEVER_S, SENSOR_FAULTS
from ..loop.suite import Suite
from ..model.cmg import held_momentum_B
from .faults import register_fault_effect

__all__ = ["FdirLoop", "fdir_for", "fdir_columns", "FDIR_COLUMNS", "detections_vs_truth"]

#: the rows' columns: the mode of the tick before t, the CMG residual's chi-squared, whether a
#: CMG fault has been declared, when [s] (-1: not yet) and the unit blamed (0: none)
FDIR_COLUMNS = ["fdir_mode", "fdir_cmg_nis", "fdir_cmg_fault", "fdir_t_cmg_s", "fdir_cmg_unit"]
_FIELDS = ["fdir_mode", "nis", "cmg_fault", "t_cmg", "cmg_unit"]
#: the kinds of the truth's schedule a CMG detection answers (scene [[fault]] kinds, issue 34)
CMG_KINDS = ("cmg_failed", "gimbal_stuck", "gimbal_rate_limit", "wheel_speed_drop")


def _sensor_effect(f, comp):
    """A sensor fault changes no number of the plant or of a block at its tick: its times are
    numbers of the sensor's step (loop/sensor_faults.py, written by the flight at the start);
    its step marks the time in the run's list of faults applied."""
    return {}, {}, False


for _kind in SENSOR_FAULTS:
    register_fault_effect(_kind)(_sensor_effect)


def fdir_columns(scene) -> list[str]:
    """The CSV columns of the fault detection (none without ``[fdir]``)."""
    return list(FDIR_COLUMNS) if getattr(scene, "fdir", None) is not None else []


def fdir_for(scene, model, plant) -> "FdirLoop | None":
    """The run's fault detection (None without ``[fdir]``)."""
    if getattr(scene, "fdir", None) is None:
        return None
    geo = model.cmg.geometry
    # the torque one gimbal at its rate limit gives: above it the limiter may cut the request
    tau_max = geo.rotor_momentum(scene.cmg) * geo.max_gimbal_rate(scene.cmg)
    tau_max = tau_max if np.isfinite(tau_max) and tau_max > 0 else NEVER_S
    # the flight's suite (the same layout as run/closed_loop.py's Flight builds): its gyro
    # detectors inhibit the CMG test (loop/fdir.py rate_suspect)
    suite = Suite(scene, scene.controller.period) if scene.sensor and getattr(scene, "estimator", None) else None
    known = plant.scene.cmg  # the working units' capacity flight software knows, some units declared out

    def capacity_of(declared):
        return geo.capacity(known.model_copy(update={"failed": sorted(set(known.failed) | set(declared))}))

    # the known cluster for the working units' momentum the assist_at climb reads (loop/working_momentum.py)
    cmg = (geo, geo.params(known), held_momentum_B(known)) if geo.gimballed else None
    return FdirLoop(scene, FdirSpec(scene.fdir, scene.mode, geo.n_units, geo.gimbals_per_unit, plant.h_capacity, tau_max,
                                    suite=suite, capacity_of=capacity_of, cmg=cmg))


class FdirLoop:
    """The fault detection of one run: its block, its memory (``x`` after the last tick,
    ``x_row`` before the current one), the rows' values and the summary."""

    def __init__(self, scene, spec: FdirSpec):
        self.scene, self.spec = scene, spec
        self.block = fdir_block(spec)
        self.name = self.block.name  #: its block's name: its memory in a composed carry
        self.x = self.block.x0.copy()
        self.x_row = self.x.copy()
        S = self.block.state
        #: where the row's values lie in the block's memory (:data:`FDIR_COLUMNS`' order), as an
        #: actuator's ``idx`` (the executors hand both back alike: ``Composition.memories``)
        self.idx = np.array([S.slice(f).start for f in _FIELDS])

    def row(self) -> list[float]:
        return np.asarray(self.x_row, dtype=float)[self.idx].tolist()

    def summary(self, comp, xs=None) -> dict:
        """The detections (time, unit, right or wrong against the truth's schedule; the sensors'
        from the suite's memory ``xs``), the stated false-alarm rate of the CMG detector, the time
        in each mode [s] and the mode changes."""
        S = self.block.state
        x = self.x
        out = {"fdir_cmg_false_alarms_per_hour_stated": false_alarms_per_hour(self.spec.alpha, self.spec.n,
                                                                            3600.0 / comp.period)}
        det = S.get(x, "cmg_fault")[0] > 0.5
        truth = detections_vs_truth(getattr(comp.scene, "fault", ()), det, float(S.get(x, "t_cmg")[0]),
                                    int(S.get(x, "cmg_unit")[0]))
        out.update(truth)
        out["fdir_cmg_excluded"] = [i + 1 for i, v in enumerate(S.get(x, "cmg_excluded")) if v > 0.5]
        # every CMG declaration (a second failure after the first is isolated: loop/fdir.py item 2), in time order
        out["fdir_cmg_declared"] = [{"unit": i + 1, "t": float(v)} for v, i in
                                    sorted((v, i) for i, v in enumerate(S.get(x, "t_unit")) if v >= 0.0)]
        out["fdir_cmg_capacity_Nms"] = float(S.get(x, "cmg_capacity")[0])  # the working units' as flight software knows
        if xs is not None and comp.flight is not None and comp.flight.mekf is not None:
            out.update(sensor_detections(comp, xs))
        out["fdir_mode_s"] = {k: float(S.get(x, "mode_s")[v]) for k, v in MODE_NUMBERS.items()}
        out["fdir_mode_changes"] = int(S.get(x, "mode_changes")[0])
        return out


def sensor_detections(comp, xs) -> dict:
    """The MEKF's innovation detections (loop/mekf.py ``innovation_gate``) from the suite's
    memory ``xs`` at the run's end: the heads excluded and the gyro declared, with their times,
    each against the truth's first sensor fault (its unit and time: right unit, latency)."""
    m, S = comp.flight.mekf, comp.flight.suite.STATE
    xf = S.get(np.asarray(xs, dtype=float), "mekf")
    L = m.state
    t = L.get(xf, "t_fdir")
    names = [h.name for h in m.heads] + [m.gyro.name]
    declared = [(float(t[i]), names[i]) for i in range(len(names)) if t[i] >= 0.0]
    if comp.flight.suite.pair is not None:  # the redundant gyros' comparison
        cnt, dec, tp, who = S.get(np.asarray(xs, dtype=float), "gyro_pair")
        if dec > 0.5:
            declared.append((float(tp), comp.flight.suite.pair[int(who) - 1].name))
    out: dict = {"fdir_sensor_declared": [{"unit": u, "t": tt} for tt, u in sorted(declared)]}
    truth = sorted((f for f in getattr(comp.scene, "fault", ()) if f.kind in SENSOR_FAULTS and f.enabled),
                   key=lambda f: f.t)
    if truth:
        out.update(fault_sensor_t_s=float(truth[0].t), fault_sensor_unit=str(truth[0].unit))
    if declared:
        tt, u = min(declared)
        before = [f for f in truth if f.t <= tt]
        out["fdir_sensor_false_alarm"] = not before
        if before:
            out["fdir_sensor_latency_s"] = tt - before[0].t
            out["fdir_sensor_unit_right"] = u == str(before[0].unit)
    return out


def detections_vs_truth(faults, detected: bool, t_det: float, unit: int) -> dict:
    """The CMG detection against the truth's schedule: the first scheduled CMG fault (``t``,
    ``unit``) and the detection (time, unit, latency, whether the unit blamed is the failed one;
    a detection with no CMG fault scheduled before it is a false alarm; a fault a Monte Carlo
    sample did not draw, ``enabled = false``, is none)."""
    cmg = sorted((f for f in faults or () if f.kind in CMG_KINDS and f.enabled), key=lambda f: f.t)
    out: dict = {"fdir_cmg_detected": bool(detected)}
    if detected:
        out.update(fdir_cmg_t_s=t_det, fdir_cmg_unit=unit)
    if cmg:
        f = cmg[0]
        out.update(fault_cmg_t_s=float(f.t), fault_cmg_unit=int(f.unit))
    before = [f for f in cmg if f.t <= t_det] if detected else []
    if detected:
        out["fdir_cmg_false_alarm"] = not before
        if before:
            out["fdir_cmg_latency_s"] = t_det - before[0].t
            out["fdir_cmg_unit_right"] = unit == int(before[0].unit)
    return out
