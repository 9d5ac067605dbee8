"""adapter.py - an FMI 2.0 / 3.0 FMU (co-simulation or model exchange) wrapped as a shevsim component.

:class:`FMUComponent` loads an FMU with ``fmpy``, exposes its inputs and
outputs as ports (``u``/``y`` dicts, exactly like a native component) and
advances it over each communication step. The master cannot tell it from a
native component.

Interfaces
----------
* **Co-simulation** (``interface="cs"``): ``doStep`` on the FMU's own solver.
* **Model exchange** (``interface="me"``): the component integrates the FMU's
  derivatives itself over each communication step, with event handling as
  fmpy's ``simulateME`` does it: time events (``nextEventTime``), state events
  (event-indicator roots found by the solver), step events
  (``completedIntegratorStep``), each followed by event mode, the
  discrete-state iteration and a solver reset. Inputs are held over a step
  (zero-order hold); a changed input at a communication point is an input
  event (event mode, then a solver restart), as fmpy treats input
  discontinuities. Solvers: ``"cvode"`` (SUNDIALS CVODE BDF through fmpy,
  the default) or a SciPy ``solve_ivp`` method (``"BDF"``, ``"Radau"``,
  ``"LSODA"``, ``"RK45"``, ``"DOP853"``) with the event indicators as
  terminal events. ``tolerance`` is the relative tolerance (absolute
  tolerance = tolerance x the states' nominal values, as fmpy).
* ``interface="auto"`` (default): co-simulation when the FMU has it, else model exchange.

Variables
---------
Float64/Real, Float32, integer (Int8...UInt64, Integer, Enumeration) and
Boolean inputs/outputs become ports (booleans and integers carried as floats:
``1.0``/``0.0``). FMI 3 **array variables** become one port per element,
named ``name[i]`` (1-based; ``name[i,j]`` for matrices, row-major, as
Modelica shows them); their size comes from fixed dimensions or the start
value of the structural parameter that sizes them. String, Binary and Clock
variables are not ports (ports carry numbers) but the FMU is accepted: they are
listed (:attr:`FMUComponent.value_variables`, ``shevsim info X.fmu``), their
start value can be set with ``parameters`` (a scenario's ``set``; Binary as
bytes or a hex string), and only a connection to or from one is refused, with
a message naming the variable.

Hot path
--------
All Real/Float64 inputs are written with ONE ``fmi2SetReal``/``fmi3SetFloat64``
call and all Real/Float64 outputs read with ONE ``fmi2GetReal``/``fmi3GetFloat64``
call (arrays included), on preallocated ctypes arrays, calling the raw ctypes
entry points that ``fmpy`` loaded. Status codes are checked inline; a
failing call raises :class:`~shevsim.fmu.errors.FMUStepError` naming the
component, the time, the step and the FMI status, with the FMU's own last log
messages (for a pythonfmu FMU: the Python exception text).

Per-call timeout
----------------
``step_timeout_s`` (default :data:`DEFAULT_STEP_TIMEOUT_S`) bounds the wall time
of one communication step (``doStep``, or the integration over a step): the
step runs on a helper thread and a step that does not return in time raises
:class:`~shevsim.fmu.errors.FMUTimeoutError` naming the FMU, the time and the
step. The blocked instance is abandoned (never called or freed again); its
unpack folder is still removed. ``step_timeout_s=None`` (or 0) steps on the
calling thread without a bound (slightly faster).

Life cycle and resources
------------------------
``__init__`` validates and extracts the FMU to an absolute temporary
directory and instantiates it (load errors surface when the scenario is
built); ``initialize(t0)`` applies parameters and start values and runs the
FMI initialisation; ``terminate()`` terminates, frees the instance and deletes
the extracted files. A finaliser frees the instance and the directory if the
caller never reaches ``terminate`` (for example after an exception), and a
failure in ``__init__`` cleans up before raising. Every unpack folder carries
a marker with the owning process id: folders left by a killed process are
removed by the next FMU load.
"""
from __future__ import annotations

import difflib
import math
import os
import queue
import shutil
import tempfile
import threading
import time as _time
import weakref
import zipfile
from collections import deque
from ctypes import POINTER, byref, c_bool, c_double, c_uint32
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence
from xml.etree import ElementTree

from ..core.component import Component
from ..core.variables import Variable, canonical_unit
from .errors import (FMUError, FMULoadError, FMUMappingError, FMUStateError, FMUStepError, FMUTimeoutError,
                     FMUUnitError, FMUUnsupportedError)

__all__ = ["FMUComponent", "read_fmi_version", "load_model_description", "expected_units_of",
           "DEFAULT_STEP_TIMEOUT_S", "SOLVERS", "element_names", "variable_shape"]

_REAL_TYPES = ("Real", "Float64")
_INT_TYPES = ("Integer", "Int32", "Int64", "Int16", "Int8", "UInt32", "UInt16", "UInt8", "UInt64",
              "Enumeration")
_BOOL_TYPES = ("Boolean",)
_OTHER_NUM = ("Float32",)
PORT_TYPES = _REAL_TYPES + _INT_TYPES + _BOOL_TYPES + _OTHER_NUM

#: wall-time bound of one communication step of an FMU (s); scenario key ``step_timeout_s`` (0: none).
#: Long enough for any step of a working FMU stepped at a co-simulation step (well under a second here),
#: short enough to wait for when one hangs.
DEFAULT_STEP_TIMEOUT_S = 30.0
#: largest modelDescription.xml read (bytes, unpacked); the biggest real ones are a few MB
MAX_MODEL_DESCRIPTION_BYTES = 64 * 2**20
#: largest FMU unpacked (all members, bytes) and the most members; checked from the archive's directory
#: before anything is read or extracted
MAX_UNPACKED_BYTES = 2 * 2**30
MAX_MEMBERS = 100_000


def check_archive(zf: zipfile.ZipFile, path, what: str = "FMU", error: type | None = None,
                  members: dict[str, int] | None = None) -> None:
    """Refuse an archive whose members would unpack beyond the limits, from its directory, before any
    member is read: more than :data:`MAX_MEMBERS` members, more than :data:`MAX_UNPACKED_BYTES` in all,
    or a member above its own limit (``members``: name -> bytes; default modelDescription.xml ->
    :data:`MAX_MODEL_DESCRIPTION_BYTES`). ``zipfile`` never unpacks more than a member's declared size,
    so a lying directory cannot get past these limits either."""
    error = error or FMULoadError
    members = {"modelDescription.xml": MAX_MODEL_DESCRIPTION_BYTES} if members is None else members
    infos = zf.infolist()
    if len(infos) > MAX_MEMBERS:
        raise error(f"{path}: the {what} archive has {len(infos)} members (limit {MAX_MEMBERS}): refused "
                    f"before unpacking; not a usable {what}")
    total = 0
    for info in infos:
        total += info.file_size
        cap = members.get(info.filename)
        if cap is not None and info.file_size > cap:
            raise error(f"{path}: {info.filename} unpacks to {info.file_size / 2**20:.4g} MiB (limit "
                        f"{cap / 2**20:.4g} MiB; it is {info.compress_size / 2**20:.3g} MiB compressed): refused "
                        f"before reading it; a real {what} keeps it far smaller - rebuild or re-export it")
    if total > MAX_UNPACKED_BYTES:
        raise error(f"{path}: the {what} unpacks to {total / 2**30:.4g} GiB (limit {MAX_UNPACKED_BYTES / 2**30:.4g} "
                    f"GiB): refused before unpacking; rebuild it smaller")
#: model-exchange solvers: fmpy's CVODE wrapper, or a scipy.integrate.solve_ivp method
SOLVERS = ("cvode", "BDF", "Radau", "LSODA", "RK45", "RK23", "DOP853")
#: component options that can be given among ``parameters`` (scenario ``set``) unless the FMU has a
#: variable of that name
OPTION_KEYS = ("interface", "solver", "tolerance", "max_step_s", "step_timeout_s")

_MARKER = ".shevsim_fmu_owner"
_PREFIX = "shevsim_fmu_"


def _suggest(key: str, options: Iterable[str]) -> str:
    best = difflib.get_close_matches(key, list(options), n=1)
    return f" (did you mean '{best[0]}'?)" if best else ""


