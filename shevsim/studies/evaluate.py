"""evaluate.py - one study evaluation: (scenario, parameter overrides) -> metrics, with a deterministic key.

An *evaluation item* is a small, picklable object with three methods:

``key() -> str``
    A deterministic SHA-256 hex digest of everything that decides the result: for a scenario
    evaluation the scenario file text, the contents of every parameter file it resolves (and of the
    data files those name or sit beside, e.g. map CSVs and the cycle CSV), the overrides, the stop
    time, the shevsim version and a hash of the shevsim package sources (:func:`code_version`).
    Change any of them and the cache (``cache.py``) no longer matches, so a stale result is never
    reused.
``inputs() -> dict``
    A JSON-serialisable description stored with the cached result.
``run() -> dict``
    Perform the evaluation and return a flat ``{name: float | str}`` dict of outputs. Outputs must
    depend on the inputs only (no wall time in them), so a parallel run equals a serial one.

:class:`Evaluation` is the real one: ``load_scenario`` + ``simulate`` + ``compute_run_metrics``
(nothing saved, no plots). Its outputs are the scalar scenario metrics (``fuel_economy_soc_sustained_kmpl``, the
SOC-sustainable definition of seed A.1, ``soot_g_per_km``, ... as computed by
``shevsim.metrics.compute_metrics``), ``termination`` and, on request, final values of signals
(``final:component.port``). A failing run (:class:`~shevsim.core.errors.ShevsimError` or any other
exception raised by the model) is returned as ``{"error": message}`` so one bad point does not end
a campaign; studies treat it as infeasible. Because the code version is in the key, a failure
caused by a bug is not reused once the code changes.

Worker processes must not oversubscribe the 2 cores with BLAS threads: :func:`limit_threads` sets
``OPENBLAS_NUM_THREADS``/``MKL_NUM_THREADS``/``OMP_NUM_THREADS``/... to 1 (the parallel runner also
passes them in the worker environment, where they take effect before NumPy loads).
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.tomlio import toml_value

THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
              "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}

_PKG_ROOT = Path(__file__).resolve().parents[1]          # .../shevsim
_MAX_HASH_BYTES = 64 * 1024 * 1024


def limit_threads() -> None:
    """Set the single-thread BLAS/OpenMP environment variables in this process (idempotent)."""
    for k, v in THREAD_ENV.items():
        os.environ[k] = v


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 of the shevsim package's Python sources (sorted relative paths + contents)."""
    h = hashlib.sha256()
    for p in sorted(_PKG_ROOT.rglob("*.py")):
        if "__pycache__" in p.parts:
            continue
        h.update(str(p.relative_to(_PKG_ROOT)).encode())
        h.update(b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def shevsim_version() -> str:
    from ..version import __version__
    return __version__


def _canonical(obj: Any) -> str:
    """Canonical JSON (sorted keys, floats by repr, inf/nan allowed) used for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=str)


def _hash_file(h, p: Path) -> None:
    h.update(str(p.name).encode())
    h.update(b"\0")
    try:
        if p.stat().st_size <= _MAX_HASH_BYTES:
            h.update(p.read_bytes())
        else:  # huge file: size and mtime stand in for the contents
            st = p.stat()
            h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
    except OSError as exc:
        h.update(f"unreadable:{exc}".encode())
    h.update(b"\0")


def _strings(obj) -> list[str]:
    if isinstance(obj, str):
        return [obj]
    if isinstance(obj, dict):
        return [s for v in obj.values() for s in _strings(v)]
    if isinstance(obj, list):
        return [s for v in obj for s in _strings(v)]
    return []


def _param_file_deps(pfile: Path) -> list[Path]:
    """A parameter file, the files beside it (maps) and the files its string values name (cycle CSV...)."""
    deps = {pfile.resolve()}
    for sib in pfile.parent.iterdir():
        if sib.is_file() and not sib.name.startswith(".") and sib.suffix.lower() in {".toml", ".csv", ".json", ".txt"}:
            deps.add(sib.resolve())
    try:
        doc = tomllib.loads(pfile.read_text())
    except (OSError, tomllib.TOMLDecodeError):
        doc = {}
    from ..core.scenario import PROJECT_ROOT
    for s in _strings(doc):
        if len(s) > 300 or "\n" in s or not any(c in s for c in "./"):
            continue
        for base in (pfile.parent, PROJECT_ROOT):
            cand = (base / s)
            try:
                if cand.is_file():
                    deps.add(cand.resolve())
                    break
            except OSError:
                pass
    return sorted(deps)


@functools.lru_cache(maxsize=64)
def _scenario_fingerprint_cached(path: str, text: str, mtimes: tuple) -> str:
    from ..core.scenario import load_scenario
    h = hashlib.sha256()
    h.update(text.encode())
    sc = load_scenario(Path(path), text=text)
    files: set[Path] = set()
    for spec in sc.components:
        if spec.params_file is not None:
            files.update(_param_file_deps(Path(spec.params_file)))
        if spec.fmu is not None and Path(spec.fmu).is_file():
            files.add(Path(spec.fmu).resolve())
    for f in sorted(files):
        _hash_file(h, f)
    return h.hexdigest()


def _dir_mtimes(path: Path, text: str) -> tuple:
    """Modification times of the component parameter folders (invalidate the fingerprint memo)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return ()
    from ..core.scenario import resolve_path
    out = []
    for cd in (doc.get("components") or {}).values():
        if isinstance(cd, dict) and isinstance(cd.get("params"), str):
            d = resolve_path(cd["params"], path).parent
            try:
                out.append((str(d), d.stat().st_mtime_ns, max((f.stat().st_mtime_ns for f in d.iterdir()), default=0)))
            except OSError:
                out.append((str(d), 0, 0))
    return tuple(out)


def scenario_fingerprint(path: str | Path, text: str | None = None) -> str:
    """SHA-256 of a scenario's text and of the parameter/data files it resolves.

    ``text`` defaults to the file's contents. Memoised per (path, text, parameter-folder mtimes).
    Raises :class:`~shevsim.core.errors.ScenarioError` for a malformed scenario.
    """
    p = Path(path).resolve()
    if text is None:
        text = p.read_text()
    return _scenario_fingerprint_cached(str(p), text, _dir_mtimes(p, text))


def _freeze(v):
    if isinstance(v, (list, tuple)):
        return tuple(_freeze(x) for x in v)
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):
        return v.item()
    return v


