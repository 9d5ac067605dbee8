"""known.py - read a calibration's ``--params`` file: known parameters, starting values, an OCV curve or an overlay.

The file (TOML)::

    [meta]                      # free text, ignored
    source = "..."
    [params]                    # the component's own parameters (e.g. capacity_ah, mass_kg) - known
    capacity_ah = 2.9           # values or starting values; unknown names fail with a suggestion
    soc0_frac = 1.0             # cell short form: initial SOC (< 0: from the first rest voltage)
    [ocv]                       # cell short form: open-circuit voltage curve
    soc_frac = [0.0, 0.1, ...]
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
                if k not in ("soc_frac", "ocv_v"):
                    raise DataError(f"{path}: [ocv] unknown key '{k}' (expected soc_frac, ocv_v)")
            if "soc_frac" not in body or "ocv_v" not in body:
                raise DataError(f"{path}: [ocv] needs both soc_frac and ocv_v")
            try:
                out["ocv_soc_frac"] = tuple(float(x) for x in body["soc_frac"])
                out["ocv_v"] = tuple(float(x) for x in body["ocv_v"])
            except (TypeError, ValueError) as exc:
                raise DataError(f"{path}: [ocv] soc_frac and ocv_v must be lists of numbers ({exc})") from exc
        elif sec in COMPONENT_TABLES:
            tables[sec] = dict(body)
        else:
            raise DataError(f"{path}: unknown table [{sec}] (expected [meta], [params], [ocv] or a component "
                            f"table: {', '.join(COMPONENT_TABLES)})")
    if tables:
        out["__tables__"] = tables
    return out


COMPONENT_TABLES = ("battery", "vehicle", "motor", "bus", "engine_generator")
