"""supervisors.py - power-split supervisors: MPC (TYPE ``mpc_supervisor``) and rule-based (TYPE ``rule_supervisor``).

Both wrap :mod:`shevsim.supervisor` and share the ports of the SHEV signal table.

Ports
-----
Inputs
    ``demand_power_w`` [W] bus power demand (motor + aux, + drawn from the bus);
    ``soc_pct`` [%] estimated SOC (BMS); ``gen_power_w`` [W] present engine-generator electrical
    power (+ to the bus); ``power_max_w`` [W] pack discharge limit >= 0 (BMS);
    ``power_min_w`` [W] pack charge limit <= 0 (BMS); ``ocv_v`` [V] pack open-circuit voltage (BMS);
    ``rs_ohm`` [Ohm] pack series resistance (BMS).  The rule supervisor does not use ``ocv_v``/``rs_ohm``.
Outputs (direct feedthrough: a sampled controller's command is a function of the inputs it samples)
    ``power_cmd_w`` [W] engine-generator electrical power command (+ to the bus), held until the
    next call; ``power_rate_max_wps`` [W/s] the power-rate map at the present engine power (wire it to
    the engine-generator's ``power_rate_max_wps`` so the plant enforces the same limit);
    ``battery_power_plan_w`` [W] the battery power the split implies (demand - command, + discharge).
    MPC only: ``fallback_count`` [1] calls without a QP solution (cumulative);
    ``battery_slack_w`` [W], ``soc_slack_pct`` [%] the soft-constraint slacks of the last solution.
    The wall time of a call is *not* an output (it would make identical runs differ): the MPC component
    keeps it in the attribute ``last_call_us`` and, when ``call_times_us`` is set to a list, appends
    every call's time to it (``benchmarks/cycle_speed.py``).
    Rule only: ``engine_on_1`` [1] thermostat state.

Timing: each ``do_step(t, h)`` is one supervisor call, sampling the inputs at ``t``; run the
component with a step multiple so that ``h`` equals its ``sample_time_s`` (0.2 s: multiple 2 at a
0.1 s communication step).  The MPC raises if ``h`` differs (the QP is discretised with that step).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from shevsim.core.compiled import ERR_NAN_INPUT, ERR_SAMPLE_TIME, CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.lookup import py_max
from shevsim.core.variables import inp, out
from shevsim.supervisor.fuel_curve import SqrtFuelCurve
from shevsim.supervisor import daqp_nb
from shevsim.supervisor.mpc import MPCSettings, MPCSupervisor as _MPC, mpc_move
from shevsim.supervisor.rate_map import PowerRateMap
from shevsim.supervisor.rule_based import RuleBasedSupervisor, RuleSettings, rule_command
from shevsim.supervisor.rule_based import bisect_right
from shevsim.core.paths import data_path

DEFAULT_FUEL_CURVE = data_path("components", "engine_generator", "fuel_vs_power.csv")

_IN = ("demand_power_w", "soc_pct", "gen_power_w", "power_max_w", "power_min_w", "ocv_v", "rs_ohm")
_INPUTS = (
    inp("demand_power_w", "W", 0.0, "bus power demand (motor + aux), + drawn from the bus"),
    inp("soc_pct", "%", 50.0, "battery SOC estimate"),
    inp("gen_power_w", "W", 0.0, "present engine-generator electrical power, + to the bus"),
    inp("power_max_w", "W", 100e3, "pack discharge power limit (>= 0)"),
    inp("power_min_w", "W", -100e3, "pack charge power limit (<= 0)"),
    inp("ocv_v", "V", 429.0, "pack open-circuit voltage"),
    inp("rs_ohm", "Ohm", 0.13, "pack series resistance"),
)


def _check_rate_map(p, where):
    return PowerRateMap(p.rate_map_power_edges_w, p.rate_map_max_rate_wps, where=where)


def _wrong_h_message(name, h, ts, t) -> str:
    return (f"{name}: supervisor called with step h={h:g} s at t={t:g} s but its sample_time_s is {ts:g} s: "
            f"set the component's step multiple so that it runs every {ts:g} s")


def _check_h(name, h, ts, t):
    if abs(h - ts) > 1e-9 * max(1.0, ts):
        raise SimulationError(_wrong_h_message(name, h, ts, t))


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MPCSupervisorParams(MPCSettings):
    """Parameters of ``mpc_supervisor`` (defaults: seed Table 5.2 / A.1; see components/supervisor/mpc_default.toml).

    The MPC's own settings are :class:`~shevsim.supervisor.mpc.MPCSettings` (declared there once, checked there);
    this class adds what the component needs besides: the power-rate map and the fuel curve, and its own
    default engine limit.

    Attributes
    ----------
    n_p, n_c : int
        Prediction / control horizon (40 / 15).
    sample_time_s : float
        Sampling period [s] = the component's step (0.2).
    eta1_1, eta2_1, eta3_1, eta4_1 : float
        Cost weights (4.17, 1, 2.5e-5, 1.25e-6) on SOC fraction, sqrt(kg/s), kW per step, kW.
    soc_ref_pct, soc_min_pct, soc_max_pct : float
        SOC reference and soft window [%] (50, 30, 70).
    power_gen_min_w, power_gen_max_w : float
        Engine-generator electrical power limits [W].
    power_rate_min_wps : float
        Minimum power rate [W/s] (-60 kW/s).
    rate_map_power_edges_w, rate_map_max_rate_wps : tuple of float
        Power-rate constraint map: partition edges [W] and max rate per partition [W/s].
    capacity_ah : float
        Pack capacity [A.h] (10 x 2.3 Ah).
    soc_slack_weight_1, soc_slack_weight_quad_1, battery_slack_weight_1, battery_slack_weight_quad_1 : float
        Soft-constraint penalties (units of the cost, per % / %^2 SOC and per kW / kW^2).
    battery_limits_soft : bool
        Battery limits as exact-penalty soft constraints (True) or hard (infeasible -> fallback).
    fuel_curve_file : str
        CSV of the quasi-static fuel curve (columns elec_power_w, fuel_gps); empty: the powertrain's
        ``components/engine_generator/fuel_vs_power.csv``.  Ignored when ``fuel_curve_w`` is given.
    fuel_curve_w, fuel_rate_gps : tuple of float
        The fuel curve inline [W], [g/s] (alternative to the file).
    solver : str
        ``'daqp'`` (default, fastest exact), ``'osqp'`` or ``'cvxpy'`` (reference).
    fallback : str
        ``'shift'`` (previous plan shifted) or ``'rule'`` (rule-based split).
    warm_active_set : bool
        Solver ``'daqp'``: try the previous call's active set first (one equality-constrained solve, accepted
        only when it is the QP's optimum; :func:`shevsim.supervisor.mpc.solve_on_active_set`), DAQP otherwise
        (default True, ~1.6x faster per call); False calls DAQP on every call.
    """

    power_gen_max_w: float = 200.6e3
    rate_map_power_edges_w: tuple[float, ...] = (0.0, 236e3)
    rate_map_max_rate_wps: tuple[float, ...] = (30e3,)
    fuel_curve_file: str = ""
    fuel_curve_w: tuple[float, ...] = ()
    fuel_rate_gps: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        """Checked by :meth:`settings` when the component is built (errors named after the component)."""

    def settings(self) -> MPCSettings:
        """The MPC's settings (these parameters are them), checked."""
        MPCSettings.__post_init__(self)
        return self

    def fuel_curve(self, where: str) -> SqrtFuelCurve:
        if self.fuel_curve_w or self.fuel_rate_gps:
            return SqrtFuelCurve(self.fuel_curve_w, self.fuel_rate_gps, where=f"{where}: fuel_curve_w/fuel_rate_gps")
        return SqrtFuelCurve.from_csv(self.fuel_curve_file or DEFAULT_FUEL_CURVE)


