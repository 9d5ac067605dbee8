"""Exported FMUs are self-contained: they carry the shevsim code they run.

* (slow) the exported thermal node and battery pack run in a fresh virtual environment holding only
  the packages the FMUs declare (from PyPI by name: numpy, scipy, numba) plus fmpy - shevsim is not
  importable there: the node reproduces the closed-form solution, the pack the numbers of a run
  where shevsim is installed;
* a missing dependency is named on stderr (no debug logging needed) and in shevsim's load error.
"""
from __future__ import annotations

import ast
import json
import math
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from shevsim.fmu import FMUComponent, FMULoadError  # noqa: E402
from shevsim.fmu.export import export_component  # noqa: E402
from shevsim.fmu.reference import RCThermalNode  # noqa: E402

pytestmark = pytest.mark.fmu

RUN = """
import sys
from fmpy import simulate_fmu
r = simulate_fmu(sys.argv[1], stop_time=10.0, step_size=0.5, output_interval=0.5,
                 start_values={"heat_w": 1500.0}, output=["t_c"])
print(repr(float(r["t_c"][-1])))
"""


def _spec(fmu: Path) -> dict:
    with zipfile.ZipFile(fmu) as zf:
        return json.loads(zf.read("resources/shevsim_component.json"))


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_exported_fmu_carries_shevsim_and_declares_its_packages(tmp_path, fmi_version):
    fmu = export_component(RCThermalNode, None, tmp_path / "node.fmu", fmi_version)
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
    assert "resources/shevsim/fmu/slave.py" in names and "resources/shevsim/core/component.py" in names
    assert f"resources/pythonfmu{'' if fmi_version == 2 else '3'}/fmi{fmi_version}slave.py" in names
    assert not any("__pycache__" in n for n in names)
    assert _spec(fmu)["requires"] == ["numpy"]   # the node is pure Python + numpy (through shevsim.core)


def test_missing_dependency_is_named_without_debug_logging(tmp_path):
    fmu = export_component(RCThermalNode, None, tmp_path / "node_dep.fmu", 2,
                           extra_requires=("shevsim_no_such_pkg",))
    res = subprocess.run([sys.executable, "-c", RUN, str(fmu)], capture_output=True, text=True, timeout=120,
                         cwd=tmp_path)
    assert res.returncode != 0
    assert "missing Python package(s) shevsim_no_such_pkg" in res.stderr
    assert "pip install shevsim_no_such_pkg" in res.stderr
    with pytest.raises(FMULoadError, match="shevsim_no_such_pkg"):
        FMUComponent("node", fmu)


RUN_BATTERY = """
import sys
from fmpy import simulate_fmu
r = simulate_fmu(sys.argv[1], stop_time=60.0, step_size=0.1, output_interval=1.0,
                 start_values={"power_w": 20000.0}, output=["soc_pct", "voltage_v", "t_core_c"])
print(repr([float(r[k][-1]) for k in ("soc_pct", "voltage_v", "t_core_c")]))
"""


@pytest.mark.slow
def test_exported_fmu_runs_in_a_venv_without_shevsim(tmp_path):
    from shevsim.core.paths import data_path
    fmu = export_component(RCThermalNode, None, tmp_path / "node.fmu", 2)
    battery = export_component("battery", data_path("components", "battery", "default.toml"),
                               tmp_path / "battery.fmu", 2)
    assert _spec(battery)["requires"] == ["numba", "numpy", "scipy"]
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    pkgs = sorted(set(_spec(fmu)["requires"]) | set(_spec(battery)["requires"])) + ["fmpy"]
    inst = subprocess.run([str(py), "-m", "pip", "install", "-q", *pkgs], capture_output=True, text=True,
                          timeout=900)
    if inst.returncode:
        pytest.skip(f"pip install {' '.join(pkgs)} failed (no package index?): {inst.stderr[-500:]}")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    probe = subprocess.run([str(py), "-c", "import shevsim"], capture_output=True, text=True, cwd=tmp_path, env=env)
    assert probe.returncode != 0 and "No module named 'shevsim'" in probe.stderr
    res = subprocess.run([str(py), "-c", RUN, str(fmu)], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    t_c = float(res.stdout.strip().splitlines()[-1])
    # closed form: T = T_inf + (T0 - T_inf) exp(-t / (R C)), defaults R = 0.02 K/W, C = 5000 J/K, T0 = 25 degC
    t_inf = 25.0 + 0.02 * 1500.0
    assert t_c == pytest.approx(t_inf + (25.0 - t_inf) * math.exp(-10.0 / 100.0), abs=1e-9)
    # the battery pack (numba-compiled physics, scipy) runs there too, equal to the run where shevsim is
    # installed (same code, same numbers)
    there = subprocess.run([str(py), "-c", RUN_BATTERY, str(battery)], capture_output=True, text=True,
                           cwd=tmp_path, env=env, timeout=600)
    assert there.returncode == 0, there.stderr[-2000:]
    here = subprocess.run([sys.executable, "-c", RUN_BATTERY, str(battery)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=600)
    assert here.returncode == 0, here.stderr[-2000:]
    a = ast.literal_eval(there.stdout.strip().splitlines()[-1])
    b = ast.literal_eval(here.stdout.strip().splitlines()[-1])
    assert a == b and 0.0 < a[0] < 100.0
