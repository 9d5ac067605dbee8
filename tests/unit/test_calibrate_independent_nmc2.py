"""A second NMC cell the calibration was never developed on (issue 24): PyBaMM's SPMe with the ``Ecker2015`` set
(Kokam SLPB 75106100, NMC / graphite pouch, 7.5 A.h), records made by ``make_cell_pybamm_nmc2.py``.

The default run holds the shipped records to the cell's own physics, independently of shevsim and of the
generator's code: PyBaMM's electrode potentials and electrode loadings of the published set, the pouch's
stated size, and the logger's stated sampling and noise.  The calibration with the whole effect library
(``slow``) is asked what the issue asks of every generator: on a no-effect record no physical effect is named;
on a one-effect record that effect is named with its parameter within the tolerances of the Chen2020 rows
(capacity 5 %, current offset 25 %).
"""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pybamm_reference import equilibrium_ocv

D = Path(__file__).resolve().parents[1] / "data" / "independent"
SWING = ["none_swing", "capacity_swing", "current_offset_swing"]
DRIVE = ["none"]
PHYSICAL_CELL = {"entropic_heat", "arrhenius_resistance", "cooling_change", "ocv_hysteresis", "capacity",
                 "current_offset", "low_soc_resistance", "second_rc_branch", "initial_soc", "ocv_correction",
                 "solid_diffusion"}
RATED_AH = 7.5
F_C_MOL = 96485.33212


def _truth() -> dict:
    return json.loads((D / "cell_nmc2_truth.json").read_text())


def _record(case: str) -> pd.DataFrame:
    return pd.read_csv(D / f"cell_nmc2_{case}.csv", comment="#")


def _nominal() -> dict:
    return tomllib.loads((D / "cell_nmc2_nominal.toml").read_text())


def _equilibrium(soc_table, q_ah: float) -> np.ndarray:
    """PyBaMM's Ecker2015 equilibrium OCV at the nominal table's SOC (:func:`pybamm_reference.equilibrium_ocv`)."""
    return equilibrium_ocv("Ecker2015", soc_table, q_ah, RATED_AH)


# ------------------------------------------------------------------ the records (default run)

@pytest.mark.parametrize("case", SWING + DRIVE)
def test_nmc2_records_are_at_1_hz_with_the_stated_noise_and_protocol(case):
    truth = _truth()
    assert set(truth["cases"]) == set(SWING + DRIVE)
    c = truth["cases"][case]
    df = _record(case)
    t, i = df["time_s"].to_numpy(), df["current_a"].to_numpy()
    assert np.all(np.diff(t) == 1.0) and t[-1] - t[0] == (7200.0 if case in SWING else 3600.0)
    assert c["protocol"] == ("swing" if case in SWING else "drive")
    # the first minute at rest: the logger's voltage noise (PyBaMM's cell is relaxed there)
    assert np.std(df["voltage_v"].to_numpy()[:60]) == pytest.approx(truth["noise"]["voltage_v"], rel=0.3)
    assert np.std(df["t_surface_c"].to_numpy()[:60]) == pytest.approx(truth["noise"]["t_surface_c"], rel=0.3)
    off = c["truth"]["current_offset_a"]
    if case in SWING:
        # pulses up to 1.6C and -0.7C of 7.5 A.h; a 10 min rest stop after each 30 min block, where the logged
        # current is the sensor's offset and noise only; a wide SOC swing (half the rated capacity or more)
        assert i.max() > 10.5 and i.min() < -3.75
        for a, b in ((1860, 2460), (4260, 4860), (6660, 7200)):
            rest = i[(t >= a) & (t < b)]
            assert abs(rest.mean() - off) < 0.002 and rest.std() == pytest.approx(truth["noise"]["current_a"], rel=0.3)
        assert 0.45 < np.sum(i - off) / 3600.0 / RATED_AH < 0.75
        lo, hi = c["soc_table_range"]
        assert hi > 0.94 and lo < 0.45
    else:
        assert i.max() > 12.0 and i.min() < -4.5                 # pulses up to 2C and -1C
        assert 0.15 < np.sum(i) / 3600.0 / RATED_AH < 0.45


