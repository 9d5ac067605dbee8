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
