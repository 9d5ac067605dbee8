"""The PyBaMM cell records of ``tests/data/independent/`` (issue 24): are they what the generator says?

``make_cell_pybamm.py`` gives the calibration a pseudo-OCV "measured at C/50" as the user's nominal.  Until
it logged the C/50 discharge every 60 s, PyBaMM returned only its adaptive solver steps (a few dozen over
50 h) and the table, interpolated linearly between them, was off by up to 11 mV over the SOC range the
records visit: structure the calibration then read as effects.  These tests hold the shipped data to the
cell's own physics, independently of shevsim: PyBaMM's electrode open-circuit potentials of the same
``Chen2020`` set (a C/50 curve lies a near-constant few mV below the equilibrium), and the logger's stated
sampling and noise.
"""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

D = Path(__file__).resolve().parents[1] / "data" / "independent"


def test_nominal_pseudo_ocv_is_the_cells_equilibrium_curve_less_a_constant_c50_overpotential():
    pybamm = pytest.importorskip("pybamm")
    p = pybamm.ParameterValues("Chen2020")
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    u_n, u_p = p["Negative electrode OCP [V]"], p["Positive electrode OCP [V]"]
    nom = tomllib.loads((D / "cell_nominal.toml").read_text())
    q_ah = json.loads((D / "cell_truth.json").read_text())["pseudo_ocv_capacity_ah"]
    soc_tab, v_tab = np.array(nom["ocv"]["soc_frac"]), np.array(nom["ocv"]["ocv_v"])
    # the table's SOC is 1 - discharged A.h / 5 A.h; PyBaMM's is the fraction of its full-range capacity
    keep = (soc_tab >= 0.35) & (soc_tab <= 0.9)            # the SOC range the one-hour records visit
    s = 1.0 - (1.0 - soc_tab[keep]) * 5.0 / q_ah
    eq = np.array([float(u_p(pybamm.Scalar(y0 + a * (y1 - y0))).evaluate())
                   - float(u_n(pybamm.Scalar(x0 + a * (x1 - x0))).evaluate()) for a in s])
    d = v_tab[keep] - eq
    assert -0.010 < d.mean() < 0.0                     # below equilibrium by the C/50 overpotential (~5.5 mV)
    assert np.ptp(d) < 0.002, np.round(1e3 * d, 2)     # and nothing else (the coarse table: 17 mV peak to peak)


DRIVE_CASES = ["none", "capacity", "current_offset", "cooling_change", "arrhenius", "none_2", "none_3",
               "contact_resistance", "entropic", "none_mixing", "none_2_mixing", "entropic_mixing"]
SWING_CASES = ["none_swing", "capacity_swing", "current_offset_swing", "none_swing_2", "none_swing_mixing",
               "capacity_swing_420"]


@pytest.mark.parametrize("case", DRIVE_CASES)
def test_cell_drive_records_are_one_hour_at_1_hz_with_the_stated_noise(case):
    truth = json.loads((D / "cell_truth.json").read_text())
    assert set(truth["cases"]) == set(DRIVE_CASES + SWING_CASES) and truth["cases"][case]["protocol"] == "drive"
    df = pd.read_csv(D / f"cell_{case}.csv", comment="#")
    t = df["time_s"].to_numpy()
    assert np.all(np.diff(t) == 1.0) and t[-1] - t[0] == 3600.0
    # the logger's voltage noise, from the first 60 s of rest (PyBaMM's cell is relaxed there)
    v0 = df["voltage_v"].to_numpy()[:60]
    assert np.std(v0) == pytest.approx(truth["noise"]["voltage_v"], rel=0.3)
    # a drive-like current: discharge and charge pulses up to 2C and -1C, about a quarter of the capacity
    i = df["current_a"].to_numpy()
    assert i.max() > 8.0 and i.min() < -3.0
    assert 0.15 < np.sum(i) / 3600.0 / 5.0 < 0.45 or case.startswith("entropic")     # its drive (seed 28) swings 53 %


@pytest.mark.parametrize("case", SWING_CASES)
def test_cell_swing_records_are_two_hours_with_rest_stops_and_a_wide_soc_swing(case):
    truth = json.loads((D / "cell_truth.json").read_text())
    assert truth["cases"][case]["protocol"] == "swing"
    df = pd.read_csv(D / f"cell_{case}.csv", comment="#")
    t = df["time_s"].to_numpy()
    rest_s = truth["cases"][case]["pybamm_inputs"].get("rest_s", 600)     # capacity_swing_420: 420 s stops
    assert np.all(np.diff(t) == 1.0) and t[-1] - t[0] == 60 + 3 * (1800 + rest_s) - 60
    assert np.std(df["voltage_v"].to_numpy()[:60]) == pytest.approx(truth["noise"]["voltage_v"], rel=0.3)
    # pulses up to 1.6C and -0.7C; a rest stop of 10 min (or rest_s) after each 30 min drive block, where the
    # logged current is the sensor's offset and noise only
    i = df["current_a"].to_numpy()
    assert i.max() > 7.0 and i.min() < -2.5
    off = truth["cases"][case]["truth"]["current_offset_a"]
    for blk in range(3):
        a = 60 + blk * (1800 + rest_s) + 1800
        b = min(a + rest_s, t[-1])
        rest = i[(t >= a) & (t < b)]
        assert abs(rest.mean() - off) < 0.002 and rest.std() == pytest.approx(truth["noise"]["current_a"], rel=0.3)
    # a wide SOC swing (a capacity is identifiable only over one): half the rated capacity or more
    assert 0.45 < np.sum(i - off) / 3600.0 / 5.0 < 0.75
    lo, hi = truth["cases"][case]["soc_table_range"]
    assert hi > 0.94 and lo < 0.5


