"""model.py - the cell model written once: OCV-R-RC[-RC] electrical step with its effects, two-state thermal.

Every user of the cell physics - the battery component (:mod:`shevsim.components.battery`), the
calibration (:mod:`shevsim.calibrate.cell`) and the replay of measured profiles - calls the functions of
this module.  They are plain Python on packed arrays and floats, compiled with numba
(``cell_step = njit(_cell_step)``); the uncompiled reference of each is ``f.py_func``: there is no second
copy of the arithmetic anywhere.

Model (current ``i`` positive = discharge; per cell; SI inside; seed 4.6, B.4-B.5, 5.16)::

    dSOC/dt = -i / (3600 Q)                                       Q = capacity_ah
    dV_j/dt = -V_j / (R_j C_j) + i / C_j,   j = 1, 2              (branch 2 absent when r2_scale = 0)
    V_t     = V_oc(SOC) - R_s i - V_1 - V_2 + M h                 (M h: one-state hysteresis)
    q       = i^2 R_s + sum_j V_j^2 / R_j - i T dU/dT             (heat, seed 5.16, T in kelvin)

``R_s, R_j, C_j`` come from the SOC x temperature tables (discharge table for ``i >= 0``, charge for
``i < 0``) looked up at the cell mean temperature (25 degC when ``temperature_dependent`` is off), times
the scale factors ``rs_scale, r1_scale, c1_scale, r2_scale, c2_scale``.

The step over ``[t, t + h]`` holds the input (cell current, or cell power solved for the step-averaged
terminal power: ``p h = i (a - b i)``; see :mod:`shevsim.components.battery`), advances SOC and the RC
branches exactly (ZOH), integrates ``V_j^2 / R_j`` exactly, and steps the two-state radial thermal model
exactly (:func:`shevsim.battery.thermal.two_state_coeffs`).

Effects (each a parameter of the battery component; the neutral value reproduces the plain model
bit for bit):

===================  ==================================================================  =============
effect               term                                                                neutral
===================  ==================================================================  =============
entropic heat        ``-i T dU/dT(SOC)`` with dU/dT piecewise linear in SOC through       ``[]`` (table
                     the knots ``dudt_soc_frac`` / ``dudt_v_k`` (sign changes allowed)    if entropic_heat)
Arrhenius            all resistances x ``exp(Ea/R (1/T - 1/T_ref))``, T = mean cell T      ``arrhenius_ea_r_k = 0``
convection change    ``h -> h f`` after ``h_change_time_s`` (logistic over                ``h_change_factor = 1``
                     ``h_change_width_s``; a step when 0)
OCV hysteresis       ``h+ = e^{-|g i dt / Q|} h - (1 - e^{..}) sign(i)``, ``V += M h``      ``hyst_max_v = 0``
capacity             ``capacity_ah`` differs from the rated value                        rated
current offset       true current = commanded (sensor) current - ``current_offset_a``;   ``0``
                     the measured current output reads true + offset
low-SOC resistance   all resistances x ``1 + g exp(-SOC / s)``                            ``lowsoc_r_gain = 0``
second RC branch     ``r2_scale > 0`` (``0`` removes the branch)                          component: 1
solid diffusion      the OCV read at the particles' surface SOC, ``SOC + w - tau_d i/(105 Q)``, ``diffusion_time_s
                     ``dw/dt = -30 w/tau_d - (12/7) i/Q`` (``tau_d = R^2/D``, the three-      = 0``
                     parameter polynomial profile of a sphere); heat ``i (OCV(SOC) -
                     OCV(surface))``
===================  ==================================================================  =============

Packed parameter vector ``c`` (see :func:`pack_params`), state vector ``st`` =
``[soc, v1, v2, hyst, x0 (T_mean), x1 (gamma), e_chem, e_loss, ah, clamps, w (surface SOC - SOC, diffusion)]`` (per cell, J and A.h), and
output vector ``y`` = ``[i, voc, v, t_core, t_surface, q, rs, t_mean, h_eff]``.
"""
from __future__ import annotations

import math

import numpy as np

