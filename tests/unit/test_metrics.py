"""Run metrics on synthetic results with hand-computed answers."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from shevsim import metrics as M
from shevsim.core.errors import DataError

RHO = M.DIESEL_DENSITY_KG_PER_L


def test_fuel_constants_from_their_sources():
    # GREET: 3,167 g/gal, 128,450 Btu/gal LHV
    assert RHO == pytest.approx(0.8366, abs=1e-4)
    assert M.DIESEL_LHV_J_PER_KG == pytest.approx(42.79e6, rel=1e-3)


def frame(t, **cols):
    d = {"time_s": t}
    d.update({k.replace("__", "."): v for k, v in cols.items()})
    return pd.DataFrame(d)


# ---------------------------------------------------------------- A.1
def test_constant_speed_constant_fuel_rate_every_window_counts():
    t = np.arange(0.0, 2000.0 + 0.5, 0.5)
    df = frame(t, vehicle__speed_mps=np.full_like(t, 10.0), engine_generator__fuel_mass_g=2.0 * t,
               battery__soc_pct=np.full_like(t, 50.0))
    r = M.fuel_economy_soc_sustained(df, 1000.0)
    # 10 km per 2000 g of fuel = 2000 g / 1000 / rho litres
    assert r["fuel_economy_kmpl"] == pytest.approx(10.0 / (2.0 / RHO), rel=1e-12)
    assert r["fuel_consumption_l_per_100km"] == pytest.approx(100.0 * 0.2 / RHO, rel=1e-12)
    assert r["n_windows"] == int(1000 / 0.5) + 1  # every xi in [0, 1000]


def test_windows_are_the_roots_and_economy_is_the_mean_of_ratios():
    # SOC = 50 + sin(2 pi t / 120), T = 100 -> d(xi) = 2 cos(2 pi (xi + 50)/120) sin(pi 100/120)
    # roots in [0, 150]: xi = 40, 100. Fuel rate 1 + t/100 g/s, speed 10 m/s.
    t = np.arange(0.0, 250.0 + 0.25, 0.25)
    df = frame(t, vehicle__speed_mps=np.full_like(t, 10.0), engine_generator__fuel_mass_g=t + t ** 2 / 200.0,
               battery__soc_pct=50.0 + np.sin(2 * np.pi * t / 120.0))
    tk = M.sustainable_window_starts(t, df["battery.soc_pct"], 100.0)
    np.testing.assert_allclose(tk, [40.0, 100.0], atol=2e-3)
    r = M.fuel_economy_soc_sustained(df, 100.0)
    # windows [40,140]: 100 + (140^2-40^2)/200 = 190 g; [100,200]: 250 g; 1 km each
    expected = np.mean([1.0 / (0.190 / RHO), 1.0 / (0.250 / RHO)])
    assert r["n_windows"] == 2
    assert r["fuel_economy_kmpl"] == pytest.approx(expected, rel=1e-4)
    # not the ratio of sums
    assert abs(r["fuel_economy_kmpl"] - 2.0 / (0.440 / RHO)) > 1e-2


def test_per_cycle_summary():
    t = np.arange(0.0, 200.0 + 0.5, 0.5)
    df = frame(t, vehicle__speed_mps=np.where(t < 100, 10.0, 5.0), engine_generator__fuel_mass_g=2.0 * t,
               battery__soc_pct=60.0 - 0.01 * t)
    rows = M.per_cycle_summary(df, 100.0)
    assert len(rows) == 2
    # first cycle: speed steps 10 -> 5 m/s at t = 100, trapezoid shares the step sample: 995 m + 2.5 m
    assert rows[0]["distance_km"] == pytest.approx((99.5 * 10 + 0.5 * 7.5) / 1000.0)
    assert rows[1]["fuel_mass_g"] == pytest.approx(200.0) and rows[1]["delta_soc_pct"] == pytest.approx(-1.0)
    assert rows[1]["fuel_economy_kmpl"] == pytest.approx(rows[1]["distance_km"] / (0.2 / RHO))


def test_no_sustainable_window_gives_none_and_a_note():
    t = np.arange(0.0, 200.0 + 1.0, 1.0)
    df = frame(t, vehicle__speed_mps=np.full_like(t, 10.0), engine_generator__fuel_mass_g=t,
               battery__soc_pct=60.0 - 0.01 * t)
    assert M.fuel_economy_soc_sustained(df, 100.0)["fuel_economy_kmpl"] is None
    m = M.compute_metrics(df, {"cycle_duration_s": 100.0})
    assert m["fuel_economy_soc_sustained_kmpl"] is None
    assert any("A.1" in n for n in m["notes"])
    # with a tolerance of the SOC drop per cycle (1 %) every window qualifies
    r = M.fuel_economy_soc_sustained(df, 100.0, soc_tolerance_pct=1.0 + 1e-9)
    assert r["n_windows"] == 101 and r["fuel_economy_kmpl"] == pytest.approx(1.0 / (0.1 / RHO))


def test_delta_soc_correction_charges_the_battery_deficit_at_eg_efficiency():
    t = np.linspace(0.0, 1000.0, 1001)
    frac = t / t[-1]
    e_fuel = 1000.0 * M.DIESEL_LHV_J_PER_KG / 1000.0  # 1000 g of fuel
    e_el_per_g = 0.35 * M.DIESEL_LHV_J_PER_KG / 1000.0
    df = frame(t, vehicle__speed_mps=np.full_like(t, 10.0),
               engine_generator__fuel_mass_g=1000.0 * frac,
               engine_generator__fuel_energy_j=e_fuel * frac,
               engine_generator__engine_loss_energy_j=0.60 * e_fuel * frac,
               engine_generator__gen_loss_energy_j=0.05 * e_fuel * frac,
               battery__chem_energy_j=100.0 * e_el_per_g * frac,  # battery supplied what 100 g would make
               battery__soc_pct=60.0 - 2.0 * frac)
    r = M.fuel_economy_dsoc_corrected(df)
    assert r["eg_elec_energy_per_fuel_j_per_g"] == pytest.approx(e_el_per_g)
    assert r["fuel_equivalent_g"] == pytest.approx(1100.0)
    assert r["fuel_economy_raw_kmpl"] == pytest.approx(10.0 / (1.0 / RHO))
    assert r["fuel_economy_kmpl"] == pytest.approx(10.0 / (1.1 / RHO))
    # a charged battery is credited
    df["battery.chem_energy_j"] = -df["battery.chem_energy_j"]
    assert M.fuel_economy_dsoc_corrected(df)["fuel_equivalent_g"] == pytest.approx(900.0)
    # fallback from SOC x pack energy when chem energy is not recorded
    df2 = df.drop(columns=["battery.chem_energy_j"])
    r2 = M.fuel_economy_dsoc_corrected(df2, pack_capacity_ah=23.0, pack_nominal_voltage_v=416.0)
    assert r2["battery_net_energy_j"] == pytest.approx(0.02 * 23.0 * 3600.0 * 416.0)


# ---------------------------------------------------------------- battery
def test_effective_ah_hand_computed():
    t = np.arange(0.0, 3600.0 + 1.0, 1.0)
    df = frame(t, battery__current_a=np.full_like(t, 230.0))  # 23 A per cell for 1 h
    r = M.effective_ah_processed(df, cells_parallel=10)
    assert r["ah_throughput_cell_ah"] == pytest.approx(23.0) and r["ah_effective_cell_ah"] == pytest.approx(23.0)
    assert M.effective_ah_processed(df, 10, severity_factor=1.5)["ah_effective_cell_ah"] == pytest.approx(34.5)
    # -10 -> +10 A/cell linearly over 200 s (charge then discharge): |I| triangle area = 2 x 0.5 x 10 A x 100 s
    t = np.arange(0.0, 200.0 + 1.0, 1.0)
    df = frame(t, battery__current_a=10.0 * (-10.0 + 0.1 * t))
    assert M.effective_ah_processed(df, 10)["ah_throughput_cell_ah"] == pytest.approx(1000.0 / 3600.0)


def test_wang_severity_factor_limits():
    assert M.severity_factor_wang2011(1.0, 25.0) == pytest.approx(1.0)
    # Arrhenius: 10 K hotter at 1 C -> exp(Ea' (1/T0 - 1/T) / R / z)
    ea = 31700.0 - 370.3
    expect = math.exp(ea / M.R_GAS * (1 / 298.15 - 1 / 308.15) / 0.55)
    assert M.severity_factor_wang2011(1.0, 35.0) == pytest.approx(expect)
    assert M.severity_factor_wang2011(5.0, 25.0) > M.severity_factor_wang2011(1.0, 25.0)
    assert M.severity_factor_wang2011(-5.0, 25.0) == M.severity_factor_wang2011(5.0, 25.0)
    t = np.arange(0.0, 3600.0 + 1.0, 1.0)
    df = frame(t, battery__current_a=np.full_like(t, 23.0), battery__t_core_c=np.full_like(t, 25.0))
    r = M.effective_ah_processed(df, 10, weighting="wang2011", cell_capacity_ah=2.3)
    assert r["ah_effective_cell_ah"] == pytest.approx(2.3)  # 1 C at 25 degC: weight 1
    with pytest.raises(DataError, match="ah_weighting"):
        M.effective_ah_processed(df, 10, weighting="nonsense")


def test_current_histogram_counts():
    cell = np.array([-121.0, -5.0, 0.0, 4.99, 5.0, 17.0, 24.9, 25.0, 120.0, 130.0])
    df = frame(np.arange(cell.size, dtype=float), battery__current_a=10.0 * cell)
    h = M.current_histogram(df, cells_parallel=10)
    edges = h["edges_a"]
    counts = dict(zip(edges[:-1], h["counts"]))
    assert h["below_count"] == 1 and h["above_count"] == 1
    assert counts[-5.0] == 1 and counts[0.0] == 2 and counts[5.0] == 1
    assert counts[15.0] == 1 and counts[20.0] == 1 and counts[25.0] == 1 and counts[115.0] == 1
    assert sum(h["counts"]) == 8
    assert h["fraction"][edges.index(0.0)] == pytest.approx(0.2)
    with pytest.raises(DataError, match="hist_edges_a"):
        M.current_histogram(df, 10, edges_a=[1.0])


# ---------------------------------------------------------------- trace, soot
def test_speed_miss_and_soot():
    t = np.arange(0.0, 100.0 + 1.0, 1.0)
    ref = np.full_like(t, 10.0)
    v = ref + np.where(np.arange(t.size) % 2 == 0, 1.0, 0.0)  # 51 samples +1 m/s, 50 exact
    df = frame(t, vehicle__speed_mps=v, cycle__speed_ref_mps=ref,
               vehicle__distance_m=10.0 * t, engine_generator__soot_mass_mg=0.0316 * t)
    r = M.speed_trace_miss(df)
    assert r["speed_miss_max_kmh"] == pytest.approx(3.6)
    assert r["speed_miss_rms_kmh"] == pytest.approx(3.6 * math.sqrt(51 / 101))
    # 3.16 mg over 1 km = 0.00316 g/km
    assert M.soot_g_per_km(df) == pytest.approx(0.00316)


# ---------------------------------------------------------------- energy balance
def _shev_run(n=2001, dt=0.1):
    """A bookkeeping-consistent synthetic run: accelerate, cruise, brake."""
    t = np.arange(n) * dt
    m, g = 15554.0, 9.81
    v = np.interp(t, [0, 40, 120, 160, 200], [0, 15, 15, 0, 0])
    a = np.gradient(v, t)
    vm = v
    p_aero = 0.5 * 1.2 * 4.3 * vm ** 3
    p_roll = 0.01 * m * g * vm
    p_net = m * a * vm
    p_trac = p_aero + p_roll + p_net              # wheel power needed
    p_brake = np.where(p_trac < 0, -0.4 * p_trac, 0.0)  # 40 % of braking by friction
    p_trac = p_trac + p_brake                     # regen is the rest
    p_motor_loss = 0.1 * np.abs(p_trac)
    p_motor_el = p_trac + p_motor_loss
    p_gen_el = np.full_like(t, 60e3)
    p_batt_term = p_motor_el - p_gen_el
    p_batt_loss = 0.03 * np.abs(p_batt_term)
    p_chem = p_batt_term + p_batt_loss
    p_fuel = p_gen_el / 0.35
    cum = lambda p: np.concatenate([[0.0], np.cumsum(p[1:] * dt)])  # noqa: E731
    ke = 0.5 * m * v ** 2
    # make the KE consistent with the same discrete integration of m a v
    ke = ke[0] + cum(p_net)
    return pd.DataFrame({
        "time_s": t, "vehicle.speed_mps": v,
        "engine_generator.fuel_energy_j": cum(p_fuel),
        "engine_generator.engine_loss_energy_j": cum(p_fuel * 0.62),
        "engine_generator.gen_loss_energy_j": cum(p_fuel * 0.03),
        "battery.chem_energy_j": cum(p_chem), "battery.loss_energy_j": cum(p_batt_loss),
        "motor.loss_energy_j": cum(p_motor_loss), "bus.aux_energy_j": np.zeros_like(t),
        "vehicle.aero_energy_j": cum(p_aero), "vehicle.rolling_energy_j": cum(p_roll),
        "vehicle.brake_energy_j": cum(p_brake), "vehicle.grade_energy_j": np.zeros_like(t),
        "vehicle.kinetic_energy_j": ke,
        "vehicle.traction_energy_j": cum(p_trac), "motor.mech_energy_j": cum(p_trac),
        "motor.elec_energy_j": cum(p_motor_el), "bus.motor_energy_j": cum(p_motor_el),
        "bus.gen_energy_j": cum(p_gen_el), "bus.battery_energy_j": cum(p_batt_term),
    })


def test_energy_balance_closes_and_detects_a_missing_term():
    df = _shev_run()
    eb = M.energy_balance(df)
    assert eb["missing"] == []
    assert abs(eb["closure_error_frac"]) < 1e-12
    fuel = df["engine_generator.fuel_energy_j"].iloc[-1]
    assert eb["throughput_j"] > fuel  # battery gross energy added
    # drop the friction-brake energy: the residual is exactly that energy
    df2 = df.copy()
    df2["vehicle.brake_energy_j"] = 0.0
    eb2 = M.energy_balance(df2)
    assert eb2["residual_j"] == pytest.approx(df["vehicle.brake_energy_j"].iloc[-1], rel=1e-9)
    assert eb2["closure_error_frac"] > 1e-3
    # per-node residuals are all ~0; a wrong motor loss shows up at the motor node only
    assert set(eb["nodes_j"]) == set(M.NODE_BALANCES)
    assert max(abs(r) for r in eb["nodes_j"].values()) < 1e-9 * fuel
    df3 = df.copy()
    df3["motor.loss_energy_j"] *= 1.1
    nodes = M.energy_balance(df3)["nodes_j"]
    bad = {k for k, r in nodes.items() if abs(r) > 1e-9 * fuel}
    assert bad == {"motor"}
    # a missing column is reported, not guessed
    eb3 = M.energy_balance(df.drop(columns=["vehicle.aero_energy_j"]))
    assert eb3["closure_error_frac"] is None and "vehicle.aero_energy_j" in eb3["missing"]


# ---------------------------------------------------------------- compute_metrics
def test_compute_metrics_is_json_and_reads_run_parameters(tmp_path):
    df = _shev_run()
    t = df["time_s"].to_numpy()
    df["cycle.speed_ref_mps"] = df["vehicle.speed_mps"]
    df["vehicle.distance_m"] = np.concatenate([[0.0], np.cumsum(0.5 * (df["vehicle.speed_mps"].to_numpy()[1:]
                                                                        + df["vehicle.speed_mps"].to_numpy()[:-1]) * 0.1)])
    df["engine_generator.fuel_mass_g"] = df["engine_generator.fuel_energy_j"] / (M.DIESEL_LHV_J_PER_KG / 1000.0)
    df["engine_generator.soot_mass_mg"] = 0.01 * t
    df["battery.soc_pct"] = 50.0 + np.sin(2 * np.pi * t / 50.0)
    df["battery.current_a"] = 100.0 * np.sin(2 * np.pi * t / 37.0)
    cyc = tmp_path / "c.csv"
    cyc.write_text("time_s,speed_mps\n" + "\n".join(f"{i},0" for i in range(101)) + "\n")
    m = M.compute_metrics(df, {"scenario": {"soc_tolerance_pct": 0.0},
                               "parameters": {"cycle": {"cycle_file": str(cyc), "repeat": 2},
                                              "battery": {"cells_parallel": 10}}})
    json.dumps(m)  # serialisable
    assert m["cycle_duration_s"] == 100.0 and m["n_cycles"] == pytest.approx(2.0)
    assert m["cells_parallel"] == 10
    assert m["speed_miss_rms_kmh"] == 0.0
    assert abs(m["energy_closure_error_frac"]) < 1e-12
    assert m["fuel_economy_soc_sustained_kmpl"] > 0 and m["soc_sustained_windows_count"] >= 2
    assert m["fuel_economy_dsoc_corrected_kmpl"] > 0
    assert m["soot_g_per_km"] == pytest.approx(0.01 * 200.0 / 1000.0 / m["distance_km"])
    assert sum(m["battery_current_histogram"]["counts"]) == len(df)
    assert m["notes"] == []
    # cycle duration from time_in_cycle_s when no parameters are given
    df["cycle.time_in_cycle_s"] = np.where(t < 100.0, t, t - 100.0)
    m2 = M.compute_metrics(df.drop(columns=[]))
    assert m2["cycle_duration_s"] == pytest.approx(100.0)


def test_missing_columns_are_reported():
    t = np.arange(0.0, 10.0)
    m = M.compute_metrics(frame(t, vehicle__speed_mps=np.ones_like(t)))
    assert m["distance_km"] == pytest.approx(0.009)
    assert m["fuel_economy_soc_sustained_kmpl"] is None and m["energy_closure_error_frac"] is None
    assert len(m["notes"]) >= 3
    with pytest.raises(DataError, match="time_s"):
        M.compute_metrics(pd.DataFrame({"vehicle.speed_mps": [1.0, 2.0]}))


def test_energy_balance_mid_run_with_grade_stored_energies_and_engine_shaft():
    """Closure where every storage term is non-zero: stopped mid-cruise (kinetic energy), on a grade, with an
    auxiliary load and the engine-generator shaft spun up (its documented balance: fuel = elec + losses +
    shaft KE change)."""
    df = _shev_run().iloc[:801].copy()  # t = 80 s, 15 m/s
    t = df["time_s"].to_numpy()
    ke = df["vehicle.kinetic_energy_j"].to_numpy()
    assert ke[-1] - ke[0] > 1e6
    g_j = 2.0e4 * t  # 20 kW against gravity, supplied by the battery at its OCV (no extra loss)
    for c in ("vehicle.grade_energy_j", "battery.chem_energy_j", "bus.battery_energy_j", "bus.motor_energy_j",
              "motor.elec_energy_j", "motor.mech_energy_j", "vehicle.traction_energy_j"):
        df[c] = df[c] + g_j
    x_j = 5.0e3 * t  # 5 kW auxiliary load on the bus, from the battery
    for c in ("bus.aux_energy_j", "battery.chem_energy_j", "bus.battery_energy_j"):
        df[c] = df[c] + x_j
    s_j = np.minimum(t, 10.0) * 3.0e3  # shaft spun up by 30 kJ in the first 10 s, from extra fuel
    df["engine_generator.fuel_energy_j"] = df["engine_generator.fuel_energy_j"] + s_j
    df["engine_generator.shaft_kinetic_energy_j"] = s_j
    eb = M.energy_balance(df)
    fuel = df["engine_generator.fuel_energy_j"].iloc[-1]
    assert abs(eb["residual_j"]) < 1e-9 * fuel, eb["sinks_j"]
    assert max(abs(r) for r in eb["nodes_j"].values()) < 1e-9 * fuel, eb["nodes_j"]
    # each storage term is needed, with its sign: a missing or flipped term leaves its size as residual
    for col, size in (("vehicle.kinetic_energy_j", ke[-1] - ke[0]), ("vehicle.grade_energy_j", g_j[-1]),
                      ("bus.aux_energy_j", x_j[-1]),
                      ("engine_generator.shaft_kinetic_energy_j", s_j[-1])):
        bad = df.copy()
        bad[col] = -bad[col]
        assert M.energy_balance(bad)["residual_j"] == pytest.approx(2.0 * size, rel=1e-9), col


# ----------------------------------------------------------- a result's metrics never raise (issue 12)
def _result(t, **sig):
    from shevsim.core.results import Result
    sig = {k.replace("__", "."): np.asarray(v, float) for k, v in sig.items()}
    return Result(np.asarray(t, float), sig, {k: "" for k in sig}, {})


def test_idle_run_per_distance_metrics_are_null_with_a_note():
    t = np.arange(0.0, 101.0)
    z = np.zeros_like(t)
    res = _result(t, vehicle__speed_mps=z, cycle__speed_ref_mps=z, battery__soc_pct=50 - 0.01 * t,
                  battery__chem_energy_j=1e3 * t, engine_generator__fuel_mass_g=0.5 * t,
                  engine_generator__soot_mass_mg=t, engine_generator__elec_energy_j=4e3 * t)
    m = M.result_metrics(res)
    json.dumps(m, allow_nan=False)              # JSON-clean: no NaN/inf
    assert m["distance_km"] == 0.0 and m["fuel_mass_g"] == pytest.approx(50.0)
    assert m["fuel_economy_raw_kmpl"] == 0.0    # fuel burnt for no distance
    assert m.get("fuel_consumption_dsoc_corrected_l_per_100km") is None
    assert m.get("soot_g_per_km") is None
    assert any("did not move" in n for n in m["notes"])


def test_a_run_stopped_after_one_sample_gives_notes_not_an_exception():
    res = _result([0.0], vehicle__speed_mps=[0.0], bus__clamp_count=[0.0])
    res.termination = "error: stopped at once"
    m = M.result_metrics(res)
    assert m["bus.clamp_count"] == 0.0
    assert any("did not complete" in n for n in m["notes"])
    assert any("could not be computed" in n and "2 samples" in n for n in m["notes"])


def test_result_metrics_read_the_result_without_a_dataframe_and_equal_the_dataframe_path():
    """:func:`result_metrics` reads the result's arrays through :class:`ResultColumns` (read-only views, no
    DataFrame): every metric equals :func:`compute_metrics` on ``res.to_pandas()``, and the result's arrays
    are left untouched."""
    from shevsim.core.scenario import build_master, load_scenario
    sc = load_scenario("hd_udds_mpc", ["cycle.repeat=1"])
    res = build_master(sc).run(300.0)
    before = {k: v.copy() for k, v in res.signals.items()}
    opts = dict(sc.metrics)
    fast = M.result_metrics(res, opts)
    ref = M.compute_metrics(res.to_pandas(), {"scenario": opts, "parameters": res.parameters})
    ref_notes = ref.pop("notes")
    assert fast.pop("notes") == M._clean(ref_notes)
    for k, v in M._clean(ref).items():
        assert fast[k] == v, k
    assert fast["distance_km"] > 0.5 and sum(v is not None for v in fast.values()) > 10
    for k, v in res.signals.items():
        assert np.array_equal(v, before[k], equal_nan=True), k
