"""engine.py - diesel engine-generator physics (seed Ch. V Fig. 5.2, App. B B.1, Figs. B.1-B.3, A.2).

Chain, advanced in sub-steps of at most ``max_substep_s`` with the inputs held:

1. **Power-rate limit** on the electrical power command ``P_cmd`` (clipped to ``[0, P_max]``):
   ``P_lim += clip(P_cmd - P_lim, -R_down dt, R_up dt)``; ``R_up`` is the input
   ``power_rate_max_wps`` (the supervisor's / study's limit).
2. **Optimal operating line** (``optimal_operating_line.csv``): speed set point ``w*(P_lim)`` and the
   shaft power ``P_sh*(P_lim)`` that yields ``P_lim`` at the generator terminals in steady state.
3. **Shaft speed** follows ``w*`` through the generator's speed loop, modelled as a first-order
   response (time constant ``speed_time_constant_s``, exact exponential) with an acceleration
   limit. Justification: the generator torque is the fast actuator that closes the speed loop;
   what matters at the supervisory time scale (0.2 s) is that speed changes are not instantaneous
   and that the inertia energy is booked. The generator torque is whatever keeps that trajectory:
   ``tau_g = tau_e - J dw/dt``.
4. **Torque demand** ``tau* = P_sh*(P_lim) / w`` (at the actual speed), clipped to the full-load
   curve.
5. **PI fuel (rack) controller** (B.1): ``zeta = k_P (tau* - tau_e) + k_I int (tau* - tau_e) dt``,
   ``zeta in [0, 1]``; anti-windup by conditional integration (the integral is frozen while the rack
   is saturated in the direction of the error).
6. **Turbo lag** (B.1 text): the fuel rate the engine can burn follows the rack's fuel command
   ``m_c = zeta * m_fl(w)`` (``m_fl`` = full-load fuel) through a first-order filter with time constant
   ``turbo_lag_s`` when rising (air path / boost lag) and ``fuel_fall_s`` when falling (fuel cut is
   immediate); exact exponential update, and the fuel mass over a sub-step is the exact integral.
7. **Engine torque map** (Fig. B.1 form): ``tau_e = T(w, m_f)`` (``engine_torque_map.csv``; negative at
   fuel cut = friction).
8. **Soot**: quasi-static map ``S(w, tau_e)`` [mg/s] (Fig. B.2 role, ``soot_map.csv``) times
   ``soot_scale_frac`` plus a **transient term**
   ``S_tr = transient_soot_mg_per_g * d * (d / m_fl(w))`` [mg/s] with the fuel deficit
   ``d = max(0, m_c - m_f)``: the fuel the rack demands but the lagging air path cannot yet support
   (the over-fuelling of a tip-in against turbo lag). Soot per gram of deficit grows with the
   relative deficit ``d / m_fl`` (the air-fuel ratio drop), reaching ``transient_soot_mg_per_g`` at a
   full-load deficit. It must be super-linear: for a linear filter ``int d dt = tau_turbo * (rise
   of m_f)`` whatever the ramp, so a linear term could not respond to the ramp rate. Seed App. A.2: more than 50 % of soot is produced in transients [142], which a
   quasi-static map misses. A slower power ramp (tighter ``power_rate_max_wps``) keeps the torque
   error, hence the rack and ``m_c - m_f``, small, so it cuts transient soot - the seed's
   fuel/soot trade-off.
9. **Generator** efficiency ``eta_g(w, |tau_g|)`` (Fig. B.3 role, ``generator_eff_map.csv``).
10. **Load shedding** (input ``elec_max_w`` = what the bus can absorb without over-charging the
    battery, ``L = max(elec_max_w, 0)``). A series hybrid's generator controller cuts generator torque
    at once when the bus cannot take the power, and the engine governor cuts fuel; the downward
    power-rate limit is a smoothness constraint of normal operation, not physics. Hence, per sub-step:

    a. *command cut*: after the rate limit, ``P_lim = min(P_lim, L)`` (bypassing ``R_down``); the
       torque demand (4) follows at once, the PI rack (5) drops and the fuel falls with
       ``fuel_fall_s`` (6);
    b. *generator torque cut*: if the electrical energy of the sub-step would exceed ``L dt``, the
       generator torque is cut so that ``E_el = L dt`` exactly; its shaft work is
       ``W_g = min(L dt / eta_g(w, tau_gc), W_g,free)`` (efficiency at the cut torque
       ``tau_gc = L dt / (eta_free w_avg dt)``; never more shaft work than uncut), and the surplus
       engine work accelerates the shaft: ``dKE = W_e - W_g``, ``w1 = sqrt(w0^2 + 2 dKE / J)``; the
       engine torque at the end of the sub-step is re-read from the map at that speed;
    c. *governor*: while the generator torque is cut (previous sub-step) the generator no longer
       holds the speed, so the speed loop's torque ``J (w* - w) / T_w`` is asked of the engine
       instead (added to the torque demand of the PI rack): the over-speed from (b) is removed by
       cutting fuel, and the shaft's kinetic energy then returns to the bus (within ``L``).

    d. *generator floor* (input ``elec_min_w`` = what the bus needs from the generator so that the
       battery stays within its discharge capability, motors + auxiliaries - ``P_b,max``; ``<= 0``: none;
       issue 14): if the electrical energy of the sub-step would fall below ``F dt`` (``F = min(elec_min_w,
       P_max)``) and (b) did not act, the generator torque is raised so that ``E_el = F dt``: shaft work
       ``W_g = F dt / eta_g(w, tau_gf)`` (efficiency at ``tau_gf = F dt / (eta_free w_avg dt)``), the deficit
       comes out of the shaft's kinetic energy, ``w1 = sqrt(w0^2 + 2 (W_e - W_g) / J)``, but never below
       the optimal line's idle speed ``w*(0)`` nor above the unraised ``w1`` (then ``E_el`` is what that
       speed allows); the engine torque is re-read at that speed, and the speed loop then asks the engine
       for the dip back (fuel).  This holds the battery within its discharge limit in the step the motors
       were clamped against it, through the generator's own dynamics (the speed-up dips of the optimal
       line).

    (b) makes the electrical output of every sub-step ``<= L`` (hence its step mean too), exactly;
    the bookkeeping below stays exact because the surplus is booked as ``dKE``. Counted as
    ``shed_n`` (number of episodes: sub-steps with (a) or (b) following one without) and ``shed_s``
    (time with (a) or (b) active).

11. **Soot analyser** (what a measurement of the soot rate reads; off by default): the soot rate of
    each sub-step (held over it) through a first-order lag ``soot_analyzer_tau_s`` (exact exponential;
    0 = no lag), plus a constant ``soot_analyzer_offset_mgps``; the reading reported for a step is its
    exact mean over the step.  With both at 0 it equals the step's mean soot rate bit for bit.  It does
    not act on the engine: it lets a calibration compare the model with an analyser's record through
    the same physics (:mod:`shevsim.calibrate.engine`).

The physics above is written once, in :func:`step` (numba-compiled; :data:`step_py` is the same source
run by the Python interpreter), on maps packed by :func:`pack_maps`; every extrapolation rule of the
maps (``clamp``, ``linear``, ``error``) is carried in the packed form (:func:`shevsim.core.lookup.curve_ex`,
``grid_ex``).  :class:`EngineGenStep` binds it to one (maps, parameters) pair for the component.

Energy bookkeeping per sub-step (all exact for the discrete trajectory):
``E_fuel = LHV * fuel mass``; ``W_e = mean(tau_e) * mean(w) * dt`` (trapezoid in torque);
``dKE = J (w1^2 - w0^2)/2``; generator shaft work ``W_g = W_e - dKE``; electrical
``E_el = W_g eta_g`` (``W_g / eta_g`` when motoring); ``engine_loss = E_fuel - W_e``;
``gen_loss = W_g - E_el``; hence ``E_fuel = E_el + engine_loss + gen_loss + dKE_shaft`` (also with
load shedding, where ``dKE = W_e - W_g`` defines the new speed).
"""
from __future__ import annotations

