"""Seed Ch. IV lumped cell (eq. 4.2) and its thermal current limit (4.10-4.13), and the Fig. 4.9 analogue.

References independent of the code under test: scipy's ODE integrator for the plant, the thesis's own
step-by-step recursion (4.10-4.11) for the limit, and the thesis's published Fig. 4.9 numbers.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from shevsim.bms.lumped import KELVIN, LumpedCell, step_exact, thermal_current_limits
from shevsim.core.errors import ScenarioError
from shevsim.studies.ch4_study import THESIS_FIG_4_9, fig_4_9

CELL = LumpedCell(mass_kg=0.045, cp_j_kgk=1248.0, area_m2=4.18e-3, r_e_ohm=0.17, ds_j_molk=-30.0)


def test_plant_step_matches_an_ode_integrator_with_the_entropic_term():
    t0, i_a, dt, h, t_amb = 31.0, 4.5, 250.0, 6.0, 25.0
    mcp = CELL.mass_kg * CELL.cp_j_kgk

    def rhs(_t, y):
        t_k = y[0]
        return [(-h * CELL.area_m2 * (t_k - t_amb - KELVIN) + i_a ** 2 * CELL.r_e_ohm
                 - i_a * t_k * CELL.ds_j_molk / 96485.3365) / mcp]

    sol = solve_ivp(rhs, (0.0, dt), [t0 + KELVIN], rtol=1e-11, atol=1e-11)
    assert step_exact(CELL, t0, i_a, dt, h, t_amb) == pytest.approx(sol.y[0, -1] - KELVIN, abs=1e-7)


@pytest.mark.parametrize("t_now_c", [26.0, 40.0, 44.9])
def test_discharge_limit_puts_the_eulers_model_on_t_max_after_n_steps(t_now_c):
    """Iterate the thesis's discrete model (4.10-4.11) with the limit held: T lands on T_max at step N."""
    n, dt, h, t_amb, t_max = 100, 0.1, 6.0, 25.0, 45.0
    i_dch, i_chg = thermal_current_limits(CELL, t_now_c, t_max, n, dt, h, t_amb)
    alpha, beta, gamma, eta = CELL.coefficients(h, t_amb)
    for i_lim in (i_dch, i_chg):
        x = t_now_c + KELVIN
        beta_bar = beta * (t_now_c + KELVIN)      # held over the horizon, as in the thesis
        for _ in range(n):
            x = (1.0 + alpha * dt) * x + dt * (beta_bar * i_lim + gamma * i_lim ** 2 + eta)
        assert x - KELVIN == pytest.approx(t_max, abs=1e-9)
    assert i_dch > 0.0 > i_chg


def test_no_current_can_hold_a_cell_already_far_above_the_limit():
    i_dch, i_chg = thermal_current_limits(CELL, 80.0, 45.0, 100, 0.1, 6.0, 25.0)
    assert i_dch == i_chg                           # least-heating current when no root exists
    assert abs(i_dch) < 1.0


def test_bad_cell_is_refused_naming_the_field():
    with pytest.raises(ScenarioError, match="r_e_ohm"):
        LumpedCell(mass_kg=0.045, cp_j_kgk=1248.0, area_m2=4e-3, r_e_ohm=float("nan"))


def test_fig_4_9_analogue_predicts_the_limited_completion_from_the_unlimited_peak(tmp_path):
    res = fig_4_9(tmp_path)
    main = res["runs"][0]
    # inferred from the thesis's unlimited peak; the unlimited completion follows from the current
    assert main["t_peak_unlimited_c"] == pytest.approx(THESIS_FIG_4_9["t_peak_unlimited_c"], abs=1e-3)
    assert main["completion_unlimited_s"] == pytest.approx(THESIS_FIG_4_9["completion_unlimited_s"], abs=0.2)
    # the prediction: the limit holds 45 degC and the completion time is the thesis's within 15 %
    assert main["t_peak_limited_c"] <= 45.0 + 0.05
    assert main["completion_limited_s"] == pytest.approx(THESIS_FIG_4_9["completion_limited_s"], rel=0.15)
    assert (tmp_path / "fig_4_9.json").is_file() and (tmp_path / "fig_4_9.png").is_file()


