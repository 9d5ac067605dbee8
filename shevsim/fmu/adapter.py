"""adapter.py - an FMI 2.0 / 3.0 co-simulation FMU wrapped as a shevsim component.

:class:`FMUComponent` loads a co-simulation FMU with ``fmpy``, exposes its
inputs and outputs as ports (``u``/``y`` dicts, exactly like a native
component) and steps it with ``doStep``. The master cannot tell it from a
native component.

Hot path
--------
All Real/Float64 inputs are written with ONE ``fmi2SetReal``/``fmi3SetFloat64``
call and all Real/Float64 outputs read with ONE ``fmi2GetReal``/``fmi3GetFloat64``
call, on preallocated ctypes arrays of value references and values, calling the
raw ctypes entry points that ``fmpy`` loaded (``fmpy``'s own ``getReal`` builds
new arrays on every call). Status codes are checked inline; a failing ``doStep``
raises :class:`~shevsim.fmu.errors.FMUStepError` naming the component, the time
and the FMI status (plus the FMU's last log messages).

Integer/Boolean inputs and outputs (rare in plant models) are supported
through ``fmpy``'s regular API, one call per type.

Life cycle and resources
------------------------
``__init__`` validates and extracts the FMU to an absolute temporary
directory and instantiates it (load errors surface when the scenario is
built); ``initialize(t0)`` applies parameters and start values and runs the
FMI initialisation; ``terminate()`` terminates, frees the instance and deletes
the extracted files. A finaliser frees the instance and the directory if the
caller never reaches ``terminate`` (for example after an exception), and a
failure in ``__init__`` cleans up before raising.
"""
from __future__ import annotations

import difflib
import operator
import shutil
import tempfile
import weakref
import zipfile
from collections import deque
from ctypes import byref, c_bool, c_double, c_uint32
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence
from xml.etree import ElementTree

from ..core.component import Component
from ..core.variables import Variable, canonical_unit, units_compatible
from .errors import (FMUError, FMULoadError, FMUMappingError, FMUStateError, FMUStepError,
                     FMUUnitError, FMUUnsupportedError)

__all__ = ["FMUComponent", "read_fmi_version", "load_model_description", "expected_units_of"]

_REAL_TYPES = ("Real", "Float64")
_INT_TYPES = ("Integer", "Int32", "Int64", "Int16", "Int8", "UInt32", "UInt16", "UInt8", "UInt64",
              "Enumeration")
_BOOL_TYPES = ("Boolean",)


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
        data = md.read_bytes()
    else:
        if not zipfile.is_zipfile(path):
            raise FMULoadError(f"{path}: not a ZIP archive - the FMU file is corrupt or not an FMU")
        try:
            with zipfile.ZipFile(path) as zf:
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


def load_model_description(path: str | Path, validate: bool = True):
    """Read and check an FMU's model description (FMI 2.0/3.0 co-simulation only).

    Returns the ``fmpy`` ``ModelDescription``. Raises :class:`FMULoadError`
    (missing/corrupt/invalid) or :class:`FMUUnsupportedError` (FMI version
    other than 2.0/3.x, or no co-simulation interface).
    """
    from fmpy import read_model_description

    path = Path(path)
    version = read_fmi_version(path)
    if not (version == "2.0" or version.startswith("3.")):
        raise FMUUnsupportedError(
            f"{path}: FMI version {version!r} is not supported (shevsim imports FMI 2.0 and 3.0 "
            f"co-simulation FMUs)")
    try:
        md = read_model_description(str(path), validate=validate)
    except Exception as exc:  # fmpy raises ValidationError or plain Exception
        raise FMULoadError(f"{path}: invalid modelDescription.xml: {exc}") from exc
    if md.coSimulation is None:
        kinds = [k for k in ("modelExchange", "scheduledExecution") if getattr(md, k, None) is not None]
        raise FMUUnsupportedError(
            f"{path}: the FMU has no co-simulation interface ({' and '.join(kinds) or 'none'} only); "
            f"shevsim runs co-simulation FMUs - re-export it for co-simulation (e.g. with a solver "
            f"embedded)")
    return md