def test_entropic_truth_is_the_published_lg_m50_entropic_change():
    """The truth of the ``entropic`` record against O'Regan et al. 2022 directly (not through the generator):
    the cell's dU/dT is the positive's minus the negative's; both published fits, in mV/K, at the electrode
    stoichiometries of Chen2020's SOC window."""
    pybamm = pytest.importorskip("pybamm")
    tr = json.loads((D / "cell_truth.json").read_text())
    e = tr["cases"]["entropic"]["truth"]
    p = pybamm.ParameterValues("Chen2020")
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    soc = np.array(e["dudt_soc_frac"])
    s = 1.0 - (1.0 - soc) * 5.0 / tr["pseudo_ocv_capacity_ah"]
    x, y = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
    # O'Regan 2022, Table: graphite (a1 fixed to 0 in their final fit) and NMC811 fits [mV/K]
    dn = -0.1112 * x + 0.02914 + 0.3561 * np.exp(-((x - 0.08309) ** 2) / 0.004616)
    dp = 0.04006 * np.exp(-((y - 0.2828) ** 2) / 0.0009855) - 0.06656 * np.exp(-((y - 0.8032) ** 2) / 0.02179)
    np.testing.assert_allclose(np.array(e["dudt_v_k"]), 1e-3 * (dp - dn), atol=1e-9)
    assert e["dudt_knots_soc_frac"][-1] == pytest.approx(tr["cases"]["entropic"]["soc_table_range"][1])
    # the other records have no entropic change, and only the contact-resistance record adds a resistance
    for name, c in tr["cases"].items():
        assert (c["truth"]["series_resistance_added_ohm"] > 0) == (name == "contact_resistance")
        assert ("dudt_v_k" in c["truth"]) == name.startswith("entropic")
    # the entropic record with the heat of mixing: the same cell and drive, the same truth
    assert tr["cases"]["entropic_mixing"]["truth"] == e


# ------------------------------------------------------------------ the calibration on the PyBaMM records
#
# Given what a user has (cell_nominal.toml: rated capacity, the C/50 pseudo-OCV, size, initial SOC from the
# first rest), the equivalent circuit leaves 11-21 mV of held-out voltage residual on these SPMe records
# (1 mV noise): Butler-Volmer kinetics the linear circuit lacks.  That is a model-form discrepancy, and no
# physical effect may be named for it.  Stated tolerance: the heat-transfer factor within 30 %.

PHYSICAL_CELL = {"entropic_heat", "arrhenius_resistance", "cooling_change", "ocv_hysteresis", "capacity",
                 "current_offset", "low_soc_resistance", "second_rc_branch", "initial_soc", "ocv_correction",
                 "solid_diffusion"}


def test_every_cell_effect_of_the_library_counts_as_physical():
    """A no-effect record may name none of the library's effects: the set the tests check covers it all."""
    from shevsim.calibrate.cell import CELL_EFFECTS
    assert {f.__name__ for f in CELL_EFFECTS} <= PHYSICAL_CELL


def _cell(case: str, effects=None):
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    from shevsim.calibrate.workflow import run_workflow
    data = load_measured(str(D / f"cell_{case}.csv"), "cell")
    return run_workflow("cell", data, load_params_toml(D / "cell_nominal.toml"), plots=False, effects=effects)


def _cell_truth(case: str) -> dict:
    return json.loads((D / "cell_truth.json").read_text())["cases"][case]["truth"]


def _check_no_effect(rep):
    assert not set(rep["selected_effects"]) & PHYSICAL_CELL, rep["selected_effects"]
    # what the circuit cannot follow is said: the nominal's voltage residual is a model-form discrepancy
    assert any(d.get("channel") == "voltage_v" for d in rep["model_form_discrepancy"]), rep["model_form_discrepancy"]


def _check_cooling(rep):
    tr = _cell_truth("cooling_change")
    assert rep["selected_effects"] == ["cooling_change"], rep["selected_effects"]
    fp = rep["final_parameters"]
    assert fp["h_change_factor"] == pytest.approx(tr["h_change_factor"], rel=0.30)
    assert fp["h_change_time_s"] == pytest.approx(tr["h_change_time_s"], abs=120.0)
    assert rep["rmse_after"]["t_surface_c"]["holdout"] < 0.3 * rep["rmse_before"]["t_surface_c"]["holdout"]


# the default run: the effects the nominal's model-form error tempted before (hysteresis and Arrhenius
# on the voltage, reversible heat and a cooling change on the temperature), against the thermal effects
TEMPTED = ["ocv_hysteresis", "arrhenius_resistance", "entropic_heat", "cooling_change"]


def test_no_effect_pybamm_record_names_no_physical_effect():
    _check_no_effect(_cell("none", effects=TEMPTED))


def test_pybamm_cooling_change_named_with_its_factor_and_time():
    rep = _cell("cooling_change", effects=["cooling_change", "entropic_heat"])
    _check_cooling(rep)
    # the overlay written, run through the battery component by the master, reproduces the fit (the replay)
    assert rep["replay_max_relative_deviation"] < 0.01, rep["replay"]


@pytest.mark.slow
@pytest.mark.parametrize("case", ["none", "none_2", "none_3", "none_mixing", "none_2_mixing"])
def test_no_effect_pybamm_records_whole_library_name_no_physical_effect(case):
    """Each no-effect drive, the whole effect library: no physical effect named (the false-selection rate of
    docs/calibration_independent.md, one record at a time)."""
    r = _cell(case)
    assert not set(r["selected_effects"]) & PHYSICAL_CELL, r["selected_effects"]
    _check_no_effect(r)


@pytest.mark.slow
def test_pybamm_cooling_change_named_whole_library():
    _check_cooling(_cell("cooling_change"))


# ------------------------------------------------------------------ contact resistance (PyBaMM's own)
#
# The battery model has no separate contact resistance: a contact resistance IS a higher ohmic resistance,
# and the nominal's declared ``rs_scale`` (a factor on the R_s table) takes it - no effect of the library is
# to be named.  What a lab sees when it retests a cell after a connector change: the fitted ohmic resistance
# rises by the contact resistance.  Both records have the same drive (seed 21); stated tolerance 25 %.

def _rs_ohm(params: dict, case: str) -> float:
    """The fitted R_s [Ohm]: rs_scale x the nominal's R_s table (the project's A123 table at 25 degC, as the
    short-form nominal uses it), averaged over the SOC range the record visits, discharge and charge."""
    from shevsim.battery.cell import default_tables
    tab = default_tables()
    lo, hi = _cell_truth_case(case)["soc_table_range"]
    return params["rs_scale"] * float(np.mean([tab.params(x, 25.0, sg)[0] for x in np.linspace(lo, hi, 21)
                                               for sg in (1.0, -1.0)]))


def _cell_truth_case(case: str) -> dict:
    return json.loads((D / "cell_truth.json").read_text())["cases"][case]


