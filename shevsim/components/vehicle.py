"""vehicle.py - point-mass vehicle component (TYPE ``vehicle``), seed B.6-B.8.

Wraps :func:`shevsim.powertrain.vehicle.step_vehicle`: semi-implicit aero drag, speed >= 0, and
exact per-step energy bookkeeping (work of each force = force x mean speed x h), so that
``traction_energy_j - brake_energy_j - rolling_energy_j - aero_energy_j - grade_energy_j ==
kinetic_energy_j - kinetic_energy_j(t0)`` to round-off.

Rotating inertia (parameter ``wheel_inertia_kg_m2`` = ``J``, default 0 = the seed's point mass): the wheels
(and any drivetrain inertia referred to them) add the equivalent mass ``M_r = J / r^2`` (``r`` =
``wheel_radius_m``) to the inertia, not to the weight: ``(M + M_r) dv/dt = F_prop - F_brk - F_rr - F_wr -
M g sin(theta)``, and ``kinetic_energy_j`` = ``1/2 (M + M_r) v^2`` (translational + rotational).

Road grade along distance (parameters ``grade_distance_m`` / ``grade_frac``, default empty = off): the
grade ``tan(theta)`` interpolated between the knots at the distance travelled, held beyond the end knots
(:func:`shevsim.powertrain.vehicle.grade_rad_at`), is *added* to the ``grade_rad`` input.

Ports (``input_mode = "force"``, the default: forward dynamics)
---------------------------------------------------------------
Inputs
    ``traction_force_n`` [N]  signed wheel force from the motor (+ propel, - regenerative braking).
    ``brake_force_n`` [N]  friction brake force (>= 0).
    ``grade_rad`` [rad]  road grade (+ uphill), start 0 (the seed's cycles are flat).
Outputs (state at t + h; none is direct feedthrough)
    ``speed_mps`` [m/s] (>= 0), ``accel_mps2`` [m/s2] mean over the step, ``distance_m`` [m];
    cumulative works [J]: ``traction_energy_j`` (signed: regen counts negative),
    ``brake_energy_j``, ``rolling_energy_j``, ``aero_energy_j``, ``grade_energy_j`` (energy taken
    from the vehicle, >= 0 except grade downhill), and ``kinetic_energy_j`` = 1/2 (M + J / r^2) v^2 (state:
    translational + the rotating parts').

Ports (``input_mode = "speed"``: speed-following / backward, e.g. replaying a measured speed trace)
----------------------------------------------------------------------------------------------------
The motion is prescribed: inputs ``speed_ref_mps`` [m/s] and ``accel_ref_mps2`` [m/s2] (the speed at
t + h and the slope of the segment driven next, as a ``cycle`` outputs them) and ``grade_rad``. The
vehicle takes ``speed_mps = max(speed_ref_mps, 0)`` and outputs ``force_req_n`` [N], the wheel force
that drives the next step, ``traction_force_n(v, v + a h)`` (:mod:`shevsim.powertrain.vehicle`, the
inverse of the forward step; 0 at ``initialize``), for a motor's ``force_req_n``. The works are booked
with the force that produced the step's actual speed change (the brake work stays 0: the split of a
negative force between regeneration and friction brakes is the motor's). All outputs are direct
feedthrough of ``speed_ref_mps``; ``force_req_n`` also of ``accel_ref_mps2`` and ``grade_rad``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.params import rng
from shevsim.core.variables import inp, out
from shevsim.powertrain.vehicle import (G_MPS2, XF, XS, grade_total_rad, vehicle_force_step, vehicle_params,
                                       vehicle_speed_mode_step)

INPUT_MODES = ("force", "speed")


@dataclass(frozen=True)
class VehicleParams:
    """Point-mass vehicle parameters (defaults: hybridised M-ATV, see components/vehicle/matv.toml).

    Attributes
    ----------
    mass_kg : float
        Vehicle mass (seed Table 5.1: 15554 kg): the translational mass, which weighs (grade, rolling).
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
    wheel_inertia_kg_m2 : float
        Moment of inertia ``J`` [kg m2] of all wheels together (per wheel x number of wheels), plus whatever
        drivetrain inertia is referred to the wheels (a motor's ``J_m G^2`` behind a ratio ``G``); >= 0,
        default 0 (the seed's point mass).  It adds the equivalent mass ``J / r^2`` to the inertia only.
    wheel_radius_m : float
        Wheel (loaded tyre) radius ``r`` [m] of that equivalent mass; the shared quantity ``wheel_radius_m``
        (the motor's too).  Default 0.55 m (the M-ATV's, ``vehicles/matv.toml``).
    speed_init_mps : float
        Initial speed [m/s] (force mode; in speed mode the prescribed speed).
    grade_distance_m, grade_frac : tuple of float
        Road grade knots: distance [m] (strictly increasing) and grade ``tan(theta)`` [-], same length;
        empty (default) = no grade from the parameters. Added to the ``grade_rad`` input.
    input_mode : {"force", "speed"}
        ``"force"``: forward dynamics from the traction/brake forces; ``"speed"``: the motion follows
        the ``speed_ref_mps`` input and the required wheel force is an output (see module docstring).
    """

    mass_kg: float = 15554.0
    frontal_area_m2: float = 5.72
    drag_coefficient: float = 0.7
    rolling_coefficient: float = 0.012
    air_density_kg_m3: float = 1.2
    gravity_mps2: float = field(default=G_MPS2, metadata=rng(gt=0.0))
    wheel_inertia_kg_m2: float = field(default=0.0, metadata=rng(0.0, what="a moment of inertia, 0 = none"))
    wheel_radius_m: float = field(default=0.55, metadata=rng(gt=0.0, what="a wheel radius"))
    speed_init_mps: float = 0.0
    grade_distance_m: tuple[float, ...] = ()
    grade_frac: tuple[float, ...] = field(default=(), metadata=rng(-1.0, 1.0, what="road grade rise/run"))
    input_mode: str = "force"

    def __post_init__(self):
        for k in ("mass_kg", "frontal_area_m2", "air_density_kg_m3", "gravity_mps2", "wheel_radius_m"):
            if not getattr(self, k) > 0:
                raise ValueError(f"parameter '{k}' must be > 0, got {getattr(self, k)!r}")
        for k in ("drag_coefficient", "rolling_coefficient", "wheel_inertia_kg_m2", "speed_init_mps"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"parameter '{k}' must be >= 0, got {getattr(self, k)!r}")
        if self.input_mode not in INPUT_MODES:
            raise ValueError(f"parameter 'input_mode' must be one of {INPUT_MODES}, got {self.input_mode!r}")
        d, g = tuple(self.grade_distance_m), tuple(self.grade_frac)
        if len(d) != len(g):
            raise ValueError(f"parameters 'grade_distance_m' and 'grade_frac' must have the same length, "
                             f"got {len(d)} and {len(g)}")
        if not all(math.isfinite(x) for x in d + g):
            raise ValueError("parameters 'grade_distance_m' / 'grade_frac' must be finite")
        if any(b <= a for a, b in zip(d, d[1:])):
            raise ValueError(f"parameter 'grade_distance_m' must be strictly increasing, got {d!r}")

    @property
    def c_aero(self) -> float:
        """1/2 rho C_d A [kg/m]."""
        return 0.5 * self.air_density_kg_m3 * self.drag_coefficient * self.frontal_area_m2

    @property
    def mass_rot_kg(self) -> float:
        """Equivalent mass of the rotating parts ``J / r^2`` [kg] (``wheel_inertia_kg_m2 / wheel_radius_m^2``)."""
        return self.wheel_inertia_kg_m2 / (self.wheel_radius_m * self.wheel_radius_m)


class Vehicle(CompiledStep, Component):
    """Point-mass longitudinal vehicle (see module docstring for ports)."""

    TYPE = "vehicle"
    INPUT_DEFAULTS = ("brake_force_n", "grade_rad", "accel_ref_mps2")   # no friction brake, flat road
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
        out("kinetic_energy_j", "J", 0.0, "kinetic energy 1/2 (M + J/r^2) v^2, translational + rotating parts"),
    )

    _SPEED_INPUTS = ("speed_ref_mps", "accel_ref_mps2", "grade_rad")
    VARIABLES_SPEED = (
        inp("speed_ref_mps", "m/s", 0.0, "prescribed speed (speed mode), >= 0"),
        inp("accel_ref_mps2", "m/s2", 0.0, "prescribed acceleration over the next step (speed mode)"),
        inp("grade_rad", "rad", 0.0, "road grade, + uphill"),
        out("force_req_n", "N", 0.0, "wheel force that drives the next step (speed mode), + propel", _SPEED_INPUTS),
    ) + tuple(out(v.name, v.unit, v.start, v.description, ("speed_ref_mps",))
              for v in VARIABLES if v.causality == "output")

    def __init__(self, name: str = "vehicle", params: VehicleParams | None = None):
        super().__init__(name, params)
        p = self.params
        self._m, self._c, self._fr, self._g = p.mass_kg, p.c_aero, p.rolling_coefficient, p.gravity_mps2
        self._mr = p.mass_rot_kg
        self._kd = np.array(p.grade_distance_m, dtype=float)
        self._kg = np.array(p.grade_frac, dtype=float)
        self._knots = self._kd.size > 0
        self._speed = p.input_mode == "speed"

    DATA_MUTABLE = (3,)
    _static = ("name", "params", "_m", "_c", "_fr", "_g", "_mr", "_kd", "_kg", "_knots", "_speed", "_fn", "_u_names",
               "_y_names")

    def variables(self):
        """Force mode: :attr:`VARIABLES`; speed mode: :attr:`VARIABLES_SPEED`."""
        p = getattr(self, "params", None)
        return self.VARIABLES_SPEED if p is not None and p.input_mode == "speed" else self.VARIABLES

    def step_function(self):
        return vehicle_speed_step if self._speed else vehicle_step

    @classmethod
    def fast_examples(cls) -> dict:
        out_ = {}
        for mode in ("force", "speed"):
            c = cls(cls.TYPE, VehicleParams(input_mode=mode))
            c.initialize(0.0)
            out_[c.step_function()] = c
        return out_

    def _grade(self, th_in: float) -> float:
        return grade_total_rad(th_in, 0.0, self._kd, self._kg) if self._knots else th_in

    def initialize(self, t0: float) -> None:
        """``data`` = ``(p, grade_distance_m, grade_frac, x)``: ``p = [mass, 0.5 rho cd A, rolling, g, J / r^2]``
        (:data:`~shevsim.powertrain.vehicle.VP`), ``x`` = :data:`XF` (force mode) or :data:`XS` (speed mode)."""
        y = self.y
        p = vehicle_params(self._m, self._c, self._fr, self._g, self._mr)
        if self._speed:
            v = max(self.u["speed_ref_mps"], 0.0)
            x = [v, 0.0, self._grade(self.u["grade_rad"]), 0.0, 0.0, 0.0, 0.0, 0.0]
            y["force_req_n"] = 0.0
        else:
            v = self.params.speed_init_mps
            x = [v, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self.data = (p, np.ascontiguousarray(self._kd, dtype=np.float64),
                     np.ascontiguousarray(self._kg, dtype=np.float64), np.array(x, dtype=np.float64))
        y["speed_mps"] = v
        y["accel_mps2"] = 0.0
        y["distance_m"] = 0.0
        for k in ("traction_energy_j", "brake_energy_j", "rolling_energy_j", "aero_energy_j", "grade_energy_j"):
            y[k] = 0.0
        y["kinetic_energy_j"] = 0.5 * (self._m + self._mr) * v * v
        self._io()

    @property
    def v(self) -> float:
        """Speed [m/s] (settable: a coast-down from a given speed)."""
        return float(self.data[3][0])

    @v.setter
    def v(self, value: float) -> None:
        self.data[3][0] = float(value)

    @property
    def dist(self) -> float:
        """Distance travelled [m]."""
        return float(self.data[3][1])

    @property
    def e(self) -> list:
        """Cumulative traction, brake, rolling, aero and grade works [J]."""
        x = self.data[3]
        return x[2:7].tolist() if not self._speed else x[3:8].tolist()


U = port_index(Vehicle.VARIABLES, "input")
Y = port_index(Vehicle.VARIABLES, "output")
US = port_index(Vehicle.VARIABLES_SPEED, "input")
YS = port_index(Vehicle.VARIABLES_SPEED, "output")


@njit_step
def vehicle_step(data, u, y, t, h):
    """:class:`Vehicle`'s step in force mode (:func:`~shevsim.powertrain.vehicle.vehicle_force_step`)."""
    p, kd, kg, x = data
    f_t = u[U.traction_force_n]
    f_b = u[U.brake_force_n]
    th = u[U.grade_rad]
    if f_t != f_t or f_b != f_b or th != th:
        return ERR_NAN_INPUT
    y[Y.accel_mps2], y[Y.kinetic_energy_j] = vehicle_force_step(p, kd, kg, x, f_t, f_b, th, h)
    y[Y.speed_mps] = x[XF.v]
    y[Y.distance_m] = x[XF.dist]
    y[Y.traction_energy_j] = x[XF.e_traction]
    y[Y.aero_energy_j] = x[XF.e_aero]
    y[Y.rolling_energy_j] = x[XF.e_rolling]
    y[Y.brake_energy_j] = x[XF.e_brake]
    y[Y.grade_energy_j] = x[XF.e_grade]
    return 0


@njit_step
def vehicle_speed_step(data, u, y, t, h):
    """:class:`Vehicle`'s step in speed mode (:func:`~shevsim.powertrain.vehicle.vehicle_speed_mode_step`: follow
    ``speed_ref_mps``, book the works, output the force for the next step)."""
    p, kd, kg, x = data
    vr = u[US.speed_ref_mps]
    ar = u[US.accel_ref_mps2]
    th = u[US.grade_rad]
    if vr != vr or ar != ar or th != th:
        return ERR_NAN_INPUT
    y[YS.accel_mps2], y[YS.force_req_n], y[YS.kinetic_energy_j] = vehicle_speed_mode_step(p, kd, kg, x, vr, ar, th, h)
    y[YS.speed_mps] = x[XS.v]
    y[YS.distance_m] = x[XS.dist]
    y[YS.traction_energy_j] = x[XS.e_traction]
    y[YS.aero_energy_j] = x[XS.e_aero]
    y[YS.rolling_energy_j] = x[XS.e_rolling]
    y[YS.brake_energy_j] = x[XS.e_brake]
    y[YS.grade_energy_j] = x[XS.e_grade]
    return 0


Vehicle.STEP = vehicle_step
