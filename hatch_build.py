"""hatch_build.py - the wheel carries shevsim's compiled code, so its first run does not compile (issue 26).

A hatchling build hook (``[tool.hatch.build.targets.wheel.hooks.custom]`` in ``pyproject.toml``): when a
wheel is built, it runs ``python -m shevsim.warmup --build DIR`` on the checkout being built, which compiles
every component step the bundled scenarios use and the default scenario's fast loop with numba's cache
pointed into ``DIR`` (:mod:`shevsim.core.jitcache`), and ships ``DIR`` as ``shevsim/_jitcache`` (about a
minute or two of CPU at build time; nothing is written outside temporary folders).

Which Python compiles, the first of these that imports numba and shevsim's compiled dependencies:
``$SHEVSIM_BUILD_PYTHON`` if set; else the interpreter running the build *inside its build environment*
(``pyproject.toml``'s ``[build-system] requires`` lists numba and the packages ``shevsim.warmup --build``
imports, with the runtime dependencies' constraints, so pip's isolated build environment has them on a fresh
machine: the environment is kept as pip set it, the checkout put first on ``PYTHONPATH``); else, as a
fallback, the same interpreter and its venv's base interpreter with pip's isolation undone for that one
subprocess (``PYTHONPATH``/``PYTHONNOUSERSITE`` removed: a build with ``--no-build-isolation`` or an older
pip).  The cache is only useful with the numba, numpy, Python and CPU it was made with (``manifest.json``
records them; :func:`shevsim.core.jitcache.shipped_status` refuses a cache of another numba, numpy or Python,
since the build environment resolves the newest versions and a runtime environment may hold older ones): an
installation that differs compiles on first use as before.  Precompiling never fails the build: when no
interpreter can import numba, or the compile fails, the wheel is built without the cache and the hook says
so.  ``SHEVSIM_PRECOMPILE=0`` turns the hook off (a quick build).

Editable installs (``pip install -e .``): the same compile, written into the checkout's own
``shevsim/_jitcache`` (git-ignored; the package folder of an editable install is the checkout, where the
locator looks), replacing an older one only when the new compile succeeded.  Its content stamp covers the
sources: after an edit, what changed compiles on first use (``shevsim warmup`` does it ahead of time).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

try:
    from hatchling.builders.hooks.plugin.interface import BuildHookInterface
except ImportError:  # pragma: no cover - imported by the tests without hatchling: the functions below only
    BuildHookInterface = object

#: runs ``python -m shevsim.warmup --build DEST`` with the checkout put first on ``sys.path`` after start-up:
#: pip's build-environment ``sitecustomize`` drops every path that a ``.pth`` file of the interpreter's
#: site-packages adds, so when that interpreter holds an editable install of this very checkout, the checkout
#: on ``PYTHONPATH`` is dropped too and ``shevsim`` cannot be imported
BOOT = ("import sys, runpy; sys.path.insert(0, sys.argv.pop(1)); "
        "runpy.run_module('shevsim.warmup', run_name='__main__', alter_sys=True)")

PROBE = "import numba, numpy, scipy, pandas, daqp"


_NUMBA_TARGET = ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")


def candidates() -> list[str]:
    """The interpreters of the fallback search (pip's isolation undone), in order (see the module docstring)."""
    out = []
    for p in (os.environ.get("SHEVSIM_BUILD_PYTHON"), sys.executable, getattr(sys, "_base_executable", None)):
        if p and p not in out:
            out.append(p)
    return out


def isolated_env(root: str) -> dict:
    """The environment of a compile inside the build environment: pip's isolation kept as it is (its
    ``PYTHONPATH`` entries, ``PYTHONNOUSERSITE``; a ``python -m build`` venv needs nothing), the checkout put
    first on the path, numba's settings that would change its target left out."""
    env = {k: v for k, v in os.environ.items() if k not in _NUMBA_TARGET}
    env["PYTHONPATH"] = root + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else "")
    env["MPLBACKEND"] = "Agg"
    env["SHEVSIM_BACKGROUND_COMPILE"] = "0"
    return env


def attempts(root: str, cands=None) -> list[tuple[str, dict]]:
    """``(interpreter, environment)`` pairs tried in order: ``$SHEVSIM_BUILD_PYTHON`` (isolation undone), the
    build's own interpreter in the build environment, then the fallback search (:func:`candidates`).  With
    ``cands`` given (tests): those interpreters only, isolation undone."""
    clean = clean_env(root)
    if cands is not None:
        return [(c, clean) for c in cands]
    out = []
    if os.environ.get("SHEVSIM_BUILD_PYTHON"):
        out.append((os.environ["SHEVSIM_BUILD_PYTHON"], clean))
    out.append((sys.executable, isolated_env(root)))
    out += [(c, clean) for c in candidates() if c != os.environ.get("SHEVSIM_BUILD_PYTHON")]
    return out