def test_pybamm_contact_resistance_raises_the_fitted_ohmic_resistance_by_its_value():
    none = _cell("none", effects=[])
    contact = _cell("contact_resistance", effects=[])
    truth = _cell_truth("contact_resistance")["series_resistance_added_ohm"]
    assert truth == pytest.approx(0.010)
    rise = _rs_ohm(contact["final_parameters"], "contact_resistance") - _rs_ohm(none["final_parameters"], "none")
    assert rise == pytest.approx(truth, rel=0.25), rise
    # and the model with the risen R_s explains the record as well as the nominal explains the one without
    assert contact["rmse_before"]["voltage_v"]["holdout"] < 1.5 * none["rmse_before"]["voltage_v"]["holdout"]



# ------------------------------------------------------------------ capacity and current offset: the swing records
#
# Over the one-hour drive (25 % SOC swing, no rest stop) the nominal's slow RC branch takes up a capacity
# loss (a current offset is read in the drive's own 20-90 s stops: see the drive-offset tests below): an RC branch whose time constant is longer than any rest the record has is never
# seen relaxing, and over a swing where the OCV is near linear in the charge it is a series capacitor - a
# capacity.  The calibration now limits that time constant to the record's longest rest after current
# (CellModel.record_resolution), and reads a current-sensor offset where a lab reads it: the logged current
# in the rests (CellModel.measured_params).  The "swing" records (95 % -> 25-45 % SOC, three 30 min drive
# blocks with 10 min rest stops) identify both.  Stated tolerances: capacity 5 %, offset 25 %.  The default
# run offers the voltage effects a capacity or an offset is confused with; the whole library is `slow`.

SWING_EFFECTS = ["capacity", "current_offset", "ocv_hysteresis"]


# A small cell of our own for the rest detection (no PyBaMM, not shevsim's cell model): OCV(SOC) + R0 + one RC
# branch, a charger with CC and CV phases, a logger with a current-sensor offset and noise.
_ECM_CAP_AH, _ECM_R0, _ECM_R1, _ECM_TAU1 = 5.0, 0.03, 0.015, 60.0
_ECM_OCV_SOC = np.linspace(0.0, 1.0, 11)
_ECM_OCV_V = 3.3 + 0.9 * _ECM_OCV_SOC - 0.25 * (1.0 - _ECM_OCV_SOC) ** 4


def _ecm_record(steps, dt=1.0, soc0=0.5, v_max=4.1, offset_a=0.0, i_noise=None, v_noise=0.001, seed=0):
    """Simulate ``steps`` - ``("cc", current_a, duration_s)`` (+ discharge), ``("cv", stop_abs_current_a)`` (hold
    ``v_max`` until the charge current falls to the stop), ``("rest", duration_s)`` - exactly (the RC branch by
    its exponential step).  Returns a DataFrame as a cell record: the logged current is the true one + offset +
    noise (``i_noise``: an array of the logger's noise, or white 5 mA)."""
    t, cur, volt = [], [], []
    soc, v1, now = soc0, 0.0, 0.0
    a = math.exp(-dt / _ECM_TAU1)

    def ocv(s):
        return float(np.interp(s, _ECM_OCV_SOC, _ECM_OCV_V))

    def step(i):
        nonlocal soc, v1, now
        soc -= i * dt / 3600.0 / _ECM_CAP_AH
        v1 = a * v1 + (1.0 - a) * _ECM_R1 * i
        now += dt
        t.append(now)
        cur.append(i)
        volt.append(ocv(soc) - v1 - _ECM_R0 * i)

    for s in steps:
        if s[0] in ("cc", "rest"):
            i = float(s[1]) if s[0] == "cc" else 0.0
            for _ in range(int(round(s[-1] / dt))):
                step(i)
        else:                                  # CV: the current that holds v_max, until it falls to the stop
            while True:
                i = (ocv(soc) - a * v1 - v_max) / (_ECM_R0 + (1.0 - a) * _ECM_R1)
                if -i <= s[1]:
                    break
                step(i)
    rng = np.random.default_rng(seed)
    n = len(t)
    noise = rng.normal(0.0, 0.005, n) if i_noise is None else np.asarray(i_noise)[:n]
    return pd.DataFrame({"time_s": np.asarray(t) - dt, "current_a": np.asarray(cur) + offset_a + noise,
                         "voltage_v": np.asarray(volt) + rng.normal(0.0, v_noise, n),
                         "t_surface_c": 25.0 + rng.normal(0.0, 0.05, n), "t_ambient_c": np.full(n, 25.0)}), \
        np.asarray(cur)


def _ecm_model(df):
    """The calibration's cell model prepared on the record ``df`` (the real path: rests, offset and its SE)."""
    from types import SimpleNamespace
    from shevsim.calibrate.cell import CellModel
    m = CellModel({"capacity_ah": _ECM_CAP_AH, "ocv_soc_frac": list(_ECM_OCV_SOC), "ocv_v": list(_ECM_OCV_V)})
    m.prepare(SimpleNamespace(df=df))
    return m


_DRIVE = [("cc", 10.0, 30), ("cc", -5.0, 20), ("cc", 6.0, 60), ("cc", 0.0, 20), ("cc", -8.0, 10), ("cc", 10.0, 40)]


def test_a_cv_taper_and_a_small_charge_tail_are_not_rests():
    """The reviewer's record: a 10 A drive, a CC charge to the voltage limit, a CV taper down to 0.15 A, then a
    -0.15 A tail.  The former rule (current within 2 % of the record's peak) took the taper's end and the tail
    for a 'rest' logging a -0.15 A 'offset'.  A cell at rest carries no current and relaxes; here the current
    decays with the voltage held, then charges on with the voltage rising: no rest, no offset measured."""
    df, i_true = _ecm_record([("rest", 60)] + _DRIVE * 10 + [("cc", -2.5, 600), ("cv", 0.15), ("cc", -0.15, 900)],
                             soc0=0.6)
    t, i = df["time_s"].to_numpy(), df["current_a"].to_numpy()
    cv = int(np.flatnonzero(i_true == -2.5)[-1]) + 1           # the CV phase starts here
    assert df["voltage_v"].to_numpy()[cv:].min() > 4.09          # the charge reached the limit and held it
    tail = i[t >= t[-1] - 740.0]
    # the case the former relative rule took for a rest: still within 2 % of the peak, median -0.15 A
    assert np.ptp(tail) <= 0.02 * np.abs(i).max() and np.median(tail) == pytest.approx(-0.15, abs=0.005)
    from shevsim.calibrate.cell import CellModel
    why: list = []
    spans = CellModel._rest_spans(t, i, df["voltage_v"].to_numpy(), _ECM_CAP_AH, why=why)
    assert not [s for s in spans if s[1] >= cv], (spans, why)
    assert any("CV phase" in r for _t, _d, r in why), why       # the taper was seen and refused as a CV phase
    m = _ecm_model(df)
    assert m.measured_params({}) == {} and m.tau2_max_s is None, (m.rests_s, m.rest_current)


