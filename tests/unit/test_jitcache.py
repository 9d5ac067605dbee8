"""Issue 26 item 1, compiled ahead of time: numba's cache locator for shevsim (content stamps, the user's cache,
seeded from the precompiled cache a wheel ships), when shipped code is used and when it is not (changed source,
another CPU), the engine choice and the on-screen notice that follow, and the build hook's fallback.

The locator is exercised on a one-line compiled function in a generated-loop file (the locator's second kind of
file), so no test here compiles shevsim's models; the wheel round trip is in test_packaging.py (slow)."""
from __future__ import annotations

import importlib.util
import io
import json
import os
import shutil
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from shevsim import warmup
from shevsim.core import jitcache
from shevsim.core.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
NAME = "shevsim_loop_" + "ab" * 10 + ".py"        # the name of a generated fast loop: the locator takes it
SRC = '''from numba import njit


@njit(cache=True)
def scaled(x):
    return 2.5 * x
'''
_n = [0]


def _import(path: Path):
    _n[0] += 1
    spec = importlib.util.spec_from_file_location(f"jitcache_probe_{_n[0]}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _write(folder: Path, text: str = SRC, mtime: float | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / NAME
    p.write_text(text)
    if mtime is not None:
        os.utime(p, (mtime, mtime))
    return p


def _counts(dispatcher) -> tuple[int, int]:
    st = dispatcher.stats
    return sum(st.cache_hits.values()), sum(st.cache_misses.values())


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def shipped(tmp_path, monkeypatch):
    """A 'wheel build': the probe compiled with SHEVSIM_JITCACHE_BUILD into tmp/ship (the shipped layout); then
    the 'installation': SHIPPED points there, an empty user cache, the build variable unset."""
    ship = tmp_path / "ship"
    monkeypatch.setenv(jitcache.BUILD_ENV, str(ship))
    mod = _import(_write(tmp_path / "build"))
    assert mod.scaled(2.0) == 5.0
    assert _counts(mod.scaled) == (0, 1)                      # compiled at 'build time'
    assert list((ship / jitcache.LOOP_FOLDER).glob("*.nbi"))  # ... into the shipped layout
    monkeypatch.delenv(jitcache.BUILD_ENV)
    jitcache.write_manifest(ship, [], "0123456789abcdef", 1)   # as the build writes it (this numba/numpy/Python)
    monkeypatch.setattr(jitcache, "SHIPPED", ship)
    monkeypatch.setenv("SHEVSIM_CACHE_DIR", str(tmp_path / "user"))
    monkeypatch.setattr(jitcache, "_seeded", set())
    return ship


# ------------------------------------------------------------------------------------ the source stamp
def test_stamp_is_the_content_not_the_mtime(tmp_path):
    p = _write(tmp_path / "a", mtime=1_600_000_000)
    s1 = jitcache.file_stamp(p)
    os.utime(p, (1_700_000_000, 1_700_000_000))          # pip install sets new mtimes: same code, same stamp
    assert jitcache.file_stamp(p) == s1
    q = _write(tmp_path / "b", mtime=1_600_000_000)      # a copy elsewhere (another installation)
    assert jitcache.file_stamp(q) == s1
    p.write_text(SRC.replace("2.5", "3.5"))              # same size, other content
    os.utime(p, (1_700_000_000, 1_700_000_000))
    assert p.stat().st_size == q.stat().st_size and jitcache.file_stamp(p) != s1


def test_user_cache_folder(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("SHEVSIM_CACHE_DIR", str(tmp_path / "c"))
    assert jitcache.user_root() == tmp_path / "c" / "shevsim" / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nb"))          # numba's own setting wins
    assert jitcache.user_root() == tmp_path / "nb" / "shevsim"


def test_import_shevsim_stays_light_and_the_locator_comes_with_numba():
    code = ("import sys, shevsim; light = 'numba' not in sys.modules; "
            "import shevsim.components.battery as b, numba; "
            "d = next(v for v in vars(b).values() if isinstance(v, numba.core.dispatcher.Dispatcher)); "
            "print(light, type(d._cache._impl.locator).__name__)")
    import subprocess
    for pre in ("", "import numba; "):              # shevsim first, or numba imported before shevsim
        r = subprocess.run([sys.executable, "-c", pre + code], capture_output=True, text=True, timeout=300,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert r.returncode == 0, r.stderr
        assert r.stdout.split() == [str(not pre), "ShevsimLocator"], (pre, r.stdout)


def test_a_callees_edit_makes_the_callers_cache_stale(tmp_path, monkeypatch):
    """numba copies a callee's machine code into its caller's cache entry: the caller's stamp covers every
    shevsim module its file imports, transitively (an upgrade or edit of powertrain/motor.py must not leave the
    component step in components/motor.py on the old physics)."""
    pkg = tmp_path / "shevsim"
    (pkg / "powertrain").mkdir(parents=True)
    (pkg / "components").mkdir()
    for d in (pkg, pkg / "powertrain", pkg / "components"):
        (d / "__init__.py").write_text("")
    (pkg / "powertrain" / "motor.py").write_text("from ..core import lookup\ndef g(x):\n    return x\n")
    (pkg / "core").mkdir()
    (pkg / "core" / "__init__.py").write_text("")
    (pkg / "core" / "lookup.py").write_text("K = 1\n")
    (pkg / "unrelated.py").write_text("Z = 0\n")
    caller = pkg / "components" / "motor.py"
    caller.write_text("import numpy as np\nfrom shevsim.powertrain import motor as _m\n"
                      "def f(x):\n    from ..unrelated import Z\n    return _m.g(x) + Z\n")
    monkeypatch.setattr(jitcache, "PKG_ROOT", pkg)
    names = {Path(f).relative_to(pkg).as_posix() for f in jitcache._import_closure(str(caller))}
    assert names == {"components/motor.py", "powertrain/motor.py", "core/lookup.py", "unrelated.py",
                     "powertrain/__init__.py", "core/__init__.py"}, names
    s0 = jitcache.closure_stamp(caller)
    callee = pkg / "powertrain" / "motor.py"
    st = callee.stat()
    os.utime(callee, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))          # new mtime, same content (pip)
    assert jitcache.closure_stamp(caller) == s0
    (pkg / "core" / "lookup.py").write_text("K = 2\n")                      # two imports down
    s1 = jitcache.closure_stamp(caller)
    assert s1 != s0
    callee.write_text("from ..core import lookup\ndef g(x):\n    return 2 * x\n")
    assert jitcache.closure_stamp(caller) not in (s0, s1)
    # the real package: the motor component's step depends on the motor physics
    monkeypatch.undo()
    real = {Path(f).resolve().relative_to(jitcache.PKG_ROOT).as_posix()
            for f in jitcache._import_closure(str(jitcache.PKG_ROOT / "components" / "motor.py"))}
    assert {"powertrain/motor.py", "core/compiled.py"} <= real, sorted(real)


def test_locator_takes_shevsims_files_only(tmp_path):
    assert jitcache.relative_folder(jitcache.PKG_ROOT / "components" / "battery.py") == "components"
    assert jitcache.relative_folder(jitcache.PKG_ROOT / "warmup.py") == "."
    assert jitcache.relative_folder(tmp_path / NAME) == jitcache.LOOP_FOLDER
    assert jitcache.relative_folder(tmp_path / "user_code.py") is None      # a user's own njit: numba's locators
    assert jitcache.relative_folder(jitcache.PKG_ROOT / "_data" / "x.py") is None
    import shevsim.components.battery as b
    step = next(v for v in vars(b).values() if isinstance(v, numba.core.dispatcher.Dispatcher))
    loc = step._cache._impl.locator
    assert type(loc).__name__ == "ShevsimLocator"
    assert loc.get_source_stamp() == jitcache.closure_stamp(b.__file__)
    assert not Path(loc.get_cache_path()).resolve().is_relative_to(jitcache.PKG_ROOT)   # never into the package


# ------------------------------------------------------------------------------------ shipped -> loaded
def test_shipped_code_loads_without_compiling_and_the_package_stays_untouched(shipped, tmp_path):
    before = _snapshot(shipped)
    # installed elsewhere, with other mtimes (as pip leaves them)
    mod = _import(_write(tmp_path / "site", mtime=1_500_000_000))
    assert mod.scaled(2.0) == 5.0
    assert _counts(mod.scaled) == (1, 0)                      # loaded, not compiled
    user = tmp_path / "user" / "shevsim" / "numba"
    assert list(user.rglob("*.nbi")) and list(user.rglob("*.nbc"))
    assert _snapshot(shipped) == before                       # read only: nothing written into the shipped cache
    # a second process (a fresh import) loads from the user's copy
    jitcache._seeded.clear()
    again = _import(tmp_path / "site" / NAME)
    assert again.scaled(4.0) == 10.0 and _counts(again.scaled) == (1, 0)


def test_a_changed_source_never_loads_the_shipped_code(shipped, tmp_path):
    # same function, same bytecode, one comment more: the file's stamp differs, so the shipped index is stale
    mod = _import(_write(tmp_path / "site", SRC + "# edited after the build\n"))
    assert mod.scaled(2.0) == 5.0
    assert _counts(mod.scaled) == (0, 1)                      # compiled
    user = tmp_path / "user" / "shevsim" / "numba"
    for idx in user.rglob("*.nbi"):                           # the user's index carries the edited file's stamp
        assert jitcache.read_index(idx)[1] == jitcache.closure_stamp(tmp_path / "site" / NAME)
    # and code that changes behaviour is compiled from the new source, not taken from the cache
    jitcache._seeded.clear()
    mod2 = _import(_write(tmp_path / "site2", SRC.replace("2.5", "4.0")))
    assert mod2.scaled(2.0) == 8.0 and _counts(mod2.scaled) == (0, 1)


def test_another_cpu_compiles_on_first_use(shipped, tmp_path):
    # rewrite the shipped entries as if built on another CPU model (numba's key holds the CPU name/features)
    for idx in shipped.rglob("*.nbi"):
        version, stamp, overloads = jitcache.read_index(idx)
        moved = {(k[0], (k[1][0], "some-other-cpu", "+sse2"), k[2]): v for k, v in overloads.items()}
        jitcache._write_index(idx, stamp, moved)
    mod = _import(_write(tmp_path / "site"))
    assert mod.scaled(2.0) == 5.0
    assert _counts(mod.scaled) == (0, 1)                      # a miss: compiled, correct
    jitcache._seeded.clear()
    again = _import(tmp_path / "site" / NAME)                 # ... and cached for the next process
    assert again.scaled(1.0) == 2.5 and _counts(again.scaled) == (1, 0)


def test_another_numba_version_is_not_read(shipped, tmp_path):
    for idx in shipped.rglob("*.nbi"):
        data = idx.read_bytes()
        import pickle
        ver = pickle.dumps(numba.__version__, protocol=-1)
        assert data.startswith(ver)
        idx.write_bytes(pickle.dumps("0.0.1", protocol=-1) + data[len(ver):])
        assert jitcache.read_index(idx)[:2] == ("0.0.1", None)
    mod = _import(_write(tmp_path / "site"))
    assert mod.scaled(2.0) == 5.0 and _counts(mod.scaled) == (0, 1)


@pytest.mark.parametrize("key", ["numpy", "python", None])
def test_a_shipped_cache_of_another_numpy_or_python_is_not_seeded(shipped, tmp_path, key):
    """The build environment resolves the newest numba/numpy; a runtime environment may hold older ones: a
    manifest naming another numpy or Python (or none at all) leaves the shipped entries unused (compiled)."""
    m = json.loads((shipped / jitcache.MANIFEST).read_text())
    assert m["numpy"] == np.__version__ and m["numba"] == numba.__version__ and m["cpu"] == jitcache.cpu_key()
    if key is None:
        (shipped / jitcache.MANIFEST).unlink()
    else:
        m[key] = "1.0" if key == "python" else "1.26.0.dev0"
        (shipped / jitcache.MANIFEST).write_text(json.dumps(m))
        jitcache.shipped_status.cache_clear()
        assert f"{key} {m[key]}" in jitcache.shipped_status()
        jitcache.shipped_status.cache_clear()
    mod = _import(_write(tmp_path / "site"))
    assert mod.scaled(2.0) == 5.0 and _counts(mod.scaled) == (0, 1)      # compiled, nothing seeded
    jitcache.shipped_status.cache_clear()


# ------------------------------------------------------------------------------------ manifest -> engine
@pytest.fixture
def manifest(tmp_path, monkeypatch):
    monkeypatch.setenv("SHEVSIM_WARMUP_DIR", str(tmp_path / "warmup"))      # no markers of this machine
    ship = tmp_path / "ship"
    ship.mkdir()
    monkeypatch.setattr(jitcache, "SHIPPED", ship)
    jitcache.shipped_status.cache_clear()
    sc = load_scenario("hd_udds_rule")
    sc.set("scenario.stop_s", 20.0)
    jitcache.write_manifest(ship, [warmup.layout_of(sc)], warmup._sources_stamp(), 1)
    yield ship, sc
    jitcache.shipped_status.cache_clear()


def _edit_manifest(ship, **kw):
    m = json.loads((ship / jitcache.MANIFEST).read_text())
    m.update(kw)
    (ship / jitcache.MANIFEST).write_text(json.dumps(m))
    jitcache.shipped_status.cache_clear()


def test_a_shipped_loop_is_taken_only_where_it_fits(manifest):
    ship, sc = manifest
    assert jitcache.shipped_status() == ""
    assert warmup.is_shipped(sc) and warmup.is_compiled(sc) and warmup.choose(sc, 200, 11) == (True, "")
    assert not warmup.is_shipped(load_scenario("hd_udds_mpc"))   # another layout: not in the manifest
    cpu = jitcache.cpu_key()
    _edit_manifest(ship, cpu=[cpu[0], "some-other-cpu", ""])
    assert "another CPU (some-other-cpu; this one is" in jitcache.shipped_status()
    assert not warmup.is_compiled(sc)
    use, why = warmup.choose(sc, 200, 11)                        # -> the master, the loop built in the background
    assert not use and why
    _edit_manifest(ship, cpu=cpu, numba="0.0.1")
    assert "numba 0.0.1" in jitcache.shipped_status() and not warmup.is_compiled(sc)
    _edit_manifest(ship, numba=numba.__version__, sources="0123456789abcdef")
    assert "sources differ" in jitcache.shipped_status() and not warmup.is_compiled(sc)
    (ship / jitcache.MANIFEST).unlink()
    jitcache.shipped_status.cache_clear()
    assert "no precompiled code" in jitcache.shipped_status() and not warmup.is_compiled(sc)


def test_the_compile_notice_says_why_the_shipped_code_does_not_serve(manifest):
    ship, _ = manifest
    cpu = jitcache.cpu_key()
    _edit_manifest(ship, cpu=[cpu[0], "some-other-cpu", ""])

    def inc(x):
        return x + 1
    inc.__module__ = "shevsim.probe"                       # the notice reports shevsim's compilations only
    buf = io.StringIO()
    with warmup.CompileNotice(stream=buf):
        assert numba.njit(inc)(1) == 2
    text = buf.getvalue()
    assert text.startswith("shevsim: compiling on first use, cached afterwards: the precompiled code was built "
                           "for another CPU (some-other-cpu"), text
    assert "compiling the shevsim.probe (inc; first use" in text or "compiling the probe (inc;" in text, text


def test_the_markers_stamp_follows_content(monkeypatch):
    """The markers' stamp is the sources' content: the same for a copy with new mtimes (pip), new on an edit."""
    monkeypatch.setattr(jitcache, "_stamp_cache", {})
    a = jitcache.sources_stamp()
    p = jitcache.PKG_ROOT / "version.py"
    st = p.stat()
    try:
        os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
        monkeypatch.setattr(jitcache, "_stamp_cache", {})
        assert jitcache.sources_stamp() == a
    finally:
        os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))


