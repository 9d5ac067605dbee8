"""Cell calibration on the battery component's own model: undeclared effects in data from the plant
(the battery component stepped by the master), named, halved, carried by an overlay and replayed through
the simulator."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from shevsim.calibrate.cell import CELL_EFFECTS, CellModel
from shevsim.calibrate.cli import main_calibrate
from shevsim.calibrate.synthetic import CELL_NOMINAL, as_measured, synth_cell
from shevsim.calibrate.workflow import run_workflow
from shevsim.core.overlay import overlay_values

SEED = 7
# effect -> (channel it acts on, synth_cell options)
CASES = {
    "entropic_heat": ("t_surface_c", {}),
    "arrhenius_resistance": ("voltage_v", {"ambient": "warmup"}),
    "cooling_change": ("t_surface_c", {}),
    # hysteresis shows where rests are reached from both sides (CellModel._hysteresis_evidence): the record has
    # rests after charge, as a lab's hysteresis test has; a drive that only discharges between its rests cannot
    # tell hysteresis from an OCV offset / correction
    "ocv_hysteresis": ("voltage_v", {"charge_rests": True}),
    "capacity": ("voltage_v", {}),
    "current_offset": ("voltage_v", {}),
    "low_soc_resistance": ("voltage_v", {"soc0": 0.5, "discharge_frac": 0.45}),
    "second_rc_branch": ("voltage_v", {}),
    "initial_soc": ("voltage_v", {}),
    "ocv_correction": ("voltage_v", {}),
    "solid_diffusion": ("voltage_v", {}),
}


def _run(effects, seed=SEED, nominal=None, out=None, restrict=None, **kw):
    df, truth = synth_cell({e: {} for e in effects}, seed=seed, **kw)
    nominal = dict(nominal or CELL_NOMINAL)
    if "soc0" in kw:
        nominal["soc0_frac"] = kw["soc0"]        # the record's known initial SOC
    rep = run_workflow("cell", as_measured(df, "cell"), nominal, out_dir=out,
                       effects=restrict, plots=False)
    return rep, truth


def _check_replay(rep):
    assert rep["replay"] is not None
    for c, r in rep["replay"].items():
        for part in ("train", "holdout"):
            assert r[part] == pytest.approx(rep["rmse_after"][c][part], rel=0.01), (c, part, r, rep["rmse_after"][c])


def test_every_effect_of_the_library_has_a_case():
    m = CellModel(dict(CELL_NOMINAL))
    assert set(m.effects) == set(CASES)
    assert len(CELL_EFFECTS) == len(CASES)


# in the slow run (the default run's ~10-minute budget): the effects the default run names on records the
# project did not make - PyBaMM's Arrhenius kinetics (test_calibrate_independent_cell.py,
# test_arrhenius_record_names_the_law_its_voltage_shows), its heat-transfer change at a time
# (test_pybamm_cooling_change_named_with_its_factor_and_time) and the Leaf cell's entropic heat
_SLOW_HERE = {"arrhenius_resistance", "cooling_change", "entropic_heat"}   # entropic heat: the Nissan Leaf cell's record
                                                                            # (test_calibrate_leaf.py), real data
# also in the slow run (the default run took ~21 minutes on a 2-core machine): four more of these cases. The default
# run keeps four (initial_soc, low_soc_resistance, second_rc_branch, and ocv_correction: no other default test names
# an OCV correction) of this test; capacity and current_offset are
# named in the default run by test_cli_accepts_a_component_parameter_file (capacity) and
# test_overlay_is_a_battery_parameter_set_and_shevsim_run_uses_it (current_offset, its value within 0.03 A) here, and
# on PyBaMM's records (test_calibrate_independent_cell.py); ocv_hysteresis is one of the two effects of
# test_two_effects_are_both_found_or_the_remainder_reported (both named, or the remainder reported);
# solid_diffusion is named on this plant's records in the slow run only (a nominal with it is fitted in the default
# run: test_calibrate_independent_nmc2.py::test_nmc2_solid_diffusion_in_the_nominal_explains_part_of_the_form_error)
_SLOW_HERE |= {"capacity", "current_offset", "ocv_hysteresis", "solid_diffusion"}


@pytest.mark.parametrize("effect", [pytest.param(e, marks=pytest.mark.slow) if e in _SLOW_HERE else e
                                    for e in sorted(CASES)])
def test_single_undeclared_effect_is_named_halved_and_replayed(effect):
    channel, kw = CASES[effect]
    rep, _ = _run([effect], **kw)
    assert effect in rep["selected_effects"], [(c["name"], c["score"], c["reason"]) for c in rep["candidates"]]
    assert len(rep["selected_effects"]) <= 2
    before, after = rep["rmse_before"][channel]["holdout"], rep["rmse_after"][channel]["holdout"]
    assert after <= 0.5 * before, (channel, before, after)
    _check_replay(rep)


def test_no_missing_effect_selects_nothing_and_baseline_sits_at_the_noise():
    rep, _ = _run([])
    assert rep["selected_effects"] == [] and rep["nothing_found"]
    assert not any(c["passed"] for c in rep["candidates"])
    assert rep["rmse_before"]["voltage_v"]["holdout"] < 0.0025        # sensor noise 2 mV
    assert rep["rmse_before"]["t_surface_c"]["holdout"] < 0.07        # sensor noise 0.05 K
    assert rep["baseline_failure"] == []
    _check_replay(rep)


def test_two_effects_are_both_found_or_the_remainder_reported():
    rep, _ = _run(["cooling_change", "ocv_hysteresis"], charge_rests=True)
    sel = set(rep["selected_effects"])
    assert sel == {"cooling_change", "ocv_hysteresis"} or rep["unexplained"], rep["selected_effects"]
    for ch in ("voltage_v", "t_surface_c"):
        assert rep["rmse_after"][ch]["holdout"] <= 0.5 * rep["rmse_before"][ch]["holdout"]
    _check_replay(rep)


def test_failing_baseline_is_said(tmp_path):
    """A nominal whose capacity is 48 % of the cell's cannot follow the voltage; with the capacity effect
    withheld, the report says the baseline fails (channel, ratio, correlations, causes) in JSON and words."""
    nominal = dict(CELL_NOMINAL, capacity_ah=1.1)
    rep, _ = _run([], nominal=nominal, out=tmp_path, restrict=["entropic_heat", "cooling_change"])
    bf = {b["channel"]: b for b in rep["baseline_failure"]}
    assert "voltage_v" in bf, rep["baseline_failure"]
    b = bf["voltage_v"]
    assert b["ratio_to_noise_floor"] > 20.0 and b["correlated_signals"] and b["likely_causes"]
    assert any("capacity" in c for c in b["likely_causes"]), b["likely_causes"]
    md = (tmp_path / "report.md").read_text()
    assert "nominal model fails" in md


def test_overlay_is_a_battery_parameter_set_and_shevsim_run_uses_it(tmp_path):
    rep, truth = _run(["current_offset"], out=tmp_path)
    ov = overlay_values(tmp_path / "params.toml", "battery")
    assert ov.values["current_offset_a"] == pytest.approx(0.15, abs=0.03)
    assert ov.values["rs_scale"] == pytest.approx(truth["rs_scale"], rel=0.1)
    # the overlay in a whole-vehicle scenario: the battery component takes it
    from shevsim.core.scenario import build_master, load_scenario
    root = Path(__file__).resolve().parents[2]
    sc = load_scenario(root / "scenarios" / "hd_udds_rule.toml", ["cycle.repeat=1"],
                       overlays=[f"battery={tmp_path / 'params.toml'}"])
    m = build_master(sc)
    bat = m.components["battery"]
    assert bat.params.current_offset_a == ov.values["current_offset_a"]
    assert bat.params.rs_scale == ov.values["rs_scale"]
    assert bat.params.n_series == 130          # the rest of the pack's parameters are the scenario's


def test_cli_accepts_a_component_parameter_file(tmp_path):
    df, _ = synth_cell({"capacity": {}}, seed=SEED, duration_s=1200.0)
    csv = tmp_path / "cell.csv"
    df.to_csv(csv, index=False)
    p = tmp_path / "battery.toml"
    p.write_text('[meta]\nsource = "test"\n[params]\ncapacity_ah = 2.3\nentropic_heat = false\n'
                 'temperature_dependent = false\nr2_scale = 0.0\nsoc_init_pct = 95.0\n')
    out = tmp_path / "out"
    assert main_calibrate(["cell", str(csv), "--out", str(out), "--params", str(p), "--no-plots", "-q"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert "capacity" in rep["selected_effects"]
    assert (out / "params.toml").is_file()
    assert rep["replay"]["voltage_v"]["holdout"] == pytest.approx(rep["rmse_after"]["voltage_v"]["holdout"], rel=0.01)


@pytest.mark.slow
def test_false_selection_rate_over_twenty_noise_realisations():
    """Data with no missing effect, 20 noise/profile realisations: at most one false selection."""
    false = [s for s in range(20) if _run([], seed=100 + s, duration_s=1200.0)[0]["selected_effects"]]
    assert len(false) <= 1, false


def test_scenario_field_overlay_and_precedence(tmp_path):
    """A scenario's [components.X] overlay = FILE applies the overlay's [X] table (relative *_file paths against
    the overlay's folder); the component's set table and --set still win over it."""
    from shevsim.core.overlay import write_overlay
    from shevsim.core.scenario import build_master, load_scenario
    root = Path(__file__).resolve().parents[2]
    (tmp_path / "ocv.csv").write_text((root / "components" / "battery" / "a123_26650_ocv.csv").read_text())
    write_overlay(tmp_path / "params.toml", {"battery": {"rs_scale": 1.25, "hyst_max_v": 0.01, "ocv_file": "ocv.csv"}})
    text = (root / "scenarios" / "hd_udds_rule.toml").read_text()
    text = text.replace('[components.battery]\n', f'[components.battery]\noverlay = "{tmp_path / "params.toml"}"\n', 1)
    sc_file = tmp_path / "s.toml"
    sc_file.write_text(text)
    bat = build_master(load_scenario(sc_file, ["battery.hyst_max_v=0.02"])).components["battery"]
    assert bat.params.rs_scale == 1.25 and bat.params.hyst_max_v == 0.02
    assert Path(bat.params.ocv_file) == (tmp_path / "ocv.csv").resolve()


def test_arrhenius_claim_is_tested_on_the_voltage_alone():
    """``arrhenius_resistance`` claims that the resistances follow exp(Ea/R (1/T - 1/T_ref)); the workflow
    refits Ea/R on the voltage alone (temperature weight 0, thermal parameters held) and needs it significant
    and of the joint fit's size (``_Run.channel_claim``).  A warm-up record (chamber -10 -> +25 degC, a seed
    the selection tests do not use) with the law (Ea/R 4000 K) in the voltage: the voltage alone finds it.
    The same drive without the law, with a joint fit that claims 4000 K: the voltage alone does not."""
    from shevsim.calibrate.workflow import _Run
    eff = ("arrhenius_resistance",)
    out = {}
    for case, effects in (("law", ["arrhenius_resistance"]), ("none", [])):
        df, truth = synth_cell({e: {} for e in effects}, seed=23, ambient="warmup", duration_s=1800.0)
        run = _Run("cell", as_measured(df, "cell"), dict(CELL_NOMINAL), 0.3, "blocks", None, "<params>", None,
                   {"sample_convention": "instantaneous", "sensor_noise": {}})
        f = run.fitter
        base = f.fit((), max_nfev=40)
        joint = f.evaluate(eff, dict(base.params, arrhenius_ea_r_k=4000.0), len(base.params) + 1)
        out[case] = run.channel_claim("arrhenius_resistance", joint)
    law = out["law"]["evidence"]
    assert out["law"]["ok"], out["law"]["statement"]
    assert law["arrhenius_ea_r_k_voltage_v_only"] == pytest.approx(4000.0, rel=0.25), out["law"]["statement"]
    assert law["arrhenius_ea_r_k_se"] < 0.25 * 4000.0
    assert not out["none"]["ok"], out["none"]["statement"]
    assert "not" in out["none"]["statement"]


def test_overlay_carries_the_initial_soc_only_when_the_effect_is_named(tmp_path):
    """The record's own initial SOC (the effect's neutral value) is not a property of the cell: an overlay that
    carried it started every scenario at the record's SOC (the Panasonic 25 degC overlay: 100 %, and a vehicle run
    stopped at t = 0 with the SOC above 100 %).  A fitted, named initial SOC travels (the replay needs it)."""
    df, _ = synth_cell({}, duration_s=600.0, seed=SEED)
    m = CellModel(dict(CELL_NOMINAL))
    m.prepare(as_measured(df, "cell"))
    assert m.effects["initial_soc"].neutral["soc_init_pct"] == pytest.approx(95.0) != m.base.soc_init_pct
    assert "soc_init_pct" not in m.overlay({}, tmp_path)["battery"]
    assert m.overlay({"soc_init_pct": 80.0}, tmp_path)["battery"]["soc_init_pct"] == 80.0
