"""An installed shevsim finds its bundled data: the wheel carries components/, cycles/, scenarios/, fmus/
inside the package (shevsim/_data, pyproject force-include) and shevsim.core.paths finds them there."""
from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("components", "cycles", "scenarios", "fmus", "vehicles", "data/measured")


def test_pyproject_ships_every_data_folder_inside_the_package():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    fi = cfg["tool"]["hatch"]["build"]["targets"]["wheel"]["force-include"]
    assert {k: v for k, v in fi.items()} == {f: f"shevsim/_data/{f}" for f in FOLDERS}


def test_installed_layout_runs_a_bundled_scenario_by_name(tmp_path):
    """The wheel's layout (package + shevsim/_data), imported from elsewhere, from an empty folder."""
    site = tmp_path / "site"
    shutil.copytree(ROOT / "shevsim", site / "shevsim", ignore=shutil.ignore_patterns("__pycache__"))
    for f in FOLDERS:
        shutil.copytree(ROOT / f, site / "shevsim" / "_data" / f, ignore=shutil.ignore_patterns("__pycache__"))
    work = tmp_path / "empty"
    work.mkdir()
    code = ("import shevsim, shevsim.core.paths as p;"
            "from shevsim.core.scenario import build_master, load_scenario;"
            "sc = load_scenario('hd_udds_rule', ['cycle.repeat=1']);"
            "r = build_master(sc).run(5.0);"
            "print(shevsim.__file__, p.DATA_ROOT, sc.path, r.termination)")
    r = subprocess.run([sys.executable, "-c", code], cwd=work, capture_output=True, text=True, timeout=600,
                       env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)})
    assert r.returncode == 0, r.stderr
    pkg, data_root, path, term = r.stdout.split()
    assert pkg.startswith(str(site)) and data_root == str(site / "shevsim" / "_data")
    assert path.startswith(data_root) and term == "completed"


@pytest.mark.slow
def test_built_wheel_holds_the_data(tmp_path):
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(tmp_path)],
                       capture_output=True, text=True, timeout=900,
                       env={**os.environ, "SHEVSIM_PRECOMPILE": "0"})      # the data only: no precompile
    assert r.returncode == 0, r.stderr
    names = zipfile.ZipFile(glob.glob(str(tmp_path / "*.whl"))[0]).namelist()
    for f in FOLDERS[:3]:
        assert any(n.startswith(f"shevsim/_data/{f}/") for n in names), f
    assert "shevsim/_data/scenarios/hd_udds_mpc.toml" in names
    assert sum(n.endswith(".csv") for n in names) >= 20 and sum(n.endswith(".toml") for n in names) >= 15


def test_license_and_py_typed_ship():
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert (ROOT / "shevsim" / "py.typed").is_file()
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert cfg["project"]["license"] == {"text": "MIT"}
    assert "docs" in cfg["project"]["optional-dependencies"]


def test_docs_build_strict(tmp_path):
    """The API reference builds from the docstrings with warnings as errors (as .ci/run does)."""
    pytest.importorskip("mkdocstrings")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir",
                        str(tmp_path / "site")], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    html = (tmp_path / "site" / "api" / "shevsim" / "index.html").read_text()
    assert "overrides" in html and "simulate" in html


SCRIPT = """
import shevsim
res = shevsim.simulate("hd_udds_rule", overrides={"vehicle.mass_kg": 18000.0, "cycle.repeat": 1}, stop_s=120.0)
df = res.to_pandas()
print(shevsim.__file__)
print(res.termination, len(df), df.attrs["units"]["vehicle.speed_mps"], res.metrics["distance_km"] > 0.1)
"""


@pytest.mark.slow
def test_wheel_in_a_fresh_venv_runs_from_an_empty_folder(tmp_path):
    """Build the wheel, install it in a new virtual environment (dependencies from the system site), and from
    an empty folder run --version, a bundled scenario (one cycle) and the Python API.  The wheel carries the
    precompiled code (hatch_build.py, issue 26): its first run compiles nothing and the default scenario takes
    the fast path."""
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(tmp_path)],
                       capture_output=True, text=True, timeout=900,   # compiled with the numba the venv uses
                       env={**os.environ, "SHEVSIM_BUILD_PYTHON": sys.executable})
    assert r.returncode == 0, r.stderr
    wheel = glob.glob(str(tmp_path / "*.whl"))[0]
    names = zipfile.ZipFile(wheel).namelist()
    assert "shevsim/py.typed" in names and any(n.endswith("licenses/LICENSE") or n.endswith("/LICENSE")
                                               for n in names)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True, timeout=300)
    py, exe = venv / "bin" / "python", venv / "bin" / "shevsim"
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    work = tmp_path / "empty"
    work.mkdir()
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(tmp_path), "MPLBACKEND": "Agg"}

    def run(*args):
        out = subprocess.run(list(args), cwd=work, capture_output=True, text=True, timeout=900, env=env)
        assert out.returncode == 0, (args, out.stdout, out.stderr)
        return out.stdout
    assert run(str(exe), "--version").strip().startswith("shevsim ")
    man = json.loads(zipfile.ZipFile(wheel).read("shevsim/_jitcache/manifest.json"))
    assert man["indexes"] >= 50 and man["layouts"], man
    first = subprocess.run([str(exe), "run", "-s", "scenario.stop_s=60", "-o", "res0", "--no-plots"], cwd=work,
                           capture_output=True, text=True, timeout=900, env=env)
    assert first.returncode == 0, first.stderr
    assert "compiling" not in first.stderr and "engine fast" in first.stdout, (first.stdout, first.stderr)
    assert not [p for p in venv.rglob("*.nbi") if "_jitcache" not in p.parts]      # nothing written into the venv
    assert list((tmp_path / ".cache" / "shevsim" / "numba").rglob("*.nbi"))        # seeded into the user's cache
    run(str(exe), "run", "hd_udds_rule", "-s", "cycle.repeat=1", "-q", "-o", "res")
    assert (work / "res" / "timeseries.parquet").is_file() and (work / "res" / "overview.png").is_file()
    lines = run(str(py), "-c", SCRIPT).splitlines()
    assert lines[0].startswith(str(venv)), lines
    assert lines[1] == "completed 1201 m/s True"
    # a scenario saved by this checkout (Scenario.to_toml) runs in the other installation
    from shevsim.core.scenario import load_scenario
    (work / "saved.toml").write_text(load_scenario("hd_udds_rule").use(vehicle="city_bus").to_toml())
    run(str(exe), "run", str(work / "saved.toml"), "-s", "scenario.stop_s=30", "-q", "-o", "res2", "--no-plots")
    assert (work / "res2" / "timeseries.parquet").is_file()
