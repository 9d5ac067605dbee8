"""slave.py - the runtime inside FMUs exported by :mod:`shevsim.fmu.export`.

An exported FMU is a pythonfmu (FMI 2.0) or pythonfmu3 (FMI 3.0) FMU whose
slave script (:func:`slave_script`) defines one class deriving *directly and
only* from ``Fmi2Slave``/``Fmi3Slave`` whose methods delegate to a
:class:`Runtime` (pythonfmu's binary crashes on the second instantiation when
the slave class inherits from a class defined in another module, so no
shared base class is used). The runtime reads the component class
(``module:Class``) and its parameter values from a JSON file in the FMU's
``resources/``.
The FMU carries the ``shevsim`` source in ``resources/shevsim`` (first on
``sys.path`` when pythonfmu loads the slave; a process that already imported
shevsim keeps its own), so the Python that executes it needs only the
packages listed in the slave's ``REQUIRES`` (numpy, and scipy/numba for the
physics components); a missing one is named on stderr and in the ImportError
before anything else is imported.

Mapping of the native contract to FMI:

* every input/output port -> a Real/Float64 variable of the same name, with the
  port's unit (``<UnitDefinitions>``) and description; outputs list their
  direct dependencies (``depends_on``) in ``<ModelStructure>``;
* every float/int/bool parameter -> a ``parameter`` (``fixed``) variable, start
  = the value from the parameter file; changing one before initialisation
  rebuilds the component with the new parameters (checked by the
  component's ``Params`` dataclass);
* ``exitInitializationMode`` -> ``initialize(t0)``, ``doStep`` -> ``do_step``,
  ``getFMUstate``/``setFMUstate`` -> ``get_state``/``set_state``;
* a parameter named like a port, and non-finite parameter values, stay inside
  (FMI names are unique; xs:double has no inf/nan);
* ``step_multiple`` (SSP export of a multi-rate scenario): the component steps
  over ``k`` calls every ``k``-th ``doStep`` and holds its outputs between.
"""
from __future__ import annotations

import dataclasses
import importlib
import math
import json
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

from ..core.params import make_params
from ..core.variables import canonical_unit

PARAMS_JSON = "shevsim_component.json"


def import_class(target: str):
    """``'package.module:Class'`` -> the class."""
    mod, _, cls = target.partition(":")
    return getattr(importlib.import_module(mod), cls)


# unit of a parameter from its name suffix (DEVELOPING.md conventions); longest suffix first
_SUFFIX_UNITS = (("_w_m2k", "W/(m2.K)"), ("_j_kgk", "J/(kg.K)"), ("_w_mk", "W/(m.K)"), ("_kg_m3", "kg/m3"),
                 ("_mps2", "m/s2"), ("_radps", "rad/s"), ("_mgps", "mg/s"), ("_gps", "g/s"), ("_wps", "W/s"),
                 ("_mps", "m/s"), ("_ohm", "Ohm"), ("_pct", "%"), ("_ah", "A.h"), ("_kg", "kg"), ("_nm", "N.m"),
                 ("_w", "W"), ("_j", "J"), ("_a", "A"), ("_v", "V"), ("_f", "F"), ("_c", "degC"), ("_k", "K"),
                 ("_s", "s"), ("_m", "m"), ("_n", "N"), ("_g", "g"))


def suffix_unit(name: str) -> str | None:
    """Unit implied by a unit-suffixed name (``capacity_ah`` -> ``A.h``), else None."""
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return None


def _numeric_params(params: Any) -> dict[str, float]:
    """Float/int/bool fields of a Params dataclass (those become FMU parameters)."""
    if params is None or not dataclasses.is_dataclass(params):
        return {}
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if isinstance(v, (bool, int, float)) and math.isfinite(v):   # (xs:double has no inf/nan spelling)
            out[f.name] = float(v)
    return out


