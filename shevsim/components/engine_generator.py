"""engine_generator.py - diesel engine-generator component (TYPE ``engine_generator``).

Physics in :mod:`shevsim.powertrain.engine` (read its docstring for the equations): power-rate
limit on the command -> optimal-operating-line speed set point and shaft-power demand -> PI rack
controller on the torque error (seed B.1) -> turbo-lag filter on the fuel -> engine torque map
(speed, fuel) -> shaft speed response -> generator efficiency map; fuel and soot (quasi-static
map + transient term from the turbo-lag fuel deficit); load shedding when the bus cannot absorb the
power (command and generator torque cut, governor fuel cut; item 10 of the physics docstring).

Ports
-----
Inputs
    ``power_cmd_w`` [W] electrical power command (+ to the bus), clipped to [0, P_max].
    ``power_rate_max_wps`` [W/s] max rate of increase of the (internal) power command; start 1e12
    (no limit).
    ``elec_power_max_w`` [W] most electrical power the bus can absorb (``bus.gen_power_max_w``: motors +
    auxiliaries + battery charge capability); start 1e12 (no limit). Not direct feedthrough: it acts
    inside the step. Below the rate-limited command it cuts the command at once (no downward rate
    limit) and the generator torque is cut so that the electrical power of every internal sub-step
    is ``<= max(elec_power_max_w, 0)``; the surplus engine work accelerates the shaft (booked as
    kinetic energy) until the governor has cut the fuel (falls with ``fuel_fall_s``).
    ``elec_power_min_w`` [W] least electrical power the bus needs (``power_limits.gen_power_min_w``: motors +
    auxiliaries - battery discharge capability); start 0 (none). Not direct feedthrough: above 0 the
    generator torque is raised within the step so that every sub-step delivers at least it, out of the
    shaft's kinetic energy, down to the idle speed (item 10d of the physics docstring).
Outputs (at t + h, no direct feedthrough: every output comes from the state or the step just run)
    ``elec_power_w`` [W] + to the bus, *mean over the last step* (so that sum(P h) equals the
    electrical energy delivered); ``engine_power_w`` [W] crankshaft power (end of step);
    ``engine_speed_radps`` [rad/s]; ``engine_torque_nm`` [N m]; ``rack_frac`` [1] rack position
    zeta; ``fuel_rate_gps`` [g/s] and ``soot_rate_mgps`` [mg/s] means over the last step;
    ``power_limited_w`` [W] the rate-limited (and shed) command; ``elec_power_rated_w`` [W] max steady
    electrical output (constant, end of the optimal operating line); ``shed_count`` [1] cumulative
    number of load-shedding episodes, ``shed_time_s`` [s] cumulative time shedding was active
    (command cut or generator torque cut); cumulative ``fuel_mass_g``, ``fuel_energy_j``,
    ``soot_mass_mg``, ``soot_transient_mg``, ``engine_loss_energy_j``, ``gen_loss_energy_j``,
    ``elec_energy_j``, ``shaft_kinetic_energy_j`` (change of 1/2 J w^2 since t0);
    ``soot_rate_meas_mgps`` [mg/s] the soot analyser's reading, mean over the last step (item 11 of the
    physics docstring: first-order lag ``soot_analyzer_tau_s`` + offset ``soot_analyzer_offset_mgps``;
    equal to ``soot_rate_mgps`` with both at their default 0, except at t0, where it includes
    ``soot_scale_frac``).

Energy balance (exact): ``fuel_energy_j = elec_energy_j + engine_loss_energy_j +
gen_loss_energy_j + shaft_kinetic_energy_j``.
Initial state: steady operation on the optimal line at the start value of ``power_cmd_w``.
Physics written once, in :func:`shevsim.powertrain.engine.step`; the component's one step,
:func:`engine_generator_step` (input check, the physics, the finiteness check, publishing), runs on the
component's arrays ``data`` (:data:`D`) under the Python master and in the compiled whole-vehicle loop
alike; ``compiled=False`` runs its Python form (``.py_func``).  Every extrapolation rule of the maps is
supported.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, field_index, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.variables import inp, out
from shevsim.powertrain import engine as _eng
from shevsim.powertrain.engine import (EG_DIR, EngineGenMaps, EngineGenState, S, T, measured_soot_rate, pack_maps,
                                       pack_params, steady_state)

ERR_NONFINITE = 16
#: the step's data (:attr:`EngineGenerator.data`): packed maps, parameters, rated power, state, the step's
#: totals, state before the step
D = field_index(("md", "mi", "c", "p_max", "x", "tot", "x_prev"), "D")


@dataclass(frozen=True)
class EngineGeneratorParams:
    """Engine-generator parameters (defaults: components/engine_generator/default.toml).

    Attributes
    ----------
    *_file : str
        Derived maps (built by ``python -m shevsim.powertrain.build_maps``).
    fuel_lhv_j_per_g : float
        Diesel lower heating value [J/g].
    rack_kp_per_nm, rack_ki_per_nm_s : float
        PI rack gains of B.1 [1/(N m)], [1/(N m s)].
    turbo_lag_s, fuel_fall_s : float
        Fuel filter time constants when the rack fuel rises / falls [s].
    speed_time_constant_s, speed_accel_max_radps2 : float
        Shaft speed response to the set point [s], [rad/s2].
    shaft_inertia_kg_m2 : float
        Engine + generator rotating inertia [kg m2].
    power_rate_down_max_wps : float
        Max rate of decrease of the internal power command [W/s].
    transient_soot_mg_per_g : float
        Transient soot per gram of fuel deficit at a full-load relative deficit [mg/g]
        (``S_tr = c d^2 / m_fl``, see :mod:`shevsim.powertrain.engine`).
    soot_scale_frac : float
        Multiplier of the quasi-static soot map [-].
    max_substep_s : float
        Longest internal sub-step [s].
    soot_analyzer_tau_s : float
        Time constant of the soot analyser's first-order lag [s] (output ``soot_rate_meas_mgps``);
        0 = no lag.
    soot_analyzer_offset_mgps : float
        Constant offset of the soot analyser's reading [mg/s]; 0 = none.
    rated_power_w, maps_rated_power_w : float
        Rated engine power [W] of this engine-generator and the rating the map files describe (261 kW
        for the bundled maps).  Sizing by rating: with ``k = rated_power_w / maps_rated_power_w`` the maps
        scale as :meth:`~shevsim.powertrain.engine.EngineGenMaps.scaled` states (torque, fuel, soot and
        power x k at the same speed; the generator with the engine), the rotating inertia x k and the
        rack gains (per N m) / k, so the torque loop and the speed response keep their dynamics.
        ``k = 1`` (the default) is the maps as built, exactly.  In a scenario the rating is the shared
        quantity ``engine_power_w`` (:mod:`shevsim.components.shared`).
    """

    fuel_map_file: str = str(EG_DIR / "engine_fuel_map.csv")
    torque_map_file: str = str(EG_DIR / "engine_torque_map.csv")
    max_torque_file: str = str(EG_DIR / "engine_max_torque.csv")
    soot_map_file: str = str(EG_DIR / "soot_map.csv")
    generator_eff_file: str = str(EG_DIR / "generator_eff_map.csv")
    generator_max_torque_file: str = str(EG_DIR / "generator_max_torque.csv")
    ool_file: str = str(EG_DIR / "optimal_operating_line.csv")
    fuel_lhv_j_per_g: float = 42600.0
    rack_kp_per_nm: float = 5.5e-4
    rack_ki_per_nm_s: float = 2.0e-3
    turbo_lag_s: float = 1.5
    fuel_fall_s: float = 0.1
    speed_time_constant_s: float = 0.5
    speed_accel_max_radps2: float = 20.0
    shaft_inertia_kg_m2: float = 3.0
    power_rate_down_max_wps: float = 1e12
    transient_soot_mg_per_g: float = 10.0
    soot_scale_frac: float = 1.0
    max_substep_s: float = 0.05
    soot_analyzer_tau_s: float = 0.0
    soot_analyzer_offset_mgps: float = 0.0
    rated_power_w: float = 261e3
    maps_rated_power_w: float = 261e3

    @property
    def power_scale(self) -> float:
        """``rated_power_w / maps_rated_power_w``: the sizing factor of the maps."""
        return self.rated_power_w / self.maps_rated_power_w

    def __post_init__(self):
        for k in ("fuel_lhv_j_per_g", "turbo_lag_s", "fuel_fall_s", "speed_time_constant_s",
                  "speed_accel_max_radps2", "shaft_inertia_kg_m2", "power_rate_down_max_wps", "max_substep_s",
                  "rated_power_w", "maps_rated_power_w"):
            if not getattr(self, k) > 0:
                raise ValueError(f"parameter '{k}' must be > 0, got {getattr(self, k)!r}")
        for k in ("rack_kp_per_nm", "rack_ki_per_nm_s", "transient_soot_mg_per_g", "soot_scale_frac",
                  "soot_analyzer_tau_s"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"parameter '{k}' must be >= 0, got {getattr(self, k)!r}")


class EngineGenerator(CompiledStep, Component):
    """Diesel engine-generator with PI rack, turbo lag, soot and power-rate limit (see module docstring)."""

    TYPE = "engine_generator"
    INPUT_DEFAULTS = ("power_rate_max_wps", "elec_power_max_w", "elec_power_min_w")   # no limit, no floor
    Params = EngineGeneratorParams
    VARIABLES = (
        inp("power_cmd_w", "W", 0.0, "electrical power command, + to the bus"),
        inp("power_rate_max_wps", "W/s", 1e12, "max rate of increase of the power command"),
        inp("elec_power_max_w", "W", 1e12, "most electrical power the bus can absorb (load shedding below it)"),
        inp("elec_power_min_w", "W", 0.0, "least electrical power the bus needs (generator floor above 0)"),
        out("elec_power_w", "W", 0.0, "electrical power delivered to the bus (mean over the last step)"),
        out("engine_power_w", "W", 0.0, "engine crankshaft power"),
        out("engine_speed_radps", "rad/s", 0.0, "engine speed"),
        out("engine_torque_nm", "N.m", 0.0, "engine brake torque"),
        out("rack_frac", "1", 0.0, "rack position zeta in [0, 1]"),
        out("fuel_rate_gps", "g/s", 0.0, "fuel rate (mean over the last step)"),
        out("soot_rate_mgps", "mg/s", 0.0, "engine-out soot rate (mean over the last step)"),
        out("power_limited_w", "W", 0.0, "rate-limited (and shed) internal power command"),
        out("elec_power_rated_w", "W", 0.0, "max steady electrical output (end of the optimal line), constant"),
        out("shed_count", "1", 0.0, "cumulative number of load-shedding episodes"),
        out("shed_time_s", "s", 0.0, "cumulative time with load shedding active"),
        out("fuel_mass_g", "g", 0.0, "cumulative fuel mass"),
        out("fuel_energy_j", "J", 0.0, "cumulative fuel energy (LHV)"),
        out("soot_mass_mg", "mg", 0.0, "cumulative soot mass"),
        out("soot_transient_mg", "mg", 0.0, "cumulative transient part of the soot mass"),
        out("engine_loss_energy_j", "J", 0.0, "cumulative engine loss (fuel energy - crankshaft work)"),
        out("gen_loss_energy_j", "J", 0.0, "cumulative generator + controller loss"),
        out("elec_energy_j", "J", 0.0, "cumulative electrical energy delivered"),
        out("shaft_kinetic_energy_j", "J", 0.0, "change of the shaft kinetic energy since t0"),
        out("soot_rate_meas_mgps", "mg/s", 0.0, "soot analyser reading: lagged soot rate + offset (mean over the last step)"),
    )
    STEP_ERRORS = {ERR_NAN_INPUT: "NaN input",
                   ERR_NONFINITE: "engine-generator step gave a non-finite result (a NaN lookup, or a lookup "
                                  "outside a map with extrapolation 'error')"}
    DATA_MUTABLE = (D.x, D.tot, D.x_prev)
    _static = ("name", "params", "maps", "_compiled", "_fn", "_u_names", "_y_names")

    def __init__(self, name: str = "engine_generator", params: EngineGeneratorParams | None = None,
                 compiled: bool = True):
        super().__init__(name, params)
        p = self.params
        k = p.power_scale
        self.maps = EngineGenMaps(p.fuel_map_file, p.torque_map_file, p.max_torque_file, p.soot_map_file,
                                  p.generator_eff_file, p.generator_max_torque_file, p.ool_file).scaled(k)
        # sized by rating (k = 1: unchanged): rack gains per N m / k, inertia x k
        prm = p if k == 1.0 else dataclasses.replace(
            p, rack_kp_per_nm=p.rack_kp_per_nm / k, rack_ki_per_nm_s=p.rack_ki_per_nm_s / k,
            shaft_inertia_kg_m2=p.shaft_inertia_kg_m2 * k)
        self._compiled = compiled
        self._md, self._mi = pack_maps(self.maps)
        self._c = pack_params(prm)

    _static = _static + ("_md", "_mi", "_c")

    def set_maps(self, maps: EngineGenMaps) -> None:
        """Use ``maps`` from now on (packed again; the state is kept)."""
        self.maps = maps
        self._md, self._mi = pack_maps(maps)
        if hasattr(self, "data"):
            p_max = np.array([float(maps.p_max_w)])
            self.data = (self._md, self._mi, self._c, p_max) + self.data[D.x:]

    def step_function(self):
        return engine_generator_step if self._compiled else engine_generator_step.py_func

    def fast_reason(self) -> str:
        return "" if self._compiled else f"component '{self.name}': engine-generator built with compiled=False"

    @property
    def st(self) -> EngineGenState:
        """The state as an :class:`~shevsim.powertrain.engine.EngineGenState` (a copy, for reading)."""
        st = EngineGenState()
        st.set_values(self.data[D.x].tolist())
        return st

    def initialize(self, t0: float) -> None:
        st = steady_state(self.maps, self.u["power_cmd_w"], soot_scale_frac=self.params.soot_scale_frac)
        x = np.array(st.values(), dtype=np.float64)
        self.data = (self._md, self._mi, self._c, np.array([float(self.maps.p_max_w)]), x, np.zeros(4), x.copy())
        self._io()
        p0 = st.p_lim
        engine_generator_publish(self.data, p0, self.maps.fuel_quasi_static(p0), self.maps.soot(st.w, st.tau_e),
                                 measured_soot_rate(st, self.params), self._y_arr)
        self.y.update(zip(self._y_names, self._y_arr.tolist()))

    def step_error(self, status: int, t: float, h: float) -> str:
        if status == ERR_NONFINITE:
            x, u = self.data[D.x], self.u
            return f"{self.name}: " + _eng.nonfinite_message(self.maps, float(x[S.p_lim]), float(x[S.w]),
                                                              u["power_cmd_w"], h)
        return super().step_error(status, t, h)


U = port_index(EngineGenerator.VARIABLES, "input")
Y = port_index(EngineGenerator.VARIABLES, "output")


@njit_step
def engine_generator_publish(data, p_el, fuel_gps, soot_mgps, soot_meas_mgps, y):
    """The outputs at the state in ``data`` with the step's mean electrical power, fuel, soot and analyser rates."""
    x = data[4]
    y[Y.elec_power_w] = p_el
    y[Y.engine_power_w] = x[S.tau_e] * x[S.w]
    y[Y.engine_speed_radps] = x[S.w]
    y[Y.engine_torque_nm] = x[S.tau_e]
    y[Y.rack_frac] = x[S.rack]
    y[Y.fuel_rate_gps] = fuel_gps
    y[Y.soot_rate_mgps] = soot_mgps
    y[Y.power_limited_w] = x[S.p_lim]
    y[Y.elec_power_rated_w] = data[3][0]
    y[Y.shed_count] = x[S.shed_n]
    y[Y.shed_time_s] = x[S.shed_s]
    y[Y.fuel_mass_g] = x[S.fuel_g]
    y[Y.fuel_energy_j] = x[S.fuel_j]
    y[Y.soot_mass_mg] = x[S.soot_mg]
    y[Y.soot_transient_mg] = x[S.soot_tr_mg]
    y[Y.engine_loss_energy_j] = x[S.eng_loss_j]
    y[Y.gen_loss_energy_j] = x[S.gen_loss_j]
    y[Y.elec_energy_j] = x[S.elec_j]
    y[Y.shaft_kinetic_energy_j] = x[S.ke_j]
    y[Y.soot_rate_meas_mgps] = soot_meas_mgps


@njit_step
def engine_generator_step(data, u, y, t, h):
    """:class:`EngineGenerator`'s step: input check, :func:`shevsim.powertrain.engine.step`, the finiteness
    check (the state is left as it was on failure), the outputs at ``t + h``."""
    md, mi, c, p_max, x, tot, prev = data          # the fields of D
    pc = u[U.power_cmd_w]
    rate = u[U.power_rate_max_wps]
    lim = u[U.elec_power_max_w]
    floor = u[U.elec_power_min_w]
    if pc != pc or rate != rate or lim != lim or floor != floor:
        return ERR_NAN_INPUT
    for j in range(x.shape[0]):
        prev[j] = x[j]
    _eng.step(md, mi, c, p_max[0], x, pc, rate, h, lim, floor, tot)
    if not math.isfinite(tot[T.e_el] + tot[T.fuel] + tot[T.soot_meas] + x[S.w] + x[S.tau_e]):
        for j in range(x.shape[0]):
            x[j] = prev[j]
        return ERR_NONFINITE
    engine_generator_publish(data, tot[T.e_el] / h, tot[T.fuel] / h, tot[T.soot] / h, tot[T.soot_meas], y)
    return 0
