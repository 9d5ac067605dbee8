"""Nothing a user owns is removed or replaced (issue 22): the result folder's file list is verified, a
stopped run keeps an earlier result and saves its own partial one beside it, exports do not overwrite.

These run the ``shevsim`` command as a subprocess, on both engines (the Python master and the compiled
fast path), and stop it with real signals.
"""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from shevsim.core.results import load_result

ROOT = Path(__file__).resolve().parents[2]
ENGINES = ["python", "fast"]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["MPLBACKEND"] = "Agg"
    return env


def _shevsim(*args, cwd, timeout=600):
    return subprocess.run([sys.executable, "-m", "shevsim.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=_env(), timeout=timeout)


def _short_run(out, engine, cwd, *extra):
    return _shevsim("run", "hd_udds_rule", "--set", "scenario.stop_s=30", "--engine", engine, "--no-plots",
                    "-q", "--out", out, *extra, cwd=cwd)


def _digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("engine", ENGINES)
def test_a_forged_file_list_in_run_json_removes_nothing_of_the_users(tmp_path, engine):
    out = tmp_path / "o"
    r = _short_run(out, engine, tmp_path)
    assert r.returncode == 0, r.stderr
    (out / "notebook.ipynb").write_text('{"cells": []}')
    (out / "data.csv").write_text("a,b\n1,2\n")
    meta = json.loads((out / "run.json").read_text())
    # 1. "files": [""] used to delete the whole folder; 2. a listed notebook used to be deleted
    for files in ([""], ["run.json", "notebook.ipynb", "data.csv", "../o", "."]):
        meta["files"] = files
        (out / "run.json").write_text(json.dumps(meta))
        r = _short_run(out, engine, tmp_path)
        assert (out / "notebook.ipynb").read_text() == '{"cells": []}'
        assert (out / "data.csv").read_text() == "a,b\n1,2\n"
        if files == [""]:
            # the earlier timeseries is no longer vouched for by run.json: refused before running, nothing touched
            assert r.returncode == 2, r.stderr
            assert "not the file(s) shevsim wrote there" in r.stderr and "timeseries.parquet" in r.stderr
            assert "results in" not in r.stdout
            # the user moves the unvouched files away: the run then writes its result beside the user's files
            for n in ("timeseries.parquet", "metrics.json", "scenario.toml"):
                (out / n).rename(tmp_path / n)
        else:
            assert r.returncode == 0, r.stderr
    r = _short_run(out, engine, tmp_path)
    assert r.returncode == 0, r.stderr
    assert (out / "notebook.ipynb").is_file() and (out / "data.csv").is_file()
    assert load_result(out).termination == "completed"


@pytest.mark.parametrize("engine", ENGINES)
def test_a_changed_result_file_is_not_replaced(tmp_path, engine):
    out = tmp_path / "o"
    assert _short_run(out, engine, tmp_path).returncode == 0
    meta = json.loads((out / "run.json").read_text())
    assert set(meta["sha256"]) == set(meta["files"]) - {"run.json"}
    assert meta["sha256"]["metrics.json"] == hashlib.sha256((out / "metrics.json").read_bytes()).hexdigest()
    (out / "metrics.json").write_text('{"my": "notes"}')          # the user edited a file shevsim wrote
    before = _digest(out)
    r = _short_run(out, engine, tmp_path)
    assert r.returncode == 2 and "metrics.json" in r.stderr and "move it away" in r.stderr, r.stderr
    assert _digest(out) == before


class _Reader:
    """Read a process's stream in a thread (so a progress bar's bytes never block it) and keep the text."""

    def __init__(self, stream):
        self.chunks: list[str] = []
        self.thread = threading.Thread(target=self._pump, args=(stream,), daemon=True)
        self.thread.start()

    def _pump(self, stream):
        while True:
            ch = stream.read(1)
            if not ch:
                return
            self.chunks.append(ch)

    def wait_for(self, needle: str, timeout: float) -> bool:
        t0 = time.time()
        while time.time() - t0 < timeout and self.thread.is_alive():
            if needle in "".join(self.chunks):
                return True
            time.sleep(0.05)
        return needle in "".join(self.chunks)

    def text(self) -> str:
        self.thread.join(timeout=60)
        return "".join(self.chunks)


def _default_sigint():
    # a background test run inherits SIGINT ignored; a user's Ctrl-C reaches a process with the default
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_stopped_run_keeps_the_earlier_result_and_saves_its_own_beside_it(tmp_path, engine, sig):
    out = tmp_path / "o"
    r = _short_run(out, engine, tmp_path)
    assert r.returncode == 0, r.stderr
    (out / "notes.txt").write_text("mine")
    earlier = _digest(out)
    n_earlier = len(load_result(out))
    # a long run (200 repetitions of HD-UDDS, 2.1 M steps) into the same folder, stopped while it simulates
    cmd = [sys.executable, "-m", "shevsim.cli", "run", "hd_udds_rule", "--set", "cycle.repeat=200", "--engine",
           engine, "--no-plots", "--allow-large", "--record", "vehicle.speed_mps", "battery.soc_pct",
           "--out", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_env(),
                         preexec_fn=_default_sigint)
    try:
        reader = _Reader(p.stderr)
        assert reader.wait_for("simulating", 300), reader.text()
        time.sleep(1.0)
        t_sig = time.perf_counter()
        p.send_signal(getattr(signal, sig))
        p.wait(timeout=120)
        stop_wall = time.perf_counter() - t_sig
        err = reader.text()
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    # the earlier complete result and the user's file are exactly as they were
    assert _digest(out) == earlier
    assert len(load_result(out)) == n_earlier and load_result(out).termination == "completed"
    # the interrupted run's partial result is in a new folder beside it, named in the message
    new = sorted(tmp_path.glob("o-interrupted-*"))
    assert len(new) == 1, list(tmp_path.iterdir())
    assert str(new[0]) in err and "kept as it was" in err
    part = load_result(new[0])
    assert part.termination.status == "stopped" and "interrupted" in part.termination.reason
    assert 2 < len(part) and part.time_s[-1] < 200 * 1060.0
    assert part.termination.time_s == pytest.approx(part.time_s[-1])
    # stopped promptly: the loop checks for a stop request at least every ~0.2 s of its wall time (the
    # bound here is generous for a loaded test machine; the saving of the small record takes the rest)
    assert stop_wall < 15.0, stop_wall


@pytest.mark.parametrize("engine", ENGINES)
def test_a_stopped_run_into_a_new_folder_saves_there(tmp_path, engine):
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "shevsim.cli", "run", "hd_udds_rule", "--set", "cycle.repeat=200", "--engine",
           engine, "--no-plots", "--allow-large", "--record", "vehicle.speed_mps", "--out", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_env(),
                         preexec_fn=_default_sigint)
    try:
        reader = _Reader(p.stderr)
        assert reader.wait_for("simulating", 300), reader.text()
        time.sleep(0.5)
        p.send_signal(signal.SIGINT)
        p.wait(timeout=120)
        reader.text()
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130
    assert not list(tmp_path.glob("o-interrupted-*"))
    part = load_result(out)
    assert part.termination.status == "stopped" and len(part) > 2


@pytest.mark.parametrize("which", ["export", "export-ssp"])
def test_exports_do_not_overwrite_without_force(tmp_path, which):
    """The SSP case exports the two-component verification scenario: the refusal and --force are the same
    code for any scenario, and the HD-UDDS scenario's eleven FMUs took ~45 s (its SSP export is built and
    checked in tests/integration/test_fmu_ssp.py)."""
    pytest.importorskip("fmpy")
    target = tmp_path / ("model.fmu" if which == "export" else "system.ssp")
    target.write_bytes(b"the user's own file")
    args = (["fmu", "export", "vehicle", "--params", str(ROOT / "components/vehicle/matv.toml"), "-o", target]
            if which == "export" else
            ["fmu", "export-ssp", str(ROOT / "scenarios/verification/two_body.toml"), "-o", target])
    r = _shevsim(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert "exists" in r.stderr and "--force" in r.stderr
    assert target.read_bytes() == b"the user's own file"
    r = _shevsim(*args, "--force", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert target.read_bytes()[:2] == b"PK"
