"""One vehicle, one set of numbers (issue 25): shared quantities reach every user by every route, a
contradicting component value is refused naming both, a calibration's cell reaches the BMS, components are
sized by rating, the vehicle library runs, scenarios extend one another and save portably, unconnected
inputs are refused."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from shevsim.core.errors import ScenarioError
from shevsim.core.paths import DATA_ROOT
from shevsim.core.scenario import build_master, load_scenario
from shevsim.run import run

ROOT = Path(__file__).resolve().parents[2]
PANASONIC = ROOT / "docs" / "calibration_results" / "25degC_US06" / "params.toml"


def _params(sc, name):
    return build_master(sc).components[name].params


def _users(sc):
    m = build_master(sc)
    return {n: c for n, c in m.components.items()}


# --------------------------------------------------------------- every route reaches every user
def test_set_shared_n_parallel_reaches_battery_bms_supervisor_and_the_limits():
    base = _users(load_scenario("hd_udds_mpc"))
    sc = load_scenario("hd_udds_mpc", ["shared.n_parallel=6"])
    c = _users(sc)
    assert c["battery"].params.n_parallel == 6 and c["bms"].params.n_parallel == 6
    assert c["supervisor"].params.capacity_ah == pytest.approx(6 * 2.3)
    # the BMS's pack limits are n_s x n_p identical cells: linear in n_parallel
    assert c["bms"].y["power_max_w"] == pytest.approx(0.6 * base["bms"].y["power_max_w"], rel=1e-12)
    assert c["bms"].y["power_min_w"] == pytest.approx(0.6 * base["bms"].y["power_min_w"], rel=1e-12)


def test_component_value_of_a_shared_quantity_is_lifted_to_every_user():
    """The issue's cases: battery.n_parallel = 6 left the BMS at 10; vehicle.mass_kg left the driver's
    feed-forward at 15 554 kg."""
    c = _users(load_scenario("hd_udds_mpc", ["battery.n_parallel=6", "vehicle.mass_kg=12000"]))
    assert c["bms"].params.n_parallel == 6 and c["supervisor"].params.capacity_ah == pytest.approx(13.8)
    assert c["vehicle"].params.mass_kg == 12000.0 and c["driver"].params.mass_kg == 12000.0


def test_python_overrides_route():
    sc = load_scenario("hd_udds_rule")
    sc.set("shared.mass_kg", 12000.0)
    sc.update({"shared.n_series": 120})
    c = _users(sc)
    assert c["vehicle"].params.mass_kg == c["driver"].params.mass_kg == 12000.0
    assert c["battery"].params.n_series == c["bms"].params.n_series == 120
    assert sc.shared_values()["mass_kg"] == 12000.0


def test_overlay_routes_component_table_and_shared_table(tmp_path):
    ov = tmp_path / "ov.toml"
    ov.write_text("[battery]\nn_parallel = 8\n\n[shared]\nmass_kg = 11000.0\nengine_power_w = 200000.0\n")
    c = _users(load_scenario("hd_udds_mpc", overlays=[str(ov)]))
    assert c["bms"].params.n_parallel == 8 and c["battery"].params.n_parallel == 8
    assert c["driver"].params.mass_kg == 11000.0 and c["vehicle"].params.mass_kg == 11000.0
    k = 200000.0 / 261000.0
    assert c["engine_generator"].params.rated_power_w == 200000.0
    assert c["supervisor"].params.power_gen_max_w == pytest.approx(200600.0 * k)
    assert c["engine_generator"].maps.p_max_w == pytest.approx(200600.0 * k)
    # the MPC's fuel curve is the engine-generator's, sized with it
    assert c["supervisor"].params.fuel_curve_w[-1] == pytest.approx(200600.0 * k)


def test_calibration_overlay_gives_the_bms_the_plants_cell():
    """The shipped Panasonic calibration: capacity, OCV, factors, thermal parameters, temperature dependence
    and the record's voltage limits reach the BMS's nominal model; the MPC's capacity follows."""
    c = _users(load_scenario("hd_udds_mpc", overlays=[str(PANASONIC)]))
    b, m = c["battery"].params, c["bms"].params
    assert b.capacity_ah == m.capacity_ah == 2.9
    assert Path(b.ocv_file).resolve() == Path(m.ocv_file).resolve() == PANASONIC.parent / "ocv.csv"
    for k in ("rs_scale", "r1_scale", "c1_scale", "r2_scale", "c2_scale", "radius_m", "length_m", "density_kg_m3",
              "cp_j_kgk", "kt_w_mk", "temperature_dependent"):
        if k == "r2_scale" and b.r2_scale == 0.0:
            # a cell without second RC branch: the BMS's branch is off, its factor 1 (shared.py; the 25 degC overlay
            # names timing, not the second branch, since the seventh session's parsimony rule)
            assert m.v2_model == "none" and m.r2_scale == 1.0
            continue
        assert getattr(m, k) == getattr(b, k), k
    assert (m.v_min_v, m.v_max_v) == (2.5, 4.2)
    assert c["supervisor"].params.capacity_ah == pytest.approx(29.0)
    # the BMS's tables are the plant's: same OCV and the same scaled ECM lookups
    tb, tm = c["bms"].tables, c["battery"]
    from shevsim.battery.cell import CellTables
    plant = CellTables(b.ocv_file, b.entropy_file or None, b.discharge_file or None, b.charge_file or None,
                       scales=(b.rs_scale, b.r1_scale, b.c1_scale, b.r2_scale or 1.0, b.c2_scale), fixed_t_c=25.0)
    for soc in (0.2, 0.5, 0.8):
        assert tb.ocv(soc) == plant.ocv(soc)
        assert tb.params(soc, 40.0, 1.0) == pytest.approx(plant.params(soc, 25.0, 1.0), rel=1e-12)
    assert tm is not None


