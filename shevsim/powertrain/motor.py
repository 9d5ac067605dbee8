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
``efficiency_scale_frac`` (default 1, off) multiplies the map's efficiency, ``eta = min(s eta_map, 1)``;
``regen_efficiency_scale_frac`` (default 1, off) multiplies it once more when generating (``tau < 0``):
``eta = min(s s_regen eta_map, 1)`` - a published curve is often a motoring curve mirrored, and the
machine + inverter's generating efficiency differs from it (FASTSim 3.1, for one, uses the curve's
zero-power value for every regenerative point).

One step of the machine (:func:`motor_step`): force request -> torque -> heat-index torque limit ->
regenerative limits (speed threshold, bus power limits, ``regen_power_max_w``: the most electrical
power the drive returns, default inf = off) -> electrical power. It is the whole physics of the
``motor`` component (:mod:`shevsim.components.motor`, which only holds the state and books energies)
and of the vehicle calibration's model (:mod:`shevsim.calibrate.vehicle`). The DC bus's power balance
(:func:`bus_balance`, motor + auxiliaries) lives here too, for the ``bus`` component and the same
calibration loop. Every function here is
compiled with numba (``f.py_func`` is the Python source) and looks its maps up with the compiled
lookups of :mod:`shevsim.core.lookup` on :meth:`MotorMaps.packed` arrays (bit-identical to the maps'
Python lookups).
"""
from __future__ import annotations

import numpy as np

from shevsim.core.compiled import field_index, njit_step
from shevsim.core.lookup import curve_nb, grid_nb, njit, py_max, py_min

from .maps import Curve, Grid2D

HEAT_RATE_PER_S = 0.3 / 180.0


@njit(cache=True)
def torque_limit(tau_peak: float, tau_cont: float, gamma: float) -> float:
    """Max torque magnitude (B.2'): ``tau_cont + (1 - gamma)(tau_peak - tau_cont)``."""
    return tau_cont + (1.0 - gamma) * (tau_peak - tau_cont)


@njit(cache=True)
def heat_index_rate(tau: float, tau_cont: float, rate_per_s: float = HEAT_RATE_PER_S) -> float:
    """d gamma / dt (B.3'), unclipped."""
    return rate_per_s * (abs(tau) / tau_cont - 1.0)


@njit(cache=True)
def heat_index_step(gamma: float, tau: float, tau_cont: float, h: float,
                    rate_per_s: float = HEAT_RATE_PER_S) -> float:
    """gamma after ``h`` seconds at constant torque (exact, clipped to [0, 1])."""
    g = gamma + h * heat_index_rate(tau, tau_cont, rate_per_s)
    return 0.0 if g < 0.0 else (1.0 if g > 1.0 else g)


@njit(cache=True)
def electrical_power(tau: float, w: float, eta: float) -> float:
    """Electrical power [W] (+ drawn) for shaft torque ``tau`` [N m] at ``w`` [rad/s]."""
    p = tau * w
    return p / eta if p >= 0.0 else p * eta


@njit(cache=True)
def efficiency(md, mi, w: float, tau: float, scale: float) -> float:
    """Map efficiency at motor speed ``w`` [rad/s], torque ``tau`` [N m], times ``scale`` (capped at 1)."""
    eta = grid_nb(md, mi[4], mi[5], mi[6], w, tau)
    if scale != 1.0:
        eta = min(eta * scale, 1.0)
    return eta


#: the motor step's parameters ``p`` (:func:`motor_step`; the motor component's ``data[2]``): motor rad/s per
#: m/s, motor N m per wheel N, ``extrapolate_speed`` (1/0), ``regen_speed_min_mps``, ``regen_power_max_w``,
#: ``efficiency_scale_frac``, ``heat_rate_per_s``, ``regen_efficiency_scale_frac``
P = field_index(("k_w", "k_tau", "extrapolate", "v_regen", "p_regen", "eff_scale", "heat_rate", "regen_eff_scale"),
                "P")
#: the motor component's state (:func:`motor_component_step`; its ``data[3]``): heat index, the cumulative loss,
#: electrical and shaft energies [J], the speed input and step of the previous step
X = field_index(("gamma", "e_loss", "e_elec", "e_mech", "v_prev", "h_prev"), "X")


def motor_params(k_w: float, k_tau: float, extrapolate: bool, regen_speed_min: float, regen_power_max: float,
                 eff_scale: float, heat_rate: float, regen_eff_scale: float = 1.0) -> np.ndarray:
    """The parameter array ``p`` of :func:`motor_step` (order of :data:`P`)."""
    return np.array([k_w, k_tau, 1.0 if extrapolate else 0.0, regen_speed_min, regen_power_max, eff_scale,
                     heat_rate, regen_eff_scale], dtype=np.float64)


@njit_step
def motor_step(md, mi, p, f_req: float, v: float, p_hi: float, p_lo: float, h: float, v_prev: float,
               h_prev: float, gamma: float):
    """One step of the equivalent motor with inputs held over ``h`` (see :mod:`shevsim.components.motor`).

    Parameters
    ----------
    md, mi : arrays
        Packed maps (:meth:`MotorMaps.packed`).
    p : array
        Parameters in the order of :data:`P` (:func:`motor_params`): ``k_w``, ``k_tau`` the motor rad/s per m/s
        and motor N m per wheel N; ``extrapolate_speed``, ``regen_speed_min_mps``, ``regen_power_max_w``,
        ``efficiency_scale_frac``, ``heat_rate_per_s``, ``regen_efficiency_scale_frac``.
    f_req, v : float
        Wheel force request [N] (+ propel) and vehicle speed [m/s].
    p_hi, p_lo : float
        Bus power limits [W] (>= 0 / <= 0; others are clamped to 0).
    h, v_prev, h_prev, gamma : float
        Step [s]; speed input and step of the previous step (mid-step speed extrapolation); heat index.

    Returns
    -------
    tau, brake, p_el, p_m, w, t_lim, gamma1, v : float
        Torque [N m], friction brake force [N], electrical power [W] (+ drawn), shaft power [W] at the
        mid-step speed, motor speed [rad/s], torque limit [N m], heat index at t + h, the speed used
        (the next step's ``v_prev``).
    """
    k_w = p[P.k_w]
    k_tau = p[P.k_tau]
    eff_scale = p[P.eff_scale]
    regen_power_max = p[P.p_regen]
    if v < 0.0:
        v = 0.0
    w = v * k_w
    # mid-step speed by linear extrapolation of the speed input (second-order accurate power)
    v_mid = v + 0.5 * (v - v_prev) * (h / h_prev) if p[P.extrapolate] > 0.5 else v
    w_mid = v_mid * k_w if v_mid > 0.0 else 0.0
    t_peak = curve_nb(md, mi[0], mi[1], w)
    t_cont = curve_nb(md, mi[2], mi[3], w)
    t_lim = torque_limit(t_peak, t_cont, gamma)
    tau = f_req * k_tau
    brake = 0.0
    if tau > t_lim:
        tau = t_lim
    elif tau < 0.0:
        t_regen = t_lim if v >= p[P.v_regen] else 0.0
        if tau < -t_regen:
            tau = -t_regen
        brake = -(f_req - tau / k_tau)
    # generating: the map's efficiency times both scales (the torque keeps its sign below)
    if tau < 0.0:
        eff_scale = eff_scale * p[P.regen_eff_scale]
    p_el = electrical_power(tau, w_mid, efficiency(md, mi, w_mid, tau, eff_scale))
    # bus power limits (battery power capability + generator output) and the drive's own regenerative
    # power limit: scale the torque down until the electrical power fits; the rest of a braking
    # demand goes to the friction brakes, the rest of a propulsion demand is not delivered
    if p_hi < 0.0:
        p_hi = 0.0
    if p_lo > 0.0:
        p_lo = 0.0
    if p_lo < -regen_power_max:
        p_lo = -regen_power_max
    if p_el > p_hi or p_el < p_lo:
        target = p_hi if p_el > p_hi else p_lo
        for _ in range(4):  # fixed point on tau: eta changes slowly with torque
            tau *= target / p_el if p_el != 0.0 else 0.0
            p_el = electrical_power(tau, w_mid, efficiency(md, mi, w_mid, tau, eff_scale))
            if p_el == 0.0 or abs(p_el - target) <= 1e-6 * abs(target) + 1e-3:
                break
        if p_el > p_hi or p_el < p_lo:   # guard: never exceed the limit
            tau *= 0.999 * target / p_el if p_el != 0.0 else 0.0
            p_el = electrical_power(tau, w_mid, efficiency(md, mi, w_mid, tau, eff_scale))
        if f_req < 0.0:
            brake = -(f_req - tau / k_tau)
    p_m = tau * w_mid
    gamma1 = heat_index_step(gamma, tau, t_cont, h, p[P.heat_rate])
    return tau, brake, p_el, p_m, w, t_lim, gamma1, v


@njit_step
def motor_component_step(md, mi, p, x, f_req: float, v: float, p_hi: float, p_lo: float, h: float):
    """:func:`motor_step` from the state ``x`` (order of :data:`X`, advanced in place: heat index, the energies
    integrated over the held step, the speed input and step for the next step's extrapolation) plus the
    motor component's bookkeeping.

    Returns ``(traction_force_n, brake_force_n, elec_power_w, torque_nm, speed_radps, torque_max_nm)``.  The
    component (:class:`shevsim.components.motor.Motor`) calls it, under the Python master and in the compiled
    whole-vehicle loop alike.
    """
    tau, brake, p_el, p_m, w, t_lim, gamma1, v_used = motor_step(md, mi, p, f_req, v, p_hi, p_lo, h, x[X.v_prev],
                                                                  x[X.h_prev], x[X.gamma])
    x[X.gamma] = gamma1
    x[X.e_elec] += p_el * h
    x[X.e_mech] += p_m * h
    x[X.e_loss] += (p_el - p_m) * h
    x[X.v_prev] = v_used
    x[X.h_prev] = h
    return tau / p[P.k_tau], brake, p_el, tau, w, t_lim


@njit(cache=True, error_model="numpy")
def bus_aux_w(aux_in_w: float, aux_param_w: float) -> float:
    """Auxiliary load on the bus [W]: the ``aux_power_w`` input plus the constant ``aux_power_w`` parameter
    (the input unchanged when the parameter is 0)."""
    return aux_in_w + aux_param_w if aux_param_w != 0.0 else aux_in_w


@njit(cache=True, error_model="numpy")
def bus_balance(motor_w: float, gen_w: float, aux_in_w: float, aux_param_w: float):
    """Power balance of the DC bus (:class:`shevsim.components.bus.PowerBus`; the vehicle calibration's loop
    sums the bus with it too): ``(aux, demand = motor + aux, battery = demand - gen)`` [W]."""
    pa = bus_aux_w(aux_in_w, aux_param_w)
    d = motor_w + pa
    return pa, d, d - gen_w


@njit(cache=True)
def bus_limits(motor_w: float, gen_w: float, aux_in_w: float, bpmax_w: float, bpmin_w: float, aux_param_w: float,
               enforce: bool):
    """The bus's limit law (:class:`shevsim.components.bus.PowerBus` and ``PowerLimits``):
    ``(motor_power_max_w, motor_power_min_w, gen_power_max_w, gen_power_min_w)`` [W] from the machines'
    powers, the auxiliary load and the battery's power capability ``bpmax_w >= 0 >= bpmin_w``:

    * motor max = max(gen - aux + bpmax, 0); motor min = min(max(gen, 0) - aux + bpmin, 0) (the generator
      can be shed to any power >= 0 within the step but not made to motor: the regen limit counts on
      max(gen, 0));
    * generator max = max(motor + aux - bpmin, 0) (load shedding); generator min = motor + aux - bpmax
      (the floor: what the generator must deliver for the battery to stay within its discharge capability).

    ``enforce = False``: +-1e12 (no limits)."""
    if not enforce:
        return 1e12, -1e12, 1e12, -1e12
    pa = bus_aux_w(aux_in_w, aux_param_w)
    base = gen_w - pa
    return (py_max(base + bpmax_w, 0.0), py_min(py_max(gen_w, 0.0) - pa + bpmin_w, 0.0),
            py_max(motor_w + pa - bpmin_w, 0.0), motor_w + pa - bpmax_w)


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

    def packed(self):
        """``(md, mi)``: the peak and continuous curves and the efficiency grid packed into one float
        array ``md`` with offsets/sizes ``mi = [o_peak, n_peak, o_cont, n_cont, o_eff, n_w, n_tau]`` for
        :func:`motor_step` (layout of :mod:`shevsim.core.lookup`)."""
        parts, mi, o = [], [], 0
        for c in (self.peak, self.cont):
            parts += [c.x, c.y]
            mi += [o, c.x.size]
            o += 2 * c.x.size
        g = self.eff
        parts += [g.x, g.y, g.z.reshape(-1)]
        mi += [o, g.x.size, g.y.size]
        return np.ascontiguousarray(np.concatenate(parts), dtype=np.float64), np.array(mi, dtype=np.int64)
