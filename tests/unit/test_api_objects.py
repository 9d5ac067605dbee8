"""run_study and run_calibration return objects a notebook uses: DataFrames, a best map, a Figure, save(),
a short repr; the command line is a printer over the same calls and writes the same files."""
import json
import math
import tomllib

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

import shevsim
from shevsim.calibrate.report import CalibrationReport
from shevsim.core.atomic import MANIFEST
from shevsim.calibrate.synthetic import synth_vehicle
from shevsim.core.errors import DataError, ScenarioError, ShevsimError
from shevsim.studies.result import StudyResult


def _one_line_and_short(text: str) -> bool:
    return "\n" not in text and len(text) < 260


def test_run_study_tradeoff_in_a_notebook(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                      # out=None writes nothing, not even a default folder
    st = shevsim.run_study("tradeoff", synthetic=True, workers=0, rates_kwps=[40, 30, 20, 10], fe_loss_pct=0.5)
    assert isinstance(st, StudyResult) and list(tmp_path.iterdir()) == []
    df = st.tables["tradeoff"]
    assert isinstance(df, pd.DataFrame) and list(df["rate_wps"]) == [40e3, 30e3, 20e3, 10e3]
    # the best map: the lowest soot among the rates within the fuel-economy loss, found here from the table
    ok = df[df["fe_change_pct"] >= -0.5 - 1e-9]
    best_rate = ok.sort_values(["soot_g_per_km", "rate_wps"], ascending=[True, False]).iloc[0]["rate_wps"]
    bm = st.best_map
    n_seg = len(bm["edges_w"]) - 1
    assert bm["rates_wps"] == [best_rate] * n_seg and math.isclose(bm["soot_g_per_km"], ok["soot_g_per_km"].min())
    # the soot does not rise as the rate limit tightens, and falls overall (the seed's Fig. A.2 trend)
    soot = df["soot_g_per_km"].to_numpy()
    assert np.all(np.diff(soot) <= 0) and soot[-1] < soot[0]
    fig = st.plot()
    assert isinstance(fig, Figure)
    xs = sorted(fig.axes[0].lines[0].get_xdata())
    assert xs == [10.0, 20.0, 30.0, 40.0]            # kW/s on the x axis
    assert _one_line_and_short(repr(st)) and "tradeoff" in repr(st) and f"{best_rate / 1e3:g} kW/s" in repr(st)
    assert "<table" in st._repr_html_()
    saved = st.save(tmp_path / "saved")
    # what save writes, and the hidden list of its hashes (a file changed since is never replaced on a re-save)
    assert {p.name for p in saved.iterdir() if p.name != MANIFEST} == set(st.files) >= {
        "fig_a2_tradeoff.png", "summary.json", "tradeoff.csv", "report.html"}
    assert set(json.loads((saved / MANIFEST).read_text())["sha256"]) == set(st.files)
    assert json.loads((saved / "summary.json").read_text())["best_within_loss"]["rate_wps"] == best_rate


def test_the_cli_writes_what_save_writes(tmp_path, capsys):
    from shevsim.cli import main
    args = ["--synthetic", "--workers", "0", "--rates-kwps", "20", "40"]
    assert main(["study", "tradeoff", *args, "--out", str(tmp_path / "cli")]) == 0
    assert f"outputs in {tmp_path / 'cli'}" in capsys.readouterr().out
    st = shevsim.run_study("tradeoff", synthetic=True, workers=0, rates_kwps=[20, 40])
    st.save(tmp_path / "api")
    cli_files = sorted(p.name for p in (tmp_path / "cli").iterdir() if p.name != "cache.sqlite")
    assert cli_files == sorted(p.name for p in (tmp_path / "api").iterdir())
    assert (tmp_path / "cli" / "tradeoff.csv").read_bytes() == (tmp_path / "api" / "tradeoff.csv").read_bytes()
    assert (tmp_path / "cli" / "cache.sqlite").is_file()   # the cache stays with --out (a rerun resumes)


def test_study_save_keeps_what_a_user_wrote(tmp_path):
    st = shevsim.run_study("tradeoff", synthetic=True, workers=0, rates_kwps=[20], plots=False)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "tradeoff.csv").write_text("my own table\n")
    with pytest.raises(ShevsimError, match="no summary.json"):
        st.save(mine)
    assert (mine / "tradeoff.csv").read_text() == "my own table\n"
    (mine / "notes.txt").unlink(missing_ok=True)
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    st.save(other)                                   # no clash: written beside the user's file
    assert (other / "notes.txt").read_text() == "keep" and (other / "summary.json").is_file()