def test_a_deliberately_mismatched_bms_is_explicit(tmp_path):
    child = tmp_path / "mismatch.toml"
    child.write_text('[scenario]\nextends = "hd_udds_mpc"\nname = "mismatch"\n\n'
                     '[components.bms]\nown = ["cell"]\n')
    c = _users(load_scenario(child, overlays=[str(PANASONIC)]))
    assert c["battery"].params.capacity_ah == 2.9 and c["bms"].params.capacity_ah == 2.3   # the A123 defaults
    assert c["bms"].params.n_parallel == 10          # the pack is still shared


# --------------------------------------------------------------- contradictions refused naming both
def test_contradicting_component_value_refused_naming_both(tmp_path):
    child = tmp_path / "c.toml"
    child.write_text('[scenario]\nextends = "hd_udds_rule"\n\n[shared]\nmass_kg = 12000.0\n')
    with pytest.raises(ScenarioError) as e:
        build_master(load_scenario(child, ["vehicle.mass_kg=15000"]))
    msg = str(e.value)
    assert "--set 'vehicle.mass_kg=15000'" in msg and "shared quantity mass_kg = 12000.0" in msg
    assert "[shared] mass_kg" in msg
    with pytest.raises(ScenarioError) as e:
        build_master(load_scenario("hd_udds_mpc", ["battery.n_parallel=6", "bms.n_parallel=8"]))
    assert "battery.n_parallel = 6" in str(e.value) and "bms.n_parallel = 8" in str(e.value)


