"""py_cell3.py - pythonfmu3 (FMI 3.0 co-simulation) source: a coulomb-counting cell with R0.

    d soc_pct / dt = -100 * current_a / (3600 * capacity_ah)       (current + discharge)
    voltage_v      = ocv_0_v + ocv_slope_v_pct * soc_pct - r0_ohm * current_a

soc is exact over a step with the current held (it is linear in time). A step
that would take soc below 0 % is refused (``do_step`` returns False, which
pythonfmu3 reports as ``fmi3Discard``).
``voltage_v`` depends directly on ``current_a`` (feedthrough) and ``soc_pct``
does not; the model description says so in ``<ModelStructure>`` (added in
``to_xml``, pythonfmu3 itself writes no dependencies).
Built by shevsim.fmu.build.build_python_fmu (fmi_version=3); used by tests/unit/test_fmu.py.
"""
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3Variability, Float64
from pythonfmu3.unit import Unit


class PyCell3(Fmi3Slave):
    author = "shevsim"
    description = "Coulomb-counting cell with series resistance (FMI 3.0)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.capacity_ah = 10.0
        self.r0_ohm = 0.01
        self.soc0_pct = 80.0
        self.ocv_0_v = 3.0
        self.ocv_slope_v_pct = 0.012
        self.current_a = 0.0
        self.soc_pct = 80.0
        self.voltage_v = 3.96
        self.register_units([Unit("A", A=1), Unit("Ohm", kg=1, m=2, s=-3, A=-2),
                             Unit("V", kg=1, m=2, s=-3, A=-1), Unit("%"), Unit("A.h", A=1, s=1, factor=3600.0),
                             Unit("V/%", kg=1, m=2, s=-3, A=-1), Unit("s", s=1)])
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous, unit="s"))
        for name, unit in (("capacity_ah", "A.h"), ("r0_ohm", "Ohm"), ("soc0_pct", "%"),
                           ("ocv_0_v", "V"), ("ocv_slope_v_pct", "V/%")):
            self.register_variable(Float64(name, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.tunable, unit=unit))
        self.register_variable(Float64("current_a", causality=Fmi3Causality.input, unit="A"))
        self.register_variable(Float64("soc_pct", causality=Fmi3Causality.output, unit="%"))
        self.register_variable(Float64("voltage_v", causality=Fmi3Causality.output, unit="V"))

    def to_xml(self, model_options=dict()):
        root = super().to_xml(model_options)
        vr = {v.name: v.value_reference for v in self.vars.values()}
        for node in root.find("ModelStructure").findall("Output"):
            if node.get("valueReference") == str(vr["voltage_v"]):
                node.set("dependencies", str(vr["current_a"]))
            else:
                node.set("dependencies", "")
        return root

    def _outputs(self):
        self.voltage_v = self.ocv_0_v + self.ocv_slope_v_pct * self.soc_pct - self.r0_ohm * self.current_a

    def exit_initialization_mode(self):
        self.soc_pct = self.soc0_pct
        self._outputs()

    def do_step(self, current_time, step_size):
        soc = self.soc_pct - 100.0 * self.current_a * step_size / (3600.0 * self.capacity_ah)
        if soc < 0.0:
            # cannot complete the step: the cell would be over-discharged (-> fmi3Discard)
            self.log(f"cell empty: soc would reach {soc:.4g} % at t = {current_time + step_size:g} s",
                     Fmi3Status.warning)
            return False
        self.soc_pct = soc
        self.time = current_time + step_size
        self._outputs()
        return True
