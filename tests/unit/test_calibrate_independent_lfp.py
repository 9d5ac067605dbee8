"""The flat-OCV LFP cell records of ``tests/data/independent/`` (issue 24, "Real cells"), made by PyBaMM's SPMe
with the ``Prada2013`` set (A123 26650) by ``make_cell_pybamm_lfp.py``: are they what the generator says, and
what does the calibration do on them?

The records hold the issue's two LFP problems in a cell shevsim did not make: an initial SOC that the first
rest voltage cannot give (the OCV's plateau: 0.2-0.4 mV per % of SOC), and a user's OCV table that is not the
cell's (a C/20 discharge).  The truth is checked against PyBaMM's own electrode potentials, independently of
shevsim and of the generator's code.
"""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pybamm_reference import equilibrium_ocv

D = Path(__file__).resolve().parents[1] / "data" / "independent"
CASES = ["none", "none_2", "plateau", "plateau_2", "ocv_c20"]
PHYSICAL_CELL = {"entropic_heat", "arrhenius_resistance", "cooling_change", "ocv_hysteresis", "capacity",
                 "current_offset", "low_soc_resistance", "second_rc_branch", "initial_soc", "ocv_correction",
                 "solid_diffusion"}


def _truth() -> dict:
    return json.loads((D / "cell_lfp_truth.json").read_text())


def _table(name: str = "cell_lfp_nominal.toml"):
    nom = tomllib.loads((D / name).read_text())
    return np.array(nom["ocv"]["soc_frac"]), np.array(nom["ocv"]["ocv_v"]), nom


def _equilibrium(soc_table, q_ah: float) -> np.ndarray:
    """PyBaMM's Prada2013 equilibrium OCV at the nominal table's SOC (:func:`pybamm_reference.equilibrium_ocv`)."""
    return equilibrium_ocv("Prada2013", soc_table, q_ah, 2.3)


@pytest.mark.parametrize("case", CASES)
def test_lfp_records_are_one_hour_at_1_hz_with_the_stated_noise(case):
    truth = _truth()
    assert set(truth["cases"]) == set(CASES)
    df = pd.read_csv(D / f"cell_lfp_{case}.csv", comment="#")
    t = df["time_s"].to_numpy()
    assert np.all(np.diff(t) == 1.0) and t[-1] - t[0] == 3600.0
    v0 = df["voltage_v"].to_numpy()[:60]                 # the first minute at rest: the logger's noise
    assert np.std(v0) == pytest.approx(truth["noise"]["voltage_v"], rel=0.3)
    i = df["current_a"].to_numpy()
    assert i.max() > 3.5 and i.min() < -1.5               # pulses up to 2C and -1C of 2.3 A.h
    lo, hi = truth["cases"][case]["soc_table_range"]
    assert 0.2 < hi - lo < 0.5 and lo > 0.1               # a drive's swing, never near empty
    if truth["cases"][case]["protocol"] == "stops":       # three 300 s rest stops: the sensor's noise only
        for a in (940, 2120, 3300):
            rest = i[(t >= a + 5) & (t < a + 300)]
            assert abs(rest.mean()) < 0.002 and rest.std() == pytest.approx(truth["noise"]["current_a"], rel=0.3)


def test_lfp_nominal_ocv_is_flat_on_its_plateaus_and_steep_on_its_steps():
    soc, v, nom = _table()
    assert nom["params"]["soc0_frac"] == -1.0 and nom["params"]["capacity_ah"] == 2.3 and soc.size == 101
    assert np.all(np.diff(v) > 0.0)                        # invertible: the rest voltage gives *a* SOC

    def slope_mv_per_pct(a, b):
        k = (soc >= a - 1e-9) & (soc <= b + 1e-9)
        return 1e3 * np.polyfit(100.0 * soc[k], v[k], 1)[0]
    assert slope_mv_per_pct(0.52, 0.68) < 0.6               # the plateaus: < 0.6 mV per % of SOC
    assert slope_mv_per_pct(0.83, 0.95) < 0.6
    assert slope_mv_per_pct(0.72, 0.80) > 2.5               # the staging step the no-effect records start on


