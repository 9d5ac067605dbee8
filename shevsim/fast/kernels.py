"""kernels.py - one compiled step per native component type, for the compiled whole-vehicle loop.

Each ``*_step(data, sig, ib, ob, t, h)`` advances one component from ``t`` to ``t + h``: it reads its
inputs from ``sig[ib + j]`` (``j`` = the input's position among the component's declared inputs),
calls the component's own compiled functions (the very ones the component's ``do_step`` calls:
:func:`~shevsim.components.cycle.cycle_sample`, :func:`~shevsim.powertrain.driver.driver_step`,
:func:`~shevsim.powertrain.vehicle.vehicle_force_step` / ``vehicle_speed_mode_step``,
:func:`~shevsim.powertrain.motor.motor_component_step`, :func:`~shevsim.powertrain.motor.bus_balance`,
:func:`shevsim.powertrain.engine.step`, :func:`shevsim.battery.model.cell_step`,
:func:`shevsim.bms.electrical.dekf_step`, the thermal filter steps,
:func:`shevsim.bms.power_capability.power_limits`, :func:`shevsim.supervisor.rule_based.rule_command`,
:func:`shevsim.supervisor.mpc.mpc_move` with DAQP's C library) and writes its outputs to ``sig[ob + j]`` in
declaration order; the bus and ``power_limits`` call :func:`shevsim.powertrain.motor.bus_limits`, the same
limit law as the components.  What is left here is the bookkeeping of components whose methods are not
compiled functions (battery and BMS output publishing and the BMS's estimator sequence, the engine-generator's
outputs, the profile source's sample-and-hold), written to give the
same floating-point operations in the same order as those Python methods, so the loop reproduces
:class:`shevsim.core.master.Master` bit for bit (the agreement tests, ``tests/unit/test_fast_path.py``,
fail on any drift).

Return value: 0, or an error code (:data:`ERRORS`) that the runner turns into the component's
:class:`~shevsim.core.errors.SimulationError`.

Python's ``min``/``max`` keep the first argument unless the second is strictly smaller/larger; numba's
may pick the other one of two equal values (signed zeros), so the bookkeeping uses
:func:`shevsim.core.lookup.py_min` / ``py_max`` (imported as ``pmin`` / ``pmax``), which mirror Python.
"""
from __future__ import annotations

import math

from numba import njit

from shevsim.battery.model import (S_AH, S_CLAMPS, S_ECHEM, S_ELOSS, S_SOC, Y_I, Y_Q, Y_TCORE, Y_TMEAN, Y_TSURF,
                                   Y_V, Y_VOC, cell_step)
from shevsim.battery.thermal import two_state_ad_bd, two_state_out
from shevsim.bms.electrical import dekf_step
from shevsim.bms.power_capability import power_limits
from shevsim.bms.thermal_estimators import dkf_step, jekf_step, kf_step
from shevsim.core.lookup import _t1_value
from shevsim.core.lookup import py_max as pmax
from shevsim.core.lookup import py_min as pmin
from shevsim.powertrain.engine import step as engine_step
from shevsim.powertrain.motor import bus_aux_w, bus_balance, bus_limits, motor_component_step
from shevsim.powertrain.vehicle import vehicle_force_step, vehicle_speed_mode_step
from shevsim.components.cycle import cycle_sample
from shevsim.powertrain.driver import driver_step
from shevsim.supervisor.mpc import mpc_move
from shevsim.supervisor.rule_based import _bisect_right as bisect_right  # Python's bisect.bisect_right
from shevsim.supervisor.rule_based import rule_command

from shevsim.supervisor import daqp_nb

# component type codes of the loop
(T_CYCLE, T_DRIVER, T_VEHICLE, T_MOTOR, T_BUS, T_ENGINE, T_BATTERY, T_BMS, T_RULE, T_MPC, T_LIMITS, T_VEHICLE_SPEED,
 T_PROFILE) = range(13)

ERR_NAN_INPUT, ERR_SOC_RANGE, ERR_ENGINE_NONFINITE, ERR_DEKF, ERR_THERMAL_INPUT, ERR_SAMPLE_TIME, \
    ERR_BATTERY_INPUT, ERR_NONFINITE_OUTPUT = range(1, 9)
