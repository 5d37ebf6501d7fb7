"""FMI 3 co-simulation FMU of the shipped ``pd`` law (built by the tests with pythonfmu3)."""

from pythonfmu3 import Boolean, Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3StepResult, Fmi3Variability, Float64

from pd_core import PdCore


class PdFmi3(Fmi3Slave):
    description = "stationbed pd law (tests)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.core = PdCore()
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        for name, kind, get, set_ in self.core.variables():
            if kind == "input":
                var = Float64(name, causality=Fmi3Causality.input, variability=Fmi3Variability.continuous,
                              start=1.0 if name.endswith("[0]") and name.startswith("q_") else 0.0, getter=get, setter=set_)
            elif kind == "output":
                var = Float64(name, causality=Fmi3Causality.output, variability=Fmi3Variability.continuous, getter=get)
            elif kind == "real":
                var = Float64(name, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=get(),
                              getter=get, setter=set_)
            else:
                var = Boolean(name, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=get(),
                              getter=get, setter=set_)
            self.register_variable(var, nested=False)

    def do_step(self, current_time, step_size):
        if 0.0 <= self.core.v["terminate_at"] <= current_time:
            self.log(f"end of mission at {current_time} s", Fmi3Status.ok)
            return Fmi3StepResult(terminateSimulation=True)
        ok = self.core.step(current_time, step_size)
        if not ok:
            self.log(self.core.message, Fmi3Status.error)
        return ok
