"""export.py - pack a native shevsim component as a co-simulation FMU (pythonfmu / pythonfmu3).

``export_component("rc_thermal_node", "params.toml", "out.fmu")`` (or the CLI
``shevsim fmu export TYPE --params FILE -o OUT.fmu [--fmi-version 3]``):

1. finds the class by its registry TYPE (``shevsim.components.REGISTRY``) or a
   class passed from Python (a command line names a registered type only);
2. loads and checks the parameter file with the class's ``Params`` dataclass
   and stores the values as JSON in the FMU's ``resources/`` (files named by
   ``*_file`` parameters are copied into the FMU too);
3. generates a small pythonfmu slave script (:func:`shevsim.fmu.slave.slave_script`:
   an ``Fmi2Slave``/``Fmi3Slave`` subclass delegating to :class:`shevsim.fmu.slave.Runtime`)
   and builds the FMU.

Every input and output becomes a Real (FMI 2.0) / Float64 (FMI 3.0) variable
with the port's name, unit and description; outputs declare their direct
dependencies; numeric parameters become ``fixed`` parameters (start = the
file's value); the FMU can get/set its state.

Requirements of the exported FMU
--------------------------------
The FMU runs the component's Python code: it imports ``shevsim`` (and
NumPy/SciPy as the component needs) from the Python interpreter that executes
it - the importing process when that is Python (fmpy), otherwise the Python
the pythonfmu binary finds. **shevsim must be installed (importable) in that
Python**; a pythonfmu FMU is never self-contained. The class must live in an
importable module (not ``__main__``).
"""
from __future__ import annotations

import dataclasses
import json
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

from ..core.errors import ScenarioError
from ..core.params import load_params
from .build import build_python_fmu
from .errors import FMUError
from .slave import PARAMS_JSON, slave_script

__all__ = ["export_component", "resolve_component_class"]


def resolve_component_class(type_name_or_class: Any):
    """A component class from a class (Python API) or a registered TYPE name (never a module path)."""
    if isinstance(type_name_or_class, type):
        return type_name_or_class
    from ..components import get_component_class
    return get_component_class(str(type_name_or_class), "fmu export")


def _jsonable(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    return value


def _model_name(cls) -> str:
    base = getattr(cls, "TYPE", "") or cls.__name__
    camel = "".join(part.capitalize() for part in re.split(r"[^0-9A-Za-z]+", base) if part)
    return "Shevsim" + (camel or "Component")


def export_component(type_name_or_class: Any, params_path: str | Path | None, out_path: str | Path,
                     fmi_version: int | str = 2, model_name: str | None = None) -> Path:
    """Export a native component as a co-simulation FMU.

    Parameters
    ----------
    type_name_or_class : str or type
        Registry TYPE (``"vehicle"``) or the class.
    params_path : path or None
        TOML parameter file (``[params]`` table) of the component; None = defaults.
    out_path : path
        The ``.fmu`` to write (parent directories are created).
    fmi_version : 2 or 3
        2 -> pythonfmu (FMI 2.0), 3 -> pythonfmu3 (FMI 3.0).
    model_name : str, optional
        Model identifier (default ``Shevsim<Type>``).

    Returns
    -------
    Path of the FMU.
    """
    fmi_version = int(fmi_version)
    if fmi_version not in (2, 3):
        raise FMUError(f"fmu export: fmi_version must be 2 or 3, got {fmi_version}")
    cls = resolve_component_class(type_name_or_class)
    module = cls.__module__
    if module == "__main__" or "<" in cls.__qualname__:
        raise FMUError(f"fmu export: {cls.__qualname__} is defined in {module}; the FMU imports the class by "
                       f"module path, so it must live in an importable module")
    target = f"{module}:{cls.__qualname__}"
    params = load_params(cls.Params, params_path) if cls.Params is not None else None
    if params is None and params_path is not None:
        raise ScenarioError(f"{params_path}: component {target} takes no parameters")
    # instantiate once here: a component that cannot even be built fails now, not inside the FMU
    probe = cls("probe", params)
    ports = [v for v in probe.variables() if v.causality in ("input", "output")]
    if not ports:
        raise FMUError(f"fmu export: {target} declares no inputs or outputs")
    model = model_name or _model_name(cls)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", model):
        raise FMUError(f"fmu export: model name {model!r} must be a Python identifier")
    with tempfile.TemporaryDirectory(prefix="shevsim_export_") as tmp:
        tmp = Path(tmp)
        values: dict[str, Any] = {}
        resource_files: list[str] = []
        extra: list[Path] = []
        if params is not None:
            for f in dataclasses.fields(params):
                v = getattr(params, f.name)
                if f.name.endswith("_file") and isinstance(v, str) and v and Path(v).is_file():
                    dest = tmp / "shevsim_data" / Path(v).name
                    dest.parent.mkdir(exist_ok=True)
                    shutil.copy2(v, dest)
                    values[f.name] = f"shevsim_data/{Path(v).name}"
                    resource_files.append(f.name)
                else:
                    values[f.name] = _jsonable(v)
        if resource_files:
            extra.append(tmp / "shevsim_data")
        spec = {"component": target, "params": values, "resource_files": resource_files,
                "params_source": str(params_path) if params_path else None}
        (tmp / PARAMS_JSON).write_text(json.dumps(spec, indent=1))
        extra.append(tmp / PARAMS_JSON)
        # the slave module is imported into the executing Python by name: make the name unique
        # per (component, parameters, FMI version) so different exports never share a module
        import hashlib
        digest = hashlib.sha1(json.dumps([spec, fmi_version, model], sort_keys=True).encode()).hexdigest()[:10]
        script = tmp / f"{model.lower()}_fmi{fmi_version}_{digest}.py"
        script.write_text(slave_script(target, model, fmi_version))
        # keep the script's folder out of the project files (pythonfmu copies project files
        # into resources/); put them in a sibling folder
        proj = tmp / "project"
        proj.mkdir()
        moved = []
        for p in extra:
            dest = proj / p.name
            shutil.move(str(p), dest)
            moved.append(dest)
        return build_python_fmu(script, out_path, fmi_version=fmi_version, handle_state=True,
                                project_files=tuple(moved))
