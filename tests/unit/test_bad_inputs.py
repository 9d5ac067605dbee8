"""Bad inputs to the core: each gets a clear error that names the file/field or component/port/time."""
from pathlib import Path

import pytest

from shevsim.core.errors import AlgebraicLoopError, ConnectionError_, ScenarioError, SimulationError
from shevsim.core.scenario import build_master, load_scenario, stop_time

GOOD = """
[scenario]
name = "t"
step_s = 0.01
stop_s = 0.1

[components.body1]
type = "mass_spring"

[components.coupling]
type = "spring_damper"

[connections]
"body1.force_n" = "coupling.force_n"
"coupling.position_m" = "body1.position_m"
"coupling.velocity_mps" = "body1.velocity_mps"
"""


def load(text, tmp_path, name="s.toml", sets=()):
    p = tmp_path / name
    p.write_text(text)
    return load_scenario(p, list(sets))


def build(text, tmp_path, **kw):
    sc = load(text, tmp_path, **kw)
    return sc, build_master(sc)


def test_good_scenario_runs(tmp_path):
    sc, m = build(GOOD, tmp_path)
    r = m.run(stop_time(sc, m))
    assert len(r.time_s) == 11


def test_malformed_toml_names_file(tmp_path):
    with pytest.raises(ScenarioError, match=r"s\.toml: malformed TOML"):
        load(GOOD + "\n[components.x\n", tmp_path)


def test_unknown_top_level_key_suggests(tmp_path):
    with pytest.raises(ScenarioError, match=r"unknown key 'conections' \(did you mean 'connections'\?\)"):
        load(GOOD + '\n[conections]\n"a.b" = "c.d"\n', tmp_path)


def test_unknown_component_type(tmp_path):
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_dampr"')
    with pytest.raises(ScenarioError, match=r"\[components.coupling\]: unknown component type 'spring_dampr' "
                                            r"\(did you mean 'spring_damper'\?\)"):
        build(bad, tmp_path)


def test_unknown_component_in_connection(tmp_path):
    bad = GOOD.replace('"body1.force_n" = "coupling.force_n"', '"body1.force_n" = "couplng.force_n"')
    with pytest.raises(ScenarioError, match=r"unknown component 'couplng' \(did you mean 'coupling'\?\)"):
        load(bad, tmp_path)


def test_unknown_port(tmp_path):
    bad = GOOD.replace('"body1.force_n" = "coupling.force_n"', '"body1.force_n" = "coupling.forc_n"')
    with pytest.raises(ConnectionError_, match=r"component 'coupling' has no output 'forc_n' \(did you mean 'force_n'\?\)"):
        build(bad, tmp_path)


def test_unit_mismatch(tmp_path):
    bad = GOOD.replace('"coupling.position_m" = "body1.position_m"', '"coupling.position_m" = "body1.velocity_mps"')
    bad = bad.replace('"coupling.velocity_mps" = "body1.velocity_mps"', '"coupling.velocity_mps" = "body1.position_m"')
    # the message names both ends and both units (wording of the unit checker may vary)
    with pytest.raises(ConnectionError_, match=r"(?s)body1.velocity_mps.*coupling.position_m.*unit mismatch.*'m/s'.*'m'"
                                               r"|unit mismatch, output body1.velocity_mps is in 'm/s' but input "
                                               r"coupling.position_m expects 'm'"):
        build(bad, tmp_path)


def test_component_constructor_exception_names_component(tmp_path, monkeypatch):
    """An exception in a component's own construction code keeps its message and names the component."""
    from shevsim.components.verification import Gain

    def boom(self, *a, **k):
        raise ValueError("table row 3 is bad")
    monkeypatch.setattr(Gain, "__init__", boom)
    text = '[scenario]\nstep_s = 0.1\nstop_s = 1.0\n[components.a]\ntype = "gain"\nstart = { in_1 = 1.0 }\n'
    with pytest.raises(ScenarioError, match=r"\[components.a\]: component 'a' \(type 'gain'\) could not be built: "
                                            r"ValueError: table row 3 is bad"):
        build(text, tmp_path)