class Runtime:
    """Native component behind a pythonfmu/pythonfmu3 slave (``fmi`` = 2 or 3)."""

    def __init__(self, slave, fmi: int):
        self.slave = slave
        self.fmi = fmi
        resources = Path(slave.resources) if slave.resources else Path(".")
        spec = json.loads((resources / PARAMS_JSON).read_text())
        self.cls = import_class(spec["component"])
        values = dict(spec.get("params") or {})
        for key in spec.get("resource_files", []):   # *_file params shipped in resources/
            values[key] = str(resources / values[key])
        self.param_values = values
        self.step_multiple = int(spec.get("step_multiple", 1))
        self.calls = 0
        self.overrides: dict[str, Any] = {}
        self.t0 = 0.0
        self.time = 0.0
        self.start = {k: float(v) for k, v in (spec.get("start") or {}).items()}
        self.comp = self.make_component()
        self.comp.u.update(self.start)
        self.numeric = _numeric_params(self.comp.params)
        self.param_types = ({f.name: type(getattr(self.comp.params, f.name))
                             for f in dataclasses.fields(self.comp.params)} if self.numeric else {})
        slave.description = (f"shevsim native component {spec['component']} (Python; needs the packages "
                             f"{', '.join(spec.get('requires') or []) or 'none'})")
        vs = self.comp.variables()
        self.inputs = [v for v in vs if v.causality == "input"]
        self.outputs = [v for v in vs if v.causality == "output"]
        self.units = {v.name: canonical_unit(v.unit) for v in self.inputs + self.outputs
                      if canonical_unit(v.unit) != "1"}
        ports = {v.name for v in self.inputs + self.outputs}
        # a parameter named like a port (the bus's aux_power_w) stays inside: FMI names are unique
        self.numeric = {k: v for k, v in self.numeric.items() if k not in ports}
        for name in self.numeric:
            if suffix_unit(name):
                self.units[name] = suffix_unit(name)
        self._register()

    # -- component ------------------------------------------------------------------
    def make_component(self):
        cls = self.cls
        params = None
        if cls.Params is not None:
            params = make_params(cls.Params, {**self.param_values, **self.overrides},
                                 f"FMU {self.slave.instance_name} parameters")
        return cls(self.slave.instance_name, params)

    def set_param(self, name: str, value: float) -> None:
        typ = self.param_types.get(name, float)
        value = bool(value) if typ is bool else int(round(value)) if typ is int else float(value)
        self.overrides[name] = value
        self.numeric[name] = float(value)

    def get_u(self, name):
        return self.comp.u[name]

    def set_u(self, name, value):
        self.comp.u[name] = value

    def get_y(self, name):
        return self.comp.y[name]

    # -- FMI entry points -------------------------------------------------------------
    def setup_experiment(self, start_time) -> None:
        self.t0 = float(start_time or 0.0)

    def initialize(self) -> None:
        if self.overrides:
            u = dict(self.comp.u)
            self.comp = self.make_component()
            self.comp.u.update(u)
        self.comp.initialize(self.t0)
        self.time = self.t0
        self.calls = 0

    def do_step(self, t, h) -> bool:
        m = self.step_multiple
        if m == 1:
            self.comp.do_step(t, h)
        elif self.calls % m == 0:        # multi-rate: step over m calls at once, hold the outputs between
            self.comp.do_step(t, m * h)
        self.calls += 1
        self.time = t + h
        return True

    def terminate(self) -> None:
        self.comp.terminate()

    def get_state(self):
        return {"component": self.comp.get_state(), "time": self.time, "calls": self.calls}

    def set_state(self, state) -> None:
        self.comp.set_state(state["component"])
        self.time = state["time"]
        self.calls = state.get("calls", 0)

    # -- variables --------------------------------------------------------------------
    def _register(self) -> None:
        sl = self.slave

        def unit(n):
            return {} if self.fmi == 2 else {"unit": self.units.get(n)}

        if self.fmi == 2:
            from pythonfmu import Fmi2Causality as C, Fmi2Variability as V, Real as F
        else:
            from pythonfmu3 import Fmi3Causality as C, Fmi3Variability as V, Float64 as F
            from pythonfmu3.unit import Unit
            sl.register_units([Unit(u) for u in sorted(set(self.units.values()) | {"s"})])
            sl.register_variable(F("time", causality=C.independent, variability=V.continuous, unit="s",
                                   getter=lambda: self.time))
        for name in self.numeric:
            sl.register_variable(F(name, causality=C.parameter, variability=V.fixed, **unit(name),
                                   getter=lambda n=name: self.numeric[n],
                                   setter=lambda v, n=name: self.set_param(n, v)))

        for v in self.inputs:
            sl.register_variable(F(v.name, causality=C.input, description=v.description, **unit(v.name),
                                   getter=lambda n=v.name: self.get_u(n),
                                   setter=lambda x, n=v.name: self.set_u(n, x)))
        for v in self.outputs:
            sl.register_variable(F(v.name, causality=C.output, description=v.description, **unit(v.name),
                                   getter=lambda n=v.name: self.get_y(n)))

    def fix_xml(self, root):
        """Add what pythonfmu does not write: units (FMI 2), dependencies, InitialUnknowns (FMI 2)."""
        deps = {v.name: v.depends_on for v in self.outputs}
        structure = root.find("ModelStructure")
        if self.fmi == 3:
            vr = {v.name: v.value_reference for v in self.slave.vars.values()}
            names = {str(r): n for n, r in vr.items()}
            for node in structure.findall("Output"):
                node.set("dependencies", " ".join(str(vr[d]) for d in deps.get(names[node.get("valueReference")], ())))
            return root
        if self.units:
            ud = Element("UnitDefinitions")
            for name in sorted(set(self.units.values())):
                SubElement(ud, "Unit", attrib={"name": name})
            root.insert(list(root).index(root.find("CoSimulation")) + 1, ud)
        index = {}
        for i, sv in enumerate(root.find("ModelVariables").findall("ScalarVariable"), start=1):
            index[sv.get("name")] = i
            if sv.get("name") in self.units:
                sv.find("Real").set("unit", self.units[sv.get("name")])
        out_node = structure.find("Outputs")
        if out_node is not None:
            names = {i: n for n, i in index.items()}
            for unk in out_node.findall("Unknown"):
                unk.set("dependencies", " ".join(str(index[d]) for d in deps.get(names[int(unk.get("index"))], ())))
            init = SubElement(structure, "InitialUnknowns")
            for unk in out_node.findall("Unknown"):
                SubElement(init, "Unknown", attrib={"index": unk.get("index")})
        return root