def read_fmi_version(path: str | Path) -> str:
    """Return the ``fmiVersion`` attribute of an FMU file's ``modelDescription.xml``.

    Raises :class:`FMULoadError` when the file is missing, not a ZIP archive,
    or has no readable ``modelDescription.xml``.
    """
    path = Path(path)
    if not path.exists():
        raise FMULoadError(f"{path}: FMU file not found")
    if path.is_dir():
        md = path / "modelDescription.xml"
        if not md.is_file():
            raise FMULoadError(f"{path}: directory has no modelDescription.xml (not an extracted FMU)")
        if md.stat().st_size > MAX_MODEL_DESCRIPTION_BYTES:
            raise FMULoadError(f"{md}: {md.stat().st_size / 2**20:.4g} MiB (limit "
                               f"{MAX_MODEL_DESCRIPTION_BYTES / 2**20:.4g} MiB): refused before reading it")
        data = md.read_bytes()
    else:
        if not zipfile.is_zipfile(path):
            raise FMULoadError(f"{path}: not a ZIP archive - the FMU file is corrupt or not an FMU")
        try:
            with zipfile.ZipFile(path) as zf:
                check_archive(zf, path)
                data = zf.read("modelDescription.xml")
        except KeyError:
            raise FMULoadError(f"{path}: the archive has no modelDescription.xml (not an FMU)") from None
        except (zipfile.BadZipFile, OSError) as exc:
            raise FMULoadError(f"{path}: corrupt FMU archive: {exc}") from exc
    try:
        root = ElementTree.fromstring(data)
    except ElementTree.ParseError as exc:
        raise FMULoadError(f"{path}: modelDescription.xml is not well-formed XML: {exc}") from exc
    if root.tag != "fmiModelDescription":
        raise FMULoadError(f"{path}: modelDescription.xml root is <{root.tag}>, expected <fmiModelDescription>")
    version = root.get("fmiVersion")
    if version is None:
        raise FMULoadError(f"{path}: modelDescription.xml has no fmiVersion attribute")
    return version


def load_model_description(path: str | Path, validate: bool = True, interface: str = "auto"):
    """Read and check an FMU's model description (FMI 2.0/3.0, co-simulation or model exchange).

    Returns the ``fmpy`` ``ModelDescription``. Raises :class:`FMULoadError`
    (missing/corrupt/invalid) or :class:`FMUUnsupportedError` (FMI version
    other than 2.0/3.x, or none of the interfaces asked for).
    """
    from fmpy import read_model_description

    path = Path(path)
    version = read_fmi_version(path)
    if not (version == "2.0" or version.startswith("3.")):
        raise FMUUnsupportedError(
            f"{path}: FMI version {version!r} is not supported (shevsim imports FMI 2.0 and 3.0 "
            f"co-simulation and model-exchange FMUs)")
    try:
        md = read_model_description(str(path), validate=validate)
    except Exception as exc:  # fmpy raises ValidationError or plain Exception
        raise FMULoadError(f"{path}: invalid modelDescription.xml: {exc}") from exc
    pick_interface(md, path, interface)
    return md


def pick_interface(md, path, interface: str = "auto") -> str:
    """``'cs'`` or ``'me'``: the interface used for ``interface`` ('auto', 'cs', 'me')."""
    if interface not in ("auto", "cs", "me"):
        raise FMUMappingError(f"{path}: interface must be 'auto', 'cs' or 'me', got {interface!r}")
    have = [k for k, attr in (("cs", "coSimulation"), ("me", "modelExchange")) if getattr(md, attr, None) is not None]
    if interface == "auto":
        if have:
            return have[0]
    elif interface in have:
        return interface
    kinds = [k for k in ("coSimulation", "modelExchange", "scheduledExecution") if getattr(md, k, None) is not None]
    want = {"auto": "co-simulation or model-exchange", "cs": "co-simulation",
            "me": "model-exchange"}[interface]
    raise FMUUnsupportedError(f"{path}: the FMU has no {want} interface (it has: {', '.join(kinds) or 'none'}); "
                              f"shevsim runs FMI 2.0/3.0 co-simulation and model-exchange FMUs")


def expected_units_of(component: type | Mapping[str, str] | None) -> dict[str, str]:
    """Port -> unit expectations from a native component class (or a mapping, passed through)."""
    if component is None:
        return {}
    if isinstance(component, Mapping):
        return dict(component)
    variables = component.VARIABLES if isinstance(component, type) else component.variables()
    return {v.name: v.unit for v in variables if v.causality in ("input", "output")}


def var_unit(v) -> str:
    unit = getattr(v, "unit", None)
    if not unit and getattr(v, "declaredType", None) is not None:
        unit = getattr(v.declaredType, "unit", None)
    return unit or ""


def variable_shape(v) -> tuple[int, ...]:
    """Shape of an FMI 3 array variable (``()`` for a scalar), from its fixed dimensions or the start
    value of the structural parameter sizing it."""
    dims = getattr(v, "dimensions", None) or []
    if not dims:
        return ()
    shape = getattr(v, "shape", None)
    if shape:
        return tuple(int(n) for n in shape)
    out = []
    for d in dims:
        if getattr(d, "start", None) not in (None, ""):
            out.append(int(d.start))
        elif getattr(d, "variable", None) is not None and d.variable.start not in (None, ""):
            out.append(int(d.variable.start))
        else:
            raise FMUUnsupportedError(f"array variable '{v.name}': dimension has neither a start value nor a "
                                      f"structural parameter with a start value")
    return tuple(out)


def element_names(base: str, shape: tuple[int, ...]) -> tuple[str, ...]:
    """Port names of the elements of an array (``y[1]``, ``y[2]``; ``A[1,1]``, ``A[1,2]`` row-major)."""
    if not shape:
        return (base,)
    import itertools
    return tuple(f"{base}[{','.join(str(i + 1) for i in idx)}]"
                 for idx in itertools.product(*(range(n) for n in shape)))


def _to_float(x: Any, default: float = 0.0) -> float:
    if x is None:
        return default
    if isinstance(x, str):
        s = x.strip().lower()
        if s in ("true", "false"):
            return 1.0 if s == "true" else 0.0
        try:
            return float(s.split()[0]) if s else default
        except ValueError:
            return default
    try:
        return float(x)
    except (TypeError, ValueError):
        return default


def _starts(x: Any, n: int) -> list[float]:
    """Start values of an array (space-separated in FMI 3), padded with the first value."""
    if n == 1:
        return [_to_float(x)]
    parts = str(x).split() if x not in (None, "") else []
    vals = [_to_float(p) for p in parts] or [0.0]
    return (vals + [vals[-1]] * n)[:n]


# ------------------------------------------------------------------ unpack folders
def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def sweep_stale_unpack_dirs(tmp_root: str | Path | None = None, min_age_s: float = 5.0) -> list[str]:
    """Remove FMU unpack folders left by processes that no longer run (killed runs).

    Only folders named ``shevsim_fmu_*`` that carry shevsim's owner marker with a dead
    process id (and older than ``min_age_s``) are removed; nothing else is touched.
    Returns the removed paths.
    """
    root = Path(tmp_root or tempfile.gettempdir())
    removed = []
    try:
        cands = list(root.glob(_PREFIX + "*"))
    except OSError:
        return removed
    now = _time.time()
    for d in cands:
        marker = d / _MARKER
        try:
            if not marker.is_file() or now - marker.stat().st_mtime < min_age_s:
                continue
            pid = int(marker.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        if pid != os.getpid() and not _pid_alive(pid):
            shutil.rmtree(d, ignore_errors=True)
            removed.append(str(d))
    return removed


#: fmpy objects of instances that hung in a step: kept alive for the life of the process, so that
#: their shared library is never unloaded under the thread still running inside it
_ABANDONED: list = []


def _cleanup(fmu_box: list, unzipdir: str | None, hung: list, keep: list) -> None:
    """Finaliser: free the FMU instance (if any and not hung) and delete the extracted files.

    ``keep`` holds the logger callbacks: alive until after ``freeInstance`` (which may still log)."""
    fmu = fmu_box[0] if fmu_box else None
    if fmu is not None:
        fmu_box[0] = None
        if hung[0]:              # an instance blocked in a call on the helper thread is never touched again
            _ABANDONED.append((fmu, list(keep)))
        else:
            try:
                fmu.freeInstance()
            except Exception:
                pass
    keep.clear()
    if unzipdir:
        shutil.rmtree(unzipdir, ignore_errors=True)


def _make_logger(log: deque, fmi3: bool):
    """FMU log callback keeping the last messages in ``log`` (no reference to the component)."""
    if fmi3:
        def logger(env, status, category, message):
            log.append((status, (message or b"").decode("utf-8", "replace")))
    else:
        def logger(env, instance, status, category, message):
            log.append((status, (message or b"").decode("utf-8", "replace")))
    return logger


class _StepThread:
    """One helper thread running a component's steps, so that a step can be bounded in wall time."""

    def __init__(self, name: str):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._done: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._loop, name=f"fmu-step-{name}", daemon=True)
        self._thread.start()

    def _loop(self):
        jobs, done = self._jobs, self._done
        while True:
            job = jobs.get()
            if job is None:
                return
            fn, args = job
            try:
                fn(*args)
                done.put(None)
            except BaseException as exc:  # handed to the caller
                done.put(exc)
            # drop the references to the component while waiting, so that it can be collected
            # (its finaliser then stops this thread and frees the FMU)
            del job, fn, args

    def run(self, fn, args, timeout: float) -> bool:
        """Run ``fn(*args)``; False when it did not finish within ``timeout`` seconds."""
        self._jobs.put((fn, args))
        try:
            exc = self._done.get(timeout=timeout)
        except queue.Empty:
            return False
        if exc is not None:
            raise exc
        return True

    def stop(self):
        self._jobs.put(None)


