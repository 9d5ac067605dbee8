"""Tests of the rule-based (thermostat / power-follower) baseline supervisor and its component."""
from __future__ import annotations

import math

import numpy as np
import pytest

from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.params import load_params
from shevsim.supervisor.rate_map import PowerRateMap
from shevsim.supervisor.rule_based import RuleBasedSupervisor, RuleSettings

MAP = PowerRateMap([0.0, 75e3, 150e3, 236e3], [30e3, 20e3, 10e3])
DT = 0.2


def sup(**kw):
    return RuleBasedSupervisor(RuleSettings(**kw), MAP, DT)


def test_thermostat_hysteresis():
    r = sup()
    # low demand, SOC falling through the band: off until 45 %, then on until 55 %
    states = []
    for soc in (60, 50, 46, 45, 48, 54, 55, 50):
        r.step(soc, 20e3, 50e3, 200e3, -200e3)
        states.append(r.engine_on)
    assert states == [False, False, False, True, True, True, False, False]
    # a demand above engine_on_demand_w (or above the battery limit) runs the engine at any SOC
    r = sup()
    r.step(65.0, 80e3, 50e3, 200e3, -200e3)
    assert r.engine_on
    r = sup()
    r.step(65.0, 40e3, 50e3, 30e3, -200e3)
    assert r.engine_on


def test_power_follower_with_soc_correction():
    s = RuleSettings()
    r = RuleBasedSupervisor(s, PowerRateMap.constant(1e12), DT)      # rise-rate limit out of play
    gen = 105e3                     # the fall rate allows -12 kW per call: targets below stay >= 93 kW
    r.engine_on = True
    assert r.step(50.0, 100e3, gen, 300e3, -300e3) == pytest.approx(100e3)                  # at the reference
    assert r.step(40.0, 100e3, gen, 300e3, -300e3) == pytest.approx(100e3 + 0.5 * s.charge_power_w)
    assert r.step(31.0, 100e3, gen, 300e3, -300e3) == pytest.approx(100e3 + 0.95 * s.charge_power_w)
    # low demand, engine running: 5 kW + 0.3 x 30 kW = 14 kW -> raised to the least running power
    assert r.step(44.0, 5e3, 30e3, 300e3, -300e3) == pytest.approx(s.engine_on_min_power_w)
    assert r.step(44.0, 5e3, gen, 300e3, -300e3) == pytest.approx(gen - 60e3 * DT)   # fall-rate limited
    # engine off: P_g,min, the battery carries the demand
    r.engine_on = False
    assert r.step(60.0, 20e3, 5e3, 300e3, -300e3) == pytest.approx(s.power_gen_min_w)
    # split() evaluates without changing the thermostat
    assert r.split(40.0, 20e3, gen, 300e3, -300e3) > 0.0 and r.engine_on is False


def test_soc_window_battery_engine_and_rate_limits_hold():
    """Random states: the command respects the rate map (always), the engine limits (when the present
    power is inside them), the battery limits and the SOC window whenever the rate limits allow."""
    rng = np.random.default_rng(4)
    r = sup()
    s = r.settings
    for _ in range(3000):
        soc = rng.uniform(20, 80)
        d = rng.uniform(-150e3, 350e3)
        g = rng.uniform(0.0, s.power_gen_max_w)
        pmax, pmin = rng.uniform(0, 250e3), -rng.uniform(0, 200e3)
        v = r.step(soc, d, g, pmax, pmin)
        lo_r, hi_r = g + s.power_rate_min_wps * DT, g + MAP(g) * DT
        assert lo_r - 1e-9 <= v <= hi_r + 1e-9
        assert s.power_gen_min_w - 1e-9 <= v <= s.power_gen_max_w + 1e-9
        # battery window and SOC window as an interval for P_g; where reachable, it must be met
        lo = max(d - pmax, s.power_gen_min_w)
        hi = min(d - pmin, s.power_gen_max_w)
        if soc <= s.soc_min_pct:
            lo = max(lo, d)                  # no discharge below SOC_min
        if soc >= s.soc_max_pct:
            hi = min(hi, max(d, s.power_gen_min_w))  # no charge above SOC_max
        if lo <= hi and max(lo, lo_r) <= min(hi, hi_r):
            assert lo - 1e-6 <= v <= hi + 1e-6, (soc, d, g, pmax, pmin, v)


def test_closed_loop_soc_stays_in_window():
    """SOC integrator (pack 23 Ah, 429 V OCV, 0.156 Ohm) with the engine following the command under the
    rate limits: the baseline keeps the SOC inside its window over a long, varying demand."""
    r = sup()
    soc, gen = 50.0, 0.0
    rng = np.random.default_rng(1)
    lo = hi = soc
    for k in range(20000):
        d = max(0.0, 60e3 + 80e3 * math.sin(k / 60) + 20e3 * rng.standard_normal())
        gen = r.step(soc, d, gen, 200e3, -150e3)
        P = d - gen
        i = (429.0 - math.sqrt(429.0 ** 2 - 4 * 0.156 * P)) / (2 * 0.156)
        soc -= 100 * i * DT / (3600 * 23.0)
        lo, hi = min(lo, soc), max(hi, soc)
    assert 30.0 <= lo and hi <= 70.0
    assert hi - lo > 2.0                 # it does cycle the battery


def test_settings_validation():
    with pytest.raises(ScenarioError, match="soc_on_pct"):
        RuleSettings(soc_on_pct=60.0)
    with pytest.raises(ScenarioError, match="power_rate_min_wps"):
        RuleSettings(power_rate_min_wps=5.0)
    with pytest.raises(ScenarioError, match="dt_s"):
        RuleBasedSupervisor(RuleSettings(), MAP, 0.0)


def test_component():
    from shevsim.components.supervisors import RuleSupervisor, RuleSupervisorParams
    p = load_params(RuleSupervisorParams, "components/supervisor/rule_default.toml")
    c = RuleSupervisor("r", p)
    RuleSupervisor("x")
    c.u.update(demand_power_w=80e3, soc_pct=50.0, gen_power_w=40e3, power_max_w=150e3, power_min_w=-120e3)
    c.initialize(0.0)      # the previous command starts at the engine's present output
    c.do_step(0.0, 0.2)
    assert c.y["engine_on_1"] == 1.0
    assert c.y["power_cmd_w"] == pytest.approx(40e3 + 30e3 * 0.2)      # following 80 kW at 30 kW/s
    assert all(type(v) is float for v in c.y.values())
    st = c.get_state()
    c.u["soc_pct"] = 60.0
    c.u["demand_power_w"] = 10e3
    c.do_step(0.2, 0.2)
    assert c.y["engine_on_1"] == 0.0
    c.set_state(st)
    assert c.engine_on is True
    with pytest.raises(SimulationError, match="step multiple"):
        c.do_step(0.2, 0.1)
    c.u["soc_pct"] = float("nan")
    with pytest.raises(SimulationError, match="soc_pct"):
        c.do_step(0.2, 0.2)
    with pytest.raises(ScenarioError, match="rule_supervisor 'b'"):
        RuleSupervisor("b", RuleSupervisorParams(soc_on_pct=80.0))