_TEMPLATE = '''"""FMU slave generated by shevsim.fmu.export for {target}.

Runs the native shevsim component. The FMU carries the shevsim and {pkg} sources in resources/
(first on sys.path); the executing Python needs only the packages listed in REQUIRES.
"""
import importlib.util as _ilu
import os as _os
import sys as _sys

REQUIRES = {requires!r}
_missing = [_m for _m in REQUIRES if _ilu.find_spec(_m) is None]
if _missing and not _os.environ.get("SHEVSIM_FMU_BUILD"):   # (the build imports this script too)
    _msg = ("shevsim FMU {model}: missing Python package(s) " + ", ".join(_missing) + " in the Python that "
            "runs this FMU (" + str(_sys.executable) + "); install with: " + str(_sys.executable) +
            " -m pip install " + " ".join(_missing))
    _sys.stderr.write(_msg + "\\n")
    _sys.stderr.flush()
    raise ImportError(_msg)

from {pkg} import {base}
from shevsim.fmu.slave import Runtime


class {model}({base}):
    author = "shevsim"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._rt = Runtime(self, {fmi})

    def setup_experiment(self, start_time, *args, **kwargs):
        self._rt.setup_experiment(start_time)

    def exit_initialization_mode(self):
        self._rt.initialize()

    def do_step(self, current_time, step_size):
        return self._rt.do_step(current_time, step_size)

    def terminate(self):
        self._rt.terminate()

    def _get_fmu_state(self):
        return self._rt.get_state()

    def _set_fmu_state(self, state):
        self._rt.set_state(state)

    def to_xml(self, model_options=dict()):
        return self._rt.fix_xml(super().to_xml(model_options))
'''


def slave_script(target: str, model: str, fmi: int, requires: list[str] | tuple[str, ...] = ()) -> str:
    """Source of the pythonfmu (``fmi=2``) / pythonfmu3 (``fmi=3``) slave script for ``target``.

    ``requires``: import names checked first; a missing one is named on stderr and in the ImportError."""
    pkg, base = ("pythonfmu", "Fmi2Slave") if fmi == 2 else ("pythonfmu3", "Fmi3Slave")
    return _TEMPLATE.format(target=target, model=model, fmi=fmi, pkg=pkg, base=base, requires=list(requires))
