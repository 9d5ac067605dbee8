"""Whole-vehicle SHEV runs (issues 4 and 8): conservation, tracking, SOC window, rate map, soot trade-off."""
from pathlib import Path

import numpy as np
import pytest

from shevsim.core.scenario import load_scenario
from shevsim.run import compute_run_metrics, simulate

ROOT = Path(__file__).resolve().parents[2]


def run(name, sets=(), stop_s=None):
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml", list(sets))
    if stop_s is not None:
        sc.stop_s = stop_s
    r = simulate(sc)
    return r, compute_run_metrics(r, sc)


@pytest.fixture(scope="module")
def hd_udds_rule():
    return run("hd_udds_rule", ["cycle.repeat=1"])


def test_energy_balance_closes_over_hd_udds(hd_udds_rule):
    r, m = hd_udds_rule
    # fuel -> engine -> generator -> bus <-> battery -> motors -> wheels -> road loads + losses + dKE
    assert abs(m["energy_closure_error_frac"]) < 1e-3, m["energy_closure_error_frac"]


def test_hd_udds_rule_tracks_the_trace_and_keeps_soc(hd_udds_rule):
    r, m = hd_udds_rule
    assert m["speed_miss_rms_kmh"] < 1.0
    assert m["distance_km"] == pytest.approx(8.935, rel=0.01)
    soc = r["battery.soc_pct"]
    assert soc.min() > 30.0 and soc.max() < 70.0
    # a 15.5 t diesel series hybrid: a few km per litre, soot well under a gram per km
    assert 2.0 < m["fuel_economy_dsoc_corrected_kmpl"] < 5.0
    assert 0.01 < m["soot_g_per_km"] < 2.0


@pytest.fixture(scope="module")
def rate_map_pair():
    free, m_free = run("hd_udds_mpc", ["cycle.repeat=1"])
    edges = "supervisor.rate_map_power_edges_w=[0.0, 80000.0, 236000.0]"
    rates = "supervisor.rate_map_max_rate_wps=[30000.0, 8000.0]"
    tight, m_tight = run("hd_udds_mpc", ["cycle.repeat=1", edges, rates])
    return (free, m_free), (tight, m_tight)


def test_power_rate_map_is_respected(rate_map_pair):
    (_, _), (r, m) = rate_map_pair
    t = r.time_s
    p = r["engine_generator.power_limited_w"]            # the engine-generator's rate-limited command
    rate = np.diff(p) / np.diff(t)
    # above 80 kW (+ one 0.2 s ramp at the lower level, which may start below the edge) at most 8 kW/s
    high = p[:-1] >= 80e3 + 30e3 * 0.2
    assert high.sum() > 50
    assert rate[high].max() <= 8e3 * (1 + 1e-9)
    assert rate.max() <= 30e3 * (1 + 1e-9)
    cmd = r["supervisor.power_cmd_w"][::2]                 # supervisor commands every 0.2 s
    assert np.all(np.diff(cmd) <= 30e3 * 0.2 + 1e-6)
    assert r["supervisor.fallback_count"][-1] == 0


def test_tighter_high_power_ramp_cuts_soot(rate_map_pair):
    (_, m_free), (_, m_tight) = rate_map_pair
    print("soot g/km free %.4f tight %.4f; fuel economy (dSOC corrected) free %.4f tight %.4f km/L" % (
        m_free["soot_g_per_km"], m_tight["soot_g_per_km"],
        m_free["fuel_economy_dsoc_corrected_kmpl"], m_tight["fuel_economy_dsoc_corrected_kmpl"]))
    assert m_tight["soot_g_per_km"] < m_free["soot_g_per_km"]


def test_mpc_keeps_soc_window_without_fallbacks(rate_map_pair):
    (r, m), _ = rate_map_pair
    assert r["supervisor.fallback_count"][-1] == 0
    assert r["battery.soc_pct"].min() > 30.0 and r["battery.soc_pct"].max() < 70.0
    assert m["speed_miss_rms_kmh"] < 1.0
    assert abs(m["energy_closure_error_frac"]) < 1e-3