ERRORS = {ERR_NAN_INPUT: "NaN input", ERR_SOC_RANGE: "SOC left [0, 100] %",
          ERR_ENGINE_NONFINITE: "engine-generator step gave a non-finite result (a NaN lookup, or a lookup "
                                "outside a map with extrapolation 'error')",
          ERR_DEKF: "DEKF: non-finite or non-positive innovation variance",
          ERR_THERMAL_INPUT: "thermal estimator: non-finite input",
          ERR_SAMPLE_TIME: "supervisor called with a step that is not its sample_time_s",
          ERR_BATTERY_INPUT: "bad input (non-finite, or h_conv_w_m2k < 0)",
          ERR_NONFINITE_OUTPUT: "non-finite output"}


@njit(cache=True)
def round3(x):
    """Python's ``round(x, 3)`` (correctly rounded: the decimal ``x`` rounded half-even to 3 places, then
    the nearest double), used by the power capability's thermal-coefficient cache key."""
    if not math.isfinite(x):
        return x
    p = x * 1000.0
    if abs(p) >= 4503599627370496.0:       # 2**52: already an integer number of thousandths
        return x
    # exact error of the product x * 1000 (Dekker's two-product; 1000 splits exactly)
    c = 134217729.0 * x
    xh = c - (c - x)
    xl = x - xh
    e = (xh * 1000.0 - p) + xl * 1000.0
    fl = math.floor(p)
    d = (p - fl) - 0.5
    s = d + e
    if s > 0.0:
        q = fl + 1.0
    elif s < 0.0:
        q = fl
    else:
        q = fl if (fl % 2.0) == 0.0 else fl + 1.0
    r = q / 1000.0
    if r == 0.0:
        r = math.copysign(0.0, x)
    return r