def test_input_connected_twice(tmp_path):
    text = """
[scenario]
stop_s = 1
[components.a]
type = "gain"
[components.b]
type = "gain"
[components.c]
type = "gain"
[connections]
"c.in_1" = "a.out_1"
"""
    sc = load(text, tmp_path)
    from shevsim.core import Connection
    sc.connections.append(Connection.parse("c.in_1", "b.out_1"))
    with pytest.raises(ConnectionError_, match=r"input c.in_1 is already connected to a.out_1"):
        build_master(sc)


def test_algebraic_loop_names_every_port(tmp_path):
    text = """
[scenario]
stop_s = 1
[components.a]
type = "gain"
[components.b]
type = "gain"
[connections]
"a.in_1" = "b.out_1"
"b.in_1" = "a.out_1"
"""
    with pytest.raises(AlgebraicLoopError) as ei:
        build(text, tmp_path)
    msg = str(ei.value)
    for port in ("a.in_1", "a.out_1", "b.in_1", "b.out_1"):
        assert port in msg
    assert "algebraic loop" in msg


def test_bad_step_ratio(tmp_path):
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_damper"\nstep_multiple = 1.5')
    with pytest.raises(ScenarioError, match=r"\[components.coupling\]: field 'step_multiple' must be an integer >= 1"):
        load(bad, tmp_path)


def test_missing_parameter_file(tmp_path):
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_damper"\nparams = "components/nowhere.toml"')
    with pytest.raises(ScenarioError, match=r"field 'params': parameter file 'components/nowhere.toml' not found"):
        load(bad, tmp_path)


def test_unknown_parameter_suggests(tmp_path):
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_damper"\nset = { stifness_n_per_m = 3.0 }')
    with pytest.raises(ScenarioError, match=r"unknown parameter 'stifness_n_per_m' for SpringDamperParams "
                                            r"\(did you mean 'stiffness_n_per_m'\?\)"):
        build(bad, tmp_path)


def test_wrong_parameter_type(tmp_path):
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_damper"\nset = { mass_kg = "heavy" }')
    with pytest.raises(ScenarioError, match=r"parameter 'mass_kg': expected a number, got 'heavy'"):
        build(bad, tmp_path)


def test_parameter_file_unknown_key(tmp_path):
    pf = tmp_path / "sd.toml"
    pf.write_text("[params]\nmass_kg = 2.0\ndamping_n_s_per_m = 1.0\n")
    bad = GOOD.replace('type = "spring_damper"', f'type = "spring_damper"\nparams = "{pf}"')
    with pytest.raises(ScenarioError, match=r"sd.toml: unknown parameter 'damping_n_s_per_m'.*did you mean 'damping_ns_per_m'"):
        build(bad, tmp_path)


def test_set_override_unknown_component(tmp_path):
    with pytest.raises(ScenarioError, match=r"--set 'bdy1.mass_kg=2': unknown component 'bdy1' \(did you mean 'body1'\?\)"):
        load(GOOD, tmp_path, sets=["bdy1.mass_kg=2"])


def test_set_override_applies(tmp_path):
    sc, m = build(GOOD, tmp_path, sets=["body1.mass_kg=2.5"])
    assert m.components["body1"].params.mass_kg == 2.5


def test_fault_on_unknown_port(tmp_path):
    bad = GOOD + '\n[[faults]]\nat_s = 0.05\nport = "body1.forc_n"\nvalue = 1.0\n'
    with pytest.raises(ConnectionError_, match=r"fault at 0.05 s: component 'body1' has no input 'forc_n'"):
        build(bad, tmp_path)


