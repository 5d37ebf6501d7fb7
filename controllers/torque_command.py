"""``torque_command``: an open-loop body-torque request, constant over a time window.

Requests ``torque_B`` [N m] (B components) for ticks with ``start <= t < stop`` and zero
otherwise. With a CMG cluster the request goes through the scene's steering law (so the
cluster delivers ``-ḣ - ω × h = τ`` within its limits); without one it acts directly on the
body. It has no reference attitude (``q_ref_BN`` stays None, ``att_err_deg`` is NaN).

Uses: driving a CMG cluster along a chosen momentum path (``scenarios/sgcmg_singularity.toml``),
and tests that need a known torque history.
"""

from __future__ import annotations

import math

from pydantic import Field, model_validator

from stationbed.run.controller import Controller, ControllerParams


class TorqueCommandParams(ControllerParams):
    torque_B: list[float] = Field(min_length=3, max_length=3)  # N m, B components
    start: float = 0.0  # s, first tick that requests the torque
    stop: float | None = None  # s, first tick that no longer does (None: never stops)

    @model_validator(mode="after")
    def _window(self):
        if self.stop is not None and self.stop < self.start:
            raise ValueError(f"stop ({self.stop} s) is before start ({self.start} s)")
        return self


class TorqueCommand(Controller):
    """Constant body-torque request over ``[start, stop)``, zero otherwise (open loop)."""

    name = "torque_command"
    command = "torque"
    Params = TorqueCommandParams

    def _reset(self, plant):
        P = self.params
        self.on = tuple(float(v) for v in P.torque_B)
        self.off = (0.0, 0.0, 0.0)
        self.start = P.start
        self.stop = math.inf if P.stop is None else P.stop

    def _update(self, t, meas):
        return self.on if self.start <= t < self.stop else self.off

    def update_batch(self, t, meas):
        # per sample (n,): start, stop; on, off (n, 3) (Controller.batch_of stacked them)
        import numpy as np  # noqa: PLC0415

        active = (self.start <= t) & (t < self.stop)
        return np.where(active[:, None], self.on, self.off)

    def summary(self):
        return {"torque_command_N_m": list(self.on)}
