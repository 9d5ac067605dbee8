"""Model exchange, FMI 3 arrays, integer/Boolean ports, string refusal and unit conversion on connections.

FMUs are compiled by the test session from the vendored Modelica Reference-FMUs sources
(``fmus/src/reference_fmus``, BSD-2) with fmpy's cmake build helper (:func:`build_reference_fmu`):

* ``BouncingBall`` (FMI 2 and 3, model exchange only): state events with a state reset;
* ``StateSpace`` (FMI 3, model exchange only): array parameters A, B, C, D, x0, array input u and
  array output y, all of size 3;
* ``Feedthrough`` (FMI 3 co-simulation): every FMI 3 type; with String/Binary left out of the model
  description it has Float32, integer, Boolean and Enumeration ports.

References are closed-form solutions written here, independent of the FMUs.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from shevsim.core.component import Component  # noqa: E402
from shevsim.core.errors import ConnectionError_  # noqa: E402
from shevsim.core.master import Connection, Master, MasterSettings  # noqa: E402
from shevsim.core.units import conversion, resolve_unit  # noqa: E402
from shevsim.core.variables import inp, out  # noqa: E402
from shevsim.fmu import FMUComponent, FMUMappingError, FMUUnsupportedError  # noqa: E402
from shevsim.fmu.build import build_c_fmu, build_reference_fmu, fmu_sources_dir  # noqa: E402

pytestmark = pytest.mark.fmu

G = 9.81        # BouncingBall: g = -9.81 m/s2, e = 0.7, h0 = 1 m, v0 = 0
E = 0.7


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fmus_me")


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def ball(request, fmu_dir):
    v = request.param
    return build_reference_fmu("BouncingBall", fmu_dir / f"ball{v}.fmu", v, interfaces=("me",))


@pytest.fixture(scope="module")
def statespace(fmu_dir):
    return build_reference_fmu("StateSpace", fmu_dir / "statespace.fmu", 3, interfaces=("me",))


@pytest.fixture(scope="module")
def feedthrough(fmu_dir):
    return build_reference_fmu("Feedthrough", fmu_dir / "feedthrough.fmu", 3, interfaces=("cs",),
                               drop_types=("String", "Binary"))


@pytest.fixture(scope="module")
def rc_fmu(fmu_dir):
    return build_c_fmu(fmu_sources_dir() / "rc_thermal", fmu_dir / "rc_thermal.fmu")


def ball_height(t: float) -> float:
    """Closed-form height of the bouncing ball (bounces lose speed by E; no stop within 2 s)."""
    t1 = math.sqrt(2.0 / G)
    if t < t1:
        return 1.0 - 0.5 * G * t * t
    tb, v = t1, E * G * t1
    while True:
        flight = 2.0 * v / G
        if t < tb + flight:
            s = t - tb
            return v * s - 0.5 * G * s * s
        tb, v = tb + flight, v * E


def run_steps(comp, n, h, t0=0.0, inputs=None):
    comp.initialize(t0)
    out_rows = []
    for k in range(n):
        if inputs:
            for port, seq in inputs.items():
                comp.u[port] = seq[k]
        comp.do_step(t0 + k * h, h)
        out_rows.append(dict(comp.y))
    return out_rows


# ------------------------------------------------------------------ model exchange
@pytest.mark.parametrize("solver, tol, atol", [("cvode", 1e-9, 1e-6), ("RK45", 1e-9, 1e-8), ("BDF", 1e-9, 1e-5)])
def test_model_exchange_bouncing_ball_matches_closed_form(ball, solver, tol, atol):
    comp = FMUComponent("ball", ball, solver=solver, tolerance=tol)
    assert comp.kind == "me"
    h, n = 0.01, 200         # 2 s: four bounces (state events with a reset of v), at 0.45, 1.08, 1.53, 1.84 s
    rows = run_steps(comp, n, h)
    err = max(abs(r["h"] - ball_height((k + 1) * h)) for k, r in enumerate(rows))
    assert err < atol, f"max |h - closed form| = {err:.3g} m with {solver}"
    # the events really happened: v jumped from falling to rising four times
    signs = np.sign([r["v"] for r in rows])
    assert np.count_nonzero(np.diff(signs) > 0) == 4
    comp.terminate()


def test_model_exchange_tolerance_is_honoured(ball):
    errs = []
    for tol in (1e-4, 1e-10):
        comp = FMUComponent("ball", ball, tolerance=tol)
        rows = run_steps(comp, 100, 0.01)
        errs.append(max(abs(r["h"] - ball_height((k + 1) * 0.01)) for k, r in enumerate(rows)))
        comp.terminate()
    assert errs[1] < errs[0] / 100, errs


def test_model_exchange_bad_solver_and_interface(ball):
    with pytest.raises(FMUMappingError, match="solver 'rk4' is not one of"):
        FMUComponent("ball", ball, solver="rk4")
    with pytest.raises(FMUUnsupportedError, match="no co-simulation interface"):
        FMUComponent("ball", ball, interface="cs")


def test_model_exchange_save_restore_replays(ball):
    comp = FMUComponent("ball", ball, tolerance=1e-9)
    comp.initialize(0.0)
    for k in range(30):
        comp.do_step(k * 0.01, 0.01)
    snap = comp.get_state()
    first = []
    for k in range(30, 80):
        comp.do_step(k * 0.01, 0.01)
        first.append(comp.y["h"])
    comp.set_state(snap)
    again = []
    for k in range(30, 80):
        comp.do_step(k * 0.01, 0.01)
        again.append(comp.y["h"])
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-9)
    comp.terminate()


# ------------------------------------------------------------------ FMI 3 arrays (model exchange, inputs)
def test_fmi3_array_variables_are_ports_and_match_closed_form(statespace):
    # x' = A x + B u, y = C x + D u with A = -2 I, B = diag(1, 3, 1), C = I, D = 0: three first-order lags
    eye = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]
    comp = FMUComponent("ss", statespace, tolerance=1e-10,
                        parameters={"A": [-2.0 * x for x in eye], "D": [0.0] * 9, "B[2,2]": 3.0})
    names = [v.name for v in comp.variables() if v.causality in ("input", "output")]
    assert names == ["u[1]", "u[2]", "u[3]", "y[1]", "y[2]", "y[3]"]
    h, n = 0.05, 60
    rng = np.random.default_rng(4)
    u = {f"u[{i}]": np.repeat(rng.uniform(-3, 3, n // 10), 10) for i in (1, 2, 3)}
    rows = run_steps(comp, n, h, inputs=u)
    x = np.zeros(3)
    b = np.array([1.0, 3.0, 1.0])       # diagonal of B (element B[2,2] set alone)
    a = math.exp(-2.0 * h)
    for k, r in enumerate(rows):        # exact zero-order-hold step of x' = -2 x + B u
        uk = np.array([u[f"u[{i}]"][k] for i in (1, 2, 3)])
        x = a * x + (1 - a) * b * uk / 2.0
        np.testing.assert_allclose([r["y[1]"], r["y[2]"], r["y[3]"]], x, rtol=0, atol=1e-7)
    comp.terminate()


def test_array_element_mapping_and_parameter_errors(statespace):
    comp = FMUComponent("ss", statespace, mapping={"y": "out"})
    assert [v.name for v in comp.outputs()] == ["out[1]", "out[2]", "out[3]"]
    comp.terminate()
    with pytest.raises(FMUMappingError, match="'A' has 9 elements, got 2 values"):
        c = FMUComponent("ss", statespace, parameters={"A": [1.0, 2.0]})
        c.initialize(0.0)


# ------------------------------------------------------------------ integer / Boolean / strings
def test_integer_boolean_float32_ports_round_trip(feedthrough):
    comp = FMUComponent("ft", feedthrough)
    ins = {"Int32_input": -123456.0, "UInt8_input": 200.0, "Int64_input": 2.0 ** 40, "Boolean_input": 1.0,
           "Float32_continuous_input": 0.25, "Enumeration_input": 2.0, "Float64_continuous_input": math.pi}
    for k, v in ins.items():
        comp.u[k] = v
    comp.initialize(0.0)
    comp.do_step(0.0, 0.1)
    for k, v in ins.items():
        assert comp.y[k.replace("_input", "_output")] == v, k
    comp.u["Boolean_input"] = 0.0
    comp.do_step(0.1, 0.1)
    assert comp.y["Boolean_output"] == 0.0
    comp.terminate()


def test_string_and_binary_variables_are_settable_values_not_ports(fmu_dir):
    """Issue 26: an FMU with String/Binary inputs is accepted; they are listed, their start values set (the
    reference Feedthrough FMU copies them to its String/Binary outputs, read back with fmpy's getters), and
    they are not ports."""
    p = build_reference_fmu("Feedthrough", fmu_dir / "feedthrough_all.fmu", 3, interfaces=("cs",))
    comp = FMUComponent("ft", p, parameters={"String_input": "hello", "Binary_input": "0a0b0c"})
    try:
        vv = comp.value_variables
        assert vv["String_input"]["type"] == "String" and vv["String_input"]["causality"] == "input"
        assert vv["Binary_input"]["type"] == "Binary" and "String_output" in vv
        assert not {"String_input", "Binary_input", "String_output"} & {v.name for v in comp.variables()}
        comp.initialize(0.0)
        comp.do_step(0.0, 0.1)
        vr = {v.name: v.valueReference for v in comp.model_description.modelVariables}
        assert comp.fmu.getString([vr["String_output"]]) == ["hello"]
        assert comp.fmu.getBinary([vr["Binary_output"]]) == [b"\x0a\x0b\x0c"]
        assert "String_input" in comp.not_connectable("String_input") and comp.not_connectable("Float64_input") is None
    finally:
        comp.terminate()


# ------------------------------------------------------------------ units on connections
class _Src(Component):
    """Test source: output ``p`` = ramp in the unit given at construction."""

    TYPE = "test_src"

    def __init__(self, name, unit, scale):
        self.VARIABLES = (out("p", unit, 0.0, "ramp"),)
        self._scale = scale
        super().__init__(name, None)

    def variables(self):
        return self.VARIABLES

    def initialize(self, t0):
        self.y["p"] = 0.0

    def do_step(self, t, h):
        self.y["p"] = self._scale * (3.0 + math.sin(t + h))


class _Sink(Component):
    """Test sink: integrates its input (unit given at construction) into ``e``."""

    TYPE = "test_sink"

    def __init__(self, name, unit):
        self.VARIABLES = (inp("x", unit, 0.0, "input"), out("e", "1", 0.0, "integral of x"))
        super().__init__(name, None)

    def variables(self):
        return self.VARIABLES

    def initialize(self, t0):
        self.y["e"] = 0.0

    def do_step(self, t, h):
        self.y["e"] += self.u["x"] * h


def _run(src, sink, n=50):
    m = Master([src, sink], [Connection("src", "p", "sink", "x")], MasterSettings(step_s=0.1))
    return m.run(n * 0.1)


def test_kw_to_w_connection_equals_unconverted_reference():
    ref = _run(_Src("src", "W", 1000.0), _Sink("sink", "W"))
    conv = _run(_Src("src", "kW", 1.0), _Sink("sink", "W"))
    e_ref = np.asarray(ref.signals["sink.e"])
    e_conv = np.asarray(conv.signals["sink.e"])
    assert e_ref[-1] > 1000.0
    np.testing.assert_allclose(e_conv, e_ref, rtol=1e-14, atol=0)


def test_degc_fmu_output_to_kelvin_input_uses_the_fmu_unit_definition(rc_fmu):
    # rc_thermal declares <Unit name="degC"><BaseUnit K="1" offset="273.15"/></Unit>
    def system(sink_unit):
        fmu = FMUComponent("rc", rc_fmu, start_values={"heat_w": 800.0})
        sink = _Sink("sink", sink_unit)
        m = Master([fmu, sink], [Connection("rc", "t_c", "sink", "x")], MasterSettings(step_s=0.5))
        res = m.run(20.0)
        m.terminate()
        return np.asarray(res.signals["sink.e"]), np.asarray(res.signals["rc.t_c"])
    assert resolve_unit("degC", {})[2] == 273.15
    e_k, t_c = system("K")
    e_c, t_c2 = system("degC")
    np.testing.assert_array_equal(t_c, t_c2)
    # the K integral is the degC integral plus 273.15 K x elapsed time (each step adds x h)
    elapsed = 0.5 * np.arange(len(e_k))
    np.testing.assert_allclose(e_k, e_c + 273.15 * elapsed, rtol=1e-13, atol=1e-9)


def test_incompatible_dimensions_stay_an_error():
    with pytest.raises(ConnectionError_, match="different dimensions"):
        _run(_Src("src", "kW", 1.0), _Sink("sink", "K"))
    with pytest.raises(ConnectionError_, match="unknown"):
        _run(_Src("src", "furlong", 1.0), _Sink("sink", "m"))


def test_unit_table_conversions():
    assert conversion("km/h", "m/s") == pytest.approx((1 / 3.6, 0.0))
    assert conversion("K", "degC") == pytest.approx((1.0, -273.15))
    assert conversion("rpm", "rad/s") == pytest.approx((2 * math.pi / 60, 0.0))
    assert conversion("W", "w") is None

    class _Def:                        # an FMU's own unit: 1 myW = 1000 W
        class baseUnit:
            kg, m, s, factor, offset = 1, 2, -3, 1000.0, 0.0
    assert conversion("myW", "W", {"myW": _Def}, None) == pytest.approx((1000.0, 0.0))


def test_unit_case_is_never_folded():
    """Case carries the SI prefix: mS (millisiemens) is not ms, H (henry) not h, T (tesla) not t, Mm not mm."""
    for src, dst in (("mS", "s"), ("H", "s"), ("T", "kg"), ("Mm", "m"), ("MS", "s")):
        with pytest.raises(ValueError, match="unknown"):
            conversion(src, dst)
    assert conversion("ohm", "mOhm") == pytest.approx((1000.0, 0.0))     # a listed alias
    assert conversion("Hz", "1/s") is None


# ------------------------------------------------------------------ shevsim info
def test_info_says_what_is_supported(statespace, fmu_dir, ball):
    from shevsim.fmu.info import fmu_info
    text = fmu_info(statespace)
    assert "shevsim support (usable; 6 ports)" in text
    assert "input 'u' (array 3 of Float64): 3 ports u[1] ... u[3]" in text
    assert "model exchange: used" in text
    p = build_reference_fmu("Feedthrough", fmu_dir / "feedthrough_info.fmu", 3, interfaces=("cs",))
    text = fmu_info(p)
    assert "shevsim support (usable" in text
    assert "input 'String_input' (String" in text and "connecting it is refused" in text


def test_cli_info_lists_delayed_connections(capsys):
    from shevsim.cli import main
    assert main(["info", "hd_udds_rule"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("delayed connections"))
    # the limits held within the step (issue 14): motor_limits runs before the generator, so it takes
    # the generator's power of the previous step
    assert "engine_generator.elec_power_w -> motor_limits.gen_power_w" in line


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_model_exchange_time_events(fmu_dir, fmi_version):
    # Reference-FMUs Stair: counter = 1 at t = 0, +1 at every whole second (time events), and the FMU
    # requests termination when it reaches 10 (t = 9 s)
    p = build_reference_fmu("Stair", fmu_dir / f"stair{fmi_version}.fmu", fmi_version, interfaces=("me",))
    for solver in ("cvode", "RK45"):
        comp = FMUComponent("stair", p, solver=solver)
        rows = run_steps(comp, 34, 0.25)                  # to 8.5 s
        assert [r["counter"] for r in rows] == [1 + math.floor((k + 1) * 0.25 + 1e-9) for k in range(34)]
        with pytest.raises(Exception, match="requested terminateSimulation"):
            for k in range(34, 40):
                comp.do_step(k * 0.25, 0.25)
        comp.terminate()


def test_fmi3_arrays_through_co_simulation(fmu_dir):
    # same state space, co-simulation interface: the FMU integrates with its own forward Euler
    # (fixed 1e-3 s steps), so it agrees with the closed form to the Euler error (~h/2 |x''| t < 1e-3)
    p = build_reference_fmu("StateSpace", fmu_dir / "statespace_cs.fmu", 3, interfaces=("cs",))
    eye = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]
    comp = FMUComponent("ss", p, parameters={"A": [-2.0 * x for x in eye], "D": [0.0] * 9})
    assert comp.kind == "cs"
    rows = run_steps(comp, 20, 0.05, inputs={f"u[{i}]": [float(i)] * 20 for i in (1, 2, 3)})
    exact = [i / 2.0 * (1.0 - math.exp(-2.0)) for i in (1, 2, 3)]
    np.testing.assert_allclose([rows[-1][f"y[{i}]"] for i in (1, 2, 3)], exact, rtol=0, atol=1e-3)
    comp.terminate()