def test_nmc2_capacity_is_48_published_electrode_pairs():
    """The nominal's rating is 48 of Ecker2015's electrode pairs (its ``Nominal cell capacity``), and the C/50 run
    measured the capacity of 48 pairs' stoichiometry window, computed here from the set's electrode loading
    (thickness x active fraction x maximum concentration x window x F x area), the same for both electrodes."""
    pybamm = pytest.importorskip("pybamm")
    p = pybamm.ParameterValues("Ecker2015")
    assert 48 * p["Nominal cell capacity [A.h]"] == pytest.approx(RATED_AH)
    assert _nominal()["params"]["capacity_ah"] == RATED_AH
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    area = p["Electrode height [m]"] * p["Electrode width [m]"]
    q = {}
    for e, a, b in (("Negative", x0, x1), ("Positive", y0, y1)):
        q[e] = (48 * p[f"{e} electrode thickness [m]"] * p[f"{e} electrode active material volume fraction"]
                * p[f"Maximum concentration in {e.lower()} electrode [mol.m-3]"] * abs(b - a) * F_C_MOL * area / 3600.0)
    assert q["Negative"] == pytest.approx(q["Positive"], rel=1e-3)
    assert _truth()["pseudo_ocv_capacity_ah"] == pytest.approx(q["Negative"], rel=0.005)
    # the lost-capacity record: 85 % of the rated capacity in the table's terms, the others the rated one
    for name, c in _truth()["cases"].items():
        assert c["truth"]["capacity_ah"] == pytest.approx(RATED_AH * (0.85 if name == "capacity_swing" else 1.0))
        assert c["truth"]["current_offset_a"] == (0.15 if name == "current_offset_swing" else 0.0)


def test_nmc2_nominal_cylinder_has_the_pouchs_volume_and_cooling_surface():
    """Kokam SLPB 75106100: 7.5 x 106 x 100 mm; the nominal's cylinder (the battery model's shape) has its volume
    and its whole surface, and a conduction radius of the order of the pouch's half-thickness."""
    par = _nominal()["params"]
    r, length = par["radius_m"], par["length_m"]
    assert math.pi * r * r * length == pytest.approx(0.0075 * 0.106 * 0.100, rel=1e-4)
    assert 2.0 * math.pi * r * (length + r) == pytest.approx(2.0 * (0.106 * 0.100 + 0.0075 * (0.106 + 0.100)),
                                                             rel=1e-4)
    assert 0.00375 < r < 0.01
    assert par["soc0_frac"] == -1.0 and par["rc_pairs"] == 2 and par["h_conv_w_m2k"] == 10.0


def test_nmc2_pseudo_ocv_is_the_cells_equilibrium_less_a_small_c50_overpotential():
    """The user's C/50 table lies 0.9-4 mV below PyBaMM's equilibrium OCV over the SOC the records visit (most
    near 1 mV; the most at 40 % SOC, the graphite's staging step, where the particles' diffusion
    overpotential is largest)."""
    nom = _nominal()
    soc, v = np.array(nom["ocv"]["soc_frac"]), np.array(nom["ocv"]["ocv_v"])
    assert np.all(np.diff(v) > 0.0)
    k = (soc >= 0.3) & (soc <= 0.96)
    d = v[k] - _equilibrium(soc[k], _truth()["pseudo_ocv_capacity_ah"])
    assert -5e-3 < d.min() and d.max() < 0.0, np.round(1e3 * d, 2)
    assert -2.5e-3 < d.mean() < -0.5e-3, np.round(1e3 * d, 2)