import math

from .maps import load_curve_csv, load_grid_csv, scaled_curve, scaled_grid
from shevsim.core.paths import DATA_ROOT

ROOT = DATA_ROOT
EG_DIR = ROOT / "components" / "engine_generator"


class EngineGenMaps:
    """All maps of the engine-generator, loaded from the derived CSVs (see build_maps)."""

    def __init__(self, fuel_map_file, torque_map_file, max_torque_file, soot_map_file,
                 generator_eff_file, generator_max_torque_file, ool_file):
        self.fuel = load_grid_csv(fuel_map_file, "speed_radps", "torque_nm", "fuel_gps", ("clamp", "linear"))
        self.torque = load_grid_csv(torque_map_file, "speed_radps", "fuel_gps", "torque_nm", ("clamp", "clamp"))
        self.tmax = load_curve_csv(max_torque_file, "speed_radps", "torque_max_nm")
        self.fmax = load_curve_csv(max_torque_file, "speed_radps", "fuel_max_gps")
        self.soot = load_grid_csv(soot_map_file, "speed_radps", "torque_nm", "soot_mgps", "clamp")
        self.geff = load_grid_csv(generator_eff_file, "speed_radps", "torque_nm", "efficiency_frac", "clamp")
        self.gmax = load_curve_csv(generator_max_torque_file, "speed_radps", "torque_max_nm")
        self.ool_speed = load_curve_csv(ool_file, "elec_power_w", "speed_radps")
        self.ool_shaft = load_curve_csv(ool_file, "elec_power_w", "shaft_power_w")
        self.ool_fuel = load_curve_csv(ool_file, "elec_power_w", "fuel_gps")
        self.p_max_w = float(self.ool_speed.x[-1])
        self.w_min = float(self.fuel.x[0])

    def scaled(self, k: float) -> "EngineGenMaps":
        """The maps of an engine-generator ``k`` times as powerful (rated power x ``k``), by the rule
        of Autonomie and FASTSim (maps normalised by rated power; speeds unchanged):

        * engine: torque axes and full-load torque x k; fuel rate x k at (speed, torque x k), so the
          brake-specific fuel consumption at the same speed and relative load is unchanged;
          the torque map torque(speed, fuel) gets both axes' scaled values; full-load fuel x k;
        * soot map x k at (speed, torque x k) (soot per fuel unchanged);
        * generator: efficiency at (speed, torque x k) unchanged; max torque x k;
        * optimal operating line: electrical and shaft power x k, fuel x k, speed unchanged.

        ``k = 1`` gives maps equal to these (every array multiplied by 1.0: exact).
        """
        import copy
        k = float(k)
        if not (k > 0.0 and math.isfinite(k)):
            raise ValueError(f"engine-generator power scale must be a finite number > 0, got {k!r}")
        m = copy.copy(self)
        m.fuel = scaled_grid(self.fuel, k, k)
        m.torque = scaled_grid(self.torque, k, k)
        m.tmax = scaled_curve(self.tmax, 1.0, k)
        m.fmax = scaled_curve(self.fmax, 1.0, k)
        m.soot = scaled_grid(self.soot, k, k)
        m.geff = scaled_grid(self.geff, k, 1.0)
        m.gmax = scaled_curve(self.gmax, 1.0, k)
        m.ool_speed = scaled_curve(self.ool_speed, k, 1.0)
        m.ool_shaft = scaled_curve(self.ool_shaft, k, k)
        m.ool_fuel = scaled_curve(self.ool_fuel, k, k)
        m.p_max_w = float(m.ool_speed.x[-1])
        m.w_min = float(m.fuel.x[0])
        return m

    @classmethod
    def default(cls) -> "EngineGenMaps":
        return cls(EG_DIR / "engine_fuel_map.csv", EG_DIR / "engine_torque_map.csv",
                   EG_DIR / "engine_max_torque.csv", EG_DIR / "soot_map.csv",
                   EG_DIR / "generator_eff_map.csv", EG_DIR / "generator_max_torque.csv",
                   EG_DIR / "optimal_operating_line.csv")

    def fuel_quasi_static(self, p_elec_w: float) -> float:
        """Steady-state fuel rate [g/s] at electrical output ``p_elec_w`` (Fig. 5.2a)."""
        return self.ool_fuel(p_elec_w)


