"""The compiled whole-vehicle path (``shevsim.fast``) against the Python master, the reference.

* Agreement: on the co-simulation regression scenarios (``tests/unit/test_cosim_regression.py``:
  HD-UDDS with the MPC and the BMS, 120 s, with the default, the one-branch and the seed DEKF) and on
  the rule-based scenario, every recorded signal of the fast path equals the master's to 1e-9
  (relative, with an absolute floor of 1e-9 times the signal's scale); at the time of writing they are
  bit-identical, which the message reports.
* The pieces that must reproduce Python exactly: DAQP called through its C library from compiled code
  against ``daqp.Model`` (same iterates, warm start and exit flags), ``round3`` against Python's
  ``round(x, 3)``, the rate-map bisection against ``bisect.bisect_right``.
* Ineligible scenarios are declined with a reason; a failing run raises the component's error.
"""
from __future__ import annotations

import bisect
import math
from pathlib import Path

import numpy as np
import pytest

from shevsim.core.errors import SimulationError
from shevsim.core.scenario import build_master, load_scenario
from shevsim.fast import runner_for

ROOT = Path(__file__).resolve().parents[2]
SCEN = ROOT / "scenarios"


def _compare(name: str, stop_s: float, sets=()):
    sc = load_scenario(SCEN / f"{name}.toml", ["cycle.repeat=1", *sets])
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(stop_s)
    ref = build_master(load_scenario(SCEN / f"{name}.toml", ["cycle.repeat=1", *sets])).run(stop_s)
    assert fast.termination == ref.termination == "completed"
    assert np.array_equal(fast.time_s, ref.time_s)
    assert list(fast.signals) == list(ref.signals)
    assert fast.units == ref.units
    n_exact = 0
    for k, r in ref.signals.items():
        f = fast[k]
        assert f.shape == r.shape, k
        scale = max(float(np.max(np.abs(r))), 1.0)
        err = np.abs(f - r)
        tol = 1e-9 * np.maximum(np.abs(r), scale)
        i = int(np.argmax(err - tol))
        assert np.all(err <= tol), (f"{k}: fast {f[i]!r} vs master {r[i]!r} at t={ref.time_s[i]} s "
                                    f"(max |diff| {err.max():.3e})")
        n_exact += bool(np.array_equal(f, r))
    return fast, ref, n_exact


def test_mpc_hd_udds_120s_agrees_with_the_master_on_every_signal():
    fast, ref, n_exact = _compare("hd_udds_mpc", 120.0)
    assert len(fast.time_s) == 1201
    # the MPC really solved QPs (no silent fallback) and the supervisor acted
    assert fast["supervisor.fallback_count"][-1] == ref["supervisor.fallback_count"][-1]
    assert np.ptp(fast["supervisor.power_cmd_w"]) > 1e3
    print(f"{n_exact} of {len(ref.signals)} signals bit-identical")


@pytest.mark.slow
@pytest.mark.parametrize("sets", [("bms.v2_model=none",),
                                  ("bms.rs_model=free", "bms.rc_model=free", "bms.v2_model=none"),
                                  ("shared.cell_diffusion_time_s=2500",)])
def test_mpc_hd_udds_120s_agrees_with_the_other_dekf_variants(sets):
    _compare("hd_udds_mpc", 120.0, sets)


def test_mpc_with_daqp_on_every_call_agrees_with_the_master():
    """``supervisor.warm_active_set = false`` (no active-set guess) takes the same compiled call."""
    _compare("hd_udds_mpc", 60.0, ("supervisor.warm_active_set=false",))


def test_rule_hd_udds_agrees_with_the_master_on_every_signal():
    fast, ref, _ = _compare("hd_udds_rule", 200.0)
    assert np.ptp(fast["engine_generator.elec_power_w"]) > 1e3


def test_faults_and_within_step_power_limits_agree_with_the_master():
    # the seed's cooling fault (h_conv forced to 3 W/m2K at 300 s, its connection cut) on the within-step
    # order with two power_limits components (a stateless type with several instances)
    fast, ref, _ = _compare("uac_proxy_mpc_cooling_fault_seed", 330.0)
    assert fast["battery.t_core_c"][-1] > fast["battery.t_core_c"][2900]      # the fault acts