def test_component_parameter_file_contradicting_a_shared_quantity_refused(tmp_path):
    """A user's supervisor file still carrying the 236 kW of Table 5.2 while the generator gives 200.6 kW."""
    f = tmp_path / "mpc.toml"
    f.write_text((DATA_ROOT / "components" / "supervisor" / "mpc_default.toml").read_text()
                 .replace("[params]\n", "[params]\npower_gen_max_w = 236000.0\n")
                 .replace('"../engine_generator/fuel_vs_power.csv"',
                          f'"{DATA_ROOT / "components" / "engine_generator" / "fuel_vs_power.csv"}"'))
    sc = load_scenario("hd_udds_mpc", [f'supervisor.power_gen_max_w=236000.0'])
    with pytest.raises(ScenarioError, match=r"supervisor.power_gen_max_w = 236000.0 \(--set .*contradicts .*"
                                            r"rated electrical output.* = 200600.0"):
        build_master(sc)
    sc = load_scenario("hd_udds_mpc")
    sc.component("supervisor").params_file = f
    with pytest.raises(ScenarioError, match=rf"supervisor.power_gen_max_w = 236000.0 \({f}: \[params\].*contradicts"):
        build_master(sc)
    sc.component("supervisor").own.append("power_gen_max_w")      # a deliberate cap: explicit
    assert _params(sc, "supervisor").power_gen_max_w == 236000.0


def test_metrics_fuel_density_contradicting_the_fuel_refused():
    with pytest.raises(ScenarioError, match="fuel_density_kg_per_l = 0.9 contradicts the shared quantity"):
        run("hd_udds_rule", {"metrics.fuel_density_kg_per_l": 0.9}, stop_s=1.0)


def test_unknown_shared_quantity_named_with_a_hint():
    with pytest.raises(ScenarioError, match="unknown shared quantity 'mass_kgs'.*did you mean 'mass_kg'"):
        load_scenario("hd_udds_rule", ["shared.mass_kgs=1"])


# --------------------------------------------------------------- at the M-ATV values nothing changes
def test_shared_quantities_at_the_matv_values_change_no_number():
    """Every bundled component file and dataclass default is the M-ATV: a run with [shared] vehicle = "matv"
    equals one without shared quantities, bit for bit (compiled path)."""
    a = load_scenario("hd_udds_mpc", ["scenario.stop_s=60"])
    b = a.copy()
    b.shared.clear()
    ra, rb = run(a, engine="fast"), run(b, engine="fast")
    for k in ("battery.soc_pct", "bms.soc_pct", "engine_generator.fuel_mass_g", "vehicle.speed_mps",
              "supervisor.power_cmd_w", "bms.power_max_w"):
        assert np.array_equal(ra.signals[k], rb.signals[k]), k


# --------------------------------------------------------------- sizing by rating
def test_scaled_engine_at_scale_one_is_exact():
    from shevsim.components.engine_generator import EngineGenerator, EngineGeneratorParams
    from shevsim.powertrain.engine import EngineGenMaps
    m = EngineGenMaps.default()
    s = m.scaled(1.0)
    for attr in ("fuel", "torque", "soot", "geff"):
        for ax in ("x", "y", "z"):
            assert np.array_equal(getattr(getattr(m, attr), ax), getattr(getattr(s, attr), ax))
    for attr in ("tmax", "fmax", "gmax", "ool_speed", "ool_shaft", "ool_fuel"):
        for ax in ("x", "y"):
            assert np.array_equal(getattr(getattr(m, attr), ax), getattr(getattr(s, attr), ax))
    a = EngineGenerator("a", EngineGeneratorParams())
    b = EngineGenerator("b", EngineGeneratorParams(rated_power_w=261e3, maps_rated_power_w=261e3))
    for c in (a, b):
        c.u["power_cmd_w"] = 50e3
        c.initialize(0.0)
    for k in range(300):
        for c in (a, b):
            c.u["power_cmd_w"] = 150e3 if k < 150 else 20e3
            c.u["power_rate_max_wps"] = 30e3
            c.do_step(0.1 * k, 0.1)
        assert a.y == b.y


