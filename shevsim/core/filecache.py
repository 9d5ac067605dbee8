"""filecache.py - parse a data file once per process while it is unchanged.

A study builds the same scenario for every evaluation (only its overrides differ), so the same cycle,
map and cell-table files are read again and again.  :func:`memo_file` wraps a *pure* reader of one file
(its result depends only on the file's bytes and the reader's other arguments): the first call parses,
later calls on the same file (device and inode, symlinks followed), size and modification time (ns) get a
copy of that result (a result made of tuples of numbers and strings is shared: it cannot be changed).
A file edited in between is read again; a reader that raises is never cached (the error is raised on
every call); each caller gets its own copy (arrays copied, lists and dicts rebuilt), so a caller that
changes what it got cannot change what the next one gets.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import os
from collections import OrderedDict

import numpy as np

MAX_ENTRIES = 256
_CACHE: OrderedDict = OrderedDict()


_IMMUTABLE = (str, int, float, bool, type(None))


def _copy(x):
    if isinstance(x, np.ndarray):
        return x.copy()
    if isinstance(x, list):
        return [v if type(v) in _IMMUTABLE else _copy(v) for v in x]
    if isinstance(x, tuple):
        if all(type(v) in _IMMUTABLE or (type(v) is tuple and all(type(w) in _IMMUTABLE for w in v)) for v in x):
            return x                                 # immutable all the way down: shared, not copied
        return tuple(_copy(v) for v in x)
    if isinstance(x, dict):
        return {k: _copy(v) for k, v in x.items()}
    if isinstance(x, _IMMUTABLE):
        return x
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        new = copy.copy(x)
        for f in dataclasses.fields(x):
            object.__setattr__(new, f.name, _copy(getattr(x, f.name)))
        return new
    return copy.deepcopy(x)


def memo_file(fn):
    """Decorator: memoise ``fn(path, *args, **kwargs)`` on (device, inode, size, mtime_ns, args, kwargs)."""

    @functools.wraps(fn)
    def wrapper(path, *args, **kwargs):
        try:
            st = os.stat(path)                       # the file itself (symlinks followed): device + inode
            key = (fn.__module__, fn.__qualname__, st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, args,
                   tuple(sorted(kwargs.items())))
            hash(key)
        except (OSError, TypeError, ValueError):
            return fn(path, *args, **kwargs)           # the reader reports a missing file itself
        hit = _CACHE.get(key)
        if hit is None:
            hit = fn(path, *args, **kwargs)
            _CACHE[key] = hit
            if len(_CACHE) > MAX_ENTRIES:
                _CACHE.popitem(last=False)
        else:
            _CACHE.move_to_end(key)
        return _copy(hit)

    wrapper.cache_clear = _CACHE.clear
    return wrapper


def clear() -> None:
    """Forget every parsed file."""
    _CACHE.clear()
