"""py_mass_drag.py - pythonfmu (FMI 2.0 co-simulation) source: point mass with linear drag.

    mass_kg * dv/dt = force_n - damping_ns_m * v,   dx/dt = v

Integrated exactly over each communication step with the force held
(zero-order hold): with v_inf = F / b and tau = m / b,

    v(t+h) = v_inf + (v - v_inf) exp(-h / tau)
    x(t+h) = x + v_inf h + (v - v_inf) tau (1 - exp(-h / tau))

Also an Integer output ``steps_taken`` (doStep calls) and a Boolean output
``reversing`` (speed < 0). pythonfmu 0.7 writes no units, so the ports are unit-less in the model
description (the shevsim adapter then adopts the units of the port it maps to).
Built by shevsim.fmu.build.build_python_fmu (fmi_version=2); used by tests/unit/test_fmu.py.
"""
import math

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class PyMassDrag(Fmi2Slave):
    author = "shevsim"
    description = "Point mass with linear drag (exact ZOH discretisation)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.mass_kg = 1000.0
        self.damping_ns_m = 50.0
        self.v0_mps = 0.0
        self.force_n = 0.0
        self.speed_mps = 0.0
        self.distance_m = 0.0
        for name in ("mass_kg", "damping_ns_m", "v0_mps"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))
        self.register_variable(Real("force_n", causality=Fmi2Causality.input))
        self.register_variable(Real("speed_mps", causality=Fmi2Causality.output))
        self.register_variable(Real("distance_m", causality=Fmi2Causality.output))
        # non-Real outputs (exercise the adapter's Integer/Boolean path)
        self.steps_taken = 0
        self.reversing = False
        self.register_variable(Integer("steps_taken", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("reversing", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete))

    def to_xml(self, model_options=dict()):
        # pythonfmu 0.7 omits <InitialUnknowns>; FMI 2.0 requires the calculated outputs there.
        # <Outputs> keep no "dependencies" attribute: FMI then means "depends on all inputs".
        from xml.etree.ElementTree import SubElement
        root = super().to_xml(model_options)
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        init = SubElement(structure, "InitialUnknowns")
        for unknown in outputs.findall("Unknown"):
            SubElement(init, "Unknown", attrib=dict(index=unknown.get("index")))
        return root

    def exit_initialization_mode(self):
        self.speed_mps = self.v0_mps
        self.distance_m = 0.0

    def do_step(self, current_time, step_size):
        tau = self.mass_kg / self.damping_ns_m
        v_inf = self.force_n / self.damping_ns_m
        e = math.exp(-step_size / tau)
        dv = self.speed_mps - v_inf
        self.distance_m += v_inf * step_size + dv * tau * (1.0 - e)
        self.speed_mps = v_inf + dv * e
        self.steps_taken += 1
        self.reversing = self.speed_mps < 0.0
        return True