# ------------------------------------------------------------------------------------------------ cycle
@njit(cache=True)
def cycle_step(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.cycle.CycleSource.do_step` (:func:`~shevsim.components.cycle.cycle_sample`
    at ``t + h``)."""
    v, slope, p = data
    sig[ob], sig[ob + 1], sig[ob + 2] = cycle_sample(v, slope, p[0], p[2], int(p[3]), p[4], t + h)
    return 0


# ----------------------------------------------------------------------------------------------- driver
@njit(cache=True)
def driver_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.driver.Driver.do_step` (the law is :func:`~shevsim.powertrain.driver.driver_step`)."""
    p, x = data
    vr = sig[ib]
    ar = sig[ib + 1]
    v = sig[ib + 2]
    if vr != vr or ar != ar or v != v:
        return ERR_NAN_INPUT
    f, e, ff, integ = driver_step(vr, ar, v, x[0], h, p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7])
    x[0] = integ
    sig[ob] = f
    sig[ob + 1] = e
    sig[ob + 2] = ff
    return 0


# ---------------------------------------------------------------------------------------------- vehicle
@njit(cache=True)
def vehicle_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.vehicle.Vehicle.do_step` (force mode,
    :func:`~shevsim.powertrain.vehicle.vehicle_force_step`)."""
    p, kd, kg, x = data
    f_t = sig[ib]
    f_b = sig[ib + 1]
    th = sig[ib + 2]
    if f_t != f_t or f_b != f_b or th != th:
        return ERR_NAN_INPUT
    v1, acc, dist, e0, e1, e2, e3, e4, ke = vehicle_force_step(x[0], x[1], x[2], x[3], x[4], x[5], x[6], f_t, f_b,
                                                               th, h, p[0], p[1], p[2], p[3], p[4] > 0.5, kd, kg)
    x[0] = v1
    x[1] = dist
    x[2] = e0
    x[3] = e1
    x[4] = e2
    x[5] = e3
    x[6] = e4
    sig[ob] = v1
    sig[ob + 1] = acc
    sig[ob + 2] = dist
    sig[ob + 3] = e0            # traction
    sig[ob + 4] = e3            # aero
    sig[ob + 5] = e2            # rolling
    sig[ob + 6] = e1            # brake
    sig[ob + 7] = e4            # grade
    sig[ob + 8] = ke
    return 0


@njit(cache=True)
def vehicle_speed_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.vehicle.Vehicle.do_step` in speed mode
    (:func:`~shevsim.powertrain.vehicle.vehicle_speed_mode_step`); ``x = [v, dist, grade, works (5)]``."""
    p, kd, kg, x = data
    vr = sig[ib]
    ar = sig[ib + 1]
    th = sig[ib + 2]
    if vr != vr or ar != ar or th != th:
        return ERR_NAN_INPUT
    v1, acc, dist, th1, f_req, e0, e1, e2, e3, e4, ke = vehicle_speed_mode_step(
        x[0], x[2], x[1], x[3], x[4], x[5], x[6], x[7], vr, ar, th, h, kd, kg, p[0], p[1], p[2], p[3])
    x[0] = v1
    x[1] = dist
    x[2] = th1
    x[3] = e0
    x[4] = e1
    x[5] = e2
    x[6] = e3
    x[7] = e4
    sig[ob] = f_req
    sig[ob + 1] = v1
    sig[ob + 2] = acc
    sig[ob + 3] = dist
    sig[ob + 4] = e0            # traction
    sig[ob + 5] = e3            # aero
    sig[ob + 6] = e2            # rolling
    sig[ob + 7] = e1            # brake
    sig[ob + 8] = e4            # grade
    sig[ob + 9] = ke
    return 0


@njit(cache=True)
def profile_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.profile.ProfileSource.do_step`: the last sample at or before ``t + h``
    (tolerance 1e-9 of the time) for every port with a column (``has``); the others hold."""
    ts, cols, has = data
    te = t + h
    tol = 1e-9 * pmax(1.0, abs(te))
    k = bisect_right(ts, te + tol) - 1
    if k < 0:
        k = 0
    for q in range(has.shape[0]):
        if has[q] > 0.5:
            sig[ob + q] = cols[q, k]
    return 0


# ------------------------------------------------------------------------------------------------ motor
@njit(cache=True)
def motor_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.motor.Motor.do_step` (:func:`~shevsim.powertrain.motor.motor_component_step`)."""
    md, mi, p, x = data
    f_req = sig[ib]
    v = sig[ib + 1]
    if f_req != f_req or v != v:
        return ERR_NAN_INPUT
    (f_trac, brake, p_el, tau, w, t_lim, gamma, e_loss, e_elec, e_mech, v_used) = motor_component_step(
        md, mi, f_req, v, sig[ib + 2], sig[ib + 3], h, x[4], x[5], x[0], x[1], x[2], x[3], p[0], p[1], p[2] > 0.5,
        p[3], p[4], p[5], p[6])
    x[0] = gamma
    x[1] = e_loss
    x[2] = e_elec
    x[3] = e_mech
    x[4] = v_used
    x[5] = h
    sig[ob] = f_trac
    sig[ob + 1] = brake
    sig[ob + 2] = p_el
    sig[ob + 3] = tau
    sig[ob + 4] = w
    sig[ob + 5] = t_lim
    sig[ob + 6] = gamma
    sig[ob + 7] = e_loss
    sig[ob + 8] = e_elec
    sig[ob + 9] = e_mech
    return 0


# -------------------------------------------------------------------------------------------------- bus
@njit(cache=True)
def power_limits_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.bus.PowerLimits.do_step` (parameters ``data[0] = [aux_power_w, enforce]``)."""
    P = data[0]
    for j in range(5):
        if sig[ib + j] != sig[ib + j]:
            return ERR_NAN_INPUT
    pm = sig[ib]
    pg = sig[ib + 1]
    u_aux = sig[ib + 2]
    sig[ob], sig[ob + 1], sig[ob + 2], sig[ob + 3] = bus_limits(pm, pg, u_aux, sig[ib + 3], sig[ib + 4], P[0],
                                                                 P[1] > 0.5)
    return 0


@njit(cache=True)
def bus_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.bus.PowerBus.do_step` (balance, energies, then the limits)."""
    p, e = data
    pm = sig[ib]
    pg = sig[ib + 1]
    u_aux = sig[ib + 2]
    pa, d, b = bus_balance(pm, pg, u_aux, p[0])
    if pm != pm or pg != pg or pa != pa:
        return ERR_NAN_INPUT
    e[0] += pa * h
    e[1] += pm * h
    e[2] += pg * h
    e[3] += b * h
    sig[ob + 4] = d
    sig[ob + 3] = b
    sig[ob + 5] = e[0]
    sig[ob + 6] = e[1]
    sig[ob + 7] = e[2]
    sig[ob + 8] = e[3]
    sig[ob], sig[ob + 1], sig[ob + 2], _floor = bus_limits(pm, pg, u_aux, sig[ib + 3], sig[ib + 4], p[0], p[1] > 0.5)
    return 0


# --------------------------------------------------------------------------------------------- engine
@njit(cache=True)
def _engine_kernel_floor(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.engine_generator.EngineGenerator.do_step` with the generator floor input."""
    md, mi, c, p, s = data
    pc = sig[ib]
    rate = sig[ib + 1]
    lim = sig[ib + 2]
    floor = sig[ib + 3]
    if pc != pc or rate != rate or lim != lim or floor != floor:
        return ERR_NAN_INPUT
    r = engine_step(md, mi, c, p[0], s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11],
                    s[12], s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], pc, rate, h, lim, floor)
    if not math.isfinite(r[21] + r[22] + r[24] + r[1] + r[5]):
        return ERR_ENGINE_NONFINITE
    (s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], s[12], s[13], s[14], s[15], s[16],
     s[17], s[18], s[19], s[20]) = (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11],
                                    r[12], r[13], r[14], r[15], r[16], r[17], r[18], r[19], r[20])
    # _write(e_el / h, fuel / h, soot / h, soot_meas); state order of engine.STATE
    sig[ob] = r[21] / h
    sig[ob + 1] = s[5] * s[1]
    sig[ob + 2] = s[1]
    sig[ob + 3] = s[5]
    sig[ob + 4] = s[3]
    sig[ob + 5] = r[22] / h
    sig[ob + 6] = r[23] / h
    sig[ob + 7] = s[0]
    sig[ob + 8] = p[1]
    sig[ob + 9] = s[18]
    sig[ob + 10] = s[19]
    sig[ob + 11] = s[7]
    sig[ob + 12] = s[8]
    sig[ob + 13] = s[14]
    sig[ob + 14] = s[15]
    sig[ob + 15] = s[9]
    sig[ob + 16] = s[12]
    sig[ob + 17] = s[13]
    sig[ob + 18] = s[11]
    sig[ob + 19] = r[24]
    return 0