class MPCSupervisor(CompiledStep, Component):
    """Linear MPC power split (seed Sec. 5.2.2): TYPE ``mpc_supervisor``; ports in the module docstring."""

    TYPE = "mpc_supervisor"
    INPUT_DEFAULTS = ()                         # every input is part of its model
    #: the step it must be called with (checked when the scenario is built: step_s x step_multiple)
    SAMPLE_TIME_PARAM = "sample_time_s"
    Params = MPCSupervisorParams
    VARIABLES = _INPUTS + (
        out("power_cmd_w", "W", 0.0, "engine-generator electrical power command, + to the bus", _IN),
        out("power_rate_max_wps", "W/s", 30e3, "power-rate map at the previous command (the ramp's start)"),
        out("battery_power_plan_w", "W", 0.0, "demand - command (battery share), + discharge", _IN),
        out("fallback_count", "1", 0.0, "cumulative supervisor calls without a QP solution", _IN),
        out("battery_slack_w", "W", 0.0, "battery-limit slack of the last solution", _IN),
        out("soc_slack_pct", "%", 0.0, "SOC-window slack of the last solution", _IN),
    )
    _static = ("name", "params", "mpc", "_rule", "last_call_us", "call_times_us", "_fn", "_u_names", "_y_names")
    #: the move's state and plan, DAQP's model flags and the active set (a run's own copies)
    DATA_MUTABLE = (6, 7, 30, 31)

    def __init__(self, name: str = "mpc_supervisor", params: MPCSupervisorParams | None = None):
        super().__init__(name, params)
        p = self.params
        where = f"mpc_supervisor '{name}'"
        rate_map = _check_rate_map(p, where)
        try:
            settings = p.settings()
            # the rule-based split used by fallback='rule' (thermostat band: a quarter of the window)
            rule_settings = RuleSettings(power_gen_min_w=p.power_gen_min_w, power_gen_max_w=p.power_gen_max_w,
                                         power_rate_min_wps=p.power_rate_min_wps, soc_min_pct=p.soc_min_pct,
                                         soc_max_pct=p.soc_max_pct, soc_ref_pct=p.soc_ref_pct,
                                         soc_on_pct=p.soc_ref_pct - 0.25 * (p.soc_ref_pct - p.soc_min_pct),
                                         soc_off_pct=p.soc_ref_pct + 0.25 * (p.soc_max_pct - p.soc_ref_pct))
        except ScenarioError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
        self._rule = RuleBasedSupervisor(rule_settings, rate_map, p.sample_time_s)
        self.mpc = _MPC(settings, p.fuel_curve(where), rate_map, rule=self._rule)
        self.last_call_us = 0.0      # wall time of the last call (state -> QP -> first move) [us]
        self.call_times_us = None    # set to a list to collect every call's wall time [us]

    def step_function(self):
        """:func:`mpc_supervisor_step` when the MPC's call is the compiled :func:`~shevsim.supervisor.mpc.mpc_move`
        (solver 'daqp', compiled); None otherwise (the Python solve path, :meth:`do_step`)."""
        return mpc_supervisor_step if self.mpc.compiled_call else None

    def fast_reason(self) -> str:
        m = self.mpc
        if m.settings.solver != "daqp":
            return f"component '{self.name}': MPC solver '{m.settings.solver}' (the compiled step calls DAQP only)"
        if not m.compiled_call:
            ok, why = daqp_nb.available()
            return f"component '{self.name}': " + (why if not ok else "MPC built with compiled=False")
        return ""

    def fast_release(self, data: tuple) -> None:
        if data[30][0] != 0:
            daqp_nb.drop_model(data[24], data[30])  # free DAQP's workspace (daqp.Model.__dealloc__)

    @property
    def data(self) -> tuple:
        """:attr:`MPC.arrays <shevsim.supervisor.mpc.MPCSupervisor.arrays>`: ``x[prev_cmd_w]`` holds the
        previous command, ``mp[0]`` the sample time."""
        return self.mpc.arrays

    def initialize(self, t0: float) -> None:
        self.mpc.reset()
        self.mpc.fallback_count = 0
        g = self.u["gen_power_w"]
        self.mpc.arrays[6][0] = float(g) if math.isfinite(g) else 0.0
        self._write(self.prev_cmd)
        self._io()

    @property
    def prev_cmd(self) -> float:
        """The previous command u(k-1) [W]."""
        return float(self.mpc.arrays[6][0])

    @property
    def fallback_count(self) -> int:
        return self.mpc.fallback_count

    def _write(self, cmd: float) -> None:
        y, u, last = self.y, self.u, self.mpc.last
        cmd = float(cmd)
        y["power_cmd_w"] = cmd
        # the engine-generator ramps from the previous command to this one: the map is evaluated
        # where the ramp starts, as in the MPC's constraint dP <= dP_max(P(k-1)) dt
        y["power_rate_max_wps"] = self.mpc.rate_map(self.prev_cmd)
        y["battery_power_plan_w"] = float(u["demand_power_w"]) - cmd
        y["fallback_count"] = float(self.fallback_count)
        y["battery_slack_w"] = float(last.battery_slack_w)
        y["soc_slack_pct"] = float(last.soc_slack_pct)

    def do_step(self, t: float, h: float) -> None:
        t0 = time.perf_counter()
        if self._fn is not None:
            super().do_step(t, h)                  # the compiled step: the move and the outputs
        else:
            self._do_step_python(t, h)
        dt_us = (time.perf_counter() - t0) * 1e6
        self.last_call_us = dt_us
        if self.call_times_us is not None:
            self.call_times_us.append(dt_us)

    def _do_step_python(self, t: float, h: float) -> None:
        """The step with another solver: the MPC's Python solve path, the same :func:`first_move`."""
        _check_h(self.name, h, self.params.sample_time_s, t)
        u = self.u
        # the previous point of the linearisation and of the rate constraint is the previous
        # command u(k-1) (seed 5.5-5.8), not the measured output, which lags it by the turbo lag
        cmd = self.mpc.step(u["soc_pct"], u["demand_power_w"], self.prev_cmd, u["power_max_w"],
                            u["power_min_w"], u["ocv_v"], u["rs_ohm"])
        self._write(cmd)
        self.mpc.arrays[6][0] = float(cmd)

    def step_error(self, status: int, t: float, h: float) -> str:
        if status == ERR_SAMPLE_TIME:
            return _wrong_h_message(self.name, h, self.params.sample_time_s, t)
        return super().step_error(status, t, h)

    @property
    def plan(self):
        """Engine powers [kW] of the last optimal plan (a copy), None before the first solution."""
        p = self.mpc._plan_kw
        return None if p is None else p.copy()

    def get_state(self):
        st = super().get_state()
        st["_mpc_plan"] = (None if self.mpc._plan_kw is None else self.mpc._plan_kw.copy(), self.mpc._plan_age,
                           self.mpc.fallback_count, self.mpc.active_set, self.prev_cmd)
        return st

    def set_state(self, state) -> None:
        state = dict(state)
        plan, age, fb, *rest = state.pop("_mpc_plan", (None, 0, 0))
        super().set_state(state)
        self.mpc.reset()                      # DAQP's warm start is not state: the optimum is unique
        self.mpc._plan_kw = None if plan is None else plan.copy()
        self.mpc._plan_age = age
        self.mpc.fallback_count = fb
        # the active set tried first is: it decides which of two equal optima (to rounding) a call returns
        self.mpc.active_set = rest[0] if rest else None
        if len(rest) > 1:
            self.mpc.arrays[6][0] = rest[1]


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RuleSupervisorParams(RuleSettings):
    """Parameters of ``rule_supervisor`` (see :class:`shevsim.supervisor.rule_based.RuleSettings`).

    The rules' settings are :class:`~shevsim.supervisor.rule_based.RuleSettings` (declared and checked there
    once); this class adds the sample time, the power-rate map and its own default engine limit.

    Attributes
    ----------
    sample_time_s : float
        Sampling period [s] = the component's step.
    soc_min_pct, soc_max_pct, soc_ref_pct, soc_on_pct, soc_off_pct : float
        SOC window, target and thermostat thresholds [%].
    charge_power_w, engine_on_min_power_w, engine_on_demand_w : float
        Power-follower SOC correction, least running power, demand that forces the engine on [W].
    power_gen_min_w, power_gen_max_w : float
        Engine-generator electrical power limits [W].
    power_rate_min_wps : float
        Minimum power rate [W/s].
    rate_map_power_edges_w, rate_map_max_rate_wps : tuple of float
        Power-rate constraint map (same form as the MPC's).
    """

    sample_time_s: float = 0.2
    power_gen_max_w: float = 200.6e3
    rate_map_power_edges_w: tuple[float, ...] = (0.0, 236e3)
    rate_map_max_rate_wps: tuple[float, ...] = (30e3,)

    def __post_init__(self) -> None:
        """Checked when the component is built (:class:`RuleSettings`' checks, errors named after the component)."""


