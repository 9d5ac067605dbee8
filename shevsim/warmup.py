"""warmup.py - when the compiled fast loop is built, and which engine runs meanwhile.

The fast path (:mod:`shevsim.fast`) is one numba-compiled loop whose machine code depends on the
scenario's component layout (how many components of each type): building it takes 15-40 s of CPU the first
time a layout is used (numba caches it on disk afterwards).  The Python master steps the same compiled
component steps (:mod:`shevsim.core.master`) and needs no loop, so for a run that is short on the master a
user should not wait for the loop.  ``engine="auto"`` therefore decides as follows (:func:`choose`):

1. the loop of this layout is known to be compiled (:func:`is_compiled`: a fast run or a warm-up of this
   layout finished since the sources last changed, or the installation ships it precompiled for this
   machine, :func:`is_shipped`) -> the fast path;
2. else, when the run is estimated to take less on the master than building the loop
   (``steps x components x`` :data:`MASTER_STEP_S` ``<`` :data:`LOOP_BUILD_S`) -> the Python master, and
   when it has finished, a background process (:func:`start_background`, niced, detached) builds this
   layout's loop so that later runs take the fast path;
3. else (a long run) -> the fast path, compiled in the foreground with a message.

:func:`precompile` compiles ahead of time (``shevsim warmup``; at wheel build time, ``hatch_build.py`` runs
:func:`build_shipped_cache`, whose result the wheel ships: :mod:`shevsim.core.jitcache`).
Whatever compiles in the foreground says so on screen (:class:`CompileNotice`, a listener on numba's
compile events, used by ``shevsim run``).  ``SHEVSIM_BACKGROUND_COMPILE=0`` turns the background build
off (the test suite does); the markers live beside the compiled loops in the user cache folder
(:func:`state_dir`).
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

log = logging.getLogger(__name__)

#: wall time of one component step on the Python master (s), for the run-time estimate (hd_udds_mpc:
#: 21,200 steps x 11 components in ~3 s)
MASTER_STEP_S = 15e-6
#: CPU time to build the fast loop for a new layout (s), what a run on the master is weighed against
LOOP_BUILD_S = 30.0
#: a warm-up lock older than this is stale (its process died)
LOCK_STALE_S = 900.0
_MARKERS = "compiled_layouts.json"


def background_enabled() -> bool:
    """False when ``SHEVSIM_BACKGROUND_COMPILE`` is ``0``/``false``/``no``/``off``."""
    return os.environ.get("SHEVSIM_BACKGROUND_COMPILE", "1").strip().lower() not in ("0", "false", "no", "off")


def state_dir() -> Path:
    """Where the compiled-layout markers and warm-up locks live (created): beside the compiled loops
    (:mod:`shevsim.fast.loop` keeps them in ``$SHEVSIM_CACHE_DIR``, ``$XDG_CACHE_HOME/shevsim`` or
    ``~/.cache/shevsim``), so removing that folder forgets both; ``SHEVSIM_WARMUP_DIR`` overrides."""
    from .core.paths import writable_cache_subdir
    env = os.environ.get("SHEVSIM_WARMUP_DIR")
    return writable_cache_subdir("warmup", Path(env) if env else None) or Path(tempfile.gettempdir())


def _sources_stamp() -> str:
    """:func:`shevsim.core.jitcache.sources_stamp` (the markers are matched by it)."""
    from .core.jitcache import sources_stamp
    return sources_stamp()


def layout_of(scenario) -> str:
    """The component layout of a scenario: ``"battery:1,bms:1,..."`` (types and their counts)."""
    counts = Counter(str(c.type) for c in scenario.components)
    return ",".join(f"{t}:{n}" for t, n in sorted(counts.items()))


def layout_key(scenario) -> str:
    return hashlib.sha256(f"{layout_of(scenario)}|{_sources_stamp()}".encode()).hexdigest()[:20]


def _read_markers() -> dict:
    try:
        return json.loads((state_dir() / _MARKERS).read_text())
    except (OSError, ValueError):
        return {}


def is_compiled(scenario) -> bool:
    """True when this scenario's layout was compiled by a fast run or a warm-up since the sources changed, or
    its loop is in the precompiled cache this installation ships and that cache fits this machine
    (:func:`shevsim.core.jitcache.shipped_status`)."""
    if _read_markers().get(layout_key(scenario), {}).get("ok", False):
        return True
    return is_shipped(scenario)


def is_shipped(scenario) -> bool:
    """This layout's loop is in the shipped precompiled cache, and that cache can be loaded here."""
    from .core import jitcache
    try:
        return layout_of(scenario) in jitcache.manifest().get("layouts", ()) and jitcache.shipped_status() == ""
    except Exception as exc:  # noqa: BLE001 - a damaged manifest only costs a compile
        log.debug("shipped cache not usable: %s", exc)
        return False