@pytest.mark.parametrize("case", SWING + DRIVE)
def test_nmc2_initial_soc_truth_is_the_first_rest_voltage_at_equilibrium(case):
    truth = _truth()
    tr = truth["cases"][case]["truth"]
    v0 = _record(case)["voltage_v"].to_numpy()[:60].mean()
    eq = _equilibrium(tr["soc_init_pct"] / 100.0, truth["pseudo_ocv_capacity_ah"])[0]
    assert v0 == pytest.approx(eq, abs=4.0 * truth["noise"]["voltage_v"] / np.sqrt(60.0))


@pytest.mark.parametrize("case", SWING)
def test_nmc2_last_rest_voltage_is_the_truths_soc_not_the_logged_charges(case):
    """The end of the last rest stop (9 min after current) is the equilibrium OCV, within 1.5 mV, at the SOC of the
    truth (initial SOC, true current = logged - offset, true capacity); with what the nominal assumes (logged
    current, rated capacity) it is 10 mV off or more on the capacity and offset records: what the calibration
    has to find."""
    truth = _truth()
    c = truth["cases"][case]
    df = _record(case)
    i, v = df["current_a"].to_numpy(), df["voltage_v"].to_numpy()
    tr = c["truth"]
    passed_ah = np.sum(i[:-1]) / 3600.0                       # 1 Hz levels held over each second
    soc_true = tr["soc_init_pct"] / 100.0 - (passed_ah - tr["current_offset_a"] * (i.size - 1) / 3600.0) / tr["capacity_ah"]
    soc_naive = tr["soc_init_pct"] / 100.0 - passed_ah / RATED_AH
    v_end = v[-60:].mean()
    q = truth["pseudo_ocv_capacity_ah"]
    assert abs(v_end - _equilibrium(soc_true, q)[0]) < 1.5e-3
    if case != "none_swing":
        assert abs(v_end - _equilibrium(soc_naive, q)[0]) > 8e-3


# ------------------------------------------------------------------ the calibration, whole library (slow)
#
# What the calibration should do on a cell it was not developed on.  At the time of writing all four fail
# (docs/calibration_independent.md, "A second NMC cell"): none_swing names initial_soc, none names ocv_correction
# + arrhenius_resistance, capacity_swing names ocv_correction (capacity alone fits 6.355 A.h), current_offset_swing
# names nothing (the rests measure 0.150 A, but the held-out voltage worsens with it).  Not xfailed: they state
# the requirement.

def _cell(case: str, effects=None):
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    from shevsim.calibrate.workflow import run_workflow
    data = load_measured(str(D / f"cell_nmc2_{case}.csv"), "cell")
    return run_workflow("cell", data, load_params_toml(D / "cell_nmc2_nominal.toml"), plots=False, effects=effects)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["none_swing", "none"])
def test_nmc2_no_effect_records_whole_library_name_no_physical_effect(case):
    rep = _cell(case)
    assert not set(rep["selected_effects"]) & PHYSICAL_CELL, rep["selected_effects"]
    assert not rep["measured_parameters"]["current_offset_a"]["significant"], rep["measured_parameters"]


@pytest.mark.slow
@pytest.mark.parametrize("case, effect, param, rel", [
    ("capacity_swing", "capacity", "capacity_ah", 0.05),
    ("current_offset_swing", "current_offset", "current_offset_a", 0.25),
])
def test_nmc2_one_effect_named_whole_library(case, effect, param, rel):
    rep = _cell(case)
    truth = _truth()["cases"][case]["truth"][param]
    assert rep["selected_effects"] == [effect], rep["selected_effects"]
    assert rep["final_parameters"][param] == pytest.approx(truth, rel=rel)
    if effect == "current_offset":
        # named on its measurement, which the relaxed rests confirm; the voltage under load gets worse with it
        # (10.06 -> 11.36 mV: the baseline had fitted its form error with the drifting SOC), and the report says so
        c = [c for c in rep["candidates"] if c["name"] == effect][0]
        assert "confirmed at the record's relaxed rests" in c["reason"], c["reason"]
    else:
        assert rep["rmse_after"]["voltage_v"]["holdout"] < rep["rmse_before"]["voltage_v"]["holdout"]


