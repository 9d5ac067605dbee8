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

from shevsim.core.errors import ScenarioError

from .rate_map import PowerRateMap


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

    def _thermostat(self, soc_pct, demand_w, power_max_w) -> bool:
        s = self.settings
        must = demand_w >= s.engine_on_demand_w or demand_w > power_max_w
        if self.engine_on:
            return not (soc_pct >= s.soc_off_pct and not must)
        return soc_pct <= s.soc_on_pct or must

    def _power(self, on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w) -> float:
        s = self.settings
        if on:
            x = (s.soc_ref_pct - soc_pct) / (s.soc_ref_pct - s.soc_min_pct)
            p = demand_w + s.charge_power_w * min(max(x, -1.0), 1.0)
            p = max(p, s.engine_on_min_power_w)
        else:
            p = s.power_gen_min_w
        if soc_pct <= s.soc_min_pct:
            p = max(p, demand_w)
        if soc_pct >= s.soc_max_pct:
            p = min(p, max(demand_w, s.power_gen_min_w))
        if power_min_w <= power_max_w:
            p = min(max(p, demand_w - power_max_w), demand_w - power_min_w)
        p = min(max(p, s.power_gen_min_w), s.power_gen_max_w)
        rate = self.rate_map(gen_power_w)
        return min(max(p, gen_power_w + s.power_rate_min_wps * self.dt_s), gen_power_w + rate * self.dt_s)

    def step(self, soc_pct: float, demand_w: float, gen_power_w: float, power_max_w: float,
             power_min_w: float) -> float:
        """Advance the thermostat and return the engine-generator power command [W]."""
        self.engine_on = self._thermostat(soc_pct, demand_w, power_max_w)
        return self._power(self.engine_on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w)

    def split(self, soc_pct: float, demand_w: float, gen_power_w: float, power_max_w: float,
              power_min_w: float) -> float:
        """The command of :meth:`step` without changing the thermostat state."""
        on = self._thermostat(soc_pct, demand_w, power_max_w)
        return self._power(on, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w)
