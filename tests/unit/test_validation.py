"""One validation layer for every number (issue 13 item 2): parameter ranges declared once per field
(metadata or unit-suffix convention), applied in make_params / Component.__init__, and the same rules on
map and table columns and on the scenario's [metrics] options."""
import dataclasses
import importlib
import math
from pathlib import Path

import numpy as np
import pytest

from shevsim.components import REGISTRY, get_component_class
from shevsim.core.errors import DataError, ScenarioError, ShevsimError
from shevsim.core.params import (Range, check_options, field_range, load_params, make_params, name_rule, params_to_dict, rng,
                                 validate_params)
from shevsim.core.paths import data_path
from shevsim.core.scenario import build_master, load_scenario
from shevsim.powertrain.maps import load_curve_csv, load_grid_csv

PARAM_CLASSES = sorted({get_component_class(t).Params for t in REGISTRY if get_component_class(t).Params},
                       key=lambda c: c.__name__)


def _numeric_fields(cls):
    hints = __import__("typing").get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if hints[f.name] in (float, int, tuple[float, ...]):
            yield f, hints[f.name]


# -------------------------------------------------------------------------------- the mechanism

def test_range_semantics():
    r = rng(gt=0.0, hi=1.0)["range"]
    assert not r.ok(0.0) and r.ok(1e-12) and r.ok(1.0) and not r.ok(1.0 + 1e-12)
    assert not r.ok(math.nan) and not r.ok(math.inf)
    assert r.describe().startswith("(0, 1]")
    inf_ok = rng(gt=0.0, allow_inf=True)["range"]
    assert inf_ok.ok(math.inf) and not inf_ok.ok(-math.inf) and not inf_ok.ok(math.nan)
    assert Range().ok(-1e300) and not Range().ok(math.inf)


@pytest.mark.parametrize("name, good, bad", [
    ("soc_init_pct", 100.0, 100.5), ("heat_index_init_frac", 0.0, -0.01), ("t_init_c", -273.0, -273.15),
    ("capacity_ah", 1e-6, 0.0), ("mass_kg", 1.0, -1.0), ("density_kg_m3", 1.0, 0.0),
    ("rs0_ohm", 1e-3, 0.0), ("q_soc", 0.0, -1e-9), ("sigma_current_a", 0.0, -1.0),
    ("motor_eff", 1.0, 1.5), ("efficiency_frac", 0.5, 0.0), ("turbo_lag_s", 0.0, -0.1),
    ("n_series", 1, 0), ("fuel_density_kg_per_l", 0.85, -0.85), ("rs_scale", 0.0, -0.5),
])
def test_name_rules(name, good, bad):
    r = name_rule(name)
    assert r.ok(good), (name, good, r.describe())
    assert not r.ok(bad), (name, bad, r.describe())


def test_declared_metadata_wins_over_the_name_rule():
    @dataclasses.dataclass(frozen=True)
    class P:
        x0_m: float = dataclasses.field(default=0.0, metadata=rng(what="either sign"))
        limit_a: float = dataclasses.field(default=math.inf, metadata=rng(gt=0.0, allow_inf=True))
        length_m: float = 1.0

    assert make_params(P, {"x0_m": -3.0}).x0_m == -3.0          # the _m rule (>= 0) is overridden
    assert make_params(P, {"limit_a": math.inf}).limit_a == math.inf
    with pytest.raises(ScenarioError, match=r"'length_m' = -1.0: out of range; valid range: > 0"):
        make_params(P, {"length_m": -1.0}, "file.toml")
    with pytest.raises(ScenarioError, match=r"file.toml: parameter 'limit_a' = nan: NaN"):
        make_params(P, {"limit_a": math.nan}, "file.toml")


# -------------------------------------------------------------------------------- every component

@pytest.mark.parametrize("cls", PARAM_CLASSES, ids=lambda c: c.__name__)
def test_defaults_are_valid(cls):
    validate_params(cls())


