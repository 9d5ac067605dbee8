"""py_faulty.py - pythonfmu (FMI 2.0 co-simulation) source: an integrator that can hang or fail on purpose.

    dy/dt = u  (exact ZOH step: y(t+h) = y + u h)

Fault injection, for the adapter's fault handling (tests/unit/test_fmu_faults.py):

* ``block_at_s`` / ``block_for_s``: a ``doStep`` starting at or after ``block_at_s`` sleeps
  ``block_for_s`` seconds of wall time (an FMU that hangs);
* ``fail_at_s``: a ``doStep`` starting at or after ``fail_at_s`` raises
  ``RuntimeError("py_faulty: coolant pump model diverged at t = ... s")`` - pythonfmu reports the
  exception text through the FMU logger and returns fmi2Error.

Negative times disable a fault (the default). Built by shevsim.fmu.build.build_python_fmu (fmi_version=2).
"""
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class PyFaulty(Fmi2Slave):
    author = "shevsim"
    description = "Integrator dy/dt = u with injectable hang and failure"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.block_at_s = -1.0
        self.block_for_s = 0.0
        self.fail_at_s = -1.0
        self.u = 0.0
        self.y = 0.0
        for name in ("block_at_s", "block_for_s", "fail_at_s"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def to_xml(self, model_options=dict()):
        from xml.etree.ElementTree import SubElement
        root = super().to_xml(model_options)
        structure = root.find("ModelStructure")
        for unknown in structure.find("Outputs").findall("Unknown"):
            unknown.set("dependencies", "")
        init = SubElement(structure, "InitialUnknowns")
        for unknown in structure.find("Outputs").findall("Unknown"):
            SubElement(init, "Unknown", attrib=dict(index=unknown.get("index")))
        return root

    def do_step(self, current_time, step_size):
        if 0.0 <= self.fail_at_s <= current_time + 1e-12:
            raise RuntimeError(f"py_faulty: coolant pump model diverged at t = {current_time:g} s")
        if 0.0 <= self.block_at_s <= current_time + 1e-12:
            time.sleep(self.block_for_s)
        self.y += self.u * step_size
        return True
