"""known.py - read a calibration's ``--params`` file: known parameters, starting values, an OCV curve or an overlay.

The file (TOML)::

    [meta]                      # free text, ignored
    source = "..."
    [params]                    # the component's own parameters (e.g. capacity_ah, mass_kg) - known
    capacity_ah = 2.9           # values or starting values; unknown names fail with a suggestion
    soc0_frac = 1.0             # cell short form: initial SOC (< 0: from the first rest voltage)
    [ocv]                       # cell short form: open-circuit voltage curve (either order of SOC)
    soc_frac = [0.0, 0.1, ...]  # or soc_pct = [0.0, 10.0, ...]
    ocv_v = [3.0, 3.4, ...]

or a component parameter file (``components/battery/default.toml``...), or a calibration's own overlay
``params.toml`` (tables ``[battery]``, ``[vehicle]``/``[motor]``/``[bus]``, ``[engine_generator]``).
"""
from __future__ import annotations

from pathlib import Path

from ..core.errors import DataError


def load_params_toml(path) -> dict:
    """Read a ``--params`` file into a dict of known / initial parameters for the calibration model.

    Accepted: the short form (``[params]`` and, for a cell, ``[ocv]``), a component parameter file
    (``[meta]`` + ``[params]``), or an overlay with one table per component (``[battery]``, ``[vehicle]``,
    ``[motor]``, ``[bus]``, ``[engine_generator]`` - a calibration's own ``params.toml``), returned under the
    key ``"__tables__"``.  ``"__base_dir__"`` is the file's folder (relative ``*_file`` paths resolve
    against it).
    """
    path = Path(path)
    if not path.is_file():
        from ..core.paths import bundled_params
        found = bundled_params(str(path))          # a bundled set by name (battery/default)
        if found is None:
            raise DataError(f"{path}: parameter file not found (a file, or a bundled parameter set such as "
                            f"battery/default: shevsim components --sets)")
        path = found
    from ..core.errors import toml_loads
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise DataError(f"{path}: cannot read as UTF-8 text: {exc}") from None
    doc = toml_loads(text, str(path), DataError, "invalid TOML")
    out: dict = {"__base_dir__": str(path.resolve().parent)}
    tables: dict = {}
    for sec, body in doc.items():
        if sec == "meta":
            continue
        if not isinstance(body, dict):
            raise DataError(f"{path}: '{sec}' must be a table [{sec}] of name = value")
        if sec == "params":
            out.update(body)
        elif sec == "ocv":
            for k in body:
                if k not in ("soc_frac", "soc_pct", "ocv_v"):
                    raise DataError(f"{path}: [ocv] unknown key '{k}' (expected soc_frac or soc_pct, and ocv_v)")
            if ("soc_frac" in body) == ("soc_pct" in body) or "ocv_v" not in body:
                raise DataError(f"{path}: [ocv] needs ocv_v and one of soc_frac, soc_pct")
            key = "soc_frac" if "soc_frac" in body else "soc_pct"
            try:
                soc = [float(x) / (100.0 if key == "soc_pct" else 1.0) for x in body[key]]
                v = [float(x) for x in body["ocv_v"]]
            except (TypeError, ValueError) as exc:
                raise DataError(f"{path}: [ocv] {key} and ocv_v must be lists of numbers ({exc})") from exc
            # a discharge test lists the curve from full to empty: taken in increasing SOC (the pairs kept together)
            if len(soc) >= 2 and len(soc) == len(v) and all(b < a for a, b in zip(soc, soc[1:])):
                soc, v = soc[::-1], v[::-1]
            out["ocv_soc_frac"] = tuple(soc)
            out["ocv_v"] = tuple(v)
        elif sec in COMPONENT_TABLES:
            tables[sec] = dict(body)
        else:
            raise DataError(f"{path}: unknown table [{sec}] (expected [meta], [params], [ocv] or a component "
                            f"table: {', '.join(COMPONENT_TABLES)})")
    if tables:
        out["__tables__"] = tables
    return out


COMPONENT_TABLES = ("battery", "vehicle", "motor", "bus", "engine_generator")
