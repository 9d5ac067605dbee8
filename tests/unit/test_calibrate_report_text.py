"""What a calibration report says beyond its numbers (trial 40): the parameter table's baseline column shows the
nominal's value of an effect's parameter (it showed ``nan`` for the Leaf's 250 W auxiliary load), and a fast record
whose noise floor is its inputs' differentiated noise is told to decimate (a 10 Hz Leaf record: a ~10 kW floor,
"Nothing found"; ``--decimate 10``: 1240 W)."""
from __future__ import annotations

import pytest

from shevsim.calibrate.cli import report_lines
from shevsim.calibrate.report import baseline_values, decimate_advice, md_parameters, run_calibration
from shevsim.calibrate.synthetic import synth_vehicle

SEED = 7


@pytest.fixture()
def nominal(tmp_path):
    p = tmp_path / "nominal.toml"
    p.write_text("[params]\naux_power_w = 250.0\n")
    return p


def test_baseline_column_shows_the_nominal_value_of_an_effects_parameter(tmp_path, nominal):
    df, truth = synth_vehicle({"aux_load": {}}, duration_s=600.0, dt_s=1.0, seed=SEED)
    df.to_csv(tmp_path / "rec.csv", index=False)
    cal = run_calibration("vehicle", tmp_path / "rec.csv", params=nominal, effects=["aux_load"], plots=False)
    rep = cal.report
    assert rep["selected_effects"] == ["aux_load"] and "aux_power_w" not in rep["baseline_parameters"]
    md = "\n".join(md_parameters(rep))
    assert "| aux_power_w | 250 (nominal) |" in md and "nan" not in md, md
    assert "Baseline column: the nominal model's value - fitted for a declared parameter" in md
    for k in ("efficiency_scale_frac", "regen_efficiency_scale_frac"):      # declared: the nominal fit's
        assert baseline_values(rep)[k] == (pytest.approx(rep["baseline_parameters"][k]), "fitted")
    html = cal.to_html()
    assert "250 (nominal)</td>" in html and "Baseline column: the nominal model" in html
    # an element of a list parameter (grade knots) and the effect's declared neutral value, which comes first
    rep2 = {"baseline_parameters": {}, "known_parameters": {"grade_frac": [0.0, 0.01], "aux_power_w": 250.0},
            "final_parameters": {"grade_frac[1]": 0.02, "grade_frac[3]": 0.0, "aux_power_w": 900.0},
            "effect_neutral": {"aux_power_w": 300.0}}
    assert baseline_values(rep2) == {"grade_frac[1]": (0.01, "nominal"), "grade_frac[3]": (None, "-"),
                                     "aux_power_w": (300.0, "nominal")}


def test_fast_record_whose_floor_is_its_inputs_noise_is_told_to_decimate(tmp_path, nominal):
    df, _ = synth_vehicle({"aux_load": {}}, duration_s=300.0, dt_s=0.1, seed=SEED)
    df.to_csv(tmp_path / "rec10hz.csv", index=False)
    fast = run_calibration("vehicle", tmp_path / "rec10hz.csv", params=nominal, effects=["aux_load"], plots=False)
    nf = fast.report["noise_floor"]["power_w"]
    assert nf["propagated_inputs"]["value"] > 10.0 * nf["sensor"]["value"]      # speed noise differentiated at 0.1 s
    adv = decimate_advice(fast.report)
    assert adv is not None and "`--decimate 10` (keeps every 10th row: sample interval 0.1 s -> 1 s" in adv, adv
    assert any(line.startswith("advice: ") and "--decimate 10" in line for line in report_lines(fast.report))
    assert "--decimate 10" in fast.to_html()
    # the advice taken: the inputs' part of the floor falls (about the 10x said, >= 4x), and no advice remains
    slow = run_calibration("vehicle", tmp_path / "rec10hz.csv", params=nominal, effects=["aux_load"], plots=False,
                           decimate=10)
    nf10 = slow.report["noise_floor"]["power_w"]
    assert nf10["propagated_inputs"]["value"] < nf["propagated_inputs"]["value"] / 4.0, (nf, nf10)
    assert decimate_advice(slow.report) is None
    # the rule: an inputs' part > 3x the sensor's on a record sampled faster than 1 s
    rep = {"timing": {"sample_interval_s": 0.2}, "differentiated_inputs": ["speed_mps"],
           "noise_floor": {"power_w": {"sensor": {"value": 100.0},
                                       "propagated_inputs": {"value": 290.0, "inputs": {"speed_mps": {}}}}}}
    assert decimate_advice(rep) is None
    rep["noise_floor"]["power_w"]["propagated_inputs"]["value"] = 310.0
    assert "--decimate 5" in decimate_advice(rep)
    rep["timing"]["sample_interval_s"] = 1.0
    assert decimate_advice(rep) is None
    # an input the model does not differentiate (a cell's current, integrated into heat and charge: the Panasonic
    # -20 degC record at 10 Hz has a temperature floor 38x its sensor part from the current's noise) is not helped
    # by decimation: no advice
    rep["timing"]["sample_interval_s"] = 0.1
    rep["differentiated_inputs"] = []
    rep["noise_floor"] = {"t_surface_c": {"sensor": {"value": 0.001},
                                          "propagated_inputs": {"value": 0.04, "inputs": {"current_a": {}}}}}
    assert decimate_advice(rep) is None