def mark_compiled(scenario, ok: bool = True) -> None:
    """Record that this layout's loop is compiled (``ok=False``: that building it failed, so no warm-up
    retries it until the sources change); best effort: never fails a run."""
    try:
        d = state_dir()
        marks = _read_markers()
        marks[layout_key(scenario)] = {"layout": layout_of(scenario), "at": time.time(), "ok": bool(ok)}
        fd, tmp = tempfile.mkstemp(dir=d, prefix=".markers")
        with os.fdopen(fd, "w") as f:
            json.dump(marks, f)
        os.replace(tmp, d / _MARKERS)
    except OSError as exc:          # a read-only cache folder: the next run decides again
        log.debug("cannot record the compiled layout: %s", exc)


def choose(scenario, n_steps: int, n_components: int) -> tuple[bool, str]:
    """``(use_fast, why)`` for ``engine="auto"`` on a scenario the fast path can run (see module docstring)."""
    if is_compiled(scenario):
        return True, ""
    est = n_steps * max(1, n_components) * MASTER_STEP_S
    if est < LOOP_BUILD_S:
        return False, (f"the compiled loop for this component layout is not built yet (~{LOOP_BUILD_S:.0f} s "
                       f"of CPU once); the Python master takes ~{est:.2g} s for this run")
    return True, ""


def _lock_path(scenario) -> Path:
    return state_dir() / f"warmup-{layout_key(scenario)}.lock"


def warmup_running(scenario) -> bool:
    """A background build of this layout is in progress (a fresh lock file)."""
    p = _lock_path(scenario)
    try:
        return time.time() - p.stat().st_mtime < LOCK_STALE_S
    except OSError:
        return False


def start_background(scenario) -> int | None:
    """Start a detached, niced process that builds this layout's fast loop; returns its pid, or None when
    off, already running or not possible.  Nothing is written outside :func:`state_dir`."""
    if not background_enabled() or layout_key(scenario) in _read_markers() or warmup_running(scenario):
        return None
    import pickle
    d = state_dir()
    lock = _lock_path(scenario)
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:         # stale: take it over
        try:
            lock.unlink()
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except OSError:
            return None
    except OSError:
        return None
    try:
        sc_file = d / f"warmup-{layout_key(scenario)}.pickle"
        sc_file.write_bytes(pickle.dumps(scenario))
        logf = open(d / "warmup.log", "ab")
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parent.parent)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        p = subprocess.Popen([sys.executable, "-m", "shevsim.warmup", str(sc_file), str(lock)],
                             stdin=subprocess.DEVNULL, stdout=logf, stderr=logf, env=env,
                             start_new_session=True, close_fds=True)
        logf.close()
        os.write(fd, str(p.pid).encode())
        return p.pid
    except Exception as exc:  # noqa: BLE001 - a warm-up that cannot start never fails the run
        log.debug("background compile not started: %s", exc)
        try:
            lock.unlink()
        except OSError:
            pass
        return None
    finally:
        os.close(fd)


def warm(scenario) -> float:
    """Build (or load from numba's cache) the fast loop for ``scenario``'s layout in this process by running
    one communication step; mark the layout compiled; return the wall time (s)."""
    from .fast import runner_for
    t = time.perf_counter()
    sc = scenario.copy()
    runner, why = runner_for(sc)
    if runner is None:
        raise RuntimeError(f"not eligible for the fast path: {why}")
    runner(float(sc.t0_s) + float(sc.settings.step_s))
    mark_compiled(scenario)
    return time.perf_counter() - t


# --------------------------------------------------------------------------- compiling ahead of time
#: the scenarios whose fast loop :func:`precompile` builds by default (the default scenario of ``shevsim run``)
PRECOMPILE_LOOPS = ("hd_udds_mpc",)


