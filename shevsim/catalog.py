"""catalog.py - what a user can put in a scenario: component types (ports with units, parameters with their
valid ranges and defaults) and the bundled parameter sets.

``shevsim components [TYPE]`` and ``shevsim components --sets`` print these; the Python API returns plain
data (lists of dicts), so a notebook can tabulate them::

    >>> import shevsim.catalog as cat
    >>> [t["type"] for t in cat.component_types()][:3]
    ['battery', 'bms', 'bus']
    >>> cat.describe_type("vehicle")["parameters"][0]["name"]
    'mass_kg'
"""
from __future__ import annotations

import dataclasses
import tomllib
import typing
from typing import Any

from .components import REGISTRY, get_component_class, registered_types
from .core.params import field_range
from .core.paths import DATA_ROOT

#: the bundled parameter folder(s) of each built-in type (``components/<folder>/*.toml``)
PARAM_FOLDERS = {"mpc_supervisor": ("supervisor",), "rule_supervisor": ("supervisor",),
                 "power_limits": ("bus",)}
#: types that exist for the verification tests, listed only with ``include_test_types=True``
TEST_TYPES = ("mass_spring", "spring_damper", "trivial", "gain")


def _first_line(text: str | None) -> str:
    for line in (text or "").strip().splitlines():
        if line.strip():
            return line.strip()
    return ""


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:        # type: ignore[misc]
        return f.default_factory()                          # type: ignore[misc]
    return None


def _range_text(f: dataclasses.Field, hint, default) -> str:
    """What values a parameter takes: the numeric range, the choices of a ``Literal``, text or true/false."""
    if typing.get_origin(hint) is typing.Literal:
        return "one of " + ", ".join(repr(x) for x in typing.get_args(hint))
    if hint is bool or isinstance(default, bool):
        return "true/false"
    if hint is str or isinstance(default, str):
        return "text"
    return field_range(f).describe()


def describe_type(type_name: str) -> dict:
    """One component type: ``{"type", "class", "summary", "ports": [{name, causality, unit, start,
    description}], "parameters": [{name, default, range}], "parameter_sets": [names]}``.

    Ports are the class's declared variables (a component whose ports depend on a parameter, such as the
    vehicle's ``input_mode = "speed"``, lists its default form); ranges are those every loaded value is
    checked against (:func:`shevsim.core.params.field_range`).
    """
    cls = get_component_class(type_name, "shevsim components")
    ports = [{"name": v.name, "causality": v.causality, "unit": v.unit, "start": v.start,
              "description": v.description} for v in getattr(cls, "VARIABLES", ()) or ()]
    params = []
    pcls = getattr(cls, "Params", None)
    if pcls is not None and dataclasses.is_dataclass(pcls):
        try:
            hints = typing.get_type_hints(pcls)
        except Exception:  # noqa: BLE001 - a hint that does not resolve: fall back to the default's type
            hints = {}
        for f in dataclasses.fields(pcls):
            if f.name.startswith("_"):
                continue
            d = _default(f)
            params.append({"name": f.name, "default": d if isinstance(d, (int, float, str, bool)) or d is None
                           else (list(d) if isinstance(d, (list, tuple)) else repr(d)),
                           "range": _range_text(f, hints.get(f.name), d)})
    return {"type": type_name, "class": f"{cls.__module__}.{cls.__qualname__}",
            "summary": _first_line(cls.__doc__), "ports": ports, "parameters": params,
            "parameter_sets": [s["name"] for s in parameter_sets(type_name)]}


def component_types(include_test_types: bool = False) -> list[dict]:
    """Every registered type (built-in and plugins) with a one-line summary and its port counts."""
    out = []
    for t in registered_types():
        if t in TEST_TYPES and not include_test_types:
            continue
        try:
            cls = get_component_class(t, "shevsim components")
        except Exception as exc:  # noqa: BLE001 - a broken plugin is listed with its error, not fatal
            out.append({"type": t, "summary": f"(cannot be loaded: {exc})", "inputs": 0, "outputs": 0})
            continue
        vs = getattr(cls, "VARIABLES", ()) or ()
        out.append({"type": t, "summary": _first_line(cls.__doc__), "plugin": t not in REGISTRY,
                    "inputs": sum(v.causality == "input" for v in vs),
                    "outputs": sum(v.causality == "output" for v in vs)})
    return out


def parameter_sets(type_name: str | None = None) -> list[dict]:
    """Bundled parameter files: ``{"name": "vehicle/matv", "type": [types], "path", "description"}``.

    ``name`` is what a scenario's ``params = "..."``, ``--params`` and ``fmu export --params`` accept.
    With ``type_name``, only the sets of that type's folder(s).
    """
    root = DATA_ROOT / "components"
    by_folder: dict[str, list[str]] = {}
    for t in registered_types():
        for folder in PARAM_FOLDERS.get(t, (t,)):
            by_folder.setdefault(folder, []).append(t)
    folders = PARAM_FOLDERS.get(type_name, (type_name,)) if type_name else sorted(by_folder)
    out = []
    for folder in folders:
        d = root / folder
        if not d.is_dir():
            continue
        for p in sorted(d.glob("*.toml")):
            desc = ""
            try:
                desc = tomllib.loads(p.read_text(encoding="utf-8")).get("meta", {}).get("description", "")
            except (OSError, ValueError):
                pass
            out.append({"name": f"{folder}/{p.stem}", "type": by_folder.get(folder, []), "path": str(p),
                        "description": str(desc)})
    return out


def format_types(rows: list[dict]) -> str:
    w = max((len(r["type"]) for r in rows), default=4)
    lines = [f"{r['type']:{w}s}  {r['inputs']:2d} in {r['outputs']:2d} out  {r['summary']}"
             + ("  [plugin]" if r.get("plugin") else "") for r in rows]
    return "\n".join(lines + ["", "details: shevsim components TYPE; parameter sets: shevsim components --sets"])


def format_type(d: dict) -> str:
    lines = [f"{d['type']}: {d['summary']}", f"  class {d['class']}", "ports:"]
    for p in d["ports"]:
        lines.append(f"  {p['causality']:6s} {p['name']:28s} [{p['unit']}]  {p['description']}")
    lines.append("parameters (default; valid range):")
    for p in d["parameters"]:
        dv = p["default"]
        if isinstance(dv, list) and len(dv) > 6:
            dv = f"[{len(dv)} values]"
        lines.append(f"  {p['name']:32s} {dv!s:>14s}  {p['range']}")
    if d["parameter_sets"]:
        lines.append("parameter sets: " + ", ".join(d["parameter_sets"]))
    return "\n".join(lines)


def format_sets(rows: list[dict]) -> str:
    w = max((len(r["name"]) for r in rows), default=4)
    return "\n".join(f"{r['name']:{w}s}  {r['description']}" for r in rows)