engine_kernel = _engine_kernel_floor


# -------------------------------------------------------------------------------------------- battery
@njit(cache=True)
def battery_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.battery.BatteryPack.do_step` (two-state thermal model)."""
    d, ix, c, st, th, yv, noise, p, kn = data
    p_pack = sig[ib + 3] if p[7] > 0.5 else sig[ib]
    h_conv = sig[ib + 1]
    t_amb = sig[ib + 2]
    if not (math.isfinite(p_pack) and math.isfinite(h_conv) and math.isfinite(t_amb)) or h_conv < 0.0:
        return ERR_BATTERY_INPUT
    cell_step(d, ix, c, st, p_pack, t, h, t_amb, h_conv, th, yv)
    soc_new = st[S_SOC]
    if not (0.0 <= soc_new <= 1.0):
        return ERR_SOC_RANGE
    # _publish(t_amb)
    i = yv[Y_I]
    v = yv[Y_V]
    ts = yv[Y_TSURF]
    k = kn[0]
    n0 = noise[k]
    n1 = noise[k + 1]
    n2 = noise[k + 2]
    n3 = noise[k + 3]
    kn[0] = k + 4
    sig[ob] = i * p[0]
    sig[ob + 1] = v * p[1]
    sig[ob + 2] = 100.0 * st[S_SOC]
    sig[ob + 3] = yv[Y_VOC] * p[1]
    sig[ob + 4] = yv[Y_TCORE]
    sig[ob + 5] = ts
    sig[ob + 6] = yv[Y_TMEAN]
    sig[ob + 7] = yv[Y_Q]
    sig[ob + 8] = i + p[3] + p[4] * n0
    sig[ob + 9] = v + p[5] * n1
    sig[ob + 10] = ts + p[6] * n2
    sig[ob + 11] = t_amb + p[6] * n3
    sig[ob + 12] = st[S_ELOSS] * p[2]
    sig[ob + 13] = st[S_ECHEM] * p[2]
    sig[ob + 14] = st[S_AH] * p[0]
    sig[ob + 15] = st[S_CLAMPS]
    return 0


# ------------------------------------------------------------------------------------------------ BMS
@njit(cache=True)
def _pc_coeffs(tp, h_w_m2k, keys, vals):
    """:meth:`shevsim.bms.power_capability.PowerCapability._thermal_coeffs`: the coefficients at ``h``
    rounded to 1e-3 W/m^2/K (a pure function of the rounded h, ``tp = [R, k, alpha, bq, dt_N, dt_1]``),
    memoised in a direct-mapped table ``keys`` / ``vals`` (the estimate revisits the same rounded values);
    returns the row of ``vals`` holding them."""
    hh = round3(h_w_m2k)
    n = keys.shape[0]
    q = hh * 1000.0
    slot = int(abs(q)) % n if math.isfinite(q) else 0
    if keys[slot] == hh:
        return slot
    a = two_state_ad_bd(hh, tp[0], tp[1], tp[2], tp[3], tp[4], False)
    o = two_state_out(hh, tp[0], tp[1])
    b = two_state_ad_bd(hh, tp[0], tp[1], tp[2], tp[3], tp[5], False)
    out = vals[slot]
    out[0] = a[0]
    out[1] = a[1]
    out[2] = a[2]
    out[3] = a[3]
    out[4] = a[4]
    out[5] = a[5]
    out[6] = a[6]
    out[7] = a[7]
    out[8] = o[3]
    out[9] = o[4]
    out[10] = o[5]
    out[11] = b[0]
    out[12] = b[1]
    out[13] = b[2]
    out[14] = b[3]
    out[15] = b[4]
    out[16] = b[6]
    keys[slot] = hh
    return slot


@njit(cache=True)
def bms_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.bms.BMS.do_step`: DEKF -> heat -> thermal filter -> power capability."""
    dd, dix, dk, xe, tst, tc, pd_, pix, pk, tp, ckeys, od, oix, xb, p, cvals = data
    i = sig[ib]
    v = sig[ib + 1]
    ts = sig[ib + 2]
    ta = sig[ib + 3]
    if not (math.isfinite(i) and math.isfinite(v) and math.isfinite(ts) and math.isfinite(ta)):
        return ERR_NAN_INPUT
    # 1. electrical DEKF and 2. heat with the previous T_mean (DEKF.step_heat)
    r = dekf_step(dd, dix, dk, xe[0], xe[1], xe[2], xe[3], xe[4], xe[5], xe[6], xe[7], xe[8], xe[9], xe[10],
                  xe[11], xe[12], xe[13], i, v, h, xb[0], xe[17])
    if not r[0]:
        return ERR_DEKF
    xe[0] = r[1]
    xe[1] = r[2]
    xe[2] = r[3]
    xe[14] = r[4]
    xe[3] = r[5]
    xe[4] = r[6]
    xe[15] = r[7]
    xe[16] = r[8]
    xe[5] = r[9]
    xe[6] = r[10]
    xe[7] = r[11]
    xe[8] = r[12]
    xe[9] = r[13]
    xe[10] = r[14]
    xe[11] = r[15]
    xe[12] = r[16]
    xe[13] = r[17]
    xe[17] = r[21]
    xe[18] = r[22]
    q = r[20]
    xb[4] = q
    # 3. thermal filter (ThermalKF/DKF/JEKF.update)
    if not (math.isfinite(ts) and math.isfinite(ta) and math.isfinite(q)):
        return ERR_THERMAL_INPUT
    code = int(p[2])
    if code == 1:
        est = dkf_step(tst, tc, ts, ta, q)
    elif code == 2:
        est = jekf_step(tst, tc, ts, ta, q)
    else:
        est = kf_step(tst, tc, ts, ta, q)
    xb[0] = est[0]
    xb[1] = est[1]
    xb[2] = est[2]
    xb[3] = est[4]
    # 4. power capability (_publish)
    soc = xe[0]
    v1 = xe[1]
    rs = xe[14]
    r1 = xe[15]
    c1 = xe[16]
    slot = _pc_coeffs(tp, xb[3], ckeys, cvals)
    lim = power_limits(pd_, pix, pk, cvals[slot], soc, v1, rs, r1, c1, xb[0], xb[1], ta, xb[5], xb[6])
    xb[5] = lim[0]
    xb[6] = lim[1]
    ns = p[0]
    np_ = p[1]
    sig[ob] = 100.0 * soc
    sig[ob + 1] = v1 * ns
    sig[ob + 2] = rs * ns / np_
    sig[ob + 3] = r1 * ns / np_
    sig[ob + 4] = c1 * np_ / ns
    sig[ob + 15] = rs
    sig[ob + 5] = xb[0]
    sig[ob + 6] = xb[1]
    sig[ob + 7] = xb[2]
    sig[ob + 8] = xb[3]
    sig[ob + 9] = q
    sig[ob + 10] = _t1_value(od, oix[0], oix[1], soc) * ns
    sig[ob + 11] = lim[2]
    sig[ob + 12] = lim[3]
    sig[ob + 13] = lim[0]
    sig[ob + 14] = lim[1]
    return 0


# -------------------------------------------------------------------------------------- supervisors
@njit(cache=True)
def _check_h(h, ts):
    return abs(h - ts) > 1e-9 * pmax(1.0, ts)


@njit(cache=True)
def _rate(inner, rates, pw):
    return rates[bisect_right(inner, pw)]


@njit(cache=True)
def rule_kernel(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.supervisors.RuleSupervisor.do_step`."""
    rp, inner, rates, x = data
    if _check_h(h, rp[12]):
        return ERR_SAMPLE_TIME
    for j in range(5):
        if not math.isfinite(sig[ib + j]):
            return ERR_NAN_INPUT
    demand = sig[ib]
    prev = x[1]
    on, cmd = rule_command(rp, inner, rates, x[0] > 0.5, sig[ib + 1], demand, prev, sig[ib + 3], sig[ib + 4])
    x[0] = 1.0 if on else 0.0
    sig[ob] = cmd
    sig[ob + 1] = _rate(inner, rates, prev)
    sig[ob + 2] = demand - cmd
    sig[ob + 3] = 1.0 if on else 0.0
    x[1] = cmd
    return 0


