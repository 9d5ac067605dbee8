"""vehicle.py - point-mass longitudinal vehicle dynamics (seed B.6-B.8) with exact energy bookkeeping.

    (M + M_r) dv/dt = F_prop - F_brk - F_rr - F_wr - M g sin(theta)   (B.6 plus road grade and wheel inertia)
    F_rr = f_r M g cos(theta)   (while rolling)                        (B.7)
    F_wr = 1/2 rho C_d A v^2                                           (B.8)
    M_r = J / r^2                                                      (rotating inertia referred to the wheel)

``M`` is the translational mass (it alone weighs: grade and rolling forces); ``M_r`` the equivalent mass of
the rotating parts, ``J`` [kg m2] the moment of inertia of all wheels (plus whatever drivetrain inertia a user
refers to the wheels: ``J_motor G^2`` for a motor of inertia ``J_motor`` behind a ratio ``G``) and ``r`` the
wheel radius [m]: a wheel rolling without slip at ``omega = v / r`` stores ``1/2 J omega^2 = 1/2 M_r v^2``, so the
kinetic energy is ``KE = 1/2 (M + M_r) v^2`` (the vehicle component's ``kinetic_energy_j``), and the
rotating parts act on the acceleration only.  ``M_r = 0`` (the default, the seed's point mass) gives the
seed's equations, bit for bit (``M + 0.0`` is ``M``).  FASTSim books the same term
(``wheel_inertia_kilogram_square_meters x num_wheels / wheel_radius_meters^2``, its ``pwr_whl_inertia``).

Speed never goes negative: brakes and rolling resistance only stop the vehicle; at standstill it
moves only when ``F_prop - M g sin(theta) > F_brk + F_rr`` (the wheel brakes/static friction hold it
otherwise; a vehicle on a slope does not roll backwards - documented simplification).

Discretisation of one step of length ``h`` with the forces ``F_prop``, ``F_brk``, ``theta`` held, and
``M_e = M + M_r`` the inertial mass: aero drag is semi-implicit, ``F_wr = c v0 v1`` with ``c = 1/2 rho C_d A``,
so

    v1 = (M_e v0 + h (F_prop - F_brk - F_rr - F_g)) / (M_e + h c v0),

which is unconditionally stable and, as ``h -> 0``, first-order accurate. Every force is a
constant over the step and its work is ``W_i = F_i (v0 + v1)/2 h``; then
``sum_i W_i = M_e (v1 - v0)(v0 + v1)/2 = Delta KE`` *exactly*, with

    Delta KE = Delta (1/2 M v^2) + Delta (1/2 M_r v^2)      (translational + rotational),

so the energy balance

    traction - brake - rolling - aero - grade = Delta KE

closes to round-off on any step size (the rotating parts' energy is part of ``KE``; no force of its own).
When the update would give ``v1 < 0`` the vehicle stops inside the step, at ``t_s = M_e v0 / R`` with ``R``
the net retarding force, after ``v0 t_s / 2`` metres; each force works over that distance
(``sum W = -M_e v0^2 / 2`` exactly), and it is then held at rest. The returned works are what the component
uses for its distance too.

Speed-following (backward) use: :func:`traction_force_n` is the exact inverse of :func:`step_vehicle`
(the propulsion force that takes the point mass from ``v0`` to ``v1`` in ``h``, brakes off):

    F = (M + M_r)(v1 - v0)/h + c v0 v1 + F_rr + M g sin(theta)    (0 when at rest at both ends)

Both go through :func:`road_forces`, the one road-load law (there is no other). One step of the
speed-following vehicle is :func:`speed_follow_step` (prescribed speed -> works, distance, grade, the
force request for the next step): the ``vehicle`` component in ``input_mode = "speed"`` and the vehicle
calibration's compiled loop (:mod:`shevsim.calibrate.vehicle`) both call it, so the calibration IS the
component. Road grade along distance (:func:`grade_rad_at`, added to the ``grade_rad`` input by
:func:`grade_total_rad`): piecewise-linear grade ``tan(theta)`` between knots ``(d_j, g_j)``, held beyond
the end knots.

Every function here except the analytical coast-down references is compiled with numba (``f.py_func``
is the Python source); the components call the compiled functions, the calibration calls them from its
compiled loop.
"""
from __future__ import annotations

import math

import numpy as np

