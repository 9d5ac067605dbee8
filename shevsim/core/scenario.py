"""scenario.py - declarative scenario files (TOML) -> a ready-to-run :class:`Master`.

Example::

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

from .errors import ScenarioError, ShevsimError
from .master import Connection, Fault, Master, MasterSettings
from .overlay import overlay_tables, overlay_values, resolve_files
from .params import load_params
from shevsim.core.paths import DATA_ROOT, bundled_scenario

PROJECT_ROOT = DATA_ROOT   # the folder holding components/, cycles/, scenarios/ (checkout or wheel)

_TOP = {"scenario", "components", "connections", "faults", "record", "metrics"}
_SCEN = {"name", "description", "step_s", "stop_s", "t0_s", "method", "seed", "order"}
_COMP = {"type", "params", "set", "start", "step_multiple", "fmu", "map", "replaces", "overlay"}
_FAULT = {"at_s", "port", "value"}
_RECORD = {"signals"}


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


def parse_value(text: str) -> Any:
    """Parse a ``--set`` value as a TOML value (number, bool, string, list); bare words are strings."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


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
    are ``COMPONENT=FILE`` or ``FILE`` parameter overlays (:mod:`shevsim.core.overlay`)."""
    spath = Path(path) if path is not None else None
    if text is None and spath is not None and not spath.is_file() and bundled_scenario(str(path)) is not None:
        spath = bundled_scenario(str(path))      # a bundled scenario by name (hd_udds_rule)
    where = str(spath) if spath else "<scenario>"
    if text is None:
        if spath is None or not spath.is_file():
            from .paths import bundled_scenarios
            raise ScenarioError(f"{where}: scenario file not found (bundled scenarios by name: "
                                f"{', '.join(bundled_scenarios())})")
        text = spath.read_text()
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where}: malformed TOML: {exc}") from exc
    _check_keys(doc, _TOP, where)
    sc = doc.get("scenario", {})
    _check_keys(sc, _SCEN, f"{where}: [scenario]")
    name = sc.get("name", spath.stem if spath else "scenario")
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{where}: [scenario] field 'name' must be a string, got {name!r}")

    def num(d, k, default, w, typ=float):
        v = d.get(k, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (typ is int and not float(v).is_integer()):
            raise ScenarioError(f"{w}: field '{k}' must be {'an integer' if typ is int else 'a number'}, got {v!r}")
        return typ(v)

    settings = MasterSettings(step_s=num(sc, "step_s", 0.1, f"{where}: [scenario]"),
                              method=str(sc.get("method", "gauss-seidel")))
    try:
        settings.check()
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: [scenario] {exc}") from None
    comps_doc = doc.get("components")
    if not comps_doc:
        raise ScenarioError(f"{where}: no [components] defined")
    _check_keys(comps_doc, set(comps_doc), where)
    specs: list[ComponentSpec] = []
    for cname, cd in comps_doc.items():
        w = f"{where}: [components.{cname}]"
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
            if not pf.is_file():
                raise ScenarioError(f"{w}: field 'params': parameter file '{cd['params']}' not found")
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
        over = {}
        if "overlay" in cd:
            if not isinstance(cd["overlay"], str):
                raise ScenarioError(f"{w}: field 'overlay' must be a file path string")
            try:
                over.update(resolve_files(overlay_values(resolve_path(cd["overlay"], spath), cname)))
            except ScenarioError as exc:
                raise ScenarioError(f"{w}: field 'overlay': {exc}") from None
        over.update({key: _file_value(key, v, spath) for key, v in cd.get("set", {}).items()})
        specs.append(ComponentSpec(cname, cd["type"], pf, over, dict(cd.get("start", {})),
                                   k, fmu, dict(cd.get("map", {})), rep))
    names = {s.name for s in specs}
    for item in overlays:
        comp, sep, f = str(item).partition("=")
        if not sep or (comp not in names and Path(str(item)).exists()):
            comp, f = "", str(item)          # a bare FILE (its path may contain '=')
        fpath = Path(f)
        try:
            targets = [comp] if comp else [n for n in overlay_tables(fpath) if n in names]
            if comp and comp not in names:
                raise ScenarioError(f"unknown component '{comp}'{_hint(comp, names)}")
            if not targets:
                raise ScenarioError(f"{fpath}: no table names a component of this scenario "
                                    f"({', '.join(sorted(names))}); give COMPONENT=FILE")
            for cname in targets:
                vals = resolve_files(overlay_values(fpath, cname))
                next(c for c in specs if c.name == cname).overrides.update(vals)
        except ScenarioError as exc:
            raise ScenarioError(f"--params '{item}': {exc}") from None
    for s in sets:
        if "=" not in s or "." not in s.split("=", 1)[0]:
            raise ScenarioError(f"--set '{s}': expected component.param=value")
        key, val = s.split("=", 1)
        cname, pname = key.strip().split(".", 1)
        if cname not in names:
            raise ScenarioError(f"--set '{s}': unknown component '{cname}'{_hint(cname, names)}")
        # a relative *_file path given on the command line is relative to the working directory
        next(c for c in specs if c.name == cname).overrides[pname] = _file_value(pname, parse_value(val.strip()), None)
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
    faults = []
    for i, fd in enumerate(doc.get("faults", [])):
        w = f"{where}: [[faults]] #{i + 1}"
        _check_keys(fd, _FAULT, w)
        for key in _FAULT:
            if key not in fd:
                raise ScenarioError(f"{w}: missing field '{key}'")
        at = num(fd, "at_s", None, w)
        if not math.isfinite(at):
            raise ScenarioError(f"{w}: field 'at_s' must be a finite number, got {at!r}")
        val = num(fd, "value", None, w)
        if "." not in str(fd["port"]):
            raise ScenarioError(f"{w}: field 'port' must be 'component.port'")
        comp, port = str(fd["port"]).split(".", 1)
        if comp not in names:
            raise ScenarioError(f"{w}: unknown component '{comp}'{_hint(comp, names)}")
        faults.append(Fault(at, comp, port, val))
    rec = doc.get("record", {})
    _check_keys(rec, _RECORD, f"{where}: [record]")
    signals = rec.get("signals", "all")
    if signals == "all":
        signals = None
    elif not (isinstance(signals, list) and all(isinstance(x, str) for x in signals)):
        raise ScenarioError(f"{where}: [record] field 'signals' must be \"all\" or a list of 'component.port'")
    seed = num(sc, "seed", 0, f"{where}: [scenario]", int)
    stop_s = num(sc, "stop_s", None, f"{where}: [scenario]")
    t0_s = num(sc, "t0_s", 0.0, f"{where}: [scenario]")
    for key, v in (("t0_s", t0_s), ("stop_s", stop_s)):
        if v is not None and not math.isfinite(v):
            raise ScenarioError(f"{where}: [scenario] field '{key}' must be a finite number, got {v!r}")
    if stop_s is not None and stop_s <= t0_s:
        raise ScenarioError(f"{where}: [scenario] field 'stop_s' ({stop_s} s) must be after t0_s ({t0_s} s)")
    order = sc.get("order")
    if order is not None:
        if not (isinstance(order, list) and all(isinstance(x, str) for x in order)):
            raise ScenarioError(f"{where}: [scenario] field 'order' must be a list of component names")
        for n in order:
            if n not in names:
                raise ScenarioError(f"{where}: [scenario] field 'order': unknown component '{n}'{_hint(n, names)}")
        if sorted(order) != sorted(names):
            rep = sorted({n for n in order if order.count(n) > 1})
            raise ScenarioError(f"{where}: [scenario] field 'order' must list every component exactly once "
                                + (f"(repeated: {rep})" if rep else f"(missing: {sorted(names - set(order))})"))
    return Scenario(spath, text, name, str(sc.get("description", "")), settings,
                    stop_s, t0_s, seed, specs, conns, faults, signals, dict(doc.get("metrics", {})), order,
                    list(sets), [str(o) for o in overlays])


def _file_value(key: str, value: Any, scenario_path: Path | None) -> Any:
    """A ``*_file`` override as an absolute path: relative to the scenario file (its ``set`` table) or
    to the working directory (``--set``); other values unchanged."""
    if key.endswith("_file") and isinstance(value, str) and value:
        return str(resolve_path(value, scenario_path).absolute())
    return value


def component_seed(scenario_seed: int, name: str) -> int:
    """Per-component seed: stable under reordering of the scenario's components."""
    return (scenario_seed * 1_000_003 + zlib.crc32(name.encode())) % (2**31 - 1)