@pytest.mark.slow
@pytest.mark.parametrize("name,stop", [("hd_udds_mpc", 1060.0), ("uac_proxy_mpc", 600.0), ("uac_proxy_rule", 600.0),
                                       ("uac_proxy_mpc_cooling_fault", 900.0), ("hd_udds_rule_seed", 1060.0),
                                       ("uac_proxy_mpc_cooling_fault_one_step_late", 900.0)])
def test_longer_runs_agree(name, stop):
    _compare(name, stop)


def test_a_runner_serves_repeated_runs_identically():
    sc = load_scenario(SCEN / "hd_udds_mpc.toml", ["cycle.repeat=1"])
    run, why = runner_for(sc)
    a = run(30.0)
    b = run(30.0)
    c = run(12.0)
    for k in a.signals:
        assert np.array_equal(a[k], b[k]), k
        assert np.array_equal(a[k][:121], c[k]), k


# --------------------------------------------------------------------------------- declined scenarios
def _declined(path, sets=(), text=None):
    sc = load_scenario(path, list(sets)) if text is None else load_scenario(None, list(sets), text=text)
    run, why = runner_for(sc)
    assert run is None
    assert isinstance(why, str) and why
    return why


def test_ineligible_scenarios_are_declined_with_a_reason():
    why = _declined(SCEN / "hd_udds_fmu_battery.toml")
    assert "FMU" in why
    assert "osqp" in _declined(SCEN / "hd_udds_mpc.toml", ["supervisor.solver=osqp"])
    assert "fd30" in _declined(SCEN / "hd_udds_mpc.toml", ["battery.thermal_model=fd30"])
    text = (SCEN / "hd_udds_rule.toml").read_text().replace('type = "driver"', 'type = "gain"')
    assert "gain" in _declined(None, text=text)


def test_jacobi_method_agrees_with_the_master():
    text = (SCEN / "hd_udds_mpc.toml").read_text().replace('method = "gauss-seidel"', 'method = "jacobi"')
    sc = load_scenario(SCEN / "hd_udds_mpc.toml", ["cycle.repeat=1"], text=text)
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(60.0)
    ref = build_master(load_scenario(SCEN / "hd_udds_mpc.toml", ["cycle.repeat=1"], text=text)).run(60.0)
    for k in ref.signals:
        assert np.array_equal(fast[k], ref[k]), k
    gs = build_master(load_scenario(SCEN / "hd_udds_mpc.toml", ["cycle.repeat=1"])).run(60.0)
    assert not np.array_equal(fast["vehicle.speed_mps"], gs["vehicle.speed_mps"])      # Jacobi really differs


SPEED_REPLAY = """
[scenario]
name = "speed_replay"
step_s = 0.1
[components.cycle]
type = "cycle"
params = "components/cycle/hd_udds.toml"
[components.vehicle]
type = "vehicle"
params = "components/vehicle/matv.toml"
set = { input_mode = "speed" }
[components.motor]
type = "motor"
params = "components/motor/default.toml"
[components.amb]
type = "profile"
set = { time_s = [0.0, 10.0, 20.05, 30.0], t_ambient_c = [20.0, 30.0, 25.0, 21.0], h_conv_w_m2k = [10.0, 40.0, 5.0, 8.0] }
[components.battery]
type = "battery"
params = "components/battery/default.toml"
[connections]
"vehicle.speed_ref_mps" = "cycle.speed_ref_mps"
"vehicle.accel_ref_mps2" = "cycle.accel_ref_mps2"
"motor.force_req_n" = "vehicle.force_req_n"
"motor.speed_mps" = "vehicle.speed_mps"
"battery.power_w" = "motor.elec_power_w"
"battery.t_ambient_c" = "amb.t_ambient_c"
"battery.h_conv_w_m2k" = "amb.h_conv_w_m2k"
"""