# ---------------------------------------------------------------- Fig. 4.10 analogue: power capability (4.16-4.19)
def _ocv_csv_by_hand():
    """The shipped OCV table read with numpy alone (not with the code under test)."""
    from shevsim.studies.ch4_study import LCO_OCV_CSV
    lines = [ln for ln in LCO_OCV_CSV.read_text().splitlines() if ln and not ln.startswith("#")]
    assert lines[0] == "soc_frac,ocv_v"
    data = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    return data[:, 0], data[:, 1]


def test_lco_ocv_table_rises_with_soc_over_lco_range():
    soc, ocv = _ocv_csv_by_hand()
    assert soc[0] == 0.0 and soc[-1] == 1.0 and np.all(np.diff(soc) > 0.0)
    assert np.all(np.diff(ocv) > 0.0)                       # strictly monotonic in SOC
    assert 2.7 <= ocv[0] <= 3.1 and 4.1 <= ocv[-1] <= 4.25   # LiCoO2/graphite window, about 3.0-4.2 V
    assert 3.6 < np.interp(0.5, soc, ocv) < 3.95             # LCO's mid-SOC plateau


def test_ocv_table_refuses_a_falling_column(tmp_path):
    from shevsim.bms.lumped import OcvTable
    from shevsim.core.errors import DataError
    bad = tmp_path / "ocv.csv"
    bad.write_text("soc_frac,ocv_v\n0.0,3.0\n0.5,3.9\n1.0,3.8\n")
    with pytest.raises(DataError, match="ocv_v"):
        OcvTable(bad)


@pytest.fixture(scope="module")
def fig_4_10_run(tmp_path_factory):
    from shevsim.studies.ch4_study import fig_4_10
    out = tmp_path_factory.mktemp("fig_4_10")
    res = fig_4_10(out)
    assert (out / "fig_4_10.json").is_file() and (out / "fig_4_10.png").is_file()
    return res


def test_fig_4_10_limits_hold_and_each_constraint_sets_the_capability(fig_4_10_run):
    res = fig_4_10_run
    tr, st = res["_traces"], res["settings"]
    lim = tr["limit"]
    # each of the three constraints sets the capability (below the request) at some time
    for code in (1, 2, 3):
        assert np.any(lim == code), code
    # the thesis's order of first action: voltage, then temperature, then SOC
    assert res["order"] == ["voltage", "temperature", "soc"]
    assert lim[0] == 0                                          # every constraint inactive at first
    v_on = lim == 2
    assert tr["voltage_v"][v_on].min() >= st["v_min_v"] - 5e-3
    assert tr["voltage_v"].min() >= st["v_min_v"] - 5e-3
    assert tr["temperature_c"].max() <= st["t_max_c"] + 0.02
    assert tr["soc_frac"].min() >= st["soc_min_frac"] - 1e-3
    # the drawn power never exceeds either the request or the capability
    assert np.all(tr["power_drawn_w"] <= np.minimum(tr["power_request_w"], tr["power_capability_w"]) + 1e-9)
    # the request's mean over whole periods is the cell's 1C power (the stated rule)
    n_per = int(round(st["pulse_period_s"] / st["dt_s"]))
    whole = (tr["power_request_w"].size // n_per) * n_per
    assert tr["power_request_w"][:whole].mean() == pytest.approx(st["p_1c_w"], rel=1e-9)


def test_fig_4_10_voltage_active_step_puts_the_predicted_voltage_on_v_min(fig_4_10_run):
    """The thesis's definition (4.16b, 4.19a): at I_max the terminal voltage after N steps is V_min; computed here
    by hand from the OCV CSV (read with numpy) and R_e, without the code's linearisation."""
    res = fig_4_10_run
    tr, st = res["_traces"], res["settings"]
    soc_tab, ocv_tab = _ocv_csv_by_hand()
    ks = np.flatnonzero(tr["limit"] == 2)
    assert ks.size > 0
    for k in ks[[0, ks.size // 2, -1]]:
        soc, p_cap = tr["soc_frac"][k], tr["power_capability_w"][k]
        # the capability is I_max * V_{k+N}; with V_{k+N} = V_min, I_max = P_cap / V_min
        i_max = p_cap / st["v_min_v"]
        soc_n = soc - i_max * st["horizon_steps"] * st["dt_s"] / (3600.0 * st["capacity_ah"])
        v_n = np.interp(soc_n, soc_tab, ocv_tab) - i_max * st["r_e_ohm"]
        assert v_n == pytest.approx(st["v_min_v"], abs=2e-3)