class RuleSupervisor(CompiledStep, Component):
    """Thermostat / power-follower baseline: TYPE ``rule_supervisor``; ports in the module docstring."""

    TYPE = "rule_supervisor"
    INPUT_DEFAULTS = ("ocv_v", "rs_ohm")          # unused by the rule
    #: the step it must be called with (checked when the scenario is built: step_s x step_multiple)
    SAMPLE_TIME_PARAM = "sample_time_s"
    Params = RuleSupervisorParams
    VARIABLES = _INPUTS + (
        out("power_cmd_w", "W", 0.0, "engine-generator electrical power command, + to the bus", _IN[:5]),
        out("power_rate_max_wps", "W/s", 30e3, "power-rate map at the previous command (the ramp's start)"),
        out("battery_power_plan_w", "W", 0.0, "demand - command (battery share), + discharge", _IN[:5]),
        out("engine_on_1", "1", 0.0, "thermostat state (1 = engine on)", _IN[:5]),
    )

    _static = ("name", "params", "rule", "_fn", "_u_names", "_y_names")
    DATA_MUTABLE = (3,)

    def __init__(self, name: str = "rule_supervisor", params: RuleSupervisorParams | None = None):
        super().__init__(name, params)
        p = self.params
        where = f"rule_supervisor '{name}'"
        try:
            RuleSettings.__post_init__(p)
            settings = p                  # the parameters are the rules' settings
        except ScenarioError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
        self.rule = RuleBasedSupervisor(settings, _check_rate_map(p, where), p.sample_time_s)

    def initialize(self, t0: float) -> None:
        """``data`` = ``(rp, inner edges, rates, x = [engine on, previous command])``: ``rp`` the rules' settings
        (:func:`~shevsim.supervisor.rule_based.rule_command`) and the sample time."""
        s, p = self.rule.settings, self.params
        rp = np.array([s.soc_min_pct, s.soc_max_pct, s.soc_ref_pct, s.soc_on_pct, s.soc_off_pct, s.charge_power_w,
                       s.engine_on_min_power_w, s.engine_on_demand_w, s.power_gen_min_w, s.power_gen_max_w,
                       s.power_rate_min_wps, self.rule.dt_s, p.sample_time_s], dtype=np.float64)
        rm = self.rule.rate_map
        g = self.u["gen_power_w"]
        prev = float(g) if math.isfinite(g) else 0.0
        self.data = (rp, np.array(rm._inner, dtype=np.float64), np.array(rm.rates_wps, dtype=np.float64),
                     np.array([0.0, prev]))
        self.rule.engine_on = False
        self._write(prev)
        self._io()

    @property
    def engine_on(self) -> bool:
        """Thermostat state."""
        return bool(self.data[3][0] > 0.5)

    @property
    def prev_cmd(self) -> float:
        """The last command [W]."""
        return float(self.data[3][1])

    def step_error(self, status: int, t: float, h: float) -> str:
        if status == ERR_SAMPLE_TIME:
            return _wrong_h_message(self.name, h, self.params.sample_time_s, t)
        return super().step_error(status, t, h)

    def _write(self, cmd: float) -> None:
        y, u = self.y, self.u
        cmd = float(cmd)
        y["power_cmd_w"] = cmd
        y["power_rate_max_wps"] = self.rule.rate_map(self.prev_cmd)   # map at the ramp's start
        y["battery_power_plan_w"] = u["demand_power_w"] - cmd
        y["engine_on_1"] = 1.0 if self.engine_on else 0.0

