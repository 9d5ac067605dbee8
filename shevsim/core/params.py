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

Validation of every number (:func:`make_params` is the single entry of the parameter dataclasses, and
:func:`validate_params` checks an object built directly through the Python API).  Each numeric field has
one physical range, declared once:

* explicitly, with ``dataclasses.field(metadata=rng(...))`` on the field (e.g. ``rng(gt=0, allow_inf=True)``
  for a limit whose default ``inf`` means "no limit");
* otherwise by the unit-suffix convention of the field name (:data:`NAME_RULES`): ``_pct`` in [0, 100],
  ``_frac`` in [0, 1], ``_c`` above absolute zero (> -273.15), ``_k`` > 0, ``_kg``/``_ah``/``_f``/``_ohm``/
  densities/heat capacities/conductivities > 0, durations ``_s`` and lengths ``_m`` >= 0, noise and
  covariance tunings (``sigma_``, ``q_``, ``r_``, ``p0_``, ``s0_``) >= 0, scale factors > 0, efficiencies in
  (0, 1], counts ``n_*`` >= 1;
* every number must be finite: NaN is always refused, +-inf only where the field declares ``allow_inf``.

The same name rules check the columns of map and table files (:func:`check_column`,
:mod:`shevsim.powertrain.maps`): an ``efficiency_frac`` column of 1.5 is refused.  Messages name the file
and field (or the ``--set`` option that gave the value) and the valid range.
"""
from __future__ import annotations

import dataclasses
import functools
import difflib
import math
import tomllib
import typing
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from shevsim.core.filecache import memo_file

from .errors import ScenarioError


ABSOLUTE_ZERO_C = -273.15


@dataclasses.dataclass(frozen=True)
class Range:
    """The valid range of a number: ``lo``/``hi`` bounds (open or closed), ``allow_inf`` for "no limit"."""
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    allow_inf: bool = False
    what: str = ""               # what the range means ("temperature above absolute zero")

    def ok(self, v: float) -> bool:
        if v != v:
            return False
        if math.isinf(v):
            return self.allow_inf and ((v > 0 and self.hi == math.inf) or (v < 0 and self.lo == -math.inf))
        if v < self.lo or (self.lo_open and v == self.lo):
            return False
        if v > self.hi or (self.hi_open and v == self.hi):
            return False
        return True

    def ok_array(self, values: np.ndarray) -> np.ndarray:
        """:meth:`ok` of every element of a float array (vectorised)."""
        v = np.asarray(values, dtype=float)
        fin = np.isfinite(v)
        good = fin & (v >= self.lo) & (v <= self.hi)
        if self.lo_open:
            good &= v != self.lo
        if self.hi_open:
            good &= v != self.hi
        if self.allow_inf:
            good |= (v == math.inf) & (self.hi == math.inf)
            good |= (v == -math.inf) & (self.lo == -math.inf)
        return good

    def describe(self) -> str:
        if self.lo == -math.inf and self.hi == math.inf:
            txt = "any finite number"
        elif self.hi == math.inf:
            txt = f"{'>' if self.lo_open else '>='} {self.lo:g}"
        elif self.lo == -math.inf:
            txt = f"{'<' if self.hi_open else '<='} {self.hi:g}"
        else:
            txt = f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        if self.allow_inf:
            txt += " (inf allowed: no limit)"
        elif self.lo != -math.inf or self.hi != math.inf:
            txt += ", finite"
        return txt + (f" ({self.what})" if self.what else "")


def rng(lo: float | None = None, hi: float | None = None, *, gt: float | None = None, lt: float | None = None,
        allow_inf: bool = False, what: str = "") -> dict:
    """Field metadata declaring a number's valid range: ``field(default=..., metadata=rng(gt=0))``.

    ``lo``/``hi`` are closed bounds, ``gt``/``lt`` open ones; ``allow_inf`` lets +-inf through (a "no limit"
    default).  A declared range replaces the unit-suffix rule of the field's name."""
    r = Range(lo=-math.inf if lo is None and gt is None else (gt if gt is not None else lo),
              hi=math.inf if hi is None and lt is None else (lt if lt is not None else hi),
              lo_open=gt is not None, hi_open=lt is not None, allow_inf=allow_inf, what=what)
    return {"range": r}