@njit(cache=True)
def _mpc_kernel_daqp(data, sig, ib, ob, t, h):
    """:meth:`shevsim.components.supervisors.MPCSupervisor.do_step`: the call itself is
    :func:`shevsim.supervisor.mpc.mpc_move` (QP build, DAQP's C library, first move or fallback), the one the
    component's supervisor runs; ``data`` = its arguments (``MPCSupervisor.arrays``), ``x[0]`` the previous
    command."""
    (mp, rp, inner, rates, rinner, rrates, x, plan, c, fp, fs, fsl, MtM, LtL, Mt1, Mtr, Lt1, soc_idx, H, f, A, bu,
     bl, aux, ws, qp, res, sense, z, lam, flags, wset, wsgn, kL, kY, kS, kv, kLU, kfac) = data
    if _check_h(h, mp[0]):
        return ERR_SAMPLE_TIME
    demand = sig[ib]
    gen = x[0]                                    # the previous command u(k-1)
    cmd, rate = mpc_move(mp, rp, inner, rates, rinner, rrates, x, plan, c, fp, fs, fsl, MtM, LtL, Mt1, Mtr, Lt1,
                         soc_idx, H, f, A, bu, bl, aux, ws, qp, res, sense, z, lam, flags, wset, wsgn, kL, kY, kS,
                         kv, kLU, kfac, sig[ib + 1], demand, gen,
                         sig[ib + 3], sig[ib + 4], sig[ib + 5], sig[ib + 6])
    sig[ob] = cmd
    sig[ob + 1] = rate
    sig[ob + 2] = demand - cmd
    sig[ob + 3] = x[1]
    sig[ob + 4] = x[4]
    sig[ob + 5] = x[5]
    x[0] = cmd
    return 0


@njit(cache=True)
def _mpc_kernel_unavailable(data, sig, ib, ob, t, h):
    """Stand-in when DAQP's C library cannot be bound (MPC scenarios are then declined)."""
    return ERR_SAMPLE_TIME


# the loop must not reference the DAQP binding when it is unavailable (its symbols would not link)
mpc_kernel = _mpc_kernel_daqp if daqp_nb.available()[0] else _mpc_kernel_unavailable
