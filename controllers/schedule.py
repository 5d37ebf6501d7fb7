"""``schedule``: fly a planned attitude-command history (issue 26, the zero-propellant manoeuvre).

The ISS-style law the plan was optimised with (stationbed/plan/model.py; Bhatt 2007):

    τ_B = -J (kp ε + kd ω̃),   ε = 2 vec(conj(q_CN) ⊗ q_BN),   ω̃ = ω_BN_B - C_CR ω_RN_R

with the commanded attitude ``q_CR(t)`` of the plan (relative to its frame R: LVLH or N),
linear between the plan's points and normalised, ``q_CN = q_RN ⊗ q_CR``, and ``J`` the plant's
inertia (knowledge, as the plan had it). After the plan's end the last command is held. The
error's sign is taken the short way round (``ε`` from the error quaternion with a non-negative
scalar part), which is the plan's own sign whenever the body is within 180 deg of the command.

The reference it reports (``q_ref_BN``, hence ``att_err_deg`` and the run's attitude-error
metrics) is the plan's *planned* attitude ``q_BR(t)`` (plan.csv's ``q_*``, linear between the
points, normalised, held after the end), not the command: the command leads the body by design
(the law needs an error to produce the planned torque), so body vs command is not a tracking
error (issue 32). The command error is reported apart, in the run summary:
``final_cmd_err_deg`` and ``max_cmd_err_deg``, the angle of the law's own error quaternion
``conj(q_CN) ⊗ q_BN`` (on the attitude it measures) at the last and the largest tick.

Params: ``plan``: a plan.json written by ``stationbed plan`` (absolute, or relative to the scene
file's folder, as ``controller.fmu`` and a controller file are; the working folder for a scene
made in Python); without it the law plans from the scene's ``[plan]`` table
when the run starts (cached per scene in the process). The gains and frame are the plan's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from stationbed.plan import PlanError, plan_scene, read_plan
from stationbed.run.controller import Controller, ControllerError, ControllerParams

from ._quat import qmul


class ScheduleParams(ControllerParams):
    plan: str | None = None  # path of a plan.json; None: plan from the scene's [plan]


#: plans made in this process, by the scene's JSON (a scene checked by every formulation plans once)
_PLANS: dict[str, dict] = {}


def _planned(scene) -> dict:
    key = scene.model_dump_json()
    if key not in _PLANS:
        prob, sol = plan_scene(scene)
        _PLANS.clear()  # one scene at a time is what a process flies
        _PLANS[key] = {"t": sol.t, "q_CR": sol.q_CR, "q_BR_planned": sol.q_BR, "kp": prob.model.kp,
                       "kd": prob.model.kd, "frame": scene.plan.frame}
    return _PLANS[key]


class Schedule(Controller):
    name = "schedule"
    command = "torque"
    Params = ScheduleParams
    file_params = ("plan",)

    def _reset(self, plant):
        scene = plant.scene
        try:
            if self.params.plan is not None:
                path = Path(self.params.plan).expanduser()
                if not path.is_absolute() and scene.folder is not None:  # as fmu and controller files
                    path = scene.folder / path
                plan = read_plan(path)
            elif scene.plan is not None:
                plan = _planned(scene)
            else:
                raise ControllerError("controller 'schedule': give params.plan (a plan.json) or a [plan] table")
        except PlanError as e:
            raise ControllerError(f"controller 'schedule': {e}") from None
        if plan["frame"] == "lvlh" and plant.mean_motion is None:
            raise ControllerError("controller 'schedule': the plan is relative to LVLH and the scene has no [orbit]")
        self.t_plan = np.asarray(plan["t"], float)
        self.q_plan = np.asarray(plan["q_CR"], float)
        self.q_planned = np.asarray(plan["q_BR_planned"], float)  # the planned attitude q_BR
        self.cmd_err_max_rad = 0.0
        self.cmd_err_rad = math.nan  # the last tick's
        self.kp, self.kd = float(plan["kp"]), float(plan["kd"])
        self.lvlh = plan["frame"] == "lvlh"
        self.J = np.asarray(plant.inertia_O_B, float)

    def command_R(self, t):
        """``q_CR`` at ``t`` [s]: linear between the plan's points, normalised; held after the end."""
        return self._at(self.q_plan, t)

    def planned_R(self, t):
        """The planned attitude ``q_BR`` at ``t`` [s], as :meth:`command_R` interpolates the command."""
        return self._at(self.q_planned, t)

    def _at(self, qs, t):
        tp = self.t_plan
        k = int(np.clip(np.searchsorted(tp, t, side="right") - 1, 0, len(tp) - 2))
        a = min(max((t - tp[k]) / (tp[k + 1] - tp[k]), 0.0), 1.0)
        q = (1.0 - a) * qs[k] + a * qs[k + 1]
        return q / np.linalg.norm(q)

    def summary(self) -> dict:
        """The command error (body vs the command, which leads it by design) [deg]: last and largest tick."""
        if math.isnan(self.cmd_err_rad):
            return {}
        return {"final_cmd_err_deg": math.degrees(self.cmd_err_rad), "max_cmd_err_deg": math.degrees(self.cmd_err_max_rad)}

    def _update(self, t, meas):
        q_CR = self.command_R(t)
        q_BR = self.planned_R(t).tolist()
        if self.lvlh:
            q_CN = np.asarray(qmul(meas.q_ON.tolist(), q_CR.tolist()))
            w_RN_R = meas.omega_ON_O
            self.q_ref_BN = qmul(meas.q_ON.tolist(), q_BR)  # the planned attitude: the tracking reference
        else:
            q_CN, w_RN_R = q_CR, np.zeros(3)
            self.q_ref_BN = tuple(q_BR)
        cw, cx, cy, cz = q_CN
        e = np.asarray(qmul((cw, -cx, -cy, -cz), meas.q_BN.tolist()))
        if e[0] < 0.0:
            e = -e
        self.cmd_err_rad = 2.0 * math.atan2(math.sqrt(e[1] ** 2 + e[2] ** 2 + e[3] ** 2), e[0])
        self.cmd_err_max_rad = max(self.cmd_err_max_rad, self.cmd_err_rad)
        # C_CR v = v - w t + e × t, t = 2 e × v (the rotation of v into C's components)
        qv = q_CR[1:4]
        tv = 2.0 * np.cross(qv, w_RN_R)
        w_CR = w_RN_R - q_CR[0] * tv + np.cross(qv, tv)
        w_tilde = meas.omega_BN_B - w_CR
        tau = -self.J @ (self.kp * 2.0 * e[1:4] + self.kd * w_tilde)
        return tau.tolist()
