"""Battery electrical model and pack plant: physics checks (analytical RC solution, energy
conservation, relaxation to OCV, Arrhenius trend, noise statistics, save/restore)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from shevsim.battery import cell
from shevsim.components.battery import BatteryPack, BatteryPackParams
from shevsim.core.errors import DataError, ScenarioError, SimulationError

NS, NP = 130, 10


def _const_tables(tmp_path, rs=0.01, r1=0.006, c1=2500.0, r2=0.008, c2=37500.0, name="ecm"):
    """Constant-parameter ECM tables (same for charge/discharge) on a 2x2 grid."""
    path = tmp_path / f"{name}.csv"
    lines = ["# test table", "soc_frac,t_c,rs_ohm,r1_ohm,c1_f,r2_ohm,c2_f"]
    for t in (-30.0, 80.0):
        for s in (0.0, 1.0):
            lines.append(f"{s},{t},{rs},{r1},{c1},{r2},{c2}")
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _pack(tmp_path=None, const=False, **kw):
    if const:
        f = _const_tables(tmp_path)
        kw.setdefault("discharge_file", f)
        kw.setdefault("charge_file", f)
    b = BatteryPack("battery", BatteryPackParams(**kw))
    b.initialize(0.0)
    return b


def _drive_profile(n, dt, seed=3, scale=60e3):
    rng = np.random.default_rng(seed)
    p = np.zeros(n)
    k = 0
    while k < n:
        m = int(rng.uniform(2.0, 12.0) / dt)
        p[k:k + m] = rng.uniform(-1.0, 1.2) * scale if rng.random() > 0.2 else 0.0
        k += m
    return p


# -- cell functions ------------------------------------------------------------------------
def current_from_power(p_w, v, r):
    """Independent reference (test only): the current drawing ``p_w`` from a source ``v - r i``,
    ``i = 2 p / (v + sqrt(v^2 - 4 r p))`` (the root continuous with ``p / v``)."""
    return 2.0 * p_w / (v + math.sqrt(v * v - 4.0 * r * p_w))


def test_current_from_power_reference_is_the_quadratic_root():
    for p in (-2000.0, -50.0, 0.0, 30.0, 100.0, 131.9):
        v, r = 3.25, 0.02
        i = current_from_power(p, v, r)
        i_ref = brentq(lambda x: v * x - r * x * x - p, -1e4, v / (2 * r))
        assert i == pytest.approx(i_ref, rel=1e-12, abs=1e-12)


def test_ocv_lfp_shape_and_entropy_range():
    socs = np.linspace(0.0, 1.0, 101)
    v = np.array([cell.ocv(s) for s in socs])
    assert np.all(np.diff(v) > 0)                       # invertible
    assert 3.25 < cell.ocv(0.5) < 3.35                  # LFP plateau
    assert cell.ocv(0.6) - cell.ocv(0.3) < 0.05         # flat middle
    assert cell.ocv(0.02) < 3.1 and cell.ocv(1.0) > 3.4  # steep ends
    ds = np.array([cell.entropy_change(s) for s in socs])
    dudt = ds / cell.FARADAY_C_MOL
    assert np.max(np.abs(dudt)) < 0.5e-3                # |dU/dT| < 0.5 mV/K
    assert ds[0] < 0 and ds.max() > 0                   # sign change over SOC


def test_resistance_arrhenius_and_charge_discharge_distinct():
    temps = np.array([-10.0, 0.0, 10.0, 25.0, 40.0])
    rs = np.array([cell.cell_params(0.5, t, 1.0)[0] for t in temps])
    assert np.all(np.diff(rs) < 0)
    assert rs[0] / rs[3] > 2.5                          # ~3x at -10 degC
    # Arrhenius: ln R linear in 1/T (grid points of the table)
    slope, icpt = np.polyfit(1.0 / (temps + 273.15), np.log(rs), 1)
    resid = np.log(rs) - (slope * 1.0 / (temps + 273.15) + icpt)
    assert np.max(np.abs(resid)) < 1e-6 and slope > 0
    assert cell.cell_params(0.9, 25.0, -1.0) != cell.cell_params(0.9, 25.0, 1.0)


def test_heat_generation_sign_convention():
    """The model's heat (shevsim.battery.model): with dU/dT < 0, discharge releases reversible heat and charge
    absorbs it (q_rev = -i T dU/dT); the irreversible part is i^2 R_s + V1^2/R1 (+ V2^2/R2)."""
    from shevsim.battery import model as bm
    prm = BatteryPackParams(n_series=1, n_parallel=1, input_mode="current", entropic_heat=False, r2_scale=0.0,
                            dudt_soc_frac=(0.0, 1.0), dudt_v_k=(-20.0 / cell.FARADAY_C_MOL,) * 2)
    d, ix = cell.default_tables().packed()
    c = bm.pack_params(prm)
    q = {}
    for i in (5.0, -5.0):
        st = np.zeros(bm.N_STATE)
        st[bm.S_SOC] = 0.5
        y = np.zeros(bm.N_OUT)
        q[i] = bm.cell_electrical.py_func(d, ix, c, st, i, 1e-9, 300.0 - 273.15, y)
        rs = y[bm.Y_RS]
        q[i] -= i * i * rs          # irreversible part (V1 ~ 0 over 1 ns)
    assert q[5.0] == pytest.approx(5.0 * 300.0 * 20.0 / cell.FARADAY_C_MOL, rel=1e-6)
    assert q[-5.0] == pytest.approx(-q[5.0], rel=1e-6)


def test_bad_table_names_file_and_column(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("soc_frac,t_c,rs_ohm\n0,0,1\n1,0,1\n")
    with pytest.raises(DataError, match="bad.csv.*missing column"):
        cell.CellTables(discharge_file=bad)
    with pytest.raises(ScenarioError, match="thermal_model"):
        BatteryPackParams(thermal_model="fd99")


# -- pack plant ---------------------------------------------------------------------------
def test_ocv_at_rest_and_relaxation_after_pulse():
    b = _pack(soc_init_pct=60.0)
    for k in range(10):
        b.do_step(k * 1.0, 1.0)
    assert b.y["voltage_v"] == pytest.approx(NS * cell.ocv(0.6), abs=1e-12)
    assert b.y["ocv_v"] == pytest.approx(NS * cell.ocv(0.6), abs=1e-12)
    b.u["power_w"] = 60e3
    for k in range(60):
        b.do_step(10 + k, 1.0)
    assert b.y["voltage_v"] < b.y["ocv_v"] - 0.05 * NS   # polarised under load
    b.u["power_w"] = 0.0
    for k in range(400):
        b.do_step(100 + 10 * k, 10.0)                      # 4000 s rest >> tau_2 ~ 400 s
    soc = b.y["soc_pct"] / 100.0
    assert b.y["current_a"] == 0.0
    assert b.y["voltage_v"] / NS == pytest.approx(cell.ocv(soc), abs=1e-4)


def test_step_current_matches_analytical_rc_solution(tmp_path):
    rs, r1, c1, r2, c2 = 0.01, 0.006, 2500.0, 0.008, 37500.0
    b = _pack(tmp_path, const=True, input_mode="current", soc_init_pct=70.0, temperature_dependent=False)
    q = 3600.0 * 2.3
    i_cell = 20.0
    dt = 0.5
    t_on = 120.0
    errs = []
    for k in range(int(600 / dt)):
        t = k * dt
        b.u["current_cmd_a"] = NP * i_cell if t < t_on else 0.0
        b.do_step(t, dt)
        te = t + dt
        if te <= t_on:
            i = i_cell
            v1 = r1 * i_cell * (1 - math.exp(-te / (r1 * c1)))
            v2 = r2 * i_cell * (1 - math.exp(-te / (r2 * c2)))
            soc = 0.7 - i_cell * te / q
        else:
            i = 0.0
            v1 = r1 * i_cell * (1 - math.exp(-t_on / (r1 * c1))) * math.exp(-(te - t_on) / (r1 * c1))
            v2 = r2 * i_cell * (1 - math.exp(-t_on / (r2 * c2))) * math.exp(-(te - t_on) / (r2 * c2))
            soc = 0.7 - i_cell * t_on / q
        v_ref = cell.ocv(soc) - rs * i - v1 - v2
        errs.append(b.y["voltage_v"] / NS - v_ref)
        assert b.y["soc_pct"] == pytest.approx(100 * soc, abs=1e-9)
    assert np.max(np.abs(errs)) < 1e-9


def test_energy_consistency_terminal_equals_chem_minus_loss():
    b = _pack(soc_init_pct=60.0)
    dt = 0.1
    prof = _drive_profile(6000, dt)
    e_term = 0.0
    soc0 = b.y["soc_pct"] / 100.0
    for k, p in enumerate(prof):
        b.u["power_w"] = p
        b.do_step(k * dt, dt)
        e_term += p * dt
    assert b.y["clamp_count"] == 0
    chem, loss = b.y["chem_energy_j"], b.y["loss_energy_j"]
    throughput = np.sum(np.abs(prof)) * dt
    assert loss > 0.0
    assert e_term == pytest.approx(chem - loss, abs=1e-6 * throughput)
    # chem energy = Q n_s n_p int V_oc dSOC, by independent quadrature of the OCV curve
    soc1 = b.y["soc_pct"] / 100.0
    integral, _ = quad(cell.ocv, soc1, soc0, limit=200, points=[0.01 * k for k in range(101)])
    assert chem == pytest.approx(3600 * 2.3 * NS * NP * integral, rel=1e-9, abs=1e-3)


def test_loss_equals_joule_heat_after_relaxation(tmp_path):
    b = _pack(tmp_path, const=True, entropic_heat=False, soc_init_pct=50.0, temperature_dependent=False)
    dt = 0.2
    heat = 0.0
    prof = np.concatenate([_drive_profile(3000, dt, seed=5), np.zeros(int(5000 / dt))])
    for k, p in enumerate(prof):
        b.u["power_w"] = p
        b.do_step(k * dt, dt)
        heat += b.y["heat_w"] * dt * NS * NP
    # capacitor energy returned to zero: overpotential loss == dissipated Joule heat
    assert heat == pytest.approx(b.y["loss_energy_j"], rel=1e-6)


def test_power_to_current_in_plant_and_clamp():
    b = _pack(soc_init_pct=50.0)
    b.u["power_w"] = 40e3
    for k in range(50):
        b.do_step(k * 0.1, 0.1)
    # small step: the plant's current solves P = (V_oc - V1 - V2) i - R_s i^2 at the step start
    voc_eff = b.tables.ocv(b.soc) - b.v1 - b.v2
    rs = b.tables.params(b.soc, b.y["t_mean_c"], 1.0)[0]
    b.u["power_w"] = 80e3
    b.do_step(5.0, 1e-4)
    i_direct = current_from_power(80e3 / (NS * NP), voc_eff, rs)
    assert b.y["current_a"] / NP == pytest.approx(i_direct, rel=1e-4)
    assert b.y["current_a"] * b.y["voltage_v"] == pytest.approx(80e3, rel=1e-4)
    # infeasible demand: clamped at the maximum-power point and counted
    b.u["power_w"] = 5e6
    b.do_step(5.0, 0.1)
    assert b.y["clamp_count"] == 1
    p_del = b.y["current_a"] * b.y["voltage_v"]
    assert 0.0 < p_del < 5e6
    assert b.y["voltage_v"] == pytest.approx(0.5 * b.y["ocv_v"], rel=0.05)   # max power at ~V_oc/2


def test_measurement_noise_statistics():
    b = _pack(seed=7)
    n = 20000
    e = np.empty((n, 4))
    for k in range(n):
        b.do_step(k * 0.1, 0.1)
        y = b.y
        e[k] = (y["cell_current_meas_a"] - y["current_a"] / NP, y["cell_voltage_meas_v"] - y["voltage_v"] / NS,
                y["t_surface_meas_c"] - y["t_surface_c"], y["t_ambient_meas_c"] - b.u["t_ambient_c"])
    sig = np.array([0.003, 0.001, 0.016, 0.016])
    assert np.allclose(e.std(axis=0) / sig, 1.0, atol=0.03)
    assert np.all(np.abs(e.mean(axis=0)) < 4 * sig / math.sqrt(n))
    assert abs(np.corrcoef(e[:-1, 1], e[1:, 1])[0, 1]) < 0.03   # white


def test_save_restore_reproduces_trajectory_including_noise():
    b = _pack()
    prof = _drive_profile(400, 0.1, seed=11)
    for k in range(200):
        b.u["power_w"] = prof[k]
        b.do_step(k * 0.1, 0.1)
    snap = b.get_state()

    def run():
        rows = []
        for k in range(200, 400):
            b.u["power_w"] = prof[k]
            b.do_step(k * 0.1, 0.1)
            rows.append(tuple(b.y.values()))
        return rows

    first = run()
    b.set_state(snap)
    assert run() == first


def test_fd30_and_two_state_agree_and_cooling_fault_heats():
    ts = _pack(thermal_model="two_state")
    fd = _pack(thermal_model="fd30")
    for k in range(3000):
        for b in (ts, fd):
            b.u["power_w"] = 50e3 if (k // 100) % 2 == 0 else -45e3
            b.u["h_conv_w_m2k"] = 20.0 if k < 1500 else 3.0
            b.do_step(k * 0.2, 0.2)
    assert ts.y["t_core_c"] > 30.0
    assert abs(ts.y["t_core_c"] - fd.y["t_core_c"]) < 0.3
    assert abs(ts.y["t_surface_c"] - fd.y["t_surface_c"]) < 0.3
    assert ts.y["t_core_c"] > ts.y["t_surface_c"]


def test_bad_input_names_component_port_and_time():
    b = _pack()
    b.u["power_w"] = float("nan")
    with pytest.raises(SimulationError, match=r"battery.*t=1\.5.*power_w=nan"):
        b.do_step(1.5, 0.1)
    b = _pack(soc_init_pct=1.0)
    b.u["power_w"] = 200e3
    with pytest.raises(SimulationError, match="SOC left"):
        for k in range(1000):
            b.do_step(k * 0.1, 0.1)


@pytest.mark.slow
def test_cell_model_matches_pybamm_thevenin_2rc():
    """Independent reference: PyBaMM's Thevenin ECM (2 RC) with the same tables, isothermal."""
    import importlib.util
    from pathlib import Path

    pytest.importorskip("pybamm")
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "pybamm_thevenin_check.py"
    spec = importlib.util.spec_from_file_location("pybamm_thevenin_check", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    r = mod.compare(900.0)
    # well below the voltage sensor's sigma (1 mV) over a ~1.1 V swing
    assert r["max_abs_v"] < 1e-3
    assert r["rms_v"] < 1e-4