class _Snapshot:
    """Opaque FMU state handle plus copies of the port dicts; frees the FMU state when dropped."""

    __slots__ = ("handle", "u", "y", "extra", "_owner", "__weakref__")

    def __init__(self, owner: "FMUComponent", handle, u: dict, y: dict, extra=None):
        self.handle = handle
        self.u = u
        self.y = y
        self.extra = extra
        self._owner = weakref.ref(owner)

    def __del__(self):
        owner = self._owner()
        if owner is not None and owner._fmu_box and owner._fmu_box[0] is not None and not owner._hung[0]:
            try:
                owner._fmu_box[0].freeFMUstate(self.handle)
            except Exception:
                pass


class _ScipySolver:
    """``scipy.integrate.solve_ivp`` over the FMU's derivatives, with the event indicators as terminal
    events; same interface as fmpy's ``CVodeSolver`` (``step(t, t_next)``, ``reset(t)``)."""

    def __init__(self, nx, nz, get_x, set_x, get_dx, get_z, get_nominals, set_time, method, rtol, max_step):
        import numpy as np
        self.np = np
        self.nx, self.nz = nx, nz
        self.method, self.rtol = method, rtol
        self.max_step = max_step if max_step else math.inf
        self._x = np.zeros(max(nx, 1))
        self._dx = np.zeros(max(nx, 1))
        self._z = np.zeros(max(nz, 1))
        self._nom = np.ones(max(nx, 1))
        self._px = self._x.ctypes.data_as(POINTER(c_double))
        self._pdx = self._dx.ctypes.data_as(POINTER(c_double))
        self._pz = self._z.ctypes.data_as(POINTER(c_double))
        self._pnom = self._nom.ctypes.data_as(POINTER(c_double))
        self.get_x, self.set_x, self.get_dx, self.get_z = get_x, set_x, get_dx, get_z
        self.get_nominals, self.set_time = get_nominals, set_time
        self.events = []
        for i in range(nz):
            def ev(t, x, i=i):
                self._load(t, x)
                self.get_z(self._pz, nz)
                return self._z[i]
            ev.terminal = True
            self.events.append(ev)
        self.reset(None)

    def _load(self, t, x):
        self.set_time(t)
        if self.nx:
            self._x[:] = x
            self.set_x(self._px, self.nx)

    def _f(self, t, x):
        if not self.nx:
            return self.np.zeros(1)
        self._load(t, x)
        self.get_dx(self._pdx, self.nx)
        return self._dx.copy()

    def reset(self, time):
        if self.nx:
            self.get_nominals(self._pnom, self.nx)
        self.atol = self.rtol * self.np.abs(self._nom[:max(self.nx, 1)])
        # an indicator that is zero right after an event must not stop the next step at its start:
        # like CVODE's inactive roots, the first sliver of the next step runs without root finding
        self._after_event = True

    def step(self, t, t_next):
        from scipy.integrate import solve_ivp
        np = self.np
        if self.nx:
            self.get_x(self._px, self.nx)
            x0 = self._x.copy()
        else:
            x0 = np.zeros(1)
        if self._after_event and self.events:
            self._after_event = False
            d = min(1e-9 * max(1.0, abs(t)) + 1e-7 * (t_next - t), 0.5 * (t_next - t))
            pre = solve_ivp(self._f, (t, t + d), x0, method=self.method, rtol=self.rtol, atol=self.atol,
                            max_step=self.max_step)
            t, x0 = t + d, pre.y[:, -1]
        z0 = None
        if self.events:
            self._load(t, x0)
            self.get_z(self._pz, self.nz)
            z0 = self._z[:self.nz].copy()
        sol = solve_ivp(self._f, (t, t_next), x0, method=self.method, rtol=self.rtol, atol=self.atol,
                        events=self.events or None, max_step=self.max_step, dense_output=bool(self.events))
        if sol.status < 0:
            raise RuntimeError(f"solve_ivp ({self.method}) failed: {sol.message}")
        roots = np.zeros(self.nz, dtype=np.int32)
        if sol.status == 1:
            hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
            te, first = min(hits)
            for tt, i in hits:
                if abs(tt - te) <= 1e-12 * max(1.0, abs(te)):
                    roots[i] = 1
            # hand the FMU a point just past the root (as CVODE does): the indicator has changed sign there
            # (the last interpolant is extrapolated by at most 1e-6 of the step)
            tt, d = te, 1e-12 * max(1.0, abs(te))
            t_cap = te + max(1e-6 * (t_next - t), 2e-12 * max(1.0, abs(te)))
            for _ in range(80):
                xe = sol.sol(tt) if self.nx else np.zeros(1)
                zi = self.events[first](tt, xe)
                if (z0[first] > 0 and zi <= 0) or (z0[first] < 0 and zi >= 0) or z0[first] == 0 \
                        or tt >= t_cap:
                    break
                tt, d = min(te + d, t_cap), 2.0 * d
            self._load(tt, xe)
            return True, roots, float(tt)
        self._load(t_next, sol.y[:, -1])
        return False, roots, float(t_next)


