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
    assert str(ei.value).startswith(f"{p}: ") and kind in str(ei.value) and "export the channels as a CSV" in str(ei.value)