from shevsim.battery.thermal import two_state_coeffs
from shevsim.core.lookup import njit, t1_integral, t1_slope, t1_value, ecm_lookup, interp_held

from shevsim.battery.cell import FARADAY_C_MOL  # noqa: E402  (one constant)

# indices of the packed parameter vector
(C_NP, C_NPACK, C_QAS, C_CURRENT_MODE, C_TDEP, C_ENTROPIC, C_F, C_RS, C_R1, C_C1, C_R2, C_C2, C_EA, C_TREF,
 C_HYST_M, C_HYST_G, C_IOFF, C_LS_G, C_LS_S, C_NDUDT, C_HFAC, C_HCH_T, C_HCH_F, C_HCH_W, C_RAD, C_LEN, C_RHO,
 C_CP, C_KT, C_TDIFF, C_KNOTS) = range(31)
N_STATE = 11
N_OUT = 9
(S_SOC, S_V1, S_V2, S_HY, S_X0, S_X1, S_ECHEM, S_ELOSS, S_AH, S_CLAMPS, S_WD) = range(N_STATE)
# solid diffusion (the three-parameter polynomial profile of a sphere, Subramanian et al. 2005, in SOC units):
# surface SOC = SOC + w - tau_d i / (105 Q), dw/dt = -30 w / tau_d - (12/7) i / Q; steady state: -tau_d i / (15 Q)
DIFF_W_RATE = 30.0
DIFF_W_GAIN = 2.0 / 35.0      # w_inf = -DIFF_W_GAIN tau_d i / Q
DIFF_INSTANT = 1.0 / 105.0
(Y_I, Y_VOC, Y_V, Y_TCORE, Y_TSURF, Y_Q, Y_RS, Y_TMEAN, Y_HEFF) = range(N_OUT)


def pack_params(p, capacity_ah=None) -> np.ndarray:
    """The packed parameter vector ``c`` of a :class:`~shevsim.components.battery.BatteryPackParams`."""
    knots_s = [float(v) for v in p.dudt_soc_frac]
    knots_v = [float(v) for v in p.dudt_v_k]
    cap = p.capacity_ah if capacity_ah is None else capacity_ah
    c = [float(p.n_parallel), float(p.n_series * p.n_parallel), 3600.0 * cap,
         1.0 if p.input_mode == "current" else 0.0, 1.0 if p.temperature_dependent else 0.0,
         1.0 if p.entropic_heat else 0.0, FARADAY_C_MOL,
         p.rs_scale, p.r1_scale, p.c1_scale, p.r2_scale, p.c2_scale, p.arrhenius_ea_r_k, p.arrhenius_t_ref_c,
         p.hyst_max_v, p.hyst_rate, p.current_offset_a, p.lowsoc_r_gain, p.lowsoc_r_scale_frac,
         float(len(knots_s)), p.h_conv_factor, p.h_change_time_s, p.h_change_factor, p.h_change_width_s,
         p.radius_m, p.length_m, p.density_kg_m3, p.cp_j_kgk, p.kt_w_mk, p.diffusion_time_s]
    return np.array(c + knots_s + knots_v, dtype=np.float64)


def _effective_h(c, t, h_conv):
    """Convection coefficient acting at time ``t`` [W/(m2.K)]: input x ``h_conv_factor`` x the change."""
    hf = h_conv * c[C_HFAC]
    f = c[C_HCH_F]
    if f != 1.0:
        w = c[C_HCH_W]
        if w > 0.0:
            z = (t - c[C_HCH_T]) / w
            if z > 40.0:
                sg = 1.0
            elif z < -40.0:
                sg = 0.0
            else:
                sg = 1.0 / (1.0 + math.exp(-z))
        else:
            sg = 1.0 if t >= c[C_HCH_T] else 0.0
        hf = hf * (1.0 + (f - 1.0) * sg)
    return hf


def _dudt(c, soc):
    """dU/dT [V/K] from the knots (piecewise linear, held beyond the end knots); only called with knots."""
    n = int(c[C_NDUDT])
    return interp_held(c, C_KNOTS, c, C_KNOTS + n, n, soc)


