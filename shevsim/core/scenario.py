"""scenario.py - declarative scenario files (TOML) -> a ready-to-run `Master`.

Example:

    [scenario]
    name = "hd_udds_rule"
    step_s = 0.1                 # communication step
    method = "gauss-seidel"      # or "jacobi"
    # order = ["cycle", ...]     # optional explicit Gauss-Seidel order (default: from the graph)
    seed = 1                     # noise seeds of every component derive from it
    # stop_s = 1060              # default: the cycle's length

    [components.cycle]
    type = "cycle"                               # registry name (shevsim.components.REGISTRY)
    params = "components/cycle/hd_udds.toml"     # parameter file (relative to the project)
    step_multiple = 1                            # steps every k communication steps
    set = { repeat = 2 }                         # parameter overrides
    start = {}                                   # start values of inputs

    [components.battery_fmu]
    type = "fmu"
    fmu = "fmus/battery.fmu"
    map = { "power" = "power_w" }                # FMU variable -> port name
    replaces = "battery"                         # check ports/units against the native TYPE

    [connections]                                # input = output
    "driver.speed_ref_mps" = "cycle.speed_ref_mps"

    [[faults]]                                   # force an input from a time on
    at_s = 300.0
    port = "battery.h_conv_w_m2k"
    value = 3.0

    [record]
    signals = "all"                              # or a list of "component.port"

Every error names the file and the field.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import ScenarioError, ShevsimError, file_problem, toml_loads
from .master import Connection, Fault, Master, MasterSettings
from .overlay import overlay_tables, overlay_values, resolve_files
from .params import check_options, load_params
from .registry import component_class, fmu_component, fmu_ports, shared_quantities
from .tomlio import toml_key, toml_value
from shevsim.core.paths import DATA_ROOT, bundled_cycle, bundled_params, bundled_scenario

PROJECT_ROOT = DATA_ROOT   # the folder holding components/, cycles/, scenarios/ (checkout or wheel)

_TOP = {"scenario", "components", "connections", "faults", "record", "metrics", "shared"}
_SCEN = {"name", "description", "step_s", "stop_s", "t0_s", "method", "seed", "order", "extends"}
_COMP = {"type", "params", "set", "start", "step_multiple", "fmu", "map", "replaces", "overlay", "own"}
_FAULT = {"at_s", "port", "value"}
_RECORD = {"signals"}
#: the options of a scenario's ``[metrics]`` table (``--set metrics.OPTION=...``) and their types: float,
#: int, bool, a tuple of allowed strings, or [float] (a list of numbers). Numbers are checked against the
#: name rule of their key (`shevsim.core.params.name_rule()`: ``_pct`` in [0, 100], densities > 0...).
#: Read by [`shevsim.metrics.compute_metrics()`][shevsim.metrics.compute_metrics] and the speed-trace check ([`shevsim.run.TRACE_DEFAULTS`][shevsim.run.TRACE_DEFAULTS]).
METRICS_OPTIONS = {"cycle_duration_s": float, "soc_tolerance_pct": float, "cells_parallel": int,
                   "fuel_density_kg_per_l": float, "ah_weighting": ("constant", "wang2011"),
                   "ah_severity_factor": float, "hist_edges_a": [float], "pack_capacity_ah": float,
                   "pack_nominal_voltage_v": float, "eg_efficiency": float,
                   "trace_distance_tolerance": float, "trace_speed_tolerance_kmh": float,
                   "trace_speed_window_s": float, "trace_allow_miss": bool}


def check_metrics_options(options: Any, where: str) -> dict:
    """Check a ``[metrics]`` table like component parameters: unknown keys (with a suggestion), types
    and ranges (`METRICS_OPTIONS`). Returns it as a dict (ScenarioError otherwise)."""
    if not isinstance(options, dict):
        raise ScenarioError(f"{where}: expected a table of name = value, got {type(options).__name__}")
    for k, v in options.items():
        typ = METRICS_OPTIONS.get(k)
        if typ is None:
            raise ScenarioError(f"{where}: unknown option '{k}'{_hint(k, METRICS_OPTIONS)}")
        isnum = lambda x: isinstance(x, (int, float)) and not isinstance(x, bool)  # noqa: E731
        if typ is float and not isnum(v) or typ is int and not (isinstance(v, int) and not isinstance(v, bool)):
            raise ScenarioError(f"{where}: option '{k}' = {v!r}: must be "
                                f"{'an integer' if typ is int else 'a number'}")
        if typ is bool and not isinstance(v, bool):
            raise ScenarioError(f"{where}: option '{k}' = {v!r}: must be true or false")
        if isinstance(typ, tuple) and v not in typ:
            raise ScenarioError(f"{where}: option '{k}' = {v!r}: must be one of {', '.join(map(repr, typ))}")
        if isinstance(typ, list) and not (isinstance(v, list) and v and all(isnum(x) for x in v)):
            raise ScenarioError(f"{where}: option '{k}' = {v!r}: must be a non-empty list of numbers")
    nums = {k: v for k, v in options.items() if METRICS_OPTIONS[k] in (float, int) or isinstance(METRICS_OPTIONS[k], list)}
    check_options(nums, where)
    return dict(options)


def _hint(key: str, options) -> str:
    best = difflib.get_close_matches(key, sorted(options), n=1)
    return f" (did you mean '{best[0]}'?)" if best else f" (allowed: {', '.join(sorted(options))})"


def _check_keys(d: dict, allowed: set, where: str) -> None:
    if not isinstance(d, dict):
        raise ScenarioError(f"{where}: expected a table, got {type(d).__name__}")
    for k in d:
        if k not in allowed:
            raise ScenarioError(f"{where}: unknown key '{k}'{_hint(k, allowed)}")


def resolve_path(p: str, scenario_path: Path | None) -> Path:
    """Resolve a data path: absolute, else relative to the scenario's folder, its parent, the cwd, the project."""
    path = Path(p)
    if path.is_absolute():
        return path
    cands = []
    if scenario_path is not None:
        cands += [scenario_path.parent / path, scenario_path.parent.parent / path]
    cands += [Path.cwd() / path, PROJECT_ROOT / path]
    for c in cands:
        if c.exists():
            return c.resolve()
    for c in cands:                       # not there yet (an FMU to build): where its folder exists
        if c.parent.is_dir():
            return c.resolve()
    return cands[0]


def parse_value(text: str, origin: str = "--set") -> Any:
    """Parse a ``--set`` value as exactly one TOML value (number, bool, string, list, inline table); a bare
    word is a string. Anything after the value (a new line with more TOML, a second value) is refused
    (ScenarioError naming ``origin``), as are control characters in a bare word."""
    if any(c in text for c in "\n\r\x00"):
        raise ScenarioError(f"{origin}: the value must be exactly one value on one line (it holds a line break "
                            f"or a NUL character: {text!r}); quote a string that needs them as TOML "
                            f"(\"a\\nb\")")
    try:
        doc = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        raise ScenarioError(f"{origin}: the value is nested too deeply (more than Python's recursion limit "
                            f"allows); give a flat value") from None
    if set(doc) != {"v"}:             # cannot happen on one line, kept as the rule: exactly one value
        raise ScenarioError(f"{origin}: the value must be exactly one value, got {text!r}")
    return doc["v"]


def declared_ports(cls) -> tuple[dict[str, str], bool]:
    """``({port: "input" | "output" | "input/output"}, complete)`` declared by a component class: its
    ``VARIABLES`` and every variant ``VARIABLES_*`` (a vehicle's speed mode). ``complete`` is False when the
    class builds its ports otherwise (it overrides ``variables()`` and declares no variants), so a port
    missing here may still exist once the component is built."""
    from .component import Component
    kinds: dict[str, set] = {}
    variants = [a for a in dir(cls) if a.startswith("VARIABLES")]
    for attr in variants:
        for v in getattr(cls, attr) or ():
            if getattr(v, "causality", None) in ("input", "output"):
                kinds.setdefault(v.name, set()).add(v.causality)
    complete = getattr(cls, "variables", None) is getattr(Component, "variables") or len(variants) > 1
    return {p: "/".join(sorted(k)) for p, k in kinds.items()}, complete