@pytest.mark.parametrize("cls", PARAM_CLASSES, ids=lambda c: c.__name__)
def test_nan_refused_in_every_numeric_field(cls):
    """NaN is never a valid parameter: every numeric field of every component, named in the message."""
    fields = list(_numeric_fields(cls))
    assert fields
    for f, typ in fields:
        if typ is int:
            continue
        if typ is float:
            val, name = math.nan, f.name
        else:
            val, name = [math.nan], rf"{f.name}\[0\]"
        with pytest.raises(ScenarioError, match=rf"p.toml: parameter '{name}' = nan: NaN is not a valid value"):
            make_params(cls, {f.name: val}, "p.toml")
        if not field_range(f).allow_inf:
            with pytest.raises(ScenarioError, match=rf"parameter '{name}' = -?inf: -?inf is not allowed"):
                make_params(cls, {f.name: -math.inf if typ is float else [-math.inf]}, "p.toml")


def test_shipped_parameter_files_are_valid():
    root = data_path("components")
    files = sorted(Path(root).glob("*/*.toml"))
    assert len(files) >= 9
    for f in files:
        kind = f.parent.name
        if kind == "supervisor":
            kind = "mpc_supervisor" if "mpc" in f.stem else "rule_supervisor"
        if kind == "cell":      # a cell set: the BMS's nominal cell model has every cell field
            kind = "bms"
        load_params(get_component_class(kind).Params, f)


@pytest.mark.parametrize("setting, field", [
    ("bms.t_core_max_c=nan", "t_core_max_c"), ("bms.i_cell_max_a=nan", "i_cell_max_a"),
    ("bms.q_soc=nan", "q_soc"), ("bms.r_v=nan", "r_v"), ("bms.p0_soc=nan", "p0_soc"), ("bms.s0_r1=nan", "s0_r1"),
    ("battery.t_init_c=nan", "t_init_c"), ("battery.capacity_ah=-2.3", "capacity_ah"),
    ("vehicle.mass_kg=-15554", "mass_kg"), ("motor.wheel_radius_m=0", "wheel_radius_m"),
    ("vehicle.wheel_inertia_kg_m2=-3.26", "wheel_inertia_kg_m2"),
    ("battery.soc_init_pct=150", "soc_init_pct"), ("engine_generator.fuel_lhv_j_per_g=0", "fuel_lhv_j_per_g"),
])
def test_known_cases_refused_naming_the_set_option(setting, field):
    sc = load_scenario("hd_udds_mpc", [setting])
    with pytest.raises(ScenarioError, match=rf"--set '{setting}'.*parameter '{field}' = .*valid range"):
        build_master(sc)


def test_negative_fuel_density_refused():
    with pytest.raises(ScenarioError, match=r"fuel_density_kg_per_l' = -0.85: out of range; valid range: > 0"):
        load_scenario("hd_udds_rule", ["metrics.fuel_density_kg_per_l=-0.85"])
    assert check_options({"fuel_density_kg_per_l": 0.84, "ah_weighting": "constant"}, "x") \
        == {"fuel_density_kg_per_l": 0.84, "ah_weighting": "constant"}


def test_python_api_objects_are_checked_too():
    from shevsim.components.battery import BatteryPack, BatteryPackParams
    from shevsim.components.bms import BMS, BMSParams
    with pytest.raises(ScenarioError, match=r"component 'bms' parameters: parameter 'i_cell_max_a' = nan"):
        BMS("bms", BMSParams(i_cell_max_a=math.nan))
    with pytest.raises(ScenarioError, match=r"t_init_c.* nan"):   # (its own __post_init__ check fires first)
        BatteryPack("battery", BatteryPackParams(t_init_c=math.nan))


def test_list_values_checked_per_element():
    from shevsim.components.vehicle import VehicleParams
    with pytest.raises(ScenarioError, match=r"parameter 'grade_frac\[1\]' = nan"):
        make_params(VehicleParams, {"grade_distance_m": [0.0, 100.0], "grade_frac": [0.0, math.nan]})


# -------------------------------------------------------------------------------- maps and tables

