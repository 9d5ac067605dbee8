"""The cell model is written once (shevsim.battery.model) and compiled: the compiled and uncompiled forms
agree, the thermal closed form matches scipy's expm, and every effect term does what its physics says."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import expm

from shevsim.battery import model as m
from shevsim.battery.thermal import ThermalParams, zoh, two_state_coeffs, two_state_matrices
from shevsim.components.battery import BatteryPack, BatteryPackParams

EFFECTS_ON = dict(arrhenius_ea_r_k=3500.0, hyst_max_v=0.02, hyst_rate=50.0, current_offset_a=0.05,
                  lowsoc_r_gain=2.0, lowsoc_r_scale_frac=0.1, dudt_soc_frac=(0.0, 0.5, 1.0),
                  dudt_v_k=(-4e-4, 1e-4, 2e-4), h_change_time_s=150.0, h_change_factor=0.3,
                  h_change_width_s=10.0, rs_scale=1.2, c2_scale=0.8, diffusion_time_s=2000.0)


def _with_and_without_jit(code: str) -> dict:
    """Run ``code`` (prints a JSON array) compiled ("0") and with NUMBA_DISABLE_JIT=1 ("1")."""
    res = {}
    for jit in ("0", "1"):
        env = dict(os.environ, NUMBA_DISABLE_JIT=jit)
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
        assert r.returncode == 0, r.stderr
        res[jit] = np.array(json.loads(r.stdout))
    return res


def _drive(b, mode, n, seed=1):
    rng = np.random.default_rng(seed)
    port = "power_w" if mode == "power" else "current_cmd_a"
    scale = 1.0 if mode == "power" else 1.0 / 350.0
    x, out = 0.0, []
    for k in range(n):
        x = max(-150e3, min(300e3, 0.9 * x + rng.normal(0.0, 30e3)))
        b.u[port] = x * scale
        b.u["t_ambient_c"] = 25.0 + 0.001 * k
        b.do_step(0.1 * k, 0.1)
        out.append([b.y[k2] for k2 in ("current_a", "voltage_v", "soc_pct", "t_core_c", "t_surface_c", "heat_w",
                                       "loss_energy_j", "chem_energy_j")])
    return np.array(out)


@pytest.mark.parametrize("mode", ["power", "current"])
@pytest.mark.parametrize("effects", [False, True])
def test_compiled_and_uncompiled_forms_agree(mode, effects):
    prm = BatteryPackParams(input_mode=mode, **(EFFECTS_ON if effects else {}))
    a = _drive(BatteryPack("b", prm), mode, 2500)
    b = _drive(BatteryPack("b", prm, compiled=False), mode, 2500)
    for k in range(a.shape[1]):     # per column: energies in J must not set the tolerance of voltages in V
        np.testing.assert_allclose(a[:, k], b[:, k], rtol=1e-12, atol=1e-12 * np.abs(a[:, k]).max())


def test_component_without_any_jit_agrees_with_the_compiled_component():
    """The battery component stepped with NUMBA_DISABLE_JIT=1 (every function its Python source) vs compiled."""
    code = r"""
import json, numpy as np
from shevsim.components.battery import BatteryPack, BatteryPackParams
b = BatteryPack("b", BatteryPackParams(hyst_max_v=0.01, arrhenius_ea_r_k=3000.0, h_change_factor=0.5,
                                       h_change_time_s=60.0, h_change_width_s=5.0, dudt_soc_frac=(0.2, 0.8),
                                       dudt_v_k=(-3e-4, 2e-4)))
rng = np.random.default_rng(2); out = []
for k in range(1500):
    b.u["power_w"] = float(rng.uniform(-60e3, 90e3)); b.do_step(0.1 * k, 0.1)
    out.append([b.y[n] for n in ("current_a", "voltage_v", "soc_pct", "t_core_c", "t_surface_c", "heat_w")])