def test_speed_mode_vehicle_and_profile_source_agree_with_the_master():
    sc = load_scenario(SCEN / "speed_replay.toml", text=SPEED_REPLAY)
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(90.0)
    ref = build_master(load_scenario(SCEN / "speed_replay.toml", text=SPEED_REPLAY)).run(90.0)
    for k in ref.signals:
        assert np.array_equal(fast[k], ref[k]), k
    assert np.ptp(fast["vehicle.force_req_n"]) > 1e3 and np.ptp(fast["amb.t_ambient_c"]) == 10.0


CELL_REPLAY = """
[scenario]
name = "cell_replay"
step_s = 1.0
[components.rec]
type = "profile"
set = { time_s = [0.0, 30.0, 60.0, 90.0, 120.0], current_a = [0.0, 150.0, -90.0, 230.0, 0.0], t_ambient_c = [25.0, 25.0, 26.0, 27.0, 27.0] }
[components.battery]
type = "battery"
params = "components/battery/default.toml"
set = { input_mode = "current" }
[components.bms]
type = "bms"
params = "components/bms/default.toml"
[connections]
"battery.current_cmd_a" = "rec.current_a"
"battery.t_ambient_c" = "rec.t_ambient_c"
"bms.cell_current_meas_a" = "battery.cell_current_meas_a"
"bms.cell_voltage_meas_v" = "battery.cell_voltage_meas_v"
"bms.t_surface_meas_c" = "battery.t_surface_meas_c"
"bms.t_ambient_meas_c" = "battery.t_ambient_meas_c"
"""


def test_current_driven_battery_and_bms_at_1s_agree_with_the_master():
    # a measured-current replay (battery input_mode 'current') with the BMS sampling at 1 s (rebuilt estimators)
    sc = load_scenario(SCEN / "cell_replay.toml", text=CELL_REPLAY)
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(150.0)
    ref = build_master(load_scenario(SCEN / "cell_replay.toml", text=CELL_REPLAY)).run(150.0)
    for k in ref.signals:
        assert np.array_equal(fast[k], ref[k]), k
    assert fast["battery.current_a"][45] == pytest.approx(150.0, rel=1e-9)


def test_several_components_of_one_type_each_keep_their_own_state():
    # a second cycle (another trace, played from the same start) beside the first: one kernel, two states
    text = (SCEN / "hd_udds_rule.toml").read_text().replace('"supervisor"]', '"supervisor", "cycle2"]')
    text += '\n[components.cycle2]\ntype = "cycle"\nparams = "components/cycle/uac_proxy.toml"\n'
    sc = load_scenario(SCEN / "hd_udds_rule.toml", ["cycle.repeat=1"], text=text)
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(60.0)
    ref = build_master(load_scenario(SCEN / "hd_udds_rule.toml", ["cycle.repeat=1"], text=text)).run(60.0)
    for k in ref.signals:
        assert np.array_equal(fast[k], ref[k]), k
    assert not np.array_equal(fast["cycle.speed_ref_mps"], fast["cycle2.speed_ref_mps"])


def test_runtime_error_names_the_component_like_the_master():
    # a tiny plant the BMS does not know (bms.own: its capacity is not the shared cell's, issue 25)
    sets = ["cycle.repeat=1", "battery.soc_init_pct=30.5", "battery.capacity_ah=0.05", "bms.soc0_pct=30.5",
            'bms.own=["capacity_ah"]']
    sc = load_scenario(SCEN / "hd_udds_rule.toml", sets)
    run, why = runner_for(sc)
    assert run is not None, why
    with pytest.raises(SimulationError) as fast_err:
        run(600.0)
    with pytest.raises(SimulationError) as ref_err:
        build_master(load_scenario(SCEN / "hd_udds_rule.toml", sets)).run(600.0)
    assert "'battery'" in str(fast_err.value) and "battery" in str(ref_err.value)
    part = fast_err.value.result
    assert part.termination.status == "stopped" and part.termination.component == "battery"
    assert 1 < len(part.time_s) < 6001


