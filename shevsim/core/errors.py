"""errors.py - the exceptions shevsim raises; every message names where the problem is."""
from __future__ import annotations


class ShevsimError(Exception):
    """Base class of all shevsim errors."""


class ScenarioError(ShevsimError):
    """A scenario or parameter file is malformed or inconsistent (message names file and field)."""


class ConnectionError_(ShevsimError):
    """A connection refers to an unknown port or joins incompatible units."""


class AlgebraicLoopError(ShevsimError):
    """A cycle of direct-feedthrough connections (message lists every component.port in it)."""


class SimulationError(ShevsimError):
    """A run failed: message names component, variable and time."""



class FastPathError(SimulationError):
    """The compiled whole-system loop (:mod:`shevsim.fast`) raised inside compiled code: no component,
    port or time is known (``engine='auto'`` then reruns on the Python master, which names them)."""

class DataError(ShevsimError):
    """Input data (cycle, measurement) is malformed: message names the file and column/row."""


class OutputError(ShevsimError):
    """The environment refused a file shevsim writes (full disk, file-size limit, closed output stream):
    the message names the file, the limit met and what to do; nothing half-written is left."""


def os_error_text(exc: OSError) -> str:
    """Plain words for an OSError met while writing (errno name, what it means, what to do)."""
    import errno as _e
    hints = {_e.ENOSPC: "the disk is full: free space or write elsewhere",
             _e.EFBIG: "the file is larger than this process may write (file-size limit, `ulimit -f`, or the "
                       "file system's maximum): raise the limit, record less (--record-every N, [record] "
                       "signals) or write elsewhere",
             _e.EDQUOT: "the disk quota is exhausted: free space or write elsewhere",
             _e.EROFS: "the file system is read-only: write elsewhere",
             _e.EACCES: "permission denied: write elsewhere",
             _e.EPIPE: "the reader of the output went away"}
    name = _e.errorcode.get(exc.errno or 0, "")
    text = exc.strerror or str(exc)
    hint = hints.get(exc.errno or 0)
    return f"{text}{f' ({name})' if name else ''}{f'; {hint}' if hint else ''}"


def toml_loads(text: str, where: str, error: type = ScenarioError, malformed: str = "malformed TOML") -> dict:
    """``tomllib.loads(text)`` with every failure a plain ``error`` naming ``where``: malformed TOML, and
    nesting deeper than the reader can follow (it recurses once per level of arrays or inline tables and
    stops at Python's recursion limit) - what would otherwise be an internal RecursionError."""
    import sys
    import tomllib
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{where}: {malformed}: {exc}") from None
    except RecursionError:
        raise error(f"{where}: TOML nested too deeply: arrays or inline tables nested more than a few hundred "
                    f"levels (the limit is Python's recursion limit, {sys.getrecursionlimit()}); a scenario or "
                    f"parameter value needs at most a few levels: flatten it") from None


def file_problem(path, what: str = "file", max_bytes: int | None = None) -> str | None:
    """Why ``path`` cannot be read as an input file, in plain words, or None when it can: not found, a
    folder, not a regular file (a device such as /dev/zero, a pipe, a socket), or larger than
    ``max_bytes``. Checked before reading, so a device that never ends is never read."""
    import os
    import stat as _stat
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return f"{what} not found"
    except OSError as exc:
        return f"cannot open the {what}: {exc.strerror or exc}"
    if _stat.S_ISDIR(st.st_mode):
        return f"is a folder, not a {what}: give the file itself"
    if not _stat.S_ISREG(st.st_mode):
        kind = ("a character device" if _stat.S_ISCHR(st.st_mode) else "a block device" if _stat.S_ISBLK(st.st_mode)
                else "a pipe" if _stat.S_ISFIFO(st.st_mode) else "a socket" if _stat.S_ISSOCK(st.st_mode)
                else "not a regular file")
        return f"is {kind}, not a {what}: give a regular file"
    if max_bytes is not None and st.st_size > max_bytes:
        return (f"is {st.st_size / 2**20:.4g} MiB, above the {max_bytes / 2**20:.4g} MiB a {what} may have: "
                f"refused before reading it")
    return None