def _two_branch_record(tail_a: float, tail_s: float, seed: int = 3):
    """A two-RC-branch cell (fast 20 mOhm / 15 s, slow 5 mOhm / 300 s, exact exponential steps; not the
    calibration's model): 1200 s at 3 A discharge, ``tail_s`` at ``tail_a`` (< 0: charge), then a 240 s rest;
    voltage noise 0.5 mV.  Returns ``(t, i, v, k)``, ``k`` the rest's first sample."""
    branches = ((0.020, 15.0), (0.005, 300.0))
    cur = np.r_[np.zeros(60), np.full(1200, 3.0), np.full(int(tail_s), tail_a), np.zeros(240)]
    u = np.zeros(len(branches))
    v = np.empty(cur.size)
    for n, i in enumerate(cur):
        u = np.array([ub * math.exp(-1.0 / tau) + r * (1.0 - math.exp(-1.0 / tau)) * i
                      for ub, (r, tau) in zip(u, branches)])
        v[n] = 3.7 - 0.02 * i - u.sum()
    v += np.random.default_rng(seed).normal(0.0, 5e-4, v.size)
    return np.arange(cur.size, dtype=float), cur, v, int(cur.size - 240), branches


def test_a_rest_after_a_short_charge_that_ends_a_long_discharge_relaxes_the_charge_way_and_is_a_rest():
    """Trial 40: the last 240 s rest of the PyBaMM records came after 20-40 s of charge that ended a drive, and was
    refused ("does not relax after the discharge before it (-2.29 mV)"): the polarisation's sign was the current
    weighted over 5x the rest, where the drive's net discharge outweighs the recent charge.  The fast branch,
    charged last, relaxes the voltage down over the rest and the slow one, discharged, up; which wins is the
    cell's split between them.  Here (30 s at 2 A) the generator's fast branch wins: the voltage falls by ~7 mV,
    far beyond the noise - a rest, with the generator's branches or the default tables'.  After 200 s of charge
    the charge sets the direction on both of the generator's branches: a rest falling is one, a span rising is
    refused naming the charge.  The former weighting says 'discharge' on each record, so they are the trial's
    case."""
    from shevsim.calibrate.cell import CellModel

    def former_sign(t, i, k):
        dur = t[-1] - t[k]
        pre = (t >= t[k] - 5.0 * dur) & (t < t[k])
        return np.sign(np.sum(i[pre] * np.exp((t[pre] - t[k]) / dur)))

    w = 24
    for tail_s in (30, 200):
        t, i, v, k, branches = _two_branch_record(-2.0, tail_s)
        assert former_sign(t, i, k) > 0.0                             # the former rule: a discharge before it
        assert np.mean(v[-w:]) - np.mean(v[k:k + w]) < -5e-3          # ... but the voltage falls (the charge's)
        for br in (branches, None):
            why: list = []
            spans = CellModel._rest_spans(t, i, v, 2.0, why=why, branches=br)
            assert [(t[a], t[b]) for a, b in spans] == [(t[k], t[-1])], (tail_s, br, why)
    v2 = v.copy()                      # 200 s of charge, the voltage made to rise over the "rest" instead
    v2[k:] += 8e-5 * (t[k:] - t[k]) - (v[k:] - v[-1])
    why = []
    assert CellModel._rest_spans(t, i, v2, 2.0, why=why, branches=branches) == []
    assert "does not relax after the charge before it" in why[0][2], why
    # a drive with no charge at its end: the voltage rises (relaxes up) - a rest; made to fall instead (a small
    # real current, not a relaxation) it is refused, naming the discharge before it
    t, i, v, k, branches = _two_branch_record(0.0, 0)
    assert CellModel._rest_spans(t, i, v, 2.0, branches=branches) == [(k, t.size - 1)]
    v2 = v.copy()
    v2[k:] -= 8e-5 * (t[k:] - t[k]) + (v[k:] - v[-1])
    why = []
    assert CellModel._rest_spans(t, i, v2, 2.0, why=why, branches=branches) == []
    assert "does not relax after the discharge before it" in why[0][2], why


@pytest.mark.parametrize("rec", ["cell_trial40_oregan2022_none", "cell_trial40_oregan2022_capacity",
                                 "cell_trial40_marquis2019_none_2"])
def test_trial40_last_rest_after_a_short_charge_is_a_rest(rec):
    """The trial-40 records' final 240 s rest (after 20-40 s of charge) is found as a rest through the model's own
    prepare (the nominal's RC branches); ORegan2022 ``none`` and ``capacity`` refused it before."""
    from types import SimpleNamespace
    from shevsim.calibrate.cell import CellModel
    from shevsim.calibrate.known import load_params_toml
    raw = pd.read_csv(D / f"{rec}.csv", comment="#")
    df = pd.DataFrame({"time_s": raw["Test_Time(s)"], "current_a": -raw["Current(A)"], "voltage_v": raw["Voltage(V)"],
                       "t_surface_c": raw["Aux_Temperature_1(C)"], "t_ambient_c": 25.0})
    nominal = rec.rsplit("_", 1)[0] if not rec.endswith("none_2") else rec[: -len("_none_2")]
    m = CellModel(load_params_toml(D / f"{nominal}_nominal.toml"))
    m.prepare(SimpleNamespace(df=df))
    assert any(abs(m._rest_t[a] - 3300.0) <= 5.0 and m._rest_t[b] >= 3530.0 for a, b in m.rest_spans), \
        (m.rest_spans, m.rests_refused)


def _offset_protocol():
    return [("rest", 60)] + _DRIVE * 5 + [("rest", 600)] + _DRIVE * 5 + [("rest", 600)] + \
        [("cc", -2.5, 600), ("rest", 600)]