# ------------------------------------------------------------------------------ exact building blocks
def test_compiled_daqp_calls_reproduce_daqp_model_bit_for_bit():
    daqp = pytest.importorskip("daqp")
    from shevsim.supervisor import daqp_nb
    ok, why = daqp_nb.available()
    if not ok:
        pytest.skip(why)
    m = build_master(load_scenario(SCEN / "hd_udds_mpc.toml", ["cycle.repeat=1"]))
    prob = m.components["supervisor"].mpc.prob
    rng = np.random.default_rng(3)
    st = daqp_nb.new_state(prob.n, prob.n + prob.m)
    model = None
    flags_seen = set()
    for k in range(400):
        # a drifting operating point (warm starts carry over) with occasional jumps and infeasible limits
        soc = 50 + 15 * math.sin(k / 40) + rng.normal()
        pd = 80 * math.sin(k / 9) + 20 * rng.normal()
        vo = abs(60 + 50 * math.sin(k / 17))
        pbmax, pbmin = (150.0, -100.0) if k % 97 else (-5.0, -4.0)
        st_build = prob.build(soc, pd, vo, pbmax, pbmin, 430.0, 0.13, 30.0)
        if st_build != 0:
            continue
        if model is None:
            model = daqp.Model()
            model.setup(prob.H, prob.f, prob.A, prob.bu, prob.bl)
        else:
            model.update(H=prob.H, f=prob.f, bupper=prob.bu, blower=prob.bl)
        x, _, flag, _ = model.solve()
        if flag < 1:
            model = None
        fl = daqp_nb.solve(*st, prob.H, prob.f, prob.A, prob.bu, prob.bl)
        flags_seen.add(int(flag))
        assert fl == flag, k
        assert np.array_equal(x, st[4]), (k, np.max(np.abs(x - st[4])))
    daqp_nb.drop_model(st[0], st[6])
    assert 1 in flags_seen or 2 in flags_seen


def test_round3_is_pythons_round():
    from shevsim.bms.power_capability import round3
    rng = np.random.default_rng(0)
    xs = list(rng.uniform(0, 1000, 20000)) + list(rng.uniform(-2, 2, 5000))
    xs += [k / 1000 + 0.0005 for k in range(-3000, 3000)]            # decimal ties (as doubles)
    xs += [k / 2000 for k in range(-4000, 4000)]                      # exact binary ties where they exist
    xs += [0.0, -0.0, 1e-300, 123456789.0005, 4.5e15, math.inf, -math.inf]
    for x in xs:
        a, b = round3(float(x)), round(float(x), 3)
        assert a == b and math.copysign(1, a) == math.copysign(1, b), (x, a, b)
    assert math.isnan(round3(math.nan))


def test_rate_map_bisection_is_bisect_right():
    from shevsim.supervisor.rule_based import bisect_right
    a = np.array([-1.0, 0.0, 0.0, 2.5, 236e3])
    for x in [-2.0, -1.0, -0.5, 0.0, 1.0, 2.5, 3.0, 236e3, 1e9, math.nan, -math.inf, math.inf]:
        assert bisect_right(a, x) == bisect.bisect_right(list(a), x), x