def _isclose(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


class FMUComponent(Component):
    """An FMU (FMI 2.0 or 3.0; co-simulation or model exchange) as a shevsim component.

    Parameters
    ----------
    name : str
        Instance name (used in error messages and as the FMI instance name).
    fmu_path : str or Path
        The ``.fmu`` file (or a directory holding an extracted FMU).
    mapping : dict, optional
        ``{fmu_variable_name: port_name}``. Renames FMU inputs/outputs/parameters
        to shevsim port names (an array variable's base name: ``{"y": "out"}`` gives
        ``out[1]``...); unmapped inputs and outputs keep their FMU names.
        An unknown FMU variable raises :class:`FMUMappingError`.
    parameters : dict, optional
        ``{name: value}`` applied before initialisation; ``name`` is an FMU
        variable name or a mapped port name (an array takes a list, or one element
        ``name[i]``). The option keys ``interface``, ``solver``, ``tolerance``,
        ``max_step_s`` and ``step_timeout_s`` set the arguments of the same name
        unless the FMU has a variable of that name (so a scenario's ``set`` table
        reaches them).
    start_values : dict, optional
        Like ``parameters`` but for inputs (sets the held input value, ``u``)
        or any other variable with a settable start value.
    expected_units : native component class or dict, optional
        Declared expectations ``{port: unit}`` (a ``Component`` subclass means
        "the ports of the component this FMU replaces"). A mapped FMU variable
        whose unit is of another dimension raises :class:`FMUUnitError`; one of the
        same dimension in another scale (kW for W, degC for K) is accepted and
        converted on the connection; an FMU variable without a unit adopts the
        expected one.
    feedthrough : dict, optional
        ``{output_port: [input_port, ...]}`` overriding the direct
        dependencies read from ``<ModelStructure>`` (FMUs that omit them
        are assumed to depend on every input, as FMI prescribes).
    validate : bool
        Validate ``modelDescription.xml`` with fmpy (default True).
    tolerance : float, optional
        Co-simulation: passed to ``setupExperiment``/``enterInitializationMode``.
        Model exchange: the solver's relative tolerance (default 1e-6).
    interface : {'auto', 'cs', 'me'}
        Which FMI interface to use (auto: co-simulation if present, else model exchange).
    solver : str
        Model exchange: ``"cvode"`` (default) or a ``solve_ivp`` method (:data:`SOLVERS`).
    max_step_s : float, optional
        Model exchange: largest internal solver step (s); default: unbounded.
    step_timeout_s : float or None
        Wall-time bound of one communication step (s), default
        :data:`DEFAULT_STEP_TIMEOUT_S`; None or 0: unbounded.

    Ports
    -----
    The FMU's Real/Float64/Float32, integer and Boolean variables of causality
    ``input``/``output`` (array elements as ``name[i]``), with the units declared
    in the model description; ``parameter`` variables are listed by
    :meth:`variables` with causality ``parameter``. Outputs declare ``depends_on``
    from the FMU's ``ModelStructure`` dependencies.
    """

    TYPE = "fmu"
    Params = None
    _static = ("name", "params")

    def __init__(self, name: str, fmu_path: str | Path, mapping: Mapping[str, str] | None = None,
                 parameters: Mapping[str, Any] | None = None,
                 start_values: Mapping[str, Any] | None = None,
                 expected_units: type | Mapping[str, str] | None = None,
                 feedthrough: Mapping[str, Sequence[str]] | None = None, *,
                 validate: bool = True, tolerance: float | None = None,
                 interface: str = "auto", solver: str = "cvode", max_step_s: float | None = None,
                 step_timeout_s: float | None = DEFAULT_STEP_TIMEOUT_S):
        self.path = Path(fmu_path).absolute()
        self._fmu_box: list = [None]
        self._hung: list = [False]
        self._unzipdir: str | None = None
        self._initialized = False
        self._failed = False
        self._stepper: _StepThread | None = None
        self._log: deque = deque(maxlen=20)
        md = load_model_description(self.path, validate=validate)
        names = {v.name for v in md.modelVariables}
        opts = {}
        rest = {}
        for k, v in (parameters or {}).items():
            (opts if k in OPTION_KEYS and k not in names else rest)[k] = v
        parameters = rest
        interface = opts.get("interface", interface)
        solver = opts.get("solver", solver)
        tolerance = opts.get("tolerance", tolerance)
        max_step_s = opts.get("max_step_s", max_step_s)
        step_timeout_s = opts.get("step_timeout_s", step_timeout_s)
        self.kind = pick_interface(md, self.path, interface)
        self._me = self.kind == "me"
        if solver not in SOLVERS:
            raise FMUMappingError(f"{self.path}: component '{name}': solver {solver!r} is not one of "
                                  f"{', '.join(SOLVERS)}{_suggest(str(solver), SOLVERS)}")
        for key, val in (("tolerance", tolerance), ("max_step_s", max_step_s), ("step_timeout_s", step_timeout_s)):
            if val is not None and (isinstance(val, bool) or not isinstance(val, (int, float))
                                    or not math.isfinite(val) or val < 0 or (key == "tolerance" and val == 0)):
                raise FMUMappingError(f"{self.path}: component '{name}': {key} must be a positive number, "
                                      f"got {val!r}")
        self.solver = solver
        self.tolerance = tolerance
        self.max_step_s = max_step_s or None
        self.step_timeout_s = float(step_timeout_s) if step_timeout_s else None
        self.model_description = md
        self.fmi_version = md.fmiVersion
        self._is3 = md.fmiVersion.startswith("3.")
        iface = md.modelExchange if self._me else md.coSimulation
        self._iface = iface
        self.can_get_set_state = bool(getattr(iface, "canGetAndSetFMUstate", False)
                                      or getattr(iface, "canGetAndSetFMUState", False))
        self.unit_definitions = {u.name: u for u in (getattr(md, "unitDefinitions", None) or [])}

        self._build_ports(name, mapping or {}, expected_units, feedthrough or {})
        self._parameters = self._resolve_values(parameters or {}, "parameters")
        self._start_values = self._resolve_values(start_values or {}, "start_values")
        for which, values in (("parameters", self._parameters), ("start_values", self._start_values)):
            for vname, value in values.items():     # a wrong type is bad input: said now, before instantiating
                self._check_value_type(vname, value, which, name)
        super().__init__(name, None)
        self.params = dict(parameters or {})
        for vname, value in self._start_values.items():
            for port, val in zip(self._ports_of.get(vname, ()), self._element_values(vname, value)):
                if port in self.u:
                    self.u[port] = float(val)

        self._instantiate(name)

    # ------------------------------------------------------------------ ports
    def _build_ports(self, name: str, mapping: Mapping[str, str], expected, feedthrough) -> None:
        md = self.model_description
        by_name = {v.name: v for v in md.modelVariables}
        self._vars_by_name = by_name
        self._check_mapping(name, mapping, by_name)
        expected_units = expected_units_of(expected)
        #: String/Binary/Clock inputs, outputs and parameters: settable start values, never ports
        self.value_variables: dict[str, dict] = {}
        self._port_of: dict[str, str] = {}          # FMU variable -> base port name
        self._ports_of: dict[str, tuple[str, ...]] = {}   # FMU variable -> its element ports
        self._fmu_of: dict[str, str] = {}           # port (base or element) -> FMU variable
        self._elem_of: dict[str, int] = {}          # element port -> index in its variable
        self.port_units: dict[str, str] = {}
        variables: list[Variable] = []
        inputs: list = []
        outputs: list = []
        for v in md.modelVariables:
            self._add_variable(name, v, mapping, expected_units, (inputs, outputs, variables))
        input_ports = [p for _, ps, _, _ in inputs for p in ps]
        deps = self._output_dependencies(name, inputs, outputs, input_ports, feedthrough)
        for v, ports, unit, starts in inputs:
            for p, s in zip(ports, starts):
                variables.append(Variable(p, "input", unit or "1", s, v.description or ""))
        for v, ports, unit, starts in outputs:
            for p, s in zip(ports, starts):
                variables.append(Variable(p, "output", unit or "1", s, v.description or "",
                                          deps.get(p, tuple(input_ports))))
        self._variables = tuple(variables)
        self._inputs = inputs
        self._outputs = outputs

    def _check_mapping(self, name: str, mapping: Mapping[str, str], by_name: dict) -> None:
        """Every mapped FMU variable exists and is an input, output or parameter."""
        md = self.model_description
        for fmu_name in mapping:
            if fmu_name not in by_name:
                raise FMUMappingError(
                    f"{self.path}: mapping for component '{name}' names FMU variable '{fmu_name}', "
                    f"which the FMU does not have{_suggest(fmu_name, by_name)}; FMU inputs/outputs: "
                    f"{', '.join(v.name for v in md.modelVariables if v.causality in ('input', 'output'))}")
            if by_name[fmu_name].causality not in ("input", "output", "parameter"):
                raise FMUMappingError(
                    f"{self.path}: mapping for component '{name}': FMU variable '{fmu_name}' has causality "
                    f"'{by_name[fmu_name].causality}'; only inputs, outputs and parameters can be mapped")

    def _add_variable(self, name: str, v, mapping: Mapping[str, str], expected_units: dict, into) -> None:
        """Register one model variable: its port names (array elements as ``name[i]``), unit (checked
        against the expected one) and start values; appended to ``into = (inputs, outputs, parameters)``.
        String/Binary/Clock variables become :attr:`value_variables` instead."""
        from ..core.units import convertible
        inputs, outputs, variables = into
        if v.causality not in ("input", "output", "parameter"):
            return
        if v.type not in PORT_TYPES:
            # String/Binary/Clock: not a port; its start value is settable (`parameters`), a connection
            # to or from it is refused by name (Master: `not_connectable`)
            self.value_variables[v.name] = {"causality": v.causality, "type": v.type, "start": v.start,
                                            "description": v.description or ""}
            return
        try:
            shape = variable_shape(v)
        except FMUUnsupportedError as exc:
            raise FMUUnsupportedError(f"{self.path}: {exc}") from None
        port = mapping.get(v.name, v.name)
        ports = element_names(port, shape)
        for p in ports + ((port,) if shape else ()):
            if p in self._fmu_of:
                raise FMUMappingError(f"{self.path}: component '{name}': port name '{p}' used twice "
                                      f"(FMU variables '{self._fmu_of[p]}' and '{v.name}')")
        self._port_of[v.name] = port
        self._ports_of[v.name] = ports
        self._fmu_of[port] = v.name
        for i, p in enumerate(ports):
            self._fmu_of[p] = v.name
            self._elem_of[p] = i
        unit = var_unit(v)
        if port in expected_units and v.causality != "parameter":
            want = expected_units[port]
            if not unit:
                unit = want
            elif canonical_unit(unit) != canonical_unit(want) and \
                    not convertible(unit, want, self.unit_definitions):
                raise FMUUnitError(
                    f"{self.path}: component '{name}': FMU variable '{v.name}' (port '{port}') has unit "
                    f"'{unit}' but the port it replaces declares '{want}' "
                    f"(canonical '{canonical_unit(unit)}' vs '{canonical_unit(want)}': another dimension)")
        starts = _starts(v.start, len(ports))
        entry = (v, ports, unit, starts)
        for p in ports:
            self.port_units[p] = unit or "1"
        if v.causality == "input":
            inputs.append(entry)
        elif v.causality == "output":
            outputs.append(entry)
        else:
            for p, s in zip(ports, starts):
                variables.append(Variable(p, "parameter", unit or "1", s, v.description or ""))

    def _output_dependencies(self, name: str, inputs, outputs, input_ports: list,
                             feedthrough) -> dict[str, tuple[str, ...]]:
        """Direct dependencies of each output port: ``<ModelStructure>`` (absent: every input), then the
        ``feedthrough`` overrides, checked."""
        md = self.model_description
        # direct dependencies of outputs (ModelStructure); absent => depends on all inputs
        deps: dict[str, tuple[str, ...]] = {}
        for unknown in md.outputs:
            ports = self._ports_of.get(unknown.variable.name)
            if ports is None:
                continue
            if unknown.dependencies is None:
                d = tuple(input_ports)
            else:
                d = tuple(p for dv in unknown.dependencies if dv.causality == "input" and dv.name in self._ports_of
                          for p in self._ports_of[dv.name])
            for p in ports:
                deps[p] = d
        output_ports = [p for _, ps, _, _ in outputs for p in ps]
        for out_port, ins in feedthrough.items():
            if out_port not in output_ports:
                raise FMUMappingError(f"{self.path}: component '{name}': feedthrough names unknown output "
                                      f"port '{out_port}'{_suggest(out_port, output_ports)}")
            bad = [i for i in ins if i not in input_ports]
            if bad:
                raise FMUMappingError(f"{self.path}: component '{name}': feedthrough of '{out_port}' names "
                                      f"unknown input port(s) {bad}")
            deps[out_port] = tuple(ins)
        return deps

    def variables(self) -> tuple[Variable, ...]:
        """Ports built from the model description (inputs, outputs and parameters)."""
        return self._variables

    def inputs(self) -> tuple[Variable, ...]:  # type: ignore[override]
        return tuple(v for v in self._variables if v.causality == "input")

    def outputs(self) -> tuple[Variable, ...]:  # type: ignore[override]
        return tuple(v for v in self._variables if v.causality == "output")

    def _resolve_values(self, values: Mapping[str, Any], what: str) -> dict[str, Any]:
        """Map user keys (FMU names, port names or array elements) to FMU variable names.

        An element key (``A[2,1]``) becomes ``{variable: {index: value}}``."""
        out: dict[str, Any] = {}
        for key, value in values.items():
            if key in self._vars_by_name:
                vname = key
            elif key in self._fmu_of:
                vname = self._fmu_of[key]
            else:
                options = list(self._vars_by_name) + list(self._fmu_of)
                raise FMUMappingError(f"{self.path}: {what}: unknown FMU variable or port '{key}'"
                                      f"{_suggest(key, options)}")
            if key in self._elem_of and len(self._ports_of.get(vname, ())) > 1:
                out.setdefault(vname, {})
                if not isinstance(out[vname], dict):
                    raise FMUMappingError(f"{self.path}: {what}: '{key}' given both whole and by element")
                out[vname][self._elem_of[key]] = value
            else:
                out[vname] = value
        return out

    def _element_values(self, vname: str, value: Any) -> list:
        """All element values of variable ``vname`` for a user value (scalar, list, or {index: value})."""
        v = self._vars_by_name[vname]
        n = max(1, len(self._ports_of.get(vname, ())) or int(math.prod(variable_shape(v)) or 1))
        if isinstance(value, dict):
            cur = _starts(v.start, n)
            for i, x in value.items():
                cur[i] = x
            return cur
        if isinstance(value, (list, tuple)):
            if len(value) != n:
                raise FMUMappingError(f"{self.path}: component '{self.name}': '{vname}' has {n} elements, "
                                      f"got {len(value)} values")
            return list(value)
        return [value] * n if n > 1 else [value]

    # -------------------------------------------------------------- life cycle
    def _instantiate(self, name: str) -> None:
        import fmpy
        from fmpy import extract

        md = self.model_description
        platform = fmpy.platform_tuple if self._is3 else fmpy.platform
        sweep_stale_unpack_dirs()
        try:
            self._unzipdir = str(Path(tempfile.mkdtemp(prefix=f"{_PREFIX}{name}_")).absolute())
            self._keep: list = []
            self._finalizer = weakref.finalize(self, _cleanup, self._fmu_box, self._unzipdir, self._hung, self._keep)
            if self.path.is_dir():
                shutil.copytree(self.path, self._unzipdir, dirs_exist_ok=True)
            else:
                extract(str(self.path), self._unzipdir)
            (Path(self._unzipdir) / _MARKER).write_text(f"{os.getpid()} {self.path}\n")
            ident = self._iface.modelIdentifier
            bindir = Path(self._unzipdir) / "binaries" / platform
            if not any(bindir.glob(ident + ".*")):
                have = sorted(p.name for p in (Path(self._unzipdir) / "binaries").glob("*"))
                raise FMULoadError(f"{self.path}: no binary for platform '{platform}' "
                                   f"(the FMU has: {', '.join(have) or 'no binaries'})")
            if self._is3:
                from fmpy.fmi3 import FMU3Model, FMU3Slave
                cls = FMU3Model if self._me else FMU3Slave
                fmu = cls(guid=md.instantiationToken, unzipDirectory=self._unzipdir,
                          modelIdentifier=ident, instanceName=name)
                logger = _make_logger(self._log, fmi3=True)
                self._keep.append(logger)
                fmu.instantiate(loggingOn=True, logMessage=logger)
                self._keep.append(fmu.logMessage)
            else:
                from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackAllocateMemoryTYPE,
                                       fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
                from fmpy import calloc, free
                cb = fmi2CallbackFunctions()
                cb.logger = fmi2CallbackLoggerTYPE(_make_logger(self._log, fmi3=False))
                cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
                cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
                try:
                    from fmpy.logging import addLoggerProxy
                    addLoggerProxy(byref(cb))  # formats the variadic FMI 2 log message in C
                except Exception:
                    pass
                self._keep.append(cb)  # alive until after freeInstance (see _cleanup)
                cls = FMU2Model if self._me else FMU2Slave
                fmu = cls(guid=md.guid, unzipDirectory=self._unzipdir, modelIdentifier=ident, instanceName=name)
                fmu.instantiate(callbacks=cb, loggingOn=True)
            self._fmu_box[0] = fmu
        except FMUError:
            self._finalizer()
            raise
        except Exception as exc:
            self._finalizer()
            import re as _re
            m = _re.search(r"undefined symbol:?\s*(\w+)", str(exc))
            hint = ""
            if m:   # the binary lacks a function of the interface in use (e.g. a model-exchange-only binary)
                iface = "model-exchange" if self._me else "co-simulation"
                other = [k for k, a in (("cs", "coSimulation"), ("me", "modelExchange"))
                         if k != self.kind and getattr(md, a, None) is not None]
                hint = (f" - its binary does not implement {m.group(1)}, a function of the {iface} interface "
                        f"used here: the FMU is not a working {iface} FMU"
                        + (f"; try its other interface (set = {{ interface = \"{other[0]}\" }})" if other
                           else "; re-export it with that interface"))
            raise FMULoadError(f"{self.path}: cannot load/instantiate the FMU for component '{name}': "
                               f"{exc}{hint}{self._log_tail()}") from exc
        self._prepare_hot_path()

    def _log_tail(self) -> str:
        msgs = [m.strip() for s, m in self._log if s >= 1][-3:]
        return (" | FMU log: " + " / ".join(msgs)) if msgs else ""

    @property
    def fmu(self):
        """The fmpy ``FMU2Slave``/``FMU3Slave``/``FMU2Model``/``FMU3Model`` (None after :meth:`terminate`)."""
        return self._fmu_box[0]

    def _prepare_hot_path(self) -> None:
        fmu = self.fmu
        f = fmu._functions
        if self._is3:
            self._c_set_real, self._c_get_real = f["fmi3SetFloat64"], f["fmi3GetFloat64"]
            if not self._me:
                self._c_do_step = f["fmi3DoStep"]
            self._b_event, self._b_term, self._b_early = c_bool(), c_bool(), c_bool()
            self._d_last = c_double()
            self._step_refs = (byref(self._b_event), byref(self._b_term), byref(self._b_early),
                               byref(self._d_last))
        else:
            self._c_set_real, self._c_get_real = f["fmi2SetReal"], f["fmi2GetReal"]
            if not self._me:
                self._c_do_step = f["fmi2DoStep"]
        self._inst = fmu.component

        def split(items):
            real = [(v.valueReference, ps) for v, ps, _, _ in items if v.type in _REAL_TYPES]
            slow = [(v.valueReference, ps, v.type) for v, ps, _, _ in items if v.type not in _REAL_TYPES]
            return real, slow

        rin, self._slow_in = split(self._inputs)
        rout, self._slow_out = split(self._outputs)
        self._n_in, self._n_out = len(rin), len(rout)
        self._in_names = tuple(p for _, ps in rin for p in ps)
        self._out_names = tuple(p for _, ps in rout for p in ps)
        self._nv_in, self._nv_out = len(self._in_names), len(self._out_names)
        self._vr_in = (c_uint32 * len(rin))(*[vr for vr, _ in rin])
        self._val_in = (c_double * self._nv_in)()
        self._vr_out = (c_uint32 * len(rout))(*[vr for vr, _ in rout])
        self._val_out = (c_double * self._nv_out)()
        names = self._in_names
        if len(names) == 1:
            one = names[0]
            self._pick_in = lambda u: (u[one],)
        elif names:
            import operator
            self._pick_in = operator.itemgetter(*names)
        else:
            self._pick_in = None
        self._has_slow = bool(self._slow_in or self._slow_out)
        self._last_in: tuple | None = None

    def _call_failed(self, t: float, status: int, function: str, detail: str = "",
                     h: float | None = None) -> FMUStepError:
        self._failed = True
        if status == 4 and not self._hung[0]:
            # fmi2Fatal/fmi3Fatal: FMI allows no further call, freeInstance included (pythonfmu, for one,
            # releases its Python objects a second time if freed after a fatal error)
            self._hung[0] = "fatal"
        return FMUStepError(self.name, t, status, function, (detail + self._log_tail()).lstrip(" |"), h)

    def _typed_setter(self, typ: str):
        fmu = self.fmu
        if typ in _REAL_TYPES:
            return fmu.setFloat64 if self._is3 else fmu.setReal
        if typ == "Float32":
            return fmu.setFloat32
        if typ in _INT_TYPES:
            return fmu.setInteger if not self._is3 else getattr(fmu, "set" + ("Int64" if typ == "Enumeration"
                                                                                else typ))
        if typ in _BOOL_TYPES:
            return fmu.setBoolean
        if typ == "String":
            return fmu.setString
        if typ == "Binary" and self._is3:
            return fmu.setBinary
        if typ == "Clock" and self._is3:
            return fmu.setClock
        return None

    def not_connectable(self, port: str) -> str | None:
        """Why ``port`` cannot be connected when it names a String/Binary/Clock variable, else None."""
        v = self.value_variables.get(port)
        if v is None:
            return None
        return (f"FMU variable '{port}' of component '{self.name}' is a {v['type']} {v['causality']}: it is not a "
                f"port (ports carry numbers) and cannot be connected; set its start value instead "
                f"([components.{self.name}] set = {{ {port} = ... }})")

    def _typed_getter(self, typ: str):
        fmu = self.fmu
        if typ in _REAL_TYPES:
            return fmu.getFloat64 if self._is3 else fmu.getReal
        if typ == "Float32":
            return fmu.getFloat32
        if typ in _INT_TYPES:
            return fmu.getInteger if not self._is3 else getattr(fmu, "get" + ("Int64" if typ == "Enumeration"
                                                                                else typ))
        if typ in _BOOL_TYPES:
            return fmu.getBoolean
        return None

    @staticmethod
    def _convert(typ: str, x: Any):
        if typ in _INT_TYPES:
            if isinstance(x, float) and not x.is_integer():
                raise ValueError(f"{x!r} is not an integer")
            return int(x)
        if typ in _BOOL_TYPES:
            if isinstance(x, str):
                return x.strip().lower() in ("true", "1")
            return bool(x)
        if typ == "String":
            return str(x)
        if typ == "Binary":
            if isinstance(x, str):
                try:
                    return bytes.fromhex(x)
                except ValueError:
                    return x.encode()
            return bytes(x)
        if typ == "Clock":
            return bool(x)
        return float(x)

    def _check_value_type(self, vname: str, value: Any, which: str, name: str) -> None:
        """Refuse (FMUMappingError) a value the variable's FMI type cannot take: a number (or true/false as
        1/0) for Real/Float, an integer for Integer/Enumeration types, true/false for Boolean, a string for
        String."""
        v = self._vars_by_name.get(vname)
        if v is None:
            return
        import numbers

        import numpy as np

        def flat(val):          # a scalar, a list/tuple/array of elements, or {index: value} element sets
            if isinstance(val, dict):
                for w in val.values():
                    yield from flat(w)
            elif isinstance(val, (list, tuple)):
                for w in val:
                    yield from flat(w)
            elif isinstance(val, np.ndarray):
                yield from val.ravel().tolist()
            else:
                yield val.item() if isinstance(val, np.generic) else val
        typ = v.type
        for x in flat(value):
            # true/false are taken as 1/0 by a numeric variable (an exported native component's flags are Real)
            if typ in _REAL_TYPES or typ in _OTHER_NUM:
                ok, want = isinstance(x, numbers.Real), "a number"
            elif typ in _INT_TYPES:
                ok, want = isinstance(x, numbers.Integral) or (isinstance(x, float) and x.is_integer()), "an integer"
            elif typ in _BOOL_TYPES:
                ok, want = isinstance(x, bool) or (isinstance(x, int) and x in (0, 1)), "true or false"
            elif typ == "String":
                ok, want = isinstance(x, str), "a string"
            else:
                return
            if not ok:
                raise FMUMappingError(f"{self.path}: component '{name}': {which} '{vname}' = {value!r}: the "
                                      f"FMU variable is of type {typ} and takes {want}")

    def _set_value(self, vname: str, value: Any) -> None:
        v = self._vars_by_name[vname]
        vr = [v.valueReference]
        setter = self._typed_setter(v.type)
        if setter is None:
            raise FMUMappingError(f"{self.path}: cannot set variable '{vname}' of type {v.type}")
        try:
            vals = [self._convert(v.type, x) for x in self._element_values(vname, value)]
            if self._is3 and len(vals) > 1:
                setter(vr, vals)
            else:
                setter(vr, vals)
        except FMUError:
            raise
        except Exception as exc:
            raise FMUMappingError(f"{self.path}: component '{self.name}': setting '{vname}' = {value!r} "
                                  f"failed: {exc}{self._log_tail()}") from exc

    def initialize(self, t0: float) -> None:
        """Apply parameters/start values, run FMI initialisation at ``t0``, read the outputs."""
        fmu = self.fmu
        if fmu is None:
            raise FMUError(f"FMU component '{self.name}': initialize() after terminate()")
        if self._hung[0]:
            raise FMUError(f"FMU component '{self.name}': the FMU was abandoned after a "
                           f"{'fatal error' if self._hung[0] == 'fatal' else 'step that did not return (timeout)'}; "
                           f"it cannot be used again")
        if self._initialized:
            try:
                fmu.reset()
            except Exception as exc:
                raise self._call_failed(t0, getattr(exc, "status", 3), "reset", str(exc)) from exc
        for vname, value in {**self._parameters, **self._start_values}.items():
            self._set_value(vname, value)
        try:
            if self._is3:
                fmu.enterInitializationMode(tolerance=self.tolerance if not self._me else None, startTime=t0)
            else:
                fmu.setupExperiment(tolerance=self.tolerance if not self._me else None, startTime=t0)
                fmu.enterInitializationMode()
            self._write_inputs(t0)
            fmu.exitInitializationMode()
            if self._me:
                self._me_start(t0)
        except FMUStepError:
            raise
        except Exception as exc:
            raise self._call_failed(t0, getattr(exc, "status", 3), getattr(exc, "function", "initialization"),
                                    str(exc)) from exc
        self._initialized = True
        self._failed = False
        self._time = t0
        self._read_outputs(t0)

    def _write_inputs(self, t: float) -> None:
        if self._pick_in is not None:
            self._val_in[:] = self._pick_in(self.u)
            if self._is3:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in, self._nv_in)
            else:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in)
            if st > 1:
                raise self._call_failed(t, st, "fmi3SetFloat64" if self._is3 else "fmi2SetReal")
        if self._has_slow:
            self._slow_io(t, write=True)

    def _read_outputs(self, t: float) -> None:
        if self._n_out:
            if self._is3:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out, self._nv_out)
            else:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out)
            if st > 1:
                raise self._call_failed(t, st, "fmi3GetFloat64" if self._is3 else "fmi2GetReal")
            self.y.update(zip(self._out_names, self._val_out))
        if self._has_slow:
            self._slow_io(t, write=False)

    def _slow_io(self, t: float, write: bool) -> None:
        try:
            if write:
                for vr, ports, typ in self._slow_in:
                    vals = [self.u[p] for p in ports]
                    if typ in _INT_TYPES:
                        vals = [int(round(x)) for x in vals]
                    elif typ in _BOOL_TYPES:
                        vals = [x != 0.0 for x in vals]
                    self._typed_setter(typ)([vr], vals)
            else:
                for vr, ports, typ in self._slow_out:
                    getter = self._typed_getter(typ)
                    vals = getter([vr], len(ports)) if (self._is3 and len(ports) > 1) else getter([vr])
                    for p, x in zip(ports, vals):
                        self.y[p] = float(x)
        except Exception as exc:
            raise self._call_failed(t, getattr(exc, "status", 3), getattr(exc, "function", "get/set"),
                                    str(exc)) from exc

    # ----------------------------------------------------------------- stepping
    def do_step(self, t: float, h: float) -> None:
        """Advance from ``t`` to ``t + h``: set all inputs (one call), ``doStep`` or integrate (model
        exchange), get all outputs (one call); bounded by ``step_timeout_s`` when set."""
        if self.step_timeout_s is None:
            self._step_impl(t, h)
            return
        if self._hung[0]:
            raise FMUError(f"FMU component '{self.name}': the FMU was abandoned after a "
                           f"{'fatal error' if self._hung[0] == 'fatal' else 'step that did not return (timeout)'}; "
                           f"it cannot be used again")
        if self._stepper is None:
            self._stepper = _StepThread(self.name)
            weakref.finalize(self, self._stepper.stop)
        if not self._stepper.run(self._step_impl, (t, h), self.step_timeout_s):
            self._hung[0] = "timeout"
            self._failed = True
            what = "the integration over the step (model exchange)" if self._me else (
                "fmi3DoStep" if self._is3 else "fmi2DoStep")
            raise FMUTimeoutError(self.name, t, h, self.step_timeout_s, what, self.path.name)

    def _step_impl(self, t: float, h: float) -> None:
        if self._me:
            self._me_step(t, h)
            return
        if self._pick_in is not None:
            self._val_in[:] = self._pick_in(self.u)
            if self._is3:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in, self._nv_in)
            else:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in)
            if st > 1:
                raise self._call_failed(t, st, "fmi3SetFloat64" if self._is3 else "fmi2SetReal")
        if self._has_slow:
            self._slow_io(t, write=True)
        if self._is3:
            st = self._c_do_step(self._inst, t, h, True, *self._step_refs)
            if st > 1:
                raise self._call_failed(t, st, "fmi3DoStep", h=h)
            if self._b_term.value:
                raise self._call_failed(t, st, "fmi3DoStep", "the FMU requested terminateSimulation", h)
            if self._b_early.value:
                raise self._call_failed(t, st, "fmi3DoStep",
                                        f"early return at t = {self._d_last.value:.6g} s", h)
        else:
            st = self._c_do_step(self._inst, t, h, 1)
            if st > 1:
                raise self._call_failed(t, st, "fmi2DoStep",
                                        "step not completed (discard)" if st == 2 else "", h)
        if self._n_out:
            if self._is3:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out, self._nv_out)
            else:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out)
            if st > 1:
                raise self._call_failed(t + h, st, "fmi3GetFloat64" if self._is3 else "fmi2GetReal")
            self.y.update(zip(self._out_names, self._val_out))
        if self._has_slow:
            self._slow_io(t + h, write=False)

    # ----------------------------------------------------------- model exchange
    def _me_discrete_update(self, t: float) -> None:
        """Event iteration (``newDiscreteStates``/``updateDiscreteStates`` until converged)."""
        fmu = self.fmu
        need = True
        while need:
            if self._is3:
                need, term, _, _, defined, nxt = fmu.updateDiscreteStates()
            else:
                need, term, _, _, defined, nxt = fmu.newDiscreteStates()
            if term:
                raise self._call_failed(t, 0, "newDiscreteStates", "the FMU requested terminateSimulation")
        self._next_event = nxt if defined else None

    def _me_start(self, t0: float) -> None:
        """After ``exitInitializationMode``: initial event iteration, continuous-time mode, a new solver."""
        fmu = self.fmu
        md = self.model_description
        self._me_discrete_update(t0)
        fmu.enterContinuousTimeMode()
        nx, nz = md.numberOfContinuousStates, md.numberOfEventIndicators
        args = dict(nx=nx, nz=nz, get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
                    get_dx=fmu.getContinuousStateDerivatives if self._is3 else fmu.getDerivatives,
                    get_z=fmu.getEventIndicators)
        rtol = self.tolerance or 1e-6
        if self.solver == "cvode":
            from fmpy.sundials import CVodeSolver

            class _Hold:          # inputs are held over the step: nothing to apply inside the solver
                @staticmethod
                def apply(*a, **k):
                    return None

            self._solver = CVodeSolver(get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime,
                                       input=_Hold(), startTime=t0,
                                       maxStep=self.max_step_s or float("inf"), relativeTolerance=rtol,
                                       maxNumSteps=100000, **args)
        else:
            self._solver = _ScipySolver(get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime,
                                        method=self.solver, rtol=rtol, max_step=self.max_step_s, **args)
        self._needs_cis = bool(getattr(self._iface, "needsCompletedIntegratorStep", True))
        self._last_in = self._input_values()

    def _input_values(self) -> tuple:
        vals = tuple(self._pick_in(self.u)) if self._pick_in is not None else ()
        if self._has_slow:
            vals += tuple(self.u[p] for _, ps, _ in self._slow_in for p in ps)
        return vals

    def _me_event(self, t: float) -> None:
        fmu = self.fmu
        fmu.enterEventMode()
        self._me_discrete_update(t)
        fmu.enterContinuousTimeMode()
        self._solver.reset(t)

    def _me_step(self, t: float, h: float) -> None:
        fmu = self.fmu
        t_end = t + h
        function = "model exchange"
        try:
            function = "setTime"
            fmu.setTime(t)
            cur = self._input_values()
            if cur != self._last_in:
                # a held input that jumps at the communication point is an input event (as fmpy's Input)
                function = "enterEventMode (input event)"
                fmu.enterEventMode()
                self._write_inputs(t)
                self._me_discrete_update(t)
                fmu.enterContinuousTimeMode()
                self._solver.reset(t)
                self._last_in = cur
            time = t
            stuck = 0
            while time < t_end and not _isclose(time, t_end):
                t_before = time
                target = t_end
                nxt = self._next_event
                time_event = False
                if nxt is not None and nxt < target + 1e-12 * max(1.0, abs(target)):
                    if _isclose(nxt, target) or nxt < target:
                        target, time_event = max(nxt, time), True
                function = f"solver {self.solver}"
                state_event, _, time = self._solver.step(time, target)
                function = "setTime"
                fmu.setTime(time)
                step_event = False
                if self._needs_cis:
                    function = "completedIntegratorStep"
                    step_event, term = fmu.completedIntegratorStep()
                    if term:
                        raise self._call_failed(time, 0, function, "the FMU requested terminateSimulation", h)
                if state_event or step_event or (time_event and _isclose(time, target)):
                    function = "event update"
                    self._me_event(time)
                stuck = stuck + 1 if _isclose(time, t_before) else 0
                if stuck > 100:
                    raise self._call_failed(time, 3, function, "more than 100 events without time advancing "
                                            "(chattering event indicator)", h)
            self._time = t_end
        except FMUStepError:
            raise
        except Exception as exc:
            raise self._call_failed(t, getattr(exc, "status", 3), function, str(exc), h) from exc
        self._read_outputs(t_end)

    # ---------------------------------------------------------------- state
    def get_state(self) -> _Snapshot:
        """Snapshot via ``getFMUstate`` (requires ``canGetAndSetFMUstate``)."""
        if not self.can_get_set_state:
            raise FMUStateError(f"FMU component '{self.name}' ({self.path.name}): the FMU cannot save/restore "
                                f"its state (canGetAndSetFMUstate is false in its model description)")
        if self.fmu is None:
            raise FMUError(f"FMU component '{self.name}': get_state() after terminate()")
        try:
            handle = self.fmu.getFMUState() if self._is3 else self.fmu.getFMUstate()
        except Exception as exc:
            raise self._call_failed(float("nan"), getattr(exc, "status", 3), "getFMUstate", str(exc)) from exc
        extra = None
        if self._me:
            # restart the solver here too, so that a restored run and the original one continue alike
            extra = (getattr(self, "_time", None), getattr(self, "_next_event", None), self._last_in)
            if extra[0] is not None and getattr(self, "_solver", None) is not None:
                self._solver.reset(extra[0])
        return _Snapshot(self, handle, dict(self.u), dict(self.y), extra)

    def set_state(self, state: _Snapshot) -> None:
        """Restore a snapshot made by :meth:`get_state` of this component."""
        if not self.can_get_set_state:
            raise FMUStateError(f"FMU component '{self.name}' ({self.path.name}): the FMU cannot save/restore "
                                f"its state (canGetAndSetFMUstate is false in its model description)")
        if not isinstance(state, _Snapshot) or state._owner() is not self:
            raise FMUStateError(f"FMU component '{self.name}': set_state() needs a snapshot taken from this "
                                f"component by get_state()")
        try:
            if self._is3:
                self.fmu.setFMUState(state.handle)
            else:
                self.fmu.setFMUstate(state.handle)
        except Exception as exc:
            raise self._call_failed(float("nan"), getattr(exc, "status", 3), "setFMUstate", str(exc)) from exc
        self.u.clear()
        self.u.update(state.u)
        self.y.clear()
        self.y.update(state.y)
        if self._me and state.extra is not None:
            self._time, self._next_event, self._last_in = state.extra
            if self._time is not None:
                self._solver.reset(self._time)

    def terminate(self) -> None:
        """``terminate`` (if initialised and not failed), ``freeInstance``, delete extracted files. Idempotent."""
        fmu = self.fmu
        if self._stepper is not None and not self._hung[0]:
            self._stepper.stop()
            self._stepper = None
        if fmu is None:
            return
        err = None
        try:
            if self._initialized and not self._failed and not self._hung[0]:
                fmu.terminate()
        except Exception as exc:  # still free the instance
            err = exc
        finally:
            self._initialized = False
            self._solver = None
            self._finalizer()
        if err is not None:
            raise FMUError(f"FMU component '{self.name}': fmiTerminate failed: {err}") from err

    # -------------------------------------------------------------- helpers
    @classmethod
    def from_spec(cls, name: str, spec: Mapping[str, Any], base_dir: str | Path | None = None,
                  replaces: type | Mapping[str, str] | None = None, where: str = "<scenario>") -> "FMUComponent":
        """Build from a scenario table, e.g.::

            [components.battery]
            fmu = "fmus/battery.fmu"                  # relative to the scenario file
            mapping = { P = "power_w", I = "current_a" }
            parameters = { capacity = 30.0 }
            start = { P = 0.0 }
            feedthrough = { current_a = ["power_w"] }
            interface = "me"                          # model exchange (default: auto)
            solver = "cvode"                          # or BDF, Radau, LSODA, RK45, DOP853
            tolerance = 1e-8
            step_timeout_s = 60

        ``replaces`` (the native class or its TYPE's ports) turns on the unit check.
        Unknown keys raise :class:`~shevsim.core.errors.ScenarioError` naming ``where``.
        """
        from ..core.errors import ScenarioError

        allowed = {"fmu", "mapping", "parameters", "start", "feedthrough", "validate", "tolerance", "type",
                   "interface", "solver", "max_step_s", "step_timeout_s"}
        extra = set(spec) - allowed
        if extra:
            k = sorted(extra)[0]
            raise ScenarioError(f"{where}: component '{name}': unknown FMU key '{k}'{_suggest(k, allowed)}")
        if "fmu" not in spec:
            raise ScenarioError(f"{where}: component '{name}': missing 'fmu' (path of the FMU file)")
        path = Path(spec["fmu"])
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        return cls(name, path, mapping=spec.get("mapping"), parameters=spec.get("parameters"),
                   start_values=spec.get("start"), expected_units=replaces,
                   feedthrough=spec.get("feedthrough"), validate=spec.get("validate", True),
                   tolerance=spec.get("tolerance"), interface=spec.get("interface", "auto"),
                   solver=spec.get("solver", "cvode"), max_step_s=spec.get("max_step_s"),
                   step_timeout_s=spec.get("step_timeout_s", DEFAULT_STEP_TIMEOUT_S))

    def __repr__(self) -> str:
        kind = "model exchange" if self._me else "co-simulation"
        return f"<FMUComponent {self.name!r} {self.path.name} FMI {self.fmi_version} {kind}>"