# ------------------------------------------------------------------------------------ the build hook
def test_build_hook_without_numba_builds_without_the_cache_and_says_so(tmp_path, monkeypatch):
    sys.path.insert(0, str(ROOT))
    try:
        import hatch_build
    finally:
        sys.path.remove(str(ROOT))
    said = []
    monkeypatch.delenv("SHEVSIM_PRECOMPILE", raising=False)
    fake = tmp_path / "python-without-numba"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    out = hatch_build.build_cache(ROOT, tmp_path / "w", lambda m, warn=False: said.append((m, warn)),
                                  cands=[str(fake), str(tmp_path / "missing-python")])
    assert out is None and not (tmp_path / "w" / "_jitcache").exists()
    assert said and said[-1][1] and "WITHOUT precompiled code" in said[-1][0] and str(fake) in said[-1][0]
    monkeypatch.setenv("SHEVSIM_PRECOMPILE", "0")
    said.clear()
    assert hatch_build.build_cache(ROOT, tmp_path / "w", lambda m, warn=False: said.append(m)) is None
    assert "SHEVSIM_PRECOMPILE=0" in said[0]
    # the interpreter of this session has numba: it is found (pip's isolation variables removed)
    monkeypatch.setenv("PYTHONNOUSERSITE", "1")
    assert hatch_build.find_python([str(fake), sys.executable], hatch_build.clean_env(str(ROOT))) == sys.executable
    assert "PYTHONNOUSERSITE" not in hatch_build.clean_env(str(ROOT))


