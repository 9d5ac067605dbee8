"""vehicle.py - point-mass vehicle component (TYPE ``vehicle``), seed B.6-B.8.

Wraps :func:`shevsim.powertrain.vehicle.step_vehicle`: semi-implicit aero drag, speed >= 0, and
exact per-step energy bookkeeping (work of each force = force x mean speed x h), so that
``traction_energy_j - brake_energy_j - rolling_energy_j - aero_energy_j - grade_energy_j ==
kinetic_energy_j - kinetic_energy_j(t0)`` to round-off.

Ports
-----
Inputs
    ``traction_force_n`` [N]  signed wheel force from the motor (+ propel, - regenerative braking).
    ``brake_force_n`` [N]  friction brake force (>= 0).
    ``grade_rad`` [rad]  road grade (+ uphill), start 0 (the seed's cycles are flat).
Outputs (state at t + h; none is direct feedthrough)
    ``speed_mps`` [m/s] (>= 0), ``accel_mps2`` [m/s2] mean over the step, ``distance_m`` [m];
    cumulative works [J]: ``traction_energy_j`` (signed: regen counts negative),
    ``brake_energy_j``, ``rolling_energy_j``, ``aero_energy_j``, ``grade_energy_j`` (energy taken
    from the vehicle, >= 0 except grade downhill), and ``kinetic_energy_j`` = 1/2 M v^2 (state).
"""
from __future__ import annotations

from dataclasses import dataclass

from shevsim.core.component import Component
from shevsim.core.errors import SimulationError
from shevsim.core.variables import inp, out
from shevsim.powertrain.vehicle import G_MPS2, step_vehicle


@dataclass(frozen=True)
class VehicleParams:
    """Point-mass vehicle parameters (defaults: hybridised M-ATV, see components/vehicle/matv.toml).

    Attributes
    ----------
    mass_kg : float
        Vehicle mass (seed Table 5.1: 15554 kg).
    frontal_area_m2 : float
        Frontal area (seed Table 5.1: 5.72 m2).
    drag_coefficient : float
        C_d [-] (assumed 0.7, boxy MRAP body).
    rolling_coefficient : float
        f_r [-] (assumed 0.012, large off-road tyres on pavement).
    air_density_kg_m3 : float
        rho [kg/m3].
    gravity_mps2 : float
        g [m/s2].
    speed_init_mps : float
        Initial speed [m/s].
    """

    mass_kg: float = 15554.0
    frontal_area_m2: float = 5.72
    drag_coefficient: float = 0.7
    rolling_coefficient: float = 0.012
    air_density_kg_m3: float = 1.2
    gravity_mps2: float = G_MPS2
    speed_init_mps: float = 0.0

    def __post_init__(self):
        for k in ("mass_kg", "frontal_area_m2", "air_density_kg_m3", "gravity_mps2"):
            if not getattr(self, k) > 0:
                raise ValueError(f"parameter '{k}' must be > 0, got {getattr(self, k)!r}")
        for k in ("drag_coefficient", "rolling_coefficient", "speed_init_mps"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"parameter '{k}' must be >= 0, got {getattr(self, k)!r}")

    @property
    def c_aero(self) -> float:
        """1/2 rho C_d A [kg/m]."""
        return 0.5 * self.air_density_kg_m3 * self.drag_coefficient * self.frontal_area_m2


class Vehicle(Component):
    """Point-mass longitudinal vehicle (see module docstring for ports)."""

    TYPE = "vehicle"
    Params = VehicleParams
    VARIABLES = (
        inp("traction_force_n", "N", 0.0, "signed wheel force from the motors, + propel"),
        inp("brake_force_n", "N", 0.0, "friction brake force, >= 0"),
        inp("grade_rad", "rad", 0.0, "road grade, + uphill"),
        out("speed_mps", "m/s", 0.0, "vehicle speed, >= 0"),
        out("accel_mps2", "m/s2", 0.0, "mean acceleration over the last step"),
        out("distance_m", "m", 0.0, "distance travelled"),
        out("traction_energy_j", "J", 0.0, "cumulative work of the traction force (signed)"),
        out("aero_energy_j", "J", 0.0, "cumulative aerodynamic drag loss"),
        out("rolling_energy_j", "J", 0.0, "cumulative rolling resistance loss"),
        out("brake_energy_j", "J", 0.0, "cumulative friction brake loss"),
        out("grade_energy_j", "J", 0.0, "cumulative work against gravity (+ climbing)"),
        out("kinetic_energy_j", "J", 0.0, "kinetic energy 1/2 M v^2"),
    )

    def __init__(self, name: str = "vehicle", params: VehicleParams | None = None):
        super().__init__(name, params)
        p = self.params
        self._m, self._c, self._fr, self._g = p.mass_kg, p.c_aero, p.rolling_coefficient, p.gravity_mps2

    _static = ("name", "params", "_m", "_c", "_fr", "_g")

    def initialize(self, t0: float) -> None:
        self.v = self.params.speed_init_mps
        self.e = [0.0, 0.0, 0.0, 0.0, 0.0]
        self.dist = 0.0
        y = self.y
        y["speed_mps"] = self.v
        y["accel_mps2"] = 0.0
        y["distance_m"] = 0.0
        for k in ("traction_energy_j", "brake_energy_j", "rolling_energy_j", "aero_energy_j", "grade_energy_j"):
            y[k] = 0.0
        y["kinetic_energy_j"] = 0.5 * self._m * self.v * self.v

    def do_step(self, t: float, h: float) -> None:
        u = self.u
        f_t, f_b, th = u["traction_force_n"], u["brake_force_n"], u["grade_rad"]
        if f_t != f_t or f_b != f_b or th != th:
            raise SimulationError(f"{self.name}: NaN input at t={t:g} s "
                                  f"(traction_force_n={f_t}, brake_force_n={f_b}, grade_rad={th})")
        v0 = self.v
        v1, dist, wp, wb, wr, wa, wg = step_vehicle(v0, f_t, f_b, th, h, self._m, self._c, self._fr, self._g)
        self.v = v1
        e = self.e
        e[0] += wp
        e[1] += wb
        e[2] += wr
        e[3] += wa
        e[4] += wg
        self.dist += dist
        y = self.y
        y["speed_mps"] = v1
        y["accel_mps2"] = (v1 - v0) / h
        y["distance_m"] = self.dist
        y["traction_energy_j"] = e[0]
        y["brake_energy_j"] = e[1]
        y["rolling_energy_j"] = e[2]
        y["aero_energy_j"] = e[3]
        y["grade_energy_j"] = e[4]
        y["kinetic_energy_j"] = 0.5 * self._m * v1 * v1