# ------------------------------------------------------- the MPC's one step: its constraints hold, every branch
def _drive_mpc(params_sets=(), n=600, seed=0):
    """Drive the MPC component (its compiled step: QP, DAQP, first move or fallback) with random inputs
    (non-finite values, infeasible battery limits, SOC outside the window, demands beyond engine + battery)
    and check what every command must satisfy: the engine limits, the power-rate limits around the previous
    command, and the battery limits whenever they are usable and reachable."""
    from shevsim.components import get_component_class
    from shevsim.core.params import load_params
    cls = get_component_class("mpc_supervisor", "test")
    over = dict(params_sets)
    comp = cls("mpc", load_params(cls.Params, None, over) if over else None)
    assert comp.step_function() is not None
    comp.u["gen_power_w"] = 20e3
    comp.initialize(0.0)
    p = comp.params
    rng = np.random.default_rng(seed)
    h = p.sample_time_s
    tol = 1e-6
    for k in range(n):
        u = {"demand_power_w": rng.normal(40e3, 60e3), "soc_pct": float(np.clip(rng.normal(50, 15), 1, 99)),
             "gen_power_w": 0.0, "power_max_w": abs(rng.normal(120e3, 40e3)), "power_min_w": -abs(rng.normal(80e3, 30e3)),
             "ocv_v": rng.normal(430, 5), "rs_ohm": abs(rng.normal(0.13, 0.02))}
        r = rng.random()
        if r < 0.05:
            u["soc_pct"] = math.nan
        elif r < 0.10:
            u["power_max_w"], u["power_min_w"] = -5e3, -1e3          # P_b,max < P_b,min: unusable limits
        elif r < 0.13:
            u["rs_ohm"] = 0.0
        elif r < 0.2:
            u["demand_power_w"] = 400e3                               # beyond engine + battery
        comp.u.update(u)
        prev = comp.prev_cmd
        rate_up = comp.mpc.rate_map(prev)
        comp.do_step(k * h, h)
        cmd = comp.y["power_cmd_w"]
        assert p.power_gen_min_w - tol <= cmd <= p.power_gen_max_w + tol, (k, cmd)
        assert prev + p.power_rate_min_wps * h - tol <= cmd <= prev + rate_up * h + tol, (k, prev, cmd)
        lo, hi = u["demand_power_w"] - u["power_max_w"], u["demand_power_w"] - u["power_min_w"]
        reach_lo = max(p.power_gen_min_w, prev + p.power_rate_min_wps * h)
        reach_hi = min(p.power_gen_max_w, prev + rate_up * h)
        if u["power_min_w"] <= u["power_max_w"] and max(lo, reach_lo) <= min(hi, reach_hi) and \
                not p.battery_limits_soft:
            assert lo - 1e-3 <= cmd <= hi + 1e-3, (k, lo, cmd, hi)
        assert comp.y["battery_power_plan_w"] == u["demand_power_w"] - cmd
    return comp.y["fallback_count"]


def test_mpc_step_keeps_its_constraints_including_fallbacks():
    assert _drive_mpc() > 10                       # the fallback branches were exercised


@pytest.mark.parametrize("sets", [(("battery_limits_soft", False), ("fallback", "rule")),
                                  (("battery_limits_soft", False), ("fallback", "shift"))])
def test_mpc_step_keeps_hard_battery_limits(sets):
    assert _drive_mpc(sets, n=400, seed=1) > 10


def test_an_exception_inside_the_compiled_loop_reruns_on_the_master(monkeypatch):
    """Numba raises without component or time; engine 'auto' reruns the scenario on the Python master
    (same numbers, its diagnosis when it fails), engine 'fast' reports the stop as such."""
    import shevsim
    from shevsim.core.errors import FastPathError
    from shevsim.fast import FastRunner
    ref = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=30.0, engine="python")

    def boom(self, t_stop_s):
        raise FastPathError("the compiled loop raised ZeroDivisionError: division by zero")
    monkeypatch.setattr(FastRunner, "__call__", boom)
    res = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=30.0, engine="auto")
    assert res.termination == "completed" and res.meta["engine"] == "python"
    for name, v in ref.signals.items():
        np.testing.assert_array_equal(res.signals[name], v, err_msg=name)
    res = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=30.0, engine="fast")
    assert res.termination.status == "stopped" and "ZeroDivisionError" in res.termination.reason


def test_a_step_longer_than_the_run_is_refused_before_running():
    import shevsim
    from shevsim.core.errors import ScenarioError
    with pytest.raises(ScenarioError, match="step_s = 1e\\+06 s is longer than the run"):
        # the supervisor's sample time follows the step (else the scenario is refused for that first)
        shevsim.simulate("hd_udds_rule", {"scenario.step_s": 1e6, "supervisor.sample_time_s": 2e6})


def test_a_unit_converting_connection_is_declined():
    """The compiled loop copies values by index: a connection the master converts (kW -> W) stays there."""
    import dataclasses
    sc = load_scenario("hd_udds_rule")
    m = build_master(sc)
    v = m._vars["motor"]["elec_power_max_w"]
    m._vars["motor"]["elec_power_max_w"] = dataclasses.replace(v, unit="kW")
    run, why = runner_for(sc, m)
    assert run is None and "converts" in why and "motor.elec_power_max_w" in why


# ------------------------------------------- a new component type: one compiled step, both engines, no fast-path code
from dataclasses import dataclass as _dataclass  # noqa: E402

