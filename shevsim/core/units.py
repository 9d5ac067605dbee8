"""units.py - unit conversion on connections (factor and offset), resolved once when a system is built.

A unit is resolved to ``(dimension, factor, offset)`` with ``value_SI = factor * value + offset``
(the FMI ``<BaseUnit>`` convention), from, in this order:

1. the unit definitions of the component that declares the port (an FMU's ``<UnitDefinitions>``,
   exposed by :class:`~shevsim.fmu.adapter.FMUComponent` as ``unit_definitions``);
2. shevsim's own table (:data:`UNITS`: W/kW, degC/K, km/h/m/s, rpm/rad/s, A.h, ...).

Two ports may be connected when their units have the same dimension (exponents of kg, m, s, A,
K, mol, cd, rad); the connection then carries ``a * value + b`` with ``a = f_src / f_dst`` and
``b = (o_src - o_dst) / f_dst``. Equal spellings (after :func:`~shevsim.core.variables.canonical_unit`)
connect without conversion even when unknown; anything else that cannot be resolved, or that has
another dimension, is an error naming both ports. ``%`` is its own dimension (a dimensionless
FMU port with no unit is ``1``, and must not silently become a percentage).

:func:`link_source` gives the master the object a connection reads from: the source's ``y`` dict
itself (no conversion: nothing changes in the step loop), or a small read-only view applying
``a * y[port] + b`` (only converted connections pay a multiply-add per step).
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from .errors import ConnectionError_
from .variables import canonical_unit

__all__ = ["UNITS", "resolve_unit", "conversion", "convertible", "link_source", "ScaledOutputs"]

_DIMS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad", "pct")


def _d(**exps: int) -> tuple[int, ...]:
    return tuple(int(exps.get(k, 0)) for k in _DIMS)


_NONE = _d()
_W = _d(kg=1, m=2, s=-3)
_J = _d(kg=1, m=2, s=-2)
_MPS = _d(m=1, s=-1)
_RADPS = _d(rad=1, s=-1)

#: shevsim's own units: name -> (dimension exponents over kg, m, s, A, K, mol, cd, rad, pct; factor; offset)
UNITS: dict[str, tuple[tuple[int, ...], float, float]] = {
    "1": (_NONE, 1.0, 0.0),
    "%": (_d(pct=1), 1.0, 0.0),
    "W": (_W, 1.0, 0.0), "kW": (_W, 1e3, 0.0), "MW": (_W, 1e6, 0.0), "mW": (_W, 1e-3, 0.0),
    "W/s": (_d(kg=1, m=2, s=-4), 1.0, 0.0), "kW/s": (_d(kg=1, m=2, s=-4), 1e3, 0.0),
    "J": (_J, 1.0, 0.0), "kJ": (_J, 1e3, 0.0), "MJ": (_J, 1e6, 0.0), "Wh": (_J, 3600.0, 0.0),
    "kWh": (_J, 3.6e6, 0.0), "W.h": (_J, 3600.0, 0.0), "kW.h": (_J, 3.6e6, 0.0),
    "A": (_d(A=1), 1.0, 0.0), "mA": (_d(A=1), 1e-3, 0.0), "kA": (_d(A=1), 1e3, 0.0),
    "V": (_d(kg=1, m=2, s=-3, A=-1), 1.0, 0.0), "mV": (_d(kg=1, m=2, s=-3, A=-1), 1e-3, 0.0),
    "kV": (_d(kg=1, m=2, s=-3, A=-1), 1e3, 0.0),
    "Ohm": (_d(kg=1, m=2, s=-3, A=-2), 1.0, 0.0), "mOhm": (_d(kg=1, m=2, s=-3, A=-2), 1e-3, 0.0),
    "F": (_d(kg=-1, m=-2, s=4, A=2), 1.0, 0.0),
    "C": (_d(A=1, s=1), 1.0, 0.0), "A.h": (_d(A=1, s=1), 3600.0, 0.0), "mA.h": (_d(A=1, s=1), 3.6, 0.0),
    "K": (_d(K=1), 1.0, 0.0), "degC": (_d(K=1), 1.0, 273.15),
    "degF": (_d(K=1), 5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0),
    "m": (_d(m=1), 1.0, 0.0), "km": (_d(m=1), 1e3, 0.0), "mm": (_d(m=1), 1e-3, 0.0), "cm": (_d(m=1), 1e-2, 0.0),
    "s": (_d(s=1), 1.0, 0.0), "ms": (_d(s=1), 1e-3, 0.0), "min": (_d(s=1), 60.0, 0.0), "h": (_d(s=1), 3600.0, 0.0),
    "kg": (_d(kg=1), 1.0, 0.0), "g": (_d(kg=1), 1e-3, 0.0), "t": (_d(kg=1), 1e3, 0.0),
    "N": (_d(kg=1, m=1, s=-2), 1.0, 0.0), "kN": (_d(kg=1, m=1, s=-2), 1e3, 0.0),
    "N.m": (_d(kg=1, m=2, s=-2), 1.0, 0.0), "kN.m": (_d(kg=1, m=2, s=-2), 1e3, 0.0),
    "m/s": (_MPS, 1.0, 0.0), "km/h": (_MPS, 1.0 / 3.6, 0.0), "mph": (_MPS, 0.44704, 0.0),
    "m/s2": (_d(m=1, s=-2), 1.0, 0.0),
    "rad": (_d(rad=1), 1.0, 0.0), "deg": (_d(rad=1), math.pi / 180.0, 0.0),
    "rad/s": (_RADPS, 1.0, 0.0), "rpm": (_RADPS, 2.0 * math.pi / 60.0, 0.0),
    "1/min": (_RADPS, 2.0 * math.pi / 60.0, 0.0), "deg/s": (_RADPS, math.pi / 180.0, 0.0),
    "g/s": (_d(kg=1, s=-1), 1e-3, 0.0), "kg/s": (_d(kg=1, s=-1), 1.0, 0.0), "mg/s": (_d(kg=1, s=-1), 1e-6, 0.0),
    "kg/h": (_d(kg=1, s=-1), 1.0 / 3600.0, 0.0), "g/h": (_d(kg=1, s=-1), 1e-3 / 3600.0, 0.0),
    "Pa": (_d(kg=1, m=-1, s=-2), 1.0, 0.0), "kPa": (_d(kg=1, m=-1, s=-2), 1e3, 0.0),
    "bar": (_d(kg=1, m=-1, s=-2), 1e5, 0.0),
    "W/(m2.K)": (_d(kg=1, s=-3, K=-1), 1.0, 0.0), "J/K": (_d(kg=1, m=2, s=-2, K=-1), 1.0, 0.0),
    "K/W": (_d(kg=-1, m=-2, s=3, K=1), 1.0, 0.0), "J/(kg.K)": (_d(m=2, s=-2, K=-1), 1.0, 0.0),
    "W/(m.K)": (_d(kg=1, m=1, s=-3, K=-1), 1.0, 0.0), "kg/m3": (_d(kg=1, m=-3), 1.0, 0.0),
}
UNITS.update({"Hz": (_d(s=-1), 1.0, 0.0), "1/s": (_d(s=-1), 1.0, 0.0)})
#: other spellings of the same units met in FMUs and spreadsheets. Case is never folded in general:
#: it carries the SI prefix (mS is millisiemens, Ms megasecond; H henry, T tesla, Mm megametre).
ALIASES: dict[str, str] = {
    "ohm": "Ohm", "Ω": "Ohm", "mohm": "mOhm", "mΩ": "mOhm", "Ah": "A.h", "mAh": "mA.h",
    "Nm": "N.m", "N*m": "N.m", "kNm": "kN.m", "Wh": "Wh", "W*h": "W.h", "kW*h": "kW.h",
    "kmh": "km/h", "kph": "km/h", "km/hr": "km/h", "RPM": "rpm", "r/min": "rpm", "rev/min": "rpm",
    "°C": "degC", "°F": "degF", "deg_C": "degC", "m/s^2": "m/s2", "m/s/s": "m/s2", "hr": "h",
    "sec": "s", "W/m2K": "W/(m2.K)", "W/(m^2.K)": "W/(m2.K)", "J/kgK": "J/(kg.K)", "W/mK": "W/(m.K)",
    "kg/m^3": "kg/m3",
}


def _from_definition(defn) -> tuple[tuple[int, ...], float, float] | None:
    """(dims, factor, offset) of an fmpy ``Unit`` (FMI ``<Unit><BaseUnit .../></Unit>``)."""
    bu = getattr(defn, "baseUnit", None)
    if bu is None:
        return None
    exps = {k: int(getattr(bu, k, 0) or 0) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")}
    factor = float(getattr(bu, "factor", 1.0) or 1.0)
    offset = float(getattr(bu, "offset", 0.0) or 0.0)
    return _d(**exps), factor, offset


def resolve_unit(unit: str, definitions: Mapping[str, Any] | None = None):
    """``(dims, factor, offset)`` of ``unit`` or None when unknown (see the module docstring)."""
    unit = (unit or "").strip()
    if definitions and unit in definitions:
        got = _from_definition(definitions[unit])
        if got is not None:
            return got
    for key in (unit, canonical_unit(unit)):
        if key in UNITS:
            return UNITS[key]
    alias = ALIASES.get(unit.replace(" ", ""))
    if alias is not None:
        return UNITS[alias]
    return None


def conversion(src_unit: str, dst_unit: str, src_defs: Mapping | None = None,
               dst_defs: Mapping | None = None) -> tuple[float, float] | None:
    """``(a, b)`` with ``dst = a * src + b``; None when no conversion is needed.

    Raises ValueError when the units cannot be connected (unknown or of another dimension).
    """
    if canonical_unit(src_unit) == canonical_unit(dst_unit) and not (src_defs or dst_defs):
        return None
    rs, rd = resolve_unit(src_unit, src_defs), resolve_unit(dst_unit, dst_defs)
    if rs is None or rd is None:
        if canonical_unit(src_unit) == canonical_unit(dst_unit):
            return None
        unknown = src_unit if rs is None else dst_unit
        raise ValueError(f"unit '{unknown}' is unknown (no unit definition and not in shevsim's table), so "
                         f"'{src_unit}' cannot be converted to '{dst_unit}'")
    if rs[0] != rd[0]:
        raise ValueError(f"'{src_unit}' and '{dst_unit}' are of different dimensions")
    a = rs[1] / rd[1]
    b = (rs[2] - rd[2]) / rd[1]
    if abs(a - 1.0) <= 1e-15 and b == 0.0:
        return None
    return a, b


def convertible(src_unit: str, dst_unit: str, defs: Mapping | None = None) -> bool:
    """True when a ``src_unit`` value can be connected to a ``dst_unit`` port (same dimension)."""
    try:
        conversion(src_unit, dst_unit, defs, defs)
        return True
    except ValueError:
        return False


class ScaledOutputs:
    """Read-only view of a component's outputs converted to the destination unit: ``a * y[k] + b``."""

    __slots__ = ("y", "a", "b")

    def __init__(self, y: dict, a: float, b: float):
        self.y, self.a, self.b = y, a, b

    def __getitem__(self, key):
        return self.a * self.y[key] + self.b

    def __repr__(self) -> str:
        return f"ScaledOutputs(a={self.a!r}, b={self.b!r})"


def _defs(component) -> Mapping | None:
    return getattr(component, "unit_definitions", None) or None


def check_connection(src_comp, src_unit: str, dst_comp, dst_unit: str, ctx: str) -> tuple[float, float] | None:
    """The conversion of one connection, or :class:`ConnectionError_` naming both ports."""
    try:
        return conversion(src_unit, dst_unit, _defs(src_comp), _defs(dst_comp))
    except ValueError as exc:
        raise ConnectionError_(f"{ctx}: unit mismatch, output in '{src_unit}' but input expects '{dst_unit}': "
                               f"{exc}") from None


def link_source(src_comp, src_unit: str, dst_comp, dst_unit: str, ctx: str = "connection"):
    """What the master's link reads from: ``src_comp.y`` itself, or a :class:`ScaledOutputs` view."""
    conv = check_connection(src_comp, src_unit, dst_comp, dst_unit, ctx)
    return src_comp.y if conv is None else ScaledOutputs(src_comp.y, *conv)
