"""One conformance harness over every registered component (cf. PyBaMM's StandardModelTest).

For each component type: declared variables are well formed (units declared, port names carry a unit
suffix that agrees with the declared unit, feedthrough refers to real inputs); default construction,
initialisation and stepping give finite outputs; get_state/set_state reproduces the continuation
exactly; the class documents itself.
"""
import math

import pytest

from shevsim.components import REGISTRY, get_component_class
from shevsim.core.variables import canonical_unit

# unit suffix of a port name -> canonical unit it must declare
SUFFIX_UNITS = {
    "w": "W", "j": "J", "a": "A", "v": "V", "ohm": "Ohm", "f": "F", "c": "degC", "k": "K", "s": "s", "m": "m",
    "mps": "m/s", "mps2": "m/s2", "kg": "kg", "n": "N", "nm": "N.m", "radps": "rad/s", "gps": "g/s",
    "mgps": "mg/s", "g": "g", "mg": "mg", "pct": "%", "frac": "1", "1": "1", "wps": "W/s", "ah": "A.h",
    "rad": "rad", "us": "us", "w_m2k": "W/(m2.K)", "m2k": "W/(m2.K)",
}
# dimensionless counters and flags may also be named plainly
PLAIN_OK = {"1"}
# ports whose name ends in a word that is not a unit suffix but whose unit is declared explicitly
EXPLICIT = {"gamma_c": "K/m", "fallback_count": "1", "clamp_count": "1"}

TYPES = sorted(REGISTRY)


def _suffix_unit(name):
    for n in (2, 1):
        parts = name.rsplit("_", n)
        if len(parts) == n + 1:
            suf = "_".join(parts[1:])
            if suf in SUFFIX_UNITS:
                return SUFFIX_UNITS[suf]
    return None


@pytest.mark.parametrize("type_name", TYPES)
def test_declared_variables_are_well_formed(type_name):
    cls = get_component_class(type_name)
    comp = cls(type_name)
    vs = comp.variables()
    names = [v.name for v in vs]
    assert len(names) == len(set(names)), "duplicate port names"
    inputs = {v.name for v in vs if v.causality == "input"}
    assert any(v.causality == "output" for v in vs)
    for v in vs:
        assert v.causality in ("parameter", "input", "output", "local")
        assert v.unit, f"{type_name}.{v.name}: no unit declared"
        if v.name in EXPLICIT:
            assert canonical_unit(v.unit) == canonical_unit(EXPLICIT[v.name])
            continue
        expected = _suffix_unit(v.name)
        assert expected is not None or canonical_unit(v.unit) in PLAIN_OK, \
            f"{type_name}.{v.name}: the name carries no unit suffix (unit '{v.unit}')"
        if expected is not None:
            assert canonical_unit(v.unit) == canonical_unit(expected), \
                f"{type_name}.{v.name}: suffix says '{expected}', declared '{v.unit}'"
        for dep in v.depends_on:
            assert dep in inputs, f"{type_name}.{v.name} depends on unknown input '{dep}'"
    assert cls.__doc__ and len(cls.__doc__.strip()) > 20, f"{type_name}: class docstring missing"


def _step_n(comp, t, h, n):
    for i in range(n):
        comp.do_step(t + i * h, h)
    return dict(comp.y)


@pytest.mark.parametrize("type_name", TYPES)
def test_default_component_steps_and_restores_exactly(type_name):
    cls = get_component_class(type_name)
    comp = cls(type_name)
    h = 0.2 if type_name in ("mpc_supervisor", "rule_supervisor") else 0.1
    comp.initialize(0.0)
    assert all(math.isfinite(x) for x in comp.y.values()), comp.y
    _step_n(comp, 0.0, h, 5)
    assert all(math.isfinite(x) for x in comp.y.values()), comp.y
    snap = comp.get_state()
    first = _step_n(comp, 5 * h, h, 5)
    comp.set_state(snap)
    again = _step_n(comp, 5 * h, h, 5)
    assert first == again
    comp.terminate()
