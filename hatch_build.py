"""hatch_build.py - the wheel carries shevsim's compiled code, so its first run does not compile (issue 26).

A hatchling build hook (``[tool.hatch.build.targets.wheel.hooks.custom]`` in ``pyproject.toml``): when a
wheel is built, it runs ``python -m shevsim.warmup --build DIR`` on the checkout being built, which compiles
every component step the bundled scenarios use and the default scenario's fast loop with numba's cache
pointed into ``DIR`` (:mod:`shevsim.core.jitcache`), and ships ``DIR`` as ``shevsim/_jitcache`` (about a
minute or two of CPU at build time; nothing is written outside temporary folders).

Which Python compiles: ``$SHEVSIM_BUILD_PYTHON`` if set, else the interpreter running the build - with pip's
build isolation undone for that one subprocess (pip isolates a build by ``PYTHONPATH``/``PYTHONNOUSERSITE``
on the same interpreter; ``python -m build`` by a venv, whose base interpreter is tried then), since the
isolated environment holds hatchling only.  The cache is only useful with the numba, Python and CPU it was
made with: an installation that differs compiles on first use as before (the manifest says what it was built
for).  When no interpreter can import numba and shevsim's dependencies, the wheel is built without the
cache, and the hook says so.  ``SHEVSIM_PRECOMPILE=0`` turns the hook off (a quick build).

Editable installs (``pip install -e .``) are left alone: pip builds them before it installs the
dependencies, so there is no numba to compile with; ``shevsim warmup`` compiles the same code into the user's
cache afterwards, or the first run does (each compilation named on screen).
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

PROBE = "import numba, numpy, scipy, pandas, daqp"


def candidates() -> list[str]:
    """The interpreters tried for the compile, in order (see the module docstring)."""
    out = []
    for p in (os.environ.get("SHEVSIM_BUILD_PYTHON"), sys.executable, getattr(sys, "_base_executable", None)):
        if p and p not in out:
            out.append(p)
    return out


def clean_env(root: str) -> dict:
    """The environment of the compile: pip's isolation removed, the checkout first on the path, numba's
    settings that would change its target left out."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONNOUSERSITE", "PYTHONHOME", "VIRTUAL_ENV", "NUMBA_CACHE_DIR",
                        "NUMBA_DISABLE_JIT", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    env["PYTHONPATH"] = root
    env["MPLBACKEND"] = "Agg"
    env["SHEVSIM_BACKGROUND_COMPILE"] = "0"
    return env


def find_python(cands, env) -> str | None:
    """The first interpreter of ``cands`` that imports numba and shevsim's compiled dependencies, or None."""
    for cand in cands:
        try:
            if subprocess.run([cand, "-c", PROBE], env=env, cwd=tempfile.gettempdir(), capture_output=True,
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
    env = clean_env(root)
    cands = candidates() if cands is None else list(cands)
    python = find_python(cands, env)
    if python is None:
        say(f"no interpreter can import numba and shevsim's dependencies ({', '.join(cands)}): the wheel is "
            f"built WITHOUT precompiled code, so its first run compiles (about a minute; set "
            f"SHEVSIM_BUILD_PYTHON to a Python with numba to include it)", True)
        return None
    dest = Path(workdir) / "_jitcache"
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    env["SHEVSIM_JITCACHE_BUILD"] = str(dest)
    env["SHEVSIM_CACHE_DIR"] = str(Path(workdir) / "user_cache")
    say(f"precompiling shevsim's numba code with {python} (a minute or two) ...", False)
    try:
        r = subprocess.run([python, "-m", "shevsim.warmup", "--build", str(dest)], env=env, cwd=str(workdir),
                           capture_output=True, text=True, timeout=3600)
    except (OSError, subprocess.SubprocessError) as exc:
        say(f"precompiling failed ({exc}): the wheel is built without precompiled code", True)
        return None
    if r.returncode != 0 or not (dest / "manifest.json").is_file():
        tail = (r.stdout + r.stderr).strip().splitlines()[-5:]
        say("precompiling failed: the wheel is built without precompiled code:\n  " + "\n  ".join(tail), True)
        return None
    say(r.stdout.strip().splitlines()[-1], False)
    return dest


class JitCacheHook(BuildHookInterface):
    PLUGIN_NAME = "custom"

    def _say(self, msg: str, warn: bool = False) -> None:
        (self.app.display_warning if warn else self.app.display_info)(f"shevsim build: {msg}")

    def initialize(self, version: str, build_data: dict) -> None:
        self._tmp = None
        if self.target_name != "wheel":
            return
        if version == "editable":
            self._say("editable install: no precompiled code (run `shevsim warmup` after the install, or let the "
                      "first run compile)")
            return
        self._tmp = tempfile.mkdtemp(prefix="shevsim_jitcache_")
        dest = build_cache(self.root, self._tmp, self._say)
        if dest is not None:
            build_data["force_include"][str(dest)] = "shevsim/_jitcache"

    def finalize(self, version: str, build_data: dict, artifact_path: str) -> None:
        if getattr(self, "_tmp", None):
            shutil.rmtree(self._tmp, ignore_errors=True)