@pytest.fixture(scope="module")
def cooling_fault_1500():
    # the one-step-late wiring (motor and generator on the bus's limits of the previous step), whose
    # mechanism this test checks; the default scenarios hold the limits within the step
    # (tests/unit/test_bms_limits_within_step.py, tests/integration/test_bms_study.py)
    return run("uac_proxy_mpc_cooling_fault_one_step_late", stop_s=1500.0)


def test_load_shedding_keeps_the_battery_within_its_power_capability(cooling_fault_1500):
    """Cooling fault (h 20 -> 3 W/m2K at 300 s): the BMS's charge limit P_b,min goes to a few tens of kW.
    The bus derates the motors and (load shedding) caps the generator at what the bus can absorb.
    Both act on the previous step's bus values (the engine-generator runs before the bus, which books
    its power), so what is left is the one-step lag: at step k the battery can be charged beyond
    P_b,min only by the drop of the motor power within that step (or, with the generator limit at 0,
    by the rise of the generator power), and discharged beyond P_b,max only by the drop of the
    generator power - exact inequalities, checked on every step. Before load shedding
    this run spent 19.8 s more than 1 kW beyond the limits (worst 181 kW: the generator kept delivering
    after braking started); with it ~5 s, in steps where the motor power fell within the step."""
    r, m = cooling_fault_1500
    assert r.termination == "completed"
    t = r.time_s
    pb, gen, mot = r["bus.battery_power_w"], r["engine_generator.elec_power_w"], r["motor.elec_power_w"]
    pmax, pmin, gmax = r["bms.power_max_w"], r["bms.power_min_w"], r["bus.gen_power_max_w"]
    # the engine-generator never delivers more than the bus limit it saw (previous step's bus output)
    assert np.all(gen[1:] <= gmax[:-1] * (1 + 1e-12) + 1e-6)
    # one-step-lag bounds (limits judged as published before the step, as in the BMS study); exact up to
    # round-off. Charge side: with the generator capped (limit > 0) the excess is at most the motor power's
    # drop within the step; else the motor derating bounds it by the generator's rise.
    tol = 1e-3  # W
    drop_motor = np.maximum(mot[:-1] - mot[1:], 0.0)
    rise_gen = np.maximum(gen[1:] - gen[:-1], 0.0)
    drop_gen = np.maximum(gen[:-1] - gen[1:], 0.0)
    capped = gmax[:-1] > 0.0
    assert np.all((pmin[:-1] - pb[1:] - drop_motor)[capped] <= tol)
    assert np.all(pmin[:-1] - pb[1:] - np.maximum(drop_motor, rise_gen) <= tol)
    assert np.all(pb[1:] - pmax[:-1] - drop_gen <= tol)
    # beyond the limits by more than 1 kW only briefly, and never two steps running at the full excess
    over = np.maximum(pmin[:-1] - pb[1:], pb[1:] - pmax[:-1])
    dt = float(np.median(np.diff(t)))
    t_over = dt * np.count_nonzero(over > 1e3)
    print("time beyond limits by > 1 kW: %.1f s, worst %.1f kW, shedding episodes %d, %.1f s" % (
        t_over, over.max() / 1e3, r["engine_generator.shed_count"][-1], r["engine_generator.shed_time_s"][-1]))
    assert t_over < 10.0                        # was 19.8 s without load shedding
    assert r["engine_generator.shed_count"][-1] > 0
    # no lasting violation: a 1 s moving mean of the excess stays below 20 kW (was up to ~100 kW)
    k = int(round(1.0 / dt))
    mean_over = np.convolve(np.maximum(over, 0.0), np.ones(k) / k, mode="valid")
    assert mean_over.max() < 20e3, mean_over.max()
    # energy still closes across the whole vehicle
    assert abs(m["energy_closure_error_frac"]) < 1e-3, m["energy_closure_error_frac"]


def test_metrics_report_the_robustness_counters(rate_map_pair):
    (r, m), _ = rate_map_pair
    # QP fallbacks, battery clamping and generator load shedding are counted in metrics.json
    for key in ("supervisor.fallback_count", "battery.clamp_count", "engine_generator.shed_count"):
        assert key in m, key
        assert m[key] == r[key][-1]
    assert m["supervisor.fallback_count"] == 0