STATE = ("p_lim", "w", "integ", "rack", "m_f", "tau_e", "fuel_cmd", "fuel_g", "fuel_j", "eng_loss_j",
         "shaft_j", "ke_j", "gen_loss_j", "elec_j", "soot_mg", "soot_tr_mg", "gen_sat", "shed", "shed_n",
         "shed_s", "soot_lag")
"""The state of the engine-generator, in the order :func:`step` takes and returns it."""

PRM_FIELDS = ("max_substep_s", "power_rate_down_max_wps", "shaft_inertia_kg_m2", "rack_kp_per_nm",
              "rack_ki_per_nm_s", "speed_time_constant_s", "speed_accel_max_radps2", "turbo_lag_s",
              "fuel_fall_s", "fuel_lhv_j_per_g", "transient_soot_mg_per_g", "soot_scale_frac",
              "soot_analyzer_tau_s", "soot_analyzer_offset_mgps")
"""The parameters :func:`step` reads, in the order of its packed parameter array ``c``."""


class EngineGenState:
    """Mutable state of the engine-generator (plain floats; deep-copied for save/restore)."""

    __slots__ = STATE

    def __init__(self):
        for s in self.__slots__:
            setattr(self, s, 0.0)

    def __deepcopy__(self, memo):
        c = EngineGenState()
        for s in self.__slots__:
            setattr(c, s, getattr(self, s))
        return c

    def values(self) -> tuple:
        """The state as a tuple in the order of :data:`STATE`."""
        return tuple(getattr(self, s) for s in STATE)

    def set_values(self, vals) -> None:
        for s, v in zip(STATE, vals):
            setattr(self, s, v)


