"""Plausibility on data (issue 13 item 3): unit sniffing and spreadsheet quirks in cycles and measured
records, identifiability of calibration parameters, studies failing loudly."""
import math

import numpy as np
import pandas as pd
import pytest

from shevsim.calibrate.data import load_measured
from shevsim.core.errors import DataError, ShevsimError
from shevsim.cycles import cycle_from_arrays, load_cycle

T = np.arange(0.0, 61.0)
V = 22.0 * np.sin(T / 60.0 * math.pi)                # m/s, max 22, |accel| <= 1.2 m/s^2


def _cycle_csv(path, header, t, v, sep=",", nl="\n", decimal=".", bom=False, trailing=""):
    rows = [sep.join(header) + trailing]
    for a, b in zip(t, v):
        rows.append(sep.join((f"{a:g}", f"{b:.4f}".replace(".", decimal))) + trailing)
    data = nl.join(rows) + nl
    path.write_bytes(("\ufeff" if bom else "").encode() + data.encode())
    return path


# ------------------------------------------------------------------------------------------- cycles

def test_cycle_in_kmh_refused_then_declared(tmp_path):
    p = _cycle_csv(tmp_path / "kmh.csv", ("time_s", "speed_mps"), T, V * 3.6)
    with pytest.raises(DataError, match=r"kmh.csv, line \d+, column 'speed_mps': speed 79.2 m/s .* looks like "
                                        r"km/h .* name it 'speed_kmh'"):
        load_cycle(p)
    q = _cycle_csv(tmp_path / "declared.csv", ("time_s", "speed_kmh"), T, V * 3.6)
    c = load_cycle(q)
    np.testing.assert_allclose(c.speed_mps, np.round(V * 3.6, 4) / 3.6, rtol=0, atol=1e-12)
    assert load_cycle(p, check_units=False).speed_mps.max() == pytest.approx(79.2, abs=1e-3)


def test_cycle_at_200_mps_refused():
    with pytest.raises(DataError, match=r"speed 200 m/s"):
        cycle_from_arrays("x", [0, 1, 2, 3], [0, 100, 200, 150])


def test_cycle_time_in_ms_refused_then_declared(tmp_path):
    p = _cycle_csv(tmp_path / "ms.csv", ("time_s", "speed_mps"), T * 1000, V)
    with pytest.raises(DataError, match=r"column 'time_s': sample step 1000 s over 16.7 hours: .* looks like milliseconds; name it "
                                        r"'time_ms'"):
        load_cycle(p)
    c = load_cycle(_cycle_csv(tmp_path / "ms2.csv", ("time_ms", "speed_mps"), T * 1000, V))
    assert c.dt_s == pytest.approx(1.0) and c.duration_s == pytest.approx(60.0)


def test_legitimate_coarse_fast_noisy_and_declared_traces_are_accepted(tmp_path):
    """The sniffing must not refuse real data: a highway trace sampled every 10 s, a cycle declared in
    minutes, a car at 55 m/s, a 10 Hz log with sensor noise; a synthetic step passes with check_units=False."""
    t10 = np.arange(0.0, 7200.0, 10.0)                                    # 2 h every 10 s
    load_cycle(_cycle_csv(tmp_path / "c10.csv", ("time_s", "speed_mps"), t10, 25 + 5 * np.sin(t10 / 600)))
    tm = np.arange(0.0, 60.0, 0.5)                                         # every 30 s, declared in minutes
    c = load_cycle(_cycle_csv(tmp_path / "cmin.csv", ("time_min", "speed_mps"), tm, 20 + 0 * tm))
    assert c.dt_s == pytest.approx(30.0)
    load_cycle(_cycle_csv(tmp_path / "fast.csv", ("time_s", "speed_mps"), T, V * 55.0 / 22.0))
    t = np.arange(0.0, 120.0, 0.1)
    noisy = np.clip(20 + 0.3 * np.random.default_rng(0).standard_normal(t.size), 0, None)
    load_cycle(_cycle_csv(tmp_path / "gps.csv", ("time_s", "speed_mps"), t, noisy))
    step = [0.0, 0.0, 12.0, 12.0]
    with pytest.raises(DataError, match="check_units = false"):
        cycle_from_arrays("step", [0, 1, 2, 3], step)
    assert cycle_from_arrays("step", [0, 1, 2, 3], step, check_units=False).speed_mps.max() == 12.0


def test_cycle_implausible_acceleration_refused():
    with pytest.raises(DataError, match=r"acceleration 30 m/s\^2 between 1 s and 2 s"):
        cycle_from_arrays("x", [0, 1, 2, 3], [0, 0, 30, 30])


