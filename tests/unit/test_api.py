"""The Python API exported from ``shevsim``: simulate with typed overrides, scenarios in code, Result."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

import shevsim
from shevsim.core.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


def test_exports():
    for name in ("simulate", "load_scenario", "new_scenario", "scenarios", "compare", "metrics_table",
                 "load_result", "run_study", "run_calibration", "Result", "Scenario", "Termination", "__version__"):
        assert hasattr(shevsim, name), name
    assert "hd_udds_rule" in shevsim.scenarios()
    assert (Path(shevsim.__file__).parent / "py.typed").is_file()


def test_simulate_bundled_by_name_with_typed_overrides():
    # the example, shortened to 60 s: a heavier vehicle needs more traction energy for the same trace
    light = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, "vehicle.mass_kg": 12000.0}, stop_s=60.0)
    heavy = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, "vehicle.mass_kg": 18000.0}, stop_s=60.0)
    assert light.termination == "completed" and heavy.termination.ok
    assert light.meta["engine"] in ("python", "fast")
    assert heavy.parameters["vehicle"]["mass_kg"] == 18000.0
    assert light.time_s[-1] == pytest.approx(60.0)
    df = heavy.to_pandas()
    assert df.attrs["units"]["vehicle.speed_mps"] == "m/s" and "time_s" in df
    e_l = np.trapezoid(np.maximum(light["motor.elec_power_w"], 0), light.time_s)
    e_h = np.trapezoid(np.maximum(heavy["motor.elec_power_w"], 0), heavy.time_s)
    assert e_h > e_l * 1.2
    assert heavy.metrics["distance_km"] == pytest.approx(light.metrics["distance_km"], rel=0.02)


def test_scenario_fields_are_overridable_and_checked():
    res = shevsim.simulate(TWO_BODY, {"scenario.step_s": 0.02, "scenario.stop_s": 1.0})
    assert np.allclose(np.diff(res.time_s), 0.02) and res.time_s[-1] == pytest.approx(1.0)
    with pytest.raises(ScenarioError, match=r"overrides\['scenario.step_s'\].*positive"):
        shevsim.simulate(TWO_BODY, {"scenario.step_s": -1.0})
    with pytest.raises(ScenarioError, match=r"overrides\['scenario.stpe_s'\].*did you mean 'st\w+'"):
        shevsim.simulate(TWO_BODY, {"scenario.stpe_s": 1.0})
    with pytest.raises(ScenarioError, match=r"overrides\['body1.mass_kg'\]: component 'body1'.*mass_kg"):
        shevsim.simulate(TWO_BODY, {"body1.mass_kg": "heavy"})
    with pytest.raises(ScenarioError, match=r"overrides\['bodyX.mass_kg'\]: unknown component 'bodyX'"):
        shevsim.simulate(TWO_BODY, {"bodyX.mass_kg": 1.0})


def test_cli_set_reaches_scenario_fields_and_names_the_option(tmp_path, capsys):
    from shevsim.cli import main
    assert main(["run", str(TWO_BODY), "-o", str(tmp_path / "o"), "--set", "scenario.stop_s=0.5", "-q",
                 "--no-plots"]) == 0
    meta = json.loads((tmp_path / "o" / "run.json").read_text())
    assert meta["resolved_scenario"]["stop_s"] == 0.5
    assert main(["run", str(TWO_BODY), "-o", str(tmp_path / "p"), "--set", "body1.mass_kg=abc", "-q"]) == 2
    err = capsys.readouterr().err
    assert "--set 'body1.mass_kg=abc'" in err and "two_body.toml" not in err
    assert not (tmp_path / "p").exists()


def test_load_scenario_inspect_change_run():
    sc = shevsim.load_scenario(TWO_BODY)
    assert sc.component_names == ["body1", "coupling"]
    sc.component("coupling").overrides["damping_ns_per_m"] = 5.0
    sc.set("scenario.stop_s", 2.0)
    a = shevsim.simulate(sc)
    b = shevsim.simulate(TWO_BODY, {"coupling.damping_ns_per_m": 5.0, "scenario.stop_s": 2.0})
    np.testing.assert_array_equal(a["body1.position_m"], b["body1.position_m"])
    assert sc.stop_s == 2.0        # simulate works on a copy: the object is unchanged by running
    # the scenario written as TOML loads back into the same run
    c = shevsim.simulate(shevsim.load_scenario(_write(sc.to_toml())))
    np.testing.assert_array_equal(a["coupling.position2_m"], c["coupling.position2_m"])


def _write(text):
    import tempfile
    p = Path(tempfile.mkdtemp()) / "s.toml"
    p.write_text(text)
    return p


def test_build_in_code_equals_the_toml_scenario():
    sc = shevsim.new_scenario("two_body", step_s=0.01, stop_s=3.0)
    sc.add_component("body1", "mass_spring", set={"mass_kg": 1.0, "stiffness_n_per_m": 10.0, "x0_m": 1.0,
                                                  "v0_mps": 0.0})
    sc.add_component("coupling", "spring_damper", set={"mass_kg": 2.0, "stiffness_n_per_m": 5.0,
                                                       "damping_ns_per_m": 0.5, "x0_m": 0.0, "v0_mps": 0.0})
    sc.connect("coupling.force_n", "body1.force_n")                       # source first (SSP order)
    sc.connect(src="body1.position_m", dst="coupling.position_m").connect("body1.velocity_mps", "coupling.velocity_mps")
    code = shevsim.simulate(sc)
    toml = shevsim.simulate(TWO_BODY, stop_s=3.0)
    for s in toml.signals:
        np.testing.assert_array_equal(code[s], toml[s], err_msg=s)
    with pytest.raises(ScenarioError, match="unknown component 'bodyy'"):
        sc.connect("coupling.force_n", "bodyy.force_n")
    with pytest.raises(ScenarioError, match=r"must be non-empty without '\.'"):
        sc.add_component("a.b", "gain")


def test_result_plot_one_axis_per_unit_and_compare():
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    r1 = shevsim.simulate(TWO_BODY, stop_s=1.0)
    r2 = shevsim.simulate(TWO_BODY, {"coupling.damping_ns_per_m": 3.0}, stop_s=1.0)
    fig = r1.plot(["body1.position_m", "coupling.position2_m", "body1.velocity_mps"])
    axes = fig.axes
    assert len(axes) == 2 and axes[0].get_ylabel() == "Position (m)" and axes[1].get_ylabel() == "Body1: velocity (km/h)"
    assert len(axes[0].lines) == 2
    np.testing.assert_allclose(axes[1].lines[0].get_ydata(), 3.6 * r1["body1.velocity_mps"])   # m/s shown as km/h
    axes = shevsim.compare([r1, r2], signals=["coupling.position2_m"], labels=["c=0.5", "c=3"]).axes
    assert len(axes) == 1 and len(axes[0].lines) == 2
    assert not np.array_equal(axes[0].lines[0].get_ydata(), axes[0].lines[1].get_ydata())
    plt.close("all")
    tab = shevsim.metrics_table([r1, r2], labels=["a", "b"])
    assert list(tab.index) == ["a", "b"] and (tab["termination"] == "completed").all()


def test_result_save_and_load_round_trip_with_parquet_units(tmp_path):
    import pyarrow.parquet as pq
    res = shevsim.simulate(TWO_BODY, stop_s=0.5)
    out = res.save(tmp_path / "r")
    schema = pq.read_schema(out / "timeseries.parquet")
    assert schema.field("body1.velocity_mps").metadata[b"unit"] == b"m/s"
    assert json.loads(schema.metadata[b"shevsim.units"])["time_s"] == "s"
    back = shevsim.load_result(out)
    np.testing.assert_array_equal(back["body1.position_m"], res["body1.position_m"])
    assert back.termination == "completed" and back.termination.status == "completed"
    assert isinstance(back.metrics, dict) and "notes" in back.metrics


def test_record_less(tmp_path):
    full = shevsim.simulate(TWO_BODY, stop_s=1.0)
    dec = shevsim.simulate(TWO_BODY, stop_s=1.0, record_every=7, record=["body1.position_m"])
    assert list(dec.signals) == ["body1.position_m"]
    assert dec.time_s[-1] == pytest.approx(1.0) and len(dec) == 100 // 7 + 2
    idx = [int(round(t / 0.01)) for t in dec.time_s]
    np.testing.assert_array_equal(dec["body1.position_m"], full["body1.position_m"][idx])


def test_engine_choice():
    res = shevsim.simulate(TWO_BODY, stop_s=0.1, engine="python")
    assert res.meta["engine"] == "python"
    with pytest.raises(ScenarioError, match="engine must be one of"):
        shevsim.simulate(TWO_BODY, stop_s=0.1, engine="turbo")
    import importlib.util
    if importlib.util.find_spec("shevsim.fast") is None:
        with pytest.raises(ScenarioError, match="engine 'fast'"):
            shevsim.simulate(TWO_BODY, stop_s=0.1, engine="fast")


def test_user_scenario_names_bundled_parameter_sets_and_cycles(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text('[scenario]\nname = "mine"\nstop_s = 5.0\n'
                 '[components.cycle]\ntype = "cycle"\nset = { cycle_file = "uac_proxy" }\n'
                 '[components.vehicle]\ntype = "vehicle"\nparams = "matv"\n'
                 '[components.driver]\ntype = "driver"\nparams = "driver/default"\n')
    sc = shevsim.load_scenario(p)
    from shevsim.core.paths import data_path
    assert sc.component("vehicle").params_file == data_path("components", "vehicle", "matv.toml")
    assert sc.component("driver").params_file == data_path("components", "driver", "default.toml")
    assert Path(sc.component("cycle").overrides["cycle_file"]) == data_path("cycles", "uac_proxy.csv").absolute()
    p.write_text(p.read_text().replace('params = "matv"', 'params = "matvv"'))
    with pytest.raises(ScenarioError, match=r"mine.toml: \[components.vehicle\]: field 'params'.*'matvv' not found"):
        shevsim.load_scenario(p)


def test_cli_version_scenarios_quiet_and_exit_codes(capsys):
    from shevsim.cli import main
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"shevsim {shevsim.__version__}"
    assert main(["scenarios", "-q"]) == 0
    assert capsys.readouterr().out.split() == shevsim.scenarios()
    assert main(["-q", "info", "hd_udds_rule"]) == 0
    assert capsys.readouterr().out.count("\n") == 1
    assert main(["run", "--no-such-flag"]) == 2
    assert main(["run", "no_such_scenario", "-q"]) == 2
    assert "bundled scenarios by name" in capsys.readouterr().err
    assert main(["--help"]) == 0
    assert "exit codes: 0 ok; 1 " in capsys.readouterr().out
    assert main(["run", "--help"]) == 0
    text = capsys.readouterr().out
    assert "SCENARIO is a bundled scenario's name" in text and "scenario.FIELD" in text


def test_internal_error_has_its_own_exit_code(monkeypatch, capsys):
    import shevsim.run as run_mod
    from shevsim.cli import main

    def bug(*a, **k):
        raise ZeroDivisionError("a bug")
    monkeypatch.setattr(run_mod, "run", bug)
    assert main(["run", str(TWO_BODY), "-q"]) == 3
    assert "internal error: ZeroDivisionError: a bug" in capsys.readouterr().err


def test_quiet_works_for_study_and_calibrate(tmp_path, capsys):
    from shevsim.cli import main
    assert main(["-q", "study", "tradeoff", "--synthetic", "--workers", "0", "--out", str(tmp_path / "s"),
                 "--rates-kwps", "20", "40", "--no-plots"]) == 0
    assert main(["study", "tradeoff", "--synthetic", "--workers", "0", "--out", str(tmp_path / "t"),
                 "--rates-kwps", "20", "40", "--no-plots", "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["-q", "calibrate", "cell", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "c")]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and "missing.csv" in cap.err


def test_a_scenario_changed_by_attribute_is_still_checked():
    """Scenario.set validates; a field changed as a plain attribute is checked before the run too."""
    from shevsim.core.errors import ScenarioError
    sc = shevsim.load_scenario("hd_udds_rule")
    sc.stop_s = float("nan")
    with pytest.raises(ScenarioError, match="'stop_s' must be a finite number"):
        shevsim.simulate(sc)
    sc = shevsim.load_scenario("hd_udds_rule")
    sc.metrics["fuel_density_kg_per_l"] = -0.85
    with pytest.raises(ScenarioError, match="fuel_density_kg_per_l"):
        shevsim.simulate(sc)