def _thaw(v):
    return [_thaw(x) for x in v] if isinstance(v, tuple) else v


@dataclass(frozen=True)
class Evaluation:
    """One scenario run with parameter overrides.

    Parameters
    ----------
    scenario : str
        Path of the scenario TOML file.
    overrides : tuple of (str, value)
        ``("component.param", value)`` pairs, sorted (use :meth:`make` to build from a dict).
    stop_s : float or None
        Override of the scenario's stop time (s); None keeps the scenario's.
    final_signals : tuple of str
        Signals (``component.port``) whose final value is returned as ``final:component.port``.
    text : str
        The scenario file's text, read once by :meth:`make`: the key hashes it and the run parses
        it, so editing the file during a study cannot make a cached result disagree with its key.
    engine : {'auto', 'python', 'fast'}
        Simulation engine (:func:`shevsim.run.simulate`): ``'auto'`` (default) runs the compiled
        whole-vehicle path (:mod:`shevsim.fast`) whenever the scenario is eligible - it gives the master's
        result bit for bit, so the engine is not part of the key.
    """

    scenario: str
    overrides: tuple = ()
    stop_s: float | None = None
    final_signals: tuple = ()
    text: str = field(default="", repr=False, compare=False)   # scenario text captured by make()
    engine: str = field(default="auto", compare=False)

    @classmethod
    def make(cls, scenario: str | Path, overrides: dict | None = None, stop_s: float | None = None,
             final_signals=(), engine: str = "auto") -> "Evaluation":
        ov = tuple(sorted((str(k), _freeze(v)) for k, v in (overrides or {}).items()))
        for k, _ in ov:
            if "." not in k:
                raise ValueError(f"override '{k}': expected 'component.param'")
        path = Path(scenario).resolve()
        try:
            text = path.read_text()
        except OSError as exc:
            from ..core.errors import ScenarioError
            raise ScenarioError(f"{scenario}: scenario file not readable: {exc}") from exc
        if engine not in ("auto", "python", "fast"):
            raise ValueError(f"engine must be 'auto', 'python' or 'fast', got {engine!r}")
        return cls(str(path), ov, None if stop_s is None else float(stop_s), tuple(final_signals), text, engine)

    def overrides_dict(self) -> dict:
        return {k: _thaw(v) for k, v in self.overrides}

    def sets(self) -> list[str]:
        """The overrides as ``load_scenario`` ``component.param=value`` strings (values in TOML)."""
        return [f"{k}={toml_value(_thaw(v))}" for k, v in self.overrides]

    def inputs(self) -> dict:
        return {"kind": "scenario", "scenario": self.scenario, "overrides": self.overrides_dict(),
                "stop_s": self.stop_s, "final_signals": list(self.final_signals)}

    def key(self) -> str:
        payload = {"inputs": {**self.inputs(), "scenario": Path(self.scenario).name},
                   "scenario_sha256": scenario_fingerprint(self.scenario, self.text or None),
                   "shevsim_version": shevsim_version(), "code_sha256": code_version()}
        return hashlib.sha256(_canonical(payload).encode()).hexdigest()

    def run(self) -> dict:
        limit_threads()
        from ..core.scenario import load_scenario
        from ..run import compute_run_metrics, simulate
        try:
            sc = load_scenario(self.scenario, self.sets(), text=self.text or None)
            if self.stop_s is not None:
                sc.stop_s = self.stop_s
            res = simulate(sc, progress=False, engine=self.engine)
            out: dict[str, Any] = {"termination": str(res.termination)}
            for k, v in compute_run_metrics(res, sc).items():
                if isinstance(v, bool):
                    out[k] = float(v)
                elif isinstance(v, (int, float)) or hasattr(v, "item") and getattr(v, "ndim", 0) == 0:
                    out[k] = float(v)
            for s in self.final_signals:
                out[f"final:{s}"] = float(res[s][-1])
            return out
        except Exception as exc:  # noqa: BLE001 - a failing point is a result (infeasible), not a crash
            return {"error": f"{type(exc).__name__}: {exc}"}


