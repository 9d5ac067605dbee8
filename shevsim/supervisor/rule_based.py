"""rule_based.py - thermostat / power-follower baseline supervisor (the standard a MPC is quoted against).

The series-hybrid "power follower" with a thermostat (on/off) engine, as in ADVISOR's series
control strategy and the usual SHEV baselines:

1. **Thermostat** (hysteresis on SOC): the engine switches *on* when ``SOC <= soc_on_pct`` or the
   demand exceeds ``engine_on_demand_w`` or the battery alone cannot carry the demand
   (``P_d > P_b,max``); it switches *off* when ``SOC >= soc_off_pct`` and the demand is below
   ``engine_on_demand_w`` and the battery can carry it.
2. **Power follower** when on: ``P_g = P_d + P_chg``, with the SOC correction
   ``P_chg = charge_power_w * clip((SOC_ref - SOC) / (SOC_ref - SOC_min), -1, 1)``, and at least
   ``engine_on_min_power_w`` (keeps a running engine out of its worst-bsfc region).  Off: ``P_g = P_g,min``.
3. **SOC window** ``[soc_min_pct, soc_max_pct]``: at or below ``SOC_min`` the battery may not discharge
   (``P_g >= P_d``); at or above ``SOC_max`` it may not charge (``P_g <= max(P_d, P_g,min)``).
4. **Battery limits** from the BMS: ``P_d - P_b,max <= P_g <= P_d - P_b,min``.
5. **Engine limits** ``[P_g,min, P_g,max]`` and **power-rate limits** around the present engine power
   ``P_g,o``: ``P_g,o + Delta P_g,min dt <= P_g <= P_g,o + Delta P_g,max(P_g,o) dt`` with the same
   power-rate map as the MPC.

Later steps override earlier ones (rates and engine limits are physical, so they win over the
battery limits when the two conflict; the battery then takes the rest, as the bus dictates).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shevsim.core.errors import ScenarioError

from shevsim.core.lookup import njit

from .rate_map import PowerRateMap


@njit(cache=True)
def bisect_right(a, x):
    """``bisect.bisect_right`` (the power-rate map's partition of :class:`PowerRateMap`)."""
    lo = 0
    hi = a.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(cache=True)
def _min(a, b):
    return b if b < a else a          # Python's min(a, b)


@njit(cache=True)
def _max(a, b):
    return b if b > a else a          # Python's max(a, b)


@njit(cache=True)
def rule_command(rp, inner, rates, engine_on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w):
    """The rules 1-5 of the module docstring, compiled once: ``(engine_on, command_w)``.

    ``rp = [soc_min, soc_max, soc_ref, soc_on, soc_off, charge_w, on_min_w, on_demand_w, pg_min_w, pg_max_w,
    rate_min_wps, dt_s]``; ``inner, rates`` the power-rate map (inner edges, rate per partition).
    :class:`RuleBasedSupervisor` and the compiled whole-vehicle loop (:mod:`shevsim.fast`) both call it.
    """
    must = demand_w >= rp[7] or demand_w > power_max_w          # 1. thermostat
    if engine_on:
        on = not (soc_pct >= rp[4] and not must)
    else:
        on = soc_pct <= rp[3] or must
    if on:                                                       # 2. power follower
        x = (rp[2] - soc_pct) / (rp[2] - rp[0])
        p = demand_w + rp[5] * _min(_max(x, -1.0), 1.0)
        p = _max(p, rp[6])
    else:
        p = rp[8]
    if soc_pct <= rp[0]:                                         # 3. SOC window
        p = _max(p, demand_w)
    if soc_pct >= rp[1]:
        p = _min(p, _max(demand_w, rp[8]))
    if power_min_w <= power_max_w:                               # 4. battery limits
        p = _min(_max(p, demand_w - power_max_w), demand_w - power_min_w)
    p = _min(_max(p, rp[8]), rp[9])                              # 5. engine and rate limits
    rate = rates[bisect_right(inner, gen_power_w)]
    return on, _min(_max(p, gen_power_w + rp[10] * rp[11]), gen_power_w + rate * rp[11])


@dataclass(frozen=True)
class RuleSettings:
    """Settings of the rule-based supervisor.

    Attributes
    ----------
    soc_min_pct, soc_max_pct : float
        Hard SOC window [%] (seed Table A.1: 0.3 / 0.7).
    soc_ref_pct : float
        SOC target of the power follower [%] (seed Table 5.2: 0.5).
    soc_on_pct, soc_off_pct : float
        Thermostat thresholds [%]: engine on at or below ``soc_on_pct``, off at or above ``soc_off_pct``.
    charge_power_w : float
        SOC-correction power at the window edge [W].
    engine_on_min_power_w : float
        Least power of a running engine [W].
    engine_on_demand_w : float
        Demand [W] above which the engine runs whatever the SOC.
    power_gen_min_w, power_gen_max_w : float
        Engine-generator electrical power limits [W].
    power_rate_min_wps : float
        Minimum power rate [W/s] (< 0).
    """

    soc_min_pct: float = 30.0
    soc_max_pct: float = 70.0
    soc_ref_pct: float = 50.0
    soc_on_pct: float = 45.0
    soc_off_pct: float = 55.0
    charge_power_w: float = 30e3
    engine_on_min_power_w: float = 25e3
    engine_on_demand_w: float = 60e3
    power_gen_min_w: float = 0.0
    power_gen_max_w: float = 236e3
    power_rate_min_wps: float = -60e3

    def __post_init__(self) -> None:
        w = "rule-based supervisor settings"
        for k in ("soc_min_pct", "soc_max_pct", "soc_ref_pct", "soc_on_pct", "soc_off_pct", "charge_power_w",
                  "engine_on_min_power_w", "engine_on_demand_w", "power_gen_min_w", "power_gen_max_w",
                  "power_rate_min_wps"):
            if not math.isfinite(getattr(self, k)):
                raise ScenarioError(f"{w}: {k} must be finite")
        if not (self.soc_min_pct < self.soc_on_pct < self.soc_off_pct < self.soc_max_pct):
            raise ScenarioError(f"{w}: need soc_min_pct < soc_on_pct < soc_off_pct < soc_max_pct, got "
                                f"{self.soc_min_pct}, {self.soc_on_pct}, {self.soc_off_pct}, {self.soc_max_pct}")
        if not (self.soc_min_pct < self.soc_ref_pct < self.soc_max_pct):
            raise ScenarioError(f"{w}: soc_ref_pct must lie inside the SOC window")
        if not self.power_gen_min_w < self.power_gen_max_w:
            raise ScenarioError(f"{w}: power_gen_min_w must be < power_gen_max_w")
        if self.charge_power_w < 0 or self.engine_on_min_power_w < 0 or self.engine_on_demand_w < 0:
            raise ScenarioError(f"{w}: charge_power_w, engine_on_min_power_w, engine_on_demand_w must be >= 0")
        if not self.power_rate_min_wps < 0:
            raise ScenarioError(f"{w}: power_rate_min_wps must be negative, got {self.power_rate_min_wps}")


class RuleBasedSupervisor:
    """Thermostat / power-follower split with SOC window, battery, engine and power-rate limits.

    Parameters
    ----------
    settings : RuleSettings
    rate_map : PowerRateMap
        ``Delta P_g,max(P_g)`` [W/s] evaluated at the present engine power.
    dt_s : float
        Supervisor sampling period [s] (the rate limits apply per call).

    Notes
    -----
    :meth:`step` advances the thermostat state; :meth:`split` evaluates the same rules without
    changing it (used by the MPC fallback).  Inputs in SI (W, %), output the engine-generator
    electrical power command [W].
    """

    def __init__(self, settings: RuleSettings, rate_map: PowerRateMap, dt_s: float = 0.2):
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ScenarioError(f"rule-based supervisor: dt_s must be positive, got {dt_s}")
        self.settings = settings
        self.rate_map = rate_map
        self.dt_s = dt_s
        self.engine_on = False

    def _law(self, engine_on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w):
        """``(on, command_w)`` of :func:`rule_command` (packed settings and rate map cached)."""
        rm = self.rate_map
        pf = getattr(self, "_packed_for", None)
        if pf is None or pf[0] is not self.settings or pf[1] is not rm or pf[2] != self.dt_s:
            s = self.settings
            self._rp = np.array([s.soc_min_pct, s.soc_max_pct, s.soc_ref_pct, s.soc_on_pct, s.soc_off_pct,
                                 s.charge_power_w, s.engine_on_min_power_w, s.engine_on_demand_w, s.power_gen_min_w,
                                 s.power_gen_max_w, s.power_rate_min_wps, self.dt_s], dtype=np.float64)
            self._inner = np.array(rm._inner, dtype=np.float64)
            self._rates = np.array(rm.rates_wps, dtype=np.float64)
            self._packed_for = (self.settings, rm, self.dt_s)
        return rule_command(self._rp, self._inner, self._rates, bool(engine_on), float(soc_pct), float(demand_w),
                            float(gen_power_w), float(power_max_w), float(power_min_w))

    def step(self, soc_pct: float, demand_w: float, gen_power_w: float, power_max_w: float,
             power_min_w: float) -> float:
        """Advance the thermostat and return the engine-generator power command [W]."""
        self.engine_on, p = self._law(self.engine_on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w)
        return p

    def split(self, soc_pct: float, demand_w: float, gen_power_w: float, power_max_w: float,
              power_min_w: float) -> float:
        """The command of :meth:`step` without changing the thermostat state."""
        return self._law(self.engine_on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w)[1]
