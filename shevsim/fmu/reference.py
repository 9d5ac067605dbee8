"""reference.py - a small native component with a closed-form solution, for FMU checks.

:class:`RCThermalNode` is the native twin of the C FMU ``fmus/src/rc_thermal``
(same ports, same parameters): a lumped heat capacity behind a thermal
resistance to ambient,

    c_j_k dT/dt = heat_w - (T - t_ambient_c) / r_k_w.

With the inputs held over a step (zero-order hold) the solution is exact:
T_inf = t_ambient_c + r_k_w heat_w, T(t+h) = T_inf + (T - T_inf) exp(-h / (r_k_w c_j_k)).
The C FMU integrates the same equation with RK4 sub-steps, so the two agree
to the RK4 truncation error; the exported/imported FMU of this class agrees
with the native one to floating-point round-off. Used by tests/unit/test_fmu.py
and benchmarks/fmu_overhead.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.component import Component
from ..core.variables import inp, out


@dataclass(frozen=True, slots=True)
class RCThermalNodeParams:
    """Parameters of :class:`RCThermalNode`.

    c_j_k : heat capacity of the node [J/K] (> 0)
    r_k_w : thermal resistance node-to-ambient [K/W] (> 0)
    t0_c : initial node temperature [degC]
    """

    c_j_k: float = 5000.0
    r_k_w: float = 0.02
    t0_c: float = 25.0

    def __post_init__(self):
        if not self.c_j_k > 0:
            raise ValueError(f"c_j_k must be > 0, got {self.c_j_k}")
        if not self.r_k_w > 0:
            raise ValueError(f"r_k_w must be > 0, got {self.r_k_w}")


class RCThermalNode(Component):
    """First-order thermal RC node (exact zero-order-hold step).

    Ports
    -----
    heat_w : input [W], heat flow into the node (+ heats the node)
    t_ambient_c : input [degC], ambient temperature
    t_c : output [degC], node temperature (state, no feedthrough)
    heat_loss_w : output [W], heat flow node -> ambient, (t_c - t_ambient_c) / r_k_w
        (+ leaves the node); direct feedthrough from ``t_ambient_c``
    """

    TYPE = "rc_thermal_node"
    Params = RCThermalNodeParams
    VARIABLES = (
        inp("heat_w", "W", 0.0, "heat flow into the node (+ heats)"),
        inp("t_ambient_c", "degC", 25.0, "ambient temperature"),
        out("t_c", "degC", 25.0, "node temperature"),
        out("heat_loss_w", "W", 0.0, "heat flow node to ambient (+ leaves the node)",
            depends_on=("t_ambient_c",)),
    )

    def __init__(self, name: str, params: RCThermalNodeParams | None = None):
        super().__init__(name, params)
        p = self.params
        self._tau_s = p.r_k_w * p.c_j_k
        self.temp_c = p.t0_c

    def initialize(self, t0: float) -> None:
        self.temp_c = self.params.t0_c
        self._outputs()

    def _outputs(self) -> None:
        self.y["t_c"] = self.temp_c
        self.y["heat_loss_w"] = (self.temp_c - self.u["t_ambient_c"]) / self.params.r_k_w

    def do_step(self, t: float, h: float) -> None:
        u = self.u
        t_inf = u["t_ambient_c"] + self.params.r_k_w * u["heat_w"]
        self.temp_c = t_inf + (self.temp_c - t_inf) * math.exp(-h / self._tau_s)
        self._outputs()
