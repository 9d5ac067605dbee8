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

import numpy as np

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.variables import inp, out
from shevsim.powertrain.driver import DP, driver_step
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


class Driver(CompiledStep, Component):
    """PI + feed-forward speed-following driver (see module docstring for ports)."""

    TYPE = "driver"
    INPUT_DEFAULTS = ("accel_ref_mps2",)         # 0: no feed-forward of the reference acceleration
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
    DATA_MUTABLE = (1,)
    _static = ("name", "params", "_c", "_fn", "_u_names", "_y_names")

    def __init__(self, name: str = "driver", params: DriverParams | None = None):
        super().__init__(name, params)
        p = self.params
        self._c = 0.5 * p.air_density_kg_m3 * p.drag_coefficient * p.frontal_area_m2

    def initialize(self, t0: float) -> None:
        """``data`` = ``(p, x = [integrator])`` (``p`` in the order of :data:`P`)."""
        p = self.params
        self.data = (np.array([p.kp_n_per_mps, p.ki_n_per_m, p.mass_kg, self._c, p.rolling_coefficient, G_MPS2,
                               p.force_brake_max_n, p.force_prop_max_n], dtype=np.float64), np.zeros(1))
        for k in ("force_req_n", "speed_error_mps", "feedforward_n"):
            self.y[k] = 0.0
        self._io()

    @property
    def integ(self) -> float:
        """The PI integrator [N]."""
        return float(self.data[1][0])


U = port_index(Driver.VARIABLES, "input")
Y = port_index(Driver.VARIABLES, "output")
#: the step's parameters ``data[0]`` (declared with the physics)
P = DP


@njit_step
def driver_component_step(data, u, y, t, h):
    """:class:`Driver`'s step: :func:`~shevsim.powertrain.driver.driver_step` at the held inputs."""
    p, x = data
    vr = u[U.speed_ref_mps]
    ar = u[U.accel_ref_mps2]
    v = u[U.speed_mps]
    if vr != vr or ar != ar or v != v:
        return ERR_NAN_INPUT
    f, e, ff, x[0] = driver_step(p, vr, ar, v, x[0], h)
    y[Y.force_req_n] = f
    y[Y.speed_error_mps] = e
    y[Y.feedforward_n] = ff
    return 0


Driver.STEP = driver_component_step