print(json.dumps(out))
"""
    res = _with_and_without_jit(code)
    for k in range(res["0"].shape[1]):
        np.testing.assert_allclose(res["0"][:, k], res["1"][:, k], rtol=1e-12, atol=1e-12 * np.abs(res["0"][:, k]).max())


def test_ecm_lookup_compiled_equals_its_source_and_the_table_rows():
    from shevsim.battery.cell import CellTables
    from shevsim.core.lookup import ecm_lookup
    tab = CellTables()
    d, ix = tab.packed()
    rng = np.random.default_rng(0)
    for _ in range(2000):
        args = (float(rng.uniform(-0.1, 1.1)), float(rng.uniform(-30.0, 70.0)), float(rng.choice([-1.0, 1.0])))
        assert ecm_lookup(d, ix, *args) == ecm_lookup.py_func(d, ix, *args)
    # at a grid node the lookup returns the table row (independent of the interpolation)
    g = tab._dch
    assert ecm_lookup(d, ix, g.socs[3], g.temps[2], 1.0) == pytest.approx(tuple(g.vals[2][3]), rel=1e-15)


def test_profile_loop_without_any_jit_agrees_with_the_compiled_loop():
    """The loop the calibration runs, compiled vs NUMBA_DISABLE_JIT=1 (no compiled function at all)."""
    code = r"""
import json, numpy as np
from shevsim.battery import model as m
from shevsim.battery.cell import CellTables
from shevsim.components.battery import BatteryPackParams
prm = BatteryPackParams(n_series=1, n_parallel=1, input_mode="current", arrhenius_ea_r_k=3000.0, hyst_max_v=0.01,
                        dudt_soc_frac=(0.0, 1.0), dudt_v_k=(-3e-4, 2e-4), h_change_factor=0.5, h_change_time_s=50.0,
                        h_change_width_s=5.0)