# ------------------------------------------------------------------ what the record's rests say (default run)
#
# The two false selections this cell first gave (sixth session), each refused by what the record's own relaxed
# rests show, not by the fit: an initial SOC fitted to the voltage's form error under current (the graphite's
# surface lags its bulk by 8-11 points), and an OCV correction judged at rests too short to show the OCV.

def _candidate(rep, name):
    (c,) = [c for c in rep["candidates"] if c["name"] == name]
    return c


def test_nmc2_an_initial_soc_its_first_rest_and_its_rest_stops_do_not_show_is_not_named():
    """none_swing named initial_soc 93.98 % (the first rest reads 94.61 %, truth 94.53 %) on a 12 % held-out gain.
    Its claim - the relaxed voltage sits where the shifted SOC puts it - is checked at the first rest (before
    any current, relaxed) and at the rest stops after current: there it moves the model by 5-7 mV and the
    record does not move."""
    rep = _cell("none_swing", effects=["initial_soc"])
    assert not rep["selected_effects"], rep["selected_effects"]
    c = _candidate(rep, "initial_soc")
    assert not c["passed"] and "its first, before any current" in c["reason"], c["reason"]
    assert c["gain"] > 0.10                                        # it would have passed on the fit alone


def test_nmc2_an_ocv_correction_is_not_judged_at_rests_shorter_than_the_slow_relaxation():
    """The drive's stops (64-92 s) end long before the slow branch (387 s) has relaxed: an OCV correction fitted
    to the form error under current passed at them, and an Arrhenius law of 10 390 K followed it.  Such rests do
    not show the OCV; with none long enough, the correction is not supported and the report says what is missing."""
    rep = _cell("none", effects=["ocv_correction"])
    assert not rep["selected_effects"], rep["selected_effects"]
    res = rep["record_resolution"]
    assert res["rests_after_current_s"] and max(res["rests_after_current_s"]) < res["slow_branch_tau_nominal_s"]
    c = _candidate(rep, "ocv_correction")
    assert not c["passed"] and "as long as the slow relaxation's time constant" in c["reason"], c["reason"]


# ------------------------------------------------------------------ solid diffusion in the model (default run)
#
# The cause of this cell's false selections, measured in PyBaMM: the graphite's surface SOC lags its bulk by 8-11
# points under the drive's current, and the lag's voltage follows the OCV's slope.  The battery model has that
# effect (diffusion_time_s, the OCV read at the surface SOC); a nominal that declares it fits its time.

def test_nmc2_solid_diffusion_in_the_nominal_explains_part_of_the_form_error(tmp_path):
    """The same nominal with solid diffusion declared (a start of 2000 s, fitted as a declared parameter): the
    baseline's held-out voltage error on the no-effect drive falls by a quarter (measured 7.24 -> 5.34 mV), the
    fitted time is inside its bounds, and the parameter reaches the overlay the simulator runs."""
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    from shevsim.calibrate.workflow import run_workflow
    nominal = tmp_path / "nominal_diffusion.toml"
    nominal.write_text((D / "cell_nmc2_nominal.toml").read_text().replace("rc_pairs = 2", "rc_pairs = 2\ndiffusion_time_s = 2000.0"))
    data = load_measured(str(D / "cell_nmc2_none.csv"), "cell")
    plain = run_workflow("cell", data, load_params_toml(D / "cell_nmc2_nominal.toml"), plots=False, effects=[])
    diff = run_workflow("cell", data, load_params_toml(nominal), plots=False, effects=[], out_dir=tmp_path / "out")
    v0, v1 = plain["rmse_before"]["voltage_v"]["holdout"], diff["rmse_before"]["voltage_v"]["holdout"]
    assert v1 < 0.85 * v0, (v0, v1)
    tau = diff["baseline_parameters"]["diffusion_time_s"]
    assert 100.0 < tau < 1.0e5, tau
    assert "diffusion_time_s" not in plain["baseline_parameters"]
    overlay = tomllib.loads((tmp_path / "out" / "params.toml").read_text())
    assert overlay["battery"]["diffusion_time_s"] == pytest.approx(tau)


