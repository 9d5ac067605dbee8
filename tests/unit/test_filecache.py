"""shevsim.core.filecache: a data file is parsed once per process while unchanged, and every caller gets
its own copy; an edited file is read again and a failing read is never cached."""
from __future__ import annotations

import os

import numpy as np
import pytest

from shevsim.core.errors import DataError
from shevsim.core.filecache import memo_file
from shevsim.cycles import load_cycle


def _write(path, speeds, mtime_ns=None):
    path.write_text("time_s,speed_mps\n" + "".join(f"{i},{v}\n" for i, v in enumerate(speeds)))
    if mtime_ns is not None:
        os.utime(path, ns=(mtime_ns, mtime_ns))


def test_a_cycle_is_parsed_once_and_each_caller_gets_its_own_copy(tmp_path):
    calls = []

    @memo_file
    def reader(path):
        calls.append(path)
        return {"rows": [[1.0, 2.0]], "a": np.arange(3.0)}

    p = tmp_path / "x.csv"
    p.write_text("x")
    a = reader(p)
    a["rows"][0][0] = 99.0
    a["a"][0] = 99.0
    b = reader(p)
    assert len(calls) == 1
    assert b["rows"][0][0] == 1.0 and b["a"][0] == 0.0


def test_an_edited_file_is_read_again(tmp_path):
    p = tmp_path / "c.csv"
    _write(p, [0.0, 1.0, 2.0], mtime_ns=1_000_000_000)
    first = load_cycle(p)
    _write(p, [0.0, 1.0, 3.0], mtime_ns=2_000_000_000)          # same size, new time
    again = load_cycle(p)
    assert first.speed_mps[-1] == 2.0 and again.speed_mps[-1] == 3.0
    again.speed_mps[0] = 5.0                                  # a caller's change stays its own
    assert load_cycle(p).speed_mps[0] == 0.0


def test_a_failing_read_is_not_cached(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time_s,speed_mps\n0,0\n1,nan\n2,1\n")
    for _ in range(2):
        with pytest.raises(DataError, match="bad.csv"):
            load_cycle(p)
    with pytest.raises(DataError):
        load_cycle(tmp_path / "missing.csv")