def test_fault_forces_input_from_its_time(tmp_path):
    text = """
[scenario]
step_s = 0.1
stop_s = 1.0
[components.a]
type = "gain"
start = { in_1 = 1.0 }
[components.b]
type = "gain"
[connections]
"b.in_1" = "a.out_1"
[[faults]]
at_s = 0.5
port = "b.in_1"
value = 7.0
"""
    sc, m = build(text, tmp_path)
    r = m.run(stop_time(sc, m))
    y = r["b.out_1"]
    assert y[4] == 1.0 and y[6] == 7.0 and y[-1] == 7.0


def test_nan_at_runtime_names_component_port_time(tmp_path):
    text = """
[scenario]
step_s = 0.1
stop_s = 1.0
[components.a]
type = "gain"
start = { in_1 = nan }
"""
    # (an infinite gain, the old trigger, is now refused before the run by the parameter ranges)
    sc, m = build(text, tmp_path)
    with pytest.raises(SimulationError, match=r"component 'a' output 'out_1' is nan at t=0 s"):
        m.run(stop_time(sc, m))
    with pytest.raises(ScenarioError, match=r"parameter 'gain' = inf: inf is not allowed"):
        build(text.replace("start = { in_1 = nan }", "start = { in_1 = 0.0 }\nset = { gain = inf }"), tmp_path)


def test_component_exception_names_component_and_time(tmp_path):
    # substeps = 0 (the old trigger) is now refused before the run: the component's code is made to fail instead
    bad = GOOD.replace('type = "mass_spring"', 'type = "mass_spring"\nset = { substeps = 0 }')
    with pytest.raises(ScenarioError, match=r"parameter 'substeps' = 0: out of range; valid range: >= 1"):
        build(bad, tmp_path)
    sc, m = build(GOOD, tmp_path)
    m.components["body1"].do_step = lambda t, dt: 1.0 / 0.0
    with pytest.raises(SimulationError, match=r"component 'body1' failed in do_step at t=0 s \(step 0\): ZeroDivisionError"):
        m.run(stop_time(sc, m))


def test_missing_stop_time(tmp_path):
    bad = GOOD.replace("stop_s = 0.1\n", "")
    sc, m = build(bad, tmp_path)
    with pytest.raises(ScenarioError, match=r"needs 'stop_s'"):
        stop_time(sc, m)


def test_bad_method(tmp_path):
    bad = GOOD.replace("step_s = 0.01", 'step_s = 0.01\nmethod = "gauss"')
    with pytest.raises(ScenarioError, match=r"method must be 'gauss-seidel' or 'jacobi'"):
        load(bad, tmp_path)


# --------------------------------------------------------------- bug hunt (core), 2026-11-22
@pytest.mark.parametrize("field, value", [("stop_s", "nan"), ("stop_s", "inf"), ("t0_s", "nan"),
                                          ("t0_s", "-inf"), ("stop_s", "-1.0"), ("stop_s", "0.0")])
def test_bad_stop_or_start_time_names_the_field(tmp_path, field, value):
    text = GOOD.replace("stop_s = 0.1", "stop_s = 0.1" if field == "t0_s" else f"stop_s = {value}")
    if field == "t0_s":
        text = text.replace("step_s = 0.01", f"step_s = 0.01\nt0_s = {value}")
    with pytest.raises(ScenarioError, match=rf"s.toml: \[scenario\] field '{field}'"):
        load(text, tmp_path)


def test_record_unknown_signal_fails_before_running_and_names_file_field(tmp_path):
    from shevsim.run import simulate
    text = GOOD + '\n[record]\nsignals = ["body1.position_m", "body1.positon_m"]\n'
    sc = load(text, tmp_path)
    with pytest.raises(ScenarioError, match=r"s.toml: \[record\] field 'signals': unknown signal "
                                            r"'body1.positon_m' \(did you mean 'body1.position_m'\?\)"):
        build_master(sc)
    with pytest.raises(ScenarioError, match=r"s.toml: \[record\]"):
        simulate(sc)