def test_scaled_engine_keeps_specific_fuel_and_efficiency():
    """k x rated power: at the same speed and k x torque the same bsfc, soot per fuel and generator efficiency;
    the quasi-static fuel curve is k x the original at k x the power (Autonomie/FASTSim rule)."""
    from shevsim.powertrain.engine import EngineGenMaps
    m = EngineGenMaps.default()
    k = 150e3 / 261e3
    s = m.scaled(k)
    w = np.linspace(m.fuel.x[0], m.fuel.x[-1], 7)
    tau = np.linspace(50.0, 900.0, 7)
    for wi in w:
        for ti in tau:
            assert s.fuel(wi, k * ti) == pytest.approx(k * m.fuel(wi, ti), rel=1e-12)
            assert s.soot(wi, k * ti) == pytest.approx(k * m.soot(wi, ti), rel=1e-12)
            assert s.geff(wi, k * ti) == pytest.approx(m.geff(wi, ti), rel=1e-12)
        assert s.tmax(wi) == pytest.approx(k * m.tmax(wi), rel=1e-12)
    for p in (10e3, 80e3, 190e3):
        assert s.fuel_quasi_static(k * p) == pytest.approx(k * m.fuel_quasi_static(p), rel=1e-12)
    assert s.p_max_w == pytest.approx(k * m.p_max_w)


def test_scaled_motor_torque_and_efficiency():
    from shevsim.components.motor import Motor, MotorParams
    a = Motor("a", MotorParams())
    b = Motor("b", MotorParams(rated_power_w=190e3))
    k = 0.5
    for w in (50.0, 300.0, 900.0):
        assert b.maps.peak(w) == pytest.approx(k * a.maps.peak(w), rel=1e-12)
        assert b.maps.eff(w, k * 400.0) == pytest.approx(a.maps.eff(w, 400.0), rel=1e-12)
    assert Motor("c", MotorParams(rated_power_w=380e3)).maps.peak.y.tolist() == a.maps.peak.y.tolist()


# --------------------------------------------------------------- the vehicle library
def test_vehicle_library_lists_three_series_hybrids_with_provenance():
    import shevsim
    v = shevsim.vehicles()
    assert {"matv", "city_bus", "delivery_truck"} <= set(v)
    for name, d in v.items():
        assert d["source"] and d["description"], name
        assert {"mass_kg", "engine_power_w", "motor_power_w", "n_series", "n_parallel", "cell"} <= set(d["shared"])
    from shevsim.cli import main
    assert main(["-q", "vehicles"]) == 0


@pytest.mark.parametrize("vehicle", ["matv", "city_bus", "delivery_truck"])
@pytest.mark.parametrize("scenario", ["hd_udds_mpc", "hd_udds_rule"])
def test_each_vehicle_runs_hd_udds_with_both_supervisors_short(vehicle, scenario):
    res = run(scenario, vehicle=vehicle, stop_s=300.0)
    df = res.to_pandas()
    assert res.termination.status == "completed", res.termination
    assert df["battery.soc_pct"].between(30.0, 70.0).all()
    assert (df["bms.soc_pct"] - df["battery.soc_pct"]).abs().max() < 1.0
    assert df["engine_generator.fuel_mass_g"].iloc[-1] > 0
    assert float(df["vehicle.speed_mps"].max()) > 15.0


def test_run_vehicle_and_cycle_from_the_command_line(tmp_path):
    from shevsim.cli import main
    out = tmp_path / "bus"
    assert main(["-q", "run", "--vehicle", "city_bus", "--cycle", "orange_county_bus", "-s", "scenario.stop_s=60",
                 "-o", str(out), "--no-plots"]) == 0
    saved = (out / "scenario.toml").read_text()
    assert 'vehicle = "city_bus"' in saved and 'cycle_file = "orange_county_bus"' in saved
    assert str(DATA_ROOT) not in saved


