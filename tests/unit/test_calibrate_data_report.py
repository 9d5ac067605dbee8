"""Calibration without trial and error (issue 26): every problem of a data file in one message (missing columns
with their candidates, repeated rows, a sign that contradicts the data), the current sign guessed from the
voltage response and stated, the shipped measured records listed and named in place of a path, and the
baseline-failure hint reflecting what was already verified."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shevsim.calibrate.cli import list_records, load_params_toml, main_calibrate
from shevsim.calibrate.data import guess_current_sign, load_measured, measured_records, resolve_record
from shevsim.calibrate.models import get_model
from shevsim.calibrate.synthetic import synth_cell
from shevsim.core.errors import DataError

SEED = 7
#: the shipped record's own header (data/measured/panasonic_18650pf: Kollmeyer's column names), charge positive
RENAME = {"time_s": "Time", "current_a": "Current", "voltage_v": "Voltage", "t_surface_c": "Battery_Temp_degC",
          "t_ambient_c": "Chamber_Temp_degC"}


@pytest.fixture(scope="module")
def cell_df():
    df, _ = synth_cell({}, seed=SEED, duration_s=600.0)
    return df


def _logger_file(df: pd.DataFrame, path: Path, dup_at=(100, 300)) -> Path:
    """The record as a battery tester writes it: its own column names, charge-positive current, an extra
    column, and repeated rows."""
    out = df.rename(columns=RENAME)
    out["Current"] = -out["Current"]
    out["Ah"] = np.cumsum(out["Current"]) * 0.1 / 3600
    parts, last = [], 0
    for k in dup_at:
        parts += [out.iloc[last:k + 1], out.iloc[k:k + 1]]
        last = k + 1
    parts.append(out.iloc[last:])
    pd.concat(parts).to_csv(path, index=False)
    return path


def test_all_problems_of_a_file_at_once(tmp_path, cell_df):
    p = _logger_file(cell_df, tmp_path / "tester.csv")
    with pytest.raises(DataError) as ei:
        load_measured(p, "cell", current_sign="auto")
    msg = str(ei.value)
    assert msg.startswith(f"{p}: 6 problems")
    for canon, col in RENAME.items():           # every missing column, each with the right candidate
        assert f"missing required column '{canon}'" in msg and f"--map {canon}={col}" in msg, canon
    assert "identical rows: 2 row(s)" in msg and "--drop-duplicate-rows" in msg
    assert "current sign guessed from the data: charge-positive" in msg
    # a sign given against the data is one more problem in the same message
    with pytest.raises(DataError) as ei:
        load_measured(p, "cell", current_sign="discharge-positive")
    assert "7 problems" in str(ei.value) and "--current-sign charge-positive" in str(ei.value)
    # the options the message gives load it, and the guessed sign is stated
    d = load_measured(p, "cell", RENAME, current_sign="auto", drop_duplicate_rows=True)
    np.testing.assert_allclose(d.df["current_a"].to_numpy(), cell_df["current_a"].to_numpy())
    assert len(d.df) == len(cell_df)
    assert any(n.startswith("current sign guessed from the data: charge-positive") for n in d.notes)
    assert d.checks["current_sign"]["how"] == "guessed" and d.checks["current_sign"]["corr_dI_dV"] < -0.3


def test_sign_guess_is_the_physics(cell_df):
    i, v = cell_df["current_a"].to_numpy(), cell_df["voltage_v"].to_numpy()
    assert guess_current_sign(i, v)[0] == "discharge-positive"      # voltage falls as discharge current rises
    assert guess_current_sign(-i, v)[0] == "charge-positive"
    flat = np.zeros_like(i)
    assert guess_current_sign(flat, v) == (None, None)


def test_no_candidate_is_said_so(tmp_path, cell_df):
    p = tmp_path / "few.csv"
    cell_df.drop(columns=["t_ambient_c"]).rename(columns={"voltage_v": "Voltage"}).to_csv(p, index=False)
    with pytest.raises(DataError) as ei:
        load_measured(p, "cell")
    msg = str(ei.value)
    assert "2 problems" in msg and "candidate 'Voltage'" in msg
    assert "missing required column 't_ambient_c' (ambient temperature [degC]) for model 'cell'; no column looks like it" in msg


def test_shipped_records_listed_and_named():
    recs = {r["name"]: r for r in measured_records()}
    name = "panasonic_18650pf/25degC_US06_Pan18650PF"
    assert name in recs and Path(recs[name]["path"]).is_file()
    assert recs[name]["options"]["current_sign"] == "charge-positive"
    assert resolve_record(name + ".csv")["path"] == recs[name]["path"] and resolve_record("nosuch") is None
    assert f"shevsim calibrate cell {name} --out DIR" in list_records()
    # the declared options load the real record in one go (sign stated by the record, and consistent)
    o = recs[name]["options"]
    d = load_measured(recs[name]["path"], "cell", o["map"], current_sign=o["current_sign"],
                      drop_duplicate_rows=o["drop_duplicate_rows"])
    assert d.checks["current_sign"]["corr_dI_dV"] < -0.3 and len(d.df) == 48060
    assert main_calibrate(["--records"]) == 0


def test_record_name_errors_and_params_by_name(tmp_path, capsys):
    assert main_calibrate(["cell", "nosuch_record", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "shipped records: " in err and "panasonic_18650pf/25degC_US06_Pan18650PF" in err
    assert main_calibrate(["vehicle", "panasonic_18650pf/25degC_US06_Pan18650PF", "--out", str(tmp_path / "o")]) == 2
    assert "is a cell record, not vehicle" in capsys.readouterr().err
    assert load_params_toml("battery/default")["__base_dir__"].endswith("battery")


def test_failure_hint_reflects_the_checks(tmp_path, cell_df):
    p = _logger_file(cell_df, tmp_path / "tester.csv")
    d = load_measured(p, "cell", RENAME, current_sign="charge-positive", drop_duplicate_rows=True)
    model = get_model("cell", {})
    diag = {"bias": 0.0, "rmse": 1.0, "correlations": []}
    causes = model.likely_causes("voltage_v", diag, d)
    assert not any("--current-sign" in c or "units or sign" in c for c in causes)
    assert any("charge-positive, as stated) agrees with the voltage response" in c for c in causes)
    assert any("units or sign" in c for c in model.likely_causes("voltage_v", diag))      # nothing verified


def test_every_unit_problem_of_a_file_at_once_with_the_options_that_fix_each(tmp_path):
    """Trial 40: a vehicle record with the speed in km/h and the power in kW was refused for the speed alone, and
    the kW power was reported only on the second run.  Every column's unit check (and every layout problem: a
    missing column beside them) is one message, each with its option, and the options given load the file."""
    from shevsim.calibrate.synthetic import synth_vehicle
    df, _ = synth_vehicle({}, seed=SEED, duration_s=300.0)
    p = tmp_path / "logger.csv"
    df.assign(speed_mps=df["speed_mps"] * 3.6, power_w=df["power_w"] / 1000.0).to_csv(p, index=False)
    with pytest.raises(DataError) as ei:
        load_measured(p, "vehicle")
    msg = str(ei.value)
    assert msg.startswith(f"{p}: 2 problems"), msg
    assert "column 'speed_mps'" in msg and "looks like km/h" in msg and "column 'power_w'" in msg and "looks like kW" in msg
    assert msg.rstrip().endswith("the options that fix the fixable ones: --unit speed_mps=kmh --unit power_w=kW"), msg
    d = load_measured(p, "vehicle", units={"speed_mps": "kmh", "power_w": "kW"})
    np.testing.assert_allclose(d.df["power_w"].to_numpy(), df["power_w"].to_numpy(), rtol=1e-12)
    # a missing column beside a unit problem: both in one message, each with its option (the candidate's unit
    # read from its name is part of its --map fix)
    p2 = tmp_path / "logger2.csv"
    df.assign(speed_mps=df["speed_mps"] * 3.6, power_w=df["power_w"] / 1000.0).rename(
        columns={"time_s": "Time", "power_w": "HVBatt_Pwr_kW"}).to_csv(p2, index=False)
    with pytest.raises(DataError) as ei:
        load_measured(p2, "vehicle")
    msg = str(ei.value)
    assert msg.startswith(f"{p2}: 3 problems"), msg
    assert "--map time_s=Time" in msg and "--map power_w=HVBatt_Pwr_kW --unit power_w=kW" in msg and \
        "--unit speed_mps=kmh" in msg, msg
    d = load_measured(p2, "vehicle", {"time_s": "Time", "power_w": "HVBatt_Pwr_kW"},
                      units={"speed_mps": "kmh", "power_w": "kW"})
    np.testing.assert_allclose(d.df["speed_mps"].to_numpy(), df["speed_mps"].to_numpy(), rtol=1e-12)
    # a cell: voltage in mV, the surface temperature in kelvin and a non-numeric current value, all at once
    cdf, _ = synth_cell({}, seed=SEED, duration_s=300.0)
    cdf = cdf.assign(voltage_v=cdf["voltage_v"] * 1000.0, t_surface_c=cdf["t_surface_c"] + 273.15).astype(object)
    cdf.loc[20, "current_a"] = "1,2"
    p3 = tmp_path / "cell.csv"
    cdf.to_csv(p3, index=False)
    with pytest.raises(DataError) as ei:
        load_measured(p3, "cell", current_sign="discharge-positive")
    msg = str(ei.value)
    assert "3 problems" in msg and "non-numeric value '1,2'" in msg and "looks like millivolts" in msg and \
        "looks like kelvin" in msg, msg
    assert "fixable ones: --unit t_surface_c=K --unit voltage_v=mV" in msg, msg


def test_constant_ambient_given_on_the_command_line_or_in_params(tmp_path, capsys):
    """Trial 40: a cell record without an ambient column was refused ("missing required column 't_ambient_c'")
    with no way round it but editing the file.  A chamber or a room at one temperature is a constant: given by
    --ambient-c (or t_ambient_c in --params), stated in the report; the refusal names the option; an implausible
    value, a vehicle, or a file with its own ambient column too is a clear error naming what gave it."""
    df, _ = synth_cell({}, seed=SEED, duration_s=600.0)
    p = tmp_path / "no_ambient.csv"
    df.drop(columns=["t_ambient_c"]).to_csv(p, index=False)
    with pytest.raises(DataError, match=r"missing required column 't_ambient_c'.*for a constant ambient pass "
                                        r"--ambient-c DEGC \(or t_ambient_c = DEGC in the --params file's \[params\]\)"):
        load_measured(p, "cell")
    d = load_measured(p, "cell", ambient_c=25.0)
    assert (d.df["t_ambient_c"] == 25.0).all() and "ambient: constant 25 degC, given by --ambient-c" in d.notes
    np.testing.assert_allclose(d.df["voltage_v"].to_numpy(), df["voltage_v"].to_numpy())
    out = tmp_path / "o"
    for bad in ("-300", "400", "nan"):
        assert main_calibrate(["cell", str(p), "--out", str(out), "--ambient-c", bad, "-q"]) == 2
        err = capsys.readouterr().err
        assert f"--ambient-c {float(bad)!r}: ambient temperature outside the plausible range [-60, 150] degC" in err, err
    assert main_calibrate(["vehicle", str(p), "--out", str(out), "--ambient-c", "25", "-q"]) == 2
    assert "--ambient-c: a constant ambient temperature is an input of model 'cell' only" in capsys.readouterr().err
    both = tmp_path / "with_ambient.csv"
    df.to_csv(both, index=False)
    with pytest.raises(DataError, match=r"the file has an ambient column \('t_ambient_c'\) and --ambient-c gives a "
                                        r"constant 20 degC: keep one"):
        load_measured(both, "cell", ambient_c=20.0)
    assert not out.exists()                                           # nothing written on bad input
    # the whole command, end to end: the constant stated in the report
    params = tmp_path / "nominal.toml"
    params.write_text("[params]\ncapacity_ah = 2.3\nt_ambient_c = 25.0\n")
    assert main_calibrate(["cell", str(p), "--out", str(out), "--params", str(params), "--no-plots", "-q",
                           "--effects", "capacity"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert f"ambient: constant 25 degC, given by t_ambient_c in {params}" in rep["data"]["notes"]
    assert f"- note: ambient: constant 25 degC, given by t_ambient_c in {params}" in (out / "report.md").read_text()
    params.write_text("[params]\ncapacity_ah = 2.3\nt_ambient_c = 400.0\n")
    assert main_calibrate(["cell", str(p), "--out", str(tmp_path / "o2"), "--params", str(params), "-q"]) == 2
    assert f"t_ambient_c in {params} 400.0: ambient temperature outside" in capsys.readouterr().err
