"""params.py - parameter sets: frozen dataclasses loaded from TOML with checked keys.

A parameter file looks like::

    [meta]
    description = "M-ATV point-mass vehicle"
    source = "seed Table 5.1; drag coefficient assumed (see below)"

    [params]
    mass_kg = 15554.0          # seed Table 5.1
    drag_coefficient = 0.75    # assumed: boxy MRAP body

Unknown keys fail with a best-match suggestion, wrong types fail with the
expected type, and both name the file and the field. Fields whose name ends in
``_file`` are paths, resolved relative to the parameter file.
"""
from __future__ import annotations

import dataclasses
import difflib
import tomllib
import typing
from pathlib import Path
from typing import Any, Mapping

from .errors import ScenarioError


def _suggest(key: str, options) -> str:
    best = difflib.get_close_matches(key, list(options), n=1)
    return f" (did you mean '{best[0]}'?)" if best else ""


def _coerce(value: Any, typ: Any, where: str) -> Any:
    origin = typing.get_origin(typ)
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                return int(value)
            raise ScenarioError(f"{where}: expected an integer, got {value!r}")
        return value
    if typ is bool:
        if not isinstance(value, bool):
            raise ScenarioError(f"{where}: expected true/false, got {value!r}")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{where}: expected a string, got {value!r}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ScenarioError(f"{where}: expected a list, got {value!r}")
        args = typing.get_args(typ)
        inner = args[0] if args else Any
        vals = [_coerce(v, inner, f"{where}[{i}]") if inner is not Any else v for i, v in enumerate(value)]
        return tuple(vals)
    return value


def make_params(cls: type, values: Mapping[str, Any], where: str = "<parameters>",
                base_dir: Path | None = None) -> Any:
    """Build a parameter dataclass ``cls`` from ``values`` with checked keys and types."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for key, value in values.items():
        if key not in fields:
            raise ScenarioError(f"{where}: unknown parameter '{key}' for {cls.__name__}{_suggest(key, fields)}")
        val = _coerce(value, hints[key], f"{where}: parameter '{key}'")
        if key.endswith("_file") and isinstance(val, str) and base_dir is not None:
            p = Path(val)
            val = str(p if p.is_absolute() else (base_dir / p).resolve())
        kwargs[key] = val
    missing = [n for n, f in fields.items() if n not in kwargs and f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ScenarioError(f"{where}: missing parameter(s) {', '.join(missing)} for {cls.__name__}")
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{where}: {exc}") from exc
    # resolve default *_file fields relative to base_dir too
    return obj


def load_params(cls: type, path: str | Path | None, overrides: Mapping[str, Any] | None = None) -> Any:
    """Load ``cls`` from a TOML parameter file (``[params]`` table) plus overrides."""
    values: dict[str, Any] = {}
    base_dir = None
    where = "<overrides>"
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ScenarioError(f"{path}: parameter file not found")
        try:
            doc = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(f"{path}: malformed TOML: {exc}") from exc
        extra = set(doc) - {"meta", "params"}
        if extra:
            k = sorted(extra)[0]
            raise ScenarioError(f"{path}: unknown table '{k}'{_suggest(k, ['meta', 'params'])}")
        if "params" not in doc:
            raise ScenarioError(f"{path}: missing table [params]")
        if not isinstance(doc["params"], dict):
            raise ScenarioError(f"{path}: [params] must be a table of name = value, got {doc['params']!r}")
        values.update(doc["params"])
        base_dir = path.parent
        where = str(path)
    if overrides:
        values.update(overrides)
    return make_params(cls, values, where, base_dir)


def params_to_dict(p: Any) -> dict[str, Any]:
    """Plain dict of a parameter dataclass (for result metadata)."""
    if p is None:
        return {}
    if dataclasses.is_dataclass(p):
        return {f.name: getattr(p, f.name) for f in dataclasses.fields(p)}
    return dict(p)