def instantiate(spec: ComponentSpec, scenario: Scenario):
    """Create one component from its spec."""
    where = f"{scenario.path or '<scenario>'}: [components.{spec.name}]"
    if spec.type == "fmu":
        from ..fmu.adapter import FMUComponent, load_model_description
        if not spec.fmu.is_file():
            kind = spec.replaces or "TYPE"
            raise ScenarioError(f"{where}: field 'fmu': file '{spec.fmu}' not found (an exported native component "
                                f"is built with: shevsim fmu export {kind} --params FILE -o {spec.fmu})")
        expected = None
        if spec.replaces is not None:
            from ..components import get_component_class
            expected = get_component_class(spec.replaces, where)
        params = dict(spec.overrides)
        try:
            md = load_model_description(spec.fmu)
            names = {v.name for v in md.modelVariables if v.causality == "parameter"}
            if "seed" in names and "seed" not in params:   # same noise seed as the native component
                params["seed"] = component_seed(scenario.seed, spec.name)
            comp = FMUComponent(spec.name, spec.fmu, mapping=spec.mapping, parameters=params,
                                expected_units=expected)
        except ShevsimError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
    else:
        from ..components import get_component_class
        cls = get_component_class(spec.type, where)
        params = None
        if cls.Params is not None:
            over = dict(spec.overrides)
            fields = {f.name for f in dataclasses.fields(cls.Params)}
            if "seed" in fields and "seed" not in over:
                over["seed"] = component_seed(scenario.seed, spec.name)
            try:
                params = load_params(cls.Params, spec.params_file, over)
            except ScenarioError as exc:
                raise ScenarioError(f"{where}: {exc}") from None
        elif spec.overrides:
            raise ScenarioError(f"{where}: component type '{spec.type}' takes no parameters")
        try:
            comp = cls(spec.name, params)
        except ShevsimError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
    inputs = {v.name for v in comp.variables() if v.causality == "input"}
    for port, val in spec.start.items():
        if port not in inputs:
            raise ScenarioError(f"{where}: field 'start': component has no input '{port}'{_hint(port, inputs)}")
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise ScenarioError(f"{where}: field 'start.{port}' must be a number")
        comp.u[port] = float(val)
    return comp


def build_master(scenario: Scenario) -> Master:
    """Instantiate the components and the master of a scenario (connections checked)."""
    comps = [instantiate(s, scenario) for s in scenario.components]
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
    if scenario.record is not None:     # checked before the run, not after it
        known = set(m._signal_names)
        for sig in scenario.record:
            if sig not in known:
                raise ScenarioError(f"{where}: [record] field 'signals': unknown signal '{sig}'"
                                    f"{_hint(sig, known)}")
    return m


def stop_time(scenario: Scenario, master: Master) -> float:
    """The scenario's stop time, else the longest natural stop time among components."""
    if scenario.stop_s is not None:
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