def test_set_file_override_is_relative_to_cwd_not_to_the_params_file(tmp_path, monkeypatch):
    # `--set cycle.cycle_file=cycles/x.csv` typed at the project root names cycles/x.csv from there,
    # not components/cycle/cycles/x.csv (the params file's folder)
    from shevsim.components.cycle import CycleParams  # noqa: F401  (registry type 'cycle')
    root = Path(__file__).resolve().parents[2]
    monkeypatch.chdir(root)
    params = tmp_path / "p" / "cycle.toml"
    params.parent.mkdir()
    params.write_text(f'[params]\ncycle_file = "{root / "cycles" / "hd_udds.csv"}"\n')
    text = f"""
[scenario]
stop_s = 1.0
[components.cycle]
type = "cycle"
params = "{params}"
"""
    sc = load(text, tmp_path, sets=["cycle.cycle_file=cycles/uac_proxy.csv"])
    m = build_master(sc)
    assert Path(m.components["cycle"].params.cycle_file) == root / "cycles" / "uac_proxy.csv"
    # in the scenario's own `set` table the path is relative to the scenario file
    (tmp_path / "c.csv").write_bytes((root / "cycles" / "uac_proxy.csv").read_bytes())
    sc = load(text.replace('params = ', 'set = { cycle_file = "c.csv" }\nparams = '), tmp_path)
    assert Path(build_master(sc).components["cycle"].params.cycle_file) == (tmp_path / "c.csv").resolve()


@pytest.mark.parametrize("old, new, msg", [
    ('name = "t"', 'name = 5', r"\[scenario\] field 'name' must be a string"),
    ('type = "mass_spring"', 'type = 5', r"\[components.body1\]: field 'type' must be a string"),
    ('type = "mass_spring"', 'type = "fmu"\nfmu = 3', r"\[components.body1\]: field 'fmu' must be a file path string"),
    ('stop_s = 0.1', 'stop_s = 0.1\norder = ["body1", "body1", "coupling"]',
     r"\[scenario\] field 'order' must list every component exactly once \(repeated: \['body1'\]\)"),
])
def test_wrong_field_types_name_file_and_field(tmp_path, old, new, msg):
    with pytest.raises(ScenarioError, match=r"s.toml: " + msg):
        load(GOOD.replace(old, new), tmp_path)


def test_fault_time_must_be_finite(tmp_path):
    bad = GOOD + '\n[[faults]]\nat_s = nan\nport = "body1.force_n"\nvalue = 1.0\n'
    with pytest.raises(ScenarioError, match=r"s.toml: \[\[faults\]\] #1: field 'at_s' must be a finite number"):
        load(bad, tmp_path)


def test_start_time_after_the_natural_stop_time(tmp_path):
    text = f"""
[scenario]
t0_s = 5000.0
[components.cycle]
type = "cycle"
"""
    sc = load(text, tmp_path)
    with pytest.raises(ScenarioError, match=r"s.toml: \[scenario\] field 't0_s' \(5000.0 s\) is not before the stop"):
        stop_time(sc, build_master(sc))


def test_params_table_that_is_not_a_table(tmp_path):
    pf = tmp_path / "p.toml"
    pf.write_text("params = 5\n")
    bad = GOOD.replace('type = "mass_spring"', f'type = "mass_spring"\nparams = "{pf}"')
    with pytest.raises(ScenarioError, match=r"p.toml: \[params\] must be a table"):
        build(bad, tmp_path)


def test_start_value_on_a_connected_input_is_an_error(tmp_path):
    # the connection overwrites the start value before initialize(): it would be silently ignored
    bad = GOOD.replace('type = "spring_damper"', 'type = "spring_damper"\nstart = { position_m = 0.5 }')
    with pytest.raises(ScenarioError, match=r"s.toml: \[components.coupling\] field 'start.position_m': the input is "
                                            r"connected to body1.position_m"):
        build(bad, tmp_path)