def _motor_map(tmp_path, transform) -> Path:
    src = Path(data_path("components", "motor", "motor_eff_map.csv")).read_text().splitlines()
    head = [ln for ln in src if ln.startswith("#") or not ln.strip()]
    rows = [ln for ln in src if ln.strip() and not ln.startswith("#")]
    out = tmp_path / "motor_eff_map.csv"
    out.write_text("\n".join(head + transform(rows)) + "\n")
    return out


def test_motor_efficiency_map_of_1_5_refused(tmp_path):
    def scale(rows):
        return [rows[0]] + [f"{a},{b},{float(c) * 1.5 / 0.92:.6g}" for a, b, c in (r.split(",") for r in rows[1:])]
    p = _motor_map(tmp_path, scale)
    with pytest.raises(DataError, match=r"column 'efficiency_frac': value .* outside the physical range \(0, 1\]"):
        load_grid_csv(p, "speed_radps", "torque_nm", "efficiency_frac")
    sc = load_scenario("hd_udds_rule", [f"motor.efficiency_map_file='{p}'"])
    with pytest.raises(ShevsimError, match=r"efficiency_frac"):
        build_master(sc)


def test_nan_map_cell_named_by_line_and_column(tmp_path):
    def nan_cell(rows):
        r = rows[:]
        a, b, _ = r[5].split(",")
        r[5] = f"{a},{b},nan"
        return r
    p = _motor_map(tmp_path, nan_cell)
    with pytest.raises(DataError, match=r"line \d+, column 'efficiency_frac': value nan is not a finite number") as e:
        load_grid_csv(p, "speed_radps", "torque_nm", "efficiency_frac")
    assert "incomplete grid" not in str(e.value)


def test_map_spreadsheet_quirks_accepted(tmp_path):
    plain = tmp_path / "plain.csv"
    plain.write_text("# c\nx_m,y_gps\n0,1.5\n1,2.5\n2,0.5\n")
    quirky = tmp_path / "quirky.csv"
    quirky.write_bytes("\ufeff# c\r\nx_m;y_gps;;\r\n0;1,5;;\r\n1;2,5;;\r\n2;0,5;;\r\n".encode("utf-8"))
    a, b = load_curve_csv(plain, "x_m", "y_gps"), load_curve_csv(quirky, "x_m", "y_gps")
    assert np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y)
    bad = tmp_path / "neg.csv"
    bad.write_text("x_m,y_gps\n0,1\n1,-2\n")
    with pytest.raises(DataError, match=r"line 3, column 'y_gps': value -2.0 is outside the physical range >= 0"):
        load_curve_csv(bad, "x_m", "y_gps")
    dup = tmp_path / "dup.csv"
    dup.write_text("x_m,y_gps\n0,1\n0,2\n1,3\n")
    with pytest.raises(DataError, match=r"appears twice"):
        load_curve_csv(dup, "x_m", "y_gps")


def test_cell_tables_bom_and_ranges(tmp_path):
    from shevsim.battery.cell import CellTables
    src = Path(data_path("components", "battery", "a123_26650_ocv.csv"))
    bom = tmp_path / "ocv.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + src.read_bytes())
    t1, t2 = CellTables(), CellTables(ocv_file=bom)
    assert t1._ocv.xs == t2._ocv.xs and t1._ocv.ys == t2._ocv.ys
    dis = Path(data_path("components", "battery", "a123_26650_ecm_discharge.csv")).read_text().splitlines()
    i = next(k for k, ln in enumerate(dis) if ln and not ln.startswith("#") and ln[0].isdigit())
    parts = dis[i].split(",")
    parts[2] = "-" + parts[2]                         # a negative series resistance
    dis[i] = ",".join(parts)
    bad = tmp_path / "dis.csv"
    bad.write_text("\n".join(dis) + "\n")
    with pytest.raises(DataError, match=r"column 'rs_ohm': value -.* outside the physical range > 0"):
        CellTables(discharge_file=bad)


