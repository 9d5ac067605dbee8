"""The shipped Nissan Leaf cell record (ORNL, MIT; ``data/measured/nissan_leaf_cell``) calibrates end to end.

Real measurements: a 33 Ah LMO/LNO pouch cell, 1C discharge to 3.0 V, rests, C/2 CC-CV charge, with the
middle-of-face thermocouple as surface temperature.  The nominal is what a user can derive from the same
project's independent 25 degC HPPC test (``ocv_25degC_hppc.toml`` by ``make_records.py``: OCV from the 1 h
rests, capacity from Ah counting).  The full calibration (every candidate effect, ~3 min) is reported in
``docs/calibration_independent.md``: it names ``entropic_heat`` (held-out surface temperature 0.61 -> 0.17 K,
voltage 12.1 -> 8.7 mV) and states the rest as a model-form discrepancy.  Here the nominal and that one
effect are run against the record (tens of seconds), through the record's declared options as
``shevsim calibrate cell nissan_leaf_cell/leaf_1C`` applies them.
"""
from __future__ import annotations

import pytest

from shevsim.calibrate.data import load_measured, resolve_record
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.workflow import run_workflow


@pytest.fixture(scope="module")
def leaf_report():
    rec = resolve_record("nissan_leaf_cell/leaf_1C")
    assert rec is not None and rec["model"] == "cell"
    opts = rec["options"]
    data = load_measured(rec["path"], "cell", current_sign=opts["current_sign"])
    from pathlib import Path
    known = load_params_toml(Path(rec["folder"]) / opts["params"])
    return run_workflow("cell", data, known, plots=False, effects=["entropic_heat"])


def test_leaf_record_names_entropic_heat_with_a_real_improvement(leaf_report):
    rep = leaf_report
    assert rep["selected_effects"] == ["entropic_heat"]
    b, a = rep["rmse_before"], rep["rmse_after"]
    assert a["t_surface_c"]["holdout"] < 0.5 * b["t_surface_c"]["holdout"]
    # the voltage: within the selection rule's 10 % - the baseline's local optimum depends on the floating-point
    # environment (the same code and packages: 12.1 -> 8.7 mV on the tenth session's machine; on an AMD EPYC's
    # OpenBLAS kernels the baseline reaches 8.2 mV and 0.76 K, and the effect ends at 8.7 mV and 0.17 K)
    assert a["voltage_v"]["holdout"] < 1.1 * b["voltage_v"]["holdout"]
    assert rep["score_after"] < 0.8
    # the replay through the battery component reproduces the fit (the record stays within 0..100 % SOC)
    assert rep["replay"] and "error" not in rep["replay"]
    assert rep["replay_max_relative_deviation"] < 1e-6


def test_leaf_record_states_what_the_model_cannot_explain(leaf_report):
    rep = leaf_report
    bf = {x["channel"]: x for x in rep["baseline_failure"]}
    assert set(bf) == {"voltage_v", "t_surface_c"}                 # the nominal fails on both, > 10x the noise
    stated = {d.get("channel") for d in rep["model_form_discrepancy"]}
    assert "voltage_v" in stated                                   # still well above the noise after the effect
