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
Physics written once: the component wraps :func:`shevsim.powertrain.engine.step` (through
:class:`~shevsim.powertrain.engine.EngineGenStep`), numba-compiled; ``compiled=False`` runs the same
source in the Python interpreter (``step.py_func``).  Every extrapolation rule of the maps is supported
by both.
"""
from __future__ import annotations

from dataclasses import dataclass

from shevsim.core.component import Component
from shevsim.core.errors import SimulationError
from shevsim.core.variables import inp, out
from shevsim.powertrain.engine import EG_DIR, EngineGenMaps, EngineGenStep, measured_soot_rate, steady_state


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

    def __post_init__(self):
        for k in ("fuel_lhv_j_per_g", "turbo_lag_s", "fuel_fall_s", "speed_time_constant_s",
                  "speed_accel_max_radps2", "shaft_inertia_kg_m2", "power_rate_down_max_wps", "max_substep_s"):
            if not getattr(self, k) > 0:
                raise ValueError(f"parameter '{k}' must be > 0, got {getattr(self, k)!r}")
        for k in ("rack_kp_per_nm", "rack_ki_per_nm_s", "transient_soot_mg_per_g", "soot_scale_frac",
                  "soot_analyzer_tau_s"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"parameter '{k}' must be >= 0, got {getattr(self, k)!r}")


class EngineGenerator(Component):
    """Diesel engine-generator with PI rack, turbo lag, soot and power-rate limit (see module docstring)."""

    TYPE = "engine_generator"
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
    _static = ("name", "params", "maps", "_step")

    def __init__(self, name: str = "engine_generator", params: EngineGeneratorParams | None = None,
                 compiled: bool = True):
        super().__init__(name, params)
        p = self.params
        self.maps = EngineGenMaps(p.fuel_map_file, p.torque_map_file, p.max_torque_file, p.soot_map_file,
                                  p.generator_eff_file, p.generator_max_torque_file, p.ool_file)
        # the one-source step: numba-compiled, or its Python form (step.py_func) when compiled=False
        self._step = EngineGenStep(self.maps, p, compiled=compiled)

    def initialize(self, t0: float) -> None:
        self.st = steady_state(self.maps, self.u["power_cmd_w"], soot_scale_frac=self.params.soot_scale_frac)
        p0 = self.st.p_lim
        self._write(p0, self.maps.fuel_quasi_static(p0), self.maps.soot(self.st.w, self.st.tau_e),
                    measured_soot_rate(self.st, self.params))

    def _write(self, p_el: float, fuel_gps: float, soot_mgps: float, soot_meas_mgps: float) -> None:
        st, y = self.st, self.y
        y["elec_power_w"] = p_el
        y["engine_power_w"] = st.tau_e * st.w
        y["engine_speed_radps"] = st.w
        y["engine_torque_nm"] = st.tau_e
        y["rack_frac"] = st.rack
        y["fuel_rate_gps"] = fuel_gps
        y["soot_rate_mgps"] = soot_mgps
        y["power_limited_w"] = st.p_lim
        y["elec_power_rated_w"] = self.maps.p_max_w
        y["shed_count"] = st.shed_n
        y["shed_time_s"] = st.shed_s
        y["fuel_mass_g"] = st.fuel_g
        y["fuel_energy_j"] = st.fuel_j
        y["soot_mass_mg"] = st.soot_mg
        y["soot_transient_mg"] = st.soot_tr_mg
        y["engine_loss_energy_j"] = st.eng_loss_j
        y["gen_loss_energy_j"] = st.gen_loss_j
        y["elec_energy_j"] = st.elec_j
        y["shaft_kinetic_energy_j"] = st.ke_j
        y["soot_rate_meas_mgps"] = soot_meas_mgps

    def do_step(self, t: float, h: float) -> None:
        pc, rate, lim = self.u["power_cmd_w"], self.u["power_rate_max_wps"], self.u["elec_power_max_w"]
        floor = self.u["elec_power_min_w"]
        if pc != pc or rate != rate or lim != lim or floor != floor:
            raise SimulationError(f"{self.name}: NaN input at t={t:g} s (power_cmd_w={pc}, power_rate_max_wps={rate}, "
                                  f"elec_power_max_w={lim}, elec_power_min_w={floor})")
        e_el, fuel, soot, soot_meas = self._step(self.st, pc, rate, h, lim, floor)
        self._write(e_el / h, fuel / h, soot / h, soot_meas)