@pytest.mark.slow
@pytest.mark.parametrize("vehicle", ["matv", "city_bus", "delivery_truck"])
@pytest.mark.parametrize("scenario", ["hd_udds_mpc", "hd_udds_rule"])
@pytest.mark.parametrize("cycle", ["hd_udds", "orange_county_bus"])
def test_each_vehicle_sustains_soc_over_three_cycles(vehicle, scenario, cycle):
    """Three consecutive cycles: the supervisors, unchanged, hold SOC (the end of cycle 3 within 1.5 % of the
    end of cycle 2, after the MPC's settling cycle) inside the window; the delta-SOC corrected fuel economy
    exists."""
    res = run(scenario, {"cycle.repeat": 3}, vehicle=vehicle, cycle=cycle)
    assert res.termination.status == "completed", res.termination
    m = res.metrics
    t, soc = res.time_s, res.signals["battery.soc_pct"]
    T = m["cycle_duration_s"]
    s2, s3 = np.interp(2 * T, t, soc), np.interp(3 * T - 1e-9, t, soc)
    assert abs(s3 - s2) < 1.5, (s2, s3)
    assert m["fuel_economy_dsoc_corrected_kmpl"] is not None and m["fuel_economy_dsoc_corrected_kmpl"] > 0
    assert np.min(soc) >= 30.0 - 1.0 and np.max(soc) <= 70.0 + 1.0


# --------------------------------------------------------------- the Panasonic hand-off
def test_panasonic_overlay_run_short_bms_soc_error_small():
    res = run("hd_udds_mpc", overlays=[str(PANASONIC)], stop_s=400.0)
    df = res.to_pandas()
    assert res.termination.status == "completed", res.termination
    assert (df["bms.soc_pct"] - df["battery.soc_pct"]).abs().max() < 2.0


@pytest.mark.slow
def test_panasonic_overlay_whole_run_completes_the_trace_with_small_bms_soc_error():
    """Issue 25: before, the BMS kept the A123 cell: SOC error up to 70 %, 13.3 of 17.9 km."""
    res = run("hd_udds_mpc", overlays=[str(PANASONIC)])
    df = res.to_pandas()
    assert res.termination.status == "completed", res.termination
    assert res.metrics["distance_km"] == pytest.approx(17.87, rel=0.01)
    assert (df["bms.soc_pct"] - df["battery.soc_pct"]).abs().max() < 3.0


# --------------------------------------------------------------- scenarios compose and save portably
def test_extends_states_only_what_differs(tmp_path):
    child = tmp_path / "bus.toml"
    child.write_text('[scenario]\nextends = "hd_udds_mpc"\nname = "bus12"\n\n'
                     '[shared]\nmass_kg = 12000.0\nengine_power_w = 150000.0\n\n'
                     '[components.cycle]\nset = { repeat = 1 }\n')
    sc = load_scenario(child)
    base = load_scenario("hd_udds_mpc")
    assert sc.name == "bus12" and sc.component_names == base.component_names
    assert len(sc.connections) == len(base.connections) and sc.order == base.order
    assert sc.shared == {"vehicle": "matv", "mass_kg": 12000.0, "engine_power_w": 150000.0}
    c = _users(sc)
    assert c["driver"].params.mass_kg == 12000.0 and c["cycle"].params.repeat == 1
    assert c["engine_generator"].params.rated_power_w == 150000.0
    with pytest.raises(ScenarioError, match="extends = 'no_such'"):
        load_scenario(text='[scenario]\nextends = "no_such"\n')


