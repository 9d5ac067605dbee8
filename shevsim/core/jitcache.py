"""jitcache.py - where numba caches shevsim's compiled functions, and the precompiled cache a wheel ships.

Every compiled function of shevsim is declared ``@njit(cache=True)``: numba keeps its machine code on disk and
loads it in later processes instead of compiling again (the component steps take about a minute of CPU to
compile; loading them takes a fraction of a second).  This module adds one cache *locator* to numba
(:class:`ShevsimLocator`, first in numba's list; :func:`install_when_numba_loads`, called by ``import shevsim``,
installs it as numba is imported, so ``import shevsim`` alone does not import numba) for shevsim's own modules
and for the generated fast loops (:mod:`shevsim.fast.loop`):

* **where**: a writable folder of the user's, ``numba/`` in :func:`shevsim.core.paths.user_cache_dir` (never the
  installed package: ``site-packages`` may not be writable and is not ours to write); one sub-folder per
  source folder (named by its absolute path, so two installations never share an index);
* **when fresh**: the source stamp (:func:`closure_stamp`) is the SHA-256 of the content of the function's file
  and of every shevsim module it imports, transitively (numba copies callees' machine code into the caller's
  entry; older numba versions used the file's own mtime and size, which ``pip install`` does not keep): a changed
  source, the function's own or a callee's, never loads stale code, a copied or re-installed one still loads;
* **seeded from the shipped cache**: a wheel (the build hook ``hatch_build.py`` runs :mod:`shevsim.warmup`'s
  :func:`~shevsim.warmup.precompile` with ``SHEVSIM_JITCACHE_BUILD`` pointing into the build) carries
  ``shevsim/_jitcache/``, and an editable install has it in the checkout's package folder (the same index and
  data files, laid out by the sources' folders inside the package, and ``manifest.json``).  The first time a
  function is cached in a process, the shipped entries of its module whose stamp matches the installed source
  are copied into the user's folder (:func:`_seed`), when the manifest's numba, numpy and Python versions are
  the running ones (:func:`versions_refusal`), and numba loads them from there.

numba's own index key holds the CPU (name and features) and the function's bytecode: on another CPU, or with
another numba or Python version, the shipped entries do not match and the function compiles on first use
as without them (with the on-screen notice of :class:`shevsim.warmup.CompileNotice`; :func:`shipped_status`
says why the shipped code is not used).  If no writable folder exists, numba's own locators take over.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import pickle
import re
import shutil
import sys
import uuid
from pathlib import Path

#: the package folder (``shevsim/``)
PKG_ROOT = Path(__file__).resolve().parents[1]
#: the precompiled cache inside the package (present in a wheel built with numba; read only)
SHIPPED = PKG_ROOT / "_jitcache"
MANIFEST = "manifest.json"
#: the sub-folder of the generated fast loops (:mod:`shevsim.fast.loop`), in the user cache and the shipped one
LOOP_FOLDER = "fastloop"
BUILD_ENV = "SHEVSIM_JITCACHE_BUILD"
_LOOP_FILE = re.compile(r"shevsim_loop_[0-9a-f]{20}\.py$")
_installed = False
_seeded: set = set()


def file_stamp(path) -> str:
    """The source stamp of a file: ``"sha256:<hex>"`` of its content (memoised in the process on its path, size,
    inode, mtime and ctime: a write changes the ctime even when the mtime is set back)."""
    st = os.stat(path)
    return _hash(os.fspath(path), st.st_size, st.st_ino, st.st_mtime_ns, st.st_ctime_ns)


@functools.lru_cache(maxsize=None)
def _hash(path: str, *stat_key) -> str:
    with open(path, "rb") as f:
        return "sha256:" + hashlib.sha256(f.read()).hexdigest()


def closure_stamp(py_file) -> str:
    """The source stamp of a compiled function's file: the content of that file AND of every shevsim module it
    imports, transitively (read from the ``import`` statements, function-level ones included).  numba copies
    the machine code of the functions a function calls into its cache entry, so an edit of a callee's file
    (``powertrain/motor.py`` under ``components/motor.py``'s step) must make the caller's entry stale: numba's
    own stamp, and the file's alone, would keep the old physics.  Memoised per process."""
    files = _import_closure(os.path.abspath(py_file))
    h = hashlib.sha256()
    named = []
    for f in files:                           # named inside the package: the same in a build tree and installed
        try:
            named.append((Path(f).resolve().relative_to(PKG_ROOT).as_posix(), f))
        except (ValueError, OSError):
            named.append((os.path.basename(f), f))
    for name, f in sorted(named):             # in the order of those names, not of the absolute paths
        try:
            h.update(f"{name}:{file_stamp(f)}\n".encode())
        except OSError:
            h.update(f"{name}:missing\n".encode())
    return "closure:" + h.hexdigest()


def _import_closure(py_file: str) -> tuple[str, ...]:
    seen: set = set()
    todo = [py_file]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        try:
            st = os.stat(f)
            todo.extend(d for d in _imported_files(f, st.st_size, st.st_mtime_ns, st.st_ctime_ns) if d not in seen)
        except OSError:
            continue
    return tuple(sorted(seen))


@functools.lru_cache(maxsize=None)
def _imported_files(py_file: str, *stat_key) -> tuple[str, ...]:
    """The files of the shevsim modules ``py_file`` imports (``import shevsim.x``, ``from .x import y``,
    ``from . import x``): the package's own, resolved against :data:`PKG_ROOT`; other packages left out."""
    import ast
    try:
        tree = ast.parse(Path(py_file).read_bytes())
    except (OSError, SyntaxError, ValueError):
        return ()
    here = Path(py_file).resolve().parent
    try:
        pkg = ("shevsim",) + here.relative_to(PKG_ROOT).parts
    except ValueError:
        pkg = ("shevsim",)                    # a generated fast loop: absolute imports only
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            mods = [a.name.split(".") for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = list(pkg[:len(pkg) - node.level + 1]) if node.level else []
            mod = base + (node.module.split(".") if node.module else [])
            mods = [mod] + [mod + [a.name] for a in node.names]
        else:
            continue
        for m in mods:
            if not m or m[0] != "shevsim":
                continue
            target = PKG_ROOT.joinpath(*m[1:])
            for cand in (target.with_suffix(".py"), target / "__init__.py"):
                if cand.is_file():
                    out.append(os.fspath(cand))
                    break
    return tuple(sorted(set(out)))


def relative_folder(py_file) -> str | None:
    """The cache sub-folder of a source file: its folder inside the package (``"components"``, ``"."``), or
    :data:`LOOP_FOLDER` for a generated fast loop; None for a file that is not shevsim's."""
    p = Path(os.path.abspath(py_file))
    if _LOOP_FILE.match(p.name):
        return LOOP_FOLDER
    return _package_folder(str(p.parent))


@functools.lru_cache(maxsize=None)
def _package_folder(folder: str) -> str | None:
    try:
        rel = Path(folder).resolve().relative_to(PKG_ROOT)
    except (ValueError, OSError):
        return None
    if rel.parts and rel.parts[0] in ("_jitcache", "_data"):
        return None
    return rel.as_posix()


def user_root() -> Path | None:
    """The writable folder holding the user's cache of compiled shevsim code (created), or None:
    ``shevsim`` in ``$NUMBA_CACHE_DIR`` when that is set (numba's own setting for where caches go), else
    ``numba`` in :func:`shevsim.core.paths.user_cache_dir`, else in the temporary folder."""
    env = tuple(os.environ.get(k) for k in ("NUMBA_CACHE_DIR", "SHEVSIM_CACHE_DIR", "XDG_CACHE_HOME", "HOME"))
    return _user_root(env)


@functools.lru_cache(maxsize=8)
def _user_root(env: tuple) -> Path | None:
    from .paths import writable_cache_subdir
    first = Path(os.environ["NUMBA_CACHE_DIR"]) / "shevsim" if os.environ.get("NUMBA_CACHE_DIR") else None
    return writable_cache_subdir("numba", first)


def _subfolder(rel: str, py_file) -> str:
    tag = rel.replace("/", "_").replace(".", "") or "shevsim"
    where = os.path.dirname(os.path.abspath(py_file))
    return f"{tag}_{hashlib.sha1(where.encode()).hexdigest()[:16]}"


# --------------------------------------------------------------------------------------- the locator
def _locator_base():
    from numba.core.caching import _CacheLocator
    return _CacheLocator


class _LocatorMixin:
    """The logic of :class:`ShevsimLocator` (kept apart from numba's base class, so it is testable cheaply)."""

    def __init__(self, py_func, py_file, rel: str):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._rel = rel
        build = os.environ.get(BUILD_ENV)
        if build:                             # precompiling for a wheel: the shipped layout, nothing seeded
            self._cache_path = os.path.join(build, rel)
            self._seed_from = None
        else:
            root = user_root()
            if root is None:
                raise OSError("no writable cache folder")
            self._cache_path = os.path.join(root, _subfolder(rel, py_file))
            self._seed_from = SHIPPED / rel

    def get_cache_path(self):
        return self._cache_path

    def get_source_stamp(self):
        return closure_stamp(self._py_file)

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        rel = relative_folder(py_file) if py_file and os.path.exists(py_file) else None
        if rel is None:
            return None
        try:
            self = cls(py_func, py_file, rel)
            self.ensure_cache_path()
        except OSError:
            return None                       # numba's own locators take over
        if self._seed_from is not None and _shipped_versions_ok():
            try:
                _seed(self._seed_from, Path(self._cache_path), py_file)
            except Exception:  # noqa: BLE001 - a shipped cache that cannot be read only costs a compile
                pass
        return self


@functools.lru_cache(maxsize=None)
def locator_class():
    """:class:`ShevsimLocator`: the mixin on numba's ``_CacheLocator`` (built on first use: numba imported late)."""
    return type("ShevsimLocator", (_LocatorMixin, _locator_base()), {"__module__": __name__})


class _InstallOnImport:
    """A one-shot import hook: when numba's ``caching`` module is imported (numba imports it with its
    dispatcher, before any function is decorated), run :func:`install` right after it.  So ``import shevsim``
    itself does not import numba (a command that compiles nothing, an exported FMU's slave, stay light)."""

    def find_spec(self, name, path=None, target=None):
        if name != "numba.core.caching":
            return None
        try:
            sys.meta_path.remove(self)
        except ValueError:
            pass
        import importlib.util
        spec = importlib.util.find_spec(name)
        loader = getattr(spec, "loader", None)
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        run = loader.exec_module

        def exec_module(module):
            run(module)
            install()
        loader.exec_module = exec_module
        return spec


def install_when_numba_loads() -> None:
    """:func:`install` now if numba is imported already, else as soon as it is (:class:`_InstallOnImport`)."""
    if "numba.core.caching" in sys.modules:
        install()
    elif not any(isinstance(f, _InstallOnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _InstallOnImport())


def install() -> bool:
    """Put the shevsim locator first in numba's list (idempotent); False when numba has no such list."""
    global _installed
    if _installed:
        return True
    try:
        from numba.core import caching
    except ImportError:
        return False
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    if not isinstance(classes, list):
        return False
    cls = locator_class()
    if cls not in classes:
        classes.insert(0, cls)
    _installed = True
    return True


# --------------------------------------------------------------------------------------- index files
def read_index(path) -> tuple[str, object, dict] | None:
    """``(numba version, source stamp, overloads)`` of a numba index file (``.nbi``), or None if unreadable.
    The overloads are not unpickled when the version is not the running numba's (empty dict then)."""
    try:
        with open(path, "rb") as f:
            version = pickle.load(f)
            data = f.read()
    except (OSError, pickle.UnpicklingError, EOFError, ValueError):
        return None
    import numba
    if version != numba.__version__:
        return str(version), None, {}
    try:
        stamp, overloads = pickle.loads(data)
    except Exception:  # noqa: BLE001 - an index written by something else
        return None
    return str(version), stamp, dict(overloads)


def _write_index(path: Path, stamp, overloads: dict) -> None:
    import numba
    from numba.core.serialize import dumps
    tmp = path.with_name(f"{path.name}.tmp.{uuid.uuid4().hex[:12]}")
    with open(tmp, "wb") as f:
        pickle.dump(numba.__version__, f, protocol=-1)
        f.write(dumps((stamp, overloads)))
    os.replace(tmp, path)


def _copy(src: Path, dst: Path) -> None:
    tmp = dst.with_name(f"{dst.name}.tmp.{uuid.uuid4().hex[:12]}")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


def _seed(shipped: Path, user: Path, py_file) -> int:
    """Copy the shipped cache entries of ``py_file``'s module into the user's folder: for each shipped index
    of the module that is fresh (this numba, the installed source's stamp), the entries the user's index lacks
    (a user index of another stamp is replaced).  Once per source file and process; returns entries copied."""
    key = (os.fspath(shipped), os.fspath(user), os.fspath(py_file))
    if key in _seeded:
        return 0
    _seeded.add(key)
    if not shipped.is_dir():
        return 0
    modname = os.path.splitext(os.path.basename(py_file))[0]
    stamp = closure_stamp(py_file)
    import numba
    copied = 0
    for idx in sorted(shipped.glob(f"{glob_escape(modname)}.*.nbi")):
        got = read_index(idx)
        if got is None or got[0] != numba.__version__ or got[1] != stamp or not got[2]:
            continue                                   # stale or foreign: never used
        target = user / idx.name
        mine = read_index(target) if target.exists() else None
        overloads = dict(mine[2]) if mine is not None and mine[0] == numba.__version__ and mine[1] == stamp else {}
        used = set(overloads.values())
        changed = False
        base = idx.name[:-len(".nbi")]
        for k, name in got[2].items():
            if k in overloads or not (shipped / name).is_file():
                continue
            n = 1
            while f"{base}.{n}.nbc" in used:
                n += 1
            new = f"{base}.{n}.nbc"
            _copy(shipped / name, user / new)
            overloads[k] = new
            used.add(new)
            changed = True
            copied += 1
        if changed:
            _write_index(target, stamp, overloads)
    return copied


def glob_escape(s: str) -> str:
    return re.sub(r"([*?\[\]])", r"[\1]", s)


# --------------------------------------------------------------------------------------- the manifest
def cpu_key() -> list:
    """numba's description of this machine's code target (triple, CPU name, features): the part of its cache
    key that decides whether machine code compiled elsewhere can be loaded here."""
    from numba.core.registry import cpu_target
    return [str(x) for x in cpu_target.target_context.codegen().magic_tuple()]


def manifest() -> dict:
    """The shipped cache's ``manifest.json`` ({} when this installation carries none)."""
    try:
        return json.loads((SHIPPED / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}


def runtime_versions() -> dict:
    """The versions a precompiled cache is tied to: numba's, numpy's (numba's typing and the arrays' layout),
    Python's (major.minor)."""
    import numba
    import numpy
    return {"numba": numba.__version__, "numpy": numpy.__version__,
            "python": f"{sys.version_info[0]}.{sys.version_info[1]}"}


def versions_refusal(m: dict) -> str:
    """``""`` when the manifest ``m`` was built with this process's numba, numpy and Python, else why not (the
    build environment resolves the newest versions; a runtime environment may hold older ones)."""
    here = runtime_versions()
    if all(m.get(k) == v for k, v in here.items()):
        return ""
    return ("the precompiled code was built with " + " / ".join(f"{k} {m.get(k)}" for k in here) + ", this is "
            + " / ".join(f"{k} {v}" for k, v in here.items()))


def _shipped_versions_ok() -> bool:
    """The shipped cache's manifest names this numba, numpy and Python (checked before a module's shipped
    entries are seeded into the user's cache; a cache without a manifest is never seeded)."""
    m = manifest()
    return bool(m) and versions_refusal(m) == ""


def write_manifest(dest: Path, layouts: list[str], sources: str, functions: int) -> dict:
    import platform
    m = {**runtime_versions(), "machine": platform.machine(), "cpu": cpu_key(), "sources": sources, "layouts": sorted(layouts), "indexes": functions}
    (Path(dest) / MANIFEST).write_text(json.dumps(m, indent=1))
    return m


@functools.lru_cache(maxsize=1)
def shipped_status() -> str:
    """``""`` when the shipped precompiled code can be used in this process, else why not (no shipped cache,
    another numba or Python, another CPU, changed sources)."""
    m = manifest()
    if not m:
        return "this installation carries no precompiled code"
    why = versions_refusal(m)
    if why:
        return why
    try:
        here = cpu_key()
    except Exception as exc:  # noqa: BLE001
        return f"numba cannot describe this CPU ({exc})"
    if m.get("cpu") != here:
        return (f"the precompiled code was built for another CPU ({m.get('cpu', ['?', '?'])[1]}; this one is "
                f"{here[1]})")
    if m.get("sources") != sources_stamp():
        return "the sources differ from those the precompiled code was built from"
    return ""


_stamp_cache: dict = {}


def sources_stamp() -> str:
    """Digest of the package's Python sources (path and content; the bundled data left out), the Python and
    numba versions: any change makes every compiled-layout marker (:mod:`shevsim.warmup`) stale, as numba's
    cache is (the loop inlines the component kernels).  Content, not mtimes: ``pip install`` does not keep them,
    and the precompiled cache a wheel ships is matched by this stamp."""
    root = Path(__file__).resolve().parent.parent
    if root in _stamp_cache:
        return _stamp_cache[root]
    import numba
    h = hashlib.sha256()
    h.update(f"{sys.version_info[:2]} numba {numba.__version__}".encode())
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root)
        if rel.parts[0] in ("_data", "_jitcache"):
            continue
        try:
            h.update(f"{rel.as_posix()}:{file_stamp(p)}\n".encode())
        except OSError:
            continue
    _stamp_cache[root] = h.hexdigest()[:16]
    return _stamp_cache[root]
