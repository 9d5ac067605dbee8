"""Bad inputs found after the thirteenth session: a record saved as UTF-16 or in an 8-bit Windows code page is read
(said in the notes) rather than refused with a decoder's message; a time column in microseconds, nanoseconds,
hours or minutes is named as such, with the option that converts it."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from shevsim.calibrate.data import load_measured
from shevsim.core.errors import DataError

REC = Path(__file__).resolve().parents[1] / "data" / "independent" / "vehicle_bolt_none.csv"   # FASTSim's Bolt, 1 Hz


@pytest.fixture(scope="module")
def frame():
    return pd.read_csv(REC, comment="#")


@pytest.mark.parametrize("encoding, said", [("utf-16", "UTF-16 (its byte-order mark)"),
                                            ("utf-16-le", "UTF-16 little-endian"),
                                            ("utf-16-be", "UTF-16 big-endian")])
def test_a_utf16_record_is_read_as_the_utf8_one(tmp_path, frame, encoding, said):
    ref = load_measured(str(REC), "vehicle")
    p = tmp_path / "rec.csv"
    frame.to_csv(p, index=False, encoding=encoding)
    got = load_measured(str(p), "vehicle")
    assert got.df[["time_s", "speed_mps", "power_w"]].equals(ref.df[["time_s", "speed_mps", "power_w"]])
    assert any(said in n for n in got.notes)


def test_a_windows_1252_record_is_read_and_the_first_non_utf8_byte_named(tmp_path, frame):
    p = tmp_path / "rec.csv"
    text = "# Fahrzeug: Prüfstand, 25 °C\n" + frame.rename(columns={"speed_mps": "Geschwindigkeit_kmh"}).assign(
        Geschwindigkeit_kmh=frame["speed_mps"] * 3.6).to_csv(index=False)
    p.write_bytes(text.encode("cp1252"))
    got = load_measured(str(p), "vehicle", mapping={"speed_mps": "Geschwindigkeit_kmh"}, units={"speed_mps": "kmh"})
    assert abs(got.df["speed_mps"].to_numpy() - frame["speed_mps"].to_numpy()).max() < 1e-9
    assert any("Windows-1252" in n and "line 1" in n and "0xfc" in n for n in got.notes)


def test_a_plain_utf8_record_has_no_encoding_note():
    assert not any("decoded as" in n for n in load_measured(str(REC), "vehicle").notes)


@pytest.mark.parametrize("scale, unit", [(1e3, "ms"), (1e6, "us"), (1e9, "ns"), (1 / 3600, "h"), (1 / 60, "min")])
def test_a_time_column_in_another_unit_is_named_with_its_fix(tmp_path, frame, scale, unit):
    p = tmp_path / "rec.csv"
    frame.assign(time_s=frame["time_s"] * scale).to_csv(p, index=False)
    with pytest.raises(DataError) as ei:
        load_measured(str(p), "vehicle")
    msg = str(ei.value)
    assert "column 'time_s'" in msg and f"--unit time_s={unit}" in msg and str(p) in msg
    # the fix it names gives the record back
    got = load_measured(str(p), "vehicle", units={"time_s": unit})
    assert abs(got.df["time_s"].to_numpy() - frame["time_s"].to_numpy()).max() < 1e-6


def test_a_header_in_microseconds_is_converted(tmp_path, frame):
    p = tmp_path / "rec.csv"
    frame.rename(columns={"time_s": "time_us"}).assign(time_us=frame["time_s"] * 1e6).to_csv(p, index=False)
    got = load_measured(str(p), "vehicle")
    assert abs(got.df["time_s"].to_numpy() - frame["time_s"].to_numpy()).max() < 1e-9


def test_a_cell_table_given_as_a_folder_is_named_as_a_folder(tmp_path):
    from shevsim.battery.cell import read_csv_table
    with pytest.raises(DataError, match=r"is a folder, not a table file: give the file itself"):
        read_csv_table(tmp_path, ("soc_frac", "ocv_v"))
    with pytest.raises(DataError, match=r"nothere\.csv: table file not found"):
        read_csv_table(tmp_path / "nothere.csv", ("soc_frac", "ocv_v"))


@pytest.mark.parametrize("fmt, start", [("%Y-%m-%d %H:%M:%S.%f", "2026-11-27 10:00:00"),
                                        ("%Y-%m-%dT%H:%M:%SZ", "2026-11-27 10:00:00"),
                                        ("%H:%M:%S", "2026-11-27 23:55:00")])      # passes midnight
def test_a_time_column_of_timestamps_is_read_as_seconds_from_the_first(tmp_path, frame, fmt, start):
    p = tmp_path / "rec.csv"
    stamps = pd.Timestamp(start) + pd.to_timedelta(frame["time_s"], unit="s")
    frame.assign(time_s=stamps.dt.strftime(fmt)).to_csv(p, index=False)
    got = load_measured(str(p), "vehicle")
    t = frame["time_s"].to_numpy()
    assert abs(got.df["time_s"].to_numpy() - (t - t[0])).max() < 1e-6
    assert any("read as timestamps" in n for n in got.notes)


def test_a_day_first_date_is_refused_as_ambiguous_naming_column_and_line(tmp_path, frame):
    p = tmp_path / "rec.csv"
    stamps = pd.Timestamp("2026-11-27 10:00:00") + pd.to_timedelta(frame["time_s"], unit="s")
    frame.assign(time_s=stamps.dt.strftime("%d.%m.%Y %H:%M:%S")).to_csv(p, index=False)
    with pytest.raises(DataError, match=r"column 'time_s', line 2 and on: '27\.11\.2026 10:00:00' looks like a "
                                        r"timestamp"):
        load_measured(str(p), "vehicle")


def test_a_unit_declared_for_a_timestamp_column_is_refused(tmp_path, frame):
    p = tmp_path / "rec.csv"
    stamps = pd.Timestamp("2026-11-27 10:00:00") + pd.to_timedelta(frame["time_s"], unit="s")
    frame.assign(time_s=stamps.dt.strftime("%H:%M:%S")).to_csv(p, index=False)
    with pytest.raises(DataError, match="carry their own unit"):
        load_measured(str(p), "vehicle", units={"time_s": "ms"})


@pytest.mark.parametrize("head, kind", [(b"PK\x03\x04" + b"\x14" * 60, "a ZIP archive (an .xlsx workbook?)"),
                                        (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + b"\x00" * 60, "an OLE2 compound file"),
                                        (b"MATLAB 5.0 MAT-file, Platform: GLNXA64" + b" " * 80, "a MATLAB .mat file"),
                                        (b"\x89HDF\r\n\x1a\n" + b"\x00" * 60, "an HDF5 file"),
                                        (b"PAR1" + b"\x00" * 60 + b"PAR1", "a Parquet file"),
                                        (b"time_s,speed_mps\n0,\x00\x01\x02\n", "holds NUL bytes")])
def test_a_binary_file_is_named_for_what_it_is(tmp_path, head, kind):
    p = tmp_path / "record.csv"
    p.write_bytes(head)
    with pytest.raises(DataError) as ei:
        load_measured(str(p), "vehicle")
    assert str(ei.value).startswith(f"{p}: ") and kind in str(ei.value) and "export the columns as a CSV" in str(ei.value)


# ---- the reviewer's cases (fourteenth session): fast loggers, compressed files, timestamps' edge forms

def _cell_csv(path, rate_hz, n=20000, t0=0.0):
    import numpy as np
    t = t0 + np.arange(n) / rate_hz
    i = 2.0 * np.sin(2 * np.pi * t / 7.0) + 1.0
    v = 3.7 - 0.05 * i - 0.02 * (t - t0) / t.max()
    pd.DataFrame({"time_s": t, "current_a": i, "voltage_v": v, "t_surface_c": 25.0, "t_ambient_c": 25.0}).to_csv(
        path, index=False, float_format="%.6f")


@pytest.mark.parametrize("rate_hz, t0", [(1000.0, 0.0), (1000.0, 1000.0), (2000.0, 0.0)])
def test_a_fast_cell_logger_is_not_refused_as_minutes(tmp_path, rate_hz, t0):
    p = tmp_path / "cell.csv"
    _cell_csv(p, rate_hz, t0=t0)
    got = load_measured(str(p), "cell", current_sign="discharge-positive")
    assert len(got.df) == 20000


def test_a_1hz_cell_record_in_hours_gets_a_note_naming_the_units(tmp_path):
    p = tmp_path / "cell.csv"
    _cell_csv(p, 3600.0, n=3600)
    got = load_measured(str(p), "cell", current_sign="discharge-positive")
    assert any("--unit time_s=h" in n and "--unit time_s=min" in n for n in got.notes)


def test_a_noisy_100hz_vehicle_record_is_not_read_as_minutes(tmp_path, frame):
    import numpy as np
    t = np.arange(0.0, frame["time_s"].iloc[-1], 0.01)
    v = np.interp(t, frame["time_s"], frame["speed_mps"]) + 0.1 * np.random.default_rng(0).standard_normal(t.size)
    p = tmp_path / "v100.csv"
    pd.DataFrame({"time_s": t, "speed_mps": v, "power_w": np.interp(t, frame["time_s"], frame["power_w"])}).to_csv(
        p, index=False)
    assert len(load_measured(str(p), "vehicle").df) == t.size


@pytest.mark.parametrize("suffix", [".csv.gz", ".CSV.GZ", ".csv.bz2", ".csv.xz", ".csv.zip"])
def test_a_compressed_record_is_read_by_its_suffix(tmp_path, frame, suffix):
    p = tmp_path / f"rec{suffix}"
    comp = {".gz": "gzip", ".bz2": "bz2", ".xz": "xz", ".zip": "zip"}[Path(suffix.lower()).suffix]
    frame.to_csv(p, index=False, compression={"method": comp, "archive_name": "rec.csv"} if comp == "zip" else comp)
    got = load_measured(str(p), "vehicle")
    assert len(got.df) == len(frame)


def test_a_damaged_gzip_record_is_a_clear_error(tmp_path, frame):
    import gzip
    p = tmp_path / "rec.csv.gz"
    blob = bytearray(gzip.compress(frame.to_csv(index=False).encode()))
    blob[40:60] = b"\xff" * 20
    p.write_bytes(bytes(blob))
    with pytest.raises(DataError, match=r"rec\.csv\.gz: a damaged gzip file"):
        load_measured(str(p), "vehicle")


def test_iso_timestamps_with_a_decimal_comma_and_long_elapsed_hours(tmp_path, frame):
    t = frame["time_s"].to_numpy()
    stamps = (pd.Timestamp("2026-11-27 10:00:00") + pd.to_timedelta(t, unit="s")).strftime("%Y-%m-%d %H:%M:%S,%f")
    p = tmp_path / "comma.csv"
    frame.assign(time_s=stamps).to_csv(p, index=False, sep=";", decimal=",")
    assert abs(load_measured(str(p), "vehicle").df["time_s"].to_numpy() - (t - t[0])).max() < 1e-6
    hours = [f"{1000 + int(x) // 3600}:{(int(x) % 3600) // 60:02d}:{int(x) % 60:02d}" for x in t]
    p = tmp_path / "ageing.csv"
    frame.assign(time_s=hours).to_csv(p, index=False)
    assert abs(load_measured(str(p), "vehicle").df["time_s"].to_numpy() - (t - t[0])).max() < 1e-6


def test_an_empty_cell_in_a_timestamp_column_is_named_at_its_line(tmp_path, frame):
    stamps = list((pd.Timestamp("2026-11-27 10:00:00") + pd.to_timedelta(frame["time_s"], unit="s"))
                  .dt.strftime("%Y-%m-%d %H:%M:%S"))
    stamps[9] = ""
    p = tmp_path / "gap.csv"
    frame.assign(time_s=stamps).to_csv(p, index=False)
    with pytest.raises(DataError, match=r"column 'time_s', line 11: .* is not a timestamp"):
        load_measured(str(p), "vehicle")


def test_a_header_starting_par1_is_a_csv_and_a_bom_file_with_a_latin_byte_is_read(tmp_path, frame):
    p = tmp_path / "par.csv"
    frame.rename(columns={"power_w": "PAR1_power"}).to_csv(p, index=False, columns=["PAR1_power", "time_s",
                                                                                    "speed_mps"])
    got = load_measured(str(p), "vehicle", mapping={"power_w": "PAR1_power"})
    assert len(got.df) == len(frame)
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf# Pr\xfcfstand\n" + frame.to_csv(index=False).encode())
    got = load_measured(str(p), "vehicle")
    assert any("Windows-1252" in n for n in got.notes)