UR = port_index(RuleSupervisor.VARIABLES, "input")
YR = port_index(RuleSupervisor.VARIABLES, "output")


@njit(cache=True)
def _wrong_step(h, ts):
    return abs(h - ts) > 1e-9 * py_max(1.0, ts)


@njit_step
def rule_supervisor_step(data, u, y, t, h):
    """:class:`RuleSupervisor`'s step: the sample-time and input checks,
    :func:`~shevsim.supervisor.rule_based.rule_command`, the outputs."""
    rp, inner, rates, x = data
    if _wrong_step(h, rp[12]):
        return ERR_SAMPLE_TIME
    for j in range(5):
        if not math.isfinite(u[j]):
            return ERR_NAN_INPUT
    demand = u[UR.demand_power_w]
    prev = x[1]
    on, cmd = rule_command(rp, inner, rates, x[0] > 0.5, u[UR.soc_pct], demand, prev, u[UR.power_max_w],
                           u[UR.power_min_w])
    x[0] = 1.0 if on else 0.0
    y[YR.power_cmd_w] = cmd
    y[YR.power_rate_max_wps] = rates[bisect_right(inner, prev)]
    y[YR.battery_power_plan_w] = demand - cmd
    y[YR.engine_on_1] = 1.0 if on else 0.0
    x[1] = cmd
    return 0