def test_min_above_max_refused():
    """Fields named alike except for min/max are a pair: the minimum must not exceed the maximum."""
    from shevsim.components.bms import BMSParams
    from shevsim.components.supervisors import RuleSupervisorParams
    with pytest.raises(ScenarioError, match=r"'soc_min_pct' = 80.0 is above 'soc_max_pct' = 70.0"):
        make_params(RuleSupervisorParams, {"soc_min_pct": 80.0}, "sup.toml")
    with pytest.raises(ScenarioError, match=r"'v_min_v' = 3.7 is above 'v_max_v' = 3.6"):
        make_params(BMSParams, {"v_min_v": 3.7}, "bms.toml")
    assert make_params(RuleSupervisorParams, {"soc_min_pct": 70.0}).soc_min_pct == 70.0   # equal is allowed


def test_numpy_scalars_are_numbers_and_still_range_checked():
    """A sweep in a notebook passes np.int64/np.float32 values (np.arange, np.linspace): accepted as the
    Python numbers they are, and still checked (a NaN or a negative mass from numpy is refused)."""
    from shevsim.components.vehicle import VehicleParams
    base = dict(params_to_dict(load_params(VehicleParams, data_path("components", "vehicle", "matv.toml"))))
    p = make_params(VehicleParams, {**base, "mass_kg": np.int64(18000)}, "<api>")
    assert p.mass_kg == 18000.0 and type(p.mass_kg) is float
    p = make_params(VehicleParams, {**base, "mass_kg": np.float32(12000.5)}, "<api>")
    assert p.mass_kg == 12000.5
    for bad in (np.float64("nan"), np.float32(-1.0)):
        with pytest.raises(ScenarioError, match="mass_kg"):
            make_params(VehicleParams, {**base, "mass_kg": bad}, "<api>")


def test_name_rules_give_each_field_its_meaning():
    """The first matching rule decides: n_c is the MPC's control horizon (a count), not a temperature;
    stiffness, damping and rates are non-negative, voltages too."""
    assert name_rule("n_c").what == "a count" and name_rule("n_c").lo == 1.0
    assert name_rule("t_core_max_c").what.startswith("a temperature")
    assert name_rule("stiffness_n_per_m").what == "a stiffness"
    assert name_rule("damping_ns_per_m").what == "a damping coefficient"
    assert name_rule("heat_rate_per_s").what == "a rate"
    assert name_rule("v_min_v").lo == 0.0


def test_vectorised_range_check_equals_the_scalar_one():
    """``Range.ok_array`` (map columns are checked with it) gives ``Range.ok`` element by element on every
    unit-suffix rule and on open, closed and "no limit" bounds, at the edges, infinities and NaN."""
    import math

    import numpy as np

    from shevsim.core.params import ANY, NAME_RULES, Range
    vals = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, math.inf, -math.inf, math.nan, 0.5, 2.0, 273.15, -273.15,
                     -273.16, 1e12, 100.0, 100.0000001])
    ranges = [r for _, _, r in NAME_RULES] + [ANY, Range(lo=0, hi=1, lo_open=True),
                                              Range(lo=0, hi=1, hi_open=True, allow_inf=True),
                                              Range(allow_inf=True), Range(lo=0, allow_inf=True)]
    for r in ranges:
        assert np.array_equal(r.ok_array(vals), [r.ok(float(v)) for v in vals]), r


@pytest.mark.parametrize("sets,fix", [(["scenario.step_s=0.05"], "set step_multiple = 4"),
                                      (["scenario.step_s=0.03"], "use a step_s that divides 0.2 s")])
def test_a_supervisor_whose_step_is_not_its_sample_time_is_refused_when_built(sets, fix):
    """A supervisor called with a step other than its sample_time_s used to stop the run at t = 0; the scenario is
    now refused before it runs, naming the component, the field and the fix."""
    from shevsim.core.scenario import build_master, load_scenario
    with pytest.raises(ScenarioError, match=r"\[components\.supervisor\] sample_time_s = 0\.2 s .*" + fix):
        build_master(load_scenario("hd_udds_mpc", sets))
