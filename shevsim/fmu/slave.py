"""slave.py - the runtime inside FMUs exported by :mod:`shevsim.fmu.export`.

An exported FMU is a pythonfmu (FMI 2.0) or pythonfmu3 (FMI 3.0) FMU whose
slave script is three lines: a subclass of :func:`fmi2_base` or
:func:`fmi3_base` naming the native component class (``module:Class``)
and the JSON file (in the FMU's ``resources/``) with its parameter values.
The FMU therefore imports ``shevsim`` (and numpy/scipy as the component
needs) from the Python that executes it: **shevsim must be installed in that
Python** (pythonfmu FMUs always need a Python environment).

Mapping of the native contract to FMI:

* every input/output port -> a Real/Float64 variable of the same name, with the
  port's unit (``<UnitDefinitions>``) and description; outputs list their
  direct dependencies (``depends_on``) in ``<ModelStructure>``;
* every float/int/bool parameter -> a ``parameter`` (``fixed``) variable, start
  = the value from the parameter file; changing one before initialisation
  rebuilds the component with the new parameters (checked by the
  component's ``Params`` dataclass);
* ``exitInitializationMode`` -> ``initialize(t0)``, ``doStep`` -> ``do_step``,
  ``getFMUstate``/``setFMUstate`` -> ``get_state``/``set_state``.
"""
from __future__ import annotations

import dataclasses
import importlib
import json
import math
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


def _numeric_params(params: Any) -> dict[str, float]:
    """Float/int/bool fields of a Params dataclass (those become FMU parameters)."""
    if params is None or not dataclasses.is_dataclass(params):
        return {}
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if isinstance(v, (bool, int, float)):
            out[f.name] = float(v)
    return out


class _ShevsimRuntime:
    """Shared logic of the FMI 2 and FMI 3 slaves (mixin; the pythonfmu base comes second)."""

    COMPONENT: str = ""
    PARAMS_FILE: str = PARAMS_JSON

    def _setup_component(self) -> None:
        resources = Path(self.resources) if self.resources else Path(".")
        spec = json.loads((resources / self.PARAMS_FILE).read_text())
        self._cls = import_class(spec.get("component", self.COMPONENT))
        values = dict(spec.get("params") or {})
        for key in spec.get("resource_files", []):   # *_file params shipped in resources/
            values[key] = str(resources / values[key])
        self._param_values = values
        self._param_overrides: dict[str, Any] = {}
        self._t0 = 0.0
        self._time = 0.0
        self.comp = self._make_component()
        self._numeric = _numeric_params(self.comp.params)
        self._param_types = {f.name: type(getattr(self.comp.params, f.name))
                             for f in dataclasses.fields(self.comp.params)} if self._numeric else {}

    def _make_component(self):
        cls = self._cls
        params = None
        if cls.Params is not None:
            values = {**self._param_values, **self._param_overrides}
            params = make_params(cls.Params, values, f"FMU {self.instance_name} parameters")
        comp = cls(self.instance_name, params)
        return comp

    def _set_param(self, name: str, value: float) -> None:
        typ = self._param_types.get(name, float)
        if typ is bool:
            value = bool(value)
        elif typ is int:
            value = int(round(value))
        else:
            value = float(value)
        self._param_overrides[name] = value
        self._numeric[name] = float(value)

    def _ports(self):
        vs = self.comp.variables()
        return ([v for v in vs if v.causality == "input"], [v for v in vs if v.causality == "output"])

    def _initialize(self) -> None:
        u = dict(self.comp.u)
        if self._param_overrides:
            self.comp = self._make_component()
            self.comp.u.update(u)
        self.comp.initialize(self._t0)
        self._time = self._t0

    # -- XML post-processing shared by both versions --------------------------------
    def _units_and_vars(self):
        units = {}
        inputs, outputs = self._ports()
        for v in inputs + outputs:
            u = canonical_unit(v.unit)
            if u != "1":
                units[v.name] = u
        return units