from numba import njit as _njit  # noqa: E402

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, port_index  # noqa: E402
from shevsim.core.component import Component  # noqa: E402
from shevsim.core.variables import inp, out  # noqa: E402


@_dataclass(frozen=True)
class LagParams:
    tau_s: float = 2.0


class Lag(CompiledStep, Component):
    """First-order lag ``tau dy/dt = u - y`` (exact over a step with ``u`` held): a component type that exists
    only in this test."""

    TYPE = "test_lag"
    Params = LagParams
    VARIABLES = (inp("u_mps", "m/s", 0.0, "input"), out("y_mps", "m/s", 0.0, "lagged input"))
    DATA_MUTABLE = (1,)
    _static = ("name", "params", "_fn", "_u_names", "_y_names")

    def initialize(self, t0):
        self.data = (np.array([self.params.tau_s]), np.zeros(1))
        self.y["y_mps"] = 0.0
        self._io()


_LU = port_index(Lag.VARIABLES, "input")
_LY = port_index(Lag.VARIABLES, "output")


@_njit(cache=True)
def lag_step(data, u, y, t, h):
    p, x = data
    v = u[_LU.u_mps]
    if v != v:
        return ERR_NAN_INPUT
    x[0] = v + (x[0] - v) * math.exp(-h / p[0])
    y[_LY.y_mps] = x[0]
    return 0


Lag.STEP = lag_step

LAG = """
[scenario]
name = "lag"
step_s = 0.1
[components.src]
type = "profile"
set = { time_s = [0.0, 0.05, 30.0], speed_mps = [0.0, 1.0, 1.0] }
[components.lag]
type = "test_lag"
set = { tau_s = 2.0 }
[connections]
"lag.u_mps" = "src.speed_mps"
"""


def test_a_new_component_type_runs_on_both_engines_with_no_fast_path_code(monkeypatch):
    """A component type defined here, with its one compiled step, runs on the compiled loop as it is (no line in
    shevsim.fast names it) and equals the master bit for bit; both follow the exact step response
    1 - exp(-t/tau) of the lag."""
    from shevsim.components import REGISTRY
    monkeypatch.setitem(REGISTRY, "test_lag", f"{__name__}:Lag")
    sc = load_scenario(None, text=LAG)
    run, why = runner_for(sc)
    assert run is not None, why
    fast = run(20.0)
    ref = build_master(load_scenario(None, text=LAG)).run(20.0)
    assert np.array_equal(fast["lag.y_mps"], ref["lag.y_mps"])
    t = ref.time_s
    np.testing.assert_allclose(ref["lag.y_mps"][1:], 1.0 - np.exp(-t[1:] / 2.0), rtol=1e-12, atol=1e-12)


class AllocLag(Lag):
    """The lag with a step that allocates: refused by njit_step's rule (no numba runtime in a step)."""
    TYPE = "test_alloc_lag"


def _alloc_lag_step(data, u, y, t, h):
    p, x = data
    tmp = np.empty(1)                    # not allowed in a step compiled without numba's runtime
    tmp[0] = u[_LU.u_mps]
    x[0] = tmp[0] + (x[0] - tmp[0]) * math.exp(-h / p[0])
    y[_LY.y_mps] = x[0]
    return 0


def test_a_users_step_that_allocates_is_a_clear_error_naming_the_component(monkeypatch):
    """A user's step compiled with njit_step that allocates: a ScenarioError (bad input, exit 2) naming the
    component, numba's first line and the rule, not a run 'stopped' with numba's traceback as the reason."""
    from shevsim.components import REGISTRY
    from shevsim.core.compiled import njit_step
    from shevsim.core.errors import ScenarioError
    monkeypatch.setattr(AllocLag, "STEP", njit_step(cache=False)(_alloc_lag_step))
    monkeypatch.setitem(REGISTRY, "test_alloc_lag", f"{__name__}:AllocLag")
    sc = load_scenario(None, text=LAG.replace('type = "test_lag"', 'type = "test_alloc_lag"'))
    with pytest.raises(ScenarioError) as e:
        build_master(sc).run(1.0)
    msg = str(e.value)
    assert "component 'lag'" in msg and "does not compile" in msg and "may not allocate" in msg, msg