def test_lfp_tables_are_the_cells_equilibrium_less_the_discharge_overpotential():
    """The C/50 table lies 1.5-3.5 mV below PyBaMM's equilibrium OCV over the SOC the records visit, the C/20 one
    about 2.5x lower; the truth's OCV-correction knots are equilibrium - C/20 table there."""
    truth = _truth()
    q = truth["pseudo_ocv_capacity_ah"]
    assert q == pytest.approx(2.3, abs=0.01)               # Prada2013's C/50 capacity is the A123's rating
    soc, v, _ = _table()
    k = (soc >= 0.3) & (soc <= 0.92)
    d50 = v[k] - _equilibrium(soc[k], q)
    assert -3.5e-3 < d50.min() and d50.max() < -1.5e-3, np.round(1e3 * d50, 2)
    soc20, v20, _ = _table("cell_lfp_nominal_c20.toml")
    k = (soc20 >= 0.3) & (soc20 <= 0.92)
    d20 = v20[k] - _equilibrium(soc20[k], q)
    assert -8.5e-3 < d20.min() and d20.max() < -4.0e-3 and d20.mean() < 2.0 * d50.mean()
    tr = truth["cases"]["ocv_c20"]["truth"]
    ks = np.array(tr["ocv_delta_knots_soc_frac"])
    assert np.allclose(tr["ocv_delta_knots_v"], _equilibrium(ks, q) - np.interp(ks, soc20, v20), atol=2e-5)


@pytest.mark.parametrize("case", CASES)
def test_lfp_initial_soc_truth_is_the_first_rest_voltage_at_equilibrium(case):
    """The truth's initial SOC (the nominal table's terms) is where PyBaMM's equilibrium OCV is the record's
    first-minute rest voltage (the cell starts relaxed): within the logger's noise over 60 samples."""
    truth = _truth()
    tr = truth["cases"][case]["truth"]
    v0 = pd.read_csv(D / f"cell_lfp_{case}.csv", comment="#")["voltage_v"].to_numpy()[:60].mean()
    eq = _equilibrium(tr["soc_init_pct"] / 100.0, truth["pseudo_ocv_capacity_ah"])[0]
    assert v0 == pytest.approx(eq, abs=4.0 * truth["noise"]["voltage_v"] / np.sqrt(60.0))


def test_the_plateau_starts_rest_voltage_gives_the_wrong_soc_the_step_starts_the_right_one():
    """The premise of the plateau records: the first rest voltage through the user's (C/50) table gives the
    SOC to about a point on the OCV's step and 5-7 points off on its plateau (the table's 2.2 mV offset over
    a slope of 0.3-0.4 mV per %)."""
    soc, v, _ = _table()
    for case in CASES:
        tr = _truth()["cases"][case]["truth"]
        name = "cell_lfp_nominal_c20.toml" if case == "ocv_c20" else "cell_lfp_nominal.toml"
        s_tab, v_tab, _ = _table(name)
        v0 = pd.read_csv(D / f"cell_lfp_{case}.csv", comment="#")["voltage_v"].to_numpy()[:60].mean()
        err = 100.0 * float(np.interp(v0, v_tab, s_tab)) - tr["soc_init_pct"]
        assert err == pytest.approx(tr["soc_from_rest_voltage_pct"] - tr["soc_init_pct"], abs=0.5)
        if case.startswith("plateau"):
            assert err > 4.0, (case, err)
        elif case.startswith("none"):
            assert abs(err) < 1.5, (case, err)


def test_the_report_says_where_the_first_rest_cannot_give_the_initial_soc():
    """The record's resolution (CellModel.record_resolution): the SOC interval that the first rest voltage
    +- 2 mV (a C/50 pseudo-OCV's own overpotential: 1.8-3.3 mV on this cell, the generator's measurement) gives
    through the user's table.  On the plateau starts it is wide, contains the truth, and the report says the
    drive cannot give the SOC; on the step starts it is narrow and nothing is said."""
    from shevsim.calibrate.cell import CellModel
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    for case in ("plateau", "plateau_2", "none", "none_2"):
        m = CellModel(load_params_toml(D / "cell_lfp_nominal.toml"))
        m.prepare(load_measured(str(D / f"cell_lfp_{case}.csv"), "cell"))
        res = m.record_resolution()
        lo, hi = res["initial_soc_from_first_rest"]["soc_pct_interval"]
        truth = _truth()["cases"][case]["truth"]["soc_init_pct"]
        flat = "flat part of the OCV table" in res["statement"]
        if case.startswith("plateau"):
            assert flat and hi - lo > 4.0 and lo <= truth <= hi, (case, lo, hi, truth)
        else:
            assert not flat and hi - lo < 4.0, (case, lo, hi)


# ------------------------------------------------------------------ the calibration on them
def _lfp(case: str, effects=None):
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    from shevsim.calibrate.workflow import run_workflow
    data = load_measured(str(D / f"cell_lfp_{case}.csv"), "cell")
    return run_workflow("cell", data, load_params_toml(D / _truth()["cases"][case]["nominal"]), plots=False,
                        effects=effects)


