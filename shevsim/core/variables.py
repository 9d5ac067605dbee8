"""variables.py - FMI-style variable declarations.

A component declares its interface as a tuple of :class:`Variable`. Names that
cross a boundary carry their unit as a suffix (``power_w``, ``speed_mps``,
``soc_pct``) and the unit is also declared explicitly in ``unit`` so that the
master can check connections.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

Causality = Literal["parameter", "input", "output", "local"]

# Unit aliases: every alias maps to one canonical spelling. Two ports are
# compatible when their canonical units are equal.
_UNIT_ALIASES = {
    "": "1", "-": "1", "1": "1", "frac": "1",
    "%": "%", "pct": "%",
    "w": "W", "kw": "kW", "w/s": "W/s", "kw/s": "kW/s",
    "a": "A", "v": "V", "ohm": "Ohm", "f": "F", "ah": "A.h", "a.h": "A.h",
    "degc": "degC", "k": "K", "j": "J",
    "m": "m", "s": "s", "kg": "kg", "n": "N", "nm": "N.m", "n.m": "N.m",
    "m/s": "m/s", "m/s2": "m/s2", "rad/s": "rad/s", "rpm": "rpm",
    "g/s": "g/s", "kg/s": "kg/s", "mg/s": "mg/s",
    "w/m2k": "W/(m2.K)", "w/(m2.k)": "W/(m2.K)", "w/m2/k": "W/(m2.K)",
    "rad": "rad", "km": "km", "km/h": "km/h",
}


def canonical_unit(unit: str) -> str:
    """Return the canonical spelling of ``unit`` (unknown units are kept as written)."""
    key = unit.strip().lower().replace(" ", "")
    return _UNIT_ALIASES.get(key, unit.strip())


def units_compatible(a: str, b: str) -> bool:
    """True when a signal in unit ``a`` may be connected to a port in unit ``b``."""
    return canonical_unit(a) == canonical_unit(b)


@dataclass(frozen=True, slots=True)
class Variable:
    """One declared variable of a component.

    Parameters
    ----------
    name : str
        Port name, unit suffixed (``current_a``).
    causality : {'parameter', 'input', 'output', 'local'}
    unit : str
        Unit string (``'A'``, ``'W'``, ``'degC'``, ``'1'`` for dimensionless).
    start : float
        Start value (inputs hold it while unconnected; outputs before the first step).
    description : str
        One line, including the sign convention where one applies.
    depends_on : tuple of str
        Outputs only: the inputs this output depends on *directly* (feedthrough),
        as FMI's ``<ModelStructure><Outputs><Unknown dependencies=...>``. Empty
        means the output is a function of the state only.
    """

    name: str
    causality: Causality
    unit: str
    start: float = 0.0
    description: str = ""
    depends_on: tuple[str, ...] = field(default=())


def inp(name: str, unit: str, start: float = 0.0, description: str = "") -> Variable:
    """Shorthand for an input declaration."""
    return Variable(name, "input", unit, float(start), description)


def out(name: str, unit: str, start: float = 0.0, description: str = "",
        depends_on: tuple[str, ...] = ()) -> Variable:
    """Shorthand for an output declaration (``depends_on``: direct-feedthrough inputs)."""
    return Variable(name, "output", unit, float(start), description, tuple(depends_on))