@dataclass
class ComponentSpec:
    name: str
    type: str
    params_file: Path | None
    overrides: dict[str, Any]
    start: dict[str, float]
    step_multiple: int = 1
    fmu: Path | None = None
    mapping: dict[str, str] = field(default_factory=dict)
    replaces: str | None = None
    #: where an override came from when it was not the scenario file (``--set 'x.y=1'``,
    #: ``overrides['x.y']``): errors name that instead of the parameter file
    origins: dict[str, str] = field(default_factory=dict)
    #: the parameter file's ``[params]`` table captured with its ``*_file`` paths absolute (a study's
    #: bundle, `shevsim.studies.bundle`): when set, ``params_file`` is named in messages but not read
    params_table: dict[str, Any] | None = None
    #: parameters (or shared quantity names, ``"cell"``) this component keeps as its own instead of the
    #: scenario's shared quantities (`shevsim.components.shared`), e.g. a mismatched BMS
    own: list[str] = field(default_factory=list)
    #: where a scenario ``set`` or overlay value came from (named by the shared-quantity checks)
    sources: dict[str, str] = field(default_factory=dict)


@dataclass
class Scenario:
    """A parsed, validated scenario."""

    path: Path | None
    text: str
    name: str
    description: str
    settings: MasterSettings
    stop_s: float | None
    t0_s: float
    seed: int
    components: list[ComponentSpec]
    connections: list[Connection]
    faults: list[Fault]
    record: list[str] | None
    metrics: dict[str, Any]
    order: list[str] | None = None
    sets: list[str] = field(default_factory=list)     # command-line ``component.param=value`` overrides
    overlays: list[str] = field(default_factory=list)  # command-line ``--params COMPONENT=FILE`` overlays
    #: the quantities of the vehicle as a whole (``[shared]``, `shevsim.components.shared`)
    shared: dict[str, Any] = field(default_factory=dict)
    shared_origins: dict[str, str] = field(default_factory=dict)
    #: the vehicle's quantities resolved (a study's bundle captures them so a worker needs no vehicle file)
    shared_base: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        stop = f"{self.stop_s:g} s" if self.stop_s is not None else "from its cycle"
        return (f"<Scenario {self.name!r}: {len(self.components)} components "
                f"({', '.join(c.name for c in self.components[:8])}{', ...' if len(self.components) > 8 else ''}), "
                f"{len(self.connections)} connections, step {self.settings.step_s:g} s, stop {stop}>")

    def _repr_html_(self) -> str | None:
        from .registry import html_view
        return html_view("scenario", self)

    # ----------------------------------------------------------- inspect / change in Python
    def component(self, name: str) -> ComponentSpec:
        """The spec of component ``name`` (its ``overrides`` dict can be changed before running)."""
        for c in self.components:
            if c.name == name:
                return c
        names = [c.name for c in self.components]
        raise ScenarioError(f"scenario '{self.name}': unknown component '{name}'{_hint(name, names)}")

    @property
    def component_names(self) -> list[str]:
        """Names of the components, in declaration order."""
        return [c.name for c in self.components]

    def set(self, key: str, value: Any, origin: str | None = None) -> "Scenario":
        """Override one value (typed): ``"component.param"``, ``"shared.QUANTITY"`` (a quantity of the
        vehicle as a whole, reaching every component that uses it: ``"shared.mass_kg"``,
        ``"shared.vehicle"``), ``"scenario.step_s"`` (any [scenario] field: name, description, step_s,
        stop_s, t0_s, method, seed, order), ``"record.signals"`` or ``"metrics.<option>"``. ``origin``
        names the override in error messages. Returns self."""
        apply_override(self, key, value, origin or f"override '{key}'")
        return self

    def update(self, overrides: dict[str, Any] | None = None, **kw) -> "Scenario":
        """Apply several overrides (``{"vehicle.mass_kg": 18000.0, "scenario.stop_s": 60.0}``)."""
        for k, v in {**(overrides or {}), **kw}.items():
            self.set(k, v, f"overrides['{k}']")
        return self

    def add_component(self, name: str, type: str, params: str | Path | None = None, *,
                      set: dict[str, Any] | None = None, start: dict[str, float] | None = None,
                      step_multiple: int = 1, fmu: str | Path | None = None, mapping: dict[str, str] | None = None,
                      replaces: str | None = None) -> "Scenario":
        """Add a component by registry ``type`` (``params``: a parameter file, a bundled one by its
        path relative to the data root such as ``"components/vehicle/matv.toml"``), or an FMU with
        ``type="fmu"`` and ``fmu=PATH`` (``mapping``: FMU variable -> port name; ``replaces``: a native
        TYPE whose port units the FMU must match; ``set``: FMU parameters), as a scenario's
        ``[components.NAME]`` table does. Returns self."""
        _check_component_name(name, f"scenario '{self.name}'")
        where = f"add_component('{name}', '{type}')"
        if name in self.component_names:
            raise ScenarioError(f"scenario '{self.name}': component '{name}' already exists")
        if isinstance(step_multiple, bool) or not isinstance(step_multiple, int) or step_multiple < 1:
            raise ScenarioError(f"component '{name}': step_multiple must be an integer >= 1, got {step_multiple!r}")
        fmu_path = None
        if type == "fmu":
            if fmu is None:
                raise ScenarioError(f"{where}: type 'fmu' needs fmu=PATH (the .fmu file)")
            if params is not None:
                raise ScenarioError(f"{where}: an FMU takes no parameter file; give its parameters as set={{...}}")
            fmu_path = resolve_path(str(fmu), self.path)
            if not fmu_path.is_file():
                raise ScenarioError(f"{where}: fmu file '{fmu}' not found")
            if mapping is not None and (not isinstance(mapping, dict) or not all(
                    isinstance(k, str) and isinstance(v, str) for k, v in mapping.items())):
                raise ScenarioError(f"{where}: mapping must be a dict of FMU variable name -> port name (strings)")
            if replaces is not None:
                component_class(replaces, f"{where}: replaces")
        elif fmu is not None or mapping is not None or replaces is not None:
            raise ScenarioError(f"{where}: fmu=, mapping= and replaces= are only for type='fmu'")
        pf = None
        if params is not None:
            pf = resolve_path(str(params), self.path)
            if not pf.is_file():
                raise ScenarioError(f"component '{name}': parameter file '{params}' not found")
        self.components.append(ComponentSpec(name, str(type), pf, {}, dict(start or {}), step_multiple,
                                             fmu=fmu_path, mapping=dict(mapping or {}), replaces=replaces))
        for k, v in (set or {}).items():
            self.set(f"{name}.{k}", v, f"add_component('{name}', set={{'{k}': ...}})")
        self.text = ""
        return self

    def ports(self, component: str) -> dict[str, str] | None:
        """``{port: "input" | "output" | "input/output"}`` of a component as declared by its type (every
        variant, e.g. a vehicle's force and speed modes) or its FMU's model description; None when it
        cannot be known before the component is built (an FMU without fmpy)."""
        return self._port_table(component)[0]

    def _port_table(self, component: str) -> tuple[dict[str, str] | None, bool]:
        spec = self.component(component)
        if spec.type == "fmu":
            ports = fmu_ports(spec)
            return ports, ports is not None
        return declared_ports(component_class(spec.type, f"component '{component}'"))

    def _end_kind(self, end: str, call: str) -> str:
        """'input', 'output', 'input/output' or 'unknown' of ``component.port``; errors for a bad end."""
        if not isinstance(end, str) or "." not in end:
            raise ScenarioError(f"scenario '{self.name}': {call}: ends must be 'component.port', got {end!r}")
        comp, port = end.split(".", 1)
        if comp not in self.component_names:
            raise ScenarioError(f"scenario '{self.name}': {call}: unknown component '{comp}'"
                                f"{_hint(comp, self.component_names)}")
        ports, complete = self._port_table(comp)
        if ports is None or (port not in ports and not complete):
            return "unknown"                     # a type whose ports are known only when it is built
        if port not in ports:
            raise ScenarioError(f"scenario '{self.name}': {call}: component '{comp}' has no port '{port}'"
                                f"{_hint(port, ports)}")
        return ports[port]

    def connect(self, *ends: str, src: str | None = None, dst: str | None = None) -> "Scenario":
        """Connect an output to an input, source first as in SSP and Simulink:

            sc.connect("vehicle.speed_mps", "driver.speed_mps")          # output, then the input it feeds
            sc.connect(src="vehicle.speed_mps", dst="driver.speed_mps")  # the same, explicit

        A connection in the wrong direction (an input as the source, an output as the destination) is an
        error here, not at ``simulate``. The older order ``connect(input, output)`` still works when the
        ports say which end is which, with a DeprecationWarning. Returns self.
        """
        import warnings
        if ends and (src is not None or dst is not None):
            raise ScenarioError(f"scenario '{self.name}': connect: give the ends either by position "
                                f"(source first) or as src=, dst=, not both")
        if not ends:
            if src is None or dst is None:
                raise ScenarioError(f"scenario '{self.name}': connect needs src= (an output) and dst= (an input)")
            call = f"connect(src='{src}', dst='{dst}')"
            ks, kd = self._end_kind(src, call), self._end_kind(dst, call)
            wrong = ([f"the source '{src}' is an input"] if ks == "input" else []) + \
                    ([f"the destination '{dst}' is an output"] if kd == "output" else [])
            if wrong:
                fix = f"; did you mean connect(src='{dst}', dst='{src}')?" if ks == "input" and kd == "output" else ""
                raise ScenarioError(f"scenario '{self.name}': {call}: wrong direction: {' and '.join(wrong)}{fix}")
        else:
            if len(ends) != 2:
                raise ScenarioError(f"scenario '{self.name}': connect takes two ends (source, destination), "
                                    f"got {len(ends)}")
            a, b = ends
            call = f"connect('{a}', '{b}')"
            ka, kb = self._end_kind(a, call), self._end_kind(b, call)
            a_in, a_out = ka == "input", ka == "output"
            b_in, b_out = kb == "input", kb == "output"
            if (a_out and kb != "output") or (b_in and ka != "input"):
                src, dst = a, b                                   # source first (SSP order)
            elif (a_in and kb != "input") or (b_out and ka != "output"):
                src, dst = b, a                                   # the old order: input first
                warnings.warn(f"{call}: the input is given first; give the source first (SSP order), "
                              f"connect('{b}', '{a}'), or connect(src='{b}', dst='{a}')",
                              DeprecationWarning, stacklevel=2)
            elif ka == kb and ka in ("input", "output"):
                raise ScenarioError(f"scenario '{self.name}': {call}: both ends are {ka}s; a connection goes from "
                                    f"an output to an input")
            else:
                raise ScenarioError(f"scenario '{self.name}': {call}: cannot tell which end is the output "
                                    f"({a}: {ka}, {b}: {kb}); give connect(src=OUTPUT, dst=INPUT)")
        try:
            c = Connection.parse(dst, src)
        except ShevsimError as exc:
            raise ScenarioError(f"scenario '{self.name}': {exc}") from None
        self.connections.append(c)
        self.text = ""
        return self

    def add_fault(self, at_s: float, port: str, value: float) -> "Scenario":
        """From ``at_s`` on, force input ``port`` ("component.port") to ``value``. Returns self."""
        if "." not in port:
            raise ScenarioError(f"fault: port must be 'component.port', got {port!r}")
        comp, pname = port.split(".", 1)
        self.component(comp)
        if isinstance(at_s, bool) or not isinstance(at_s, (int, float)) or not math.isfinite(at_s):
            raise ScenarioError(f"fault '{port}': at_s must be a finite number, got {at_s!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"fault '{port}': value must be a number, got {value!r}")
        self.faults.append(Fault(float(at_s), comp, pname, float(value)))
        self.text = ""
        return self

    def use(self, vehicle: str | None = None, cycle: str | None = None) -> "Scenario":
        """Run this scenario's powertrain and supervisors on another vehicle and/or drive cycle:
        ``vehicle`` a bundled vehicle's name (``shevsim vehicles``) or a vehicle file (sets
        ``shared.vehicle``); ``cycle`` a bundled cycle's name or a cycle CSV (the ``cycle_file`` of the
        scenario's component of type ``cycle``). Returns self."""
        if vehicle is not None:
            self.set("shared.vehicle", str(vehicle), f"vehicle '{vehicle}'")
        if cycle is not None:
            comp = next((c for c in self.components if c.type == "cycle"), None)
            if comp is None:
                raise ScenarioError(f"scenario '{self.name}': cycle '{cycle}': the scenario has no component of "
                                    f"type 'cycle'")
            p = resolve_path(str(cycle), None)
            if not p.is_file():
                p = bundled_cycle(str(cycle))
            if p is None:
                from .paths import bundled_cycles
                raise ScenarioError(f"cycle '{cycle}': neither a bundled cycle ({', '.join(bundled_cycles())}) "
                                    f"nor a CSV file")
            self.set(f"{comp.name}.cycle_file", str(p), f"cycle '{cycle}'")
        return self

    def shared_values(self) -> dict[str, Any]:
        """The shared quantities in effect (the vehicle's, then the scenario's and every change, lifted
        component values included), ``{}`` when the scenario declares none."""
        r = shared_quantities().resolve(self, file_params)
        return {} if r is None else {k: v for k, (v, _) in r.values.items()}

    def copy(self) -> "Scenario":
        """An independent copy (change it without touching this one)."""
        import copy
        return copy.deepcopy(self)

    def to_toml(self) -> str:
        """The scenario as TOML text (what ``scenario.toml`` in a result folder holds)."""
        return scenario_to_toml(self)

    def resolved(self) -> dict:
        """A plain-dict view of what will run (saved with results)."""
        return {"name": self.name, "step_s": self.settings.step_s, "method": self.settings.method,
                "stop_s": self.stop_s, "t0_s": self.t0_s, "seed": self.seed, "order": self.order,
                "record": self.record,
                "components": {c.name: {"type": c.type, "params": str(c.params_file) if c.params_file else None,
                                        "set": c.overrides, "start": c.start, "step_multiple": c.step_multiple,
                                        "fmu": str(c.fmu) if c.fmu else None}
                               for c in self.components},
                "connections": [str(c) for c in self.connections],
                "faults": [dataclasses.asdict(f) for f in self.faults]}


def load_scenario(path: str | Path | None = None, sets: list[str] | tuple = (), text: str | None = None,
                  overlays: list[str] | tuple = ()) -> Scenario:
    """Read and validate a scenario file; ``sets`` are ``component.param=value`` overrides, ``overlays``
    are ``COMPONENT=FILE`` or ``FILE`` parameter overlays (`shevsim.core.overlay`).

    The checks run in the file's order: the TOML itself, ``[scenario]``, ``[components]``, the overlays,
    ``[connections]``, ``[[faults]]``, ``[record]``, the times and the order, then the ``--set`` values."""
    spath, where, text = _scenario_source(path, text)
    doc = toml_loads(text, where)
    _check_keys(doc, _TOP, where)
    sc = doc.get("scenario", {})
    _check_keys(sc, _SCEN, f"{where}: [scenario]")
    if "extends" in sc:
        doc = _extend(doc, spath, where)
        sc = doc.get("scenario", {})
    name = sc.get("name", spath.stem if spath else "scenario")
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{where}: [scenario] field 'name' must be a string, got {name!r}")
    settings = MasterSettings(step_s=_number(sc, "step_s", 0.1, f"{where}: [scenario]"),
                              method=str(sc.get("method", "gauss-seidel")))
    try:
        settings.check()
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: [scenario] {exc}") from None
    specs = _component_specs(doc, spath, where)
    names = {s.name for s in specs}
    shared, shared_origins = _shared_table(doc, spath, where)
    _apply_overlays(specs, names, overlays, shared, shared_origins)
    conns = _connections(doc, names, where)
    faults = _faults(doc, names, where)
    signals = _record_signals(doc, where)
    seed, stop_s, t0_s = _scenario_times(sc, where)
    order = _scenario_order(sc, names, where)
    scen = Scenario(spath, text, name, str(sc.get("description", "")), settings,
                    stop_s, t0_s, seed, specs, conns, faults, signals,
                    check_metrics_options(doc.get("metrics", {}), f"{where}: [metrics]"), order,
                    list(sets), [str(o) for o in overlays], shared, shared_origins)
    for s in sets:
        if "=" not in s or "." not in s.split("=", 1)[0]:
            raise ScenarioError(f"--set '{s}': expected component.param=value (or scenario.FIELD=value)")
        key, val = s.split("=", 1)
        key = _argv_text(key)
        # a relative *_file path given on the command line is relative to the working directory
        apply_override(scen, key.strip(), parse_value(val.strip(), f"--set '{s}'"), f"--set '{s}'",
                       base=None)
    return scen


def _scenario_source(path: str | Path | None, text: str | None) -> tuple[Path | None, str, str]:
    """The scenario's path (a bundled scenario by name when no such file exists), the name errors use
    for it, and its text (read as UTF-8 unless ``text`` is given)."""
    spath = Path(path) if path is not None else None
    if text is None and spath is not None and not spath.is_file() and bundled_scenario(str(path)) is not None:
        spath = bundled_scenario(str(path))      # a bundled scenario by name (hd_udds_rule)
    where = str(spath) if spath else "<scenario>"
    if text is None:
        why = file_problem(spath, "scenario file", 64 * 2**20) if spath is not None else "scenario file not found"
        if why == "scenario file not found":
            from .paths import bundled_scenarios
            raise ScenarioError(f"{where}: scenario file not found (bundled scenarios by name: "
                                f"{', '.join(bundled_scenarios())})")
        if why is not None:
            raise ScenarioError(f"{where}: {why}")
        try:   # utf-8-sig: an editor's byte-order mark is not TOML
            text = spath.read_text(encoding="utf-8-sig")
        except (UnicodeDecodeError, OSError) as exc:
            raise ScenarioError(f"{where}: cannot read the scenario as UTF-8 text: {exc}") from None
    return spath, where, text


def _number(d: dict, k: str, default, w: str, typ=float):
    """``d[k]`` (or ``default``) as a ``typ`` number; None stays None; an error names ``w`` and ``k``."""
    v = d.get(k, default)
    if v is None:
        return None
    try:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (typ is int and not float(v).is_integer()):
            raise ScenarioError(f"{w}: field '{k}' must be {'an integer' if typ is int else 'a number'}, got {v!r}")
        return typ(v)
    except OverflowError:
        raise ScenarioError(f"{w}: field '{k}' = {v!r} is too large for a number") from None


def _component_specs(doc: dict, spath: Path | None, where: str) -> list[ComponentSpec]:
    """The ``[components]`` tables as specs, in the file's order."""
    comps_doc = doc.get("components")
    if not comps_doc:
        raise ScenarioError(f"{where}: no [components] defined")
    _check_keys(comps_doc, set(comps_doc), where)
    return [_component_spec(cname, cd, spath, f"{where}: [components.{cname}]") for cname, cd in comps_doc.items()]


def _component_spec(cname: str, cd: dict, spath: Path | None, w: str) -> ComponentSpec:
    """One ``[components.NAME]`` table as a spec (its files resolved against the scenario's folder)."""
    _check_component_name(cname, w)
    _check_keys(cd, _COMP, w)
    if "type" not in cd:
        raise ScenarioError(f"{w}: missing field 'type'")
    if not isinstance(cd["type"], str):
        raise ScenarioError(f"{w}: field 'type' must be a string (a registry name), got {cd['type']!r}")
    pf = None
    if "params" in cd:
        if not isinstance(cd["params"], str):
            raise ScenarioError(f"{w}: field 'params' must be a file path string")
        pf = resolve_path(cd["params"], spath)
        if not pf.is_file():          # a bundled parameter set by name ("matv", "vehicle/matv")
            pf = bundled_params(cd["params"], str(cd["type"]), cname)
        if pf is None:
            raise ScenarioError(f"{w}: field 'params': parameter file '{cd['params']}' not found (nor a "
                                f"bundled set of that name in components/{cd['type']}/)")
    fmu = None
    if cd["type"] == "fmu":
        if "fmu" not in cd:
            raise ScenarioError(f"{w}: type 'fmu' needs field 'fmu' (path of the .fmu file)")
        if not isinstance(cd["fmu"], str):
            raise ScenarioError(f"{w}: field 'fmu' must be a file path string")
        fmu = resolve_path(cd["fmu"], spath)
    k = cd.get("step_multiple", 1)
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ScenarioError(f"{w}: field 'step_multiple' must be an integer >= 1, got {k!r}")
    for tbl in ("set", "start", "map"):
        if tbl in cd and not isinstance(cd[tbl], dict):
            raise ScenarioError(f"{w}: field '{tbl}' must be a table")
    rep = cd.get("replaces")
    if rep is not None and (cd["type"] != "fmu" or not isinstance(rep, str)):
        raise ScenarioError(f"{w}: field 'replaces' (a native component TYPE) is only for type = \"fmu\"")
    own = cd.get("own", [])
    if not (isinstance(own, list) and all(isinstance(x, str) for x in own)):
        raise ScenarioError(f"{w}: field 'own' must be a list of parameter (or shared quantity) names")
    over, sources = {}, {}
    if "overlay" in cd:
        if not isinstance(cd["overlay"], str):
            raise ScenarioError(f"{w}: field 'overlay' must be a file path string")
        try:
            ov = overlay_values(resolve_path(cd["overlay"], spath), cname)
            over.update(resolve_files(ov))
            sources.update({key: f"{w} overlay {ov.path}" for key in ov.values})
        except ScenarioError as exc:
            raise ScenarioError(f"{w}: field 'overlay': {exc}") from None
    over.update({key: _file_value(key, v, spath) for key, v in cd.get("set", {}).items()})
    sources.update({key: f"{w} set.{key}" for key in cd.get("set", {})})
    return ComponentSpec(cname, cd["type"], pf, over, dict(cd.get("start", {})),
                         k, fmu, dict(cd.get("map", {})), rep, own=list(own), sources=sources)


def _shared_table(doc: dict, spath: Path | None, where: str) -> tuple[dict, dict]:
    """The ``[shared]`` quantities of the scenario (names and types checked; ``*_file`` paths relative to the
    scenario's folder) and where each was declared."""
    tbl = doc.get("shared") or {}
    if not isinstance(tbl, dict):
        raise ScenarioError(f"{where}: [shared] must be a table of quantity = value")
    check = shared_quantities().check_value if tbl else None
    shared = {key: check(key, _file_value(key, v, spath), f"{where}: [shared]") for key, v in tbl.items()}
    return shared, {key: f"{where}: [shared] {key}" for key in tbl}


def _apply_overlays(specs: list[ComponentSpec], names: set, overlays, shared: dict, shared_origins: dict) -> None:
    """Merge ``--params`` overlays (``COMPONENT=FILE`` or a bare ``FILE``) into the specs' overrides; an
    overlay's ``[shared]`` table into the scenario's shared quantities."""
    for item in overlays:
        comp, sep, f = str(item).partition("=")
        if not sep or (comp not in names and Path(str(item)).exists()):
            comp, f = "", str(item)          # a bare FILE (its path may contain '=')
        fpath = Path(f)
        try:
            tabs = overlay_tables(fpath) if not comp else {}
            targets = [comp] if comp else [n for n in tabs if n in names]
            if comp and comp not in names:
                raise ScenarioError(f"unknown component '{comp}'{_hint(comp, names)}")
            if "shared" in tabs and "shared" not in names:   # the overlay's shared quantities
                if not shared:
                    raise ScenarioError(f"{fpath}: table [shared] gives shared quantities, but the scenario "
                                        f"declares none (add [shared] vehicle = \"NAME\" to it)")
                check = shared_quantities().check_value
                for key, v in resolve_files(overlay_values(fpath, "shared")).items():
                    shared[key] = check(key, v, f"{fpath}: [shared]")
                    shared_origins[key] = f"--params '{item}' [shared] {key}"
            if not targets and "shared" not in tabs:
                raise ScenarioError(f"{fpath}: no table names a component of this scenario "
                                    f"({', '.join(sorted(names))}); give COMPONENT=FILE")
            for cname in targets:
                vals = resolve_files(overlay_values(fpath, cname))
                spec = next(c for c in specs if c.name == cname)
                spec.overrides.update(vals)
                # an error in one of these values names the overlay, not the component's parameter file
                spec.origins.update({k: f"--params '{item}' ({fpath}, table [{cname}])" for k in vals})
                spec.sources.update({key: f"--params '{item}' [{cname}] {key}" for key in vals})
        except ScenarioError as exc:
            raise ScenarioError(f"--params '{item}': {exc}") from None


def _connections(doc: dict, names: set, where: str) -> list[Connection]:
    """The ``[connections]`` table (``"dst.input" = "src.output"``), both ends checked against ``names``."""
    conns = []
    cd = doc.get("connections", {})
    if not isinstance(cd, dict):
        raise ScenarioError(f"{where}: [connections] must be a table of \"dst.input\" = \"src.output\"")
    for dst, src in cd.items():
        if not isinstance(src, str):
            raise ScenarioError(f"{where}: [connections] '{dst}': source must be a string 'component.port'")
        try:
            conns.append(Connection.parse(dst, src))
        except ShevsimError as exc:
            raise ScenarioError(f"{where}: [connections] {exc}") from None
        for end in (conns[-1].src, conns[-1].dst):
            if end not in names:
                raise ScenarioError(f"{where}: [connections] '{dst}' = '{src}': unknown component '{end}'"
                                    f"{_hint(end, names)}")
    return conns


def _faults(doc: dict, names: set, where: str) -> list[Fault]:
    """The ``[[faults]]`` array: a finite time, a ``component.port`` of this scenario and a value."""
    faults = []
    for i, fd in enumerate(doc.get("faults", [])):
        w = f"{where}: [[faults]] #{i + 1}"
        _check_keys(fd, _FAULT, w)
        for key in _FAULT:
            if key not in fd:
                raise ScenarioError(f"{w}: missing field '{key}'")
        at = _number(fd, "at_s", None, w)
        if not math.isfinite(at):
            raise ScenarioError(f"{w}: field 'at_s' must be a finite number, got {at!r}")
        val = _number(fd, "value", None, w)
        if "." not in str(fd["port"]):
            raise ScenarioError(f"{w}: field 'port' must be 'component.port'")
        comp, port = str(fd["port"]).split(".", 1)
        if comp not in names:
            raise ScenarioError(f"{w}: unknown component '{comp}'{_hint(comp, names)}")
        faults.append(Fault(at, comp, port, val))
    return faults


def _record_signals(doc: dict, where: str) -> list[str] | None:
    """``[record] signals``: None for "all", else the list of ``component.port`` names."""
    rec = doc.get("record", {})
    _check_keys(rec, _RECORD, f"{where}: [record]")
    signals = rec.get("signals", "all")
    if signals == "all":
        return None
    if not (isinstance(signals, list) and all(isinstance(x, str) for x in signals)):
        raise ScenarioError(f"{where}: [record] field 'signals' must be \"all\" or a list of 'component.port'")
    if not signals:
        raise ScenarioError(f"{where}: [record] field 'signals' is an empty list (nothing would be recorded): "
                            f"list at least one 'component.port', or \"all\"")
    bad = [x for x in signals if x.count(".") < 1 or not all(x.split(".", 1))]
    if bad:
        raise ScenarioError(f"{where}: [record] field 'signals': {bad[0]!r} is not 'component.port'")
    return signals


def _scenario_times(sc: dict, where: str) -> tuple[int, float | None, float]:
    """``[scenario]`` seed, stop_s and t0_s, checked (finite, stop after start)."""
    seed = _number(sc, "seed", 0, f"{where}: [scenario]", int)
    stop_s = _number(sc, "stop_s", None, f"{where}: [scenario]")
    t0_s = _number(sc, "t0_s", 0.0, f"{where}: [scenario]")
    for key, v in (("t0_s", t0_s), ("stop_s", stop_s)):
        if v is not None and not math.isfinite(v):
            raise ScenarioError(f"{where}: [scenario] field '{key}' must be a finite number, got {v!r}")
    if stop_s is not None and stop_s <= t0_s:
        raise ScenarioError(f"{where}: [scenario] field 'stop_s' ({stop_s} s) must be after t0_s ({t0_s} s)")
    return seed, stop_s, t0_s


def _scenario_order(sc: dict, names: set, where: str) -> list[str] | None:
    """``[scenario] order``: None, or every component named exactly once."""
    order = sc.get("order")
    if order is None:
        return None
    if not (isinstance(order, list) and all(isinstance(x, str) for x in order)):
        raise ScenarioError(f"{where}: [scenario] field 'order' must be a list of component names")
    for n in order:
        if n not in names:
            raise ScenarioError(f"{where}: [scenario] field 'order': unknown component '{n}'{_hint(n, names)}")
    if sorted(order) != sorted(names):
        rep = sorted({n for n in order if order.count(n) > 1})
        raise ScenarioError(f"{where}: [scenario] field 'order' must list every component exactly once "
                            + (f"(repeated: {rep})" if rep else f"(missing: {sorted(names - set(order))})"))
    return order


def _argv_text(text: str) -> str:
    """A command-line word as the UTF-8 text it most likely is: under an ASCII-only locale Python keeps the
    bytes of a non-ASCII argument as surrogate escapes ('b\\udcc3\\udcbas'), which would never match the
    component 'bús' of a (UTF-8) scenario file. Paths are not passed through this (the OS takes them as
    they came)."""
    if any(0xDC80 <= ord(c) <= 0xDCFF for c in text):
        try:
            return text.encode("utf-8", "surrogateescape").decode("utf-8")
        except UnicodeError:
            return text
    return text


def _extend(doc: dict, spath: Path | None, where: str, depth: int = 0) -> dict:
    """Merge a scenario that ``extends`` another over its base: the child states only what differs.

    ``[scenario]``, ``[shared]``, ``[metrics]``, ``[connections]`` (by input) and each component's table
    (its ``set`` and ``start`` tables key by key) are merged, the child's value winning; a component the
    base lacks is added; ``[[faults]]`` are appended; ``[record]`` is the child's when it has one.  The
    base is a bundled scenario's name (``extends = "hd_udds_mpc"``) or a scenario file relative to this one.
    """
    sc = doc.get("scenario", {})
    ext = sc.get("extends")
    if not isinstance(ext, str) or not ext:
        raise ScenarioError(f"{where}: [scenario] field 'extends' must be a bundled scenario's name or a "
                            f"scenario file path, got {ext!r}")
    if depth > 8:
        raise ScenarioError(f"{where}: [scenario] 'extends' chain longer than 8 (a cycle?)")
    cand = resolve_path(ext, spath) if spath is not None else Path(ext)
    base_path = cand if cand.is_file() else bundled_scenario(ext)
    if base_path is None:
        from .paths import bundled_scenarios
        raise ScenarioError(f"{where}: [scenario] extends = '{ext}': no such scenario file nor bundled scenario "
                            f"({', '.join(bundled_scenarios())})")
    bwhere = str(base_path)
    try:
        base = tomllib.loads(base_path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:
        raise ScenarioError(f"{where}: [scenario] extends = '{ext}': {bwhere}: cannot read: {exc}") from None
    _check_keys(base, _TOP, bwhere)
    if "extends" in base.get("scenario", {}):
        base = _extend(base, base_path, bwhere, depth + 1)
    bundled = base_path.resolve().parent == (PROJECT_ROOT / "scenarios").resolve()
    if not bundled:      # a user's base file: its relative paths are relative to it, not to the child
        for cd in (base.get("components") or {}).values():
            if not isinstance(cd, dict):
                continue
            for key in ("params", "fmu", "overlay"):
                if isinstance(cd.get(key), str):
                    p = resolve_path(cd[key], base_path)
                    if p.exists():
                        cd[key] = str(p)
            if isinstance(cd.get("set"), dict):
                cd["set"] = {k: _file_value(k, v, base_path) for k, v in cd["set"].items()}
    out = dict(base)
    bsc = dict(base.get("scenario", {}))
    bsc.pop("extends", None)
    bsc.pop("name", None)
    out["scenario"] = {**bsc, **{k: v for k, v in sc.items() if k != "extends"}}
    for tbl in ("shared", "metrics", "connections"):
        if tbl in doc or tbl in base:
            b, c = base.get(tbl, {}), doc.get(tbl, {})
            if not isinstance(b, dict) or not isinstance(c, dict):
                raise ScenarioError(f"{where}: [{tbl}] must be a table")
            out[tbl] = {**b, **c}
    comps = {k: dict(v) for k, v in (base.get("components") or {}).items() if isinstance(v, dict)}
    for cname, cd in (doc.get("components") or {}).items():
        if not isinstance(cd, dict):
            raise ScenarioError(f"{where}: [components.{cname}] must be a table")
        if cname in comps and cd.get("type", comps[cname].get("type")) == comps[cname].get("type"):
            merged = {**comps[cname], **cd}
            for sub in ("set", "start", "map"):
                if isinstance(comps[cname].get(sub), dict) and isinstance(cd.get(sub), dict):
                    merged[sub] = {**comps[cname][sub], **cd[sub]}
            comps[cname] = merged
        else:
            comps[cname] = dict(cd)
    out["components"] = comps
    out["faults"] = list(base.get("faults", [])) + list(doc.get("faults", []))
    if not out["faults"]:
        del out["faults"]
    if "record" in doc:
        out["record"] = doc["record"]
    return out


def _data_name(p: Path | str) -> str:
    """A path under the bundled data folder as its portable name (``components/vehicle/matv.toml``, the
    form scenario files use), else the absolute path."""
    p = Path(p)
    try:
        return p.resolve().relative_to(PROJECT_ROOT.resolve()).as_posix()
    except ValueError:
        return str(p)


def _portable(key: str, v: Any) -> Any:
    if isinstance(v, str) and key.endswith("_file") and Path(v).is_absolute():
        if key == "cycle_file" and Path(v).parent.resolve() == (PROJECT_ROOT / "cycles").resolve():
            return Path(v).stem        # a bundled cycle by name
        return _data_name(v)
    return v


#: names of the tables ``--set``/overrides address besides components (so no component may take them)
RESERVED = {"scenario": _SCEN, "record": _RECORD, "metrics": None, "shared": None}


def _check_component_name(name: str, where: str) -> None:
    if not isinstance(name, str) or not name or "." in name or name.strip() != name:
        raise ScenarioError(f"{where}: component name {name!r} must be non-empty without '.' or surrounding "
                            f"spaces (ports are addressed as component.port)")
    if name in RESERVED:
        raise ScenarioError(f"{where}: component name '{name}' is reserved (overrides address "
                            f"'{name}.FIELD'); choose another name")


def apply_override(scen: "Scenario", key: str, value: Any, origin: str, base: Path | None | str = "scenario") -> None:
    """Apply one typed override to a loaded scenario; errors name ``origin``.

    ``component.param`` goes into the component's overrides (checked when the component is built;
    a relative ``*_file`` path is resolved against the working directory when ``base`` is None, else
    against the scenario's folder); ``scenario.FIELD``, ``record.signals`` and ``metrics.OPTION``
    change the scenario itself (checked here).
    """
    if not isinstance(key, str) or "." not in key:
        raise ScenarioError(f"{origin}: expected 'component.param' (or 'scenario.FIELD'), got {key!r}")
    head, name = key.split(".", 1)
    if head == "scenario":
        _set_scenario_field(scen, name, value, origin)
        return
    if head == "record":
        if name != "signals":
            raise ScenarioError(f"{origin}: [record] has only 'signals'")
        if value == "all" or value is None:
            scen.record = None
        elif isinstance(value, (list, tuple)) and all(isinstance(x, str) for x in value):
            scen.record = list(value)
        else:
            raise ScenarioError(f"{origin}: record.signals must be \"all\" or a list of 'component.port'")
        return
    if head == "metrics":
        scen.metrics.update(check_metrics_options({name: value}, f"{origin}: [metrics]"))
        return
    if head == "shared":
        if value is None:
            scen.shared.pop(name, None)
            scen.shared_origins.pop(name, None)
            return
        if name.endswith("_file") and isinstance(value, str):
            value = _file_value(name, value, scen.path if base == "scenario" else None)
        scen.shared[name] = shared_quantities().check_value(name, value, origin)
        scen.shared_origins[name] = origin
        return
    names = [c.name for c in scen.components]
    if head not in names:
        raise ScenarioError(f"{origin}: unknown component '{head}'{_hint(head, names + list(RESERVED))}")
    if not name:
        raise ScenarioError(f"{origin}: missing parameter name after '{head}.'")
    spec = next(c for c in scen.components if c.name == head)
    if name == "own":         # the component keeps these parameters instead of the shared quantities
        if not (isinstance(value, (list, tuple)) and all(isinstance(x, str) for x in value)):
            raise ScenarioError(f"{origin}: {head}.own must be a list of parameter (or shared quantity) names")
        spec.own = list(value)
        return
    spec.overrides[name] = _file_value(name, value, scen.path if base == "scenario" else None)
    spec.origins[name] = origin


def _set_scenario_field(scen: "Scenario", name: str, value: Any, origin: str) -> None:
    def number(v, integer=False, allow_none=False):
        if v is None and allow_none:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or \
                (integer and not float(v).is_integer()):
            raise ScenarioError(f"{origin}: scenario.{name} must be a finite "
                                f"{'integer' if integer else 'number'}, got {v!r}")
        return int(v) if integer else float(v)
    if name == "step_s":
        st = MasterSettings(step_s=number(value), method=scen.settings.method)
        try:
            st.check()
        except ScenarioError as exc:
            raise ScenarioError(f"{origin}: {exc}") from None
        scen.settings.step_s = st.step_s
    elif name == "method":
        st = MasterSettings(step_s=scen.settings.step_s, method=str(value))
        try:
            st.check()
        except ScenarioError as exc:
            raise ScenarioError(f"{origin}: {exc}") from None
        scen.settings.method = st.method
    elif name == "stop_s":
        v = number(value, allow_none=True)
        if v is not None and v <= scen.t0_s:
            raise ScenarioError(f"{origin}: scenario.stop_s ({v} s) must be after t0_s ({scen.t0_s} s)")
        scen.stop_s = v
    elif name == "t0_s":
        v = number(value)
        if scen.stop_s is not None and scen.stop_s <= v:
            raise ScenarioError(f"{origin}: scenario.t0_s ({v} s) must be before stop_s ({scen.stop_s} s)")
        scen.t0_s = v
    elif name == "seed":
        scen.seed = number(value, integer=True)
    elif name in ("name", "description"):
        if not isinstance(value, str) or (name == "name" and not value):
            raise ScenarioError(f"{origin}: scenario.{name} must be a {'non-empty ' if name == 'name' else ''}"
                                f"string, got {value!r}")
        setattr(scen, name, value)
    elif name == "order":
        names = [c.name for c in scen.components]
        if value is not None and not (isinstance(value, (list, tuple)) and sorted(value) == sorted(names)):
            raise ScenarioError(f"{origin}: scenario.order must list every component exactly once ({names})")
        scen.order = None if value is None else list(value)
    else:
        raise ScenarioError(f"{origin}: unknown scenario field '{name}'{_hint(name, _SCEN)}")


def scenario_to_toml(sc: "Scenario") -> str:
    """TOML text of a scenario as it stands; loads back into an equal scenario.  Bundled data are named
    by their path in the data folder (``components/vehicle/matv.toml``, ``cycle_file = "hd_udds"``), so the
    text runs on any installation; a user's own files keep their absolute paths."""
    out = ["[scenario]", f"name = {toml_value(sc.name)}"]
    if sc.description:
        out.append(f"description = {toml_value(sc.description)}")
    out += [f"step_s = {toml_value(float(sc.settings.step_s))}", f"method = {toml_value(sc.settings.method)}",
            f"seed = {int(sc.seed)}", f"t0_s = {toml_value(float(sc.t0_s))}"]
    if sc.stop_s is not None:
        out.append(f"stop_s = {toml_value(float(sc.stop_s))}")
    if sc.order:
        out.append(f"order = {toml_value(list(sc.order))}")
    if sc.shared:
        out += ["", "[shared]"] + [f"{toml_key(k)} = {toml_value(_portable(k, v))}" for k, v in sc.shared.items()]
    for c in sc.components:
        out += ["", f"[components.{toml_key(c.name)}]", f"type = {toml_value(c.type)}"]
        if c.params_file is not None:
            out.append(f"params = {toml_value(_data_name(c.params_file))}")
        if c.fmu is not None:
            out.append(f"fmu = {toml_value(_data_name(c.fmu))}")
        if c.own:
            out.append(f"own = {toml_value(list(c.own))}")
        if c.mapping:
            out.append(f"map = {toml_value(c.mapping)}")
        if c.replaces:
            out.append(f"replaces = {toml_value(c.replaces)}")
        if c.step_multiple != 1:
            out.append(f"step_multiple = {c.step_multiple}")
        if c.overrides:
            out.append(f"set = {toml_value({k: _portable(k, v) for k, v in c.overrides.items()})}")
        if c.start:
            out.append(f"start = {toml_value(c.start)}")
    if sc.connections:
        out += ["", "[connections]"]
        out += [f"{toml_value(f'{c.dst}.{c.dst_port}')} = {toml_value(f'{c.src}.{c.src_port}')}"
                for c in sc.connections]
    for f in sc.faults:
        out += ["", "[[faults]]", f"at_s = {toml_value(float(f.at_s))}",
                f"port = {toml_value(f'{f.component}.{f.port}')}", f"value = {toml_value(float(f.value))}"]
    if sc.record is not None:
        out += ["", "[record]", f"signals = {toml_value(list(sc.record))}"]
    if sc.metrics:
        out += ["", "[metrics]"] + [f"{toml_key(k)} = {toml_value(v)}" for k, v in sc.metrics.items()]
    return "\n".join(out) + "\n"


def new_scenario(name: str = "scenario", *, step_s: float = 0.1, stop_s: float | None = None, t0_s: float = 0.0,
                 method: str = "gauss-seidel", seed: int = 0, description: str = "") -> Scenario:
    """An empty scenario to build in code: add components, connections and faults, then simulate.

    Examples
    --------
    >>> sc = new_scenario("two_body", step_s=0.01, stop_s=1.0)        # doctest: +SKIP
    >>> sc.add_component("body1", "mass", "scenarios/verification/params/body1.toml")  # doctest: +SKIP
    """
    sc = Scenario(None, "", name, description, MasterSettings(), None, 0.0, 0, [], [], [], None, {})
    for k, v in (("name", name), ("step_s", step_s), ("method", method), ("seed", seed), ("t0_s", t0_s),
                 ("stop_s", stop_s)):
        _set_scenario_field(sc, k, v, f"new_scenario({k}=...)")
    sc.description = str(description)
    return sc


def _file_value(key: str, value: Any, scenario_path: Path | None) -> Any:
    """A ``*_file`` override as an absolute path: relative to the scenario file (its ``set`` table) or
    to the working directory (``--set``); other values unchanged."""
    if key.endswith("_file") and isinstance(value, str) and value:
        p = resolve_path(value, scenario_path)
        if not p.exists() and key == "cycle_file" and bundled_cycle(value) is not None:
            p = bundled_cycle(value)      # a bundled cycle by name ("uac_proxy")
        return str(p.absolute())
    return value


def component_seed(scenario_seed: int, name: str) -> int:
    """Per-component seed: stable under reordering of the scenario's components."""
    return (scenario_seed * 1_000_003 + zlib.crc32(name.encode())) % (2**31 - 1)


def file_params(spec: ComponentSpec) -> dict:
    """The ``[params]`` a component's parameter file states (``*_file`` values absolute), ``{}`` without."""
    if spec.params_table is not None:        # captured (a study's bundle): paths already absolute
        return dict(spec.params_table)
    if spec.params_file is None or not Path(spec.params_file).is_file():
        return {}
    from .params import read_param_toml
    prm = read_param_toml(Path(spec.params_file)).get("params", {})
    if not isinstance(prm, dict):
        return {}
    base = Path(spec.params_file).parent
    return {k: (str((base / v).resolve()) if k.endswith("_file") and isinstance(v, str) and v
                and not Path(v).is_absolute() else v) for k, v in prm.items()}


def shared_params(scenario: Scenario) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, str]]]:
    """What the scenario's shared quantities give each component (``{name: {param: value}}``) and where
    each value came from; checks that no component-level value contradicts them
    (`shevsim.components.shared`)."""
    try:
        r = shared_quantities().resolve(scenario, file_params)
    except ScenarioError as exc:
        raise ScenarioError(f"{scenario.path or '<scenario>'}: [shared]: {exc}") from None
    return ({}, {}) if r is None else (r.params, r.sources)


