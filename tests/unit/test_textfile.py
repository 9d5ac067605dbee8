"""A user's CSV in another encoding, or a binary file under a CSV's name, for every kind of file a user hands
over (a record, a drive cycle, a map, a cell table): read alike (:mod:`shevsim.core.textfile`), each checked
against the same file written as UTF-8 - the reference is the project's own shipped file, re-encoded."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shevsim.battery.cell import read_csv_table
from shevsim.core.errors import DataError
from shevsim.core.textfile import decode_text
from shevsim.cycles import load_cycle
from shevsim.powertrain.maps import read_columns

ROOT = Path(__file__).resolve().parents[2]
CYCLE = ROOT / "cycles" / "hd_udds.csv"
MAP = ROOT / "components" / "engine_generator" / "generator_max_torque.csv"
TABLE = ROOT / "components" / "battery" / "a123_26650_ocv.csv"

ENCODINGS = [("utf-16", "UTF-16 (its byte-order mark)"), ("utf-16-le", "little-endian"),
             ("utf-16-be", "big-endian"), ("cp1252", None), ("utf-8-sig", None)]


def _reencode(src: Path, dst: Path, enc: str, extra: str = "") -> Path:
    text = src.read_text(encoding="utf-8")
    lines = text.splitlines()
    lines.insert(0, "# " + extra) if extra else None
    dst.write_bytes(("\r\n".join(lines) + "\r\n").encode(enc))      # a Windows export's line ends
    return dst


@pytest.mark.parametrize("enc, note", ENCODINGS)
def test_every_users_csv_reads_the_same_in_other_encodings(tmp_path, enc, note):
    # a degree sign and a micro sign in a comment: bytes that are not UTF-8 in Windows-1252
    extra = "exported at 25 \u00b0C, \u00b5s clock"
    c0, c1 = load_cycle(CYCLE), load_cycle(_reencode(CYCLE, tmp_path / "c.csv", enc, extra))
    assert np.array_equal(c0.speed_mps, c1.speed_mps) and np.array_equal(c0.time_s, c1.time_s)
    m0 = read_columns(MAP, ("speed_radps", "torque_max_nm"))
    m1 = read_columns(_reencode(MAP, tmp_path / "m.csv", enc, extra), ("speed_radps", "torque_max_nm"))
    assert all(np.array_equal(m0[k], m1[k]) for k in m0)
    t0 = read_csv_table(TABLE, ("soc_frac", "ocv_v"))
    assert read_csv_table(_reencode(TABLE, tmp_path / "t.csv", enc, extra), ("soc_frac", "ocv_v")) == t0
    data = _reencode(TABLE, tmp_path / "n.csv", enc, extra).read_bytes()
    got = decode_text(data, "n.csv")[1]
    if enc == "cp1252":
        assert got.startswith("decoded as Windows-1252: not UTF-8 (byte 0xb0 on line 1)"), got
    else:
        assert (got is None) if note is None else (note in got), got


@pytest.mark.parametrize("head, kind", [(b"PK\x03\x04" + b"\x14" * 60, "a ZIP archive (an .xlsx workbook?)"),
                                        (b"%PDF-1.7\n" + b"x" * 60, "a PDF document"),
                                        (b"time_s,speed_mps\n0,\x00\x01\x02\n", "holds NUL bytes")])
def test_a_binary_file_given_as_a_cycle_map_or_table_is_named(tmp_path, head, kind):
    p = tmp_path / "given.csv"
    p.write_bytes(head)
    for read in (lambda: load_cycle(p), lambda: read_columns(p, ("speed_radps", "torque_max_nm")),
                 lambda: read_csv_table(p, ("soc_frac", "ocv_v"))):
        with pytest.raises(DataError) as ei:
            read()
        assert str(ei.value).startswith(f"{p}") and kind in str(ei.value) and "export the columns as a CSV" in str(ei.value)


def test_a_folder_given_as_a_map_is_named_as_one(tmp_path):
    with pytest.raises(DataError, match="is a folder, not a map file"):
        read_columns(tmp_path, ("speed_radps", "torque_max_nm"))


# ---- a reviewer's cases (fifteenth session)

def test_utf32_is_read_with_its_mark_and_refused_clearly_without(tmp_path):
    text = CYCLE.read_text(encoding="utf-8")
    p = tmp_path / "c32.csv"
    p.write_bytes(text.encode("utf-32"))
    assert np.array_equal(load_cycle(p).speed_mps, load_cycle(CYCLE).speed_mps)
    p.write_bytes(text.encode("utf-32-le"))      # read as UTF-16 it keeps NULs: refused, not a NUL-laden header
    with pytest.raises(DataError, match="still holds NUL characters"):
        load_cycle(p)


def test_a_compressed_cycle_map_or_table_is_told_to_be_decompressed(tmp_path):
    import gzip
    p = tmp_path / "cyc.csv.gz"
    p.write_bytes(gzip.compress(CYCLE.read_bytes()))
    for read in (lambda: load_cycle(p), lambda: read_columns(p, ("speed_radps", "torque_max_nm")),
                 lambda: read_csv_table(p, ("soc_frac", "ocv_v"))):
        with pytest.raises(DataError) as ei:
            read()
        assert "is a gzip-compressed file: decompress it first" in str(ei.value), ei.value


def test_a_latin1_byte_that_python_counts_as_a_line_break_is_not_one(tmp_path):
    """0x81 is undefined in Windows-1252, so the file is read as Latin-1, where 0x85 is U+0085 - a line break to
    ``str.splitlines``, not to an editor or to the CSV."""
    p = tmp_path / "l1.csv"
    p.write_bytes(b"# caf\xe9 \x85 \x81\n" + CYCLE.read_bytes())
    assert np.array_equal(load_cycle(p).speed_mps, load_cycle(CYCLE).speed_mps)


def test_a_tab_separated_unicode_text_cell_table_is_read(tmp_path):
    """A spreadsheet's "Unicode text" export: UTF-16, tab-separated."""
    t0 = read_csv_table(TABLE, ("soc_frac", "ocv_v"))
    rows = [ln for ln in TABLE.read_text(encoding="utf-8").splitlines() if ln and not ln.startswith("#")]
    p = tmp_path / "tab.csv"
    p.write_bytes(("\r\n".join(r.replace(",", "\t") for r in rows) + "\r\n").encode("utf-16"))
    assert read_csv_table(p, ("soc_frac", "ocv_v")) == t0
