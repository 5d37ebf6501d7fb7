"""FMI 3 co-simulation FMU of the shipped ``pd`` law with FMI 3 *array* variables (built by the
tests with pythonfmu3): inputs ``q_BN`` (4), ``omega_BN_B`` (3), ``q_ON`` (4), ``omega_ON_O`` (3),
outputs ``torque`` (3, the command under its own name) and ``q_ref_BN`` (4), array parameters
``inertia_O_B`` (9, a plant fact) and ``q_ref`` (4)."""

from pythonfmu3 import Boolean, Dimension, Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3Variability, Float64

from pd_core import BOOL_PARAMS, INPUTS, REAL_PARAMS, PdCore

#: the command output's name in this FMU (the scene maps tau_cmd to it)
TORQUE = "torque"


class PdFmi3Arrays(Fmi3Slave):
    description = "stationbed pd law with FMI 3 arrays (tests)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.core = PdCore()
        v = self.core.v
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))

        def array(name, key, n, causality, variability, start):
            def get(key=key):
                return list(v[key])

            def set_(values, key=key):
                v[key][:] = [float(x) for x in values]

            kw = dict(causality=causality, variability=variability, dimensions=[Dimension(start=str(n))], getter=get)
            if causality != Fmi3Causality.output:
                kw.update(setter=set_, start=start)
            self.register_variable(Float64(name, **kw), nested=False)

        for name, n in INPUTS:
            array(name, name, n, Fmi3Causality.input, Fmi3Variability.continuous, [1.0] + [0.0] * (n - 1))
        array(TORQUE, "tau_cmd", 3, Fmi3Causality.output, Fmi3Variability.continuous, None)
        array("q_ref_BN", "q_ref_BN", 4, Fmi3Causality.output, Fmi3Variability.continuous, None)
        for name, n, start in REAL_PARAMS:
            if n == 1:
                self.register_variable(Float64(name, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable,
                                               start=start, getter=self.core._get(name), setter=self.core._set(name)), nested=False)
            else:
                array(name, name, n, Fmi3Causality.parameter, Fmi3Variability.tunable, list(v[name]))
        for name, start in BOOL_PARAMS:
            self.register_variable(Boolean(name, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable,
                                           start=start, getter=self.core._get(name), setter=self.core._set(name)), nested=False)

    def do_step(self, current_time, step_size):
        ok = self.core.step(current_time, step_size)
        if not ok:
            self.log(self.core.message, Fmi3Status.error)
        return ok