def test_run_study_options_are_checked_by_name():
    with pytest.raises(ScenarioError, match="did you mean 'rates_kwps'"):
        shevsim.run_study("tradeoff", synthetic=True, workers=0, rate_kwps=[20])
    with pytest.raises(ScenarioError, match="did you mean 'tradeoff'"):
        shevsim.run_study("tradeof", synthetic=True)


def test_run_study_powerrate_map_best_map_and_figures():
    st = shevsim.run_study("powerrate-map", synthetic=True, workers=0, generations=3, population=6, max_cases=20,
                           seed=3)
    bm = st.best_map
    assert len(bm["rates_wps"]) == len(bm["edges_w"]) - 1
    top = st.tables["top_solutions"]
    assert {"fe_change_pct", "soot_change_pct", "rate_d1_wps"} <= set(top.columns)
    # the best map is the first of the top table, and it meets the fuel-economy constraint (0.4 %)
    assert math.isclose(top["soot_change_pct"].iloc[0], bm["soot_change_pct"])
    assert bm["fe_change_pct"] >= -0.4 - 1e-9
    assert {"exhaustive", "ga_history", "constant_limits"} <= set(st.tables)
    assert isinstance(st.plot(), Figure) and isinstance(st.plot("comparison"), Figure)
    with pytest.raises(ScenarioError, match="'maps' or 'comparison'"):
        st.plot("nope")


def _vehicle_record(tmp_path):
    """A synthetic vehicle record with a regenerative-braking limit the nominal model lacks; the file
    logs delivered power as positive under its own column names (as tests/unit/test_calibrate.py)."""
    df, truth = synth_vehicle({"regen_limit": {}}, seed=7, duration_s=900.0)
    df = df.rename(columns={"power_w": "P_bus", "speed_mps": "v"})
    df["P_bus"] = -df["P_bus"]
    csv = tmp_path / "veh.csv"
    df.to_csv(csv, index=False)
    params = tmp_path / "p.toml"
    params.write_text('[params]\nmass_kg = 15554.0\nefficiency_scale_frac = 0.9\n')
    return csv, params, truth


def test_run_calibration_in_a_notebook(tmp_path, monkeypatch):
    csv, params, truth = _vehicle_record(tmp_path)
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    cal = shevsim.run_calibration("vehicle", csv, params=params, map={"power_w": "P_bus", "speed_mps": "v"},
                                  power_sign="delivered-positive",
                                  sample_convention="power_w=mean-ending")   # synth_vehicle: the period's mean power, the speed at t
    assert isinstance(cal, CalibrationReport) and sorted(p.name for p in tmp_path.iterdir()) == before
    assert cal.selected_effects == ["regen_limit"]
    ba = cal.before_after
    assert isinstance(ba, pd.DataFrame) and "power_w" in ba.index
    assert ba.loc["power_w", "holdout_after"] <= 0.5 * ba.loc["power_w", "holdout_before"]
    if "replay_holdout" in ba:                       # the overlay replayed through the simulator agrees
        assert ba.loc["power_w", "replay_holdout"] == pytest.approx(ba.loc["power_w", "holdout_after"], rel=0.05)
    assert isinstance(cal.candidates, pd.DataFrame) and "regen_limit" in set(cal.candidates["name"])
    # the overlay carries the synthetic truth (within 2 %), and the params.toml text says the same as the dict
    motor = cal.overlay["motor"]
    for k, v in truth.items():
        assert motor[k] == pytest.approx(v, rel=0.02), (k, motor[k], v)
    assert tomllib.loads(cal.overlay_toml)["motor"] == motor
    assert isinstance(cal.plot(), Figure) and isinstance(cal.plot("fit_before_after.png"), Figure)
    with pytest.raises(DataError, match="no figure"):
        cal.plot("fit.png")
    assert _one_line_and_short(repr(cal)) and "regen_limit" in repr(cal) and "<table" in cal._repr_html_()
    out = cal.save(tmp_path / "cal")
    names = {p.name for p in out.iterdir()}
    assert {"params.toml", "report.json", "report.md", "fit_before_after.png", "residuals_before_after.png"} <= names
    assert json.loads((out / "report.json").read_text())["selected_effects"] == ["regen_limit"]
    from shevsim.calibrate.known import load_params_toml      # the saved overlay reads back as --params
    assert "__tables__" in load_params_toml(out / "params.toml")


def test_run_calibration_bad_input_names_the_problem(tmp_path):
    with pytest.raises(DataError, match="did you mean 'vehicle'"):
        shevsim.run_calibration("vehicel", tmp_path / "x.csv")
    with pytest.raises(DataError, match="x.csv"):
        shevsim.run_calibration("vehicle", tmp_path / "x.csv")
    with pytest.raises(DataError, match="split must be one of"):
        shevsim.run_calibration("vehicle", tmp_path / "x.csv", split="middle")
