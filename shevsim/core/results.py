"""results.py - one result object per run, and atomic saving under results/<scenario>/.

Column names are ``component.port`` and every port name carries its unit as a
suffix (``battery.current_a``, ``vehicle.speed_mps``); the unit strings are kept
beside them in ``units`` and written into the saved metadata.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .atomic import file_sha256, write_json_atomic  # the one atomic JSON writer (re-exported)
from .errors import OutputError, ShevsimError, os_error_text


class Termination(str):
    """Why a run ended: a string (``"completed"``, ``"stopped: <reason>"``, ``"degraded: <reason>"``)
    that also carries the details as attributes.

    Attributes
    ----------
    status : {'completed', 'stopped', 'degraded'}
        ``stopped``: the run ended before its stop time (non-finite value, plant limit, component or
        FMU failure, interruption) and the result holds what was simulated up to then;
        ``degraded``: the run reached its stop time but did not do what the scenario asked (trace miss).
    reason : str
        The error message or the failed check ('' when completed).
    component, port : str or None
        Where it happened, when known.
    time_s : float or None
        Simulation time of the stop, when known.
    """

    STATUSES = ("completed", "stopped", "degraded")

    def __new__(cls, status: str = "completed", reason: str = "", component: str | None = None,
                port: str | None = None, time_s: float | None = None):
        if status not in cls.STATUSES:
            raise ValueError(f"termination status must be one of {cls.STATUSES}, got {status!r}")
        obj = super().__new__(cls, status if not reason else f"{status}: {reason}")
        obj.status, obj.reason, obj.component, obj.port = status, str(reason), component, port
        obj.time_s = None if time_s is None else float(time_s)
        return obj

    def __reduce__(self):
        return (Termination, (self.status, self.reason, self.component, self.port, self.time_s))

    @property
    def ok(self) -> bool:
        """True when the run completed."""
        return self.status == "completed"

    def to_dict(self) -> dict:
        """Plain-dict form (saved in ``run.json`` as ``termination_detail``)."""
        return {"status": self.status, "reason": self.reason, "component": self.component,
                "port": self.port, "time_s": self.time_s}

    @classmethod
    def coerce(cls, value: Any, detail: dict | None = None) -> "Termination":
        """A [`Termination`][shevsim.core.results.Termination] from itself, a detail dict or an old-style string
        (``"completed"``, ``"error: ..."``)."""
        if isinstance(value, Termination):
            return value
        if isinstance(detail, dict) and detail.get("status") in cls.STATUSES:
            return cls(detail["status"], detail.get("reason") or "", detail.get("component"),
                       detail.get("port"), detail.get("time_s"))
        text = str(value)
        if text == "completed":
            return cls()
        for st in ("stopped", "degraded"):
            if text.startswith(st + ": "):
                return cls(st, text[len(st) + 2:])
        return cls("stopped", text[7:] if text.startswith("error: ") else text)


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
        ``'component.port'`` -> unit string (``'m/s'``, ``'W'``, ``'%'``).
    parameters : dict
        Component name -> parameter values used.
    termination : Termination
        Why the run ended: compares equal to ``'completed'`` when it did; otherwise
        ``.status`` ('stopped' / 'degraded'), ``.reason``, ``.component``, ``.port``, ``.time_s``.
    meta : dict
        Scenario name, seed, version, git commit, wall time, engine...
    """

    time_s: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str]
    parameters: dict[str, Any]
    termination: Termination | str = "completed"
    meta: dict[str, Any] = field(default_factory=dict)
    _metrics: dict | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        self.termination = Termination.coerce(self.termination)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[name]
        except KeyError:
            import difflib
            best = difflib.get_close_matches(name, list(self.signals), n=3)
            raise KeyError(f"no signal '{name}' in the result; close: {best}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.signals

    def __len__(self) -> int:
        return len(self.time_s)

    def to_pandas(self, signals: list[str] | None = None):
        """DataFrame with ``time_s`` and one column per signal (``component.port``).

        The unit of every column is in ``df.attrs["units"]`` (``{"time_s": "s", ...}``).
        """
        import pandas as pd
        names = list(self.signals) if signals is None else list(signals)
        data = {"time_s": self.time_s}
        for n in names:
            data[n] = self[n]
        df = pd.DataFrame(data)
        df.attrs["units"] = {"time_s": "s", **{n: self.units.get(n, "") for n in names}}
        return df

    @property
    def metrics(self) -> dict:
        """Scenario metrics ([`shevsim.metrics.compute_metrics()`][shevsim.metrics.compute_metrics], registered with
        `shevsim.core.registry`; a metric that cannot be computed is None and explained in
        ``metrics["notes"]``). Computed on first access."""
        if self._metrics is None:
            from .registry import result_metrics
            self._metrics = result_metrics(self)
        return self._metrics

    @metrics.setter
    def metrics(self, value: dict) -> None:
        self._metrics = dict(value)

    def __repr__(self) -> str:
        t = self.time_s
        span = f"{t[0]:g}-{t[-1]:g} s, {len(t)} points" if len(t) else "no points"
        return (f"<Result {self.meta.get('scenario', 'run')!r}: {str(self.termination)[:80]!r}, {span}, "
                f"{len(self.signals)} signals, engine {self.meta.get('engine', '?')!r}>")

    def _repr_html_(self) -> str | None:
        from .registry import html_view
        return html_view("result", self)

    #: what ``plot()`` shows when no signals are named (those of them the run has)
    DEFAULT_PLOT = ("cycle.speed_ref_mps", "vehicle.speed_mps", "engine_generator.elec_power_w",
                    "bus.battery_power_w", "battery.soc_pct", "battery.t_core_c")

    def plot(self, signals: list[str] | str | None = None, ax=None):
        """Plot signals against time, one axis per display unit (kW, km/h, degC: values scaled from SI).

        Parameters
        ----------
        signals : list of str, optional
            ``component.port`` names (default: speed, power split, SOC and cell temperature when the
            run has them, else its first six signals).
        ax : matplotlib Axes or sequence of Axes, optional
            Where to draw (one per unit); new figure when omitted.

        Returns
        -------
        matplotlib.figure.Figure
            Its axes (``fig.axes``) are one per unit, in order of first appearance.
        """
        from .registry import plot_function
        plot_signals = plot_function("signals")
        if isinstance(signals, str):
            signals = [signals]
        if signals is None:
            signals = [s for s in self.DEFAULT_PLOT if s in self.signals] or list(self.signals)[:6]
        return plot_signals([self], list(signals), ax=ax)

    def save(self, out_dir: str | Path, *, plots: bool = False, fmt: str = "parquet") -> Path:
        """Save the run (timeseries with units, ``run.json``, ``metrics.json``) to ``out_dir``.

        Only the files shevsim writes are replaced in an earlier result folder; a folder holding
        other files and no ``run.json`` is refused.
        """
        plot_fn = None
        if plots:
            from .registry import plot_function
            plot_fn = plot_function("scenario")
        return save_result(self, out_dir, scenario_text=self.meta.get("scenario_text"), metrics=self.metrics,
                           plots=plot_fn, fmt=fmt)


def _flat_params(params: Mapping[str, Any]) -> dict[str, str]:
    import json
    out = {}
    for comp, p in (params or {}).items():
        if isinstance(p, Mapping):
            for k, v in p.items():
                out[f"{comp}.{k}"] = json.dumps(v, sort_keys=True, default=str)
        else:
            out[str(comp)] = json.dumps(p, sort_keys=True, default=str)
    return out


def run_labels(results: Sequence[Result], fallback: Sequence[str] | None = None) -> list[str]:
    """One distinct label per result: ``res.meta["label"]`` when set, else the scenario name; runs of the same
    name are told apart by the parameters in which they differ (``hd_udds_mpc (vehicle.mass_kg=18000)``),
    else by ``fallback`` (e.g. their folder names), else numbered (``#2``)."""
    import json
    results = list(results)
    base = []
    for i, r in enumerate(results):
        lab = r.meta.get("label") or r.meta.get("scenario") or (fallback[i] if fallback else None) or f"run {i + 1}"
        base.append(str(lab))
    out = list(base)
    for name in set(base):
        group = [i for i, b in enumerate(base) if b == name]
        if len(group) < 2:
            continue
        flat = [_flat_params(results[i].parameters) for i in group]
        keys = sorted(set().union(*flat))
        differ = [k for k in keys if len({f.get(k) for f in flat}) > 1]
        for j, i in enumerate(group):
            parts = []
            for k in differ[:2]:
                v = flat[j].get(k)
                v = "unset" if v is None else json.loads(v)
                parts.append(f"{k}={v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{k}={v}")
            if parts:
                out[i] = f"{name} ({', '.join(parts)}{', ...' if len(differ) > 2 else ''})"
            elif fallback and len({fallback[g] for g in group}) == len(group):
                out[i] = f"{name} ({fallback[i]})"
            else:
                out[i] = f"{name} #{j + 1}"
    counts = {lab: out.count(lab) for lab in out}
    seen: dict[str, int] = {}
    for i, lab in enumerate(out):            # still equal (the same differences shown): number them
        if counts[lab] > 1:
            seen[lab] = seen.get(lab, 0) + 1
            out[i] = f"{lab} #{seen[lab]}"
    return out


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



#: files a run writes into its folder (older results have no manifest in run.json: these are taken as ours)
_OWN_FILES = ("timeseries.parquet", "timeseries.csv", "run.json", "metrics.json", "scenario.toml", "overview.png",
              "report.html")
#: besides those, figures a run may write (``scenario_plots``): plain lower-case names ending in .png
_OWN_FIGURE = re.compile(r"^[a-z0-9_]{1,64}\.png$")


def _own_name(name: Any) -> bool:
    """True for a plain file name shevsim writes into a result folder (no folder part, no dot file)."""
    return isinstance(name, str) and (name in _OWN_FILES or bool(_OWN_FIGURE.match(name)))


def _earlier_manifest(out_dir: Path) -> dict[str, str | None] | None:
    """The files of an earlier result in ``out_dir`` that shevsim may replace or remove, verified.

    ``{name: sha256 or None}`` from its ``run.json``; None when ``run.json`` is missing or not a shevsim
    record (then nothing in the folder is ours). An entry is kept only when it is a plain name shevsim
    writes (`_OWN_FILES`, figures ``*.png``); a ``run.json`` written since the content hashes were
    recorded (key ``sha256``) lists each file with its hash, and an older one (no hashes) only the
    fixed names of `_OWN_FILES` (hash None: taken as ours by name)."""
    try:
        meta = json.loads((out_dir / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError, RecursionError):
        return None
    if not isinstance(meta, dict) or "termination" not in meta or "timeseries" not in meta:
        return None
    hashes = meta.get("sha256")
    listed = meta.get("files")
    if not isinstance(listed, list):
        listed = list(_OWN_FILES)
    out: dict[str, str | None] = {}
    for name in listed:
        if not _own_name(name) or name == "run.json":
            continue
        if isinstance(hashes, dict):
            h = hashes.get(name)
            if isinstance(h, str) and re.fullmatch(r"[0-9a-f]{64}", h):
                out[name] = h
        elif name in _OWN_FILES:
            out[name] = None
    return out


#: the generator mark of a report shevsim wrote (shevsim.report.write._MARK)
_REPORT_MARK = '<meta name="generator" content="shevsim'


def _is_ours(out_dir: Path, name: str, manifest: dict[str, str | None] | None) -> bool:
    """True when ``out_dir/name`` is a regular file an earlier run wrote and nobody changed since
    (its content hash is the one recorded in run.json)."""
    if manifest is None or name not in manifest:
        return False
    q = out_dir / name
    if q.is_symlink() or not q.is_file():
        return False
    want = manifest[name]
    if want is None:
        return True
    try:
        if file_sha256(q) == want:
            return True
        # `shevsim report DIR` rewrites report.html after the run: ours when it carries the report's own
        # generator mark (the check shevsim.report.write makes before replacing it)
        return name == "report.html" and _REPORT_MARK in q.read_text(errors="replace")[:4000]
    except OSError:
        return False


def _conflicts(out_dir: Path, names, manifest) -> list[str]:
    """Names a new result would write over in ``out_dir`` that are not verified as an earlier run's."""
    bad = []
    for name in names:
        q = out_dir / name
        if name == "run.json":
            if q.exists() and manifest is None:
                bad.append(name)
        elif (q.exists() or q.is_symlink()) and not _is_ours(out_dir, name, manifest):
            bad.append(name)
    return bad


def check_out_dir(out_dir: str | Path) -> Path:
    """Check, before anything runs, that ``out_dir`` can take a result; return it.

    Refused with `ShevsimError`: an existing file (or anything that is not a folder), a folder
    that holds files but no shevsim ``run.json`` (not a shevsim result: nothing a user wrote is touched),
    a result folder where a file the run would write is not the one shevsim wrote there (changed since,
    or added by the user: its content hash differs from the one in run.json), a place that cannot be
    created or written.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() or out_dir.is_symlink():
        if not out_dir.is_dir():
            raise ShevsimError(f"output folder '{out_dir}' exists and is not a folder: not replaced; "
                               f"choose another --out")
        others = [p for p in out_dir.iterdir() if not p.name.startswith(f".{out_dir.name}.")]
        manifest = _earlier_manifest(out_dir) if (out_dir / "run.json").is_file() else None
        if others and manifest is None:
            why = "its run.json is not a shevsim run record" if (out_dir / "run.json").exists() else "no run.json"
            raise ShevsimError(f"output folder '{out_dir}' is not empty and not a shevsim result ({why}): "
                               f"not replaced; choose another --out")
        if manifest is not None:
            bad = _conflicts(out_dir, [n for n in _OWN_FILES if n != "run.json"], manifest)
            if bad:
                raise ShevsimError(f"output folder '{out_dir}': {', '.join(bad)} "
                                   f"{'is' if len(bad) == 1 else 'are'} not the file(s) shevsim wrote there "
                                   f"(changed or added since: the content differs from the hash in run.json): "
                                   f"not replaced; move {'it' if len(bad) == 1 else 'them'} away or choose "
                                   f"another --out")
    parent = out_dir.absolute().parent
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ShevsimError(f"output folder '{out_dir}': '{probe}' is a file, so the folder cannot be created")
    try:                                 # a real write test (permission bits lie for root and on some mounts),
        # in the nearest folder that exists: nothing is created before the run
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=f".{out_dir.name}.probe-")
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise ShevsimError(f"output folder '{out_dir}' is not writable: {exc.strerror or exc}") from None
    return out_dir


def holds_result(out_dir: str | Path) -> bool:
    """True when ``out_dir`` holds an earlier shevsim result (a run.json shevsim wrote)."""
    out_dir = Path(out_dir)
    return out_dir.is_dir() and (out_dir / "run.json").is_file() and _earlier_manifest(out_dir) is not None


def beside_folder(out_dir: str | Path, tag: str) -> Path:
    """A new folder name beside ``out_dir`` for a result that must not replace the one in it:
    ``NAME-TAG-YYYYmmddTHHMMSSZ`` (``-2``, ``-3``... when taken)."""
    import time as _t
    out_dir = Path(out_dir)
    stamp = _t.strftime("%Y%m%dT%H%M%SZ", _t.gmtime())
    base = out_dir.with_name(f"{out_dir.name}-{tag}-{stamp}")
    cand, i = base, 1
    while cand.exists() or cand.is_symlink():
        i += 1
        cand = base.with_name(f"{base.name}-{i}")
    return cand


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def clean_stale_temp(out_dir: str | Path) -> list[Path]:
    """Remove the temporary folders that killed runs left beside ``out_dir``
    (``.NAME.tmp-p<pid>-*`` of a process that no longer runs; older unnamed ones after an hour)."""
    import re
    import time as _t
    out_dir = Path(out_dir)
    parent = out_dir.parent
    removed = []
    if not parent.is_dir():
        return removed
    pat = re.compile(rf"^\.{re.escape(out_dir.name)}\.(?:tmp-p(\d+)-[^/]+|old-(\d+)|tmp-[a-z0-9_]{{8}})$")
    for p in parent.iterdir():
        m = pat.match(p.name)
        if not m or not p.is_dir() or p.is_symlink():
            continue
        pid = m.group(1) or m.group(2)
        stale = (not _pid_alive(int(pid))) if pid else (_t.time() - p.stat().st_mtime > 3600)
        if stale:
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


#: formats of the saved trajectory (``shevsim run --format``)
TIMESERIES_FORMATS = ("parquet", "csv", "mat")


def _mat_name(name: str) -> str:
    """A MATLAB variable/field name for a signal or port name (letters, digits, ``_``; starts with a letter)."""
    import re
    out = re.sub(r"\W", "_", name).strip("_") or "x"
    return out if out[0].isalpha() else f"x_{out}"


def write_mat(result: Result, path: Path) -> None:
    """A MATLAB file: ``time_s``, one struct per component with its signals (``vehicle.speed_mps`` ->
    ``vehicle.speed_mps``; other characters become ``_``), ``units`` (the same structs holding unit strings),
    ``signal_names`` (the original names, in column order) and ``termination``."""
    from scipy.io import savemat
    data: dict = {"time_s": np.asarray(result.time_s, float)}
    units: dict = {"time_s": "s"}
    for name, values in result.signals.items():
        comp, _, port = name.partition(".")
        c, q = _mat_name(comp), _mat_name(port or comp)
        if c in ("time_s", "units", "signal_names", "termination"):
            c = f"{c}_"
        data.setdefault(c, {})[q] = np.asarray(values, float)
        units.setdefault(c, {})[q] = result.units.get(name, "")
    data["units"] = units
    data["signal_names"] = np.array(list(result.signals), dtype=object)
    data["termination"] = str(result.termination)
    savemat(str(path), data, do_compression=True, long_field_names=True)


def _read_mat(path: Path):
    import pandas as pd
    from scipy.io import loadmat
    m = loadmat(str(path), squeeze_me=True, struct_as_record=False)
    signal_names = [str(x) for x in np.atleast_1d(m["signal_names"])] if np.size(m["signal_names"]) else []
    cols = {"time_s": np.atleast_1d(np.asarray(m["time_s"], float))}
    for name in signal_names:
        comp, _, port = name.partition(".")
        c = _mat_name(comp)
        c = f"{c}_" if c in ("time_s", "units", "signal_names", "termination") else c
        cols[name] = np.atleast_1d(np.asarray(getattr(m[c], _mat_name(port or comp)), float))
    return pd.DataFrame(cols)


def write_timeseries(result: Result, folder: Path, fmt: str = "parquet") -> str:
    """Write ``timeseries.parquet`` (units as field metadata ``unit`` and schema metadata
    ``shevsim.units``), ``timeseries.csv`` or ``timeseries.mat`` (`write_mat()`); return the file name."""
    if fmt not in TIMESERIES_FORMATS:
        raise ValueError(f"format must be one of {', '.join(TIMESERIES_FORMATS)}, got {fmt!r}")
    if fmt == "mat":
        write_mat(result, folder / "timeseries.mat")
        return "timeseries.mat"
    units = {"time_s": "s", **{k: result.units.get(k, "") for k in result.signals}}
    if fmt == "parquet":
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            fmt = "csv"
        else:
            # straight from the arrays (no DataFrame copy: a long interrupted run is saved quickly)
            cols = {"time_s": np.asarray(result.time_s), **{k: np.asarray(v) for k, v in result.signals.items()}}
            arrays = [pa.array(v) for v in cols.values()]
            fields = [pa.field(k, a.type, metadata={"unit": units.get(k, "")}) for k, a in zip(cols, arrays)]
            schema = pa.schema(fields, metadata={"shevsim.units": json.dumps(units),
                                                 "shevsim.termination": str(result.termination)})
            # through a Python file object: a path with non-ASCII bytes under an ASCII locale (surrogate-
            # escaped) is passed to the OS as it came, where pyarrow's own path handling cannot encode it
            with open(folder / "timeseries.parquet", "wb") as f:
                pq.write_table(pa.Table.from_arrays(arrays, schema=schema), f)
            return "timeseries.parquet"
    df = result.to_pandas()
    df.to_csv(folder / "timeseries.csv", index=False, float_format="%.9g")
    return "timeseries.csv"


def save_result(result: Result, out_dir: str | Path, *, scenario_text: str | None = None,
                metrics: dict | None = None, plots=None, fmt: str = "parquet") -> Path:
    """Write a run to ``out_dir``.

    Everything is written into a temporary sibling folder first (the trajectory before anything
    else), then moved into place: a new folder in one rename; an earlier result folder file by file,
    replacing only the files shevsim wrote there - each listed in its ``run.json`` with the SHA-256 of
    its content recorded when written, and checked again before it is replaced or removed; anything else
    (files a user added or changed) stays. ``plots`` is an optional callable ``plots(result, folder)``
    that writes figures; when it fails, the run is saved without them and the error is raised afterwards
    (with a note). A write the machine refuses (full disk, file-size limit) raises `OutputError`
    naming the file and the limit; the earlier result is then untouched and nothing half-written stays.
    """
    out_dir = check_out_dir(out_dir)
    clean_stale_temp(out_dir)
    plot_error = None
    tmp = None
    current = "the result folder"
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.tmp-p{os.getpid()}-"))
        current = "timeseries.parquet" if fmt == "parquet" else "timeseries.csv"
        ts = write_timeseries(result, tmp, fmt)          # the trajectory first
        from ..version import __version__
        meta = dict(result.meta)
        meta.pop("scenario_text", None)
        term = Termination.coerce(result.termination)
        meta.update({"termination": str(term), "termination_detail": term.to_dict(), "version": __version__,
                     "git_commit": meta.get("git_commit") or git_commit(),
                     "units": {"time_s": "s", **result.units}, "parameters": result.parameters,
                     "timeseries": ts})
        files = [ts, "run.json", "metrics.json"]
        meta["files"] = files
        current = "run.json"
        write_json_atomic(tmp / "run.json", meta)
        current = "metrics.json"
        write_json_atomic(tmp / "metrics.json", metrics or {})
        if scenario_text is not None:
            current = "scenario.toml"
            (tmp / "scenario.toml").write_text(scenario_text, encoding="utf-8")
            files.append("scenario.toml")
        if plots is not None:
            before = set(os.listdir(tmp))
            current = "the figures"
            try:
                plots(result, tmp)
            except Exception as exc:    # noqa: BLE001 - the run is saved without figures, then the error raised
                plot_error = exc
                for name in set(os.listdir(tmp)) - before:      # half-written figures are dropped
                    q = tmp / name
                    shutil.rmtree(q) if q.is_dir() else q.unlink()
                meta["plot_error"] = f"{type(exc).__name__}: {exc}"
        files[:] = sorted(n for n in os.listdir(tmp) if _own_name(n) and (tmp / n).is_file())
        meta["files"] = files
        # the content hash of each file as written: checked before a later run replaces or removes it
        meta["sha256"] = {n: file_sha256(tmp / n) for n in files if n != "run.json"}
        current = "run.json"
        write_json_atomic(tmp / "run.json", meta)
        umask = os.umask(0)                  # mkdtemp made the folder 0700: give it the usual permissions
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)
        current = "the result folder"
        _publish(tmp, out_dir, files)
    except OSError as exc:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"could not save the result in '{out_dir}' ({current}): {os_error_text(exc)}. "
                          f"Nothing was changed in '{out_dir}' (no half-written file is left)") from None
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    if plot_error is not None:
        plot_error.add_note(f"the run was saved in {out_dir} without figures")
        raise plot_error
    return out_dir


def _publish(tmp: Path, out_dir: Path, files: list[str]) -> None:
    """Move the files of ``tmp`` into ``out_dir``; replace or remove only files an earlier run wrote
    there and nobody changed since (verified by name and content hash, `_earlier_manifest()`)."""
    if not out_dir.exists() and not out_dir.is_symlink():
        os.replace(tmp, out_dir)
        return
    manifest = _earlier_manifest(out_dir) if (out_dir / "run.json").is_file() else None
    bad = _conflicts(out_dir, files, manifest)
    if bad:                   # changed since check_out_dir: nothing in out_dir is touched
        raise ShevsimError(f"output folder '{out_dir}': {', '.join(bad)} changed while the run was going "
                           f"(not the file(s) shevsim wrote there): not replaced; the result is not saved, "
                           f"choose another --out")
    stale = [n for n in (manifest or {}) if n not in files and _is_ours(out_dir, n, manifest)]
    for name in [f for f in files if f != "run.json"] + ["run.json"]:   # run.json last: it lists the others
        os.replace(tmp / name, out_dir / name)
    for name in stale:                  # an earlier run's file this run did not write (e.g. its figure)
        try:
            (out_dir / name).unlink()
        except OSError:
            pass
    shutil.rmtree(tmp, ignore_errors=True)


def load_result(out_dir: str | Path) -> Result:
    """Read a saved run back."""
    import pandas as pd
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / "run.json").read_text(encoding="utf-8"))
    path = out_dir / meta["timeseries"]
    if path.suffix == ".mat":
        df = _read_mat(path)
    else:
        with open(path, "rb") as f:          # a file object: any path the OS takes (see write_timeseries)
            df = pd.read_parquet(f) if path.suffix == ".parquet" else pd.read_csv(f)
    t = df.pop("time_s").to_numpy()
    units = meta.pop("units")
    units.pop("time_s", None)
    detail = meta.pop("termination_detail", None)
    term = Termination.coerce(meta.pop("termination"), detail)
    meta.pop("files", None)
    res = Result(t, {c: df[c].to_numpy() for c in df.columns}, units, meta.pop("parameters"), term, meta)
    mpath = out_dir / "metrics.json"
    if mpath.is_file():
        res.metrics = json.loads(mpath.read_text(encoding="utf-8"))
    return res