def fmi2_base():
    """The FMI 2.0 slave base class (pythonfmu ``Fmi2Slave`` + the shevsim runtime); set ``COMPONENT``."""
    from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

    class Slave2(_ShevsimRuntime, Fmi2Slave):
        author = "shevsim"

        def __init__(self, **kwargs):
            Fmi2Slave.__init__(self, **kwargs)
            self._setup_component()
            self.description = f"shevsim native component {self._cls.__module__}:{self._cls.__name__}"
            for name, val in self._numeric.items():
                self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                            variability=Fmi2Variability.fixed,
                                            getter=lambda n=name: self._numeric[n],
                                            setter=lambda v, n=name: self._set_param(n, v)))
            inputs, outputs = self._ports()
            u, y = self.comp.u, self.comp.y
            for v in inputs:
                self.register_variable(Real(v.name, causality=Fmi2Causality.input, description=v.description,
                                            getter=lambda n=v.name: self.comp.u[n],
                                            setter=lambda x, n=v.name: self.comp.u.__setitem__(n, x)))
            for v in outputs:
                self.register_variable(Real(v.name, causality=Fmi2Causality.output, description=v.description,
                                            getter=lambda n=v.name: self.comp.y[n]))

        def setup_experiment(self, start_time, stop_time=None, tolerance=None):
            self._t0 = float(start_time or 0.0)

        def exit_initialization_mode(self):
            self._initialize()

        def do_step(self, current_time, step_size):
            self.comp.do_step(current_time, step_size)
            return True

        def terminate(self):
            self.comp.terminate()

        def _get_fmu_state(self):
            return {"component": self.comp.get_state(), "overrides": dict(self._param_overrides)}

        def _set_fmu_state(self, state):
            self.comp.set_state(state["component"])

        def to_xml(self, model_options=dict()):
            root = Fmi2Slave.to_xml(self, model_options)
            units = self._units_and_vars()
            # units: <UnitDefinitions> right after <CoSimulation>, unit attribute on <Real>
            if units:
                ud = Element("UnitDefinitions")
                for name in sorted(set(units.values())):
                    SubElement(ud, "Unit", attrib={"name": name})
                root.insert(list(root).index(root.find("CoSimulation")) + 1, ud)
            index = {}
            for i, sv in enumerate(root.find("ModelVariables").findall("ScalarVariable"), start=1):
                index[sv.get("name")] = i
                if sv.get("name") in units:
                    sv.find("Real").set("unit", units[sv.get("name")])
            inputs, outputs = self._ports()
            deps = {v.name: v.depends_on for v in outputs}
            structure = root.find("ModelStructure")
            out_node = structure.find("Outputs")
            if out_node is not None:
                names = {i: n for n, i in index.items()}
                for unk in out_node.findall("Unknown"):
                    name = names[int(unk.get("index"))]
                    unk.set("dependencies", " ".join(str(index[d]) for d in deps.get(name, ())))
                init = SubElement(structure, "InitialUnknowns")
                for unk in out_node.findall("Unknown"):
                    SubElement(init, "Unknown", attrib={"index": unk.get("index")})
            return root

    return Slave2


def fmi3_base():
    """The FMI 3.0 slave base class (pythonfmu3 ``Fmi3Slave`` + the shevsim runtime); set ``COMPONENT``."""
    from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64
    from pythonfmu3.unit import Unit

    class Slave3(_ShevsimRuntime, Fmi3Slave):
        author = "shevsim"

        def __init__(self, **kwargs):
            Fmi3Slave.__init__(self, **kwargs)
            self._setup_component()
            self.description = f"shevsim native component {self._cls.__module__}:{self._cls.__name__}"
            units = self._units_and_vars()
            self.register_units([Unit(u) for u in sorted(set(units.values()) | {"s"})])
            self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                           variability=Fmi3Variability.continuous, unit="s",
                                           getter=lambda: self._time))
            for name, val in self._numeric.items():
                self.register_variable(Float64(name, causality=Fmi3Causality.parameter,
                                               variability=Fmi3Variability.fixed,
                                               getter=lambda n=name: self._numeric[n],
                                               setter=lambda v, n=name: self._set_param(n, v)))
            inputs, outputs = self._ports()
            for v in inputs:
                self.register_variable(Float64(v.name, causality=Fmi3Causality.input, description=v.description,
                                               unit=units.get(v.name),
                                               getter=lambda n=v.name: self.comp.u[n],
                                               setter=lambda x, n=v.name: self.comp.u.__setitem__(n, x)))
            for v in outputs:
                self.register_variable(Float64(v.name, causality=Fmi3Causality.output, description=v.description,
                                               unit=units.get(v.name),
                                               getter=lambda n=v.name: self.comp.y[n]))

        def enter_initialization_mode(self):
            pass

        def setup_experiment(self, start_time, *args, **kwargs):
            self._t0 = float(start_time or 0.0)

        def exit_initialization_mode(self):
            self._initialize()

        def do_step(self, current_time, step_size):
            self.comp.do_step(current_time, step_size)
            self._time = current_time + step_size
            return True

        def terminate(self):
            self.comp.terminate()

        def _get_fmu_state(self):
            return {"component": self.comp.get_state(), "time": self._time}

        def _set_fmu_state(self, state):
            self.comp.set_state(state["component"])
            self._time = state["time"]

        def to_xml(self, model_options=dict()):
            root = Fmi3Slave.to_xml(self, model_options)
            inputs, outputs = self._ports()
            vr = {v.name: v.value_reference for v in self.vars.values()}
            deps = {v.name: v.depends_on for v in outputs}
            names = {str(r): n for n, r in vr.items()}
            for node in root.find("ModelStructure").findall("Output"):
                name = names[node.get("valueReference")]
                node.set("dependencies", " ".join(str(vr[d]) for d in deps.get(name, ())))
            return root

    return Slave3
