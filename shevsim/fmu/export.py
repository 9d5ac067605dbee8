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

Self-contained: what the exported FMU carries
---------------------------------------------
The FMU runs the component's Python code in the Python that executes it (the
importing process when that is Python, e.g. fmpy; otherwise the Python the
pythonfmu binary finds). It carries in ``resources/``:

* the ``shevsim`` package source (no data folders, no caches) - and pythonfmu/pythonfmu3
  embed their own runtime modules - so neither needs to be installed;
* the parameter values and the files named by ``*_file`` parameters.

What it still needs installed are the numeric packages the component imports,
found at export time by importing the component in a clean interpreter and
intersecting the imported top-level modules with shevsim's own requirements
(typically ``numpy``, plus ``scipy`` and ``numba`` for the physics components).
They are listed in the FMU's description and checked before anything else is
imported: a missing one prints (to stderr, visible without debug logging) and
raises ``shevsim FMU ...: missing Python package(s) numba ...`` naming the
packages, the interpreter and the pip command. The class must live in an
importable module of the shevsim package or of an installed plugin package
(not ``__main__``); a plugin's own package is not bundled.
"""
from __future__ import annotations

import dataclasses
import functools
import os
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


def _bundle_sources(dest: Path) -> list[Path]:
    """Copy the shevsim package source (no caches or tests) into ``dest``, and beside it the components'
    default data tables (``components/``: the OCV and resistance tables, maps - what a component reads when no
    ``*_file`` parameter names another file; ``shevsim.core.paths.DATA_ROOT`` is the package's parent folder
    inside the FMU, ``resources/``); return the folders.  (Without them an exported battery pack failed to
    instantiate in an environment without shevsim: ``a123_26650_ocv.csv: table file not found``.)

    (pythonfmu/pythonfmu3 embed their own runtime modules in every FMU they build.)"""
    from ..core.paths import data_path
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "_data", "*.so", "*.fmu", "tests")
    pkg = Path(__file__).resolve().parents[1]
    shutil.copytree(pkg, dest / "shevsim", ignore=ignore)
    shutil.copytree(data_path("components"), dest / "components",
                    ignore=shutil.ignore_patterns("*.md", "*.py", "__pycache__"))
    return [dest / "shevsim", dest / "components"]


@functools.lru_cache(maxsize=None)
def required_packages(module: str) -> list[str]:
    """Distributions the component module needs at run time (import names, e.g. ``numpy``).

    The module is imported in a clean interpreter; the third-party top-level modules it loads are
    intersected with shevsim's own declared requirements (so optional imports of those packages,
    like numba's of PyYAML, are not required)."""
    import subprocess
    import sys
    code = ("import sys, importlib; importlib.import_module('shevsim.fmu.slave'); "
            f"importlib.import_module({module!r}); "
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))")
    from .build import python_env      # the package's root on PYTHONPATH, as for the build
    env = python_env()
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2]) + os.pathsep + env.get("PYTHONPATH", "")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    if res.returncode:
        raise FMUError(f"fmu export: importing {module} failed in a clean interpreter:\n{res.stderr[-2000:]}")
    loaded = set(res.stdout.split())
    try:
        from importlib.metadata import packages_distributions, requires
        declared = {re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0].lower() for r in (requires("shevsim") or [])
                    if "extra ==" not in r}
        dists = packages_distributions()
    except Exception:  # no metadata (source checkout not installed): the usual numeric stack
        declared, dists = {"numpy", "scipy", "numba"}, {}
    need = set()
    for top in loaded:
        for dist in dists.get(top, [top]):
            if dist.lower() in declared:
                need.add(top)
    return sorted(need)


