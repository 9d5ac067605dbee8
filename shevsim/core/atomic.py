"""atomic.py - write files so that a crash never leaves half of one.

Everything is written to a temporary file in the destination folder and moved onto the
destination with ``os.replace`` (atomic on POSIX and Windows). The temporary file gets the
usual permissions (``mkstemp`` creates it 0600).
"""
from __future__ import annotations

import hashlib
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


#: the hidden list, in an output folder `write_files` wrote, of each file's SHA-256 as written (a file whose content
#: is no longer one of them was changed since, by somebody else: never replaced)
MANIFEST = ".shevsim-files.json"
#: a shevsim report page (``shevsim report DIR`` rewrites report.html after the output): its generator mark
_REPORT_MARK = '<meta name="generator" content="shevsim'


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's content."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read_manifest(out: Path) -> dict[str, list[str]] | None:
    """``{name: [sha256, ...]}`` from ``out/MANIFEST``; None when there is none (an output written before the
    manifest existed) or it is not one of ours."""
    try:
        doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError, RecursionError):
        return None
    files = doc.get("sha256") if isinstance(doc, dict) else None
    if not isinstance(files, dict):
        return None
    return {str(k): [h for h in (v if isinstance(v, list) else [v]) if isinstance(h, str)] for k, v in files.items()}


def edited_outputs(out_dir: str | Path, names, marker: str) -> list[str]:
    """The names in ``names`` that exist in the output folder ``out_dir`` (one holding ``marker``) but are not as
    shevsim wrote them there: changed since (their SHA-256 is not one `MANIFEST` lists), added by somebody else
    (not listed), or not a regular file.  An output written before the manifest existed has none: there a file
    modified more than a second after ``marker`` (written last) counts as changed.  A report page with shevsim's
    generator mark (``shevsim report DIR`` rewrote it) is ours."""
    out = Path(out_dir)
    man = _read_manifest(out)
    try:
        t_marker = (out / marker).stat().st_mtime
    except OSError:
        t_marker = None
    bad = []
    for name in names:
        q = out / name
        if not (q.exists() or q.is_symlink()) or name == MANIFEST:
            continue
        try:
            if q.is_symlink() or not q.is_file():
                bad.append(name)
            elif q.suffix == ".html" and _REPORT_MARK in q.read_text(errors="replace")[:4000]:
                continue
            elif man is not None:
                if file_sha256(q) not in man.get(name, []):
                    bad.append(name)
            elif t_marker is not None and name != marker and q.stat().st_mtime > t_marker + 1.0:
                bad.append(name)
        except OSError:
            bad.append(name)
    return bad


def foreign_files(out_dir: str | Path, names) -> list[str]:
    """The names in ``names`` that exist in ``out_dir`` (a folder without its marker: a first save that did not
    finish, or a user's folder) and are not listed in its `MANIFEST` with their present content (a crash during
    shevsim's first save there leaves only listed files)."""
    out = Path(out_dir)
    man = _read_manifest(out) or {}
    bad = []
    for name in sorted(names):
        q = out / name
        if not (q.exists() or q.is_symlink()):
            continue
        try:
            if q.is_symlink() or not q.is_file() or file_sha256(q) not in man.get(name, []):
                bad.append(name)
        except OSError:
            bad.append(name)
    return bad


def edited_message(what: str, out: str | Path, bad: list[str]) -> str:
    """The refusal of `edited_outputs`' findings, naming the first file."""
    return (f"{what}: '{Path(out) / bad[0]}' was changed since shevsim wrote it (or was put there by somebody else)"
            + (f", as were {len(bad) - 1} more ({', '.join(bad[1:4])})" if len(bad) > 1 else "")
            + ": not replaced; move it away or choose another folder")


def check_output_folder(out_dir: str | Path, names, marker: str, what: str) -> None:
    """Refuse (`ShevsimError`, naming the file) writing ``names`` into ``out_dir``: a path that is not a folder; a
    folder without ``marker`` holding one of the names not as shevsim wrote it (`foreign_files`); an earlier output
    (``marker`` there) one of whose files was changed since (`edited_outputs`).  Nothing is written."""
    from .errors import ShevsimError
    out = Path(out_dir)
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise ShevsimError(f"{what}: '{out}' exists and is not a folder: not replaced; choose another folder")
    if not out.is_dir():
        return
    if not (out / marker).is_file():
        clash = foreign_files(out, names)
        if clash:
            raise ShevsimError(f"{what}: '{out}' holds files but no {marker} (not an output of shevsim), and "
                               f"{clash[0]} would be replaced: choose another folder")
        return
    bad = edited_outputs(out, names, marker)
    if bad:
        raise ShevsimError(edited_message(what, out, bad))


def write_files(out_dir: str | Path, files: dict[str, bytes], marker: str, what: str) -> Path:
    """Write ``files`` (relative path -> bytes) into ``out_dir``, each atomically; return the folder.

    Files of the same names are replaced only where they are an earlier output of the same kind exactly as
    shevsim wrote it (`edited_outputs`: a file a user changed or put there is refused, naming it, before anything
    is written); other files are kept.  A folder that holds files of these names but no ``marker`` (say
    ``summary.json``) is not an output of ours and is refused (`foreign_files`: unless the manifest lists them as
    they are - a first save that crashed), as is a path that exists and is not a folder.  The hashes of what is
    written go to the hidden `MANIFEST`, merged with what it lists already (another kind of output in the same
    folder; an older output's files adopted as they were written): first with the earlier and the new hash of
    each name (a crash between two files leaves every file one of them), then with the new ones only."""
    out = Path(out_dir)
    check_output_folder(out, sorted(files), marker, what)
    old: dict[str, list[str]] = (_read_manifest(out) or {}) if out.is_dir() else {}
    if out.is_dir() and (out / marker).is_file():
        if _read_manifest(out) is None:    # an output written before the list: adopt what is as it was written
            t_marker = (out / marker).stat().st_mtime
            for q in sorted(out.rglob("*")):
                rel = q.relative_to(out).as_posix()
                if q.is_file() and not q.is_symlink() and not rel.startswith(".") \
                        and q.stat().st_mtime <= t_marker + 1.0:
                    old.setdefault(rel, [file_sha256(q)])
    new = {name: hashlib.sha256(data).hexdigest() for name, data in files.items()}
    both = {**old, **{n: list(dict.fromkeys(old.get(n, []) + [h])) for n, h in new.items()}}
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / MANIFEST, json.dumps({"sha256": both}, indent=1, sort_keys=True))
    for name in sorted(files, key=lambda n: n == marker):      # the marker last: a complete folder has it
        write_bytes_atomic(out / name, files[name])
    write_text_atomic(out / MANIFEST, json.dumps({"sha256": {**old, **{n: [h] for n, h in new.items()}}},
                                                 indent=1, sort_keys=True))
    return out
