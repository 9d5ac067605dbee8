"""overlay.py - parameter overlays: partial parameter sets merged over a scenario's component parameters.

A calibration writes what it found as an overlay, ``DIR/params.toml``::

    [meta]
    source = "shevsim calibrate cell DATA.csv"
    [battery]                 # one table per component, in the component's own parameter names and units
    rs_scale = 1.31
    hyst_max_v = 0.012
    ocv_file = "ocv.csv"      # *_file paths are relative to the overlay's folder

A plain component parameter file (``[meta]`` + ``[params]``) is an overlay too (its ``[params]`` apply to
the component it is given for).  The next run uses it with ``shevsim run SCENARIO --params
battery=DIR/params.toml`` (``--params DIR/params.toml`` applies every table to the component of the same
name) or, in a scenario, ``[components.battery] overlay = "DIR/params.toml"``.

Precedence, lowest first: the component's parameter file, the scenario's ``overlay``, its ``set`` table,
``--params`` overlays, ``--set`` options.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from .atomic import write_text_atomic
from .errors import ScenarioError
from .tomlio import toml_key, toml_value


@dataclass
class Overlay:
    """Values of one component's table of an overlay file; ``base_dir`` resolves its ``*_file`` paths."""
    values: dict
    base_dir: Path
    path: Path


def _find(path: str | Path) -> Path:
    """An overlay file, or a bundled parameter set named as ``shevsim components --sets`` lists it
    (``vehicle/matv``) when no such file exists."""
    path = Path(path)
    if not path.is_file():
        from .paths import bundled_params
        found = bundled_params(str(path))
        if found is not None:
            return found
    return path


def _read(path: Path) -> dict:
    from .errors import file_problem
    why = file_problem(path, "parameter overlay", 64 * 2**20)
    if why is not None:
        raise ScenarioError(f"{path}: {why}")
    from .errors import toml_loads
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise ScenarioError(f"{path}: cannot read the overlay as UTF-8 text: {exc}") from None
    return toml_loads(text, str(path))


def overlay_tables(path: str | Path) -> dict[str, dict]:
    """All component tables of an overlay file (``[params]`` is returned under the key ``""``)."""
    path = _find(path)
    doc = _read(path)
    out = {}
    for k, v in doc.items():
        if k == "meta":
            continue
        if not isinstance(v, dict):
            raise ScenarioError(f"{path}: '{k}' must be a table [{k}] of name = value")
        out["" if k == "params" else k] = v
    if not out:
        raise ScenarioError(f"{path}: no component table (expected [params] or [<component name>])")
    return out


def overlay_values(path: str | Path, component: str) -> Overlay:
    """The values an overlay file gives ``component`` (its ``[component]`` table, else its ``[params]``)."""
    path = _find(path)
    tabs = overlay_tables(path)
    if component in tabs:
        vals = tabs[component]
    elif "" in tabs:
        vals = tabs[""]
    else:
        raise ScenarioError(f"{path}: no table [{component}] or [params] (tables: {', '.join(sorted(tabs))})")
    return Overlay(dict(vals), path.parent.resolve(), path)


def resolve_files(ov: Overlay) -> dict:
    """The overlay's values with relative ``*_file`` paths made absolute against its folder."""
    out = {}
    for k, v in ov.values.items():
        if k.endswith("_file") and isinstance(v, str) and v and not Path(v).is_absolute():
            v = str((ov.base_dir / v).resolve())
        out[k] = v
    return out


def write_overlay(path: str | Path, tables: dict[str, dict], meta: dict | None = None) -> Path:
    """Write an overlay file atomically (``[meta]`` then one table per component)."""
    lines = []
    if meta:
        lines.append("[meta]")
        lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in meta.items()]
        lines.append("")
    for comp, vals in tables.items():
        lines.append(f"[{toml_key(comp)}]")
        lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in vals.items()]
        lines.append("")
    return write_text_atomic(path, "\n".join(lines))
