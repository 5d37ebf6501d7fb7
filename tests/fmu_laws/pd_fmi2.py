"""FMI 2 co-simulation FMU of the shipped ``pd`` law (built by the tests with pythonfmu)."""

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

from pd_core import PdCore


class PdFmi2(Fmi2Slave):
    description = "stationbed pd law (tests)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.core = PdCore()
        for name, kind, get, set_ in self.core.variables():
            if kind == "input":
                var = Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous, getter=get, setter=set_)
            elif kind == "output":
                var = Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous, getter=get)
            elif kind == "real":
                var = Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable, getter=get, setter=set_)
            else:
                var = Boolean(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable, getter=get, setter=set_)
            self.register_variable(var, nested=False)

    def do_step(self, current_time, step_size):
        ok = self.core.step(current_time, step_size)
        if not ok:
            self.log(self.core.message, Fmi2Status.error)
        return ok
