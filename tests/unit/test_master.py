"""Verification of the co-simulation master against a two-body system with a known answer."""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from shevsim.core import Master, MasterSettings
from shevsim.core.scenario import build_master, load_scenario, stop_time

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


def exact_x1(t, m1=1.0, k1=10.0, m2=2.0, k=5.0, c=0.5, x10=1.0):
    A = np.array([[0, 1, 0, 0],
                  [-(k1 + k) / m1, -c / m1, k / m1, c / m1],
                  [0, 0, 0, 1],
                  [k / m2, c / m2, -k / m2, -c / m2]])
    x0 = np.array([x10, 0, 0, 0])
    return np.array([(expm(A * ti) @ x0)[0] for ti in t])


def run_two_body(step, method):
    sc = load_scenario(TWO_BODY, [])
    sc.settings.step_s = step
    sc.settings.method = method
    m = build_master(sc)
    return m.run(stop_time(sc, m))


@pytest.mark.parametrize("method", ["gauss-seidel", "jacobi"])
def test_two_body_converges_first_order(method):
    steps = [0.02, 0.01, 0.005]
    errs = []
    for h in steps:
        r = run_two_body(h, method)
        x1 = r["body1.position_m"]
        errs.append(np.max(np.abs(x1 - exact_x1(r.time_s))))
    orders = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    print(method, "max errors", errs, "observed orders", orders)
    # zero-order-hold coupling is first order: error halves when the step halves
    assert errs[0] > errs[1] > errs[2]
    assert all(0.8 < o < 1.3 for o in orders), orders
    assert errs[2] < 0.05  # 10 s of a lightly damped oscillation, h = 5 ms


def test_gauss_seidel_order_follows_feedthrough():
    sc = load_scenario(TWO_BODY, [])
    m = build_master(sc)
    # coupling.force_n depends directly on body1's outputs: body1 must run first
    assert m.order == ["body1", "coupling"]


def test_save_restore_gives_identical_trajectories():
    sc = load_scenario(TWO_BODY, [])
    m = build_master(sc)
    m.initialize(0.0)
    for _ in range(300):
        m.step()
    snap = m.save_state()
    for _ in range(400):
        m.step()
    first = m.result().to_pandas()
    m.restore_state(snap)
    assert m.time_s == pytest.approx(3.0)
    for _ in range(400):
        m.step()
    second = m.result().to_pandas()
    assert first.shape == second.shape
    np.testing.assert_array_equal(first.to_numpy(), second.to_numpy())


def test_same_scenario_twice_identical():
    a = run_two_body(0.01, "gauss-seidel").to_pandas()
    b = run_two_body(0.01, "gauss-seidel").to_pandas()
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())


def test_multirate_component_steps_at_its_multiple():
    from shevsim.components.verification import MassSpring, SpringDamper
    from shevsim.core import Connection
    calls = []

    class Counting(SpringDamper):
        def do_step(self, t, h):
            calls.append((round(t, 9), round(h, 9)))
            super().do_step(t, h)
    b = MassSpring("body1")
    c = Counting("coupling")
    conns = [Connection.parse("body1.force_n", "coupling.force_n"),
             Connection.parse("coupling.position_m", "body1.position_m"),
             Connection.parse("coupling.velocity_mps", "body1.velocity_mps")]
    m = Master([b, c], conns, MasterSettings(step_s=0.1), {"coupling": 3})
    m.run(1.2)
    assert calls == [(round(0.3 * i, 9), 0.3) for i in range(4)]


def test_result_columns_carry_units():
    r = run_two_body(0.01, "gauss-seidel")
    df = r.to_pandas()
    assert "time_s" in df.columns and "body1.position_m" in df.columns
    assert r.units["coupling.force_n"] == "N"


