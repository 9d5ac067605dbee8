"""A new user's records of a vehicle and two cells the project never used (eighth session; made by
``tests/data/independent/make_vehicle_fastsim_bolt.py`` - FASTSim 3.1's 2020 Chevrolet Bolt EV - and
``make_cell_pybamm_oos.py`` - PyBaMM's Ai2020 LCO and Mohtat2020 NMC532 cells), each with the nominal such a user
has.  What they showed, and what the calibration does since:

* a vehicle given without its motor map took the project's 380 kW truck motor's, its efficiency scales ended on
  their bound, and a mass 9 % and a drag 23 % too low were named on a record with neither: the defaults used are
  now stated, and effects that pass only beside declared parameters held by a bound are a model-form discrepancy;
* a current offset the rests measured (0.1001 A, truth 0.1) lost to a capacity 15 % high that fitted 1.7 points
  better: a measured effect is now selected before the inferred ones of its round;
* a measured offset that cut the held-out voltage error 45 % was vetoed by the BIC (the training fit had bent to
  its absence): a significant measurement is judged on the held-out part.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from shevsim.calibrate.cli import build_parser
from shevsim.calibrate.data import load_measured
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.workflow import render_markdown, run_workflow

D = Path(__file__).resolve().parents[1] / "data" / "independent"


def _truth(group: str) -> dict:
    return json.loads((D / f"{group}_truth.json").read_text())["cases"]


def _run(group: str, case: str, model: str, effects=None, nominal: str | None = None):
    tc = _truth(group)[case]
    nom = D / (nominal or tc.get("nominal", f"{group}_nominal.toml"))
    data = load_measured(str(D / tc.get("file", f"{group}_{case}.csv")), model)
    return run_workflow(model, data, load_params_toml(nom), plots=False, effects=effects), tc["truth"]


def test_vehicle_without_its_motor_map_names_no_physics_and_says_whose_map_it_used():
    """The Bolt's no-effect UDDS record with a spec-sheet nominal that has no motor map: the defaults used are
    named (the truck's map), the efficiency scales end on their bound with the record pushing past it, and the
    mass / drag errors that passed beside them are a model-form discrepancy, not the result."""
    rep, _ = _run("vehicle_bolt", "none_nomap", "vehicle")
    used = {d["parameter"] for d in rep["defaults_used"]}
    assert {"efficiency_map_file", "rated_power_w"} <= used, used
    assert "mass_kg" not in used and "drag_coefficient" not in used          # given by the user
    assert rep["selected_effects"] == [], rep["selected_effects"]
    pinned = [d for d in rep["model_form_discrepancy"] if d.get("declared_on_bound")]
    assert pinned and {b["parameter"] for b in pinned[0]["declared_on_bound"]} & {
        "efficiency_scale_frac", "regen_efficiency_scale_frac"}
    assert all(b["dbic_beyond"] <= -10.0 for b in pinned[0]["declared_on_bound"])
    gone = [d for d in rep["model_form_discrepancy"] if d.get("effect") in (
        "mass_error", "aero_error", "rolling_error", "road_grade", "aux_load")]
    assert gone and all("not as the cause" in d["statement"] for d in gone)   # what had passed, stated as not the cause
    md = render_markdown(rep)
    assert "Not in `--params`" in md and "M-ATV" in md


def test_vehicle_with_its_published_curve_names_the_payload():
    """The same vehicle given with its published efficiency curve: +300 kg named within 5 %, nothing pinned."""
    rep, truth = _run("vehicle_bolt", "payload", "vehicle")
    assert rep["selected_effects"] == ["mass_error"], rep["selected_effects"]
    assert rep["final_parameters"]["mass_kg"] == pytest.approx(truth["mass_kg"], rel=0.05)
    assert not [d for d in rep["model_form_discrepancy"] if d.get("declared_on_bound")]
    assert "efficiency_map_file" not in {d["parameter"] for d in rep["defaults_used"]}


def _scaled_curve_nominal(tmp_path, factor: float) -> str:
    """The Bolt's nominal with its published efficiency curve scaled by ``factor`` (a map too pessimistic)."""
    lines = (D / "vehicle_bolt_eff_curve.csv").read_text().splitlines()
    out = []
    for ln in lines:
        parts = ln.split(",")
        if ln.startswith("#") or parts[0] == "speed_radps":
            out.append(ln)
        else:
            out.append(",".join(parts[:2] + [f"{float(parts[2]) * factor:.6f}"]))
    (tmp_path / "eff.csv").write_text("\n".join(out) + "\n")
    nom = (D / "vehicle_bolt_nominal.toml").read_text()
    nom = nom.replace('"vehicle_bolt_eff_curve.csv"', '"eff.csv"').replace(
        '"vehicle_bolt_torque.csv"', f'"{(D / "vehicle_bolt_torque.csv").as_posix()}"')
    (tmp_path / "nominal.toml").write_text(nom)
    return str(tmp_path / "nominal.toml")


@pytest.mark.parametrize("factor", [0.88, pytest.param(0.84, marks=pytest.mark.slow)])
def test_a_map_too_pessimistic_is_profiled_past_its_bound_not_read_as_mass(tmp_path, factor):
    """The Bolt's no-effect record given its published curve x 0.88 (x 0.84): the motor efficiency scale ends on
    its 1.08 guard and a mass 6 % low took the push it could not follow (named before the profile: a false
    selection the one-parameter probe did not see).  Profiled past the guard the record needs no mass: nothing
    named, the mass stated as a stand-in, and the scale the record takes past the guard is the map's error - 1/factor
    times the scale fitted with the true curve (an exact compensation the test knows independently of the fit).
    With no effect named the final model keeps the declared range and the profile is stated, not adopted."""
    rep, _ = _run("vehicle_bolt", "none", "vehicle", nominal=_scaled_curve_nominal(tmp_path, factor))
    ref, _ = _run("vehicle_bolt", "none", "vehicle")
    assert rep["selected_effects"] == [], rep["selected_effects"]
    gone = [d for d in rep["model_form_discrepancy"] if d.get("effect") == "mass_error"]
    assert gone and "stood in for the declared freedom" in gone[0]["statement"], rep["model_form_discrepancy"]
    (said,) = [d for d in rep["model_form_discrepancy"] if d.get("declared_on_bound")]
    (scale,) = [b for b in said["declared_on_bound"] if b["parameter"] == "efficiency_scale_frac" and not b.get("probe")]
    want = ref["final_parameters"]["efficiency_scale_frac"] / factor
    assert scale["profiled_value"] == pytest.approx(want, rel=0.02)
    assert "not adopted" in said["statement"], said["statement"]
    lo, hi = scale["declared_range"]
    assert lo <= rep["final_parameters"]["efficiency_scale_frac"] <= hi


@pytest.mark.parametrize("case, param, factor", [
    ("payload", "mass_kg", 0.84), pytest.param("aux", "aux_power_w", 0.88, marks=pytest.mark.slow)])
def test_a_true_effect_beside_a_pessimistic_map_is_named_with_the_records_value(tmp_path, case, param, factor):
    """The payload (aux) record given the curve x 0.84 (x 0.88): the one-parameter probe removed every physical
    effect (the true payload reported as a discrepancy); the profile keeps what the record still needs with the
    scale free past its guard, and its value is the one fitted there (mass 1923 vs 1926 kg; held within the guard
    the mass was 1753 kg)."""
    rep, truth = _run("vehicle_bolt", case, "vehicle", nominal=_scaled_curve_nominal(tmp_path, factor))
    expect = {"mass_kg": "mass_error", "aux_power_w": "aux_load"}[param]
    assert rep["selected_effects"] == [expect], rep["selected_effects"]
    tol = 0.05 if param == "mass_kg" else 0.15
    assert rep["final_parameters"][param] == pytest.approx(truth[param], rel=tol)
    stated = [d for d in rep["model_form_discrepancy"] if d.get("declared_on_bound")]
    assert stated and "that fit is the final one" in stated[0]["statement"], rep["model_form_discrepancy"]


def test_a_measured_offset_is_named_before_an_inferred_capacity():
    """Ai2020 (LCO), +0.1 A on the logged current: both candidates pass in round 1 and the capacity (15 % high)
    fits the held-out part better; the offset the rests measure is named, and the capacity is not."""
    rep, truth = _run("cell_ai2020", "current_offset", "cell", effects=["capacity", "current_offset"])
    r1 = {c["name"]: c for c in rep["rounds"][0]["candidates"]}
    assert r1["capacity"]["passed"] and r1["current_offset"]["passed"]          # the situation the rule is for
    assert rep["measured_parameters"]["current_offset_a"]["significant"]
    assert rep["selected_effects"] == ["current_offset"], rep["selected_effects"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(truth["current_offset_a"], rel=0.05)


def test_a_significant_measured_offset_is_judged_on_the_held_out_part():
    """Mohtat2020 (NMC532), +0.1 A: the offset cuts the held-out voltage error by more than a third while the
    training fit's BIC rises; the measurement is named."""
    rep, truth = _run("cell_mohtat2020", "current_offset", "cell", effects=["current_offset"])
    c = rep["rounds"][0]["candidates"][0]
    assert c["name"] == "current_offset"
    gain = 1.0 - c["holdout_rmse"]["voltage_v"] / rep["rmse_before"]["voltage_v"]["holdout"]
    assert gain > 0.3 and c["delta_bic"] > 0.0, (gain, c["delta_bic"])         # the rules disagree here
    assert rep["selected_effects"] == ["current_offset"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(truth["current_offset_a"], rel=0.05)
    assert "in the final model" in render_markdown(rep)


def test_sensor_noise_takes_several_channels_repeated_or_comma_separated():
    from shevsim.calibrate.cli import _sensor_noise
    a = build_parser().parse_args(["vehicle", "--sensor-noise", "power_w=300,speed_mps=0.02", "r.csv", "-o", "out"])
    assert a.data == "r.csv"                      # a positional after the option is not taken as a noise value
    assert _sensor_noise(a.sensor_noise) == {"power_w": 300.0, "speed_mps": 0.02}
    a = build_parser().parse_args(["vehicle", "r.csv", "-o", "out", "--sensor-noise", "power_w=300",
                                   "--sensor-noise", "speed_mps=0.02"])
    assert _sensor_noise(a.sensor_noise) == {"power_w": 300.0, "speed_mps": 0.02}


@pytest.mark.slow
@pytest.mark.parametrize("group", ["cell_ai2020", "cell_mohtat2020"])
@pytest.mark.parametrize("case", ["none", "none_2", "none_3"])
def test_out_of_sample_no_effect_cells_name_no_physical_effect(group, case):
    """Nothing named - except the generator's own solid diffusion, which every SPMe record has and the nominal
    lacks: allowed (not required) with its time constant within 25 % of the range of the particles' R^2/D
    (``solid_diffusion_time_s`` of the truth file, from PyBaMM's parameters; Mohtat2020 ``none_3`` names it at
    1136 s, the electrodes' 1250 and 1531 s)."""
    rep, _ = _run(group, case, "cell")
    sel = rep["selected_effects"]
    assert set(sel) <= {"solid_diffusion"}, sel
    if sel:
        tr = json.loads((D / f"{group}_truth.json").read_text())["solid_diffusion_time_s"]
        lo, hi = sorted((tr["negative"], tr["positive"]))
        assert lo / 1.25 <= rep["final_parameters"]["diffusion_time_s"] <= 1.25 * hi, rep["final_parameters"]


@pytest.mark.slow
@pytest.mark.parametrize("group", ["cell_ai2020", "cell_mohtat2020"])
@pytest.mark.parametrize("case", ["current_offset", "current_offset_2"])
def test_out_of_sample_offsets_whole_library(group, case):
    """The whole library: the offset named within 25 % and no temperature law beside it (the cells have none:
    an Arrhenius claim at 2.4 standard errors passed at the former 5 % level)."""
    rep, truth = _run(group, case, "cell")
    assert "current_offset" in rep["selected_effects"] and "capacity" not in rep["selected_effects"]
    assert "arrhenius_resistance" not in rep["selected_effects"], rep["selected_effects"]
    assert rep["final_parameters"]["current_offset_a"] == pytest.approx(truth["current_offset_a"], rel=0.25)


def test_an_ocv_table_in_discharge_order_or_in_percent_is_the_same_curve(tmp_path):
    """The trial's refused nominals: a C/50 discharge lists the curve from full to empty, and SOC in % is the
    project's own convention elsewhere.  Both read as the increasing table; a table that is not monotonic, or gives
    both keys, is still refused with the file named."""
    from shevsim.calibrate.cell import CellModel
    from shevsim.core.errors import DataError
    base = load_params_toml(D / "cell_ai2020_nominal.toml")
    soc, v = list(base["ocv_soc_frac"]), list(base["ocv_v"])
    head = "[params]\ncapacity_ah = 2.28\nsoc0_frac = -1.0\n[ocv]\n"
    desc = tmp_path / "desc.toml"
    desc.write_text(head + f"soc_frac = {soc[::-1]}\nocv_v = {v[::-1]}\n")
    pct = tmp_path / "pct.toml"
    pct.write_text(head + f"soc_pct = {[100.0 * x for x in soc]}\nocv_v = {v}\n")
    for f in (desc, pct):
        k = load_params_toml(f)
        assert k["ocv_soc_frac"] == pytest.approx(soc) and k["ocv_v"] == pytest.approx(v)
        CellModel(k, str(f))                                   # the model takes it
    bad = tmp_path / "bad.toml"
    bad.write_text(head + f"soc_frac = {[soc[1], soc[0]] + soc[2:]}\nocv_v = {v}\n")
    with pytest.raises(DataError, match="bad.toml"):
        CellModel(load_params_toml(bad), str(bad))
    both = tmp_path / "both.toml"
    both.write_text(head + f"soc_frac = {soc}\nsoc_pct = {soc}\nocv_v = {v}\n")
    with pytest.raises(DataError, match="both.toml.*one of soc_frac, soc_pct"):
        load_params_toml(both)


def test_a_constant_grade_is_named_as_grade_not_as_tyres():
    """A new user's trial (tests/data/independent/make_vehicle_fastsim_trial40.py): FASTSim's 2016 Nissan Leaf on
    UDDS up a constant 2 % grade.  While the car moves a constant grade and the rolling resistance are the same
    force; the rolling coefficient scored 0.2 % better and was named at f_r = 0.0287, 3.6x the given 0.008.  A
    rolling coefficient is plausible within a factor 2 of the given one (one tyre class on paved roads): the grade
    is named, each knot within 0.004 of the true 0.02."""
    data = load_measured(str(D / "vehicle_trial40_leaf_grade.csv"), "vehicle",
                         mapping={"time_s": "Time", "speed_mps": "VehSpd_kph", "power_w": "HVBatt_Pwr_kW"},
                         units={"speed_mps": "kmh", "power_w": "kW"})
    rep = run_workflow("vehicle", data, load_params_toml(D / "vehicle_trial40_leaf_nominal.toml"), plots=False)
    assert rep["selected_effects"] == ["road_grade"], rep["selected_effects"]
    knots = [rep["final_parameters"][f"grade_frac[{j}]"] for j in range(6)]
    assert all(abs(g - 0.02) < 0.004 for g in knots), knots
    said = [d for d in rep["model_form_discrepancy"] if d.get("effect") == "rolling_error"]
    assert said and "plausible range" in said[0]["statement"], rep["model_form_discrepancy"]


def test_a_rest_still_relaxing_does_not_confirm_a_capacity():
    """A new user's trial (tests/data/independent/make_cell_pybamm_trial40.py): PyBaMM's ORegan2022 (LG M50) on a
    drive-and-park with no effect.  A capacity 8 % low passed the held-out rule (gain 10.0 %), and its claim at the
    one rest as long as the slow relaxation (483 s) looked confirmed: -13.9 mV there against the -14.6 mV the
    capacity put there.  But the voltage less the model's was still rising at that rest's end (the LG M50's slow
    solid diffusion, which the circuit does not follow): by its own tail about 22 mV were still to come, so the
    rest cannot tell the capacity from its absence.  Nothing is named; the evidence says how much was still
    relaxing.  (A true capacity on rests the model follows, capacity_swing_420, is still named: the test above.)"""
    m = {"time_s": "Test_Time(s)", "current_a": "Current(A)", "voltage_v": "Voltage(V)",
         "t_surface_c": "Aux_Temperature_1(C)", "t_ambient_c": "Chamber_Temperature(C)"}
    data = load_measured(str(D / "cell_trial40_oregan2022_none.csv"), "cell", mapping=m, current_sign="auto")
    rep = run_workflow("cell", data, load_params_toml(D / "cell_trial40_oregan2022_nominal.toml"), plots=False,
                       effects=["capacity"])
    assert rep["selected_effects"] == [], rep["selected_effects"]
    (cand,) = [c for c in rep["rounds"][0]["candidates"] if c["name"] == "capacity"]
    # Whether the capacity tempts the held-out rule at all depends on the baseline's local optimum, which depends on
    # the floating-point environment (the same code and packages: 10.0 % on the tenth session's machine; on an AMD
    # EPYC's OpenBLAS kernels the baseline lands elsewhere and the capacity gains -3.4 %, refused by the held-out
    # rule).  Where it passes the held-out rule, its claim at the still-relaxing rest is what refuses it.
    if cand["gain"] < 0.10:
        assert not cand["passed"] and "held-out" in cand["reason"], cand
        return
    (d,) = [d for d in rep["model_form_discrepancy"] if d.get("effect") == "capacity"]
    (ev,) = [x for x in d["evidence"] if "still_relaxing_v" in x]
    assert max(abs(x) for x in ev["still_relaxing_v"]) > max(abs(x) for x in ev["rest_end_deviation_v"]), ev
    assert "still relaxing" in d["statement"]
    # its first rest and one rest after current: the rests' scatter is not measured, and the report does not
    # pretend to a t-test (the first rest's deviation, ~0 where the initial SOC was read, made its standard error)
    assert ev["n_rests"] == 2 and ev["t_test"] is False and ev["se"] is None, ev
    assert "judged by its size alone" in d["statement"]


def test_a_capacity_the_nominal_already_mimics_is_said_to_be_inseparable():
    """A new user's trial: PyBaMM's Marquis2019 (Kokam 0.68 A.h pouch) with 12 % lost capacity.  The baseline
    stretches its slow RC branch (r2_scale 3.15, c2_scale 35) to stand in for it; the capacity then fits 0.615 A.h
    (2.7 % from the truth) but gains 0.2 % held-out, the branch going back (0.85, 0.29) - the record cannot tell
    the two apart.  Not named; before, the report did not say why."""
    from shevsim.calibrate.report import run_calibration
    m = {"time_s": "Test_Time(s)", "current_a": "Current(A)", "voltage_v": "Voltage(V)",
         "t_surface_c": "Aux_Temperature_1(C)"}
    rep = run_calibration("cell", D / "cell_trial40_marquis2019_capacity.csv", map=m, ambient_c=25.0,
                          params=D / "cell_trial40_marquis2019_nominal.toml", effects=["capacity"], plots=False).report
    assert rep["selected_effects"] == [], rep["selected_effects"]
    (d,) = [d for d in rep["model_form_discrepancy"] if d.get("effect") == "capacity"]
    assert "cannot be told from them" in d["statement"], d["statement"]
    (moved,) = [x["declared_moved"] for x in d["evidence"] if "declared_moved" in x]
    assert {"r2_scale", "c2_scale"} <= set(moved), moved
    truth = json.loads((D / "cell_trial40_marquis2019_truth.json").read_text())["cases"]["capacity"]["truth"]
    (cap,) = [x["value"] for x in d["evidence"] if x.get("parameter") == "capacity_ah"]
    assert cap == pytest.approx(truth["capacity_ah"], rel=0.05)     # the fit was right: the record cannot say so


def test_the_inseparable_statement_is_not_made_from_a_shape_parameter_or_a_declared_parameter_on_a_bound():
    """The statement above first fired on most cell records from an effect's shape parameter while the effect was
    off (the low-SOC resistance's scale, the hysteresis rate) and from declared parameters pinned on a bound (a
    thermal conductivity at 0.05) - a reviewer's finding.  Only amplitude parameters with a nonzero neutral value and
    declared parameters off their bounds count: ORegan2022's no-effect drive says nothing of the kind."""
    m = {"time_s": "Test_Time(s)", "current_a": "Current(A)", "voltage_v": "Voltage(V)",
         "t_surface_c": "Aux_Temperature_1(C)", "t_ambient_c": "Chamber_Temperature(C)"}
    data = load_measured(str(D / "cell_trial40_oregan2022_none.csv"), "cell", mapping=m, current_sign="auto")
    rep = run_workflow("cell", data, load_params_toml(D / "cell_trial40_oregan2022_nominal.toml"), plots=False)
    said = [d for d in rep["model_form_discrepancy"] if "cannot be told from them" in d.get("statement", "")]
    assert not said, [d["statement"] for d in said]


def test_with_no_effect_named_a_profile_past_the_guard_is_stated_not_adopted():
    """Two reviewers' findings.  The ninth session adopted the profile past a plausibility guard as the final model
    when effects had been selected going in: the Bolt's no-effect record with its curve x 0.88 ended past the guard
    (the mass removed as a stand-in, nothing named) while the Leaf's payload record, nothing selected, ended on it.
    Adopted everywhere, the Leaf's final model put the payload's inertial power into a regenerative efficiency
    1.14-1.17 (the truth is +250 kg), and on payload_2 fitted the held-out part worse (1551 W against 1539 W).  With
    no effect named the final model keeps the declared ranges, on both records, and the profile is stated with its
    numbers (FASTSim's 2016 Leaf, +250 kg: the mass candidate fits 1917 kg against the truth 1926 kg but gains 8.8 %
    held out, under the 10 % rule)."""
    data = load_measured(str(D / "vehicle_trial40_leaf_payload.csv"), "vehicle",
                         mapping={"time_s": "Time", "speed_mps": "VehSpd_kph", "power_w": "HVBatt_Pwr_kW"},
                         units={"speed_mps": "kmh", "power_w": "kW"})
    rep = run_workflow("vehicle", data, load_params_toml(D / "vehicle_trial40_leaf_nominal.toml"), plots=False)
    assert rep["selected_effects"] == [], rep["selected_effects"]
    (said,) = [d for d in rep["model_form_discrepancy"] if d.get("declared_on_bound")]
    assert "not adopted" in said["statement"], said["statement"]
    past = 0
    for b in said["declared_on_bound"]:
        if b.get("probe"):
            continue
        lo, hi = b["declared_range"]
        assert lo <= rep["final_parameters"][b["parameter"]] <= hi, (b, rep["final_parameters"])
        past += not lo <= b["profiled_value"] <= hi
    assert past >= 1, said
    assert {p["parameter"] for p in rep["parameters_at_bounds"]} & {b["parameter"] for b in said["declared_on_bound"]}
    (mass,) = [c for c in rep["candidates"] if c["name"] == "mass_error"]
    assert mass["parameters"]["mass_kg"] == pytest.approx(1926.0, rel=0.05) and not mass["passed"]