def component_from_spec(spec, scenario, where: str) -> FMUComponent:
    """The :class:`FMUComponent` of a scenario's ``type = "fmu"`` component spec (registered with
    :func:`shevsim.core.registry.register_fmu_factory`; errors name ``where``).

    An FMU that ``replaces`` a native type is checked against that type's port units; an FMU with a
    ``seed`` parameter gets the same per-component seed as the native component would."""
    from ..core.errors import ScenarioError, ShevsimError
    from ..core.registry import component_class
    from ..core.scenario import component_seed
    from ..core.paths import DATA_ROOT
    fmu_path = Path(spec.fmu)
    if not fmu_path.is_file() and spec.replaces and is_inside(fmu_path, DATA_ROOT):
        fmu_path = bundled_export(spec, where)      # a bundled scenario's exported native component
    if not fmu_path.is_file():
        kind = spec.replaces or "TYPE"
        raise ScenarioError(f"{where}: field 'fmu': file '{spec.fmu}' not found (an exported native component "
                            f"is built with: shevsim fmu export {kind} --params FILE -o {fmu_path.name} in a "
                            f"folder of yours, and the scenario's fmu = \"...\" names that file)")
    expected = None
    if spec.replaces is not None:
        expected = component_class(spec.replaces, where)
    params = dict(spec.overrides)
    try:
        md = load_model_description(fmu_path)
        names = {v.name for v in md.modelVariables if v.causality == "parameter"}
        if "seed" in names and "seed" not in params:   # same noise seed as the native component
            params["seed"] = component_seed(scenario.seed, spec.name)
        return FMUComponent(spec.name, fmu_path, mapping=spec.mapping, parameters=params, expected_units=expected)
    except ShevsimError as exc:
        raise ScenarioError(f"{where}: {exc}") from exc