def steady_state(maps: EngineGenMaps, p_elec_w: float, state: EngineGenState | None = None,
                 soot_scale_frac: float = 1.0) -> EngineGenState:
    """State in steady operation at ``p_elec_w`` on the optimal line (cumulative sums left as given).

    The analyser's lagged soot rate ``soot_lag`` starts at the quasi-static soot rate
    ``soot_scale_frac * S(w, tau_e)`` (no transient soot in steady operation)."""
    st = state if state is not None else EngineGenState()
    p = min(max(p_elec_w, 0.0), maps.p_max_w)
    st.p_lim = p
    st.w = maps.ool_speed(p)
    st.tau_e = maps.ool_shaft(p) / st.w
    st.m_f = maps.fuel(st.w, st.tau_e)
    st.fuel_cmd = st.m_f
    st.rack = st.m_f / maps.fmax(st.w)
    st.integ = st.rack
    st.ke_j = 0.0
    st.gen_sat = st.shed = 0.0
    st.soot_lag = soot_scale_frac * maps.soot(st.w, st.tau_e) if st.tau_e > 0.0 else 0.0
    return st


def measured_soot_rate(st: EngineGenState, prm) -> float:
    """The analyser reading [mg/s] of state ``st`` (lagged soot rate + offset), e.g. at t0."""
    return st.soot_lag + prm.soot_analyzer_offset_mgps


# ---------------------------------------------------------------------------------------------
# the physics, written once: one numba-compatible function of packed maps (md, mi), packed parameters
# (c) and the state (floats), returning the new state and the step's totals.  Compiled with numba for the
# component's hot path and the calibration's record loop; ``step_py`` (= ``step.py_func``) is the same
# source run by the Python interpreter (the reference of the tests; ``compiled=False``).
# ---------------------------------------------------------------------------------------------
import numpy as np  # noqa: E402

from shevsim.core.compiled import field_index, njit_step  # noqa: E402
from shevsim.core.errors import DataError  # noqa: E402
from shevsim.core.lookup import EXTRAPOLATION_CODES, HAVE_NUMBA, curve_ex, grid_ex, njit  # noqa: E402


#: index constants of the state array ``x`` (:data:`STATE`) and the parameter array ``c`` (:data:`PRM_FIELDS`)
S = field_index(STATE, "S")
C = field_index(PRM_FIELDS, "C")
#: the step's totals ``tot``: electrical energy [J], fuel [g], soot [mg], the analyser's mean reading [mg/s]
T = field_index(("e_el", "fuel", "soot", "soot_meas"), "T")


