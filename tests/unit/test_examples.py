"""Every script in examples/ runs (shortened with SHEVSIM_EXAMPLE_QUICK=1) and its numbers make sense."""
import runpy
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _load(name, monkeypatch):
    monkeypatch.setenv("SHEVSIM_EXAMPLE_QUICK", "1")
    return runpy.run_path(str(EXAMPLES / name), run_name="shevsim_example")


def test_every_example_is_tested():
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == \
        ["bus_vs_matv.py", "calibrate_cell.py", "compare_vehicles.py", "parameter_sweep.py"]


def test_compare_vehicles(tmp_path, monkeypatch):
    runs = _load("compare_vehicles.py", monkeypatch)["main"](tmp_path)
    heavy, light = runs
    assert heavy.termination == "completed" and light.termination == "completed"
    # same trace, less mass and drag: less fuel for the same distance
    assert light.metrics["distance_km"] == pytest.approx(heavy.metrics["distance_km"], rel=0.01)
    assert light.metrics["fuel_mass_g"] < heavy.metrics["fuel_mass_g"]
    assert (tmp_path / "compare_vehicles.png").stat().st_size > 10_000


def test_bus_vs_matv(tmp_path, monkeypatch):
    mod = _load("bus_vs_matv.py", monkeypatch)
    text = mod["BUS"].strip().splitlines()
    assert len([x for x in text if x.strip() and not x.strip().startswith("#")]) <= 20   # a bus in ~20 lines
    runs = mod["main"](tmp_path)
    bus, matv = runs.values()
    assert bus.termination == "completed" and matv.termination == "completed"
    assert bus.parameters["engine_generator"]["rated_power_w"] == 150000.0
    assert bus.parameters["driver"]["mass_kg"] == 12000.0
    assert bus.metrics["distance_km"] == pytest.approx(matv.metrics["distance_km"], rel=0.01)
    # a smaller engine, 3.5 t lighter: less fuel on the same trace
    assert bus.metrics["fuel_mass_g"] < matv.metrics["fuel_mass_g"]


def test_parameter_sweep(tmp_path, monkeypatch):
    fe = _load("parameter_sweep.py", monkeypatch)["main"](tmp_path)
    masses = sorted(fe)
    assert len(masses) == 3 and all(fe[m] is not None and fe[m] > 0 for m in masses)
    assert fe[masses[0]] > fe[masses[1]] > fe[masses[2]]      # heavier -> lower fuel economy
    assert (tmp_path / "sweep_mass.png").is_file()
    assert all((tmp_path / f"mass_{m:.0f}" / "timeseries.parquet").is_file() for m in masses)


def test_calibrate_cell_on_the_shipped_measured_data(tmp_path, monkeypatch):
    rep = _load("calibrate_cell.py", monkeypatch)["main"](tmp_path)
    before, after = rep["rmse_before"]["voltage_v"]["holdout"], rep["rmse_after"]["voltage_v"]["holdout"]
    assert 0 < after <= before < 0.1          # volts: held-out error not worse after the calibration
    assert (tmp_path / "calibration" / "params.toml").is_file()
    # the record's voltage limits travel to the scenario's BMS through the overlay's [shared] table (issue 25)
    from shevsim.core.overlay import overlay_tables
    assert overlay_tables(tmp_path / "calibration" / "params.toml")["shared"] == {"cell_v_min_v": 2.5,
                                                                               "cell_v_max_v": 4.2}