def is_inside(p: Path, root: Path) -> bool:
    try:
        Path(p).resolve().relative_to(Path(root).resolve())
        return True
    except ValueError:
        return False


def bundled_export(spec: ComponentSpec, where: str) -> Path:
    """The FMU a bundled scenario names but the package does not ship (``fmus/battery.fmu``, ``replaces =
    "battery"``): exported once from the native component with its bundled default parameters into
    :func:`user_cache_dir` (never into the installed package) and reused while the sources are unchanged."""
    import hashlib
    import logging
    import os
    from .. import __version__
    from ..core.errors import ScenarioError, ShevsimError
    from ..core.paths import DATA_ROOT, user_cache_dir
    kind = str(spec.replaces)
    params = DATA_ROOT / "components" / kind / "default.toml"
    src = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(f"{__version__}|{kind}|{params.read_bytes() if params.is_file() else b''!r}".encode())
    for f in sorted(src.rglob("*.py")):
        st = f.stat()
        h.update(f"{f.relative_to(src)}:{st.st_size}:{st.st_mtime_ns}".encode())
    out = user_cache_dir() / "fmus" / f"{Path(spec.fmu).stem}-{h.hexdigest()[:12]}.fmu"
    if out.is_file():
        return out
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        from ..fmu.export import export_component
        logging.getLogger(__name__).warning("%s: building %s once from the native '%s' component (%s) into %s",
                                            where, Path(spec.fmu).name, kind, params.name, out)
        tmp = out.with_name(f".{out.name}.tmp-{os.getpid()}")
        export_component(kind, params if params.is_file() else None, tmp)
        os.replace(tmp, out)
    except ShevsimError as exc:
        raise ScenarioError(f"{where}: field 'fmu': '{spec.fmu}' is not shipped and could not be built from the "
                            f"native '{kind}' component: {exc}") from exc
    except OSError as exc:
        raise ScenarioError(f"{where}: field 'fmu': '{spec.fmu}' is not shipped and cannot be built into "
                            f"{out.parent} ({exc}); set SHEVSIM_CACHE_DIR to a writable folder") from exc
    return out
