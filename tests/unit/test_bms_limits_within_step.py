"""Battery power limits held within the step (issue 14): the ``power_limits`` component and the seed
scenario order (BMS -> motor_limits -> motor -> gen_limits -> engine_generator -> bus)."""
from __future__ import annotations

import numpy as np
import pytest

from shevsim.components import get_component_class
from shevsim.components.bus import BusParams, PowerBus, PowerLimits
from shevsim.core.paths import data_path
from shevsim.core.scenario import load_scenario
from shevsim.run import simulate


def test_power_limits_is_the_bus_limit_law():
    rng = np.random.default_rng(0)
    assert get_component_class("power_limits") is PowerLimits
    for enforce in (True, False):
        prm = BusParams(enforce_battery_limits=enforce, aux_power_w=1500.0)
        lim, bus = PowerLimits("l", prm), PowerBus("b", prm)
        lim.initialize(0.0)
        bus.initialize(0.0)
        for _ in range(200):
            u = dict(motor_power_w=rng.uniform(-2e5, 2e5), gen_power_w=rng.uniform(-5e3, 2.4e5),
                     aux_power_w=rng.uniform(0, 5e3), battery_power_max_w=rng.uniform(0, 3e5),
                     battery_power_min_w=rng.uniform(-3e5, 0))
            lim.u.update(u)
            bus.u.update(u)
            lim.do_step(0.0, 0.1)
            bus.do_step(0.0, 0.1)
            for k in ("motor_power_max_w", "motor_power_min_w", "gen_power_max_w"):
                assert lim.y[k] == bus.y[k], k


def test_power_limits_refuses_nan_naming_the_port():
    lim = PowerLimits("motor_limits")
    lim.initialize(0.0)
    lim.u["battery_power_max_w"] = float("nan")
    with pytest.raises(Exception, match="motor_limits.*battery_power_max_w"):
        lim.do_step(1.0, 0.1)


def _violation_s(res, tol_w=1e3):
    pb = res["bus.battery_power_w"]
    h = res.time_s[1] - res.time_s[0]
    bad = (pb > res["bms.power_max_w"] + tol_w) | (pb < res["bms.power_min_w"] - tol_w)
    return float(bad.sum() * h)


def _run(name):
    return simulate(load_scenario(data_path("scenarios", name)))


def test_seed_order_holds_the_limits_better_than_the_one_step_late_order():
    """The whole cooling-fault run (2926 s, fault at 300 s, ~3 s wall each): the within-step order leaves
    the same-step BMS limits (1 kW tolerance) for a fraction of the time the previous order does, and the
    core stays at the limit."""
    late = _run("uac_proxy_mpc_cooling_fault_one_step_late.toml")
    now = _run("uac_proxy_mpc_cooling_fault.toml")      # the default wiring (same as *_seed.toml)
    v_late, v_now = _violation_s(late), _violation_s(now)
    assert v_late > 10.0                     # the one-step-late order leaves the limits (issue 14: ~50 s)
    assert v_now < 0.25 * v_late, (v_now, v_late)
    assert v_now < 1.0                       # issue 14: < 1 s in total (measured 0.5 s; the old order 47.9 s)
    assert now["battery.t_core_c"].max() <= 45.0
    # the charge side holds exactly: the generator is shed against this step's motor power and charge limit,
    # and the regen limit counts only on the generator power that shedding can hold (>= 0)
    assert np.all(now["bus.battery_power_w"] >= now["bms.power_min_w"] - 1.0)


def test_power_limits_generator_floor_is_the_rest_of_the_load_beyond_the_discharge_limit():
    lim = PowerLimits("gen_limits", BusParams(aux_power_w=2e3))
    lim.initialize(0.0)
    lim.u.update(motor_power_w=150e3, aux_power_w=1e3, battery_power_max_w=50e3, battery_power_min_w=-40e3)
    lim.do_step(0.0, 0.1)
    assert lim.y["gen_power_min_w"] == pytest.approx(150e3 + 3e3 - 50e3)
    off = PowerLimits("gen_limits", BusParams(enforce_battery_limits=False))
    off.initialize(0.0)
    assert off.y["gen_power_min_w"] == -1e12


def test_engine_generator_floor_holds_the_power_through_a_speed_up_dip_with_exact_energy_bookkeeping():
    """A step up of the command makes the optimal-line speed rise: the generator torque falls while the
    shaft accelerates (a dip in electrical power).  With a floor at the pre-step power the generator holds
    it (every step's mean >= floor, to round-off) out of the shaft's kinetic energy, and the energy balance
    fuel = elec + engine loss + generator loss + kinetic energy stays exact."""
    from shevsim.components.engine_generator import EngineGenerator
    runs = {}
    for floor in (0.0, 1.0):
        eg = EngineGenerator("eg")
        eg.u["power_cmd_w"] = 180e3
        eg.initialize(0.0)
        p0 = eg.y["elec_power_w"]
        eg.u["power_cmd_w"] = 236e3
        eg.u["power_rate_max_wps"] = 30e3
        eg.u["elec_power_min_w"] = floor * p0
        p = []
        for k in range(100):
            eg.do_step(0.1 * k, 0.1)
            p.append(eg.y["elec_power_w"])
            y = eg.y
            bal = y["elec_energy_j"] + y["engine_loss_energy_j"] + y["gen_loss_energy_j"] + y["shaft_kinetic_energy_j"]
            assert bal == pytest.approx(y["fuel_energy_j"], rel=1e-9, abs=1e-6)
        runs[floor] = (p0, np.array(p))
    p0, free = runs[0.0]
    assert free.min() < p0 - 1e3                 # without the floor the speed-up dips below the start power
    _, held = runs[1.0]
    assert held.min() >= p0 - 1e-6 * p0          # held at the floor


def test_engine_generator_floor_compiled_equals_py_func():
    """One source: the floor (engine step item 10d) in the compiled step and in its py_func."""
    from shevsim.components.engine_generator import EngineGenerator
    a, b = EngineGenerator("a"), EngineGenerator("b", compiled=False)
    assert b.step_function() is not a.step_function()
    rng = np.random.default_rng(5)
    for eg in (a, b):
        eg.u["power_cmd_w"] = 150e3
        eg.initialize(0.0)
    for k in range(300):
        u = dict(power_cmd_w=rng.uniform(0, 236e3), power_rate_max_wps=rng.choice([10e3, 30e3, 1e12]),
                 elec_power_min_w=rng.uniform(-50e3, 200e3), elec_power_max_w=rng.choice([1e12, 236e3, 100e3]))
        for eg in (a, b):
            eg.u.update(u)
            eg.do_step(0.1 * k, 0.1)
        for key, v in a.y.items():
            assert v == pytest.approx(b.y[key], rel=1e-12, abs=1e-9), (k, key)
