"""Bad input, round 13: what a logger or a user writes that earlier rounds did not try - an infinite value or an
instrument's overload code in one channel, a logger dropout (a time gap), a record too short to split, an output
folder that cannot take the result (checked before the fit, not after it), wrong types in the ``--params`` file
(a string, a list, true/false, a date where a number is expected; an OCV table with NaN, in millivolts or in
percent) and an option given twice with different values.  Each must be a plain error naming the file and the
field (exit code 2), never an internal error, a temporary file's name or a silently wrong result."""
from __future__ import annotations

from pathlib import Path

import pytest

from shevsim.calibrate.cli import _sensor_noise, main_calibrate
from shevsim.calibrate.data import load_measured, parse_mapping, parse_units
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.models import get_model
from shevsim.calibrate.timing import parse_conventions
from shevsim.cli import main as shevsim_main
from shevsim.core.errors import DataError

DATA = Path(__file__).resolve().parents[1] / "data" / "independent"


def _vehicle_rows(n: int = 400) -> tuple[str, list[str]]:
    lines = [ln for ln in (DATA / "vehicle_bolt_none.csv").read_text().splitlines() if not ln.startswith("#")]
    return lines[0], lines[1:n + 1]


def _write(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text("\n".join([header] + rows) + "\n")
    return path


def _set(rows: list[str], k: int, col: int, value: str) -> list[str]:
    out = list(rows)
    parts = out[k].split(",")
    parts[col] = value
    out[k] = ",".join(parts)
    return out


def _shift_time(rows: list[str], start: int, by: float) -> list[str]:
    out = []
    for k, r in enumerate(rows):
        t, rest = r.split(",", 1)
        out.append(f"{float(t) + (by if k >= start else 0.0)},{rest}")
    return out


@pytest.mark.parametrize("col, value, name, what", [
    (2, "inf", "power_w", "infinite"),
    (1, "-inf", "speed_mps", "infinite"),
    (2, "9.9E+37", "power_w", "overload"),        # a meter's overload code
    (0, "inf", "time_s", "infinite"),
])
def test_an_infinite_or_overload_value_names_column_and_line(tmp_path, col, value, name, what):
    header, rows = _vehicle_rows()
    k = 50 if col else len(rows) - 1
    f = _write(tmp_path / "rec.csv", header, _set(rows, k, col, value))
    with pytest.raises(DataError, match=rf"rec\.csv: column '{name}', line {k + 2}: value .* {what}"):
        load_measured(f, "vehicle")


def test_an_infinite_cell_value_is_not_called_milliamps_or_kelvin(tmp_path):
    lines = (DATA / "cell_ai2020_none.csv").read_text().splitlines()[1:402]
    rows = [r + ",inf" for r in lines[1:]]
    f = _write(tmp_path / "cell.csv", lines[0] + ",t_core_c", _set(rows, 40, 1, "-inf"))
    with pytest.raises(DataError) as exc:
        load_measured(f, "cell", current_sign="discharge-positive")
    msg = str(exc.value)
    assert "column 'current_a', line 42: value -inf is infinite" in msg
    assert "column 't_core_c', line 2: value inf is infinite (400 in all)" in msg
    assert "milliamps" not in msg and "kelvin" not in msg


def test_a_time_gap_is_stated_in_the_notes(tmp_path):
    header, rows = _vehicle_rows()
    f = _write(tmp_path / "rec.csv", header, _shift_time(rows, 200, 600.0))   # a 10-minute logger dropout
    m = load_measured(f, "vehicle")
    gap = [n for n in m.notes if n.startswith("time gaps")]
    assert gap and "the longest 601 s (lines 201-202" in gap[0] and "interpolated linearly" in gap[0]
    assert not [n for n in load_measured(_write(tmp_path / "ok.csv", header, rows), "vehicle").notes
                if n.startswith("time gaps")]


def test_a_logger_that_samples_on_change_is_said_to_sample_variably_not_to_drop_out():
    """The shipped Nissan Leaf record is logged every second under current and every minute at rest (224 long steps):
    variable sampling, not 224 dropouts to cut the record at."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    m = load_measured(root / "data" / "measured" / "nissan_leaf_cell" / "leaf_1C.csv", "cell", current_sign="auto")
    notes = [n for n in m.notes if "sampl" in n or "gap" in n]
    assert any(n.startswith("variable sampling: 224 sample steps") for n in notes), notes
    assert not any(n.startswith("time gaps") for n in notes)


def test_a_gap_that_makes_the_grid_huge_is_refused_before_the_fit(tmp_path):
    from shevsim.calibrate.report import check_record_size
    header, rows = _vehicle_rows()
    f = _write(tmp_path / "rec.csv", header, _shift_time(rows, 200, 3e6))   # 35 days off: 3 million grid points
    m = load_measured(f, "vehicle")
    with pytest.raises(DataError, match=r"rec\.csv: the record's 400 rows span .* grid of 3,000,400 points .* "
                                        r"--allow-large"):
        check_record_size(m, "vehicle", {}, False, lambda s: None)
    from shevsim.calibrate.report import grid_too_large
    grid_too_large(m, True)                   # --allow-large: as it is (no simulation here: it would take minutes)


def test_a_record_too_short_to_split_names_the_file(tmp_path, capsys):
    lines = [ln for ln in (DATA / "engine_none.csv").read_text().splitlines() if not ln.startswith("#")]
    f = _write(tmp_path / "short.csv", lines[0], lines[1:6])
    rc = main_calibrate(["engine", str(f), "-o", str(tmp_path / "out"), "--no-plots", "-q", "--effects", "timing"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "short.csv: split leaves too few samples" in err and "the record has 5 samples" in err


def test_the_output_folder_is_checked_before_the_record_is_read(tmp_path, capsys):
    common = ["--no-plots", "-q", "--effects", "timing"]
    missing = str(tmp_path / "no_such_record.csv")       # never reached: the folder is refused first
    a_file = tmp_path / "results"
    a_file.write_text("mine\n")
    assert main_calibrate(["vehicle", missing, "-o", str(a_file)] + common) == 2
    assert "'" + str(a_file) + "' exists and is not a folder" in capsys.readouterr().err
    assert main_calibrate(["vehicle", missing, "-o", str(a_file / "sub")] + common) == 2
    assert "is a file, so the folder cannot be created" in capsys.readouterr().err
    mine = tmp_path / "mycell"
    mine.mkdir()
    (mine / "ocv.csv").write_text("my own OCV table\n")
    assert main_calibrate(["cell", missing, "-o", str(mine)] + common) == 2
    assert "ocv.csv would be replaced" in capsys.readouterr().err
    assert (mine / "ocv.csv").read_text() == "my own OCV table\n" and a_file.read_text() == "mine\n"


def _cell_nominal(tmp_path: Path, old: str, new: str) -> Path:
    text = (DATA / "cell_ai2020_nominal.toml").read_text()
    assert old in text
    p = tmp_path / "nominal.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize("old, new, match", [
    ("capacity_ah = 2.28", 'capacity_ah = "2.28"', r"parameter 'capacity_ah': expected a number, got '2.28'"),
    ("capacity_ah = 2.28", "capacity_ah = [2.28]", r"parameter 'capacity_ah': expected a number"),
    ("capacity_ah = 2.28", "capacity_ah = true", r"parameter 'capacity_ah': expected a number, got True"),
    ("capacity_ah = 2.28", "capacity_ah = 2024-01-01", r"parameter 'capacity_ah': expected a number"),
    ("rc_pairs = 2", 'rc_pairs = 2\ntemperature_dependent = "yes"', r"parameter 'temperature_dependent': expected true"),
    ("rc_pairs = 2", "rc_pairs = 2\ndischarge_file = 5", r"parameter 'discharge_file': expected a string"),
    ("soc0_frac = -1.0", "soc0_frac = [1.0]", r"parameter 'soc0_frac': expected a number"),
    ("soc0_frac = -1.0", 'soc0_frac = "full"', r"parameter 'soc0_frac': expected a number"),
    ("soc0_frac = -1.0", "soc0_frac = nan", r"parameter 'soc0_frac' must be finite"),
    ("soc0_frac = -1.0", "soc0_frac = 5.0", r"soc0_frac = 5.0: the initial SOC is a fraction in \[0, 1\]"),
    ("rc_pairs = 2", "rc_pairs = 3", r"rc_pairs = 3: the cell has 1 or 2 RC branches"),
    ("rc_pairs = 2", "rc_pairs = 1.5", r"rc_pairs = 1.5: the cell has 1 or 2 RC branches"),
])
def test_a_wrong_cell_parameter_is_named(tmp_path, old, new, match):
    p = _cell_nominal(tmp_path, old, new)
    with pytest.raises(DataError, match=r"nominal\.toml: .*" + match):
        get_model("cell", load_params_toml(p), str(p))


@pytest.mark.parametrize("which, new, match", [
    ("ocv_v", lambda v: v[:10] + ["nan"] + v[11:], r"\[ocv\] ocv_v\[10\] = nan: every value must be finite"),
    ("ocv_v", lambda v: [f"{float(x) * 1000:.1f}" for x in v], r"\[ocv\] ocv_v median .* looks like millivolts"),
    ("soc_frac", lambda v: [f"{float(x) * 100:.1f}" for x in v], r"\[ocv\] soc_frac must lie in \[0, 1\].*soc_pct"),
])
def test_the_ocv_table_of_the_params_file_is_checked_there(tmp_path, which, new, match):
    import re
    text = (DATA / "cell_ai2020_nominal.toml").read_text()
    m = re.search(rf"^{which} = \[(.*)\]$", text, re.M)
    vals = [x.strip() for x in m.group(1).split(",")]
    p = tmp_path / "nominal.toml"
    p.write_text(text.replace(m.group(0), f"{which} = [{', '.join(new(vals))}]"))
    with pytest.raises(DataError, match=r"nominal\.toml: " + match) as exc:
        get_model("cell", load_params_toml(p), str(p))
    assert "shevsim_" not in str(exc.value)                        # not a temporary file of ours


@pytest.mark.parametrize("model, text, match", [
    ("vehicle", "[params]\nmass_kg = [1626.1]\n", r"parameter 'mass_kg': expected a number"),
    ("vehicle", "[vehicle]\nmass_kg = \"x\"\n", r"parameter 'mass_kg': expected a number, got 'x'"),
    ("vehicle", "[params]\nefficiency_scale_frac = \"1\"\n", r"parameter 'efficiency_scale_frac': expected a number"),
    ("engine", "[params]\nsoot_scale_frac = [1.0]\n", r"parameter 'soot_scale_frac': expected a number"),
    ("engine", "[params]\nturbo_lag_s = \"x\"\n", r"parameter 'turbo_lag_s': expected a number, got 'x'"),
    ("engine", "[params]\npower_rate_max_wps = \"x\"\n", r"parameter 'power_rate_max_wps': expected a number"),
])
def test_a_wrong_vehicle_or_engine_parameter_is_named(tmp_path, model, text, match):
    p = tmp_path / "nominal.toml"
    p.write_text(text)
    with pytest.raises(DataError, match=r"nominal\.toml: .*" + match):
        get_model(model, load_params_toml(p), str(p))


def test_a_list_for_a_number_is_not_an_internal_error(tmp_path, capsys):
    header, rows = _vehicle_rows(60)
    f = _write(tmp_path / "rec.csv", header, rows)
    p = tmp_path / "nominal.toml"
    p.write_text("[params]\nmass_kg = [1626.1]\n")
    rc = shevsim_main(["calibrate", "vehicle", str(f), "-p", str(p), "-o", str(tmp_path / "out"), "--no-plots",
                       "-q", "--effects", "timing"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "nominal.toml: vehicle parameters: parameter 'mass_kg': expected a number" in err


def test_an_option_given_twice_with_different_values_is_refused():
    with pytest.raises(DataError, match=r"--unit time_s=s and --unit time_s=ms: 'time_s' given twice"):
        parse_units(["time_s=s", "time_s=ms"])
    with pytest.raises(DataError, match=r"--map speed_mps=Speed and --map speed_mps=v: 'speed_mps' given twice"):
        parse_mapping(["speed_mps=Speed", "speed_mps=v"])
    with pytest.raises(DataError, match=r"--sensor-noise power_w=300 and power_w=30: 'power_w' given twice"):
        _sensor_noise(["power_w=300", "power_w=30"])
    with pytest.raises(DataError, match=r"channel 'power_w' given twice with different conventions"):
        parse_conventions("power_w=mean-ending,power_w=instantaneous")
    # the same value twice is no contradiction
    assert parse_units(["time_s=ms", "time_s=ms"]) == {"time_s": "ms"}
    assert _sensor_noise(["power_w=300", "power_w=300"]) == {"power_w": 300.0}
