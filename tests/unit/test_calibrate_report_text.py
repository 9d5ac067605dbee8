"""What a calibration report says beyond its numbers (trial 40): the parameter table's baseline column shows the
nominal's value of an effect's parameter (it showed ``nan`` for the Leaf's 250 W auxiliary load), and a fast record
whose noise floor is its inputs' differentiated noise is told to decimate (a 10 Hz Leaf record: a ~10 kW floor,
"Nothing found"; ``--decimate 10``: 1240 W)."""
from __future__ import annotations

import pytest

from shevsim.calibrate.report import baseline_values, md_parameters, run_calibration
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