@njit(cache=True, inline="always")   # inlined into step: its locals stay in registers
def _coefficients(md, mi, c, p_max, dt, p_cmd_w, rate_up_wps, elec_max_w, elec_min_w):
    """The sub-steps' constants ``k = (dt, target, r_up, r_dn, a_w, dw_max, a_up, a_dn, a_a, p_shed, e_shed,
    e_floor, w_idle)``."""
    target = min(max(p_cmd_w, 0.0), p_max)
    r_up = max(rate_up_wps, 0.0) * dt
    r_dn = c[C.power_rate_down_max_wps] * dt
    a_w = math.exp(-dt / c[C.speed_time_constant_s])
    dw_max = c[C.speed_accel_max_radps2] * dt
    a_up = math.exp(-dt / c[C.turbo_lag_s])
    a_dn = math.exp(-dt / c[C.fuel_fall_s])
    tau_a = c[C.soot_analyzer_tau_s]
    a_a = math.exp(-dt / tau_a) if tau_a > 0.0 else 0.0
    p_shed = max(elec_max_w, 0.0)
    e_shed = p_shed * dt
    e_floor = min(elec_min_w, p_max) * dt          # 10d: <= 0 = no floor
    w_idle = curve_ex(md, mi[0], mi[1], mi[2], 0.0)
    return (dt, target, r_up, r_dn, a_w, dw_max, a_up, a_dn, a_a, p_shed, e_shed, e_floor, w_idle)


@njit(cache=True, inline="always")   # inlined into step: its locals stay in registers
def _rack_and_fuel(md, mi, c, k, x):
    """Items 1-6 of a sub-step: rate limit and cut (``x[p_lim]``), speed response, torque demand, PI rack
    (``x[integ]``, ``x[rack]``), fuel command and turbo lag.  Returns ``(cut, w0, w1, m_c, m1, dm, fl)``."""
    dt, target, r_up, r_dn, a_w, dw_max, a_up, a_dn, _a_a, p_shed, _e_shed, _e_floor, _w_idle = k
    # 1. rate limit, 10a. command cut to the bus limit (bypasses the downward rate limit)
    p_lim = x[S.p_lim]
    dp = target - p_lim
    p_lim += r_up if dp > r_up else (-r_dn if dp < -r_dn else dp)
    cut = 0.0
    if p_lim > p_shed:
        p_lim = p_shed
        cut = 1.0
    x[S.p_lim] = p_lim
    # 2-3. speed set point and speed response
    w0 = x[S.w]
    w_set = curve_ex(md, mi[0], mi[1], mi[2], p_lim)
    w1 = w_set + (w0 - w_set) * a_w
    if w1 - w0 > dw_max:
        w1 = w0 + dw_max
    elif w0 - w1 > dw_max:
        w1 = w0 - dw_max
    # 4. torque demand (10c. + the speed loop's torque while the generator torque is cut)
    tau_ref = curve_ex(md, mi[3], mi[4], mi[5], p_lim) / w0
    if x[S.gen_sat] > 0.0:
        tau_ref += c[C.shaft_inertia_kg_m2] * (w_set - w0) / c[C.speed_time_constant_s]
    tl = curve_ex(md, mi[6], mi[7], mi[8], w0)
    if tau_ref > tl:
        tau_ref = tl
    # 5. PI rack with conditional integration
    integ0 = x[S.integ]
    e = tau_ref - x[S.tau_e]
    integ = integ0 + c[C.rack_ki_per_nm_s] * e * dt
    rack = c[C.rack_kp_per_nm] * e + integ
    if rack > 1.0:
        rack = 1.0
        if e > 0.0:
            integ = integ0
    elif rack < 0.0:
        rack = 0.0
        if e < 0.0:
            integ = integ0
    x[S.integ] = integ
    x[S.rack] = rack
    # 6. fuel command and turbo lag (exact)
    fl = curve_ex(md, mi[9], mi[10], mi[11], w1)
    m_c = rack * fl
    m0 = x[S.m_f]
    if m_c > m0:
        a = a_up
        tf = c[C.turbo_lag_s]
    else:
        a = a_dn
        tf = c[C.fuel_fall_s]
    m1 = m_c + (m0 - m_c) * a
    dm = m_c * dt + (m0 - m_c) * tf * (1.0 - a)          # fuel mass over the sub-step [g]
    return cut, w0, w1, m_c, m1, dm, fl


