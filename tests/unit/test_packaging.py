"""An installed shevsim finds its bundled data: the wheel carries components/, cycles/, scenarios/, fmus/
inside the package (shevsim/_data, pyproject force-include) and shevsim.core.paths finds them there."""
from __future__ import annotations

import glob
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("components", "cycles", "scenarios", "fmus")


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
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    names = zipfile.ZipFile(glob.glob(str(tmp_path / "*.whl"))[0]).namelist()
    for f in FOLDERS[:3]:
        assert any(n.startswith(f"shevsim/_data/{f}/") for n in names), f
    assert "shevsim/_data/scenarios/hd_udds_mpc.toml" in names
    assert sum(n.endswith(".csv") for n in names) >= 20 and sum(n.endswith(".toml") for n in names) >= 15
