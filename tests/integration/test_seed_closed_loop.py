"""Seed fidelity (issue 14): the closed-loop BMS under the MPC is unbiased enough for A.1.

The DEKF propagates the plant's slow second RC branch (``bms.v2_model = "nominal_maps"``); over
HD-UDDS cycles under the MPC the SOC estimate error must stay below 1 % after the first 600 s and end
below 0.5 %, and the SOC-sustained fuel economy (seed A.1) must have windows after the MPC's settling
cycle.  Without the slow branch the same loop drifts by ~3 %.
"""
from __future__ import annotations

import numpy as np
import pytest

from shevsim.core.paths import data_path
from shevsim.core.scenario import load_scenario
from shevsim.metrics import sustainable_window_starts
from shevsim.run import compute_run_metrics, simulate

MPC = data_path("scenarios", "hd_udds_mpc_seed.toml")
RULE = data_path("scenarios", "hd_udds_rule_seed.toml")
T_CYCLE_S = 1060.0


def _run(path, sets=()):
    sc = load_scenario(path, list(sets))
    res = simulate(sc)
    assert res.termination == "completed"
    return res, sc


def _soc_err(res):
    return res["bms.soc_pct"] - res["battery.soc_pct"]


def test_one_hd_udds_cycle_under_the_mpc_soc_estimate_unbiased_and_limits_held():
    """Default run: one cycle (~1 s wall).  With the seed's one-branch DEKF the same loop is > 1 % off."""
    res, _ = _run(MPC, ["cycle.repeat=1"])
    t, e = res.time_s, _soc_err(res)
    assert np.max(np.abs(e[t >= 600.0])) < 1.0
    assert abs(e[-1]) < 0.5
    one, _ = _run(MPC, ["cycle.repeat=1", "bms.v2_model=none"])
    assert np.max(np.abs(_soc_err(one)[t >= 600.0])) > 1.0        # the departure this fixes
    # the within-step order: the battery stays within this step's BMS limits (1 kW tolerance)
    pb = res["bus.battery_power_w"]
    out = (pb > res["bms.power_max_w"] + 1e3) | (pb < res["bms.power_min_w"] - 1e3)
    assert out.sum() * (t[1] - t[0]) < 1.0


@pytest.mark.slow
def test_four_hd_udds_cycles_under_the_mpc_soc_error_below_1pct_after_600s_and_0p5pct_at_the_end():
    res, _ = _run(MPC, ["cycle.repeat=4"])
    t, e = res.time_s, _soc_err(res)
    assert t[-1] == pytest.approx(4 * T_CYCLE_S)
    assert np.max(np.abs(e[t >= 600.0])) < 1.0
    assert abs(e[-1]) < 0.5


@pytest.mark.slow
@pytest.mark.parametrize("path", [MPC, RULE], ids=["mpc", "rule"])
def test_a1_windows_exist_after_the_settling_cycle(path):
    """Four HD-UDDS cycles (the seed scenarios): A.1 windows (SOC(t) = SOC(t + T), exactly) start after
    the first (settling) cycle, for the MPC and the rule supervisor; the run's metrics report A.1."""
    res, sc = _run(path)
    m = compute_run_metrics(res, sc)
    starts = sustainable_window_starts(res.time_s, res["battery.soc_pct"], T_CYCLE_S)
    assert np.sum(starts >= T_CYCLE_S) >= 1
    assert m["fuel_economy_soc_sustained_kmpl"] is not None and m["soc_sustained_windows_count"] >= 1
    e = _soc_err(res)
    assert np.max(np.abs(e[res.time_s >= 600.0])) < 1.0