def precompile(scenarios=None, loops=PRECOMPILE_LOOPS, stream=None, mark: bool = True) -> dict:
    """Compile ahead of time what runs need: every compiled component step the Python master calls in the
    bundled scenarios (one communication step of each scenario without FMUs, so each step compiles with the
    signature a run uses) and the fast loop of the ``loops`` scenarios' layouts.  numba caches the code
    (:mod:`shevsim.core.jitcache`: the user's cache, or with ``SHEVSIM_JITCACHE_BUILD`` set, the cache a wheel
    ships).  ``mark``: record the built layouts as compiled (:func:`mark_compiled`).  Prints one line per
    scenario (and :class:`CompileNotice`'s lines) to ``stream``; returns ``{"scenarios": [...], "layouts": [...],
    "failed": {name: reason}, "wall_s": ...}``."""
    from .core.paths import bundled_scenarios
    from .core.scenario import build_master, load_scenario
    stream = stream if stream is not None else sys.stderr
    t0 = time.perf_counter()
    names = list(scenarios) if scenarios is not None else bundled_scenarios()
    done, failed, layouts = [], {}, []
    with CompileNotice(stream=stream):
        for name in names:
            try:
                sc = load_scenario(name)
                if any(c.type == "fmu" for c in sc.components):
                    continue                                    # FMUs run their own code
                sc.faults = []                                  # a fault due later would refuse the run
                sc.set("scenario.stop_s", float(sc.t0_s) + float(sc.settings.step_s))
                stream.write(f"precompiling the component steps of {name} ...\n")
                stream.flush()
                master = build_master(sc)               # the Python master, one step: what simulate(
                try:                                    # engine="python") does, without metrics or files
                    master.run(float(sc.t0_s) + float(sc.settings.step_s), t0=sc.t0_s)
                finally:
                    master.terminate()
                done.append(name)
            except Exception as exc:  # noqa: BLE001 - one scenario that cannot run does not stop the others
                failed[name] = f"{type(exc).__name__}: {exc}"
        for name in loops or ():
            try:
                sc = load_scenario(name)
                stream.write(f"precompiling the fast loop of {name}'s layout ({layout_of(sc)}) ...\n")
                stream.flush()
                from .fast import runner_for
                runner, why = runner_for(sc.copy())
                if runner is None:
                    raise RuntimeError(f"not eligible for the fast path: {why}")
                runner(float(sc.t0_s) + float(sc.settings.step_s))
                layouts.append(layout_of(sc))
                if mark:
                    mark_compiled(sc)
            except Exception as exc:  # noqa: BLE001
                failed[f"loop {name}"] = f"{type(exc).__name__}: {exc}"
    for k, v in failed.items():
        stream.write(f"precompile: {k} skipped ({v})\n")
    return {"scenarios": done, "layouts": layouts, "failed": failed, "wall_s": time.perf_counter() - t0}


def build_shipped_cache(dest) -> int:
    """``python -m shevsim.warmup --build DEST``: precompile into ``DEST`` (the ``_jitcache`` folder a wheel
    ships; ``SHEVSIM_JITCACHE_BUILD`` must name it before shevsim is imported) and write its manifest.
    Exit 0 with a manifest, 1 when nothing could be compiled."""
    from .core import jitcache
    dest = Path(dest)
    if Path(os.environ.get(jitcache.BUILD_ENV, "")).resolve() != dest.resolve():
        print(f"{jitcache.BUILD_ENV} must name {dest} before shevsim is imported", file=sys.stderr)
        return 2
    out = precompile(mark=False, stream=sys.stdout)
    n = len(list(dest.rglob("*.nbi")))
    if not n:
        print("nothing was compiled: no precompiled cache", file=sys.stdout)
        return 1
    m = jitcache.write_manifest(dest, out["layouts"], _sources_stamp(), n)
    size = sum(p.stat().st_size for p in dest.rglob("*") if p.is_file())
    print(f"precompiled {n} function caches ({size / 1e6:.1f} MB) for numba {m['numba']}, Python {m['python']}, "
          f"CPU {m['cpu'][1]}; loops: {', '.join(m['layouts']) or 'none'}; {out['wall_s']:.0f} s", flush=True)
    return 0