def test_build_hook_says_what_it_could_not_precompile(tmp_path, monkeypatch):
    """A precompile that skipped a part (a scenario or loop that failed) still ships what it made, and the
    build says, as a warning, which parts will compile on first use."""
    sys.path.insert(0, str(ROOT))
    try:
        import hatch_build
    finally:
        sys.path.remove(str(ROOT))
    monkeypatch.delenv("SHEVSIM_PRECOMPILE", raising=False)
    fake = tmp_path / "python-partial"
    fake.write_text('#!/bin/sh\nif [ "$#" -eq 2 ]; then exit 0; fi\nfor a; do last="$a"; done\necho "{}" > "$last/manifest.json"\n'
                    'echo "precompile: loop hd_udds_mpc skipped (TypingError: boom)"\n'
                    'echo "precompiled 3 function caches"\n')
    fake.chmod(0o755)
    said = []
    out = hatch_build.build_cache(ROOT, tmp_path / "w", lambda m, warn=False: said.append((m, warn)),
                                  cands=[str(fake)])
    assert out is not None and (out / "manifest.json").is_file()
    warns = [m for m, w in said if w]
    assert len(warns) == 1 and "loop hd_udds_mpc skipped (TypingError: boom)" in warns[0], said
    assert said[-1] == ("precompiled 3 function caches", False)