def _rc_branch(v0, i, r, tau, ex, g, h):
    """Exact ``(v_end, int v dt, int v^2 dt)`` of an RC branch over ``h`` (current held); ``g = tau (1 - ex)``."""
    vinf = r * i
    dd = v0 - vinf
    return (vinf + dd * ex, vinf * h + dd * g,
            vinf * vinf * h + 2.0 * vinf * dd * g + dd * dd * 0.5 * tau * (1.0 - ex * ex))


def _cell_electrical(d, ix, c, st, p_in, h, t_mean, y):
    """Advance the electrical state ``st`` of one cell over ``h`` with the input held; fill ``y``.

    ``p_in`` is the pack input (current command [A] or power [W], + discharge); ``t_mean`` the cell mean
    temperature [degC] over the step.  Writes ``y[Y_I, Y_RS, Y_Q, Y_VOC, Y_V]`` and returns the heat [W].
    """
    q_as = c[C_QAS]
    current_mode = c[C_CURRENT_MODE] > 0.5
    p_cell = (p_in / c[C_NP] - c[C_IOFF]) if current_mode else (p_in / c[C_NPACK])
    soc = st[S_SOC]
    v1 = st[S_V1]
    v2 = st[S_V2]
    t_look = t_mean if c[C_TDEP] > 0.5 else 25.0
    rs, r1, c1, r2, c2 = ecm_lookup(d, ix, soc, t_look, p_cell)
    sr = 1.0
    if c[C_EA] != 0.0:
        sr = math.exp(c[C_EA] * (1.0 / (t_mean + 273.15) - 1.0 / (c[C_TREF] + 273.15)))
    if c[C_LS_G] != 0.0:
        # (the SOC floored at 0: below it a negative gain would turn the resistances negative)
        sr = sr * (1.0 + c[C_LS_G] * math.exp(-max(soc, 0.0) / c[C_LS_S]))
    rs = rs * c[C_RS] * sr
    r1 = r1 * c[C_R1] * sr
    c1 = c1 * c[C_C1]
    two = c[C_R2] > 0.0
    r2 = r2 * c[C_R2] * sr
    c2 = c2 * c[C_C2]
    oo, no = ix[0], ix[1]
    tau1 = r1 * c1
    ex1 = math.exp(-h / tau1)
    g1 = tau1 * (1.0 - ex1)
    td = c[C_TDIFF]
    diff = td > 0.0
    sv = soc           # the SOC the OCV is read at: the particles' surface with solid diffusion
    w0 = 0.0
    exw = 0.0
    kw = 0.0
    kd = 0.0
    if diff:
        w0 = st[S_WD]
        sv = soc + w0
        exw = math.exp(-h * DIFF_W_RATE / td)
        gw = td / DIFF_W_RATE * (1.0 - exw)
        kw = DIFF_W_GAIN * td / q_as
        kd = DIFF_INSTANT * td / q_as
    slope = t1_slope(d, oo, no, sv)
    a = h * t1_value(d, oo, no, sv) - v1 * g1
    b = h * rs + r1 * (h - g1)
    if diff:
        # the surface's drift over the step, linear in the OCV's slope: w relaxes towards -kw i (time
        # constant td / 30) and the instantaneous part -kd i acts over the whole step
        a = a - slope * w0 * (h - gw)
        b = b + slope * (kw * (h - gw) + kd * h)
    tau2 = 1.0
    ex2 = 0.0
    g2 = 0.0
    if two:
        tau2 = r2 * c2
        ex2 = math.exp(-h / tau2)
        g2 = tau2 * (1.0 - ex2)
        a = a - v2 * g2
        b = b + r2 * (h - g2)
    b = b + 0.5 * h * h * slope / q_as
    m_h = c[C_HYST_M]
    hy = st[S_HY]
    if m_h != 0.0:
        a = a + h * m_h * hy
    if current_mode:
        i = p_cell
    else:
        ph = p_cell * h
        disc = a * a - 4.0 * b * ph
        if disc >= 0.0 and a > 0.0:
            i = 2.0 * ph / (a + math.sqrt(disc))
        else:
            i = 0.5 * a / b if a > 0.0 else 0.0
            st[S_CLAMPS] += 1.0
    soc_new = soc - i * h / q_as
    v1n, iv1, iv1s = _rc_branch(v1, i, r1, tau1, ex1, g1, h)
    q = i * i * rs + iv1s / r1 / h
    e_loss = i * i * rs * h + i * iv1
    v2n = 0.0
    if two:
        v2n, iv2, iv2s = _rc_branch(v2, i, r2, tau2, ex2, g2, h)
        q = i * i * rs + (iv1s / r1 + iv2s / r2) / h
        e_loss = i * i * rs * h + i * (iv1 + iv2)
    if m_h != 0.0:
        eh = math.exp(-abs(c[C_HYST_G] * i * h / q_as))
        sgn = 1.0 if i > 0.0 else (-1.0 if i < 0.0 else 0.0)
        hy = eh * hy - (1.0 - eh) * sgn
        e_loss = e_loss - i * m_h * hy * h
    wn = 0.0
    voc = t1_value(d, oo, no, soc_new)
    vsurf = voc
    if diff:
        # the diffusion overpotential OCV(SOC) - OCV(surface SOC) dissipates i eta (mean of the step's ends)
        wn = -kw * i + (w0 + kw * i) * exw
        vsurf = t1_value(d, oo, no, soc_new + wn - kd * i)
        eta = 0.5 * (t1_value(d, oo, no, soc) - t1_value(d, oo, no, soc + w0 - kd * i) + voc - vsurf)
        q = q + i * eta
        e_loss = e_loss + i * eta * h
    if c[C_NDUDT] > 0.0:
        q -= i * (t_mean + 273.15) * _dudt(c, 0.5 * (soc + soc_new))
    elif c[C_ENTROPIC] > 0.5:
        ds = t1_value(d, ix[2], ix[3], 0.5 * (soc + soc_new))
        q -= i * (t_mean + 273.15) * ds / c[C_F]
    st[S_ECHEM] += q_as * (t1_integral(d, oo, no, soc) - t1_integral(d, oo, no, soc_new))
    st[S_ELOSS] += e_loss
    st[S_AH] += abs(i) * h / 3600.0
    st[S_SOC] = soc_new
    st[S_V1] = v1n
    st[S_V2] = v2n
    st[S_HY] = hy
    st[S_WD] = wn
    y[Y_I] = i
    y[Y_RS] = rs
    y[Y_Q] = q
    y[Y_VOC] = voc
    y[Y_V] = vsurf - rs * i - v1n - v2n + m_h * hy
    return q


