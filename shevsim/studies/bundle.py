"""bundle.py - a scenario captured on the client with every file it references, shipped by content.

A study on a cluster cannot assume that its workers see the user's files: on a cloud or Kubernetes cluster
they do not.  So the client resolves the scenario once (:func:`capture`): it loads it (``load_scenario``:
overlays merged, ``set`` tables and bundled names resolved), reads each parameter file's ``[params]``
table, and replaces every file reference - each ``*_file`` parameter (cycles, maps, cell tables, measured
data), each FMU - by a *token* ``shevsim-blob:<sha256>/<file name>``, keeping the file's bytes under its
SHA-256.  The result, a :class:`ScenarioBundle`, is a plain :class:`~shevsim.core.scenario.Scenario`
(picklable, holding only values and tokens) plus ``{sha256: bytes}``.

On a worker (:func:`materialize`) each token becomes a file in a content-addressed store
(``<store>/<sha256>/<file name>``, written once per worker process and checked against its hash), the
scenario's tokens are replaced by those paths (:func:`localize`) and the run proceeds as usual: the worker
opens no path of the user's machine, only its store and the installed package's own data (parameters a
scenario leaves at their empty default, e.g. the battery's built-in OCV table, come from the installed
shevsim, which the runner checks is the client's version).

The bundle is also what the evaluation key hashes (:func:`describe`): the scenario's values, the
components' parameter tables and overrides with file *contents* (by hash) in place of paths - nothing that
depends on where the files lie - so the same inputs give the same key on any machine.

Nothing here imports or executes anything a user's file names: files are read as bytes, and the scenario
and parameter files are parsed as TOML.  An FMU, however, is native code: the worker that runs a captured
scenario loads and runs the FMUs it ships (as ``shevsim run`` does), so a study must use trusted FMUs only.
"""
from __future__ import annotations

import atexit
import copy
import dataclasses
import hashlib
import os
import re
import shutil
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.errors import ScenarioError

TOKEN = "shevsim-blob:"


def is_token(v: Any) -> bool:
    return isinstance(v, str) and v.startswith(TOKEN)


def token_sha(tok: str) -> str:
    return tok[len(TOKEN):].split("/", 1)[0]


def token_name(tok: str) -> str:
    return tok[len(TOKEN):].split("/", 1)[1]


# -- client: files by content -------------------------------------------------------------------------
_FILES: dict[tuple, tuple[str, bytes]] = {}
_FILES_LOCK = threading.Lock()


