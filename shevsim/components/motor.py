"""motor.py - traction motor component (TYPE ``motor``): equivalent machine of the in-hub motors.

Force request -> motor torque -> limits -> delivered traction force, friction brakes, bus power.

* wheel force ``F`` <-> motor torque (total of all motors): ``tau = F r_w / G``, motor speed
  ``w = v G / r_w`` (hub reduction ``G``, gear assumed lossless);
* torque limit (heat index, seed B.2-B.3 as corrected, see :mod:`shevsim.powertrain.motor`):
  ``tau_max = tau_cont + (1 - gamma)(tau_peak - tau_cont)``,
  ``d gamma/dt = (0.3/180)(|tau|/tau_cont - 1)``, gamma in [0, 1], gamma(0) = ``heat_index_init_frac``;
  the same limit bounds motoring and regenerative torque;
* propulsion beyond the limit is not delivered (no other source); braking beyond the regen limit
  (and all braking below ``regen_speed_min_mps``, where an induction machine cannot regenerate
  usefully) goes to the friction brakes: ``brake_force_n = -(F_req - F_regen)``;
* regenerative electrical power limited to ``regen_power_max_w`` (default inf = off; the rest of
  the braking goes to the friction brakes, as beyond the bus limits);
* electrical power ``P = tau w / eta`` (motoring) or ``tau w eta`` (generating), map
  ``eta(w, tau)`` times ``efficiency_scale_frac`` (default 1), and when generating times
  ``regen_efficiency_scale_frac`` too (default 1), capped at 1.

The step itself is :func:`shevsim.powertrain.motor.motor_step` (compiled, shared with the vehicle
calibration); the component holds the state and books the energies.

The torque and the powers are held over the step (feedthrough of the held inputs), so the
cumulative energies integrate exactly what was output: ``elec_energy_j = mech_energy_j +
loss_energy_j``. The vehicle books traction work at the step-mean speed ``(v0 + v1)/2``; to match
it the motor evaluates its shaft power at the mid-step speed extrapolated linearly from its last
two speed inputs, ``v_mid = v0 + (v0 - v_prev) h / (2 h_prev)`` (``extrapolate_speed``; standard
co-simulation input extrapolation). The remaining motor/vehicle mismatch is second order in h
(HD-UDDS at h = 0.1 s: 0.03 % of the traction energy; without extrapolation 0.56 %).

Ports
-----
Inputs
    ``force_req_n`` [N] signed wheel force demand (+ propel, - brake); ``speed_mps`` [m/s];
    ``elec_power_max_w`` [W] (>= 0) and ``elec_power_min_w`` [W] (<= 0): the electrical power the
    bus can supply / absorb (battery power capability from the BMS plus generator output, see
    :mod:`shevsim.components.bus`); unconnected they are +-1e12 (no limit). The torque is scaled
    so the electrical power stays inside them (braking beyond goes to the friction brakes).
Outputs (all direct feedthrough of the inputs)
    ``traction_force_n`` [N] signed force delivered by the motors at the wheels;
    ``brake_force_n`` [N] friction brake force (>= 0); ``elec_power_w`` [W] + drawn from the bus;
    ``torque_nm`` [N m] total motor torque; ``speed_radps`` [rad/s] motor speed;
    ``torque_max_nm`` [N m] current torque limit; ``heat_index_frac`` [1] gamma (at t + h);
    cumulative ``loss_energy_j``, ``elec_energy_j``, ``mech_energy_j`` [J].
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.params import rng
from shevsim.core.variables import inp, out
from shevsim.powertrain.maps import load_curve_csv, load_grid_csv, scaled_curve, scaled_grid
from shevsim.powertrain import motor as _motor
from shevsim.powertrain.motor import HEAT_RATE_PER_S, MotorMaps, motor_component_step, motor_params
from shevsim.core.paths import data_path

_DIR = data_path("components", "motor")


@dataclass(frozen=True)
class MotorParams:
    """Motor parameters (defaults: components/motor/default.toml).

    Attributes
    ----------
    efficiency_map_file : str
        CSV ``speed_radps, torque_nm, efficiency_frac`` (equivalent machine).
    torque_curves_file : str
        CSV ``speed_radps, peak_torque_nm, cont_torque_nm``.
    gear_ratio : float
        Hub reduction, motor speed / wheel speed [-].
    wheel_radius_m : float
        Loaded tyre radius [m].
    heat_index_init_frac : float
        gamma(0) [-] (seed B.3: 0.3).
    heat_rate_per_s : float
        Heat-index rate at |tau| = 2 tau_cont [1/s] (seed: 0.3/180).
    regen_speed_min_mps : float
        Below this vehicle speed braking is all friction [m/s].
    extrapolate_speed : bool
        Evaluate the shaft power at the extrapolated mid-step speed (see module docstring).
    regen_power_max_w : float
        Most electrical power the drive returns while regenerating [W] (inverter/machine limit; braking
        beyond it goes to the friction brakes). Default inf = no limit (off).
    efficiency_scale_frac : float
        Actual / map efficiency [-]: ``eta = min(s eta_map(w, tau), 1)``. Default 1 (the map as built).
    regen_efficiency_scale_frac : float
        Generating / motoring efficiency ratio on top of it [-]: when regenerating ``eta = min(s s_regen
        eta_map(w, tau), 1)``. Default 1 (the map holds for both directions).
    rated_power_w, maps_rated_power_w : float
        Rated (peak) power [W] of this drive and the rating the map files describe (380 kW = 4 x 95 kW
        for the bundled maps).  Sizing by rating: with ``k = rated_power_w / maps_rated_power_w`` the peak
        and continuous torque x k and the efficiency map's torque axis x k (efficiency at the same speed
        and relative torque unchanged; speeds unchanged), the rule of Autonomie and FASTSim.  ``k = 1``
        (default) is the maps as built, exactly.  In a scenario: the shared quantity ``motor_power_w``.
    """

    efficiency_map_file: str = str(_DIR / "motor_eff_map.csv")
    torque_curves_file: str = str(_DIR / "motor_torque_curves.csv")
    gear_ratio: float = 19.0
    wheel_radius_m: float = 0.55
    heat_index_init_frac: float = 0.3
    heat_rate_per_s: float = HEAT_RATE_PER_S
    regen_speed_min_mps: float = 0.5
    extrapolate_speed: bool = True
    regen_power_max_w: float = field(default=float("inf"), metadata=rng(lo=0.0, allow_inf=True))
    efficiency_scale_frac: float = 1.0
    regen_efficiency_scale_frac: float = 1.0
    rated_power_w: float = 380e3
    maps_rated_power_w: float = 380e3

    def __post_init__(self):
        for k in ("gear_ratio", "wheel_radius_m", "rated_power_w", "maps_rated_power_w"):
            if not getattr(self, k) > 0:
                raise ValueError(f"parameter '{k}' must be > 0, got {getattr(self, k)!r}")
        if not 0.0 <= self.heat_index_init_frac <= 1.0:
            raise ValueError(f"parameter 'heat_index_init_frac' must be in [0, 1], got {self.heat_index_init_frac!r}")
        if not (self.heat_rate_per_s >= 0 and self.regen_speed_min_mps >= 0):
            raise ValueError("parameters 'heat_rate_per_s' and 'regen_speed_min_mps' must be >= 0")
        if not self.regen_power_max_w >= 0:
            raise ValueError(f"parameter 'regen_power_max_w' must be >= 0, got {self.regen_power_max_w!r}")
        if not 0.0 < self.efficiency_scale_frac <= 2.0:
            raise ValueError(f"parameter 'efficiency_scale_frac' must be in (0, 2], got {self.efficiency_scale_frac!r}")
        if not 0.0 < self.regen_efficiency_scale_frac <= 2.0:
            raise ValueError(f"parameter 'regen_efficiency_scale_frac' must be in (0, 2], got "
                             f"{self.regen_efficiency_scale_frac!r}")


class Motor(CompiledStep, Component):
    """Equivalent traction motor with heat-index derating (see module docstring for ports)."""

    TYPE = "motor"
    INPUT_DEFAULTS = ("elec_power_max_w", "elec_power_min_w")   # no limit
    Params = MotorParams
    _FT = ("force_req_n", "speed_mps", "elec_power_max_w", "elec_power_min_w")
    VARIABLES = (
        inp("force_req_n", "N", 0.0, "signed wheel force demand, + propel / - brake"),
        inp("speed_mps", "m/s", 0.0, "vehicle speed"),
        inp("elec_power_max_w", "W", 1e12, "most electrical power the bus can supply to the motors (>= 0)"),
        inp("elec_power_min_w", "W", -1e12, "most regenerative power the bus can absorb (<= 0)"),
        out("traction_force_n", "N", 0.0, "signed force delivered at the wheels by the motors", _FT),
        out("brake_force_n", "N", 0.0, "friction brake force, >= 0", _FT),
        out("elec_power_w", "W", 0.0, "electrical power, + drawn from the bus", _FT),
        out("torque_nm", "N.m", 0.0, "total motor torque (+ motoring)", _FT),
        out("speed_radps", "rad/s", 0.0, "motor speed", _FT),
        out("torque_max_nm", "N.m", 0.0, "torque limit after heat-index derating", _FT),
        out("heat_index_frac", "1", 0.0, "heat index gamma (0 cold .. 1 limited to continuous)", _FT),
        out("loss_energy_j", "J", 0.0, "cumulative motor+inverter loss", _FT),
        out("elec_energy_j", "J", 0.0, "cumulative electrical energy drawn (signed)", _FT),
        out("mech_energy_j", "J", 0.0, "cumulative shaft energy delivered (signed)", _FT),
    )
    _static = ("name", "params", "maps", "_k_tau", "_k_w", "extrapolate", "_md", "_mi", "_v_regen", "_p_regen",
               "_eff_scale", "_heat_rate", "_regen_eff_scale", "_fn", "_u_names", "_y_names")
    DATA_MUTABLE = (3,)

    def __init__(self, name: str = "motor", params: MotorParams | None = None):
        super().__init__(name, params)
        p = self.params
        k = p.rated_power_w / p.maps_rated_power_w       # sized by rating (1: the maps as built)
        self.maps = MotorMaps(
            scaled_grid(load_grid_csv(p.efficiency_map_file, "speed_radps", "torque_nm", "efficiency_frac", "clamp"),
                        k, 1.0),
            scaled_curve(load_curve_csv(p.torque_curves_file, "speed_radps", "peak_torque_nm"), 1.0, k),
            scaled_curve(load_curve_csv(p.torque_curves_file, "speed_radps", "cont_torque_nm"), 1.0, k))
        self._k_tau = p.wheel_radius_m / p.gear_ratio      # N m of motor torque per N at the wheel
        self._k_w = p.gear_ratio / p.wheel_radius_m        # rad/s of motor per m/s
        self.extrapolate = bool(p.extrapolate_speed)
        self._md, self._mi = self.maps.packed()
        self._v_regen = float(p.regen_speed_min_mps)
        self._p_regen = float(p.regen_power_max_w)
        self._eff_scale = float(p.efficiency_scale_frac)
        self._heat_rate = float(p.heat_rate_per_s)
        self._regen_eff_scale = float(p.regen_efficiency_scale_frac)

    def initialize(self, t0: float) -> None:
        """``data`` = ``(md, mi, p, x)``: the packed maps, ``p`` (:data:`P`) and the state ``x`` (:data:`X`)."""
        gamma = self.params.heat_index_init_frac
        v_prev = max(self.u["speed_mps"], 0.0)
        self.data = (self._md, self._mi,
                     motor_params(self._k_w, self._k_tau, self.extrapolate, self._v_regen, self._p_regen,
                                  self._eff_scale, self._heat_rate, self._regen_eff_scale),
                     np.array([gamma, 0.0, 0.0, 0.0, v_prev, 1.0], dtype=np.float64))
        w = v_prev * self._k_w
        self.y["heat_index_frac"] = gamma
        self.y["torque_max_nm"] = self.maps.limit(w, gamma)
        self.y["speed_radps"] = w
        for k in ("traction_force_n", "brake_force_n", "elec_power_w", "torque_nm",
                  "loss_energy_j", "elec_energy_j", "mech_energy_j"):
            self.y[k] = 0.0
        self._io()

    @property
    def gamma(self) -> float:
        """Heat index [1]."""
        return float(self.data[3][X.gamma])


U = port_index(Motor.VARIABLES, "input")
Y = port_index(Motor.VARIABLES, "output")
#: parameters ``data[2]`` and state ``data[3]`` of the step (declared with the physics)
P, X = _motor.P, _motor.X


@njit_step
def motor_step(data, u, y, t, h):
    """:class:`Motor`'s step (:func:`~shevsim.powertrain.motor.motor_component_step`)."""
    md, mi, p, x = data
    f_req = u[U.force_req_n]
    v = u[U.speed_mps]
    if f_req != f_req or v != v:
        return ERR_NAN_INPUT
    (y[Y.traction_force_n], y[Y.brake_force_n], y[Y.elec_power_w], y[Y.torque_nm], y[Y.speed_radps],
     y[Y.torque_max_nm]) = motor_component_step(md, mi, p, x, f_req, v, u[U.elec_power_max_w], u[U.elec_power_min_w], h)
    y[Y.heat_index_frac] = x[X.gamma]
    y[Y.loss_energy_j] = x[X.e_loss]
    y[Y.elec_energy_j] = x[X.e_elec]
    y[Y.mech_energy_j] = x[X.e_mech]
    return 0


Motor.STEP = motor_step