def expected_units_of(component: type | Mapping[str, str] | None) -> dict[str, str]:
    """Port -> unit expectations from a native component class (or a mapping, passed through)."""
    if component is None:
        return {}
    if isinstance(component, Mapping):
        return dict(component)
    variables = component.VARIABLES if isinstance(component, type) else component.variables()
    return {v.name: v.unit for v in variables if v.causality in ("input", "output")}


def _var_unit(v) -> str:
    unit = getattr(v, "unit", None)
    if not unit and getattr(v, "declaredType", None) is not None:
        unit = getattr(v.declaredType, "unit", None)
    return unit or ""


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


def _cleanup(fmu_box: list, unzipdir: str | None) -> None:
    """Finaliser: free the FMU instance (if any) and delete the extracted files."""
    fmu = fmu_box[0] if fmu_box else None
    if fmu is not None:
        fmu_box[0] = None
        try:
            fmu.freeInstance()
        except Exception:
            pass
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


class _Snapshot:
    """Opaque FMU state handle plus copies of the port dicts; frees the FMU state when dropped."""

    __slots__ = ("handle", "u", "y", "_owner", "__weakref__")

    def __init__(self, owner: "FMUComponent", handle, u: dict, y: dict):
        self.handle = handle
        self.u = u
        self.y = y
        self._owner = weakref.ref(owner)

    def __del__(self):
        owner = self._owner()
        if owner is not None and owner._fmu_box and owner._fmu_box[0] is not None:
            try:
                owner._fmu_box[0].freeFMUstate(self.handle)
            except Exception:
                pass


