"""results.py - one result object per run, and atomic saving under results/<scenario>/.

Column names are ``component.port`` and every port name carries its unit as a
suffix (``battery.current_a``, ``vehicle.speed_mps``); the unit strings are kept
beside them in ``units`` and written into the saved metadata.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import write_json_atomic  # the one atomic JSON writer (re-exported)
from .errors import ShevsimError


@dataclass
class Result:
    """Time plus named signals of one run.

    Attributes
    ----------
    time_s : ndarray
        Communication points (s).
    signals : dict of str -> ndarray
        ``'component.port'`` -> values at each communication point.
    units : dict of str -> str
    parameters : dict
        Component name -> parameter values used.
    termination : str
        Why the run ended (``'completed'`` or the error).
    meta : dict
        Scenario name, seed, version, git commit, wall time...
    """

    time_s: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str]
    parameters: dict[str, Any]
    termination: str = "completed"
    meta: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[name]
        except KeyError:
            import difflib
            best = difflib.get_close_matches(name, list(self.signals), n=3)
            raise KeyError(f"no signal '{name}' in the result; close: {best}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.signals

    def to_pandas(self, signals: list[str] | None = None):
        """DataFrame with ``time_s`` and one column per signal (``component.port``)."""
        import pandas as pd
        names = list(self.signals) if signals is None else signals
        data = {"time_s": self.time_s}
        for n in names:
            data[n] = self[n]
        return pd.DataFrame(data)

    def plot(self, signals: list[str], ax=None):
        """Plot signals against time; returns the matplotlib axes."""
        import matplotlib.pyplot as plt      # the caller's backend (headless: Agg by default)
        if ax is None:
            _, ax = plt.subplots(figsize=(8, 3))
        for n in signals:
            ax.plot(self.time_s, self[n], label=f"{n} [{self.units.get(n, '')}]")
        ax.set_xlabel("time [s]")
        ax.legend(fontsize=7)
        ax.grid(True, alpha=0.3)
        return ax


def git_commit(path: Path | None = None) -> str:
    """Current git commit of the source tree, or 'unknown'."""
    try:
        here = Path(path or Path(__file__).resolve().parent)
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        if out.returncode == 0:
            dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                                   capture_output=True, text=True, timeout=5).stdout.strip()
            return out.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return "unknown"



def save_result(result: Result, out_dir: str | Path, *, scenario_text: str | None = None,
                metrics: dict | None = None, plots=None, fmt: str = "parquet") -> Path:
    """Write a run to ``out_dir`` atomically.

    Everything is written into a temporary sibling folder which then replaces
    ``out_dir`` in one rename, so a crash never leaves a half-written result.
    ``plots`` is an optional callable ``plots(result, folder)`` that writes figures.
    """
    out_dir = Path(out_dir)
    # the folder is replaced as a whole: never a file, nor a folder that holds something else
    if out_dir.exists() or out_dir.is_symlink():
        if not out_dir.is_dir():
            raise ShevsimError(f"output folder '{out_dir}' exists and is not a folder: not replaced")
        if any(out_dir.iterdir()) and not (out_dir / "run.json").is_file():
            raise ShevsimError(f"output folder '{out_dir}' is not empty and not a shevsim result "
                               f"(no run.json): not replaced; choose another --out")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.tmp-"))
    try:
        df = result.to_pandas()
        if fmt == "parquet":
            try:
                df.to_parquet(tmp / "timeseries.parquet", index=False)
            except ImportError:
                fmt = "csv"
        if fmt == "csv":
            df.to_csv(tmp / "timeseries.csv", index=False, float_format="%.9g")
        from .. import __version__
        meta = dict(result.meta)
        meta.update({"termination": result.termination, "version": __version__,
                     "git_commit": meta.get("git_commit") or git_commit(),
                     "units": {"time_s": "s", **result.units}, "parameters": result.parameters,
                     "timeseries": f"timeseries.{fmt}"})
        write_json_atomic(tmp / "run.json", meta)
        write_json_atomic(tmp / "metrics.json", metrics or {})
        if scenario_text is not None:
            (tmp / "scenario.toml").write_text(scenario_text)
        if plots is not None:
            plots(result, tmp)
        umask = os.umask(0)                  # mkdtemp made the folder 0700: give it the usual permissions
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)
        old = None
        if out_dir.exists():
            old = out_dir.with_name(f".{out_dir.name}.old-{os.getpid()}")
            os.replace(out_dir, old)
        os.replace(tmp, out_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def load_result(out_dir: str | Path) -> Result:
    """Read a saved run back."""
    import pandas as pd
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / "run.json").read_text())
    path = out_dir / meta["timeseries"]
    df = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    t = df.pop("time_s").to_numpy()
    units = meta.pop("units")
    units.pop("time_s", None)
    return Result(t, {c: df[c].to_numpy() for c in df.columns}, units, meta.pop("parameters"),
                  meta.pop("termination"), meta)