def test_cycle_spreadsheet_quirks_accepted(tmp_path):
    plain = load_cycle(_cycle_csv(tmp_path / "plain.csv", ("time_s", "speed_mps"), T, V))
    quirky = load_cycle(_cycle_csv(tmp_path / "quirky.csv", ("time_s", "speed_mps"), T, V, sep=";", nl="\r\n",
                                   decimal=",", bom=True, trailing=";;"))
    np.testing.assert_array_equal(plain.time_s, quirky.time_s)
    np.testing.assert_array_equal(plain.speed_mps, quirky.speed_mps)
    tab = load_cycle(_cycle_csv(tmp_path / "tab.csv", ("time_s", "speed_mps"), T, V, sep="\t"))
    np.testing.assert_array_equal(plain.speed_mps, tab.speed_mps)


def test_cycle_utf16_read_and_binary_named(tmp_path):
    """A spreadsheet's "Unicode text" export (UTF-16) is read (it was refused until the fifteenth session); a
    binary file is named as one."""
    p = tmp_path / "u16.csv"
    p.write_bytes("time_s,speed_mps\n0,0\n1,1\n".encode("utf-16"))
    np.testing.assert_array_equal(load_cycle(p).speed_mps, [0.0, 1.0])
    b = tmp_path / "bin.csv"
    b.write_bytes(b"time_s,speed_mps\n0,\x00\x01\n")
    with pytest.raises(DataError, match=r"bin.csv: holds NUL bytes"):
        load_cycle(b)


# ------------------------------------------------------------------------------------- measured data

