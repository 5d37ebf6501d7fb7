"""The shipped ``pd`` law behind an FMU's variables (packed into the test FMUs; issue 23).

The FMU scripts (``pd_fmi2.py``, ``pd_fmi3.py``) register these variables with pythonfmu and
call :meth:`PdCore.step` from ``do_step``: the FMU runs the very law of
``stationbed.controllers.pd`` (the FMU's Python is the process's, so ``stationbed`` imports),
on the values the loop wrote through FMI. Flying it must give the Python law's trajectory.

Test hooks (parameters): ``fail_at`` [s] makes ``do_step`` fail from that time on, ``nan_at`` [s]
makes ``tau_cmd[1]`` NaN, ``terminate_at`` [s] makes an FMI 3 step ask to terminate the
simulation, ``raise_at`` [s] makes ``do_step`` raise (a Python exception inside the FMU), ``step_wall_s`` [s] makes each
step sleep that long (a signal then lands inside the FMU's own Python); negative = never. The FMU keeps its own clock and fails a step that
does not start where the last one ended (as the FMI reference FMUs do), so a co-simulation
master that loses the chain (or a reset that does not restart it at 0) is caught.
"""

import math
import time
from types import SimpleNamespace

import numpy as np

#: (name, size) of the inputs, outputs and Real parameters (arrays as name[0..n-1])
INPUTS = (("q_BN", 4), ("omega_BN_B", 3), ("q_ON", 4), ("omega_ON_O", 3))
OUTPUTS = (("tau_cmd", 3), ("q_ref_BN", 4), ("n_steps", 1))
REAL_PARAMS = (("bandwidth", 1, 0.01), ("damping", 1, 0.9), ("max_slew_rate", 1, 0.005),
               ("q_ref", 4, None), ("inertia_O_B", 9, None), ("mean_motion", 1, 0.0),
               ("fail_at", 1, -1.0), ("nan_at", 1, -1.0), ("terminate_at", 1, -1.0),
               ("raise_at", 1, -1.0), ("step_wall_s", 1, -1.0))
BOOL_PARAMS = (("lvlh", True), ("gyro_compensation", True))
#: the FMU's clock check [s]: ticks are k * period, computed without accumulation by the loop
CLOCK_TOL_S = 1e-9


class PdCore:
    def __init__(self):
        self.v = {}
        for name, n in INPUTS + OUTPUTS:
            self.v[name] = [0.0] * n
        for name, n, start in REAL_PARAMS:
            if n == 1:
                self.v[name] = start
            else:
                self.v[name] = [1.0, 0.0, 0.0, 0.0] if name == "q_ref" else [0.0] * n
        for name, start in BOOL_PARAMS:
            self.v[name] = start
        self.law = None
        self.clock = 0.0
        self.message = ""

    def variables(self):
        """(name, kind, getter, setter) of every scalar: kind in input/output/real/bool."""
        out = []
        for group, kind in ((INPUTS, "input"), (OUTPUTS, "output")):
            for name, n in group:
                for i in range(n):
                    if name == "n_steps":
                        out.append((name, kind, lambda: float(self.v["n_steps"][0]), None))
                    else:
                        out.append((f"{name}[{i}]", kind, self._get(name, i), self._set(name, i)))
        for name, n, start in REAL_PARAMS:
            if n == 1:
                out.append((name, "real", self._get(name), self._set(name)))
            else:
                for i in range(n):
                    out.append((f"{name}[{i}]", "real", self._get(name, i), self._set(name, i)))
        for name, start in BOOL_PARAMS:
            out.append((name, "bool", self._get(name), self._set(name)))
        return out

    def _get(self, name, i=None):
        return (lambda: self.v[name]) if i is None else (lambda: self.v[name][i])

    def _set(self, name, i=None):
        def setter(value):
            if i is None:
                self.v[name] = value
            else:
                self.v[name][i] = value
        return setter

    def _law(self):
        from stationbed.controllers.pd import PD

        v = self.v
        law = PD(period=1.0, reference="lvlh" if v["lvlh"] else "inertial", q_ref=list(v["q_ref"]),
                 bandwidth=v["bandwidth"], damping=v["damping"], max_slew_rate=v["max_slew_rate"],
                 gyro_compensation=bool(v["gyro_compensation"]))
        plant = SimpleNamespace(scene=SimpleNamespace(appendage=()), inertia_O_B=np.array(v["inertia_O_B"]).reshape(3, 3),
                                mean_motion=v["mean_motion"] if v["lvlh"] else None, n_gimbals=0)
        law.reset(plant)
        return law

    def _measurement(self):
        """What pd reads, in the measurement layout of a plant without gimbals or arrays."""
        from stationbed.run.controller import Measurement, measurement_fields

        lay = measurement_fields(0, 0)
        meas = Measurement(np.zeros(lay.size), lay)
        for name, _ in INPUTS:
            getattr(meas, name)[:] = self.v[name]
        return meas

    def step(self, t, h):
        """The law at the step's start ``t`` on the inputs; False (with ``message``) to fail."""
        v = self.v
        if abs(t - self.clock) > CLOCK_TOL_S * max(1.0, abs(t)):
            self.message = f"doStep starts at {t!r} s, the FMU's clock is at {self.clock!r} s"
            return False
        if v["step_wall_s"] > 0.0:
            time.sleep(v["step_wall_s"])
        if 0.0 <= v["raise_at"] <= t:
            raise RuntimeError(f"gain table lost at {t} s")
        if 0.0 <= v["fail_at"] <= t:
            self.message = f"gain table exhausted at {t} s"
            return False
        if self.law is None:
            self.law = self._law()
        meas = self._measurement()
        tau = self.law.update(t, meas)
        v["tau_cmd"][:] = [float(x) for x in tau]
        v["q_ref_BN"][:] = [float(x) for x in self.law.q_ref_BN]
        if 0.0 <= v["nan_at"] <= t:
            v["tau_cmd"][1] = math.nan
        v["n_steps"][0] += 1
        self.clock = t + h
        return True