@pytest.mark.parametrize("offset_a", [0.1, 0.0])
def test_rests_measure_a_true_current_sensor_offset_through_prepare(offset_a):
    """Real rests (after a discharge and after a charge) logging 0.1 A of sensor offset with 5 mA white noise:
    the rests are found (600 s each), the offset is measured at 0.1 A (within 3 of its own standard errors,
    which the model computes from the record) and significant; without the offset it is measured as zero."""
    df, _ = _ecm_record(_offset_protocol(), offset_a=offset_a, seed=7)
    m = _ecm_model(df)
    assert m.rests_s == pytest.approx([600.0, 600.0, 600.0], abs=5.0), m.rests_s
    assert m.tau2_max_s == pytest.approx(max(m.rests_s))
    got = m.measured_params({})["current_offset_a"]
    # white noise: median of ~1800 samples, SE = 1.2533 x 5 mA / sqrt(n)
    assert got["se"] == pytest.approx(1.2533 * 0.005 / math.sqrt(m.rest_current["n"]), rel=0.2)
    assert abs(got["value"] - offset_a) < 3.0 * got["se"]
    assert got["significant"] == (offset_a != 0.0)


@pytest.mark.parametrize("offset_a", [0.0, 0.1])
def test_small_real_currents_that_pass_for_rests_are_left_out_by_the_rests_consensus(offset_a):
    """Drives followed by six true 40 s rests and by three 30 s spans of a real 80 mA discharge (below C/20,
    after a 10 A pulse, its voltage relaxing: each passes for a rest).  Each rest is one measurement of the offset;
    the 80 mA spans disagree with them by some 15 of their standard errors and are left out (a single pooled
    median would have been pulled towards them).  With as many such spans as rests there is no consensus, and
    no measurement."""
    drive = _DRIVE + [("rest", 40)] + _DRIVE + [("rest", 40)] + _DRIVE + [("cc", 0.08, 30)]
    df, _ = _ecm_record([("rest", 60)] + drive * 3, offset_a=offset_a, seed=11)
    m = _ecm_model(df)
    rc = m.rest_current
    assert rc["n_rests"] == 6 and len(rc["rests_left_out"]) == 3, rc
    assert all(r["level_a"] == pytest.approx(offset_a + 0.08, abs=0.01) for r in rc["rests_left_out"])
    got = m.measured_params({})["current_offset_a"]
    assert abs(got["value"] - offset_a) < 3.0 * got["se"], got
    assert got["significant"] == (offset_a != 0.0)
    even = _DRIVE + [("rest", 40)] + _DRIVE + [("cc", 0.08, 30)]
    df, _ = _ecm_record([("rest", 60)] + even * 4, offset_a=offset_a, seed=11)
    assert _ecm_model(df).rest_current is None


NO_OFFSET_CASES = ["none", "none_2", "none_3", "capacity", "cooling_change", "arrhenius", "contact_resistance",
                   "entropic", "none_swing", "none_swing_2", "capacity_swing"]


def _prepared(case):
    from shevsim.calibrate.cell import CellModel
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    m = CellModel(load_params_toml(D / "cell_nominal.toml"))
    m.prepare(load_measured(str(D / f"cell_{case}.csv"), "cell"))
    return m


def test_pybamm_rests_measure_the_offset_within_its_standard_error_on_every_record():
    """The drive's stops (20-90 s) and the swing's rest stops, every PyBaMM record: no offset within 3 standard
    errors where there is none (several records have 20-40 s spans of a real -243..+242 mA current that pass for
    rests: the consensus leaves them out), the +0.1 A offset within 3 standard errors where there is one."""
    for case in NO_OFFSET_CASES:
        rc = _prepared(case).rest_current
        assert rc is not None and rc["n_rests"] >= 3, (case, rc)
        assert abs(rc["value"]) < 3.0 * rc["se"], (case, rc)
    for case in ("current_offset", "current_offset_swing"):
        rc = _prepared(case).rest_current
        assert abs(rc["value"] - _cell_truth(case)["current_offset_a"]) < 3.0 * rc["se"], (case, rc)


def test_autocorrelated_rest_current_does_not_fake_a_significant_offset():
    """A 10 Hz logger whose current noise is filtered (AR(1), 2 s correlation time, 5 mA): counted as independent
    samples its median's standard error is some 6x too small, and a zero offset would look 'significant' (5
    standard errors) on some seeds.  With the effective sample size it never does."""
    dt, tau = 0.1, 2.0
    phi = math.exp(-dt / tau)
    z_naive, z = [], []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        e = rng.normal(0.0, 0.005 * math.sqrt(1.0 - phi * phi), 60000)
        from scipy.signal import lfilter
        noise = lfilter([1.0], [1.0, -phi], e)
        df, _ = _ecm_record(_offset_protocol(), dt=dt, i_noise=noise, seed=seed)
        m = _ecm_model(df)
        assert len(m.rests_s) == 3, m.rests_s
        got = m.measured_params({})["current_offset_a"]
        rc = m.rest_current
        assert rc["n_eff"] < rc["n"] / 10.0                      # (1 + phi) / (1 - phi) = 40: counted as such
        z.append(abs(got["value"]) / got["se"])
        naive_se = got["se"] * math.sqrt(rc["n_eff"] / rc["n"])
        z_naive.append(abs(got["value"]) / naive_se)
        assert not got["significant"], (seed, got)
    assert max(z) < 4.0, z
    assert max(z_naive) > 5.0, z_naive                           # the former SE would have fired


def test_pybamm_swing_capacity_named_within_5_percent():
    rep = _cell("capacity_swing", effects=SWING_EFFECTS)
    res = rep["record_resolution"]
    assert 500.0 < res["slow_branch_tau_max_s"] < 700.0 and res["soc_swing_frac"] > 0.5
    off = rep["measured_parameters"]["current_offset_a"]     # the rests carry no current: measured as zero
    assert not off["significant"] and abs(off["value"]) < 0.002
    assert rep["selected_effects"] == ["capacity"], rep["selected_effects"]
    cap = rep["final_parameters"]["capacity_ah"]
    assert cap == pytest.approx(_cell_truth("capacity_swing")["capacity_ah"], rel=0.05), cap
    assert rep["rmse_after"]["voltage_v"]["holdout"] < 0.75 * rep["rmse_before"]["voltage_v"]["holdout"]


