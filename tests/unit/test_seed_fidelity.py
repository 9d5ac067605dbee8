"""Seed fidelity (issue 14): the App. A reproduction configuration and its common fuel/soot basis."""
from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

from shevsim.core.paths import data_path
from shevsim.core.scenario import load_scenario
from shevsim.metrics import DIESEL_DENSITY_KG_PER_L, compute_metrics, soot_dsoc_corrected
from shevsim.run import compute_run_metrics, simulate
from shevsim.studies.evaluate import toml_value
from shevsim.studies.problem import DEFAULT_EDGES_W, map_overrides

SEED = data_path("scenarios", "uac_proxy_mpc_seed.toml")


def test_soot_dsoc_corrected_books_the_battery_energy_at_the_runs_soot_per_fuel():
    # no net battery energy: the equivalent fuel is the fuel, the corrected soot the raw one
    assert soot_dsoc_corrected(500.0, 1000.0, 1000.0, 10.0) == pytest.approx(0.05)
    # the battery gave energy worth 20 g of fuel: 2 % more soot is charged to the run
    assert soot_dsoc_corrected(500.0, 1000.0, 1020.0, 10.0) == pytest.approx(0.05 * 1.02)
    for bad in ((500.0, 0.0, 10.0, 10.0), (500.0, 1000.0, None, 10.0), (500.0, 1000.0, 1000.0, 0.0)):
        assert soot_dsoc_corrected(*bad) is None


def test_seed_engine_parameters_quasi_static_soot_scaled_to_the_thesis():
    p = tomllib.loads(data_path("components", "engine_generator", "seed_app_a.toml").read_text())["params"]
    assert p["transient_soot_mg_per_g"] == 0.0          # App. A simulated the quasi-static map only
    # the thesis's soot per fuel: 0.0316 g/km at 3.278 km/l (App. A baseline)
    thesis_g_per_kg = 0.0316 / (DIESEL_DENSITY_KG_PER_L / 3.278)
    assert thesis_g_per_kg == pytest.approx(0.1238, abs=5e-5)
    assert p["soot_scale_frac"] == pytest.approx(thesis_g_per_kg / 0.8152, rel=1e-3)


def _run(sets=()):
    sc = load_scenario(SEED, list(sets))
    res = simulate(sc)
    assert res.termination == "completed"
    return res, compute_run_metrics(res, sc)


@pytest.fixture(scope="module")
def baseline():
    return _run()


def test_seed_baseline_soot_per_fuel_is_the_thesis_level(baseline):
    res, m = baseline
    assert float(res["engine_generator.soot_transient_mg"][-1]) == 0.0
    # the scaling in the parameter file gives the thesis's 0.124 g/kg on the reproduction run
    assert m["soot_per_fuel_g_per_kg"] == pytest.approx(0.1238, rel=0.01)
    # the corrected soot and fuel economy use the same equivalent fuel
    fe_raw_ratio = m["fuel_economy_raw_kmpl"] / m["fuel_economy_dsoc_corrected_kmpl"]
    assert m["soot_dsoc_corrected_g_per_km"] / m["soot_g_per_km"] == pytest.approx(fe_raw_ratio, rel=1e-12)


def test_app_a_direction_at_19p3_kwps_on_the_reproduction_config(baseline):
    """App. A: a constant 19.3 kW/s limit cut soot by 1.9 % at a fuel-economy cost within 0.5 %.  On the
    reproduction configuration, both on the Delta-SOC-corrected basis: soot down 0.5-4 %, fuel economy
    down by less than 0.5 % (or up)."""
    _, m0 = baseline
    n = len(DEFAULT_EDGES_W) - 1
    ov = map_overrides("supervisor", DEFAULT_EDGES_W, [19.3e3] * n)
    _, m1 = _run([f"{k}={toml_value(v)}" for k, v in ov.items()])
    d_soot = 100.0 * (m1["soot_dsoc_corrected_g_per_km"] / m0["soot_dsoc_corrected_g_per_km"] - 1.0)
    d_fe = 100.0 * (m1["fuel_economy_dsoc_corrected_kmpl"] / m0["fuel_economy_dsoc_corrected_kmpl"] - 1.0)
    assert -4.0 <= d_soot <= -0.5, d_soot
    assert d_fe > -0.5, d_fe