from shevsim.core.compiled import field_index, njit_step
from shevsim.core.lookup import njit, interp_held

G_MPS2 = 9.80665

#: the vehicle's parameters ``p`` (:func:`speed_follow_step`, :func:`vehicle_force_step`,
#: :func:`vehicle_speed_mode_step`; the vehicle component's ``data[0]``, built by :func:`vehicle_params`):
#: translational mass [kg], ``c_aero = 1/2 rho C_d A`` [kg/m], rolling coefficient [-], gravity [m/s2] and the
#: rotating parts' equivalent mass ``M_r = J / r^2`` [kg]
VP = field_index(("mass_kg", "c_aero", "f_roll_coeff", "g_mps2", "mass_rot_kg"), "VP")
#: the vehicle component's state in force mode and in speed mode (``th``: the grade acting over the next step)
XF = field_index(("v", "dist", "e_traction", "e_brake", "e_rolling", "e_aero", "e_grade"), "XF")
XS = field_index(("v", "dist", "th", "e_traction", "e_brake", "e_rolling", "e_aero", "e_grade"), "XS")


def vehicle_params(mass_kg: float, c_aero: float, f_roll_coeff: float, g_mps2: float = G_MPS2,
                   mass_rot_kg: float = 0.0):
    """The parameter array ``p`` of :data:`VP` (float64, in its order): the one place it is built, for the
    component, the calibration's loop and the tests alike."""
    p = np.empty(len(VP), dtype=np.float64)
    p[VP.mass_kg], p[VP.c_aero], p[VP.f_roll_coeff], p[VP.g_mps2], p[VP.mass_rot_kg] = (
        mass_kg, c_aero, f_roll_coeff, g_mps2, mass_rot_kg)
    return p


@njit(cache=True)
def road_forces(grade_rad: float, mass_kg: float, f_roll_coeff: float, g: float = G_MPS2) -> tuple[float, float]:
    """Grade force ``M g sin(theta)`` and rolling force ``f_r M g cos(theta)`` [N] (rolling applies while moving)."""
    return mass_kg * g * math.sin(grade_rad), f_roll_coeff * mass_kg * g * math.cos(grade_rad)


@njit(cache=True)
def grade_rad_at(d: float, knot_d, knot_frac) -> float:
    """Road grade [rad] at distance ``d`` [m]: ``atan`` of the grade ``tan(theta)`` interpolated linearly
    between knots ``knot_d`` [m] (increasing) / ``knot_frac`` [-], held beyond the end knots; 0 without knots."""
    n = knot_d.shape[0]
    if n == 0:
        return 0.0
    return math.atan(interp_held(knot_d, 0, knot_frac, 0, n, d))


@njit(cache=True)
def traction_force_n(v0: float, v1: float, h: float, grade_rad: float, mass_kg: float, c_aero: float,
                     f_roll_coeff: float, g: float = G_MPS2, mass_rot_kg: float = 0.0) -> float:
    """Propulsion force [N] (negative = braking) that takes :func:`step_vehicle` from ``v0`` to ``v1``
    over ``h`` with the brakes off: ``(M + M_r)(v1 - v0)/h + c v0 v1 + F_rr + M g sin(theta)``
    (``mass_rot_kg`` = ``M_r``, the rotating parts' equivalent mass); 0 at rest at both ends (the brakes hold
    the vehicle)."""
    if v0 <= 0.0:
        v0 = 0.0
        if v1 <= 0.0:
            return 0.0
    f_g, f_rr = road_forces(grade_rad, mass_kg, f_roll_coeff, g)
    return (mass_kg + mass_rot_kg) * (v1 - v0) / h + c_aero * v0 * v1 + f_rr + f_g


@njit(cache=True, error_model="numpy")
def grade_total_rad(grade_in: float, d: float, knot_d, knot_frac) -> float:
    """Road grade [rad] a vehicle sees at distance ``d``: the ``grade_rad`` input plus the knots' grade
    (:func:`grade_rad_at`); the input unchanged without knots."""
    if knot_d.shape[0] > 0:
        return grade_in + grade_rad_at(d, knot_d, knot_frac)
    return grade_in


