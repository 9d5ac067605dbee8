"""vehicle.py - point-mass longitudinal vehicle dynamics (seed B.6-B.8) with exact energy bookkeeping.

    M dv/dt = F_prop - F_brk - F_rr - F_wr - M g sin(theta)        (B.6 plus road grade)
    F_rr = f_r M g cos(theta)   (while rolling)                     (B.7)
    F_wr = 1/2 rho C_d A v^2                                        (B.8)

Speed never goes negative: brakes and rolling resistance only stop the vehicle; at standstill it
moves only when ``F_prop - M g sin(theta) > F_brk + F_rr`` (the wheel brakes/static friction hold it
otherwise; a vehicle on a slope does not roll backwards - documented simplification).

Discretisation of one step of length ``h`` with the forces ``F_prop``, ``F_brk``, ``theta`` held:
aero drag is semi-implicit, ``F_wr = c v0 v1`` with ``c = 1/2 rho C_d A``, so

    v1 = (M v0 + h (F_prop - F_brk - F_rr - F_g)) / (M + h c v0),

which is unconditionally stable and, as ``h -> 0``, first-order accurate. Every force is a
constant over the step and its work is ``W_i = F_i (v0 + v1)/2 h``; then
``sum_i W_i = M (v1 - v0)(v0 + v1)/2 = Delta KE`` *exactly*, so the energy balance

    traction - brake - rolling - aero - grade = Delta KE

closes to round-off on any step size. When the update would give ``v1 < 0`` the vehicle stops
inside the step, at ``t_s = M v0 / R`` with ``R`` the net retarding force, after ``v0 t_s / 2``
metres; each force works over that distance (``sum W = -M v0^2 / 2`` exactly), and it is then
held at rest. The returned works are what the component uses for its distance too.
"""
from __future__ import annotations

import math

G_MPS2 = 9.80665


def step_vehicle(v0: float, f_prop: float, f_brk: float, grade_rad: float, h: float,
                 mass_kg: float, c_aero: float, f_roll_coeff: float,
                 g: float = G_MPS2) -> tuple[float, float, float, float, float, float, float]:
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
        Mass, ``1/2 rho C_d A`` [kg/m], rolling coefficient ``f_r`` [-].

    Returns
    -------
    v1, dist, w_prop, w_brk, w_roll, w_aero, w_grade : float
        End speed [m/s], distance covered [m] and the work of each force over the step [J] (propulsion positive when
        it accelerates; brake, rolling, aero, grade as energy taken from the vehicle).
    """
    f_brk = max(f_brk, 0.0)
    f_g = mass_kg * g * math.sin(grade_rad)
    f_rr = f_roll_coeff * mass_kg * g * math.cos(grade_rad)
    if v0 <= 0.0:
        v0 = 0.0
        drive = f_prop - f_g
        if drive <= f_brk + f_rr:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        v1 = h * (drive - f_brk - f_rr) / mass_kg
        f_a = 0.0
    else:
        v1 = (mass_kg * v0 + h * (f_prop - f_brk - f_rr - f_g)) / (mass_kg + h * c_aero * v0)
        f_a = c_aero * v0 * v1
        if v1 < 0.0:
            # stops inside the step: net retarding force R > M v0 / h (aero neglected in this last
            # fraction of a step); it stops after t_s = M v0 / R < h, having covered v0 t_s / 2,
            # and is held at rest for the remainder (no work)
            r = -(f_prop - f_brk - f_rr - f_g)
            dist = 0.5 * v0 * (mass_kg * v0 / r)
            return 0.0, dist, f_prop * dist, f_brk * dist, f_rr * dist, 0.0, f_g * dist
    dist = 0.5 * (v0 + v1) * h
    return v1, dist, f_prop * dist, f_brk * dist, f_rr * dist, f_a * dist, f_g * dist


def road_load_n(v: float, mass_kg: float, c_aero: float, f_roll_coeff: float, grade_rad: float = 0.0,
                g: float = G_MPS2) -> float:
    """Steady road load ``F_rr + F_wr + M g sin(theta)`` at speed ``v`` [N] (rolling only if v > 0)."""
    f_rr = f_roll_coeff * mass_kg * g * math.cos(grade_rad) if v > 0.0 else 0.0
    return f_rr + c_aero * v * v + mass_kg * g * math.sin(grade_rad)


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