def _check_no_effect(rep):
    assert not set(rep["selected_effects"]) & PHYSICAL_CELL, rep["selected_effects"]
    # an SPMe LFP cell is not an equivalent circuit (its graphite's slow diffusion through a staged OCV): the
    # nominal's ~10 mV voltage residual, about 10x the sensor noise, is stated as a model-form discrepancy
    # whenever it is a baseline failure (10x the combined floor, the workflow's rule: `none` 10.0x; `none_2`
    # is just below it and states none - the test asserted the statement on both until the slow run showed
    # none_2 at the rule's edge)
    failed = any(b["channel"] == "voltage_v" for b in rep["baseline_failure"])
    stated = any(d.get("channel") == "voltage_v" for d in rep["model_form_discrepancy"])
    assert stated == failed, (rep["baseline_failure"], rep["model_form_discrepancy"])
    assert rep["rmse_before"]["voltage_v"]["holdout"] > 5.0 * 1e-3      # far above the 1 mV sensor noise either way


def test_lfp_no_effect_record_names_neither_an_initial_soc_nor_an_ocv_correction():
    """The default run: the two effects of a flat OCV, on the record that starts on the OCV's step (where the
    rest voltage gives the SOC) - neither is named, and the circuit's form error is stated."""
    _check_no_effect(_lfp("none", effects=["initial_soc", "ocv_correction"]))


@pytest.mark.slow
@pytest.mark.parametrize("case", ["none", "none_2"])
def test_lfp_no_effect_records_whole_library_name_no_physical_effect(case):
    _check_no_effect(_lfp(case))


# Not in the default run: the calibration does not do this yet (measured at this commit, the whole library:
# nothing named on either record; the initial_soc candidate's fit 53.8 % on `plateau`, truth 60.1 %, rest
# voltage 66.7 %, held-out gain 4 %; 87.5 % on `plateau_2`, truth 90.0 %, rest voltage 94.9 %, gain 11 %,
# dBIC -7 > -10 - against the nominal's 10-40 mV model-form error).  A failing test, not an xfail.
# Why, measured afterwards in PyBaMM (docs/calibration_independent.md, the LFP section): under load the
# graphite's surface SOC lags its bulk by 4-9 points (Prada2013 graphite R^2/D = 8300 s; lag ~ C-rate R^2/(15 D)),
# and the OCV step the voltage shows is the surface's, so a loaded drive places it several points early; the
# initial SOC fitted freely lands 2.5-6 points low (53.8 / 87.5 %), and a diffusion term beside the circuit
# (OCV read at SOC - g lag(i/Q, tau)) improves the voltage (42 -> 18 mV on `plateau`) but is confounded with the
# initial SOC over a steady discharge.  The 2-point tolerance assumes a step under load shows the SOC to the
# table's 0.6 point; the drive cannot - relaxed rests on a step (>~30 min here) can.  Kept as the open case.
@pytest.mark.slow
@pytest.mark.parametrize("case", ["plateau", "plateau_2"])
def test_lfp_plateau_start_names_initial_soc_within_2_points(case):
    """On the OCV's plateau the first rest voltage gives the SOC 5-7 points off; the drive crosses an OCV step
    where the voltage shows the SOC to 0.6 point (the C/50 table's 2.2 mV offset over 3.6 mV per %):
    initial_soc named and within 2 points."""
    rep = _lfp(case)
    assert "initial_soc" in rep["selected_effects"], rep["selected_effects"]
    assert rep["final_parameters"]["soc_init_pct"] == pytest.approx(_truth()["cases"][case]["truth"]["soc_init_pct"],
                                                                    abs=2.0)


# Not in the default run either (measured: nothing named; the ocv_correction candidate's knots +1.4, +2.8,
# +10.0, -9.9, -12.9 mV against the truth's +4.7, +4.5, +4.5, +5.7, +6.8 mV, held-out gain 10 %, dBIC +8).
@pytest.mark.slow
def test_lfp_c20_table_names_an_ocv_correction_near_the_tables_error():
    rep = _lfp("ocv_c20")
    assert "ocv_correction" in rep["selected_effects"], rep["selected_effects"]
    true = np.array(_truth()["cases"]["ocv_c20"]["truth"]["ocv_delta_knots_v"])
    fit = np.array([rep["final_parameters"][f"ocv_delta_v[{k}]"] for k in range(true.size)])
    assert np.sqrt(np.mean((fit - true) ** 2)) < 0.5 * np.sqrt(np.mean(true ** 2))