def test_saved_scenario_names_bundled_data_and_loads_from_another_folder(tmp_path):
    """to_toml names bundled data by name; the text runs from an empty folder with a copy of the package in
    the wheel's layout (package + shevsim/_data) - another installation."""
    sc = load_scenario("hd_udds_rule", ["shared.mass_kg=12000"]).use(vehicle="city_bus", cycle="orange_county_bus")
    text = sc.to_toml()
    assert str(DATA_ROOT) not in text and str(ROOT) not in text
    assert 'params = "components/vehicle/matv.toml"' in text and 'cycle_file = "orange_county_bus"' in text
    again = load_scenario(text=text)
    assert again.to_toml() == text
    site = tmp_path / "site"
    shutil.copytree(ROOT / "shevsim", site / "shevsim", ignore=shutil.ignore_patterns("__pycache__"))
    for f in ("components", "cycles", "scenarios", "fmus", "vehicles"):
        shutil.copytree(ROOT / f, site / "shevsim" / "_data" / f, ignore=shutil.ignore_patterns("__pycache__"))
    work = tmp_path / "empty"
    work.mkdir()
    (work / "saved.toml").write_text(text)
    code = ("import shevsim.core.paths as p; from shevsim.core.scenario import build_master, load_scenario;"
            "sc = load_scenario('saved.toml'); m = build_master(sc);"
            "print(p.DATA_ROOT, m.components['vehicle'].params.mass_kg, m.components['battery'].params.n_parallel,"
            " m.components['cycle'].params.cycle_file)")
    r = subprocess.run([sys.executable, "-c", code], cwd=work, capture_output=True, text=True, timeout=600,
                       env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path),
                            "NUMBA_DISABLE_JIT": "1"})
    assert r.returncode == 0, r.stderr
    root, mass, npar, cyc = r.stdout.split()
    assert root == str(site / "shevsim" / "_data") and float(mass) == 12000.0 and int(npar) == 18
    assert cyc.startswith(str(site))


# --------------------------------------------------------------- unconnected inputs
def test_unconnected_input_refused_unless_defaulted():
    text = (DATA_ROOT / "scenarios" / "hd_udds_mpc.toml").read_text()
    cut = text.replace('"vehicle.traction_force_n" = "motor.traction_force_n"\n', "")
    assert cut != text
    with pytest.raises(ScenarioError, match=r"\[components.vehicle\] input 'traction_force_n' .* is not connected"):
        build_master(load_scenario(text=cut))
    # bus.aux_power_w is unconnected in every bundled scenario: its default (no auxiliary input) is declared
    build_master(load_scenario(text=text))


def test_vehicle_only_scenario_refused_not_run_to_zero_distance():
    text = ('[scenario]\nname = "vehicle_only"\nstop_s = 10.0\n\n[components.vehicle]\ntype = "vehicle"\n'
            'params = "components/vehicle/matv.toml"\n')
    with pytest.raises(ScenarioError, match="input 'traction_force_n'"):
        build_master(load_scenario(text=text))
    # a start value is a declared value: accepted
    ok = text + "start = { traction_force_n = 1000.0 }\n"
    r = build_master(load_scenario(text=ok)).run(10.0)
    assert r.termination.status == "completed"


# --------------------------------------------------------------- studies: the key sees the shared quantities
def test_study_evaluation_key_and_run_carry_shared_quantities():
    """A study's evaluation captures the resolved shared quantities (values, cell tables by content): a
    shared change changes the key, equal inputs by any route give equal keys, the captured run uses them."""
    from shevsim.studies.evaluate import Evaluation
    scen = DATA_ROOT / "scenarios" / "hd_udds_rule.toml"
    a = Evaluation.make(scen, {"shared.mass_kg": 12000.0}, stop_s=80.0, final_signals=("vehicle.distance_m",))
    b = Evaluation.make(scen, {"shared.mass_kg": 13000.0}, stop_s=80.0, final_signals=("vehicle.distance_m",))
    c = Evaluation.make(scen, {}, stop_s=80.0, final_signals=("vehicle.distance_m",))
    assert len({a.key(), b.key(), c.key()}) == 3
    assert Evaluation.make(scen, {"shared.mass_kg": 12000.0}, stop_s=80.0,
                           final_signals=("vehicle.distance_m",)).key() == a.key()
    out = a.run()
    assert out["termination"] == "completed" and out["final:vehicle.distance_m"] > 10.0