d, ix = CellTables().packed()
c = m.pack_params(prm)
t = np.cumsum(np.r_[0.0, np.full(999, 0.1) + 0.01 * np.sin(np.arange(999))])
i = 3.0 * np.sin(t / 7.0) + 1.0
st = np.zeros(m.N_STATE); st[m.S_SOC] = 0.6; st[m.S_X0] = 25.0
ov, ots, otc = np.empty(t.size), np.empty(t.size), np.empty(t.size)
m.run_profile(d, ix, c, st, t, i, np.full(t.size, 25.0), 20.0, ov, ots, otc)
print(json.dumps([ov.tolist(), ots.tolist(), otc.tolist()]))
"""
    res = _with_and_without_jit(code)
    np.testing.assert_allclose(res["0"], res["1"], rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("h", [0.0, 0.5, 20.0, 300.0])
@pytest.mark.parametrize("dt", [1e-3, 0.1, 10.0, 600.0])
def test_two_state_closed_form_zoh_matches_expm(h, dt):
    p = ThermalParams()
    A, B, C, D = two_state_matrices(p, h)
    Ad, Bd = zoh(A, B, dt)
    c = two_state_coeffs(p.radius_m, p.length_m, p.density_kg_m3, p.cp_j_kgk, p.kt_w_mk, h, dt)
    assert np.allclose(c[:4], Ad.ravel(), rtol=1e-12, atol=1e-13)
    assert np.allclose(c[4:8], Bd.ravel(), rtol=1e-11, atol=1e-12 * np.abs(Bd).max())
    assert c[8:] == pytest.approx([C[0, 0], C[0, 1], D[0, 1], C[1, 0], C[1, 1], D[1, 1]], rel=1e-15)
    # and expm of the augmented matrix directly (independent of zoh's construction)
    M = np.zeros((4, 4)); M[:2, :2] = A; M[:2, 2:] = B
    assert np.allclose(expm(M * dt)[:2, :2].ravel(), c[:4], rtol=1e-12, atol=1e-13)


def _cell(**kw):
    base = dict(n_series=1, n_parallel=1, input_mode="current", soc_init_pct=80.0, sigma_current_a=0.0,
                sigma_voltage_v=0.0, sigma_temperature_c=0.0)
    base.update(kw)
    return BatteryPack("c", BatteryPackParams(**base))


def _hold(b, i_a, seconds, h=1.0, t0=0.0):
    b.u["current_cmd_a"] = i_a
    for k in range(int(seconds / h)):
        b.do_step(t0 + k * h, h)
    return b


def test_capacity_and_current_offset_act_on_coulomb_counting_exactly():
    for cap, off in ((2.3, 0.0), (1.7, 0.0), (2.3, 0.2)):
        b = _hold(_cell(capacity_ah=cap, current_offset_a=off), 2.0, 600.0)
        expect = 80.0 - 100.0 * (2.0 - off) * 600.0 / (3600.0 * cap)
        assert b.y["soc_pct"] == pytest.approx(expect, rel=1e-12)
        assert b.y["current_a"] == pytest.approx(2.0 - off, rel=1e-12)
        assert b.y["cell_current_meas_a"] == pytest.approx(2.0, rel=1e-12)   # the sensor reads true + offset


def test_entropic_knots_add_exactly_the_reversible_heat():
    kw = dict(entropic_heat=False)
    plain, rev = _cell(**kw), _cell(dudt_soc_frac=(0.0, 1.0), dudt_v_k=(-5e-4, -5e-4), **kw)
    for b in (plain, rev):
        b.u["current_cmd_a"] = 3.0
        b.do_step(0.0, 1.0)
    t_k = 25.0 + 273.15
    assert rev.y["heat_w"] - plain.y["heat_w"] == pytest.approx(-3.0 * t_k * -5e-4, rel=1e-9)
    # a sign change in SOC: discharge through the knot flips the sign of the reversible heat
    c = m.pack_params(BatteryPackParams(dudt_soc_frac=(0.2, 0.8), dudt_v_k=(-1e-3, 1e-3)))
    assert m._dudt.py_func(c, 0.5) == pytest.approx(0.0, abs=1e-18)
    assert m._dudt.py_func(c, 0.1) == -1e-3 and m._dudt.py_func(c, 0.9) == 1e-3


def test_arrhenius_is_identity_at_the_reference_and_scales_every_resistance_when_cold():
    plain, ref = _cell(), _cell(arrhenius_ea_r_k=4000.0, arrhenius_t_ref_c=25.0)
    for b in (plain, ref):
        _hold(b, 4.0, 1.0)     # one step: the mean temperature is exactly T_ref during it
    assert ref.y["voltage_v"] == pytest.approx(plain.y["voltage_v"], rel=1e-12)
    cold = _cell(temperature_dependent=False, arrhenius_ea_r_k=4000.0)
    y = np.zeros(m.N_OUT)
    m.cell_electrical.py_func(cold._d, cold._ix, cold._c, cold.st.copy(), 4.0, 1e-6, 0.0, y)
    rs_base = cold.tables.params(0.8, 25.0, 1.0)[0]
    assert y[m.Y_RS] / rs_base == pytest.approx(math.exp(4000.0 * (1 / 273.15 - 1 / 298.15)), rel=1e-12)


def test_hysteresis_converges_to_minus_m_on_discharge_and_second_branch_can_be_removed():
    b = _hold(_cell(hyst_max_v=0.03, hyst_rate=200.0), 2.0, 1200.0)
    assert b.st[m.S_HY] == pytest.approx(-1.0, abs=1e-6)
    nb = _hold(_cell(hyst_max_v=0.0), 2.0, 1200.0)
    assert nb.y["voltage_v"] - b.y["voltage_v"] == pytest.approx(0.03, rel=1e-4)
    one = _hold(_cell(r2_scale=0.0), 2.0, 100.0)
    assert one.v2 == 0.0 and one.v1 > 0.0


def test_low_soc_resistance_rise_and_convection_change():
    hi, lo = _cell(soc_init_pct=90.0, lowsoc_r_gain=3.0, lowsoc_r_scale_frac=0.05), _cell(soc_init_pct=5.0, lowsoc_r_gain=3.0, lowsoc_r_scale_frac=0.05)
    c = m.pack_params(lo.params)
    y = np.zeros(m.N_OUT)
    for b, soc in ((hi, 0.9), (lo, 0.05)):
        st = b.st.copy()
        m.cell_electrical.py_func(b._d, b._ix, c, st, 1.0, 1e-6, 25.0, y)
        rs_base = b.tables.params(soc, 25.0, 1.0)[0]
        assert y[m.Y_RS] / rs_base == pytest.approx(1.0 + 3.0 * math.exp(-soc / 0.05), rel=1e-6)
    c = m.pack_params(BatteryPackParams(h_change_time_s=100.0, h_change_factor=0.25, h_change_width_s=0.0))
    assert m.effective_h(c, 99.9, 20.0) == 20.0 and m.effective_h(c, 100.0, 20.0) == 5.0
    # a step change equals the same change applied to the convection input (the fault mechanism)
    a, f = _cell(), _cell(h_change_time_s=300.0, h_change_factor=0.2)
    for k in range(900):
        for b in (a, f):
            b.u["current_cmd_a"] = 6.0
            b.u["h_conv_w_m2k"] = 20.0 if (b is f or k < 300) else 4.0
            b.do_step(float(k), 1.0)
    assert f.y["t_surface_c"] == pytest.approx(a.y["t_surface_c"], rel=1e-12)
    assert f.y["t_core_c"] == pytest.approx(a.y["t_core_c"], rel=1e-12)


def test_neutral_effect_parameters_are_bit_identical_to_the_plain_model():
    neutral = dict(arrhenius_ea_r_k=0.0, hyst_max_v=0.0, current_offset_a=0.0, lowsoc_r_gain=0.0,
                   dudt_soc_frac=(), dudt_v_k=(), h_change_factor=1.0, rs_scale=1.0, r2_scale=1.0, h_conv_factor=1.0,
                   diffusion_time_s=0.0)
    a = _drive(BatteryPack("b", BatteryPackParams()), "power", 800)
    b = _drive(BatteryPack("b", replace(BatteryPackParams(), **neutral)), "power", 800)
    assert np.array_equal(a, b)
    # and every effect switched on changes the trajectory (the switch is wired)
    for k, v in EFFECTS_ON.items():
        if k in ("h_change_time_s", "h_change_width_s", "dudt_soc_frac", "lowsoc_r_scale_frac", "hyst_rate",
                 "current_offset_a"):    # the offset acts in current mode (test_capacity_and_current_offset...)
            continue
        on = dict(EFFECTS_ON) if k in ("dudt_v_k", "h_change_factor", "hyst_max_v", "lowsoc_r_gain") else {k: v}
        if k == "dudt_v_k":
            on = {"dudt_soc_frac": EFFECTS_ON["dudt_soc_frac"], "dudt_v_k": v}
        elif k == "h_change_factor":
            on = {"h_change_factor": v, "h_change_time_s": 20.0, "h_change_width_s": 0.0}
        elif k == "hyst_max_v":
            on = {"hyst_max_v": v, "hyst_rate": EFFECTS_ON["hyst_rate"]}
        elif k == "lowsoc_r_gain":
            on = {"lowsoc_r_gain": v, "lowsoc_r_scale_frac": 0.5}
        c = _drive(BatteryPack("b", replace(BatteryPackParams(), **on)), "power", 800)
        assert not np.array_equal(a, c), k


def test_bad_effect_parameters_are_refused_with_the_field_name():
    from shevsim.core.errors import ScenarioError
    for bad in (dict(hyst_max_v=float("nan")), dict(dudt_soc_frac=(0.0, 1.0), dudt_v_k=(1e-4,)),
                dict(rs_scale=0.0), dict(arrhenius_ea_r_k=-1.0), dict(dudt_soc_frac=(0.5, 0.2), dudt_v_k=(0.0, 0.0))):
        with pytest.raises(ScenarioError, match="battery parameters"):
            BatteryPackParams(**bad)