def test_build_hook_compiles_inside_the_isolated_build_environment(tmp_path, monkeypatch):
    """pip's isolated build: the build's own interpreter is tried first with pip's isolation variables kept
    (its build environment holds numba from [build-system] requires), the checkout first on the path; the
    undone-isolation search only after; $SHEVSIM_BUILD_PYTHON before both."""
    sys.path.insert(0, str(ROOT))
    try:
        import hatch_build
    finally:
        sys.path.remove(str(ROOT))
    monkeypatch.delenv("SHEVSIM_BUILD_PYTHON", raising=False)
    monkeypatch.setenv("PYTHONNOUSERSITE", "1")
    monkeypatch.setenv("PYTHONPATH", "/tmp/pip-build-env-x/site")
    monkeypatch.setenv("NUMBA_CPU_NAME", "generic")
    tries = hatch_build.attempts(str(ROOT))
    py, env = tries[0]
    assert py == sys.executable and env["PYTHONNOUSERSITE"] == "1" and "NUMBA_CPU_NAME" not in env
    assert env["PYTHONPATH"].split(os.pathsep) == [str(ROOT), "/tmp/pip-build-env-x/site"]
    assert all("PYTHONNOUSERSITE" not in e and e["PYTHONPATH"] == str(ROOT) for _, e in tries[1:])
    monkeypatch.setenv("SHEVSIM_BUILD_PYTHON", "/opt/py/bin/python")
    tries = hatch_build.attempts(str(ROOT))
    assert tries[0][0] == "/opt/py/bin/python" and "PYTHONNOUSERSITE" not in tries[0][1]
    assert tries[1][0] == sys.executable and tries[1][1]["PYTHONNOUSERSITE"] == "1"
    assert [p for p, _ in tries].count("/opt/py/bin/python") == 1
    # pyproject: the build environment gets numba and what the probe imports, with the runtime constraints
    import tomllib
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    req = {r.split(">")[0]: r for r in cfg["build-system"]["requires"]}
    deps = {r.split(">")[0]: r for r in cfg["project"]["dependencies"]}
    for name in hatch_build.PROBE.removeprefix("import ").split(", "):
        assert req[name] == deps[name], name