@njit_step(error_model="numpy")
def speed_follow_step(p, knot_d, knot_frac, v0: float, grade0: float, d0: float, v_ref: float, a_ref: float,
                      grade_in: float, h: float):
    """One step of the speed-following (``input_mode = "speed"``) vehicle: the whole physics of
    :class:`shevsim.components.vehicle.Vehicle` in speed mode and of the vehicle calibration's loop.

    ``p``: the vehicle's parameters (order of :data:`VP`, :func:`vehicle_params`); ``knot_d``, ``knot_frac``:
    the road grade's knots.
    The vehicle at ``v0`` (grade ``grade0`` [rad] held over the step, distance ``d0``) moves to
    ``v1 = max(v_ref, 0)`` over ``h``; the works are those of the force :func:`traction_force_n` that
    produced that change.  Then the grade at the new distance (:func:`grade_total_rad` of ``grade_in``) and
    the wheel force that drives the next step to ``v1 + a_ref h`` (clipped at 0).

    Returns
    -------
    v1, d1, grade1, f_req, dist, w_prop, w_roll, w_aero, w_grade : float
        Speed [m/s], distance [m], grade for the next step [rad], force request for the next step [N], distance
        covered [m] and the works of propulsion, rolling, aero and grade over the step [J].
    """
    mass_kg = p[VP.mass_kg]
    c_aero = p[VP.c_aero]
    f_roll_coeff = p[VP.f_roll_coeff]
    g = p[VP.g_mps2]
    m_rot = p[VP.mass_rot_kg]
    v1 = v_ref if v_ref > 0.0 else 0.0
    f = traction_force_n(v0, v1, h, grade0, mass_kg, c_aero, f_roll_coeff, g, m_rot)
    dist = 0.5 * (v0 + v1) * h
    if dist > 0.0:
        f_g, f_rr = road_forces(grade0, mass_kg, f_roll_coeff, g)
    else:
        f_g, f_rr = 0.0, 0.0
    d1 = d0 + dist
    grade1 = grade_total_rad(grade_in, d1, knot_d, knot_frac)
    v_next = v1 + a_ref * h
    f_req = traction_force_n(v1, v_next if v_next > 0.0 else 0.0, h, grade1, mass_kg, c_aero, f_roll_coeff, g, m_rot)
    return v1, d1, grade1, f_req, dist, f * dist, f_rr * dist, c_aero * v0 * v1 * dist, f_g * dist


@njit(cache=True)
def step_vehicle(v0: float, f_prop: float, f_brk: float, grade_rad: float, h: float,
                 mass_kg: float, c_aero: float, f_roll_coeff: float,
                 g: float = G_MPS2, mass_rot_kg: float = 0.0) -> tuple[float, float, float, float, float, float, float]:
    """Advance the point mass one step.

    Parameters
    ----------
    v0 : float
        Speed at the start of the step [m/s], >= 0.
    f_prop : float
        Signed propulsion (traction) force at the wheels [N] (negative = regenerative braking).
    f_brk : float
        Friction brake force [N], >= 0 (negative values are treated as 0).
    grade_rad : float
        Road grade [rad], + uphill.
    h : float
        Step [s].
    mass_kg, c_aero, f_roll_coeff : float
        Translational mass, ``1/2 rho C_d A`` [kg/m], rolling coefficient ``f_r`` [-].
    g : float
        Gravity [m/s2].
    mass_rot_kg : float
        Equivalent mass of the rotating parts ``M_r = J / r^2`` [kg] (acts on the acceleration only).

    Returns
    -------
    v1, dist, w_prop, w_brk, w_roll, w_aero, w_grade : float
        End speed [m/s], distance covered [m] and the work of each force over the step [J] (propulsion positive when
        it accelerates; brake, rolling, aero, grade as energy taken from the vehicle).
    """
    f_brk = max(f_brk, 0.0)
    f_g, f_rr = road_forces(grade_rad, mass_kg, f_roll_coeff, g)
    m_e = mass_kg + mass_rot_kg                  # inertial mass M + M_r (weight: M alone, in road_forces)
    if v0 <= 0.0:
        v0 = 0.0
        drive = f_prop - f_g
        if drive <= f_brk + f_rr:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        v1 = h * (drive - f_brk - f_rr) / m_e
        f_a = 0.0
    else:
        v1 = (m_e * v0 + h * (f_prop - f_brk - f_rr - f_g)) / (m_e + h * c_aero * v0)
        f_a = c_aero * v0 * v1
        if v1 < 0.0:
            # stops inside the step: net retarding force R > M_e v0 / h (aero neglected in this last
            # fraction of a step); it stops after t_s = M_e v0 / R < h, having covered v0 t_s / 2,
            # and is held at rest for the remainder (no work)
            r = -(f_prop - f_brk - f_rr - f_g)
            dist = 0.5 * v0 * (m_e * v0 / r)
            return 0.0, dist, f_prop * dist, f_brk * dist, f_rr * dist, 0.0, f_g * dist
    dist = 0.5 * (v0 + v1) * h
    return v1, dist, f_prop * dist, f_brk * dist, f_rr * dist, f_a * dist, f_g * dist


