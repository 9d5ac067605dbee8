"""Battery plant + BMS under the co-simulation master: ordering, cooling fault, save/restore."""
from __future__ import annotations

import numpy as np

from shevsim.components.battery import BatteryPack, BatteryPackParams
from shevsim.components.bms import BMS, BMSParams
from shevsim.core.component import Component
from shevsim.core.master import Connection, Fault, Master, MasterSettings
from shevsim.core.variables import inp, out


class ClampedDemand(Component):
    """Drive-cycle-like pack-power demand clamped by the BMS limits (a stand-in supervisor)."""

    TYPE = "test_demand"
    VARIABLES = (inp("power_max_w", "W", 1e9), inp("power_min_w", "W", -1e9),
                 out("power_w", "W", 0.0, "", ("power_max_w", "power_min_w")))

    def initialize(self, t0):
        rng = np.random.default_rng(2)
        levels = rng.uniform(-120e3, 140e3, 400)
        self.levels = levels - 0.9 * levels.mean()
        self.y["power_w"] = 0.0

    def do_step(self, t, h):
        p = float(self.levels[int(t // 6.0) % len(self.levels)])
        self.y["power_w"] = min(max(p, self.u["power_min_w"]), self.u["power_max_w"])


def _master():
    comps = [ClampedDemand("demand"), BatteryPack("battery", BatteryPackParams(soc_init_pct=55.0)),
             BMS("bms", BMSParams.retuned())]
    conns = [Connection.parse("battery.power_w", "demand.power_w"),
             Connection.parse("demand.power_max_w", "bms.power_max_w"),
             Connection.parse("demand.power_min_w", "bms.power_min_w")]
    for port in ("cell_current_meas_a", "cell_voltage_meas_v", "t_surface_meas_c", "t_ambient_meas_c"):
        conns.append(Connection.parse(f"bms.{port}", f"battery.{port}"))
    return Master(comps, conns, MasterSettings(step_s=0.1),
                  faults=[Fault(300.0, "battery", "h_conv_w_m2k", 3.0)])


def test_master_run_keeps_core_below_limit_through_cooling_fault():
    m = _master()
    res = m.run(900.0)
    t_core = res["battery.t_core_c"]
    assert t_core.max() > 43.0 and t_core.max() <= 45.2
    assert np.all(res["bms.power_max_w"] >= 0.0) and np.all(res["bms.power_min_w"] <= 0.0)
    soc_err = np.abs(res["bms.soc_pct"] - res["battery.soc_pct"])
    assert soc_err[-1000:].max() < 3.0


def test_master_save_restore_reproduces_battery_and_bms():
    m = _master()
    m.run(100.0)
    snap = m.save_state()
    a = m.run(200.0)
    first = {k: a[k][-1000:].copy() for k in ("battery.voltage_v", "battery.cell_voltage_meas_v", "bms.soc_pct",
                                              "bms.power_max_w")}
    m.restore_state(snap)
    b = m.run(200.0)
    for k, v in first.items():
        assert np.array_equal(b[k][-1000:], v), k
