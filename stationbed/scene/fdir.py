"""Scene tables of flight software's fault detection and its mode manager (issue 34 items 2-3;
the block: :mod:`stationbed.loop.fdir`).

```toml
[fdir]
cmg_sigma_Nm = 0.5          # N m, 1 sigma per axis of the CMG momentum residual under nominal flight
cmg_alpha = 1e-3            # per-tick probability that a nominal residual exceeds the gate
cmg_persistence = 20        # consecutive ticks over the gate before a CMG fault is declared
isolate = true              # the blamed unit out of the steering law (the knowledge update)
initial_mode = "hold"       # hold | assist | thruster_only | drift
on_cmg_fault = "assist"     # the mode a CMG detection moves to (at least)
assist_at = 0.6             # |h| / capacity at which hold moves to assist (momentum threshold)
st_alpha = 1e-4             # the MEKF's innovation gate: P(chi-squared(3) > gate) per head sample
st_persistence = 3          # consecutive rejected samples: the head out, or (heads together) the gyro
gyro_pair_alpha = 1e-4      # two gyros of one period compared: P(chi-squared(3) > gate) per sample
gyro_pair_persistence = 5   # consecutive samples over it
cmg_rate_settle_s = 2.0     # s: the CMG test off after the filter takes the spare gyro (and while
                            # a gyro detector flags the rate)

[[mode]]                    # a scheduled command: this mode over [t, until)
mode = "thruster_only"
t = 3000.0                  # s
until = 3600.0              # s (none: to the end)
```
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from .base import FieldError, Strict
from .thrusters import flown_thrusters as _flown

__all__ = ["Fdir", "ModeCommand", "MODES", "check_fdir"]

#: the mode manager's modes, by their number in the loop (the ``fdir_mode`` column)
MODES = {"hold": 0, "assist": 1, "thruster_only": 2, "drift": 3}
Mode = Literal["hold", "assist", "thruster_only", "drift"]


class Fdir(Strict):
    """``[fdir]``: the detectors' thresholds and the mode manager's rules (module docstring)."""

    cmg_sigma_Nm: float = Field(default=0.5, gt=0.0)
    cmg_alpha: float = Field(default=1e-3, gt=0.0, lt=1.0)
    cmg_persistence: int = Field(default=20, ge=1)
    isolate: bool = True
    initial_mode: Mode = "hold"
    on_cmg_fault: Mode = "assist"
    assist_at: float = Field(default=math.inf, gt=0.0)
    st_alpha: float | None = Field(default=None, gt=0.0, lt=1.0)  # the MEKF's innovation gate (none: off)
    st_persistence: int = Field(default=3, ge=1)  # consecutive rejected samples of a head
    gyro_pair_alpha: float | None = Field(default=None, gt=0.0, lt=1.0)  # the redundant gyros' gate (none: off)
    gyro_pair_persistence: int = Field(default=5, ge=1)  # consecutive samples over it
    cmg_rate_settle_s: float = Field(default=2.0, ge=0.0)  # s, the CMG test off after a gyro switch


class ModeCommand(Strict):
    """``[[mode]]``: a commanded mode over ``[t, until)`` (a ground command, a planned test)."""

    mode: Mode
    t: float = Field(ge=0.0)
    until: float | None = None

    @model_validator(mode="after")
    def _window(self):
        if self.until is not None and not self.until > self.t:
            raise FieldError("until", f"must be after t ({self.t:g} s), got {self.until:g}")
        return self


def check_fdir(scene) -> None:
    """``[fdir]`` and ``[[mode]]`` fit the scene: a closed loop with a CMG cluster; the thruster
    modes need ``[[thruster]]`` tables (one-line FieldError)."""
    if scene.fdir is None:
        if scene.mode:
            raise FieldError("mode", "a [[mode]] command needs an [fdir] table (the mode manager)")
        return
    if scene.controller is None or scene.cmg is None:
        raise FieldError("fdir", "fault detection runs in the closed loop of a CMG cluster: add [controller] and [cmg]")
    wanted = [("fdir.initial_mode", scene.fdir.initial_mode), ("fdir.on_cmg_fault", scene.fdir.on_cmg_fault)]
    wanted += [(f"mode[{i}].mode", m.mode) for i, m in enumerate(scene.mode)]
    for where, m in wanted:
        if m in ("assist", "thruster_only") and not _flown(scene):
            raise FieldError(where, f"mode '{m}' needs [[thruster]] tables")