@njit(cache=True, inline="always")   # inlined into step: its locals stay in registers
def _shaft_and_generator(md, mi, c, k, x, cut, w0, w1, m1):
    """Items 7, 10b, 10d of a sub-step: engine torque, shaft energy, generator work and its cut to the bus limit
    or raise to the floor (``x[gen_sat]``, the shedding counters).  Returns ``(w1, tau1, w_avg, tau_avg,
    w_e, dke, w_g, el)``."""
    dt, _target, _r_up, _r_dn, _a_w, _dw_max, _a_up, _a_dn, _a_a, _p_shed, e_shed, e_floor, w_idle = k
    J = c[C.shaft_inertia_kg_m2]
    # 7. engine torque
    tau1 = grid_ex(md, mi[12], mi[13], mi[14], mi[15], mi[16], w1, m1)
    w_avg = 0.5 * (w0 + w1)
    tau_avg = 0.5 * (x[S.tau_e] + tau1)
    w_e = tau_avg * w_avg * dt
    dke = 0.5 * J * (w1 * w1 - w0 * w0)
    w_g = w_e - dke
    tau_g = w_g / (w_avg * dt)
    eta = grid_ex(md, mi[17], mi[18], mi[19], mi[20], mi[21], w_avg, abs(tau_g))
    el = w_g * eta if w_g >= 0.0 else w_g / eta
    # 10b. generator torque cut to the bus limit; the surplus engine work accelerates the shaft
    gen_sat = 0.0
    if el > e_shed:
        if e_shed > 0.0:
            eta = grid_ex(md, mi[17], mi[18], mi[19], mi[20], mi[21], w_avg, e_shed / (eta * w_avg * dt))
            w_gc = e_shed / eta
        else:
            w_gc = 0.0
        if w_gc < w_g:
            w_g = w_gc
        el = e_shed
        dke = w_e - w_g
        w1 = math.sqrt(w0 * w0 + 2.0 * dke / J)
        tau1 = grid_ex(md, mi[12], mi[13], mi[14], mi[15], mi[16], w1, m1)
        gen_sat = 1.0
    elif e_floor > 0.0 and el < e_floor and w1 > w_idle:
        # 10d. generator torque raised to the floor; the deficit comes out of the shaft's kinetic energy
        eta_f = grid_ex(md, mi[17], mi[18], mi[19], mi[20], mi[21], w_avg,
                         e_floor / (max(eta, 1e-3) * w_avg * dt))
        w1sq = w0 * w0 + 2.0 * (w_e - e_floor / eta_f) / J
        if w1sq < w_idle * w_idle:
            w1sq = w_idle * w_idle
        w1f = math.sqrt(w1sq)
        if w1f < w1:
            dke = 0.5 * J * (w1f * w1f - w0 * w0)
            w_g = w_e - dke
            el = w_g * eta_f
            w1 = w1f
            tau1 = grid_ex(md, mi[12], mi[13], mi[14], mi[15], mi[16], w1, m1)
    x[S.gen_sat] = gen_sat
    if cut > 0.0 or gen_sat > 0.0:
        if x[S.shed] == 0.0:
            x[S.shed_n] += 1.0
        x[S.shed] = 1.0
        x[S.shed_s] += dt
    else:
        x[S.shed] = 0.0
    return w1, tau1, w_avg, tau_avg, w_e, dke, w_g, el


@njit(cache=True, inline="always")   # inlined into step: its locals stay in registers
def _soot(md, mi, c, k, x, w_avg, tau_avg, m_c, dm, fl):
    """Items 8 and 11 of a sub-step: quasi-static and transient soot, the analyser's lag (``x[soot_lag]``).
    Returns ``(s_sub, s_tr, analyser reading integral)``."""
    dt = k[0]
    a_a = k[8]
    if tau_avg > 0.0:
        s = c[C.soot_scale_frac] * grid_ex(md, mi[22], mi[23], mi[24], mi[25], mi[26], w_avg, tau_avg) * dt
    else:
        s = 0.0
    deficit = m_c * dt - dm                              # int (m_c - m_f) dt over the sub-step [g]
    s_tr = c[C.transient_soot_mg_per_g] * deficit * deficit / (dt * fl) if deficit > 0.0 else 0.0
    # 11. analyser: first-order lag of the soot rate (held over the sub-step), exact integral
    s_sub = s + s_tr
    r = s_sub / dt
    soot_lag = x[S.soot_lag]
    meas = s_sub + (soot_lag - r) * c[C.soot_analyzer_tau_s] * (1.0 - a_a)
    x[S.soot_lag] = r + (soot_lag - r) * a_a
    return s_sub, s_tr, meas