def read_blob(path: str | Path) -> tuple[str, bytes]:
    """``(sha256, bytes)`` of a file (memoised while its device, inode, size and mtime are unchanged)."""
    p = Path(path)
    st = p.stat()
    k = (str(p), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    with _FILES_LOCK:
        hit = _FILES.get(k)
    if hit is None:
        data = p.read_bytes()
        hit = (hashlib.sha256(data).hexdigest(), data)
        with _FILES_LOCK:
            if len(_FILES) > 512:
                _FILES.clear()
            _FILES[k] = hit
    return hit


def file_state(path) -> tuple:
    """(inode, size, mtime in ns) of a file: what tells that it changed since it was captured."""
    st = os.stat(path)
    return (st.st_ino, st.st_size, st.st_mtime_ns)


def _tokenize(value: str, what: str, blobs: dict, seen: dict | None = None) -> str:
    p = Path(value)
    if not p.is_file():
        raise ScenarioError(f"{what}: file '{value}' not found")
    try:
        sha, data = read_blob(p)
        if seen is not None:
            seen[str(p)] = file_state(p)
    except OSError as exc:
        raise ScenarioError(f"{what}: cannot read '{value}': {exc}") from None
    blobs[sha] = data
    return f"{TOKEN}{sha}/{p.name}"


def _tokenize_table(d: dict, where: str, blobs: dict, base: Path | None = None, seen: dict | None = None) -> dict:
    """A copy of a parameter table with every non-empty ``*_file`` string replaced by a token."""
    out = {}
    for k, v in d.items():
        if isinstance(k, str) and k.endswith("_file") and isinstance(v, str) and v and not is_token(v):
            p = Path(v)
            if not p.is_absolute() and base is not None:      # relative to its parameter file (make_params)
                p = (base / p).resolve()
            v = _tokenize(str(p), f"{where}: parameter '{k}'", blobs, seen)
        out[k] = v
    return out


def _fmu_file(spec, where: str) -> Path:
    """The FMU file of a component: a bundled scenario's FMU that the package does not ship (e.g.
    ``fmus/battery.fmu`` of ``hd_udds_fmu_battery``) is built first, through the same export as ``shevsim run``
    (:func:`shevsim.fmu.adapter.bundled_export`, into the user cache), so that its bytes can be captured."""
    p = Path(spec.fmu)
    if p.is_file() or not spec.replaces:
        return p
    from ..core.paths import DATA_ROOT
    from ..fmu.adapter import bundled_export, is_inside
    return bundled_export(spec, where) if is_inside(p, DATA_ROOT) else p


def tokenize_scenario(sc, blobs: dict, seen: dict | None = None) -> None:
    """Capture, in place, every file ``sc`` references (see the module docstring); bytes go to ``blobs``, the
    state of every file read to ``seen`` (``{path: file_state}``)."""
    from ..core.params import read_params_table
    where = str(sc.path or "<scenario>")
    for spec in sc.components:
        w = f"{where}: [components.{spec.name}]"
        if spec.params_file is not None and spec.params_table is None:
            pf = Path(spec.params_file)
            if seen is not None:
                seen[str(pf)] = file_state(pf)
            spec.params_table = _tokenize_table(read_params_table(pf), str(pf), blobs, pf.parent, seen)
        elif spec.params_table is not None:
            spec.params_table = _tokenize_table(spec.params_table, str(spec.params_file), blobs, None, seen)
        spec.overrides = _tokenize_table(spec.overrides, w, blobs, None, seen)
        if spec.fmu is not None and not is_token(str(spec.fmu)):
            spec.fmu = _tokenize(str(_fmu_file(spec, w)), f"{w}: field 'fmu'", blobs, seen)
    _capture_shared(sc, blobs, seen)


def _capture_shared(sc, blobs: dict, seen: dict | None) -> None:
    """The scenario's ``[shared]`` quantities resolved on the client: the vehicle's (and its cell's, fuel's)
    values become ``sc.shared_base``, the declared ones ``sc.shared`` (names of cell/fuel sets expanded),
    every ``*_file`` value a token - a worker reads no vehicle or cell file of the client's."""
    if not sc.shared and not sc.shared_base:
        return
    from ..core.registry import shared_quantities
    from ..core.scenario import file_params
    if not sc.shared_base or "vehicle" in sc.shared:
        r = shared_quantities().resolve(sc, file_params)
        veh = r.vehicle
        sc.shared_base = {q: v for q, (v, _) in r.values.items() if q not in r.explicit and q not in r.lifted}
        declared = {q: r.values[q][0] for q in r.explicit if q in r.values}
        sc.shared = {**{k: v for k, v in sc.shared.items() if k not in ("vehicle", "cell", "fuel")}, **declared}
        if veh is not None:           # the vehicle's own values for its component types (below overrides)
            for spec in sc.components:
                for k, v in veh.components.get(spec.type, {}).items():
                    spec.overrides.setdefault(k, v)
    w = f"{sc.path or '<scenario>'}: [shared]"
    sc.shared_base = _tokenize_table(sc.shared_base, w, blobs, None, seen)
    sc.shared = _tokenize_table(sc.shared, w, blobs, None, seen)


def tokens_of(sc) -> list[str]:
    """Every token in a captured scenario."""
    out = [v for d in (sc.shared, sc.shared_base) for v in d.values() if is_token(v)]
    for spec in sc.components:
        for d in (spec.params_table or {}, spec.overrides):
            out += [v for v in d.values() if is_token(v)]
        if is_token(spec.fmu):
            out.append(spec.fmu)
    return sorted(set(out))


_DIRS = re.compile(r"(?:[A-Za-z]:)?[\\/](?:[^\s:\\/'\"]+[\\/])+")


def _names_only(text: str) -> str:
    """``text`` with the folder part of every absolute path removed (``/home/u/p/my.toml: x`` -> ``my.toml: x``)."""
    return _DIRS.sub("", text)


def strip_locations(sc) -> None:
    """Remove, in place, every trace of where the client's files lie from a captured scenario, before it is
    shipped: its path and its parameter files' become their file names (messages still name them), the
    origins noted for messages lose their folders, and the scenario's text (not needed to run it) is dropped.
    None of these enter the key (:func:`describe`)."""
    if sc.path is not None:
        sc.path = Path(Path(sc.path).name)
    sc.text = ""
    sc.overlays = [_names_only(str(o)) for o in (getattr(sc, "overlays", None) or [])]
    sc.sets = [_names_only(str(x)) for x in (getattr(sc, "sets", None) or [])]
    if getattr(sc, "shared_origins", None):
        sc.shared_origins = {k: _names_only(str(v)) for k, v in sc.shared_origins.items()}
    for spec in sc.components:
        if spec.params_file is not None:
            spec.params_file = Path(Path(spec.params_file).name)
        if getattr(spec, "sources", None):
            spec.sources = {k: _names_only(str(v)) for k, v in spec.sources.items()}


def describe(sc) -> dict:
    """What decides a captured scenario's run, free of paths (files by content): hashed into the key."""
    st = dataclasses.asdict(sc.settings)
    st.pop("progress", None)
    return {"name": sc.name, "settings": st, "stop_s": sc.stop_s, "t0_s": sc.t0_s, "seed": sc.seed,
            "order": sc.order, "record": sc.record, "metrics": sc.metrics,
            "shared": sc.shared, "shared_base": sc.shared_base,
            "components": [{"name": c.name, "type": c.type, "params": c.params_table, "set": c.overrides,
                            "start": c.start, "step_multiple": c.step_multiple,
                            "fmu": None if c.fmu is None else str(c.fmu), "map": c.mapping,
                            "replaces": c.replaces, "own": sorted(c.own)} for c in sc.components],
            "connections": [str(c) for c in sc.connections],
            "faults": [dataclasses.asdict(f) for f in sc.faults]}


@dataclass(frozen=True)
class ScenarioBundle:
    """A scenario captured with its files: ``scenario`` holds tokens, ``blobs`` maps sha256 -> bytes."""

    scenario: Any
    blobs: dict
    source: str            # the scenario file on the client (messages only; never opened on a worker)
    files: tuple = ()      # ((path, file_state), ...) of every file read on the client when capturing

    def changed(self) -> bool:
        """True when a file read at capture has changed or gone since (the bundle is then stale)."""
        try:
            return any(file_state(p) != st for p, st in self.files)
        except OSError:
            return True

    def with_overrides(self, overrides: dict, stop_s: float | None = None):
        """``(scenario, blobs)``: a copy with ``component.param`` overrides applied (files they name, e.g. a
        ``*_file`` relative to the working directory, captured now).  Raises
        :class:`~shevsim.core.errors.ScenarioError` for an override that does not apply."""
        from ..core.scenario import apply_override
        sc = copy.deepcopy(self.scenario)
        for k, v in overrides.items():
            apply_override(sc, k, v, f"override '{k}'", base=None)
        blobs = dict(self.blobs)
        tokenize_scenario(sc, blobs)
        if stop_s is not None:
            sc.stop_s = float(stop_s)
        strip_locations(sc)
        used = {token_sha(t) for t in tokens_of(sc)}
        return sc, {h: b for h, b in blobs.items() if h in used}


def capture(path: str | Path, text: str | None = None, sets=()) -> ScenarioBundle:
    """Load a scenario on the client and capture every file it references (see the module docstring).

    Raises :class:`~shevsim.core.errors.ScenarioError` naming the file and field for a malformed scenario
    or a referenced file that does not exist."""
    import tomllib
    from ..core.scenario import load_scenario, resolve_path
    sc = load_scenario(path, list(sets), text=text)
    blobs: dict[str, bytes] = {}
    seen: dict[str, tuple] = {}
    try:        # overlays are merged into the components' overrides by load_scenario: note their state too
        for cd in (tomllib.loads(sc.text).get("components") or {}).values():
            if isinstance(cd, dict) and isinstance(cd.get("overlay"), str):
                f = resolve_path(cd["overlay"], sc.path)
                seen[str(f)] = file_state(f)
    except (tomllib.TOMLDecodeError, OSError):
        pass
    tokenize_scenario(sc, blobs, seen)
    return ScenarioBundle(sc, blobs, str(sc.path or path), tuple(sorted(seen.items())))


# -- worker: the content-addressed store --------------------------------------------------------------
_STORE: Path | None = None
_DONE: dict[str, str] = {}
_STORE_LOCK = threading.Lock()


def _remove_store(p: Path) -> None:
    shutil.rmtree(p, ignore_errors=True)


def store_dir() -> Path:
    """This process's file store: in the Dask worker's own local directory, else a private temp folder
    (removed when the process exits)."""
    global _STORE
    if _STORE is not None and _STORE.is_dir():
        return _STORE
    base = None
    try:
        from distributed import get_worker
        base = Path(get_worker().local_directory) / "shevsim-files"
        base.mkdir(parents=True, exist_ok=True)
    except (ImportError, ValueError, AttributeError, OSError):
        base = None
    if base is None:
        base = Path(tempfile.mkdtemp(prefix="shevsim-files-"))
        atexit.register(_remove_store, base)
    _STORE = base
    _DONE.clear()
    return base


def materialize(tokens, blobs: dict) -> dict[str, str]:
    """``{token: local path}``: each token's bytes written once into this process's store (checked
    against the hash; atomic rename, so a concurrent reader never sees half a file)."""
    out = {}
    with _STORE_LOCK:
        root = store_dir()
        for tok in tokens:
            path = _DONE.get(tok)
            if path is not None and os.path.isfile(path):
                out[tok] = path
                continue
            sha, name = token_sha(tok), token_name(tok)
            if sha not in blobs:
                raise ScenarioError(f"file {name} (sha256 {sha[:12]}) was not sent with the evaluation")
            data = blobs[sha]
            if hashlib.sha256(data).hexdigest() != sha:
                raise ScenarioError(f"file {name}: the bytes received do not match their sha256 {sha[:12]}")
            d = root / sha
            d.mkdir(parents=True, exist_ok=True)
            dest = d / Path(name).name
            if not dest.is_file() or dest.stat().st_size != len(data):
                tmp = d / f".{dest.name}.{os.getpid()}.tmp"
                tmp.write_bytes(data)
                os.replace(tmp, dest)
            _DONE[tok] = str(dest)
            out[tok] = str(dest)
    return out


def localize(sc, paths: dict[str, str]):
    """A copy of a captured scenario with every token replaced by its local path."""
    sc = copy.deepcopy(sc)

    def loc(d):
        return {k: (paths[v] if is_token(v) else v) for k, v in d.items()}

    sc.shared, sc.shared_base = loc(sc.shared), loc(sc.shared_base)
    for spec in sc.components:
        if spec.params_table is not None:
            spec.params_table = loc(spec.params_table)
        spec.overrides = loc(spec.overrides)
        if is_token(spec.fmu):
            spec.fmu = Path(paths[spec.fmu])
    return sc
