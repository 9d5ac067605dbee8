"""A notebook that feels native: short repr, HTML views, plot() -> Figure in display units, distinct row
labels in metrics_table, FMUs added from the API, connections with an explicit direction checked when made."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import shevsim
from shevsim.core.errors import ScenarioError, ShevsimError

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


@pytest.fixture(scope="module")
def shev():
    """A short run of the bundled series-hybrid scenario (Python master: no compilation)."""
    return shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=60.0, engine="python")


def test_repr_is_short_and_says_what_matters(shev):
    text = repr(shev)
    assert len(text) < 200, len(text)
    assert "hd_udds_rule" in text and "completed" in text and "601 points" in text and "signals" in text
    sc = shevsim.load_scenario("hd_udds_rule")
    text = repr(sc)
    assert len(text) < 300, len(text)
    assert "hd_udds_rule" in text and f"{len(sc.components)} components" in text
    assert f"{len(sc.connections)} connections" in text


def test_repr_html_of_result_and_scenario(shev):
    html = shev._repr_html_()
    assert len(html) < 20000
    assert "completed" in html and "Distance" in html and f"{shev.metrics['distance_km']:.4g}" in html
    assert "<script" not in html                  # a notebook shows it without JavaScript
    sc = shevsim.load_scenario("hd_udds_rule")
    h = sc._repr_html_()
    assert "<table>" in h and "engine_generator" in h
    assert "vehicle.speed_mps" in h and "→" in h   # connections shown source -> input


def test_plot_returns_a_figure_in_display_units(shev):
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure
    fig = shev.plot(["vehicle.speed_mps", "bus.battery_power_w", "battery.t_core_c"])
    try:
        assert isinstance(fig, Figure)
        labels = [a.get_ylabel() for a in fig.axes]
        assert labels == ["Vehicle speed (km/h)", "Battery power (+ discharge) (kW)", "Cell core temperature (°C)"]
        np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), shev["vehicle.speed_mps"] * 3.6)
        np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), shev["bus.battery_power_w"] / 1e3)
        assert fig.axes[-1].get_xlabel() == "Time (s)"
        default = shev.plot()                       # speed, power split, SOC, temperature
        assert isinstance(default, Figure) and len(default.axes) >= 3
    finally:
        plt.close("all")


def test_compare_plots_power_in_kw(shev):
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    heavy = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, "vehicle.mass_kg": 20000.0}, stop_s=60.0,
                             engine="python")
    fig = shevsim.compare([shev, heavy], "motor.elec_power_w")
    try:
        (ax,) = fig.axes
        assert ax.get_ylabel() == "Motor electric power (kW)"
        assert max(abs(y).max() for y in (line.get_ydata() for line in ax.lines)) < 1000   # kW, not 200000 W
        names = [line.get_label() for line in ax.lines]
        assert len(set(names)) == 2 and any("mass_kg=20000" in n for n in names)
    finally:
        plt.close("all")


def test_metrics_table_rows_are_distinct(shev):
    heavy = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, "vehicle.mass_kg": 20000.0}, stop_s=60.0,
                             engine="python")
    again = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=60.0, engine="python")
    tab = shevsim.metrics_table([shev, heavy, again], ["distance_km", "fuel_mass_g"])
    idx = list(tab.index)
    assert len(set(idx)) == 3, idx
    assert idx[1].startswith("hd_udds_rule (") and "vehicle.mass_kg=20000" in idx[1], idx   # what differs
    assert idx[0].startswith("hd_udds_rule (") and "vehicle.mass_kg=" in idx[0], idx
    assert idx[2] != idx[0]                                          # same parameters: numbered apart
    assert tab.attrs["units"]["fuel_mass_g"] == "g"
    assert tab.loc[idx[1], "fuel_mass_g"] > tab.loc[idx[0], "fuel_mass_g"]   # heavier: more fuel
    by_name = shevsim.metrics_table({"rule": shev, "heavy": heavy}, ["distance_km"])
    assert list(by_name.index) == ["rule", "heavy"]
    assert list(shevsim.metrics_table([shev, heavy], labels=["a", "b"]).index) == ["a", "b"]
    shev.meta["label"] = "light"
    try:
        assert list(shevsim.metrics_table([shev, heavy]).index) == ["light", "hd_udds_rule"]
    finally:
        del shev.meta["label"]
    with pytest.raises(ShevsimError, match="distinct"):
        shevsim.metrics_table([shev, heavy], labels=["x", "x"])


# ----------------------------------------------------------------------------------------- connections

def _bodies():
    sc = shevsim.new_scenario("two_body", step_s=0.01, stop_s=3.0)
    sc.add_component("body1", "mass_spring", set={"mass_kg": 1.0, "stiffness_n_per_m": 10.0, "x0_m": 1.0,
                                                  "v0_mps": 0.0})
    sc.add_component("coupling", "spring_damper", set={"mass_kg": 2.0, "stiffness_n_per_m": 5.0,
                                                       "damping_ns_per_m": 0.5, "x0_m": 0.0, "v0_mps": 0.0})
    return sc


def test_connect_source_first_and_by_keyword_equal_the_toml_scenario():
    sc = _bodies()
    with warnings.catch_warnings():
        warnings.simplefilter("error")               # neither form warns
        sc.connect("coupling.force_n", "body1.force_n")
        sc.connect(src="body1.position_m", dst="coupling.position_m")
        sc.connect("body1.velocity_mps", "coupling.velocity_mps")
    code = shevsim.simulate(sc)
    toml = shevsim.simulate(TWO_BODY, stop_s=3.0)
    for s in toml.signals:
        np.testing.assert_array_equal(code[s], toml[s], err_msg=s)


def test_connect_wrong_direction_is_caught_when_made():
    sc = _bodies()
    with pytest.raises(ScenarioError, match=r"wrong direction: the source 'coupling.position_m' is an input.*"
                                            r"did you mean connect\(src='body1.position_m', dst='coupling.position_m'\)"):
        sc.connect(src="coupling.position_m", dst="body1.position_m")
    with pytest.raises(ScenarioError, match="both ends are inputs"):
        sc.connect("body1.force_n", "coupling.position_m")
    with pytest.raises(ScenarioError, match="both ends are outputs"):
        sc.connect("body1.position_m", "coupling.force_n")
    with pytest.raises(ScenarioError, match=r"component 'body1' has no port 'forc_n' \(did you mean 'force_n'"):
        sc.connect("coupling.force_n", "body1.forc_n")
    with pytest.raises(ScenarioError, match="either by position"):
        sc.connect("coupling.force_n", dst="body1.force_n")
    assert sc.connections == []                      # nothing half-added


def test_connect_old_input_first_order_still_works_with_a_warning():
    sc = _bodies()
    with pytest.warns(DeprecationWarning, match=r"give the source first.*connect\('coupling.force_n', 'body1.force_n'\)"):
        sc.connect("body1.force_n", "coupling.force_n")          # input first: unambiguous from the ports
    (c,) = sc.connections
    assert (c.src, c.src_port, c.dst, c.dst_port) == ("coupling", "force_n", "body1", "force_n")


# ----------------------------------------------------------------------------------------- FMUs from the API

def test_add_component_fmu_argument_checks(tmp_path):
    sc = shevsim.new_scenario("s", step_s=0.1, stop_s=1.0)
    with pytest.raises(ScenarioError, match="needs fmu=PATH"):
        sc.add_component("v", "fmu")
    with pytest.raises(ScenarioError, match="fmu file '.*nope.fmu' not found"):
        sc.add_component("v", "fmu", fmu=tmp_path / "nope.fmu")
    with pytest.raises(ScenarioError, match="only for type='fmu'"):
        sc.add_component("v", "vehicle", fmu=tmp_path / "x.fmu")
    assert sc.components == []


@pytest.mark.fmu
def test_fmu_added_from_the_api_runs_and_matches_the_closed_form(tmp_path):
    pytest.importorskip("fmpy")
    pytest.importorskip("pythonfmu")
    from shevsim.fmu.build import build_python_fmu, fmu_sources_dir
    fmu = build_python_fmu(fmu_sources_dir() / "py_mass_drag" / "py_mass_drag.py", tmp_path / "mass.fmu", 2)
    m, b, v0, f = 1500.0, 60.0, 3.0, 1200.0
    sc = shevsim.new_scenario("fmu_in_code", step_s=0.2, stop_s=10.0)
    sc.add_component("v", "fmu", fmu=fmu, mapping={"force_n": "traction_force_n"},
                     set={"mass_kg": m, "damping_ns_m": b, "v0_mps": v0}, start={"traction_force_n": f})
    assert sc.ports("v")["traction_force_n"] == "input" and sc.ports("v")["speed_mps"] == "output"
    sc.add_component("g", "gain", set={"gain": 3.6})   # pythonfmu writes no units: a dimensionless input
    with pytest.raises(ScenarioError, match="wrong direction: the source 'g.in_1' is an input"):
        sc.connect(src="g.in_1", dst="v.speed_mps")
    sc.connect("v.speed_mps", "g.in_1")                             # FMU output -> native input
    res = shevsim.simulate(sc)
    assert res.termination.ok
    tau = m / b
    expect = f / b + (v0 - f / b) * np.exp(-res.time_s / tau)      # v(t) under a constant force
    np.testing.assert_allclose(res["v.speed_mps"], expect, rtol=1e-10)
    np.testing.assert_allclose(res["g.out_1"], 3.6 * res["v.speed_mps"], rtol=1e-12)   # (Gauss-Seidel: same step)
    back = shevsim.load_scenario(_write(tmp_path, sc.to_toml()))               # written out and read back
    assert back.component("v").fmu == Path(fmu).resolve() and back.component("v").mapping == {"force_n": "traction_force_n"}


def _write(folder, text):
    p = folder / "s.toml"
    p.write_text(text)
    return p


# ----------------------------------------------------------------------------------------- study and calibration objects

def test_study_and_calibration_objects_show_html_and_write_the_report(tmp_path):
    from shevsim.calibrate.synthetic import synth_vehicle
    st = shevsim.run_study("tradeoff", synthetic=True, workers=0, rates_kwps=[30, 10])
    h = st._repr_html_()
    assert "<script" not in h and "Baseline fuel economy (km/l)" in h and "Chosen rate limit (kW/s)" in h
    page = st.to_html(tmp_path / "study.html").read_text()
    assert '<meta name="shevsim-figures" content="2">' in page and "Maximum engine-generator power rate" in page
    df, _ = synth_vehicle({"regen_limit": {}}, seed=7, duration_s=300.0)
    df.to_csv(tmp_path / "veh.csv", index=False)
    cal = shevsim.run_calibration("vehicle", tmp_path / "veh.csv")
    h = cal._repr_html_()
    assert "<script" not in h and "Power (kW)" in h and "veh.csv" in h
    text = cal.to_html()
    assert '<meta name="shevsim-figures" content="3">' in text and "Fit before and after" in text