ANY = Range()
_POS = Range(lo=0.0, lo_open=True)
_NONNEG = Range(lo=0.0)

#: Name rules, first match wins: (kind, token, range). ``suffix`` matches the end of the name, ``prefix`` its
#: start, ``exact`` the whole name.  Applied to parameter fields without a declared range and to map columns.
NAME_RULES: tuple[tuple[str, str, Range], ...] = (
    ("prefix", "sigma_", Range(lo=0.0, what="a standard deviation")),
    ("suffix", "_sigma_c", Range(lo=0.0, what="a standard deviation")),
    ("prefix", "q_", Range(lo=0.0, what="a process-noise variance")),
    ("prefix", "r_", Range(lo=0.0, lo_open=True, what="a measurement-noise variance")),
    ("prefix", "p0_", Range(lo=0.0, what="an initial covariance")),
    ("prefix", "s0_", Range(lo=0.0, what="an initial covariance")),
    ("prefix", "factor_", Range(lo=0.0, what="a covariance factor")),
    ("prefix", "eta", Range(lo=0.0, what="a cost weight")),
    ("suffix", "_weight", Range(lo=0.0, what="a cost weight")),
    ("suffix", "_weight_1", Range(lo=0.0, what="a cost weight")),
    ("suffix", "_weight_quad_1", Range(lo=0.0, what="a cost weight")),
    ("suffix", "_coefficient", Range(lo=0.0, what="a coefficient")),
    ("prefix", "kp_", Range(lo=0.0, what="a controller gain")),
    ("prefix", "ki_", Range(lo=0.0, what="a controller gain")),
    ("prefix", "rack_k", Range(lo=0.0, what="a controller gain")),
    ("suffix", "_gain", Range(lo=0.0, what="a gain")),
    ("suffix", "_rate", Range(lo=0.0, what="a rate")),
    ("prefix", "thermal_", Range(lo=0.0, what="an estimator tuning")),
    ("suffix", "_scale_frac", Range(lo=0.0, lo_open=True, what="a scale factor")),
    ("suffix", "radius_m", Range(lo=0.0, lo_open=True, what="a radius")),
    ("suffix", "length_m", Range(lo=0.0, lo_open=True, what="a length")),
    ("suffix", "sample_time_s", Range(lo=0.0, lo_open=True, what="a sample time")),
    ("suffix", "horizon_s", Range(lo=0.0, lo_open=True, what="a horizon")),
    ("suffix", "_substep_s", Range(lo=0.0, lo_open=True, what="a step size")),
    ("suffix", "_time_s", Range(what="a point in time")),
    ("exact", "time_s", Range(what="a time axis")),
    ("suffix", "_max_n", Range(lo=0.0, what="a force limit")),
    ("suffix", "_max_wps", Range(lo=0.0, lo_open=True, what="a rate limit")),
    ("suffix", "max_rate_wps", Range(lo=0.0, lo_open=True, what="a rate limit")),
    ("suffix", "_max_radps2", Range(lo=0.0, lo_open=True, what="an acceleration limit")),
    ("suffix", "_min_mps", Range(lo=0.0, what="a speed threshold")),
    ("suffix", "speed_init_mps", Range(lo=0.0, what="an initial speed")),
    ("prefix", "power_gen_", Range(lo=0.0, what="a generator power")),
    ("suffix", "_mg_per_g", Range(lo=0.0, what="a mass ratio")),
    ("exact", "gear_ratio", Range(lo=0.0, lo_open=True, what="a gear ratio")),
    ("exact", "repeat", Range(lo=1.0, what="a count")),
    ("exact", "substeps", Range(lo=1.0, what="a count")),
    ("suffix", "_scale", Range(lo=0.0, what="a scale factor")),
    ("suffix", "_factor", Range(lo=0.0, what="a scale factor")),
    ("suffix", "_eff", Range(lo=0.0, hi=1.0, lo_open=True, what="an efficiency")),
    ("suffix", "efficiency_frac", Range(lo=0.0, hi=1.0, lo_open=True, what="an efficiency")),
    ("exact", "efficiency", Range(lo=0.0, hi=1.0, lo_open=True, what="an efficiency")),
    ("prefix", "n_", Range(lo=1.0, what="a count")),            # before the '_c' suffix (n_c: control horizon)
    ("suffix", "_n_per_m", Range(lo=0.0, what="a stiffness")),
    ("suffix", "_ns_per_m", Range(lo=0.0, what="a damping coefficient")),
    ("suffix", "_per_s", Range(lo=0.0, what="a rate")),
    ("suffix", "_v", Range(lo=0.0, what="a voltage magnitude")),
    ("suffix", "_pct", Range(lo=0.0, hi=100.0, what="a percentage")),
    ("suffix", "_frac", Range(lo=0.0, hi=1.0, what="a fraction")),
    ("suffix", "_c", Range(lo=ABSOLUTE_ZERO_C, lo_open=True, what="a temperature in degC, above absolute zero")),
    ("suffix", "_k", Range(lo=0.0, lo_open=True, what="an absolute temperature in K")),
    ("suffix", "_kg_m3", Range(lo=0.0, lo_open=True, what="a density")),
    ("suffix", "_kg_per_l", Range(lo=0.0, lo_open=True, what="a density")),
    ("suffix", "_j_kgk", Range(lo=0.0, lo_open=True, what="a heat capacity")),
    ("suffix", "_w_mk", Range(lo=0.0, lo_open=True, what="a thermal conductivity")),
    ("suffix", "_w_m2k", Range(lo=0.0, what="a heat-transfer coefficient")),
    ("suffix", "_kg_m2", Range(lo=0.0, lo_open=True, what="an inertia")),
    ("suffix", "_j_per_g", Range(lo=0.0, lo_open=True, what="a heating value")),
    ("suffix", "_kg", Range(lo=0.0, lo_open=True, what="a mass")),
    ("suffix", "_m2", Range(lo=0.0, lo_open=True, what="an area")),
    ("suffix", "_ah", Range(lo=0.0, lo_open=True, what="a capacity")),
    ("suffix", "_ohm", Range(lo=0.0, lo_open=True, what="a resistance")),
    ("suffix", "_f", Range(lo=0.0, lo_open=True, what="a capacitance")),
    ("suffix", "_gps", Range(lo=0.0, what="a mass rate")),
    ("suffix", "_mgps", Range(lo=0.0, what="a mass rate")),
    ("suffix", "_hz", Range(lo=0.0, lo_open=True, what="a frequency")),
    ("suffix", "_s", Range(lo=0.0, what="a duration or time")),
    ("suffix", "_m", Range(lo=0.0, what="a length")),
)