def clean_env(root: str) -> dict:
    """The environment of the compile: pip's isolation removed, the checkout first on the path, numba's
    settings that would change its target left out."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONNOUSERSITE", "PYTHONHOME", "VIRTUAL_ENV") + _NUMBA_TARGET}
    env["PYTHONPATH"] = root
    env["MPLBACKEND"] = "Agg"
    env["SHEVSIM_BACKGROUND_COMPILE"] = "0"
    return env


def find_python(cands, env=None):
    """The first interpreter that imports numba and shevsim's compiled dependencies, or None: ``cands`` is a
    list of interpreters run with ``env`` (returns the interpreter), or of ``(interpreter, env)`` pairs
    (returns the pair)."""
    for cand in cands:
        py, e = cand if isinstance(cand, tuple) else (cand, env)
        try:
            if subprocess.run([py, "-c", PROBE], env=e, cwd=tempfile.gettempdir(), capture_output=True,
                              timeout=300).returncode == 0:
                return cand
        except (OSError, subprocess.SubprocessError):
            continue
    return None


def build_cache(root, workdir, say, cands=None) -> Path | None:
    """Precompile the checkout ``root`` into ``workdir/_jitcache``; return that folder, or None (said why)."""
    if os.environ.get("SHEVSIM_PRECOMPILE", "1").strip().lower() in ("0", "false", "no", "off"):
        say("SHEVSIM_PRECOMPILE=0: the wheel is built without precompiled code", True)
        return None
    root = str(Path(root).resolve())
    tries = attempts(root, cands)
    found = find_python(tries)
    if found is None:
        names = ", ".join(dict.fromkeys(py for py, _ in tries))
        say(f"no interpreter can import numba and shevsim's dependencies ({names}): the wheel is "
            f"built WITHOUT precompiled code, so its first run compiles (about a minute; set "
            f"SHEVSIM_BUILD_PYTHON to a Python with numba to include it)", True)
        return None
    python, env = found[0], dict(found[1])
    dest = Path(workdir) / "_jitcache"
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    env["SHEVSIM_JITCACHE_BUILD"] = str(dest)
    env["SHEVSIM_CACHE_DIR"] = str(Path(workdir) / "user_cache")
    say(f"precompiling shevsim's numba code with {python} (a minute or two) ...", False)
    try:
        r = subprocess.run([python, "-c", BOOT, root, "--build", str(dest)], env=env, cwd=str(workdir),
                           capture_output=True, text=True, timeout=3600)
    except (OSError, subprocess.SubprocessError) as exc:
        say(f"precompiling failed ({exc}): the wheel is built without precompiled code", True)
        return None
    if r.returncode != 0 or not (dest / "manifest.json").is_file():
        tail = (r.stdout + r.stderr).strip().splitlines()[-5:]
        say("precompiling failed: the wheel is built without precompiled code:\n  " + "\n  ".join(tail), True)
        return None
    lines = r.stdout.strip().splitlines()
    skipped = [ln for ln in lines if ln.startswith("precompile: ") and " skipped (" in ln]
    if skipped:                             # a partial cache still serves, but what it lacks compiles on first use
        say(f"{len(skipped)} part(s) could not be precompiled and will compile on first use:\n  "
            + "\n  ".join(skipped), True)
    say(lines[-1], False)
    return dest


def install_in_tree(dest: Path, root) -> Path:
    """An editable install: move the compiled cache ``dest`` to the checkout's ``shevsim/_jitcache`` (a
    generated, git-ignored folder; the old one is replaced only now that the new compile succeeded)."""
    target = Path(root).resolve() / "shevsim" / "_jitcache"
    old = target.with_name(f"_jitcache.old.{os.getpid()}")
    if target.exists():
        target.rename(old)
    try:
        shutil.copytree(dest, target)
    except OSError:
        shutil.rmtree(target, ignore_errors=True)
        if old.exists():
            old.rename(target)
        raise
    shutil.rmtree(old, ignore_errors=True)
    return target


class JitCacheHook(BuildHookInterface):
    PLUGIN_NAME = "custom"

    def _say(self, msg: str, warn: bool = False) -> None:
        (self.app.display_warning if warn else self.app.display_info)(f"shevsim build: {msg}")

    def initialize(self, version: str, build_data: dict) -> None:
        self._tmp = None
        if self.target_name != "wheel":
            return
        self._tmp = tempfile.mkdtemp(prefix="shevsim_jitcache_")
        try:
            dest = build_cache(self.root, self._tmp, self._say)
            if dest is None:
                return
            if version == "editable":
                self._say(f"editable install: precompiled code in {install_in_tree(dest, self.root)}")
            else:
                build_data["force_include"][str(dest)] = "shevsim/_jitcache"
        except Exception as exc:  # noqa: BLE001 - precompiling never fails the install
            self._say(f"precompiling failed ({type(exc).__name__}: {exc}): built without precompiled code", True)

    def finalize(self, version: str, build_data: dict, artifact_path: str) -> None:
        if getattr(self, "_tmp", None):
            shutil.rmtree(self._tmp, ignore_errors=True)