def shared_metrics(scenario: Scenario) -> dict[str, Any]:
    """Metric options the shared quantities set (``fuel_density_kg_per_l``); a ``[metrics]`` value that
    contradicts one is an error naming both."""
    sq = shared_quantities()
    r = sq.resolve(scenario, file_params)
    if r is None:
        return {}
    out = {}
    for k, (v, origin) in r.metrics.items():
        if k in scenario.metrics and not sq.same(scenario.metrics[k], v):
            raise ScenarioError(f"{scenario.path or '<scenario>'}: [metrics] {k} = {scenario.metrics[k]!r} "
                                f"contradicts the shared quantity {k} = {v!r} ({origin}); declare it once, as "
                                f"shared.{k}")
        out[k] = v
    return out


def instantiate(spec: ComponentSpec, scenario: Scenario, injected: dict[str, Any] | None = None,
                sources: dict[str, str] | None = None):
    """Create one component from its spec; ``injected``: values from the shared quantities (below the
    spec's own overrides, above its parameter file), ``sources`` where each came from."""
    where = f"{scenario.path or '<scenario>'}: [components.{spec.name}]"
    if spec.type == "fmu":
        comp = fmu_component(spec, scenario, where)
    else:
        cls = component_class(spec.type, where)
        params = None
        if cls.Params is not None:
            over = {**(injected or {}), **spec.overrides}
            fields = {f.name for f in dataclasses.fields(cls.Params)}
            if "seed" in fields and "seed" not in over:
                over["seed"] = component_seed(scenario.seed, spec.name)
            try:
                params = load_params(cls.Params, spec.params_file, over, table=spec.params_table)
            except ScenarioError as exc:
                _blame_override(cls, spec, over, exc)
                _blame_injected(cls, spec, injected or {}, sources or {})
                raise ScenarioError(f"{where}: {exc}") from None
        elif spec.overrides or injected:
            raise ScenarioError(f"{where}: component type '{spec.type}' takes no parameters")
        try:
            comp = cls(spec.name, params)
        except ShevsimError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
        except Exception as exc:          # the component's own code failed: keep its message, name it
            raise ScenarioError(f"{where}: component '{spec.name}' (type '{spec.type}') could not be built: "
                                f"{type(exc).__name__}: {exc}") from exc
    inputs = {v.name for v in comp.variables() if v.causality == "input"}
    for port, val in spec.start.items():
        if port not in inputs:
            raise ScenarioError(f"{where}: field 'start': component has no input '{port}'{_hint(port, inputs)}")
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise ScenarioError(f"{where}: field 'start.{port}' must be a number")
        comp.u[port] = float(val)
    return comp