@njit_step
def step(md, mi, c, p_max, x, p_cmd_w, rate_up_wps, h, elec_max_w, elec_min_w, tot):
    """Advance the engine-generator by ``h`` with the inputs held (items 1-11 of the module docstring).

    Parameters
    ----------
    md, mi : ndarray
        Maps packed by :func:`pack_maps` (values; offsets, sizes and extrapolation codes).
    c : ndarray
        Parameters in the order of :data:`PRM_FIELDS` (indices :data:`C`).
    p_max : float
        Rated electrical power [W] (end of the optimal operating line).
    x : ndarray
        The state in the order of :data:`STATE` (indices :data:`S`), advanced in place.
    p_cmd_w, rate_up_wps, h, elec_max_w, elec_min_w : float
        Power command [W], its max rate of increase [W/s], step [s], bus limit [W], generator floor [W]
        (item 10d; <= 0 = none).
    tot : ndarray
        Receives the step's electrical energy [J], fuel [g], soot [mg] and the analyser's mean reading over
        the step [mg/s] (lagged soot rate + offset), indices :data:`T`.
    """
    n = max(1, math.ceil(h / c[C.max_substep_s] - 1e-9))
    k = _coefficients(md, mi, c, p_max, h / n, p_cmd_w, rate_up_wps, elec_max_w, elec_min_w)
    lhv = c[C.fuel_lhv_j_per_g]
    e_el = 0.0
    fuel = 0.0
    soot = 0.0
    soot_meas = 0.0
    for _ in range(n):
        cut, w0, w1, m_c, m1, dm, fl = _rack_and_fuel(md, mi, c, k, x)
        w1, tau1, w_avg, tau_avg, w_e, dke, w_g, el = _shaft_and_generator(md, mi, c, k, x, cut, w0, w1, m1)
        s_sub, s_tr, meas = _soot(md, mi, c, k, x, w_avg, tau_avg, m_c, dm, fl)
        soot_meas += meas
        # bookkeeping
        x[S.w] = w1
        x[S.m_f] = m1
        x[S.tau_e] = tau1
        x[S.fuel_cmd] = m_c
        x[S.fuel_g] += dm
        x[S.fuel_j] += dm * lhv
        x[S.eng_loss_j] += dm * lhv - w_e
        x[S.shaft_j] += w_g
        x[S.ke_j] += dke
        x[S.gen_loss_j] += w_g - el
        x[S.elec_j] += el
        x[S.soot_mg] += s_sub
        x[S.soot_tr_mg] += s_tr
        e_el += el
        fuel += dm
        soot += s_sub
    tot[T.e_el] = e_el
    tot[T.fuel] = fuel
    tot[T.soot] = soot
    tot[T.soot_meas] = soot_meas / h + c[C.soot_analyzer_offset_mgps]


@njit(cache=True)
def run_record(md, mi, c, p_max, x, t, p_cmd, rate_up_wps, elec_max_w, out):  # pragma: no cover - compiled
    """:func:`step` through a record (the calibration's loop, :mod:`shevsim.calibrate.engine`): state ``x``
    (order of :data:`STATE`; not changed) at ``t[0]``; step ``k`` runs from ``t[k-1]`` to ``t[k]`` with
    ``p_cmd[k]`` held (the ``profile`` source's convention under the Gauss-Seidel master) and writes its mean
    analyser reading [mg/s] to ``out[k]`` (``out[0]`` is left as given).  Kept in this file so that numba's
    cache of it is renewed whenever :func:`step` changes."""
    tot = np.zeros(4)
    x = x.copy()
    for k in range(1, t.shape[0]):
        step(md, mi, c, p_max, x, p_cmd[k], rate_up_wps, t[k] - t[k - 1], elec_max_w, 0.0, tot)
        out[k] = tot[T.soot_meas]
    return 0


step_py = getattr(step, "py_func", step)
"""The same source as :func:`step`, run by the Python interpreter (reference; ``compiled=False``)."""