class FMUComponent(Component):
    """A co-simulation FMU (FMI 2.0 or 3.0) as a shevsim component.

    Parameters
    ----------
    name : str
        Instance name (used in error messages and as the FMI instance name).
    fmu_path : str or Path
        The ``.fmu`` file (or a directory holding an extracted FMU).
    mapping : dict, optional
        ``{fmu_variable_name: port_name}``. Renames FMU inputs/outputs/parameters
        to shevsim port names; unmapped inputs and outputs keep their FMU names.
        An unknown FMU variable raises :class:`FMUMappingError`.
    parameters : dict, optional
        ``{name: value}`` applied before initialisation; ``name`` is an FMU
        variable name or a mapped port name. Typically causality
        ``parameter`` variables.
    start_values : dict, optional
        Like ``parameters`` but for inputs (sets the held input value, ``u``)
        or any other variable with a settable start value.
    expected_units : native component class or dict, optional
        Declared expectations ``{port: unit}`` (a ``Component`` subclass means
        "the ports of the component this FMU replaces"). A mapped FMU variable
        whose unit differs raises :class:`FMUUnitError`; an FMU variable
        without a unit adopts the expected one.
    feedthrough : dict, optional
        ``{output_port: [input_port, ...]}`` overriding the direct
        dependencies read from ``<ModelStructure>`` (FMUs that omit them
        are assumed to depend on every input, as FMI prescribes).
    validate : bool
        Validate ``modelDescription.xml`` with fmpy (default True).
    tolerance : float, optional
        Passed to ``setupExperiment``/``enterInitializationMode``.

    Ports
    -----
    The FMU's Real/Float64 (and Integer/Boolean) variables of causality
    ``input``/``output``, with the units declared in the model description;
    ``parameter`` variables are listed by :meth:`variables` with causality
    ``parameter``. Outputs declare ``depends_on`` from the FMU's
    ``ModelStructure`` dependencies.
    """

    TYPE = "fmu"
    Params = None
    _static = ("name", "params")

    def __init__(self, name: str, fmu_path: str | Path, mapping: Mapping[str, str] | None = None,
                 parameters: Mapping[str, Any] | None = None,
                 start_values: Mapping[str, Any] | None = None,
                 expected_units: type | Mapping[str, str] | None = None,
                 feedthrough: Mapping[str, Sequence[str]] | None = None,
                 validate: bool = True, tolerance: float | None = None):
        self.path = Path(fmu_path).absolute()
        self.tolerance = tolerance
        self._fmu_box: list = [None]
        self._unzipdir: str | None = None
        self._initialized = False
        self._failed = False
        self._log: deque = deque(maxlen=20)
        md = load_model_description(self.path, validate=validate)
        self.model_description = md
        self.fmi_version = md.fmiVersion
        self._is3 = md.fmiVersion.startswith("3.")
        cs = md.coSimulation
        self.can_get_set_state = bool(getattr(cs, "canGetAndSetFMUstate", False))

        self._build_ports(name, mapping or {}, expected_units, feedthrough or {})
        self._parameters = self._resolve_values(parameters or {}, "parameters")
        self._start_values = self._resolve_values(start_values or {}, "start_values")
        super().__init__(name, None)
        self.params = dict(parameters or {})
        for vname, value in self._start_values.items():
            port = self._port_of.get(vname)
            if port in self.u:
                self.u[port] = float(value)

        self._instantiate(name)

    # ------------------------------------------------------------------ ports
    def _build_ports(self, name: str, mapping: Mapping[str, str], expected, feedthrough) -> None:
        md = self.model_description
        by_name = {v.name: v for v in md.modelVariables}
        self._vars_by_name = by_name
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
        expected_units = expected_units_of(expected)
        self._port_of: dict[str, str] = {}
        self._fmu_of: dict[str, str] = {}
        variables: list[Variable] = []
        inputs: list = []
        outputs: list = []
        for v in md.modelVariables:
            if v.causality not in ("input", "output", "parameter"):
                continue
            if v.type not in _REAL_TYPES + _INT_TYPES + _BOOL_TYPES:
                if v.causality == "parameter":
                    continue  # string/binary parameters can still be set via `parameters`
                raise FMUUnsupportedError(
                    f"{self.path}: {v.causality} '{v.name}' has type {v.type}; shevsim ports are "
                    f"Real/Float64, Integer or Boolean")
            if getattr(v, "dimensions", None):
                raise FMUUnsupportedError(f"{self.path}: array variable '{v.name}' is not supported")
            port = mapping.get(v.name, v.name)
            if port in self._fmu_of:
                raise FMUMappingError(f"{self.path}: component '{name}': port name '{port}' used twice "
                                      f"(FMU variables '{self._fmu_of[port]}' and '{v.name}')")
            self._port_of[v.name] = port
            self._fmu_of[port] = v.name
            unit = _var_unit(v)
            if port in expected_units and v.causality != "parameter":
                want = expected_units[port]
                if not unit:
                    unit = want
                elif not units_compatible(unit, want):
                    raise FMUUnitError(
                        f"{self.path}: component '{name}': FMU variable '{v.name}' (port '{port}') has unit "
                        f"'{unit}' but the port it replaces declares '{want}' "
                        f"(canonical '{canonical_unit(unit)}' vs '{canonical_unit(want)}')")
            if v.causality == "input":
                inputs.append((v, port, unit))
            elif v.causality == "output":
                outputs.append((v, port, unit))
            else:
                variables.append(Variable(port, "parameter", unit or "1", _to_float(v.start),
                                          v.description or ""))
        input_ports = [p for _, p, _ in inputs]
        # direct dependencies of outputs (ModelStructure); absent => depends on all inputs
        deps: dict[str, tuple[str, ...]] = {}
        for unknown in md.outputs:
            port = self._port_of.get(unknown.variable.name)
            if port is None:
                continue
            if unknown.dependencies is None:
                deps[port] = tuple(input_ports)
            else:
                deps[port] = tuple(self._port_of[d.name] for d in unknown.dependencies
                                   if d.causality == "input" and d.name in self._port_of)
        for out_port, ins in feedthrough.items():
            if out_port not in [p for _, p, _ in outputs]:
                raise FMUMappingError(f"{self.path}: component '{name}': feedthrough names unknown output "
                                      f"port '{out_port}'{_suggest(out_port, [p for _, p, _ in outputs])}")
            bad = [i for i in ins if i not in input_ports]
            if bad:
                raise FMUMappingError(f"{self.path}: component '{name}': feedthrough of '{out_port}' names "
                                      f"unknown input port(s) {bad}")
            deps[out_port] = tuple(ins)
        for v, port, unit in inputs:
            variables.append(Variable(port, "input", unit or "1", _to_float(v.start), v.description or ""))
        for v, port, unit in outputs:
            variables.append(Variable(port, "output", unit or "1", _to_float(v.start), v.description or "",
                                      deps.get(port, tuple(input_ports))))
        self._variables = tuple(variables)
        self._inputs = inputs
        self._outputs = outputs

    def variables(self) -> tuple[Variable, ...]:
        """Ports built from the model description (inputs, outputs and parameters)."""
        return self._variables

    def inputs(self) -> tuple[Variable, ...]:  # type: ignore[override]
        return tuple(v for v in self._variables if v.causality == "input")

    def outputs(self) -> tuple[Variable, ...]:  # type: ignore[override]
        return tuple(v for v in self._variables if v.causality == "output")

    def _resolve_values(self, values: Mapping[str, Any], what: str) -> dict[str, Any]:
        """Map user keys (FMU names or port names) to FMU variable names."""
        out = {}
        for key, value in values.items():
            if key in self._vars_by_name:
                out[key] = value
            elif key in self._fmu_of:
                out[self._fmu_of[key]] = value
            else:
                options = list(self._vars_by_name) + list(self._fmu_of)
                raise FMUMappingError(f"{self.path}: {what}: unknown FMU variable or port '{key}'"
                                      f"{_suggest(key, options)}")
        return out

    # -------------------------------------------------------------- life cycle
    def _instantiate(self, name: str) -> None:
        import fmpy
        from fmpy import extract

        md = self.model_description
        platform = fmpy.platform_tuple if self._is3 else fmpy.platform
        try:
            self._unzipdir = str(Path(tempfile.mkdtemp(prefix=f"shevsim_fmu_{name}_")).absolute())
            self._finalizer = weakref.finalize(self, _cleanup, self._fmu_box, self._unzipdir)
            if self.path.is_dir():
                shutil.copytree(self.path, self._unzipdir, dirs_exist_ok=True)
            else:
                extract(str(self.path), self._unzipdir)
            ident = md.coSimulation.modelIdentifier
            bindir = Path(self._unzipdir) / "binaries" / platform
            if not any(bindir.glob(ident + ".*")):
                have = sorted(p.name for p in (Path(self._unzipdir) / "binaries").glob("*"))
                raise FMULoadError(f"{self.path}: no binary for platform '{platform}' "
                                   f"(the FMU has: {', '.join(have) or 'no binaries'})")
            if self._is3:
                from fmpy.fmi3 import FMU3Slave
                fmu = FMU3Slave(guid=md.instantiationToken, unzipDirectory=self._unzipdir,
                                modelIdentifier=ident, instanceName=name)
                fmu.instantiate(logMessage=_make_logger(self._log, fmi3=True))
            else:
                from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
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
                self._callbacks = cb  # keep alive
                fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir, modelIdentifier=ident,
                                instanceName=name)
                fmu.instantiate(callbacks=cb)
            self._fmu_box[0] = fmu
        except FMUError:
            self._finalizer()
            raise
        except Exception as exc:
            self._finalizer()
            raise FMULoadError(f"{self.path}: cannot load/instantiate the FMU for component '{name}': "
                               f"{exc}{self._log_tail()}") from exc
        self._prepare_hot_path()

    def _log_tail(self) -> str:
        msgs = [m for s, m in self._log if s >= 1][-3:]
        return (" | FMU log: " + " / ".join(msgs)) if msgs else ""

    @property
    def fmu(self):
        """The fmpy ``FMU2Slave``/``FMU3Slave`` (None after :meth:`terminate`)."""
        return self._fmu_box[0]

    def _prepare_hot_path(self) -> None:
        fmu = self.fmu
        f = fmu._functions
        if self._is3:
            self._c_set_real, self._c_get_real = f["fmi3SetFloat64"], f["fmi3GetFloat64"]
            self._c_do_step = f["fmi3DoStep"]
            self._b_event, self._b_term, self._b_early = c_bool(), c_bool(), c_bool()
            self._d_last = c_double()
            self._step_refs = (byref(self._b_event), byref(self._b_term), byref(self._b_early),
                               byref(self._d_last))
        else:
            self._c_set_real, self._c_get_real = f["fmi2SetReal"], f["fmi2GetReal"]
            self._c_do_step = f["fmi2DoStep"]
        self._inst = fmu.component

        def split(items):
            real = [(v.valueReference, p) for v, p, _ in items if v.type in _REAL_TYPES]
            ints = [(v.valueReference, p, v.type) for v, p, _ in items if v.type in _INT_TYPES]
            bools = [(v.valueReference, p) for v, p, _ in items if v.type in _BOOL_TYPES]
            return real, ints, bools

        rin, self._int_in, self._bool_in = split(self._inputs)
        rout, self._int_out, self._bool_out = split(self._outputs)
        self._n_in, self._n_out = len(rin), len(rout)
        self._in_names = tuple(p for _, p in rin)
        self._out_names = tuple(p for _, p in rout)
        self._vr_in = (c_uint32 * len(rin))(*[vr for vr, _ in rin])
        self._val_in = (c_double * len(rin))()
        self._vr_out = (c_uint32 * len(rout))(*[vr for vr, _ in rout])
        self._val_out = (c_double * len(rout))()
        if len(rin) == 1:
            one = rin[0][1]
            self._pick_in = lambda u: (u[one],)
        elif rin:
            self._pick_in = operator.itemgetter(*self._in_names)
        else:
            self._pick_in = None
        self._has_slow = bool(self._int_in or self._bool_in or self._int_out or self._bool_out)

    def _call_failed(self, t: float, status: int, function: str, detail: str = "",
                     h: float | None = None) -> FMUStepError:
        self._failed = True
        return FMUStepError(self.name, t, status, function, (detail + self._log_tail()).lstrip(" |"), h)

    def _set_value(self, vname: str, value: Any) -> None:
        fmu = self.fmu
        v = self._vars_by_name[vname]
        vr = [v.valueReference]
        try:
            if v.type in _REAL_TYPES:
                (fmu.setFloat64 if self._is3 else fmu.setReal)(vr, [float(value)])
            elif v.type == "Float32":
                fmu.setFloat32(vr, [float(value)])
            elif v.type in _INT_TYPES:
                setter = fmu.setInteger if not self._is3 else getattr(fmu, "set" + (
                    "Int64" if v.type == "Enumeration" else v.type))
                setter(vr, [int(value)])
            elif v.type in _BOOL_TYPES:
                fmu.setBoolean(vr, [bool(value)])
            elif v.type == "String":
                fmu.setString(vr, [str(value)])
            else:
                raise FMUMappingError(f"{self.path}: cannot set variable '{vname}' of type {v.type}")
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
        if self._initialized:
            try:
                fmu.reset()
            except Exception as exc:
                raise self._call_failed(t0, getattr(exc, "status", 3), "reset", str(exc)) from exc
        for vname, value in {**self._parameters, **self._start_values}.items():
            self._set_value(vname, value)
        try:
            if self._is3:
                fmu.enterInitializationMode(tolerance=self.tolerance, startTime=t0)
            else:
                fmu.setupExperiment(tolerance=self.tolerance, startTime=t0)
                fmu.enterInitializationMode()
            self._write_inputs(t0)
            fmu.exitInitializationMode()
        except FMUStepError:
            raise
        except Exception as exc:
            raise self._call_failed(t0, getattr(exc, "status", 3), getattr(exc, "function", "initialization"),
                                    str(exc)) from exc
        self._initialized = True
        self._failed = False
        self._read_outputs(t0)

    def _write_inputs(self, t: float) -> None:
        if self._pick_in is not None:
            self._val_in[:] = self._pick_in(self.u)
            if self._is3:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in, self._n_in)
            else:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in)
            if st > 1:
                raise self._call_failed(t, st, "fmi3SetFloat64" if self._is3 else "fmi2SetReal")
        if self._has_slow:
            self._slow_io(t, write=True)

    def _read_outputs(self, t: float) -> None:
        if self._n_out:
            if self._is3:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out, self._n_out)
            else:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out)
            if st > 1:
                raise self._call_failed(t, st, "fmi3GetFloat64" if self._is3 else "fmi2GetReal")
            self.y.update(zip(self._out_names, self._val_out))
        if self._has_slow:
            self._slow_io(t, write=False)

    def _slow_io(self, t: float, write: bool) -> None:
        fmu = self.fmu
        try:
            if write:
                for vr, port, typ in self._int_in:
                    setter = fmu.setInteger if not self._is3 else getattr(
                        fmu, "set" + ("Int64" if typ == "Enumeration" else typ))
                    setter([vr], [int(round(self.u[port]))])
                if self._bool_in:
                    fmu.setBoolean([vr for vr, _ in self._bool_in], [self.u[p] != 0.0 for _, p in self._bool_in])
            else:
                for vr, port, typ in self._int_out:
                    getter = fmu.getInteger if not self._is3 else getattr(
                        fmu, "get" + ("Int64" if typ == "Enumeration" else typ))
                    self.y[port] = float(getter([vr])[0])
                if self._bool_out:
                    vals = fmu.getBoolean([vr for vr, _ in self._bool_out])
                    for (_, p), b in zip(self._bool_out, vals):
                        self.y[p] = 1.0 if b else 0.0
        except Exception as exc:
            raise self._call_failed(t, getattr(exc, "status", 3), getattr(exc, "function", "get/set"),
                                    str(exc)) from exc

    def do_step(self, t: float, h: float) -> None:
        """Set all inputs (one call), ``doStep(t, h)``, get all outputs (one call)."""
        if self._pick_in is not None:
            self._val_in[:] = self._pick_in(self.u)
            if self._is3:
                st = self._c_set_real(self._inst, self._vr_in, self._n_in, self._val_in, self._n_in)
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
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out, self._n_out)
            else:
                st = self._c_get_real(self._inst, self._vr_out, self._n_out, self._val_out)
            if st > 1:
                raise self._call_failed(t + h, st, "fmi3GetFloat64" if self._is3 else "fmi2GetReal")
            self.y.update(zip(self._out_names, self._val_out))
        if self._has_slow:
            self._slow_io(t + h, write=False)

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
        return _Snapshot(self, handle, dict(self.u), dict(self.y))

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

    def terminate(self) -> None:
        """``terminate`` (if initialised and not failed), ``freeInstance``, delete extracted files. Idempotent."""
        fmu = self.fmu
        if fmu is None:
            return
        err = None
        try:
            if self._initialized and not self._failed:
                fmu.terminate()
        except Exception as exc:  # still free the instance
            err = exc
        finally:
            self._initialized = False
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

        ``replaces`` (the native class or its TYPE's ports) turns on the unit check.
        Unknown keys raise :class:`~shevsim.core.errors.ScenarioError` naming ``where``.
        """
        from ..core.errors import ScenarioError

        allowed = {"fmu", "mapping", "parameters", "start", "feedthrough", "validate", "tolerance", "type"}
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
                   tolerance=spec.get("tolerance"))

    def __repr__(self) -> str:
        return f"<FMUComponent {self.name!r} {self.path.name} FMI {self.fmi_version}>"
