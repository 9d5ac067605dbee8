"""tomlio.py - the one TOML writer of values and keys (``tomllib`` reads; nothing in the standard library writes).

Scenario files (`shevsim.core.scenario.scenario_to_toml`), parameter overlays
(`shevsim.core.overlay.write_overlay`), study overrides (``component.param=value``) and scenarios
imported from SSP packages all write their values through `toml_value`, so a value written by one
reads back the same everywhere: ``tomllib.loads(f"x = {toml_value(v)}")["x"] == v`` for every value it
accepts (floats exactly, via ``repr``; ``nan`` and ``inf`` as TOML's own words).
"""
from __future__ import annotations

import json
import math
import re
from pathlib import PurePath
from typing import Any

from .errors import ScenarioError

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


class TomlValueError(ScenarioError, TypeError):
    """A value that TOML cannot hold (a ``ScenarioError``, and a ``TypeError`` as before)."""


def toml_key(k: str) -> str:
    """A TOML key: bare when it may be (``mass_kg``), else a quoted string (``"battery.soc"``)."""
    k = str(k)
    return k if _BARE_KEY.fullmatch(k) else json.dumps(k)


def toml_value(v: Any) -> str:
    """A Python value as TOML: bool, int, float (``nan``/``inf`` included), str or path (a basic
    string), list or tuple (an array), dict (an inline table) and numpy scalars or arrays."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(int(v))
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(float(v))
    if isinstance(v, (str, PurePath)):
        return json.dumps(str(v))         # JSON's escapes (\", \\, \n, \uXXXX) are TOML's
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    if getattr(v, "ndim", None) == 0 and hasattr(v, "item"):      # numpy scalar
        return toml_value(v.item())
    if hasattr(v, "tolist") and getattr(v, "ndim", 0) >= 1:        # numpy array
        return toml_value(v.tolist())
    raise TomlValueError(f"cannot write {type(v).__name__} value {v!r} as TOML")