# --------------------------------------------------------------------------- messages while compiling
_FRIENDLY = {"components.supervisors": "supervisor", "components.battery": "battery",
             "components.bms": "BMS", "components.engine_generator": "engine-generator",
             "components.vehicle": "vehicle", "components.motor": "motor", "components.driver": "driver",
             "components.bus": "power bus", "components.cycle": "drive cycle",
             "supervisor.daqp_nb": "QP solver binding (DAQP)", "supervisor.mpc": "MPC supervisor", "supervisor.rule_based": "rule-based supervisor",
             "battery": "battery model", "bms": "BMS estimators", "powertrain.engine": "engine-generator",
             "powertrain.motor": "motor", "powertrain.vehicle": "vehicle", "powertrain.driver": "driver",
             "core.lookup": "table lookups",
             "fast.daqp_nb": "QP solver binding (DAQP)", "fast.kernels": "fast-path kernels",
             "fast": "compiled fast loop"}


def _friendly(module: str) -> str:
    mod = module.removeprefix("shevsim.")
    for k, v in _FRIENDLY.items():
        if mod == k or mod.startswith(k + "."):
            return v
    return mod


class CompileNotice:
    """Context manager: while it is active, every top-level numba compilation of shevsim code prints one line
    to ``stream`` (stderr) when it starts and the time when it ends, so a first run never waits in silence::

        compiling the MPC supervisor (mpc_move; first use, cached afterwards) ... 8.1 s
    """

    def __init__(self, stream=None, enabled: bool = True, prefix: str = "shevsim"):
        self.stream = stream if stream is not None else sys.stderr
        self.prefix = prefix
        self.enabled = enabled
        self._depth = 0
        self._t0 = 0.0
        self._listener = None
        self.count = 0
        self.total_s = 0.0

    def __enter__(self):
        if not self.enabled:
            return self
        try:
            from numba.core import event as ev
        except ImportError:
            return self
        notice = self

        class _L(ev.Listener):
            def on_start(self, e):
                notice._start(e)

            def on_end(self, e):
                notice._end(e)

        self._listener = _L()
        ev.register("numba:compile", self._listener)
        return self

    def _start(self, e):
        self._depth += 1
        if self._depth != 1:
            return
        d = e.data.get("dispatcher")
        fn = getattr(d, "py_func", None)
        mod = getattr(fn, "__module__", "") or ""
        if not mod.startswith(self.prefix):
            return
        self._t0 = time.perf_counter()
        self.count += 1
        if self.count == 1:
            self._why_not_shipped()
        what = "the compiled fast loop for this component layout" if mod.startswith(("shevsim.fast.loop",
                                                                                   "shevsim_loop")) else \
            f"the {_friendly(mod)}"
        self.stream.write(f"compiling {what} ({fn.__name__}; first use, cached afterwards) ... ")
        self.stream.flush()

    def _why_not_shipped(self):
        """Before the first compilation: one line on why the precompiled code of the installation (if it
        has any) does not serve, so a user on another CPU knows the wait is once."""
        try:
            from .core import jitcache
            why = jitcache.shipped_status() if jitcache.manifest() else ""
        except Exception:  # noqa: BLE001 - a message only
            why = ""
        if why:
            self.stream.write(f"shevsim: compiling on first use, cached afterwards: {why}\n")
            self.stream.flush()

    def _end(self, e):
        self._depth -= 1
        if self._depth != 0 or not self._t0:
            return
        dt = time.perf_counter() - self._t0
        self.total_s += dt
        self._t0 = 0.0
        self.stream.write(f"{dt:.1f} s\n")
        self.stream.flush()

    def __exit__(self, *exc):
        if self._listener is not None:
            from numba.core import event as ev
            ev.unregister("numba:compile", self._listener)
            self._listener = None
        return False


def main(argv=None) -> int:
    """``python -m shevsim.warmup SCENARIO.pickle LOCK``: the background build (see :func:`start_background`)."""
    import pickle
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "--build":
        return build_shipped_cache(argv[1])
    sc_file, lock = Path(argv[0]), Path(argv[1])
    scenario = None
    try:
        try:
            os.nice(10)
        except (OSError, AttributeError):
            pass
        scenario = pickle.loads(sc_file.read_bytes())
        dt = warm(scenario)
        print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} warm-up {layout_of(scenario)}: {dt:.1f} s", flush=True)
        return 0
    except Exception as exc:  # noqa: BLE001 - logged; the next run decides again
        print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} warm-up failed: {type(exc).__name__}: {exc}", flush=True)
        if scenario is not None:
            mark_compiled(scenario, ok=False)
        return 1
    finally:
        for p in (sc_file, lock):
            try:
                p.unlink()
            except OSError:
                pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