def _thermal_outputs(c, st, t_amb, h_eff, y):
    """Core / surface temperature of the two-state state in ``st`` (outputs of the model at the state)."""
    th = two_state_coeffs(c[C_RAD], c[C_LEN], c[C_RHO], c[C_CP], c[C_KT], h_eff, 1.0)
    y[Y_TCORE] = th[8] * st[S_X0] + th[9] * st[S_X1] + th[10] * t_amb
    y[Y_TSURF] = th[11] * st[S_X0] + th[12] * st[S_X1] + th[13] * t_amb
    y[Y_TMEAN] = st[S_X0]
    y[Y_HEFF] = h_eff


def _thermal_coeffs(c, h_eff, h, th):
    """Two-state ZOH/output coefficients for ``(h_eff, h)`` into the workspace ``th`` (16 floats; the last
    two hold the key): recomputed only when the key changes."""
    if th[14] != h_eff or th[15] != h:
        co = two_state_coeffs(c[C_RAD], c[C_LEN], c[C_RHO], c[C_CP], c[C_KT], h_eff, h)
        for k in range(14):
            th[k] = co[k]
        th[14] = h_eff
        th[15] = h


def _cell_step(d, ix, c, st, p_in, t, h, t_amb, h_conv, th, y):
    """One step ``[t, t + h]`` of a cell with the two-state thermal model; ``y`` = outputs at ``t + h``.

    ``h_conv`` is the convection input [W/(m2.K)] (the component's ``h_conv_w_m2k``); the effective
    coefficient over the step is taken at the step's midpoint (:func:`_effective_h`).  ``th`` is the
    caller's 16-float workspace of thermal coefficients (start it with NaN keys).
    """
    h_eff = _effective_h(c, t + 0.5 * h, h_conv)
    x0 = st[S_X0]
    x1 = st[S_X1]
    q = _cell_electrical(d, ix, c, st, p_in, h, x0, y)
    _thermal_coeffs(c, h_eff, h, th)
    x0n = th[0] * x0 + th[1] * x1 + th[4] * q + th[5] * t_amb
    x1n = th[2] * x0 + th[3] * x1 + th[6] * q + th[7] * t_amb
    st[S_X0] = x0n
    st[S_X1] = x1n
    h_out = _effective_h(c, t + h, h_conv)
    y[Y_TCORE] = th[8] * x0n + th[9] * x1n + th[10] * t_amb
    y[Y_TSURF] = th[11] * x0n + th[12] * x1n + th[13] * t_amb
    if h_out != h_eff:
        _thermal_outputs(c, st, t_amb, h_out, y)
    y[Y_TMEAN] = x0n
    y[Y_HEFF] = h_out