def test_editable_build_replaces_the_in_tree_cache_only_with_a_new_one(tmp_path):
    sys.path.insert(0, str(ROOT))
    try:
        import hatch_build
    finally:
        sys.path.remove(str(ROOT))
    root = tmp_path / "checkout"
    (root / "shevsim" / "_jitcache").mkdir(parents=True)
    (root / "shevsim" / "_jitcache" / "old.nbi").write_text("old")
    new = tmp_path / "w" / "_jitcache"
    new.mkdir(parents=True)
    (new / "manifest.json").write_text("{}")
    out = hatch_build.install_in_tree(new, root)
    assert out == root / "shevsim" / "_jitcache" and sorted(p.name for p in out.iterdir()) == ["manifest.json"]
    assert sorted(p.name for p in (root / "shevsim").iterdir()) == ["_jitcache"]      # no leftover


def test_build_refuses_a_destination_it_was_not_told_about(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv(jitcache.BUILD_ENV, raising=False)
    assert warmup.build_shipped_cache(tmp_path / "_jitcache") == 2
    assert jitcache.BUILD_ENV in capsys.readouterr().err


def test_warmup_command_compiles_ahead_and_marks_the_default_loop(tmp_path, monkeypatch, capsys):
    """`shevsim warmup NAME`: the steps of that scenario and the default scenario's loop, cached (in this test
    session they are compiled already: this checks the command, not the compile time)."""
    from shevsim.cli import main
    monkeypatch.setenv("SHEVSIM_WARMUP_DIR", str(tmp_path / "warmup"))
    monkeypatch.setattr(jitcache, "SHIPPED", tmp_path / "none")
    jitcache.shipped_status.cache_clear()
    mpc = load_scenario("hd_udds_mpc")
    assert not warmup.is_compiled(mpc)
    assert main(["warmup", "hd_udds_rule"]) == 0
    out, err = capsys.readouterr()
    assert "precompiling the component steps of hd_udds_rule" in err and "fast loop of hd_udds_mpc" in err
    assert "compiled code for 1 scenario(s) and 1 fast loop(s) is cached in" in out
    assert warmup.is_compiled(mpc)
    assert main(["warmup", "no_such_scenario"]) == 2
    jitcache.shipped_status.cache_clear()


NRT_PROBE = """
import numpy as np
from numba import njit, types
import shevsim
from shevsim.supervisor import daqp_nb

def probe(ws, qp, res, sense, x, lam, flags, H, f, A, bu, bl):
    return daqp_nb.solve(ws, qp, res, sense, x, lam, flags, H, f, A, bu, bl)

i64, f64 = types.int64[::1], types.float64[::1]
sig = (i64, i64, i64, types.int32[::1], f64, f64, i64, types.float64[:, ::1], f64, types.float64[:, ::1], f64, f64)
njit(_nrt=False)(probe).compile(sig)       # as a step compiled by core.compiled.njit_step calls it
print("compiled")
"""


def test_daqp_binding_compiles_fresh_inside_a_step_without_numbas_runtime(tmp_path):
    """With an empty cache, the DAQP binding compiles as a callee of a step built without numba's reference
    counting (a callee compiled that way may not allocate; a warm cache had hidden an allocation there, so
    a new installation's MPC runs failed to compile)."""
    import subprocess
    r = subprocess.run([sys.executable, "-c", NRT_PROBE], capture_output=True, text=True, timeout=600,
                       env={**os.environ, "PYTHONPATH": str(ROOT), "SHEVSIM_CACHE_DIR": str(tmp_path / "fresh")})
    assert r.returncode == 0 and r.stdout.strip() == "compiled", r.stderr[-3000:]
