"""atomic.py - write files so that a crash never leaves half of one.

Everything is written to a temporary file in the destination folder and moved onto the
destination with ``os.replace`` (atomic on POSIX and Windows). The temporary file gets the
usual permissions (``mkstemp`` creates it 0600).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np


def atomic_write(path: str | Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` to fill a temporary file, then move it onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (flushed to disk before the rename)."""
    def w(tmp):
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return atomic_write(path, w)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    return str(o)


def write_json_atomic(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON (numpy values converted) to ``path`` atomically."""
    return write_text_atomic(path, json.dumps(obj, indent=2, default=_json_default, allow_nan=True))


def write_csv_atomic(path: str | Path, df, **to_csv_kwargs) -> Path:
    """Write a DataFrame as CSV to ``path`` atomically."""
    to_csv_kwargs.setdefault("index", False)
    return atomic_write(path, lambda tmp: df.to_csv(tmp, **to_csv_kwargs))


def refuse_overwrite(path: str | Path, force: bool = False, option: str = "--force") -> Path:
    """Check that ``path`` may be written: an existing file is refused unless ``force`` (raises
    :class:`~shevsim.core.errors.ShevsimError` naming it); a folder is never replaced."""
    from .errors import ShevsimError
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        raise ShevsimError(f"'{path}' exists and is a folder: not replaced; choose another output file")
    if (path.exists() or path.is_symlink()) and not force:
        raise ShevsimError(f"'{path}' exists: not overwritten; give {option} to replace it, or choose another "
                           f"output file")
    return path


def read_files(folder: str | Path, exclude: tuple[str, ...] = ()) -> dict[str, bytes]:
    """Every file under ``folder`` (relative POSIX path -> bytes), sorted; names in ``exclude`` (and
    names starting with one of them, e.g. ``cache.sqlite-wal``) and hidden files are left out."""
    folder = Path(folder)
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(folder).parts) \
                and not any(rel.startswith(x) for x in exclude):
            out[rel] = p.read_bytes()
    return out


def write_files(out_dir: str | Path, files: dict[str, bytes], marker: str, what: str) -> Path:
    """Write ``files`` (relative path -> bytes) into ``out_dir``, each atomically; return the folder.

    Files of the same names are replaced (an earlier output of the same kind); other files are kept.
    A folder that holds files but no ``marker`` (say ``summary.json``) is not an output of ours and is
    refused before anything is written, as is a path that exists and is not a folder."""
    from .errors import ShevsimError
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ShevsimError(f"{what}: '{out}' exists and is not a folder: not replaced; choose another folder")
    if out.is_dir() and not (out / marker).is_file():
        clash = sorted(n for n in files if (out / n).exists())
        if clash:
            raise ShevsimError(f"{what}: '{out}' holds files but no {marker} (not an output of shevsim), and "
                               f"{clash[0]} would be replaced: choose another folder")
    for name in sorted(files, key=lambda n: n == marker):      # the marker last: a complete folder has it
        write_bytes_atomic(out / name, files[name])
    return out