@functools.lru_cache(maxsize=None)
def _type_hints(cls) -> dict:
    """``typing.get_type_hints`` of a parameter class (resolved once: it compiles every string annotation)."""
    return typing.get_type_hints(cls)


@functools.lru_cache(maxsize=4096)
def name_rule(name: str) -> Range:
    """The range the unit-suffix convention gives a field or column ``name`` (:data:`NAME_RULES`)."""
    for kind, tok, r in NAME_RULES:
        if (kind == "suffix" and name.endswith(tok)) or (kind == "prefix" and name.startswith(tok)) \
                or (kind == "exact" and name == tok):
            return r
    return ANY


def field_range(f: dataclasses.Field) -> Range:
    """The declared range of a dataclass field (``metadata['range']``), else its name rule."""
    r = f.metadata.get("range") if f.metadata else None
    return r if isinstance(r, Range) else name_rule(f.name)


def _bad_number(v: Any, r: Range) -> str | None:
    """Why number ``v`` is not valid for ``r`` (None when it is)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        v = float(v)
    except OverflowError:
        return "too large for a number"
    if v != v:
        return "NaN is not a valid value"
    if r.ok(v):
        return None
    if math.isinf(v):
        return f"{v} is not allowed (a finite number is needed)"
    return "out of range"


def check_value(name: str, value: Any, where: str, r: Range | None = None) -> None:
    """Raise :class:`ScenarioError` unless ``value`` (a number, or a list of numbers) fits ``r``
    (default: the name rule of ``name``).  The message names ``where``, the field and the valid range."""
    r = name_rule(name) if r is None else r
    vals = value if isinstance(value, (list, tuple)) else (value,)
    for i, v in enumerate(vals):
        why = _bad_number(v, r)
        if why is not None:
            idx = f"[{i}]" if isinstance(value, (list, tuple)) else ""
            raise ScenarioError(f"{where}: parameter '{name}{idx}' = {v!r}: {why}; valid range: {r.describe()}")


def validate_params(obj: Any, where: str = "<parameters>", sources: Mapping[str, str] | None = None) -> Any:
    """Check every number of parameter dataclass ``obj`` against its field's range (see module docstring).

    ``sources`` maps a field name to where its value came from (``--set 'bms.t0_c=nan'``); other fields are
    blamed on ``where``.  Returns ``obj``."""
    sources = sources or {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            pass
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        check_value(f.name, v, sources.get(f.name, where), field_range(f))
    # pairs named alike except for min/max (soc_min_pct / soc_max_pct, v_min_v / v_max_v): min <= max
    names = {f.name for f in dataclasses.fields(obj)}
    for lo_name in sorted(names):
        if "_min" not in f"_{lo_name}":
            continue
        hi_name = f"_{lo_name}".replace("_min", "_max", 1)[1:]
        if hi_name == lo_name or hi_name not in names:
            continue
        lo_v, hi_v = getattr(obj, lo_name), getattr(obj, hi_name)
        if (isinstance(lo_v, (int, float)) and isinstance(hi_v, (int, float)) and not isinstance(lo_v, bool)
                and not isinstance(hi_v, bool) and lo_v > hi_v):
            src = sources.get(lo_name) or sources.get(hi_name) or where
            raise ScenarioError(f"{src}: parameter '{lo_name}' = {lo_v!r} is above '{hi_name}' = {hi_v!r} "
                                f"(a minimum must not exceed its maximum)")
    return obj


def check_options(options: Mapping[str, Any], where: str) -> dict:
    """Check every number (or list of numbers) of an options table (a scenario's ``[metrics]``) against
    the name rule of its key (``fuel_density_kg_per_l`` > 0, ``soc_tolerance_pct`` in [0, 100], ...);
    NaN and inf are refused.  Returns the options as a dict."""
    if not isinstance(options, Mapping):
        raise ScenarioError(f"{where}: expected a table of name = value, got {options!r}")
    for k, v in options.items():
        check_value(str(k), v, where)
    return dict(options)


def _suggest(key: str, options) -> str:
    best = difflib.get_close_matches(key, list(options), n=1)
    return f" (did you mean '{best[0]}'?)" if best else ""


def _coerce(value: Any, typ: Any, where: str) -> Any:
    origin = typing.get_origin(typ)
    if isinstance(value, np.generic) and not isinstance(value, (np.str_, np.bytes_)):
        value = value.item()              # numpy scalars (np.arange, np.linspace in a sweep) as Python numbers
    elif isinstance(value, np.ndarray) and value.ndim == 1 and origin in (tuple, list):
        value = value.tolist()
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{where}: expected a number, got {value!r}")
        try:
            return float(value)
        except OverflowError:
            raise ScenarioError(f"{where}: {value!r} is too large for a number") from None
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
                base_dir: Path | None = None, sources: Mapping[str, str] | None = None) -> Any:
    """Build a parameter dataclass ``cls`` from ``values`` with checked keys, types and ranges.

    ``sources`` maps a key to where its value came from (a ``--set`` option, a scenario's ``set`` table);
    keys not in it are blamed on ``where`` (the parameter file)."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise ScenarioError(f"{where}: {cls!r} is not a parameter dataclass")
    if not isinstance(values, Mapping):
        raise ScenarioError(f"{where}: parameters must be a table of name = value, got {type(values).__name__}")
    sources = dict(sources or {})
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = _type_hints(cls)
    kwargs = {}
    for key, value in values.items():
        src = sources.get(key, where)
        if not isinstance(key, str) or key not in fields:
            raise ScenarioError(f"{src}: unknown parameter '{key}' for {cls.__name__}{_suggest(str(key), fields)}")
        val = _coerce(value, hints[key], f"{src}: parameter '{key}'")
        if isinstance(val, (int, float, tuple)):
            check_value(key, val, src, field_range(fields[key]))
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
    except (TypeError, ValueError, ArithmeticError, IndexError, KeyError) as exc:
        raise ScenarioError(f"{where}: {exc}") from exc
    # every number, defaults included (a default that breaks its own declared range is a bug, said here)
    return validate_params(obj, where, sources)


@memo_file
def read_param_toml(path: Path) -> dict:
    """The parsed TOML of a parameter file (parsed once per process while the file is unchanged)."""
    from .errors import toml_loads
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: malformed TOML: {exc}") from exc
    return toml_loads(text, str(path))


def read_params_table(path: str | Path) -> dict[str, Any]:
    """The ``[params]`` table of a parameter file, checked (a copy: the caller may change it)."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"{path}: parameter file not found")
    doc = read_param_toml(path)
    extra = set(doc) - {"meta", "params"}
    if extra:
        k = sorted(extra)[0]
        raise ScenarioError(f"{path}: unknown table '{k}'{_suggest(k, ['meta', 'params'])}")
    if "params" not in doc:
        raise ScenarioError(f"{path}: missing table [params]")
    if not isinstance(doc["params"], dict):
        raise ScenarioError(f"{path}: [params] must be a table of name = value, got {doc['params']!r}")
    return dict(doc["params"])


def load_params(cls: type, path: str | Path | None, overrides: Mapping[str, Any] | None = None,
                sources: Mapping[str, str] | None = None, table: Mapping[str, Any] | None = None) -> Any:
    """Load ``cls`` from a TOML parameter file (``[params]`` table) plus overrides.

    ``sources`` names where each override came from (default: "override"), so an error in a value given
    by ``--set`` blames that option, not the parameter file.  ``table``: the file's ``[params]`` table
    already read (a study's captured scenario, :mod:`shevsim.studies.bundle`, whose ``*_file`` values are
    absolute): the file is then not opened, ``path`` only names it in messages."""
    values: dict[str, Any] = {}
    base_dir = None
    where = "<overrides>"
    if path is not None:
        path = Path(path)
        values.update(read_params_table(path) if table is None else table)
        base_dir = path.parent
        where = str(path)
    elif table is not None:
        values.update(table)
    src: dict[str, str] = {}
    if overrides:
        values.update(overrides)
        for k in overrides:
            src[k] = (sources or {}).get(k, where)
    return make_params(cls, values, where, base_dir, src)


def params_to_dict(p: Any) -> dict[str, Any]:
    """Plain dict of a parameter dataclass (for result metadata)."""
    if p is None:
        return {}
    if dataclasses.is_dataclass(p):
        return {f.name: getattr(p, f.name) for f in dataclasses.fields(p)}
    return dict(p)