def _cell_df(n=400, dt=1.0, i_amp=2.0, r_ohm=0.03, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    i = i_amp * np.sign(np.sin(t / 20.0)) * (rng.random(n) > 0.2)
    v = 3.3 - r_ohm * i + rng.normal(0, 1e-3, n)
    return pd.DataFrame({"time_s": t, "current_a": i, "voltage_v": v, "t_surface_c": 25.0 + rng.normal(0, .05, n),
                         "t_ambient_c": 25.0 + rng.normal(0, .05, n)})


def test_record_time_in_ms_refused_declared_or_converted(tmp_path):
    df = _cell_df()
    ms = df.assign(time_s=df.time_s * 1000)
    p = tmp_path / "ms.csv"
    ms.to_csv(p, index=False)
    with pytest.raises(DataError, match=r"ms.csv: column 'time_s', line 3: median sample step 1000 s looks like "
                                        r"milliseconds .* 'time_ms' or pass --unit time_s=ms"):
        load_measured(p, "cell")
    d = load_measured(p, "cell", units={"time_s": "ms"})
    np.testing.assert_allclose(d.df.time_s.to_numpy(), df.time_s.to_numpy())
    q = tmp_path / "declared.csv"
    ms.rename(columns={"time_s": "time_ms"}).to_csv(q, index=False)
    d2 = load_measured(q, "cell")
    np.testing.assert_allclose(d2.df.time_s.to_numpy(), df.time_s.to_numpy())
    assert any("converted from ms" in n for n in d2.notes)


def test_record_current_in_ma_refused_then_declared(tmp_path):
    df = _cell_df(i_amp=0.5)               # 500 mA pulses: below the old '> 1000 A' check
    p = tmp_path / "ma.csv"
    df.assign(current_a=df.current_a * 1000).to_csv(p, index=False)
    with pytest.raises(DataError, match=r"column 'current_a'.*cell resistance of 0.03\d* mOhm.* looks like milliamps"):
        load_measured(p, "cell")
    d = load_measured(p, "cell", units={"current_a": "mA"})
    np.testing.assert_allclose(d.df.current_a.to_numpy(), df.current_a.to_numpy(), atol=1e-12)
    load_measured(_write(tmp_path / "ok.csv", df), "cell")          # the same record in A passes


def _write(p, df):
    df.to_csv(p, index=False)
    return p


def test_vehicle_time_in_ms_and_speed_in_kmh(tmp_path):
    t = np.arange(0, 300.0)
    s = np.clip(15 * np.sin(t / 40.0), 0, None)
    df = pd.DataFrame({"time_s": t, "speed_mps": s, "power_w": 2e4 * s + 1e3})
    with pytest.raises(DataError, match=r"'speed_kmh' or pass --unit speed_mps=kmh"):
        load_measured(_write(tmp_path / "kmh.csv", df.assign(speed_mps=s * 3.6 * 1.5)), "vehicle")
    d = load_measured(_write(tmp_path / "kmh2.csv", df.assign(speed_mps=s * 3.6).rename(
        columns={"speed_mps": "speed_kmh"})), "vehicle")
    np.testing.assert_allclose(d.df.speed_mps.to_numpy(), s, atol=1e-9)
    with pytest.raises(DataError, match=r"looks like milliseconds"):
        load_measured(_write(tmp_path / "vms.csv", df.assign(time_s=t * 1000)), "vehicle")
    with pytest.raises(DataError, match=r"--unit: 'nosuch' is not|--unit nosuch=ms"):
        load_measured(tmp_path / "kmh2.csv", "vehicle", units={"nosuch": "ms"})


def test_record_spreadsheet_quirks(tmp_path):
    df = _cell_df()
    plain = load_measured(_write(tmp_path / "plain.csv", df), "cell")
    p = tmp_path / "quirky.csv"
    text = df.to_csv(index=False, sep=";", decimal=",", lineterminator="\r\n").replace("\r\n", ";\r\n")
    p.write_bytes(b"\xef\xbb\xbf" + text.encode())
    quirky = load_measured(p, "cell")
    assert list(quirky.df.columns) == list(plain.df.columns)
    np.testing.assert_allclose(quirky.df.to_numpy(), plain.df.to_numpy(), rtol=1e-12)


def test_calibrate_cli_time_in_ms_is_a_clear_error(tmp_path, capsys):
    from shevsim.calibrate.cli import main_calibrate
    df = _cell_df()
    p = _write(tmp_path / "ms.csv", df.assign(time_s=df.time_s * 1000))
    assert main_calibrate(["cell", str(p), "--out", str(tmp_path / "o"), "--no-plots", "-q"]) == 2
    err = capsys.readouterr().err
    assert "looks like milliseconds" in err and "Traceback" not in err


# ------------------------------------------------------------------------------- identifiability

def test_identifiability_needs_excitation():
    """rs_scale (series resistance) is identified from a record with current pulses and reported not
    identifiable from a rest record (same cell, same noise, no current)."""
    from shevsim.calibrate.models import get_model
    from shevsim.calibrate.synthetic import as_measured, synth_cell
    from shevsim.calibrate.workflow import Fitter, identifiability
    df, _ = synth_cell(duration_s=400.0, seed=1)
    rest = df.assign(current_a=np.random.default_rng(2).normal(0, 0.01, len(df)),
                     voltage_v=df.voltage_v.iloc[0] + np.random.default_rng(3).normal(0, 0.002, len(df)))
    out = {}
    for name, d in (("pulses", df), ("rest", rest)):
        data = as_measured(d, "cell")
        model = get_model("cell", {}, "<test>")
        train = np.ones(len(d), bool)
        fitter = Fitter(model, data, train, ~train)
        out[name] = {r["parameter"]: r for r in identifiability(fitter, (), model.defaults())}
    assert out["pulses"]["rs_scale"]["identifiable"], out["pulses"]["rs_scale"]
    assert not out["rest"]["rs_scale"]["identifiable"], out["rest"]["rs_scale"]
    assert out["rest"]["rs_scale"]["se_frac"] > 10 * out["pulses"]["rs_scale"]["se_frac"]


# ---------------------------------------------------------------------------------------- studies

def test_study_unknown_supervisor_refused_up_front(capsys):
    from shevsim.core.paths import bundled_scenario
    from shevsim.studies.cli import main_study
    sc = str(bundled_scenario("hd_udds_mpc"))
    assert main_study(["tradeoff", sc, "--supervisor", "nosuch", "--workers", "0", "--no-plots"]) == 2
    assert "--supervisor 'nosuch': no such component" in capsys.readouterr().err
    assert main_study(["tradeoff", sc, "--supervisor", "battery", "--workers", "0", "--no-plots"]) == 2
    assert "without a power-rate map" in capsys.readouterr().err


def test_study_all_failed_exits_nonzero(capsys):
    from shevsim.studies.cli import _report
    from shevsim.studies.result import StudyResult, failed_rows
    code, notes = failed_rows("t", [{"error": "boom"}, {"error": "bang"}])
    assert code == 1 and "all 2 evaluations failed; first: boom" in notes[0]
    assert _report("t", StudyResult("tradeoff", {}, notes=notes, exit_code=code), "out") == 1   # what the CLI exits
    assert "all 2 evaluations failed; first: boom" in capsys.readouterr().err
    code, notes = failed_rows("t", [{"error": ""}, {"error": "bang"}])
    assert code == 0 and "1 of 2 evaluations failed" in notes[0]