def pack_maps(maps: EngineGenMaps):
    """Pack the maps :func:`step` reads into ``(md, mi)``: one float array of values and one int array of
    (offset, size[, size], extrapolation code[, code]) per map, in the order ool_speed, ool_shaft, tmax,
    fmax (curves), torque, geff, soot (grids)."""
    import numpy as np
    chunks, mi, off = [], [], 0
    for cv in (maps.ool_speed, maps.ool_shaft, maps.tmax, maps.fmax):
        chunks += [cv.x, cv.y]
        mi += [off, cv.x.size, EXTRAPOLATION_CODES[cv.mode]]
        off += 2 * cv.x.size
    for g in (maps.torque, maps.geff, maps.soot):
        chunks += [g.x, g.y, g.z.ravel()]
        mi += [off, g.x.size, g.y.size, EXTRAPOLATION_CODES[g.mode_x], EXTRAPOLATION_CODES[g.mode_y]]
        off += g.x.size + g.y.size + g.z.size
    return (np.ascontiguousarray(np.concatenate(chunks), dtype=np.float64), np.array(mi, dtype=np.int64))


def pack_params(prm):
    """The parameters :func:`step` reads (:data:`PRM_FIELDS`) as a float array."""
    import numpy as np
    return np.array([float(getattr(prm, k)) for k in PRM_FIELDS], dtype=np.float64)


class EngineGenStep:
    """:func:`step` bound to one (maps, parameters) pair, acting on an :class:`EngineGenState`.

    ``compiled=True`` calls the numba-compiled :func:`step` (when numba is installed), ``False`` its
    Python form :data:`step_py`; both are the one source.  ``__call__(st, p_cmd_w, rate_up_wps, h,
    elec_max_w=1e12, elec_min_w=0)`` advances ``st`` in place and returns (elec J, fuel g, soot mg, analyser reading
    mg/s) of the step.  A non-finite result (a map with extrapolation ``"error"`` queried outside its
    range, or a NaN met inside) raises :class:`~shevsim.core.errors.DataError`; the state is then left
    unchanged.
    """

    def __init__(self, maps: EngineGenMaps, prm, compiled: bool = True):
        self.maps, self.prm = maps, prm
        self.md, self.mi = pack_maps(maps)
        self.c = pack_params(prm)
        self.p_max = float(maps.p_max_w)
        self.compiled = bool(compiled and HAVE_NUMBA)
        self.fn = step if self.compiled else step_py

    def __call__(self, st: EngineGenState, p_cmd_w: float, rate_up_wps: float, h: float,
                 elec_max_w: float = 1e12, elec_min_w: float = 0.0):
        x = np.array(st.values(), dtype=np.float64)
        tot = np.zeros(4)
        self.fn(self.md, self.mi, self.c, self.p_max, x, float(p_cmd_w), float(rate_up_wps), float(h),
                float(elec_max_w), float(elec_min_w), tot)
        if not math.isfinite(tot[T.e_el] + tot[T.fuel] + tot[T.soot_meas] + x[S.w] + x[S.tau_e]):
            raise DataError(nonfinite_message(self.maps, st.p_lim, st.w, p_cmd_w, h))
        st.set_values(x.tolist())
        return tuple(tot.tolist())


def nonfinite_message(maps: EngineGenMaps, p_lim: float, w: float, p_cmd_w: float, h: float) -> str:
    """Why a step gave a non-finite result (NaN met inside, or a map with extrapolation ``"error"``)."""
    modes = [m.name for m in (maps.ool_speed, maps.ool_shaft, maps.tmax, maps.fmax) if m.mode == "error"]
    modes += [g.name for g in (maps.torque, maps.geff, maps.soot) if "error" in (g.mode_x, g.mode_y)]
    return (f"engine-generator step from p_lim={p_lim!r} W, w={w!r} rad/s with command {p_cmd_w!r} W, h={h!r} s "
            f"gave a non-finite result (a NaN lookup"
            + (f", or a lookup outside a map with extrapolation 'error': {', '.join(modes)}" if modes else "") + ")")


def advance(maps: EngineGenMaps, prm, st: EngineGenState, p_cmd_w: float, rate_up_wps: float,
            h: float, elec_max_w: float = 1e12) -> tuple[float, float, float]:
    """Advance ``st`` by ``h`` (Python form of :func:`step`); return (elec J, fuel g, soot mg) of this step.

    Convenience for one-off calls (packs the maps on every call); a component keeps an
    :class:`EngineGenStep`.
    """
    return EngineGenStep(maps, prm, compiled=False)(st, p_cmd_w, rate_up_wps, h, elec_max_w)[:3]


def generator_torque_limit(maps: EngineGenMaps, w: float) -> float:
    """Max generator shaft torque at engine speed ``w`` [N m] (for checks and plots)."""
    return maps.gmax(w)
