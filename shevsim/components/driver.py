"""driver.py - driver component (TYPE ``driver``): PI on speed error with feed-forward.

See :mod:`shevsim.powertrain.driver` for the law. The feed-forward parameters are the driver's
model of the vehicle (defaults = the M-ATV of components/vehicle/matv.toml); the PI gains are
expressed in absolute units (N per m/s, N per m).

Ports
-----
Inputs
    ``speed_ref_mps`` [m/s], ``accel_ref_mps2`` [m/s2] (from the cycle), ``speed_mps`` [m/s] (vehicle).
Outputs (direct feedthrough of all three inputs)
    ``force_req_n`` [N] signed wheel force demand (+ propel / - brake);
    ``speed_error_mps`` [m/s] ``v_ref - v``; ``feedforward_n`` [N] the feed-forward part.
"""
from __future__ import annotations

from dataclasses import dataclass

from shevsim.core.component import Component
from shevsim.core.errors import SimulationError
from shevsim.core.variables import inp, out
from shevsim.powertrain.driver import driver_step
from shevsim.powertrain.vehicle import G_MPS2


@dataclass(frozen=True)
class DriverParams:
    """Driver parameters (defaults: components/driver/default.toml).

    Attributes
    ----------
    kp_n_per_mps : float
        Proportional gain [N/(m/s)].
    ki_n_per_m : float
        Integral gain [N/m] (= N/(m/s)/s).
    mass_kg, frontal_area_m2, drag_coefficient, rolling_coefficient, air_density_kg_m3 : float
        The driver's vehicle model for the feed-forward.
    force_prop_max_n, force_brake_max_n : float
        Output saturation [N] (propulsion > 0, braking magnitude > 0).
    """

    kp_n_per_mps: float = 31000.0
    ki_n_per_m: float = 6200.0
    mass_kg: float = 15554.0
    frontal_area_m2: float = 5.72
    drag_coefficient: float = 0.7
    rolling_coefficient: float = 0.012
    air_density_kg_m3: float = 1.2
    force_prop_max_n: float = 60000.0
    force_brake_max_n: float = 120000.0

    def __post_init__(self):
        for k in ("kp_n_per_mps", "ki_n_per_m", "mass_kg", "force_prop_max_n", "force_brake_max_n"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"parameter '{k}' must be >= 0, got {getattr(self, k)!r}")


class Driver(Component):
    """PI + feed-forward speed-following driver (see module docstring for ports)."""

    TYPE = "driver"
    Params = DriverParams
    _FT = ("speed_ref_mps", "accel_ref_mps2", "speed_mps")
    VARIABLES = (
        inp("speed_ref_mps", "m/s", 0.0, "reference speed"),
        inp("accel_ref_mps2", "m/s2", 0.0, "reference acceleration"),
        inp("speed_mps", "m/s", 0.0, "vehicle speed"),
        out("force_req_n", "N", 0.0, "signed wheel force demand, + propel / - brake", _FT),
        out("speed_error_mps", "m/s", 0.0, "v_ref - v", _FT),
        out("feedforward_n", "N", 0.0, "feed-forward part of the demand", _FT),
    )
    _static = ("name", "params", "_c")

    def __init__(self, name: str = "driver", params: DriverParams | None = None):
        super().__init__(name, params)
        p = self.params
        self._c = 0.5 * p.air_density_kg_m3 * p.drag_coefficient * p.frontal_area_m2

    def initialize(self, t0: float) -> None:
        self.integ = 0.0
        for k in ("force_req_n", "speed_error_mps", "feedforward_n"):
            self.y[k] = 0.0

    def do_step(self, t: float, h: float) -> None:
        u, p = self.u, self.params
        vr, ar, v = u["speed_ref_mps"], u["accel_ref_mps2"], u["speed_mps"]
        if vr != vr or ar != ar or v != v:
            raise SimulationError(f"{self.name}: NaN input at t={t:g} s")
        f, e, ff, self.integ = driver_step(float(vr), float(ar), float(v), self.integ, float(h), p.kp_n_per_mps,
                                           p.ki_n_per_m, p.mass_kg, self._c, p.rolling_coefficient, G_MPS2,
                                           p.force_brake_max_n, p.force_prop_max_n)
        y = self.y
        y["force_req_n"] = f
        y["speed_error_mps"] = e
        y["feedforward_n"] = ff