def _blame_injected(cls, spec: ComponentSpec, injected: dict, sources: dict) -> None:
    """When a value from the shared quantities makes a component's parameters invalid, name where the
    shared value came from (``--set vehicle.mass_kg=...`` lifted, ``[shared] mass_kg``)."""
    for key, v in injected.items():
        if key in spec.overrides:
            continue
        try:
            load_params(cls.Params, spec.params_file, {key: v})
        except ScenarioError as e2:
            msg = str(e2)
            if spec.params_file is not None:
                msg = msg.replace(f"{spec.params_file}: ", "")
            msg = msg.replace("<overrides>: ", "").replace("<parameters>: ", "")
            raise ScenarioError(f"{sources.get(key, 'shared quantities')}: component '{spec.name}': {msg}") from None


def _blame_override(cls, spec: ComponentSpec, over: dict, exc: ScenarioError) -> None:
    """When an override given outside the scenario file (``--set``, the Python API) makes the
    parameters invalid, raise an error that names that override instead of the parameter file."""
    if not spec.origins:
        return
    base = {k: v for k, v in over.items() if k not in spec.origins}
    for key, origin in spec.origins.items():
        if key not in over:
            continue
        try:
            load_params(cls.Params, spec.params_file, {**base, key: over[key]}, table=spec.params_table)
        except ScenarioError as e2:
            msg = str(e2)
            if spec.params_file is not None:
                msg = msg.replace(f"{spec.params_file}: ", "")
            msg = msg.replace("<overrides>: ", "").replace("<parameters>: ", "")
            raise ScenarioError(f"{origin}: component '{spec.name}': {msg}") from None


