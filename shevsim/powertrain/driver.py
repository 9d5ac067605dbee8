"""driver.py - driver model: PI on speed error with feed-forward (seed App. B end, [137]).

    F_req = F_ff + k_P e + I,     e = v_ref - v,     dI/dt = k_I e
    F_ff  = M a_ref + F_rr + 1/2 rho C_d A v_ref^2         (rolling only while v_ref > 0)

The feed-forward uses the driver's *belief* of the vehicle (its own mass/road-load parameters),
so a 15.5 t vehicle follows a cycle with small PI action; the PI removes the model error
(unknown grade, wrong mass). Output saturates at ``[-force_brake_max_n, force_prop_max_n]``;
anti-windup: the integral is frozen while the output is saturated in the direction of the error.
At a standstill request (``v_ref <= 0`` and ``a_ref <= 0``) the integral is reset to 0 and the
driver holds the brake (``F_req <= 0``).

Discretisation: the output of a step is computed from the held inputs and the integral at the
start of the step (direct feedthrough); the integral is then advanced by ``k_I e h``.
"""
from __future__ import annotations

from shevsim.core.compiled import field_index, njit_step
from shevsim.core.lookup import njit

from .vehicle import G_MPS2


@njit(cache=True)
def feedforward_n(v_ref: float, a_ref: float, mass_kg: float, c_aero: float, f_roll: float,
                  g: float = G_MPS2) -> float:
    """Feed-forward force [N] for reference speed and acceleration."""
    f = mass_kg * a_ref + c_aero * v_ref * v_ref
    if v_ref > 0.0:
        f += f_roll * mass_kg * g
    return f


@njit(cache=True)
def pi_force(e: float, integ: float, ff: float, kp: float, f_min: float, f_max: float) -> tuple[float, bool]:
    """Saturated PI output and whether the integral may integrate ``e`` (anti-windup)."""
    f = ff + kp * e + integ
    if f > f_max:
        return f_max, e < 0.0
    if f < f_min:
        return f_min, e > 0.0
    return f, True


#: the driver's parameters ``p`` (:func:`driver_step`; the driver component's ``data[0]``): the PI gains, the
#: feed-forward's vehicle (mass, ``0.5 rho C_d A``, rolling coefficient, g) and the force saturation
DP = field_index(("kp_n_per_mps", "ki_n_per_m", "mass_kg", "drag_n_per_mps2", "rolling_coefficient", "g_mps2",
                  "force_brake_max_n", "force_prop_max_n"), "DP")


@njit_step
def driver_step(p, v_ref: float, a_ref: float, v: float, integ: float, h: float):
    """One driver step with the inputs held over ``h`` and parameters ``p`` (order of :data:`DP`):
    ``(force_req_n, speed_error_mps, feedforward_n, integral at t + h)``.  The component's step calls it, under
    the Python master and in the compiled whole-vehicle loop alike."""
    kp = p[DP.kp_n_per_mps]
    force_brake_max_n = p[DP.force_brake_max_n]
    e = v_ref - v
    if v_ref <= 0.0 and a_ref <= 0.0:
        integ = 0.0
        ff = 0.0
        f = kp * e
        if 0.0 < f:                      # min(kp e, 0.0), then max(., -F_brake,max), as Python's min/max
            f = 0.0
        if -force_brake_max_n > f:
            f = -force_brake_max_n
    else:
        ff = feedforward_n(v_ref, a_ref, p[DP.mass_kg], p[DP.drag_n_per_mps2], p[DP.rolling_coefficient],
                           p[DP.g_mps2])
        f, integrate = pi_force(e, integ, ff, kp, -force_brake_max_n, p[DP.force_prop_max_n])
        if integrate:
            integ += p[DP.ki_n_per_m] * e * h
    return f, e, ff, integ
