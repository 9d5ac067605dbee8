"""evaluate.py - one study evaluation: (scenario, parameter overrides) -> metrics, with a deterministic key.

An *evaluation item* is a small, picklable object with three methods:

``key() -> str``
    A deterministic SHA-256 hex digest of everything that decides the result: for a scenario
    evaluation the scenario as captured on the client (:mod:`.bundle`: its settings, components,
    parameter tables, overrides and connections, with every referenced file - parameter sets, maps,
    cycles, cell tables, FMUs, overlays - by the SHA-256 of its bytes, never by its path), the stop
    time, the shevsim version and a hash of the shevsim package sources and bundled data files (:func:`code_version`).
    Change any of them and the cache (``cache.py``) no longer matches, so a stale result is never
    reused; move the files to another machine and the key stays the same.
``inputs() -> dict``
    A JSON-serialisable description stored with the cached result.
``payload() -> (run, blobs)`` (scenario evaluations)
    What a worker runs (:class:`ScenarioRun`: the captured scenario, files as tokens) and the files'
    bytes by hash; the parallel runner ships the bytes once per worker (``parallel.py``).
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

Worker processes must not oversubscribe the cores with BLAS threads: ``OPENBLAS_NUM_THREADS``/
``MKL_NUM_THREADS``/``OMP_NUM_THREADS``/... (:data:`THREAD_ENV`) must be 1 when a worker process starts,
before NumPy loads its BLAS: the embedded cluster passes them in its workers' environment; workers of an
existing cluster must be started with them (docs/cluster.md).  :func:`limit_threads` sets them in the
running process too, which reaches only what reads them later (child processes, libraries not yet loaded),
not a BLAS that is already loaded.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.tomlio import toml_value

THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
              "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}

_PKG_ROOT = Path(__file__).resolve().parents[1]          # .../shevsim


def limit_threads() -> None:
    """Set the single-thread BLAS/OpenMP environment variables in this process (idempotent).  This reaches
    only what reads them afterwards (child processes, a library not yet loaded): a BLAS that NumPy has already
    loaded keeps its thread count, so a worker must have them in its environment when it starts."""
    for k, v in THREAD_ENV.items():
        os.environ[k] = v


#: the bundled data folders (under :data:`shevsim.core.paths.DATA_ROOT`) hashed into :func:`code_version`
DATA_FOLDERS = ("components", "cycles", "scenarios", "fmus", "vehicles", "data/measured")


def _data_files(root: Path) -> list[tuple[str, Path]]:
    """``(relative name, path)`` of every file of the bundled data folders under ``root`` (caches excluded)."""
    out = []
    for folder in DATA_FOLDERS:
        d = root / folder
        if not d.is_dir():
            continue
        for p in d.rglob("*"):
            rel = p.relative_to(root).parts
            # caches and build outputs are not data: FMUs (fmus/*.fmu is git-ignored, none is shipped) are
            # captured by content whenever a scenario names one
            if not p.is_file() or "__pycache__" in rel or any(part.startswith(".") for part in rel) \
                    or p.suffix in (".pyc", ".fmu"):
                continue
            out.append(("/".join(rel), p))
    return sorted(out)


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 of what the installed shevsim runs: the package's Python sources and the bundled data files
    (:data:`DATA_FOLDERS` under ``shevsim.core.paths.DATA_ROOT``: the parameter sets, cycles, maps and tables
    that components take by default - the cycle's ``hd_udds.csv``, the supervisor's fuel curve, the battery's
    OCV table - which a scenario does not name and a study therefore does not capture)."""
    from ..core import paths
    h = hashlib.sha256()
    for p in sorted(_PKG_ROOT.rglob("*.py")):
        rel = p.relative_to(_PKG_ROOT).parts
        if "__pycache__" in rel or rel[0] == "_data":      # the wheel's data folder: hashed below, as data
            continue
        h.update(str(p.relative_to(_PKG_ROOT)).encode())
        h.update(b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    for rel, p in _data_files(Path(paths.DATA_ROOT)):
        h.update(b"data:" + rel.encode())
        h.update(b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def shevsim_version() -> str:
    from ..version import __version__
    return __version__


def canonical(obj: Any) -> str:
    """Canonical JSON (sorted keys, floats by repr, inf/nan allowed) used for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=str)




def freeze(v):
    if isinstance(v, (list, tuple)):
        return tuple(freeze(x) for x in v)
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):
        return v.item()
    return v


def _thaw(v):
    return [_thaw(x) for x in v] if isinstance(v, tuple) else v


_BUNDLES: dict[tuple, Any] = {}


def _bundle_for(path: str, text: str):
    """The scenario captured once per (path, text) while none of the files it read changed (bundle.capture)."""
    from .bundle import capture
    b = _BUNDLES.get((path, text))
    if b is None or b.changed():
        b = capture(path, text=text)
        if len(_BUNDLES) > 64:
            _BUNDLES.clear()
        _BUNDLES[(path, text)] = b
    return b


@dataclass(frozen=True)
class ScenarioRun:
    """What a worker runs: a captured scenario (:mod:`.bundle`; files as tokens), its final signals and the
    engine.  ``run(paths)`` takes ``{token: local file}`` (:func:`.bundle.materialize`)."""

    scenario: Any
    final_signals: tuple = ()
    engine: str = "auto"

    def tokens(self) -> list[str]:
        from .bundle import tokens_of
        return tokens_of(self.scenario)

    def run(self, paths: dict) -> dict:
        limit_threads()
        from ..run import compute_run_metrics, simulate
        from .bundle import localize
        try:
            sc = localize(self.scenario, paths)
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


@dataclass(frozen=True)
class FailedRun:
    """An evaluation whose overrides do not apply to the scenario: its result is this error."""

    error: str

    def tokens(self) -> list[str]:
        return []

    def run(self, paths: dict) -> dict:
        return {"error": self.error}


@dataclass(frozen=True)
class Evaluation:
    """One scenario run with parameter overrides.

    Parameters
    ----------
    scenario : str
        Path of the scenario TOML file (on the client; a worker never opens it).
    overrides : tuple of (str, value)
        ``("component.param", value)`` pairs, sorted (use :meth:`make` to build from a dict).
    stop_s : float or None
        Override of the scenario's stop time (s); None keeps the scenario's.
    final_signals : tuple of str
        Signals (``component.port``) whose final value is returned as ``final:component.port``.
    text : str
        The scenario file's text, read once by :meth:`make`.
    engine : {'auto', 'python', 'fast'}
        Simulation engine (:func:`shevsim.run.simulate`): ``'auto'`` (default) runs the compiled
        whole-vehicle path (:mod:`shevsim.fast`) whenever the scenario is eligible - it gives the master's
        result bit for bit, so the engine is not part of the key.
    bundle : ScenarioBundle
        The scenario captured with every file it references (:mod:`.bundle`), once per study: the key
        hashes it and the workers run from it, so editing or removing the user's files during a study
        cannot make a result disagree with its key.
    """

    scenario: str
    overrides: tuple = ()
    stop_s: float | None = None
    final_signals: tuple = ()
    text: str = field(default="", repr=False, compare=False)   # scenario text captured by make()
    engine: str = field(default="auto", compare=False)
    bundle: Any = field(default=None, repr=False, compare=False)

    @classmethod
    def make(cls, scenario: str | Path, overrides: dict | None = None, stop_s: float | None = None,
             final_signals=(), engine: str = "auto", bundle=None) -> "Evaluation":
        """An evaluation of ``scenario`` (captured now, or ``bundle``: a :class:`.bundle.ScenarioBundle`
        captured once for a whole study)."""
        ov = tuple(sorted((str(k), freeze(v)) for k, v in (overrides or {}).items()))
        for k, _ in ov:
            if "." not in k:
                raise ValueError(f"override '{k}': expected 'component.param'")
        if engine not in ("auto", "python", "fast"):
            raise ValueError(f"engine must be 'auto', 'python' or 'fast', got {engine!r}")
        if bundle is None:
            path = Path(scenario).resolve()
            try:
                text = path.read_text(encoding="utf-8-sig")
            except (OSError, UnicodeDecodeError) as exc:
                from ..core.errors import ScenarioError
                raise ScenarioError(f"{scenario}: scenario file not readable: {exc}") from exc
            bundle = _bundle_for(str(path), text)
        else:
            path, text = Path(bundle.source), bundle.scenario.text
        return cls(str(path), ov, None if stop_s is None else float(stop_s), tuple(final_signals), text, engine,
                   bundle)

    def overrides_dict(self) -> dict:
        return {k: _thaw(v) for k, v in self.overrides}

    def sets(self) -> list[str]:
        """The overrides as ``load_scenario`` ``component.param=value`` strings (values in TOML)."""
        return [f"{k}={toml_value(_thaw(v))}" for k, v in self.overrides]

    def inputs(self) -> dict:
        return {"kind": "scenario", "scenario": self.scenario, "overrides": self.overrides_dict(),
                "stop_s": self.stop_s, "final_signals": list(self.final_signals)}

    def payload(self) -> tuple[Any, dict]:
        """``(run, blobs)``: what a worker runs (:class:`ScenarioRun`, or :class:`FailedRun` when the
        overrides do not apply) and the files it needs, ``{sha256: bytes}``.  Computed once per item."""
        got = self.__dict__.get("_payload")
        if got is None:
            from ..core.errors import ShevsimError
            bundle = self.bundle if self.bundle is not None else _bundle_for(self.scenario, self.text)
            try:
                sc, blobs = bundle.with_overrides(self.overrides_dict(), self.stop_s)
                run = ScenarioRun(sc, tuple(self.final_signals), self.engine)
                desc = {"scenario": _describe(sc), "final_signals": list(self.final_signals)}
            except (ShevsimError, ValueError, TypeError) as exc:
                run, blobs = FailedRun(f"{type(exc).__name__}: {exc}"), {}
                desc = {"scenario": _describe(bundle.scenario), "overrides": self.overrides_dict(),
                        "stop_s": self.stop_s, "final_signals": list(self.final_signals), "failed": run.error}
            payload = {**desc, "shevsim_version": shevsim_version(), "code_sha256": code_version()}
            got = (run, blobs, hashlib.sha256(canonical(payload).encode()).hexdigest())
            object.__setattr__(self, "_payload", got)
        return got[0], got[1]

    def key(self) -> str:
        self.payload()
        return self.__dict__["_payload"][2]

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_payload"}

    def run(self) -> dict:
        """Run here (serially): the files from the captured bundle, through this process's store."""
        from .bundle import materialize
        run, blobs = self.payload()
        return run.run(materialize(run.tokens(), blobs))


def _describe(sc) -> dict:
    from .bundle import describe
    return describe(sc)


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


class WorkerVersionError(Exception):
    """A worker runs another shevsim than the client, version or package sources (raised in the worker,
    refused by the client).  ``args[0]`` is the worker's :func:`worker_identity` (with its ``address``)."""

    def __str__(self) -> str:
        info = self.args[0] if self.args and isinstance(self.args[0], dict) else {}
        return f"worker {info.get('address', '?')} runs shevsim {info.get('shevsim')} (sources " \
               f"{str(info.get('code_sha256'))[:12]})"


def worker_identity() -> dict:
    """``{"shevsim": version, "code_sha256": sources hash, "python": version}`` of this process."""
    import platform
    return {"shevsim": shevsim_version(), "code_sha256": code_version(), "python": platform.python_version()}


def run_item(item, blobs: dict | None = None, expect_version: str | None = None,
             expect_code: str | None = None) -> tuple[dict, float, str]:
    """Worker entry point: run one evaluation item; return (outputs, wall time in s, worker code version).

    ``item`` is a :class:`ScenarioRun`/:class:`FailedRun` (its files in ``blobs``, ``{sha256: bytes}``,
    written once into this worker's store) or any object with ``run()`` (e.g. the synthetic problem's).
    ``expect_version``, ``expect_code``: the client's shevsim version and :func:`code_version`; a worker with
    another one (e.g. one that joined the cluster after the client checked the workers) raises
    :class:`WorkerVersionError` with its own identity and runs nothing.  The code version returned lets the
    client refuse to cache a result computed by a worker whose shevsim sources differ from the ones the key
    was made with (e.g. files edited while a study runs, with the process pool that gets no ``expect_code``).
    """
    if (expect_version is not None and expect_version != shevsim_version()) or \
            (expect_code is not None and expect_code != code_version()):
        info = worker_identity()
        try:
            from distributed import get_worker
            info["address"] = get_worker().address
        except (ImportError, ValueError, AttributeError):
            info["address"] = f"pid {os.getpid()}"
        raise WorkerVersionError(info)
    limit_threads()
    t0 = time.perf_counter()
    if isinstance(item, (ScenarioRun, FailedRun)):
        from .bundle import materialize
        out = item.run(materialize(item.tokens(), blobs or {}))
    else:
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