def build_master(scenario: Scenario) -> Master:
    """Instantiate the components and the master of a scenario (connections checked)."""
    inj, src = shared_params(scenario)
    comps = [instantiate(s, scenario, inj.get(s.name), src.get(s.name)) for s in scenario.components]
    where = scenario.path or '<scenario>'
    try:
        m = Master(comps, scenario.connections, scenario.settings,
                   {s.name: s.step_multiple for s in scenario.components}, scenario.faults, scenario.order)
    except ShevsimError as exc:
        raise type(exc)(f"{where}: {exc}") from None
    for spec in scenario.components:    # a connection overwrites the start value before initialize()
        for c in scenario.connections:
            if c.dst == spec.name and c.dst_port in spec.start:
                raise ScenarioError(f"{where}: [components.{spec.name}] field 'start.{c.dst_port}': the input is "
                                    f"connected to {c.src}.{c.src_port}, so its start value is never used")
    connected = {(c.dst, c.dst_port) for c in scenario.connections}
    for spec, comp in zip(scenario.components, comps):   # an input nobody drives must have a declared default
        fn = getattr(comp, "defaulted_inputs", None)
        if fn is None:
            continue
        free = fn()
        for v in comp.variables():
            if v.causality == "input" and (spec.name, v.name) not in connected and v.name not in free \
                    and v.name not in spec.start:
                raise ScenarioError(f"{where}: [components.{spec.name}] input '{v.name}' ({v.unit}, {v.description}) "
                                    f"is not connected and the component declares no default for it: connect it in "
                                    f"[connections] (\"{spec.name}.{v.name}\" = \"COMPONENT.OUTPUT\") or give it a "
                                    f"value in [components.{spec.name}] start")
    step = scenario.settings.step_s
    for spec, comp in zip(scenario.components, comps):   # a sampled controller must get its own step
        pname = getattr(comp, "SAMPLE_TIME_PARAM", None)
        ts = getattr(getattr(comp, "params", None), pname, None) if pname else None
        if isinstance(ts, (int, float)) and math.isfinite(ts):
            hk = step * spec.step_multiple
            if abs(hk - ts) > 1e-9 * max(1.0, ts):
                k = ts / step
                fix = (f"set step_multiple = {round(k)}" if abs(k - round(k)) <= 1e-9 * max(1.0, k) and round(k) >= 1
                       else f"use a step_s that divides {ts:g} s")
                raise ScenarioError(f"{where}: [components.{spec.name}] {pname} = {ts:g} s but the component "
                                    f"steps every {hk:g} s (step_s {step:g} s x step_multiple "
                                    f"{spec.step_multiple}): {fix}")
    if scenario.record is not None:     # checked before the run, not after it
        known = set(m._signal_names)
        for sig in scenario.record:
            if sig not in known:
                raise ScenarioError(f"{where}: [record] field 'signals': unknown signal '{sig}'"
                                    f"{_hint(sig, known)}")
    return m