def test_a_capacity_that_pushes_the_slow_branch_onto_its_limit_is_not_named():
    """The swing drive with PyBaMM's heat of mixing and no capacity error: the pair low_soc_resistance +
    capacity fitted a capacity 4.7 % above the rated one, and passed, by pushing the slow RC branch from 321 s
    onto its time-constant limit (the longest rest, 620 s): a series capacitor traded against the capacity.  A
    true capacity error does not push it there (the test above and the next one)."""
    rep = _cell("none_swing_mixing", effects=["low_soc_resistance", "capacity"])
    assert not rep["selected_effects"], rep["selected_effects"]
    tmax = rep["record_resolution"]["slow_branch_tau_max_s"]
    (pair,) = [c for c in rep["rounds"][0]["pairs"] if c["name"] == "low_soc_resistance+capacity"]
    assert not pair["passed"], pair
    # Which local optimum the baseline reaches depends on the floating-point environment (the same code and packages:
    # on the tenth session's machine the pair fitted 4.7 % above the rated capacity and gained > 10 %; on an AMD
    # EPYC's OpenBLAS kernels its own channel gains 9.5 % and it is refused by the held-out rule).  Where the pair
    # fits a sizeable capacity that the held-out rule would pass, the slow branch's limit is what refuses it.
    # Since the capacity starts from 0.85, 1.0 and 1.15x the rated one (fifteenth session) the pair reaches another
    # optimum, 5.196 A.h with the low-SOC law's scale on its upper bound (gain 34 %): refused as implausible, the
    # check made before the slow branch's limit - a refusal of the same trade with another piece of its evidence.
    if pair["parameters"]["capacity_ah"] > 1.02 * 5.0 and pair["gain"] > 0.10 and "held-out" not in pair["reason"]:
        assert ("pushing the slow RC branch onto its time-constant limit" in pair["reason"]
                or pair["reason"].startswith("implausible: lowsoc_r_scale_frac")), pair["reason"]
    assert 500.0 < tmax < 700.0


def test_a_true_capacity_fitted_with_the_slow_branch_at_its_limit_is_named():
    """A reviewer's counter-record: 8 % lost capacity on the swing drive with rest stops of 420 s, barely longer
    than the cell's own slow relaxation.  The baseline already stretches the slow branch past the limit to stand
    in for the capacity, and the capacity's fit keeps it there: the capacity did not push it there, and it is
    named (a rule that refused any capacity with the branch at the limit named a false OCV correction here)."""
    rep = _cell("capacity_swing_420", effects=["capacity"])
    tmax = rep["record_resolution"]["slow_branch_tau_max_s"]
    assert 400.0 < tmax < 440.0, tmax
    assert rep["selected_effects"] == ["capacity"], rep["selected_effects"]
    cap = rep["final_parameters"]["capacity_ah"]
    assert cap == pytest.approx(_cell_truth("capacity_swing_420")["capacity_ah"], rel=0.05), cap