@njit_step
def vehicle_force_step(p, knot_d, knot_frac, x, f_prop: float, f_brk: float, grade_in: float, h: float):
    """The vehicle component's force-mode step from the state ``x`` (order of :data:`XF`, advanced in place):
    the parameter grade added (:func:`grade_total_rad`), :func:`step_vehicle`, the works accumulated.

    Returns ``(accel_mps2, kinetic_energy_j)`` at t + h (``KE = 1/2 (M + M_r) v^2``, translational and
    rotational; speed, distance and works are in ``x``).  The
    component (:class:`shevsim.components.vehicle.Vehicle`) calls it, under the Python master and in the
    compiled whole-vehicle loop alike.
    """
    v0 = x[XF.v]
    th = grade_total_rad(grade_in, x[XF.dist], knot_d, knot_frac)
    v1, dd, wp, wb, wr, wa, wg = step_vehicle(v0, f_prop, f_brk, th, h, p[VP.mass_kg], p[VP.c_aero],
                                              p[VP.f_roll_coeff], p[VP.g_mps2], p[VP.mass_rot_kg])
    x[XF.v] = v1
    x[XF.dist] += dd
    x[XF.e_traction] += wp
    x[XF.e_brake] += wb
    x[XF.e_rolling] += wr
    x[XF.e_aero] += wa
    x[XF.e_grade] += wg
    return (v1 - v0) / h, 0.5 * (p[VP.mass_kg] + p[VP.mass_rot_kg]) * v1 * v1


@njit_step
def vehicle_speed_mode_step(p, knot_d, knot_frac, x, v_ref: float, a_ref: float, grade_in: float, h: float):
    """The vehicle component's speed-mode step from the state ``x`` (order of :data:`XS`, advanced in place):
    :func:`speed_follow_step` and the works accumulated (the brake work stays 0: the split of a negative force
    is the motor's).

    Returns ``(accel_mps2, force_req_n, kinetic_energy_j)`` at t + h (``KE = 1/2 (M + M_r) v^2``; speed,
    distance, grade and works are in ``x``).  The component (:class:`shevsim.components.vehicle.Vehicle`) calls
    it on both engines.
    """
    v0 = x[XS.v]
    v1, d1, th1, f_req, dd, wp, wr, wa, wg = speed_follow_step(p, knot_d, knot_frac, v0, x[XS.th], x[XS.dist], v_ref,
                                                               a_ref, grade_in, h)
    x[XS.v] = v1
    x[XS.dist] = d1
    x[XS.th] = th1
    x[XS.e_traction] += wp
    x[XS.e_brake] += 0.0
    x[XS.e_rolling] += wr
    x[XS.e_aero] += wa
    x[XS.e_grade] += wg
    return (v1 - v0) / h, f_req, 0.5 * (p[VP.mass_kg] + p[VP.mass_rot_kg]) * v1 * v1


def coast_down_aero_only(v0: float, t: float, mass_kg: float, c_aero: float) -> float:
    """Analytical speed of ``M dv/dt = -c v^2``: ``v = v0 / (1 + c v0 t / M)``."""
    return v0 / (1.0 + c_aero * v0 * t / mass_kg)


def coast_down_aero_rolling(v0: float, t: float, mass_kg: float, c_aero: float, f_rr: float) -> float:
    """Analytical speed of ``M dv/dt = -F_rr - c v^2`` (stops at ``t_stop``, then 0)."""
    a = math.sqrt(f_rr / c_aero)                 # characteristic speed
    k = math.sqrt(f_rr * c_aero) / mass_kg       # 1/s
    t_stop = math.atan(v0 / a) / k
    if t >= t_stop:
        return 0.0
    return a * math.tan(math.atan(v0 / a) - k * t)