def stop_time(scenario: Scenario, master: Master) -> float:
    """The scenario's stop time, else the longest natural stop time among components. The scenario's
    time fields are checked here too (an object changed by attribute in Python skipped ``Scenario.set``)."""
    where = f"{scenario.path or '<scenario>'}: [scenario]"
    for key, val in (("t0_s", scenario.t0_s), ("stop_s", scenario.stop_s), ("step_s", scenario.settings.step_s)):
        if val is not None and (isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val)):
            raise ScenarioError(f"{where} field '{key}' must be a finite number, got {val!r}")
    if not scenario.settings.step_s > 0:
        raise ScenarioError(f"{where} field 'step_s' must be > 0, got {scenario.settings.step_s!r}")
    if scenario.stop_s is not None:
        if scenario.stop_s <= scenario.t0_s:
            raise ScenarioError(f"{where} field 'stop_s' ({scenario.stop_s} s) must be after t0_s ({scenario.t0_s} s)")
        return scenario.stop_s
    natural = [c.natural_stop_time() for c in master.components.values()
               if hasattr(c, "natural_stop_time") and c.natural_stop_time() is not None]
    if not natural:
        raise ScenarioError(f"{scenario.path or '<scenario>'}: [scenario] needs 'stop_s' "
                            "(no component, such as a cycle, defines the run length)")
    stop = max(natural)
    if stop <= scenario.t0_s:
        raise ScenarioError(f"{scenario.path or '<scenario>'}: [scenario] field 't0_s' ({scenario.t0_s} s) is not "
                            f"before the stop time {stop} s (the components' natural end); give 'stop_s'")
    return stop