def _run_profile(d, ix, c, st, t, p_in, t_amb, h_conv, out_v, out_ts, out_tc):
    """Step a cell through a sampled input profile: the loop the replay's master runs, compiled.

    Sample ``k >= 1`` is the output at ``t[k]`` of the step ``[t[k-1], t[k]]`` with the input ``p_in[k]``
    (and ``t_amb[k]``) held - the value the Gauss-Seidel master hands a component from a source that
    precedes it; sample 0 is the initial state with ``p_in[0]``.  Returns the number of steps whose
    SOC left [0, 1] (the profile keeps running: the caller decides).
    """
    n = t.shape[0]
    y = np.zeros(N_OUT)
    th = np.full(16, np.nan)
    bad = 0
    # initial outputs (no step, as the component's initialize): the open-circuit voltage
    out_v[0] = t1_value(d, ix[0], ix[1], st[S_SOC] + st[S_WD]) + c[C_HYST_M] * st[S_HY]
    _thermal_outputs(c, st, t_amb[0], _effective_h(c, t[0], h_conv), y)
    out_ts[0] = y[Y_TSURF]
    out_tc[0] = y[Y_TCORE]
    hp = t[1] - t[0] if n > 1 else 0.0
    for k in range(1, n):
        dt = t[k] - t[k - 1]
        if abs(dt - hp) <= 1e-9 * hp:
            dt = hp          # a regular grid's steps differ in the last bits: one step (as the master's)
        else:
            hp = dt
        _cell_step(d, ix, c, st, p_in[k], t[k - 1], dt, t_amb[k], h_conv, th, y)
        out_v[k] = y[Y_V]
        out_ts[k] = y[Y_TSURF]
        out_tc[k] = y[Y_TCORE]
        if not (0.0 <= st[S_SOC] <= 1.0):
            bad += 1
    return bad


def _jit(f):
    """Compile one source.  ``error_model="numpy"``: IEEE division (no Python zero-division check and its
    branch on every ``/``), the same results for every finite, non-zero divisor."""
    return njit(cache=True, error_model="numpy")(f)


_effective_h = _jit(_effective_h)
_dudt = _jit(_dudt)
_rc_branch = _jit(_rc_branch)
cell_electrical = _jit(_cell_electrical)
_cell_electrical = cell_electrical
_thermal_outputs = _jit(_thermal_outputs)
_thermal_coeffs = _jit(_thermal_coeffs)
cell_step = _jit(_cell_step)
_cell_step = cell_step
run_profile = _jit(_run_profile)
effective_h = _effective_h
thermal_outputs = _thermal_outputs

__all__ = ["pack_params", "cell_step", "cell_electrical", "run_profile", "effective_h", "thermal_outputs",
           "FARADAY_C_MOL", "N_STATE", "N_OUT"]
