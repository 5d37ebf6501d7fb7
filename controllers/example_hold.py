"""``example_hold``: the "write your own controller" example of the README.

A plain PD that holds LVLH (or an inertial attitude), written for reading rather than speed:
numpy and the library's rotation helpers, no tricks. Copy this file, rename the class, change
``_update``, and name it in a scene as

* ``name = "my_hold.py:MyHold"``: a file, relative to the scene file's folder (a path such as
  ``"laws/my_hold.py:MyHold"`` works too; no ``PYTHONPATH`` needed);
* ``name = "my_module:MyHold"``: an importable module (installed, or on ``PYTHONPATH``);
* or register it as an entry point of the group ``stationbed.controllers`` (see pyproject.toml).

The file's top-level code runs when a scene naming it is run: keep it to imports and
definitions. ``_update`` returns a tuple, list or (3,) numpy array of finite floats; anything
else (a (3, 1) array, strings, None, NaN) stops the run with an error naming the controller and
the time, as an exception raised in ``_update`` does (``STATIONBED_DEBUG=1`` shows its traceback).

    τ = -J (kp e + kd (ω - ω_ref))        e = 2 sign(q_e,w) q_e,vec ≈ attitude error angle [rad]

with ``q_e = conj(q_ref) ⊗ q_BN``. Compare controllers/pd.py: the same law in Wie's eigenaxis
form with a slew-rate limit, written on floats for speed, with a casadi form for the fused loop.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from stationbed import Controller, ControllerParams, dcm, quat_conj, quat_mult  # the public names, as in the README


class ExampleHoldParams(ControllerParams):
    """Every parameter with its unit; unknown keys in [controller.params] are errors."""

    reference: Literal["lvlh", "inertial"] = "lvlh"
    kp: float = Field(default=4.0e-5, gt=0.0)  # 1/s², proportional gain (ω_n² of each axis)
    kd: float = Field(default=1.2e-2, gt=0.0)  # 1/s, derivative gain (2 ζ ω_n)


class ExampleHold(Controller):
    name = "example_hold"
    command = "torque"  # a body-torque request [N m]; the CMG steering law delivers it
    Params = ExampleHoldParams

    def _reset(self, plant):
        # design from the plant's facts (called once per run)
        if self.params.reference == "lvlh" and plant.mean_motion is None:
            raise ValueError("example_hold: reference = 'lvlh' needs an [orbit]")
        self.J = np.array(plant.inertia_O_B)
        self.w_RN_R = np.zeros(3)  # the inertial reference is at rest in N

    def _update(self, t, meas):
        # the reference attitude R relative to N: LVLH now, or N itself
        q_RN = meas.q_ON.copy() if self.params.reference == "lvlh" else np.array([1.0, 0.0, 0.0, 0.0])
        self.q_ref_BN = q_RN  # the run logs att_err_deg against this
        q_e = quat_mult(quat_conj(q_RN), meas.q_BN)  # B relative to R
        e = 2.0 * np.sign(q_e[0] or 1.0) * q_e[1:]
        w_RN_R = meas.omega_ON_O if self.params.reference == "lvlh" else self.w_RN_R  # LVLH's rate, measured
        w_ref_B = dcm(q_e) @ w_RN_R  # the reference's rate, in B
        p = self.params
        tau = -self.J @ (p.kp * e + p.kd * (meas.omega_BN_B - w_ref_B))
        return tau  # a (3,) array; a tuple or list of 3 floats does as well

    def update_batch(self, t, meas):
        # Optional: the same law for many samples at once (the Monte Carlo runs its samples in
        # lockstep and calls this once per tick; without it, the default calls _update per
        # sample). Every field of meas has a leading sample axis: meas.q_BN is (n, 4); per-sample
        # numbers are arrays: self.J is (n, 3, 3), self.params_batch.kp is (n,). The rotation
        # helpers take component-first arrays ((4, n): q[0] is the n scalar parts), so the same
        # formulas run on every sample; stacked matmul does each sample's 3x3 product as `@` does.
        n = meas.n_samples
        lvlh = self.params.reference == "lvlh"
        q_RN = meas.q_ON.copy() if lvlh else np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.q_ref_BN = q_RN
        q_e = quat_mult(quat_conj(q_RN.T), meas.q_BN.T)  # (4, n)
        s = np.sign(q_e[0])
        s[s == 0.0] = 1.0  # (`q_e[0] or 1.0` of _update)
        e = (2.0 * s * q_e[1:]).T  # (n, 3)
        w_RN_R = meas.omega_ON_O if lvlh else self.w_RN_R
        C = dcm(q_e).transpose(2, 0, 1)  # (n, 3, 3)
        w_ref_B = np.matmul(C, w_RN_R[:, :, None])[:, :, 0]
        p = self.params_batch
        v = p.kp[:, None] * e + p.kd[:, None] * (meas.omega_BN_B - w_ref_B)
        return np.matmul(-self.J, v[:, :, None])[:, :, 0]  # (n, 3)