# --------------------------------------------------------------- bug hunt (core), 2026-11-22
_GAIN_FAULT = """
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


def test_initialize_again_resets_faults():
    # a second initialize() (re-run from t0) must not keep a fault forced that starts later
    m = build_master(load_scenario(None, [], text=_GAIN_FAULT))
    first = m.run(1.0)["b.out_1"].copy()
    assert first[5] == 1.0 and first[6] == 7.0
    m.initialize(0.0)
    second = m.run(1.0)["b.out_1"]
    np.testing.assert_array_equal(first, second)


def test_restore_into_fresh_master_continues_from_snapshot():
    # a snapshot restored into a new (not yet initialised) master: run() continues, it does not restart
    m = build_master(load_scenario(None, [], text=_GAIN_FAULT))
    m.initialize(0.0)
    for _ in range(3):
        m.step()
    snap = m.save_state()
    ref = m.run(1.0)
    m2 = build_master(load_scenario(None, [], text=_GAIN_FAULT))
    m2.restore_state(snap)
    r = m2.run(1.0)
    # the new record starts at the snapshot (t = 0.3 s) and continues without a gap
    np.testing.assert_allclose(r.time_s, ref.time_s[3:])
    np.testing.assert_array_equal(r["b.out_1"], ref["b.out_1"][3:])


def test_restoring_a_later_snapshot_after_an_earlier_one_leaves_no_gap():
    m = build_master(load_scenario(None, [], text=_GAIN_FAULT))
    m.initialize(0.0)
    for _ in range(2):
        m.step()
    early = m.save_state()
    for _ in range(4):
        m.step()
    late = m.save_state()
    ref = m.run(1.0)
    m.restore_state(early)
    m.restore_state(late)          # the history (to 0.2 s) does not reach this snapshot (0.6 s)
    r = m.run(1.0)
    dt = np.diff(r.time_s)
    np.testing.assert_allclose(dt, 0.1, rtol=1e-9)       # contiguous
    np.testing.assert_allclose(r.time_s, ref.time_s[6:])
    np.testing.assert_array_equal(r["b.out_1"], ref["b.out_1"][6:])


def test_stop_time_not_a_multiple_of_the_step_is_reached():
    # the run ends at the first communication point at or after stop_s, never before it
    for stop, last in ((1.05, 1.1), (1.15, 1.2), (1.0, 1.0), (0.3 + 0.7, 1.0)):
        m = build_master(load_scenario(None, [], text=_GAIN_FAULT))
        r = m.run(stop)
        assert r.time_s[-1] == pytest.approx(last), (stop, r.time_s[-1])


def test_depends_on_an_unknown_input_is_an_error():
    from shevsim.components.verification import Gain
    from shevsim.core.errors import ScenarioError
    from shevsim.core.variables import inp, out

    class Typo(Gain):
        VARIABLES = (inp("in_1", "1"), out("out_1", "1", depends_on=("inn_1",)))
    with pytest.raises(ScenarioError, match=r"component 'x' output 'out_1' depends_on 'inn_1'.*no such input"):
        Master([Typo("x")], [], MasterSettings(step_s=0.1))


def test_progress_bar_reaches_the_total(capsys):
    pytest.importorskip("tqdm")
    m = build_master(load_scenario(TWO_BODY, []))
    m.settings.progress = True
    m.run(10.25)          # 1025 steps: not a multiple of the bar's update chunk
    err = capsys.readouterr().err
    assert "1025/1025" in err, err[-300:]


def test_delayed_connections_report_names_the_cause():
    text = TWO_BODY.read_text()
    # explicit order against the feedthrough: delayed because of the given order (there is no component cycle)
    m = build_master(load_scenario(None, [], text=text.replace(
        'method = "gauss-seidel"', 'method = "gauss-seidel"\norder = ["coupling", "body1"]')))
    assert [str(c) for c in m.delayed] == ["body1.position_m -> coupling.position_m",
                                           "body1.velocity_mps -> coupling.velocity_mps"]
    d = m.describe()
    assert "cycle broken" not in d and d.count("one-step delay: source runs later in the given order") == 2
    # Jacobi: every connection into a feedthrough input carries the previous step's value
    m = build_master(load_scenario(None, [], text=text.replace('method = "gauss-seidel"', 'method = "jacobi"')))
    assert {str(c) for c in m.delayed} == {"body1.position_m -> coupling.position_m",
                                           "body1.velocity_mps -> coupling.velocity_mps"}
    assert m.describe().count("one-step delay: Jacobi") == 2


def test_initialize_failure_names_component_time_and_exception_type():
    from shevsim.components.verification import Gain
    from shevsim.core.errors import SimulationError

    class Broken(Gain):
        def initialize(self, t0):
            raise KeyError("ocv_v")
    m = Master([Gain("a"), Broken("b")], [], MasterSettings(step_s=0.1))
    with pytest.raises(SimulationError, match=r"component 'b' failed to initialise at t=2.5 s: KeyError: 'ocv_v'"):
        m.run(3.0, t0=2.5)


# ------------------------------------------------------------------ recording less (issue 12)
def test_record_every_keeps_every_kth_point_and_the_last():
    sc = load_scenario(TWO_BODY, [])
    full = build_master(sc).run(1.0)
    m = build_master(sc)
    m.record_every = 3
    dec = m.run(1.0)
    k = [int(round(t / 0.01)) for t in dec.time_s]
    assert k[:4] == [0, 3, 6, 9] and k[-2:] == [99, 100]
    for s in full.signals:
        np.testing.assert_array_equal(dec[s], full[s][k])


def test_record_every_still_stops_on_a_non_finite_step_it_does_not_keep():
    from shevsim.components.verification import Trivial, TrivialParams
    from shevsim.core.errors import SimulationError
    comp = Trivial("lag", TrivialParams(gain=1e4))     # x_{k+1} = -999 x_k + 1000 u: overflows at step 103
    comp.u["in0_1"] = 1.0
    m = Master([comp], [], MasterSettings(step_s=0.1))
    m.record_every = 1000
    with pytest.raises(SimulationError, match=r"component 'lag' output 'out0_1' is inf at t=10.3 s") as ei:
        m.run(100.0)
    assert ei.value.component == "lag" and ei.value.port == "out0_1" and ei.value.time_s == pytest.approx(10.3)
