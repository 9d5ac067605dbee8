"""A new user's third trial (tenth session; ``tests/data/independent/make_cell_pybamm_trial41.py``,
``make_vehicle_fastsim_trial41.py``, runner ``eval_trial41_calibrate.py``): records of models and parameter sets the
project had never used - PyBaMM's DFN (not the SPMe of the earlier records) on Ramadass2004 (an 18650 LCO cell) and
OKane2022 (LG M50 21700), and FASTSim 3.1 with an electric minivan (the Pacifica's chassis, the Bolt's powertrain) -
given with a user's nominal only.  The cases the calibration gets right are kept here as regression cases (and the
false Arrhenius law the trial found on a Ramadass2004 drive, now refused); the ones it does not (a solid diffusion
for a capacity on Ramadass2004's 300 s parks, a
cooling change its energy balance cannot show, an OKane2022 capacity 5.002 % low, an OKane2022 offset that loses to
the initial SOC on the held-out part) are in ``docs/calibration_independent.md``, "A third new-user trial"."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from shevsim.calibrate.data import load_measured
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.workflow import run_workflow

D = Path(__file__).resolve().parents[1] / "data" / "independent"
CELL = {"time_s": "t_s", "current_a": "I_pack_A", "voltage_v": "U_cell_V", "t_surface_c": "T_cell_degC",
        "t_ambient_c": "T_amb_degC"}
VEH = {"time_s": "time_s", "speed_mps": "speed_kmh", "power_w": "batt_power_kw"}
PHYSICAL = {"mass_error", "aux_load", "road_grade", "rolling_error", "aero_error", "regen_limit", "entropic_heat",
            "arrhenius_resistance", "cooling_change", "ocv_hysteresis", "capacity", "current_offset",
            "low_soc_resistance", "second_rc_branch", "initial_soc", "ocv_correction", "solid_diffusion"}
PRE = {"ra": "cell_trial41_ramadass2004", "ok": "cell_trial41_okane2022", "emv": "vehicle_trial41_emv"}


def _run(gen: str, case: str, convention=None, effects=None):
    pre = PRE[gen]
    truth = json.loads((D / f"{pre}_truth.json").read_text())
    c = truth["cases"][case]
    if gen == "emv":
        data = load_measured(str(D / c["file"]), "vehicle", mapping=VEH, units={"speed_mps": "kmh", "power_w": "kW"})
        model = "vehicle"
    else:
        data = load_measured(str(D / c["file"]), "cell", mapping=CELL, current_sign="auto")
        model = "cell"
    rep = run_workflow(model, data, load_params_toml(D / f"{pre}_nominal.toml"), plots=False,
                       sample_convention=convention, effects=effects)
    return rep, c["truth"]


def test_the_report_tells_refused_candidates_from_what_the_model_leaves(tmp_path):
    """A new user's reading of the minivan's grade record: road_grade takes the held-out error from 3562 W to 740 W,
    and report.md listed an implausible rolling coefficient and drag under "Model-form discrepancy (not explained by
    any effect of the library)".  They are candidates refused as explanations; the discrepancy section is what the
    final model leaves."""
    import re
    pre = PRE["emv"]
    truth = json.loads((D / f"{pre}_truth.json").read_text())
    data = load_measured(str(D / truth["cases"]["grade"]["file"]), "vehicle", mapping=VEH,
                         units={"speed_mps": "kmh", "power_w": "kW"})
    rep = run_workflow("vehicle", data, load_params_toml(D / f"{pre}_nominal.toml"), plots=False, out_dir=tmp_path)
    assert rep["selected_effects"] == ["road_grade"], rep["selected_effects"]
    md = (tmp_path / "report.md").read_text()
    refused = [d["effect"] for d in rep["model_form_discrepancy"] if d.get("effect")]
    assert refused, rep["model_form_discrepancy"]
    sec = re.search(r"\*\*Candidates refused or removed as explanations\*\*.*?(?:\n\n|\Z)", md, re.S)
    assert sec and all(f"'{e}'" in sec.group(0) for e in refused), md
    assert "not explained by any effect of the library" not in md


@pytest.mark.slow     # the default run: the grade record above (named, and its report)
def test_minivan_payload_is_named_as_mass_within_5_percent():
    rep, truth = _run("emv", "payload")
    assert rep["selected_effects"] == ["mass_error"], rep["selected_effects"]
    assert rep["final_parameters"]["mass_kg"] == pytest.approx(truth["mass_kg"], rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("gen, case", [("ra", "none"), ("ra", "none_2"), ("ok", "none"), ("ok", "none_2"), ("ok", "none_swing"),
                                       ("ok", "none_standing_charge"),
                                       ("emv", "none"), ("emv", "none_2"), ("emv", "none_2hz"),
                                       ("emv", "none_mean")])
def test_no_effect_records_name_no_physical_effect(gen, case):
    rep, _ = _run(gen, case)
    assert not set(rep["selected_effects"]) & PHYSICAL, rep["selected_effects"]


@pytest.mark.slow
@pytest.mark.parametrize("gen, case, effect, param, rel", [
    ("ra", "current_offset", "current_offset", "current_offset_a", 0.25),
    ("ra", "capacity_swing", "capacity", "capacity_ah", 0.05),
    ("ok", "capacity_swing", "capacity", "capacity_ah", 0.05),
    ("ok", "current_offset_swing", "current_offset", "current_offset_a", 0.25),
    ("ok", "cooling_change", "cooling_change", "h_change_factor", 0.30),
    ("emv", "aux", "aux_load", "aux_power_w", 0.15),
    ("emv", "latency_2", "timing", "time_shift_s", None),
    ("emv", "payload_mean", "mass_error", "mass_kg", 0.05)])
def test_one_effect_records_name_it_within_tolerance(gen, case, effect, param, rel):
    rep, truth = _run(gen, case)
    assert rep["selected_effects"] == [effect], rep["selected_effects"]
    if rel is None:
        assert abs(rep["final_parameters"][param] - truth[param]) <= 0.25
    else:
        assert rep["final_parameters"][param] == pytest.approx(truth[param], rel=rel)


@pytest.mark.slow
def test_minivan_grade_is_named_with_its_mean_grade():
    rep, truth = _run("emv", "grade")
    assert rep["selected_effects"] == ["road_grade"], rep["selected_effects"]
    g = [v for k, v in rep["final_parameters"].items() if k.startswith("grade_frac[")]
    assert sum(g) / len(g) == pytest.approx(truth["grade_frac"], rel=0.25)


@pytest.mark.slow
def test_a_drive_and_park_warming_is_not_read_as_a_temperature_law():
    """Ramadass2004 (DFN, no temperature dependence: the generator holds its kinetics at 25 degC) warms 1.3-2.2 K
    over four 10-minute drives with 5-minute parks.  ``arrhenius_resistance`` was named at Ea/R 1709 K, passed by
    its claim on the voltage alone (2466 +- 440 K beside the SOC law): the particles' diffusion overpotential
    builds under current and relaxes at rest, as the temperature rises and falls.  Beside the diffusion too the
    voltage alone shows no law (0 K, at its bound), and the report says the record cannot tell them apart."""
    rep, _ = _run("ra", "none_2", effects=["arrhenius_resistance"])
    assert rep["selected_effects"] == [], rep["selected_effects"]
    (c,) = [c for c in rep["rounds"][0]["candidates"] if c["name"] == "arrhenius_resistance"]
    assert not c["passed"]


def test_a_real_standing_current_at_rest_is_not_read_as_a_sensor_offset():
    """A reviewer's record (fifteenth session): OKane2022 DFN with a real -0.2 A current all through, rests included,
    logged as it flows - no offset.  The rests read -0.2003 +- 0.0004 A, as they do on the offset record
    (``current_offset``), so the level alone cannot tell the two apart; the fit under load must gain with the
    offset, and here it loses (the nominal fails at 12.5x its noise floor, where a waived gain named this offset).
    The report says what else the level can be."""
    rep, _ = _run("ok", "none_standing_charge", effects=["current_offset", "initial_soc"])
    assert "current_offset" not in rep["selected_effects"], rep["selected_effects"]
    m = rep["measured_parameters"]["current_offset_a"]
    assert m["significant"] and m["value"] == pytest.approx(-0.2, abs=0.002)
    (c,) = [c for c in rep["rounds"][0]["candidates"] if c["name"] == "current_offset"]
    assert not c["passed"] and c["gain"] <= 0.0, c
    from shevsim.calibrate.workflow import render_markdown
    md = render_markdown(rep)
    assert "**not applied**" in md and "a real current the cell carried at rest" in md, md
