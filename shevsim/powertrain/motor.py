"""motor.py - traction motor physics: efficiency map, torque limits and the heat index (seed B.2-B.3).

Heat index (the intent of seed B.2-B.3; the printed equations have inconsistent signs, SPEC §2.1)
------------------------------------------------------------------------------------------------
``gamma in [0, 1]`` measures accumulated thermal load: 0 = cold (full peak torque available),
1 = hot (limited to the continuous torque)::

    tau_max(w, gamma) = tau_cont(w) + (1 - gamma) (tau_peak(w) - tau_cont(w))            (B.2')
    d gamma/dt       = (r / 1) (|tau_m| / tau_cont(w) - 1),   gamma clipped to [0, 1]    (B.3')
    r = 0.3 / 180 s^-1,  gamma(0) = 0.3 (seed)

So sustained torque at twice continuous raises gamma by 0.3 in 180 s (the limit falls by 0.3 of
the peak-continuous span); torque below continuous lets gamma fall (light load recovers; at zero
torque at the same 0.3 per 180 s). Seed B.2 as printed adds ``(1 - gamma) tau_peak`` to
``tau_cont`` (exceeding the peak) and B.3 as printed lowers gamma under overload; both are
corrected here. ``|tau_m|`` is used so regenerative overload heats the machine as motoring does.
Over one step with the torque held, gamma is advanced exactly (it is linear in time) and clipped.

Electrical power (the equivalent machine, motor-shaft quantities)::

    P_mech = tau w;   P_elec = P_mech / eta(w, tau)   if P_mech >= 0  (motoring)
                      P_elec = P_mech * eta(w, tau)   if P_mech <  0  (generating)
    P_loss = P_elec - P_mech >= 0

At standstill the map's efficiency gives zero loss (P_mech = 0); stall copper loss is not modelled.
"""
from __future__ import annotations

from .maps import Curve, Grid2D

HEAT_RATE_PER_S = 0.3 / 180.0


def torque_limit(tau_peak: float, tau_cont: float, gamma: float) -> float:
    """Max torque magnitude (B.2'): ``tau_cont + (1 - gamma)(tau_peak - tau_cont)``."""
    return tau_cont + (1.0 - gamma) * (tau_peak - tau_cont)


def heat_index_rate(tau: float, tau_cont: float, rate_per_s: float = HEAT_RATE_PER_S) -> float:
    """d gamma / dt (B.3'), unclipped."""
    return rate_per_s * (abs(tau) / tau_cont - 1.0)


def heat_index_step(gamma: float, tau: float, tau_cont: float, h: float,
                    rate_per_s: float = HEAT_RATE_PER_S) -> float:
    """gamma after ``h`` seconds at constant torque (exact, clipped to [0, 1])."""
    g = gamma + h * heat_index_rate(tau, tau_cont, rate_per_s)
    return 0.0 if g < 0.0 else (1.0 if g > 1.0 else g)


def electrical_power(tau: float, w: float, eta: float) -> float:
    """Electrical power [W] (+ drawn) for shaft torque ``tau`` [N m] at ``w`` [rad/s]."""
    p = tau * w
    return p / eta if p >= 0.0 else p * eta


class MotorMaps:
    """Efficiency map and torque curves of the equivalent motor.

    Parameters
    ----------
    eff : Grid2D
        ``eta(w [rad/s], tau [N m])``, clamped outside the grid.
    peak, cont : Curve
        Peak and continuous torque magnitude vs speed [N m], clamped.
    """

    def __init__(self, eff: Grid2D, peak: Curve, cont: Curve):
        self.eff, self.peak, self.cont = eff, peak, cont
        if (cont.eval_array(peak.x) > peak.y + 1e-9).any():
            raise ValueError("motor: continuous torque exceeds peak torque")

    def limit(self, w: float, gamma: float) -> float:
        return torque_limit(self.peak(w), self.cont(w), gamma)

    def power(self, tau: float, w: float) -> float:
        return electrical_power(tau, w, self.eff(w, tau))
