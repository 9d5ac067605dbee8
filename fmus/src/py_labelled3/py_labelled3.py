"""py_labelled3.py - pythonfmu3 (FMI 3.0 co-simulation) source: a gain whose factor is chosen by a String input.

    y = k(mode) * u,   k("single") = 1, k("double") = 2, k("negate") = -1   (any other mode: the step fails)

``mode`` is an input of type String (FMI 3 allows string inputs): a value, not a number port. shevsim lists
it, sets its start value (scenario ``set = { mode = "double" }``) and refuses only a connection to it (issue
26). Built by shevsim.fmu.build.build_python_fmu (fmi_version=3); used by tests/unit/test_fmu_string.py.
"""
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64, String

_GAIN = {"single": 1.0, "double": 2.0, "negate": -1.0}


class PyLabelled3(Fmi3Slave):
    author = "shevsim"
    description = "Gain selected by a String input (FMI 3.0)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.mode = "single"
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.register_variable(String("mode", causality=Fmi3Causality.input, variability=Fmi3Variability.discrete))
        self.register_variable(Float64("u", causality=Fmi3Causality.input))
        self.register_variable(Float64("y", causality=Fmi3Causality.output))

    def exit_initialization_mode(self):
        self.y = _GAIN.get(self.mode, 0.0) * self.u

    def do_step(self, current_time, step_size):
        if self.mode not in _GAIN:
            return False
        self.y = _GAIN[self.mode] * self.u
        return True