def export_component(type_name_or_class: Any, params_path: str | Path | None, out_path: str | Path,
                     fmi_version: int | str = 2, model_name: str | None = None,
                     extra_requires: tuple[str, ...] = (), step_multiple: int = 1, params: Any = None,
                     start_values: dict[str, float] | None = None, force: bool = False) -> Path:
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
    extra_requires : tuple of str
        More import names to check for when the FMU is loaded (besides those found).
    params : Params instance, optional
        Ready parameters (instead of ``params_path``), e.g. those of a component built from a scenario.
    start_values : dict, optional
        ``{input: value}`` held by inputs until set (the FMU's input start values).
    force : bool
        Replace ``out_path`` when it exists (default: an existing file is refused, not overwritten).
    step_multiple : int
        The component steps every ``step_multiple``-th ``doStep`` over that many steps (holding its
        outputs between), as the master's multi-rate ``step_multiple`` (SSP export of a scenario).

    Returns
    -------
    Path of the FMU.
    """
    from ..core.atomic import refuse_overwrite
    refuse_overwrite(out_path, force)
    fmi_version = int(fmi_version)
    if fmi_version not in (2, 3):
        raise FMUError(f"fmu export: fmi_version must be 2 or 3, got {fmi_version}")
    cls = resolve_component_class(type_name_or_class)
    module = cls.__module__
    if module == "__main__" or "<" in cls.__qualname__:
        raise FMUError(f"fmu export: {cls.__qualname__} is defined in {module}; the FMU imports the class by "
                       f"module path, so it must live in an importable module")
    target = f"{module}:{cls.__qualname__}"
    if params is None:
        params = load_params(cls.Params, params_path) if cls.Params is not None else None
    if params is None and params_path is not None:
        raise ScenarioError(f"{params_path}: component {target} takes no parameters")
    # instantiate once here: a component that cannot even be built fails now, not inside the FMU
    _check_ports(cls, params, start_values, target)
    model = model_name or _model_name(cls)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", model):
        raise FMUError(f"fmu export: model name {model!r} must be a Python identifier")
    with tempfile.TemporaryDirectory(prefix="shevsim_export_") as tmp:
        tmp = Path(tmp)
        values, resource_files, extra = _stage_parameters(params, tmp)
        requires = sorted(set(required_packages(module)) | set(extra_requires))  # (cached per module)
        if isinstance(step_multiple, bool) or not isinstance(step_multiple, int) or step_multiple < 1:
            raise FMUError(f"fmu export: step_multiple must be an integer >= 1, got {step_multiple!r}")
        spec = {"component": target, "params": values, "resource_files": resource_files,
                "params_source": str(params_path) if params_path else None, "requires": requires,
                "step_multiple": step_multiple, "start": {k: float(v) for k, v in (start_values or {}).items()}}
        (tmp / PARAMS_JSON).write_text(json.dumps(spec, indent=1))
        extra.append(tmp / PARAMS_JSON)
        # the slave module is imported into the executing Python by name: make the name unique
        # per (component, parameters, FMI version) so different exports never share a module
        import hashlib
        digest = hashlib.sha1(json.dumps([spec, fmi_version, model], sort_keys=True).encode()).hexdigest()[:10]
        script = tmp / f"{model.lower()}_fmi{fmi_version}_{digest}.py"
        script.write_text(slave_script(target, model, fmi_version, requires))
        # keep the script's folder out of the project files (pythonfmu copies project files
        # into resources/); put them in a sibling folder
        moved = _stage_project(tmp, extra)
        return build_python_fmu(script, out_path, fmi_version=fmi_version, handle_state=True,
                                project_files=tuple(moved))


def _check_ports(cls, params, start_values, target: str) -> None:
    """Build the component once (a component that cannot be built fails here, not inside the FMU): it must
    have ports, and the start values must name its inputs."""
    probe = cls("probe", params)
    ports = [v for v in probe.variables() if v.causality in ("input", "output")]
    bad = [k for k in (start_values or {}) if k not in {v.name for v in ports if v.causality == "input"}]
    if bad:
        raise FMUError(f"fmu export: start values for unknown input(s) {bad} of {target}")
    if not ports:
        raise FMUError(f"fmu export: {target} declares no inputs or outputs")


def _stage_parameters(params, tmp: Path) -> tuple[dict[str, Any], list[str], list[Path]]:
    """The parameters as JSON values, their ``*_file`` data copied into ``tmp/shevsim_data``:
    ``(values, names of file parameters, files to bundle)``."""
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
    return values, resource_files, extra


def _stage_project(tmp: Path, extra: list[Path]) -> list[Path]:
    """Move the files to bundle into a folder beside the slave script (pythonfmu copies project files into
    ``resources/``: the script's own folder stays out), plus shevsim's sources."""
    proj = tmp / "project"
    proj.mkdir()
    moved = []
    for p in extra:
        dest = proj / p.name
        shutil.move(str(p), dest)
        moved.append(dest)
    moved += _bundle_sources(proj)
    return moved
