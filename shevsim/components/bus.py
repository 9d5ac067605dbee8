"""bus.py - DC power bus component (TYPE ``bus``): power balance of seed Fig. 5.1.

    battery_power_w = motor_power_w + aux_power_w - gen_power_w      (+ = battery discharges)

``aux_power_w`` is the input plus the parameter ``aux_power_w`` (a constant auxiliary load: HVAC,
fans, electronics; default 0 = off). Wherever this docstring says ``aux`` it means that total.

The balance is :func:`shevsim.powertrain.motor.bus_balance` (compiled; the vehicle calibration's loop
sums the bus with it too). A lossless node (converter losses are inside the motor and generator maps). Cumulative energies
are the inputs integrated with the same zero-order hold the master applies, so
``battery_energy_j = motor_energy_j + aux_energy_j - gen_energy_j`` exactly.

Ports
-----
Inputs
    ``motor_power_w`` [W] (+ drawn by the motors), ``gen_power_w`` [W] (+ delivered by the
    generator), ``aux_power_w`` [W] (+ drawn by auxiliaries, start 0).
    ``battery_power_max_w`` [W] (>= 0) and ``battery_power_min_w`` [W] (<= 0): the battery power
    capability (from the BMS), start +-1e12 (no limit).
Outputs (direct feedthrough of the inputs they use)
    ``motor_power_max_w`` = gen + battery_power_max - aux and ``motor_power_min_w`` =
    gen + battery_power_min - aux [W]: what the motors may draw / return so that the battery stays
    inside its power capability (the vehicle controller's traction derating). With the parameter
    ``enforce_battery_limits = false`` they are +-1e12 (the counterfactual without limits).
    ``gen_power_max_w`` = max(motor + aux - battery_power_min, 0) [W]: the most generator power the bus
    can absorb without charging the battery beyond its capability (the engine-generator sheds load
    above it, see :mod:`shevsim.components.engine_generator`); 1e12 with
    ``enforce_battery_limits = false``.
    ``battery_power_w`` [W] + discharge; ``demand_power_w`` [W] = motor + aux;
    cumulative ``aux_energy_j``, ``motor_energy_j``, ``gen_energy_j``, ``battery_energy_j`` [J].

Limits held within the step (:class:`PowerLimits`, TYPE ``power_limits``)
-----------------------------------------------------------------------
The bus computes its limit outputs in its own step, *after* the motor and the generator have run (it
books their power), so a motor or generator connected to them is clamped against the previous step's
BMS limits and the previous step's other machine: over the cooling-fault run the battery then leaves the
same-step BMS limits for ~50 s (up to 170 kW in a step, issue 14).  ``power_limits`` is the same limit
algebra (:func:`shevsim.powertrain.motor.bus_limits`) as a component of its own, so a scenario can evaluate it where the
limits act, in the step they are computed for (``scenarios/*seed*.toml``)::

    order = [..., "bms", "motor_limits", "motor", "gen_limits", "engine_generator", "bus", "battery", ...]

``motor_limits`` (after the BMS) clamps the motor against this step's BMS limits and the generator's
last power (the regen side counts only on max(gen, 0): shedding can hold the generator at any power
>= 0, not make it motor); ``gen_limits`` (after the motor) sheds the generator against this step's motor
power and charge limit (``gen_power_max_w``) and gives it a floor (``gen_power_min_w`` = motor + aux -
P_max, the engine-generator's ``elec_power_min_w``: the generator holds that power out of its shaft's
kinetic energy when its own dynamics dip, :mod:`shevsim.powertrain.engine` item 10d).  The charge side
then holds exactly (battery = motor + aux - gen >= P_min whenever the generator can shed); the discharge
side whenever the floor can be held above the engine's idle speed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.variables import inp, out
from shevsim.powertrain.motor import bus_aux_w, bus_balance, bus_limits

_ALL = ("motor_power_w", "gen_power_w", "aux_power_w")


@dataclass(frozen=True, slots=True)
class BusParams:
    """Bus parameters.

    Attributes
    ----------
    enforce_battery_limits : bool
        Derive motor power limits from the battery power capability (default true).
    aux_power_w : float
        Constant auxiliary load [W] added to the ``aux_power_w`` input (default 0).
    """

    enforce_battery_limits: bool = True
    aux_power_w: float = 0.0

    def __post_init__(self):
        import math
        if not math.isfinite(self.aux_power_w):
            raise ValueError(f"parameter 'aux_power_w' must be finite, got {self.aux_power_w!r}")


_LIM = ("gen_power_w", "aux_power_w", "battery_power_max_w", "battery_power_min_w")
_GLIM = ("motor_power_w", "aux_power_w", "battery_power_min_w")


class PowerBus(CompiledStep, Component):
    """Lossless power balance (see module docstring for ports)."""

    TYPE = "bus"
    Params = BusParams
    INPUT_DEFAULTS = ("aux_power_w", "battery_power_max_w", "battery_power_min_w")   # none, no limit
    VARIABLES = (
        inp("motor_power_w", "W", 0.0, "motor electrical power, + drawn from the bus"),
        inp("gen_power_w", "W", 0.0, "generator electrical power, + delivered to the bus"),
        inp("aux_power_w", "W", 0.0, "auxiliary load, + drawn from the bus"),
        inp("battery_power_max_w", "W", 1e12, "battery discharge power capability (>= 0)"),
        inp("battery_power_min_w", "W", -1e12, "battery charge power capability (<= 0)"),
        out("motor_power_max_w", "W", 1e12, "most power the motors may draw", _LIM),
        out("motor_power_min_w", "W", -1e12, "most power the motors may return (<= 0)", _LIM),
        out("gen_power_max_w", "W", 1e12, "most generator power the bus can absorb (>= 0)", _GLIM),
        out("battery_power_w", "W", 0.0, "battery power, + discharge", _ALL),
        out("demand_power_w", "W", 0.0, "motor + auxiliary power", ("motor_power_w", "aux_power_w")),
        out("aux_energy_j", "J", 0.0, "cumulative auxiliary energy", ("aux_power_w",)),
        out("motor_energy_j", "J", 0.0, "cumulative motor electrical energy", ("motor_power_w",)),
        out("gen_energy_j", "J", 0.0, "cumulative generator electrical energy", ("gen_power_w",)),
        out("battery_energy_j", "J", 0.0, "cumulative battery energy, + discharged", _ALL),
    )

    DATA_MUTABLE = (1,)
    _static = ("name", "params", "_aux_w", "_fn", "_u_names", "_y_names")

    def _aux(self) -> float:
        return bus_aux_w(self.u["aux_power_w"], self._aux_w)

    def __init__(self, name: str = "bus", params: BusParams | None = None):
        super().__init__(name, params)
        self._aux_w = float(self.params.aux_power_w)

    def initialize(self, t0: float) -> None:
        """Outputs at t0: the limits and the balance of the start inputs, no energy yet.  ``data`` =
        ``(p = [aux_power_w, enforce_battery_limits], e = [aux, motor, gen, battery energies])``."""
        self.data = (np.array([self._aux_w, 1.0 if self.params.enforce_battery_limits else 0.0]), np.zeros(4))
        u, y = self.u, self.y
        (y["motor_power_max_w"], y["motor_power_min_w"], y["gen_power_max_w"], _floor) = bus_limits(
            u["motor_power_w"], u["gen_power_w"], u["aux_power_w"], u["battery_power_max_w"],
            u["battery_power_min_w"], self._aux_w, self.params.enforce_battery_limits)
        _pa, y["demand_power_w"], y["battery_power_w"] = bus_balance(u["motor_power_w"], u["gen_power_w"],
                                                                     u["aux_power_w"], self._aux_w)
        for k in ("aux_energy_j", "motor_energy_j", "gen_energy_j", "battery_energy_j"):
            y[k] = 0.0
        self._io()

    @property
    def e(self) -> list:
        """Cumulative auxiliary, motor, generator and battery energies [J]."""
        return self.data[1].tolist()


class PowerLimits(CompiledStep, Component):
    """The bus's limit algebra as a component of its own (TYPE ``power_limits``), evaluated in the step
    the limits act in (module docstring, "Limits held within the step").

    Inputs ``motor_power_w``, ``gen_power_w``, ``aux_power_w`` [W] (signs as the bus),
    ``battery_power_max_w`` (>= 0), ``battery_power_min_w`` (<= 0) [W].  Outputs (direct feedthrough)
    ``motor_power_max_w``, ``motor_power_min_w``, ``gen_power_max_w`` [W], the same laws as
    :class:`PowerBus`, and ``gen_power_min_w`` = motor + aux - battery_power_max [W] (what the generator
    must deliver for the battery to stay within its discharge capability; <= 0: nothing; -1e12 with
    ``enforce_battery_limits = false``), the engine-generator's floor.  Parameters: :class:`BusParams`
    (``enforce_battery_limits``, ``aux_power_w``).
    """

    TYPE = "power_limits"
    Params = BusParams
    INPUT_DEFAULTS = ("aux_power_w", "battery_power_max_w", "battery_power_min_w")   # none, no limit
    VARIABLES = (
        inp("motor_power_w", "W", 0.0, "motor electrical power, + drawn from the bus"),
        inp("gen_power_w", "W", 0.0, "generator electrical power, + delivered to the bus"),
        inp("aux_power_w", "W", 0.0, "auxiliary load, + drawn from the bus"),
        inp("battery_power_max_w", "W", 1e12, "battery discharge power capability (>= 0)"),
        inp("battery_power_min_w", "W", -1e12, "battery charge power capability (<= 0)"),
        out("motor_power_max_w", "W", 1e12, "most power the motors may draw", _LIM),
        out("motor_power_min_w", "W", -1e12, "most power the motors may return (<= 0)", _LIM),
        out("gen_power_max_w", "W", 1e12, "most generator power the bus can absorb (>= 0)", _GLIM),
        out("gen_power_min_w", "W", -1e12, "least generator power the bus needs (<= 0: none)",
            ("motor_power_w", "aux_power_w", "battery_power_max_w")),
    )
    _static = ("name", "params", "_aux_w", "_fn", "_u_names", "_y_names")

    def __init__(self, name: str = "power_limits", params: BusParams | None = None):
        super().__init__(name, params)
        self._aux_w = float(self.params.aux_power_w)

    _aux = PowerBus._aux

    def initialize(self, t0: float) -> None:
        """``data`` = ``(p = [aux_power_w, enforce_battery_limits],)``; the outputs are those of the start inputs."""
        self.data = (np.array([self._aux_w, 1.0 if self.params.enforce_battery_limits else 0.0]),)
        self._io()
        power_limits_step(self.data, self._u_arr, self._y_arr, t0, 0.0)
        self.y.update(zip(self._y_names, self._y_arr.tolist()))


UB = port_index(PowerBus.VARIABLES, "input")
YB = port_index(PowerBus.VARIABLES, "output")
UL = port_index(PowerLimits.VARIABLES, "input")
YL = port_index(PowerLimits.VARIABLES, "output")


@njit_step
def power_bus_step(data, u, y, t, h):
    """:class:`PowerBus`'s step: the balance (:func:`~shevsim.powertrain.motor.bus_balance`), the energies
    over ``h``, then the limits (:func:`~shevsim.powertrain.motor.bus_limits`) at the held inputs."""
    p, e = data
    pm = u[UB.motor_power_w]
    pg = u[UB.gen_power_w]
    u_aux = u[UB.aux_power_w]
    pa, d, b = bus_balance(pm, pg, u_aux, p[0])
    if pm != pm or pg != pg or pa != pa:
        return ERR_NAN_INPUT
    e[0] += pa * h
    e[1] += pm * h
    e[2] += pg * h
    e[3] += b * h
    y[YB.demand_power_w] = d
    y[YB.battery_power_w] = b
    y[YB.aux_energy_j] = e[0]
    y[YB.motor_energy_j] = e[1]
    y[YB.gen_energy_j] = e[2]
    y[YB.battery_energy_j] = e[3]
    y[YB.motor_power_max_w], y[YB.motor_power_min_w], y[YB.gen_power_max_w], _floor = bus_limits(
        pm, pg, u_aux, u[UB.battery_power_max_w], u[UB.battery_power_min_w], p[0], p[1] > 0.5)
    return 0


@njit_step
def power_limits_step(data, u, y, t, h):
    """:class:`PowerLimits`'s step: the bus's limit law at the held inputs (NaN inputs refused)."""
    p = data[0]
    for j in range(5):
        if u[j] != u[j]:
            return ERR_NAN_INPUT
    y[YL.motor_power_max_w], y[YL.motor_power_min_w], y[YL.gen_power_max_w], y[YL.gen_power_min_w] = bus_limits(
        u[UL.motor_power_w], u[UL.gen_power_w], u[UL.aux_power_w], u[UL.battery_power_max_w],
        u[UL.battery_power_min_w], p[0], p[1] > 0.5)
    return 0


PowerBus.STEP = power_bus_step
PowerLimits.STEP = power_limits_step