def test_nmc2_capacity_is_named_not_an_ocv_correction_its_rests_do_not_show():
    """The capacity record: an OCV correction (five knots) and the capacity (one parameter).  Until the ninth
    session both passed, the correction scored 9 % better and the parsimony rule (_Run.parsimonious, tested on its
    own in test_calibrate.py) named the capacity.  Since a rest's end voltage counts only within the relaxation
    still under way there (CellModel._unrelaxed: the residual's own tail), the correction is refused at the rests:
    the first rest after current ended 27 mV from where the model without it put it, but was still relaxing by up
    to 18 mV towards it.  The capacity is named within the benchmark's 5 % of the truth (0.3 % on the tenth session's
    machine, 2.6 % on an AMD EPYC's OpenBLAS kernels with the same code and packages: a different local optimum of
    the baseline - the 1 % this test asked for was one machine's, not what the record identifies)."""
    rep = _cell("capacity_swing", effects=["capacity", "ocv_correction"])
    assert rep["selected_effects"] == ["capacity"], rep["selected_effects"]
    truth = _truth()["cases"]["capacity_swing"]["truth"]["capacity_ah"]
    assert rep["final_parameters"]["capacity_ah"] == pytest.approx(truth, rel=0.05)
    first = {c["name"]: c for c in rep["rounds"][0]["candidates"]}
    assert first["capacity"]["passed"]
    assert not first["ocv_correction"]["passed"] and "still relaxing" in first["ocv_correction"]["reason"]


def test_nmc2_a_measured_offset_the_rests_confirm_is_named_though_the_fit_under_load_worsens():
    """The offset record: the rests measure the sensor's offset (0.1501 +- 0.0003 A, truth 0.15), and with it the
    relaxed rest voltages sit where the corrected charge puts them (slope 1.09 +- 0.13); the voltage under current
    gets worse with it (held-out -11 %: the baseline had fitted its form error with the drifting SOC).  A measured
    parameter the record's own check confirms is named; the report says what the fit under load said."""
    rep = _cell("current_offset_swing", effects=["current_offset"])
    assert rep["selected_effects"] == ["current_offset"], rep["selected_effects"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(0.15, rel=0.02)
    c = _candidate(rep, "current_offset")
    assert "confirmed at the record's relaxed rests" in c["reason"] and "does not confirm it" in c["reason"], c["reason"]
    # and on the no-effect record the rests measure no offset: it is not named
    rep0 = _cell("none_swing", effects=["current_offset"])
    assert not rep0["selected_effects"] and not rep0["measured_parameters"]["current_offset_a"]["significant"]


def test_nmc2_an_initial_soc_outside_the_relaxed_first_rests_reading_is_not_named():
    """The drive has no rest after current as long as the slow relaxation, so only its relaxed first rest can
    check an initial SOC: its voltage +- the table's error (2 mV) reads 78.04-78.54 % (truth 78.11 %).  The fit
    under current put it at 77.58 % on a 12 % held-out gain and was named (the one false selection left on this
    cell); outside the first rest's interval, it is not."""
    rep = _cell("none", effects=["initial_soc"])
    assert not rep["selected_effects"], rep["selected_effects"]
    lo, hi = rep["record_resolution"]["initial_soc_from_first_rest"]["soc_pct_interval"]
    assert lo < _truth()["cases"]["none"]["truth"]["soc_init_pct"] < hi
    c = _candidate(rep, "initial_soc")
    assert not c["passed"] and "relaxed first rest" in c["reason"] and "outside" in c["reason"], c["reason"]