RuleSupervisor.STEP = rule_supervisor_step


UM = port_index(MPCSupervisor.VARIABLES, "input")
YM = port_index(MPCSupervisor.VARIABLES, "output")


@njit_step
def _mpc_supervisor_step(data, u, y, t, h):
    """:class:`MPCSupervisor`'s step (solver 'daqp'): the sample-time check,
    :func:`~shevsim.supervisor.mpc.mpc_move` (QP build, DAQP's C library, first move or fallback) from the
    previous command ``x[prev_cmd_w]``, the outputs."""
    mp = data[0]
    x = data[6]
    if _wrong_step(h, mp[0]):
        return ERR_SAMPLE_TIME
    demand = u[UM.demand_power_w]
    cmd, rate = mpc_move(data, u[UM.soc_pct], demand, x[0], u[UM.power_max_w], u[UM.power_min_w], u[UM.ocv_v],
                         u[UM.rs_ohm])
    y[YM.power_cmd_w] = cmd
    y[YM.power_rate_max_wps] = rate
    y[YM.battery_power_plan_w] = demand - cmd
    y[YM.fallback_count] = x[1]
    y[YM.battery_slack_w] = x[4]
    y[YM.soc_slack_pct] = x[5]
    x[0] = cmd
    return 0


# the step must not reference the DAQP binding when it is unavailable (its symbols would not link)
mpc_supervisor_step = _mpc_supervisor_step if daqp_nb.available()[0] else None