def warm_up_fast_path() -> str:
    """Load the compiled whole-vehicle loop in this process (from numba's on-disk cache, or compile it
    once) so that a worker's first evaluation does not pay for it; returns "" or why it is unavailable."""
    limit_threads()
    try:
        from ..core.paths import bundled_scenario
        from ..core.scenario import load_scenario
        from ..fast import runner_for
        why = ""
        for name in ("hd_udds_mpc", "hd_udds_rule"):      # the MPC one also loads the DAQP binding's calls
            sc = load_scenario(bundled_scenario(name), ["cycle.repeat=1"])
            run, why = runner_for(sc)
            if run is not None:
                run(2 * sc.settings.step_s)
                return ""
        return why
    except Exception as exc:  # noqa: BLE001 - a warm-up must never stop a study
        return f"{type(exc).__name__}: {exc}"


def run_item(item) -> tuple[dict, float, str]:
    """Worker entry point: run one evaluation item; return (outputs, wall time in s, worker code version).

    The code version lets the client refuse to cache a result computed by a worker whose shevsim
    sources differ from the ones the key was made with (e.g. files edited while a study runs).
    """
    limit_threads()
    t0 = time.perf_counter()
    out = item.run()
    return out, time.perf_counter() - t0, code_version()


def failure_reason(outputs: dict, *keys: str) -> str:
    """Why an evaluation is unusable ("" when it is fine): its error, its termination, or a missing metric."""
    if "error" in outputs:
        return str(outputs["error"])
    term = outputs.get("termination", "completed")
    if term not in ("completed", None):
        return f"run ended: {term}"
    for k in keys:
        v = outputs.get(k)
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            return f"metric '{k}' missing or not finite ({v!r})"
    return ""


def is_failed(outputs: dict, *keys: str) -> bool:
    """True when an evaluation failed or lacks a finite value for one of ``keys``."""
    return bool(failure_reason(outputs, *keys))