def test_pybamm_swing_current_offset_named_with_the_offset_its_rests_measure():
    rep = _cell("current_offset_swing", effects=SWING_EFFECTS)
    truth = _cell_truth("current_offset_swing")["current_offset_a"]
    meas = rep["measured_parameters"]["current_offset_a"]
    assert meas["significant"] and meas["value"] == pytest.approx(truth, rel=0.25)
    assert rep["selected_effects"] == ["current_offset"], rep["selected_effects"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(truth, rel=0.25)
    # the measured offset explains the voltage: held-out error down by a quarter or more
    assert rep["rmse_after"]["voltage_v"]["holdout"] < 0.75 * rep["rmse_before"]["voltage_v"]["holdout"]


def test_no_effect_swing_record_names_no_physical_effect():
    rep = _cell("none_swing", effects=SWING_EFFECTS)
    assert not rep["measured_parameters"]["current_offset_a"]["significant"]
    _check_no_effect(rep)


def test_pybamm_drive_current_offset_named_from_the_drives_own_stops():
    """The one-hour drive has no rest stop, but its 20-90 s stops are rests: the logged current there is the
    sensor's offset (measured and held, not inferred from the voltage), and the offset is named on the drive too."""
    rep = _cell("current_offset", effects=SWING_EFFECTS)
    truth = _cell_truth("current_offset")["current_offset_a"]
    meas = rep["measured_parameters"]["current_offset_a"]
    assert meas["significant"] and abs(meas["value"] - truth) < 3.0 * meas["se"], meas
    assert rep["record_resolution"]["rest_current_a"]["n_rests"] >= 10
    assert rep["record_resolution"]["rests_after_current_s"] == []       # none long enough for the slow branch
    assert rep["selected_effects"] == ["current_offset"], rep["selected_effects"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(truth, rel=0.25)
    assert rep["rmse_after"]["voltage_v"]["holdout"] < rep["rmse_before"]["voltage_v"]["holdout"]


def test_no_effect_drive_stops_measure_the_offset_as_zero():
    rep = _cell("none", effects=["current_offset"])
    off = rep["measured_parameters"]["current_offset_a"]
    assert not off["significant"] and abs(off["value"]) < 0.002, off
    assert rep["selected_effects"] == [], rep["selected_effects"]


@pytest.mark.slow
@pytest.mark.parametrize("case, effect, param, truth, rel", [
    ("current_offset", "current_offset", "current_offset_a", 0.1, 0.25),
    ("capacity_swing", "capacity", "capacity_ah", 4.25, 0.05),
    ("capacity_swing_420", "capacity", "capacity_ah", 4.6, 0.05),
    ("current_offset_swing", "current_offset", "current_offset_a", 0.1, 0.25),
])
def test_pybamm_one_effect_named_whole_library(case, effect, param, truth, rel):
    rep = _cell(case)
    assert rep["selected_effects"] == [effect], rep["selected_effects"]
    assert rep["final_parameters"][param] == pytest.approx(truth, rel=rel)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["none_swing", "none_swing_2", "none_swing_mixing"])
def test_no_effect_swing_records_whole_library_name_no_physical_effect(case):
    # none_swing_2 named ocv_hysteresis (+24 mV) and entropic_heat, then (hysteresis refused at its rests) an OCV
    # correction, then a capacity (4.76 A.h): each fitted to the SPMe's voltage under current, none where its rests
    # put it (CellModel._hysteresis_evidence, _rest_claim)
    _check_no_effect(_cell(case))


# ------------------------------------------------------------------ thermal effects: what the record itself shows
#
# A thermal effect's claim is checked on the record's own lumped energy balance, whatever the circuit
# (CellModel.effect_evidence): a cooling change must change the cell's heat loss per kelvin at its time, a
# reversible heat must be carried by the record's balance beside the heat of mixing.  Stated tolerances: the
# entropic record's dU/dT within 0.03 mV/K at the interior SOC knots; the balance's reversible-heat scale of
# the fitted dU/dT at least one half on the records that have it and not significant on those without.

def _discrepancy_of(rep, effect):
    return [d for d in rep["model_form_discrepancy"] if d.get("effect") == effect]


@pytest.mark.parametrize("case", ["arrhenius", "current_offset"])
def test_a_step_in_h_that_only_bends_to_the_thermal_model_form_is_not_a_cooling_change(case):
    """On the Arrhenius and offset records a step in h at a free time (factor 1.5 at 1136 s, 1.8 at 865 s) fitted
    the temperature better, but the record's own heat loss per kelvin is the same on both sides of it."""
    rep = _cell(case, effects=["cooling_change"])
    assert "cooling_change" not in rep["selected_effects"]
    (d,) = _discrepancy_of(rep, "cooling_change")
    (ev,) = d["evidence"]
    assert abs(math.log(ev["ratio"])) < 1.645 * ev["se_ln_ratio"]          # no change of the time constant
    assert abs(math.log(ev["h_change_factor"])) > 0.3                      # though the step fitted is large


def test_the_true_cooling_change_shows_in_the_records_own_energy_balance():
    rep = _cell("cooling_change", effects=["cooling_change"])
    _check_cooling(rep)
    cand = next(c for c in rep["candidates"] if c["name"] == "cooling_change")
    assert cand["passed"]


def test_no_effect_none_2_names_no_reversible_heat():
    """none_2 named entropic_heat (dU/dT 0.1-0.3 mV/K) before: the record's balance does not carry it."""
    rep = _cell("none_2", effects=["entropic_heat", "cooling_change"])
    assert not set(rep["selected_effects"]) & PHYSICAL_CELL, rep["selected_effects"]
    (d,) = _discrepancy_of(rep, "entropic_heat")
    (ev,) = d["evidence"]
    assert abs(ev["reversible_heat_scale"]) < 1.645 * ev["se"]              # not significant


def test_pybamm_entropic_record_names_entropic_heat_near_the_truth():
    """O'Regan 2022's entropic change switched on in PyBaMM: named, the record's own balance carries the fitted
    reversible heat, and the fitted dU/dT is the truth's at the interior knots (the end knots are not: see
    docs/calibration_independent.md)."""
    rep = _cell("entropic", effects=["entropic_heat"])
    assert rep["selected_effects"] == ["entropic_heat"]
    tr = _cell_truth("entropic")
    ov = rep["overlay"]["tables"]["battery"]
    ks, fit = np.array(ov["dudt_soc_frac"]), np.array(ov["dudt_v_k"])
    true = np.interp(ks, tr["dudt_soc_frac"], tr["dudt_v_k"])
    assert np.all(np.abs(fit[1:-1] - true[1:-1]) < 3e-5), (1e3 * fit, 1e3 * true)
    assert rep["rmse_after"]["t_surface_c"]["holdout"] < 0.5 * rep["rmse_before"]["t_surface_c"]["holdout"]
    cand = next(c for c in rep["candidates"] if c["name"] == "entropic_heat")
    assert cand["passed"]


def test_arrhenius_record_names_the_law_its_voltage_shows():
    """Chen2020's own Arrhenius kinetics (truth: apparent Ea/R 1413 K; the cell warms 25 -> 34 degC).  The law
    refitted on the voltage alone, the thermal parameters held at the nominal fit's, is significant by its HAC
    standard error (1431 +- 220 K) and of the joint fit's size (1598 K), so the held-out part has only to
    confirm it (any gain: 4.2 %; the held-out blocks sit within 3 K of the mean temperature, where the law moves
    the voltage little against the circuit's 12 mV form error).  With the thermal parameters free the joint
    fit trades the law against the temperature's form error (2662 K, held-out voltage +12.7 %)."""
    rep = _cell("arrhenius", effects=["arrhenius_resistance", "cooling_change"])
    assert rep["selected_effects"] == ["arrhenius_resistance"], rep["selected_effects"]
    truth = _cell_truth("arrhenius")["arrhenius_ea_r_k"]
    assert rep["final_parameters"]["arrhenius_ea_r_k"] == pytest.approx(truth, rel=0.30)
    cand = next(c for c in rep["candidates"] if c["name"] == "arrhenius_resistance")
    assert cand["passed"] and "claim verified" in cand["reason"], cand["reason"]
    assert 0.0 < cand["gain"] < 0.10                       # below MIN_GAIN: passed by its verified claim
    # the thermal parameters stayed at the nominal fit's (held while the law is in the model)
    for k in ("kt_w_mk", "cp_j_kgk", "h_conv_factor"):
        assert rep["final_parameters"][k] == pytest.approx(rep["baseline_parameters"][k], rel=1e-9)
    # the overlay written, run through the battery component by the master, reproduces the fit (the replay)
    assert rep["replay_max_relative_deviation"] < 0.01, rep["replay"]


def test_a_resistance_that_falls_with_the_soc_as_the_cell_warms_is_not_an_arrhenius_law():
    """none_2_mixing: no temperature law (PyBaMM's exchange currents held at 25 degC; apparent Ea/R -212 K), the
    cell warms 25 -> 44 degC (PyBaMM's heat of mixing) while its SOC falls 81 -> 36 % and its resistance with
    it (6 % from 80 to 60 % SOC).  The joint fit finds 902 K (held-out gain 12.8 %, dBIC -172) and the voltage
    alone 507 +- 300 K: the two trends read as a law.  The claim refitted beside the library's SOC law of the
    resistances (either sign, from a start on each of its branches) is 181 +- 270 K: not named, and the report
    says the record cannot tell a temperature law from an SOC law of the resistances."""
    rep = _cell("none_2_mixing", effects=["arrhenius_resistance"])
    assert rep["selected_effects"] == [], rep["selected_effects"]
    cand = next(c for c in rep["candidates"] if c["name"] == "arrhenius_resistance")
    assert "not supported by the record" in cand["reason"] and "beside low_soc_resistance" in cand["reason"], cand["reason"]
    # the SOC law took the resistance's fall towards low SOC (a negative gain)
    ev = next(x for u in rep["model_form_discrepancy"] if u.get("effect") == "arrhenius_resistance"
              for x in u["evidence"] if "lowsoc_r_gain" in x)
    assert ev["lowsoc_r_gain"] < 0.0, ev
    assert ev["arrhenius_ea_r_k_voltage_v_only"] < 1.645 * ev["arrhenius_ea_r_k_se"], ev
    # without the SOC law the voltage alone would show it (t 1.7): the report says the record cannot tell the two
    # apart, not that the voltage shows no law (the claim vetoes a candidate that passed the held-out rule at the
    # 5 % level; the 3 standard errors of CLAIM_SIGNIFICANCE are for a claim that waives the held-out gain)
    first = next(x for u in rep["model_form_discrepancy"] if u.get("effect") == "arrhenius_resistance"
                 for x in u["evidence"] if "not_separable" in x)
    assert first["not_separable"] and first["without_confounders_arrhenius_ea_r_k_voltage_v_only"] > 1.645 * first[
        "without_confounders_arrhenius_ea_r_k_se"], first


@pytest.mark.slow
@pytest.mark.parametrize("case", ["arrhenius", "current_offset"])
def test_whole_library_names_no_cooling_change_on_the_arrhenius_and_offset_records(case):
    assert "cooling_change" not in _cell(case)["selected_effects"]


def test_energy_balance_recovers_a_lumped_cell_it_did_not_make():
    """The record's own energy balance against an analytical lumped cell (exact exponential steps of
    C dT/dt = Q + Q_rev - hA (T - T_amb)): heat capacity, heat loss per kelvin before and after a step in hA,
    and the reversible heat's scale (1: present, 0: absent), whatever the circuit."""
    from shevsim.calibrate.cell import CellModel
    from shevsim.calibrate.data import MeasuredData

    rng = np.random.default_rng(5)
    t = np.arange(3601.0)
    # charge-sustaining pulses (mean current ~0): on a drive that discharges on average a constant dU/dT is
    # i times a constant, the form of the heat of mixing too, and the balance cannot tell them apart
    i = np.repeat(rng.choice([-6.0, -3.0, 0.0, 3.0, 6.0], size=121), 30)[:t.size]
    soc = 0.6 - np.cumsum(i) / 3600.0 / 5.0
    nom = tomllib.loads((D / "cell_nominal.toml").read_text())
    u = np.interp(soc, nom["ocv"]["soc_frac"], nom["ocv"]["ocv_v"])
    v = u - 0.03 * i                                        # Q = i (U - V) = 0.03 i^2
    cap, dudt = 60.0, 2e-4                                  # J/K, V/K
    ha = np.where(t < 1800.0, 0.06, 0.02)                   # W/K: the cooling falls to a third at 1800 s
    for rev_on in (1.0, 0.0):
        temp = np.empty(t.size)
        temp[0] = 25.0
        for k in range(1, t.size):
            q = 0.03 * i[k] ** 2 - rev_on * i[k] * (temp[k - 1] + 273.15) * dudt
            tau = cap / ha[k]
            temp[k] = 25.0 + q / ha[k] + (temp[k - 1] - 25.0 - q / ha[k]) * math.exp(-1.0 / tau)
        df = pd.DataFrame({"time_s": t, "current_a": i, "voltage_v": v, "t_surface_c": temp,
                           "t_ambient_c": np.full(t.size, 25.0)})
        m = CellModel(dict(nom["params"], ocv_soc_frac=nom["ocv"]["soc_frac"], ocv_v=nom["ocv"]["ocv_v"],
                           soc0_frac=0.6))
        ctx = m.prepare(MeasuredData(df=df, model="cell", path="<analytical>"))
        meas = {"voltage_v": v, "t_surface_c": temp}
        vals = m.full_values({})
        rev = -i * (temp + 273.15) * dudt                   # its form (the balance fits its scale)
        before = m._energy_balance(ctx, vals, meas, t < 1740.0, extra=(rev,))[0]
        after = m._energy_balance(ctx, vals, meas, t > 1860.0, extra=(rev,))[0]
        assert before[0] == pytest.approx(1.0 / cap, rel=0.05)                   # a = 1 / C
        assert before[1] == pytest.approx(0.06 / cap, rel=0.1)                   # b = hA / C
        assert after[1] / before[1] == pytest.approx(1.0 / 3.0, rel=0.1)         # the step in hA
        assert before[3] / before[0] == pytest.approx(rev_on, abs=0.05)          # the reversible heat's scale
        knots = {f"dudt_v_k[{k}]": rev_on * dudt for k in range(len(m.dudt_knots))}
        ev = m.effect_evidence("cooling_change", ctx, m.full_values({"h_change_time_s": 1800.0,
                                                                     "h_change_factor": 1.0 / 3.0, **knots}), meas)
        assert ev["ok"] and ev["evidence"]["ratio"] == pytest.approx(1.0 / 3.0, rel=0.2), ev["statement"]
        knots = {f"dudt_v_k[{k}]": dudt for k in range(len(m.dudt_knots))}
        ev = m.effect_evidence("entropic_heat", ctx, m.full_values({"h_change_time_s": 1800.0,
                                                                    "h_change_factor": 1.0 / 3.0, **knots}), meas)
        assert ev["ok"] is bool(rev_on), ev["statement"]
        assert ev["evidence"]["reversible_heat_scale"] == pytest.approx(rev_on, abs=0.25)


def test_the_first_rest_checks_the_initial_soc_only_when_it_is_relaxed(tmp_path):
    """initial_soc's rest claim includes the record's first rest (before any current) - when the cell is relaxed
    there.  A record whose logger starts 5 s into a rest stop (the none_swing drive from 1865 s: the voltage still
    recovering from the drive block) reads a biased initial SOC, which is what initial_soc corrects: that first
    "rest" is not evidence against it.  The records that start relaxed keep it."""
    from shevsim.calibrate.cell import CellModel
    from shevsim.calibrate.data import load_measured
    from shevsim.calibrate.known import load_params_toml
    nominal = load_params_toml(D / "cell_nominal.toml")
    m = CellModel(nominal)
    m.prepare(load_measured(str(D / "cell_none_swing.csv"), "cell"))
    assert m.first_rest_span == (0, 59)
    df = pd.read_csv(D / "cell_none_swing.csv", comment="#")
    late = df[df["time_s"] >= 1865.0].copy()
    late["time_s"] -= late["time_s"].iloc[0]
    v = late["voltage_v"].to_numpy()[:60]
    assert v[-6:].mean() - v[:6].mean() > 2e-3                      # still relaxing: up after the discharge
    path = tmp_path / "late_start.csv"
    late.to_csv(path, index=False)
    m = CellModel(nominal)
    m.prepare(load_measured(str(path), "cell"))
    assert m.first_rest_span is None
