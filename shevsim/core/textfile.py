"""textfile.py - a user's text file (a record, a cycle, a map, a cell table) read as text, whatever its encoding.

Spreadsheets and loggers write CSV in more than UTF-8: "Unicode text" exports are UTF-16 (with a byte-order mark,
or without one: a NUL in every other byte), Western Windows machines write Windows-1252.  :func:`decode_text` reads
them all (UTF-32 with its byte-order mark too) and says which it used; a binary file (a workbook, a MATLAB or HDF5
file, Parquet, a PDF, an MDF measurement, anything with NUL bytes) is a :class:`DataError` naming what it is and how
to export a CSV, a compressed one (gzip, bzip2, xz) what to do with it.  :func:`text_lines` splits text into lines
as an editor does.  :func:`read_text_file` does the same for a file on disk, checked first by
:func:`shevsim.core.errors.file_problem` (not found, a folder, a device, too large).
"""
from __future__ import annotations

from pathlib import Path

from .errors import DataError, file_problem

#: magic bytes at a file's start -> what the file is (Parquet: its magic at both ends)
BINARY_KINDS = ((b"PK\x03\x04", "a ZIP archive (an .xlsx workbook?)"),
                (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1", "an OLE2 compound file (an .xls workbook?)"),
                (b"MATLAB 5.0 MAT-file", "a MATLAB .mat file"), (b"\x89HDF\r\n\x1a\n", "an HDF5 file (a MATLAB v7.3 .mat?)"),
                (b"PAR1", "a Parquet file"), (b"\x1f\x8b", "a gzip-compressed file"),
                (b"BZh", "a bzip2-compressed file"), (b"\xfd7zXZ\x00", "an xz-compressed file"),
                (b"%PDF", "a PDF document"), (b"MDF     ", "an ASAM MDF measurement file"))
#: the compressed kinds of BINARY_KINDS and their suffix
COMPRESSED_SUFFIX = {"a gzip-compressed file": ".gz", "a bzip2-compressed file": ".bz2", "an xz-compressed file": ".xz"}
BINARY_FIX = ("export the columns as a CSV (UTF-8, a header row naming the columns; e.g. pandas: "
              "pd.read_parquet(f).to_csv('data.csv', index=False); MATLAB: writetable(T, 'data.csv'))")
UTF32_BOMS = (b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff")


def text_lines(text: str) -> list[str]:
    """The lines of ``text`` as an editor counts them: split at ``\\n``, ``\\r\\n`` and ``\\r`` only (``str.splitlines``
    also splits at form feeds, file separators, U+0085 and U+2028, which a Latin-1 or UTF-16 file may hold inside a
    line)."""
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def decode_text(data: bytes, path, decompresses: bool = False) -> tuple[str, str | None]:
    """The text of the file ``path`` whose bytes are ``data``, and a note when it is not UTF-8: a byte-order mark
    (UTF-16 of spreadsheet "Unicode text" exports, UTF-8 with BOM), UTF-16 without one (a NUL in every other
    byte), else UTF-8 when the whole file decodes as such, else Windows-1252 (the loggers' and spreadsheets' 8-bit
    Western code page; Latin-1 where a byte is undefined there), said with the first byte that is not UTF-8.  A
    binary file (:data:`BINARY_KINDS`, NUL bytes) is a DataError naming what it is; a compressed one says, for a
    reader that ``decompresses`` by the file's suffix (a record), which suffix it needs, else to decompress it."""
    kind = next((k for magic, k in BINARY_KINDS if data.startswith(magic)
                 and (magic != b"PAR1" or data.rstrip().endswith(b"PAR1"))), None)
    if kind in COMPRESSED_SUFFIX:
        fix = (f"name it with the suffix {COMPRESSED_SUFFIX[kind]} (read decompressed by it), or decompress it"
               if decompresses else "decompress it first (this file is read as plain text)")
        raise DataError(f"{path}: is {kind}: {fix}")
    if kind is not None:
        raise DataError(f"{path}: is {kind}, not a CSV text file: {BINARY_FIX}")
    if data[:4] in UTF32_BOMS:
        try:
            return _no_nul(data.decode("utf-32"), path, "UTF-32"), "decoded as UTF-32 (its byte-order mark)"
        except UnicodeDecodeError as exc:
            raise DataError(f"{path}: a UTF-32 byte-order mark, but not UTF-32 text (byte {exc.start})") from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        try:
            return _no_nul(data.decode("utf-16"), path, "UTF-16"), "decoded as UTF-16 (its byte-order mark)"
        except UnicodeDecodeError as exc:
            raise DataError(f"{path}: a UTF-16 byte-order mark, but not UTF-16 text (byte {exc.start})") from None
    head = data[:4096]
    for enc, pos, end in (("utf-16-le", 1, "little"), ("utf-16-be", 0, "big")):
        if len(head) >= 8 and head[pos::2].count(0) > 0.9 * len(head[pos::2]):
            try:
                return (_no_nul(data.decode(enc), path, f"UTF-16 {end}-endian"),
                        f"decoded as UTF-16 {end}-endian (no byte-order mark; a NUL in every other byte)")
            except UnicodeDecodeError:
                break
    if b"\x00" in head:
        raise DataError(f"{path}: holds NUL bytes (byte {head.index(0)}): a binary file, not a CSV text file: "
                        f"{BINARY_FIX}")
    body = data[3:] if data[:3] == b"\xef\xbb\xbf" else data
    try:
        return body.decode("utf-8"), None
    except UnicodeDecodeError as exc:
        where = exc.start + (len(data) - len(body))
    try:
        text, name = body.decode("cp1252"), "Windows-1252"
    except UnicodeDecodeError:
        text, name = body.decode("latin-1"), "Latin-1"
    line = data.count(b"\n", 0, where) + 1
    return text, (f"decoded as {name}: not UTF-8 (byte 0x{data[where]:02x} on line {line}); save the file as UTF-8 "
                  f"if a name or unit reads wrong")


def _no_nul(text: str, path, enc: str) -> str:
    """``text`` decoded as ``enc``, refused when it still holds NUL characters (UTF-32 without a byte-order mark read
    as UTF-16, or a binary file)."""
    if "\x00" in text:
        raise DataError(f"{path}: decoded as {enc} it still holds NUL characters (at character {text.index(chr(0))}): "
                        f"UTF-32 without a byte-order mark, or a binary file - save it as a UTF-8 CSV")
    return text


def read_text_file(path, what: str = "file", max_bytes: int | None = None) -> tuple[str, str | None]:
    """The text of the user's file ``path`` (:func:`decode_text`) and its note; a file that cannot be read (not
    found, a folder, a device, larger than ``max_bytes``, an OS error) is a DataError naming it as ``what``."""
    path = Path(path)
    why = file_problem(path, what, max_bytes)
    if why is not None:
        raise DataError(f"{path}: {why}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    return decode_text(data, path)
