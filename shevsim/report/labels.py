"""labels.py - plain-language names and display units for signals, metrics and channels.

Inside shevsim everything is SI with the unit in the name (``bus.battery_power_w``, ``vehicle.speed_mps``).
People read kW, km/h and degrees C: [`display_unit()`][shevsim.report.labels.display_unit] gives the unit a value is shown in and the factor
from SI, [`signal_label()`][shevsim.report.labels.signal_label] a plain-language name (``"Battery power (+ discharge)"``) and, where the
thesis (Kim 2014) has one, its symbol (``"P_b"``) for a tooltip or a legend note only.
"""
from __future__ import annotations

import math
import re

#: SI unit string (as in ``Result.units``) -> (display unit, factor, offset): shown = SI * factor + offset
DISPLAY_UNITS: dict[str, tuple[str, float, float]] = {
    "W": ("kW", 1e-3, 0.0),
    "W/s": ("kW/s", 1e-3, 0.0),
    "m/s": ("km/h", 3.6, 0.0),
    "J": ("kWh", 1.0 / 3.6e6, 0.0),
    "rad/s": ("rpm", 60.0 / (2.0 * math.pi), 0.0),
    "K": ("°C", 1.0, -273.15),
    "degC": ("°C", 1.0, 0.0),
    "m/s2": ("m/s²", 1.0, 0.0),
    "N.m": ("N·m", 1.0, 0.0),
    "A.h": ("Ah", 1.0, 0.0),
    "W/(m2.K)": ("W/(m²·K)", 1.0, 0.0),
    "K/m": ("K/m", 1.0, 0.0),
    "1": ("-", 1.0, 0.0),
    "": ("-", 1.0, 0.0),
}

#: the unit suffixes of names (longest first when matched) -> SI unit string
SUFFIX_UNITS: dict[str, str] = {
    "g_per_km": "g/km", "kg_per_l": "kg/l", "l_per_100km": "l/100 km", "g_per_kg": "g/kg", "j_per_g": "J/g", "kmpl": "km/l", "kmh": "km/h", "mps2": "m/s2", "mps": "m/s", "wps": "W/s",
    "radps": "rad/s", "mgps": "mg/s", "gps": "g/s", "w_m2k": "W/(m2.K)", "pct": "%", "frac": "-",
    "kwh": "kWh", "kw": "kW", "ah": "A.h", "nm": "N.m", "ohm": "Ohm", "kg": "kg", "km": "km", "mg": "mg",
    "w": "W", "j": "J", "s": "s", "a": "A", "v": "V", "c": "degC", "n": "N", "m": "m", "g": "g", "f": "F",
    "rad": "rad", "count": "-", "1": "-",
}
_SUFFIXES = sorted(SUFFIX_UNITS, key=len, reverse=True)

#: plain-language names of the standard signals: name -> (label, thesis symbol or None)
SIGNALS: dict[str, tuple[str, str | None]] = {
    "cycle.speed_ref_mps": ("Reference speed (drive cycle)", "v_ref"),
    "vehicle.speed_mps": ("Vehicle speed", "v"),
    "vehicle.accel_mps2": ("Vehicle acceleration", "a"),
    "vehicle.distance_m": ("Distance travelled", "s"),
    "bus.demand_power_w": ("Power demanded at the bus", "P_dem"),
    "engine_generator.elec_power_w": ("Engine-generator power", "P_g"),
    "bus.battery_power_w": ("Battery power (+ discharge)", "P_b"),
    "bms.power_max_w": ("Battery discharge limit (BMS)", "P_b,max"),
    "bms.power_min_w": ("Battery charge limit (BMS)", "P_b,min"),
    "battery.soc_pct": ("State of charge", "SOC"),
    "bms.soc_pct": ("State of charge, BMS estimate", "SOC (estimated)"),
    "engine_generator.engine_power_w": ("Engine power", "P_e"),
    "supervisor.power_cmd_w": ("Engine-generator power command", "P_g,cmd"),
    "__rate__engine_generator.elec_power_w": ("Engine-generator power rate", "dP_g/dt"),
    "supervisor.power_rate_max_wps": ("Allowed power rate (supervisor)", "dP_g/dt max"),
    "engine_generator.soot_rate_mgps": ("Soot emission rate", "soot rate"),
    "engine_generator.fuel_rate_gps": ("Fuel rate", "m_f dot"),
    "engine_generator.engine_speed_radps": ("Engine speed", "omega_e"),
    "battery.current_a": ("Battery current (+ discharge)", "I_b"),
    "battery.voltage_v": ("Battery voltage", "V_b"),
    "battery.t_core_c": ("Cell core temperature", "T_c"),
    "battery.t_surface_c": ("Cell surface temperature", "T_s"),
    "bms.t_core_c": ("Cell core temperature, BMS estimate", "T_c (estimated)"),
    "motor.elec_power_w": ("Motor electric power", "P_m"),
    "motor.torque_nm": ("Motor torque", "T_m"),
}

#: metric key -> plain label (unit from the suffix); keys not listed are prettified
METRICS: dict[str, str] = {
    "fuel_economy_raw_kmpl": "Fuel economy (raw)",
    "fuel_economy_kmpl": "Fuel economy",
    "fuel_economy_dsoc_corrected_kmpl": "Fuel economy, corrected for the SOC change",
    "fuel_economy_soc_sustained_kmpl": "Fuel economy over SOC-sustained windows",
    "soot_g_per_km": "Soot per distance",
    "soot_dsoc_corrected_g_per_km": "Soot per distance, corrected for the SOC change",
    "soot_mass_g": "Soot mass",
    "fuel_mass_g": "Fuel used",
    "fuel_equivalent_g": "Fuel equivalent of the SOC change",
    "distance_km": "Distance",
    "duration_s": "Duration",
    "delta_soc_pct": "SOC change (end - start)",
    "soc_start_pct": "SOC at start",
    "speed_miss_rms_kmh": "Speed-trace miss, RMS",
    "speed_miss_max_kmh": "Speed-trace miss, largest",
    "cell_current_rms_a": "Cell current, RMS",
    "cell_current_max_abs_a": "Cell current, largest magnitude",
    "energy_closure_error_frac": "Energy balance closure error",
    "soc_end_pct": "SOC at end",
    "soc_min_pct": "SOC, lowest",
    "soc_max_pct": "SOC, highest",
    "wall_s": "Wall-clock time of the run",
    "fuel_consumption_dsoc_corrected_l_per_100km": "Fuel consumption, corrected for the SOC change",
    "eg_elec_energy_per_fuel_j_per_g": "Engine-generator electric energy per fuel mass",
    "battery_net_energy_j": "Battery net energy (+ delivered)",
}

#: the metrics shown first (the rest in a collapsed table)
HEADLINE = ("distance_km", "duration_s", "fuel_mass_g", "fuel_economy_raw_kmpl", "fuel_economy_dsoc_corrected_kmpl",
            "soot_g_per_km", "soot_dsoc_corrected_g_per_km", "soc_start_pct", "soc_end_pct", "delta_soc_pct",
            "speed_miss_rms_kmh", "speed_miss_max_kmh", "cell_current_rms_a", "energy_closure_error_frac")


def split_unit(name: str) -> tuple[str, str]:
    """``"battery_power_w"`` -> (``"battery_power"``, ``"W"``); no known suffix: (name, "")."""
    for suf in _SUFFIXES:
        if name.endswith("_" + suf) and len(name) > len(suf) + 1:
            return name[: -len(suf) - 1], SUFFIX_UNITS[suf]
    return name, ""


def display_unit(unit: str) -> tuple[str, float, float]:
    """(display unit, factor, offset) for an SI unit string: shown = value * factor + offset."""
    if unit in DISPLAY_UNITS:
        return DISPLAY_UNITS[unit]
    return unit, 1.0, 0.0


def to_display(values, unit: str):
    """Values in their display unit, and that unit: ``to_display(p_w, "W") -> (p_w / 1e3, "kW")``."""
    import numpy as np
    du, f, o = display_unit(unit)
    return np.asarray(values, dtype=float) * f + o, du


_WORDS = {"soc": "SOC", "bms": "BMS", "rms": "RMS", "eg": "engine-generator", "ah": "Ah", "ocv": "OCV",
          "mpc": "MPC", "fmu": "FMU", "dsoc": "SOC-change", "n": "number of", "abs": "magnitude"}


def _pretty(stem: str) -> str:
    words = [_WORDS.get(w, w) for w in stem.replace("__", "_").strip("_").split("_") if w]
    text = " ".join(words)
    return text[:1].upper() + text[1:]


def signal_label(name: str) -> tuple[str, str | None]:
    """(plain-language label without the unit, thesis symbol or None) of ``component.port``."""
    if name in SIGNALS:
        return SIGNALS[name]
    comp, _, port = name.partition(".")
    stem, _ = split_unit(port or comp)
    if not port:
        return _pretty(stem), None
    return f"{_pretty(comp)}: {_pretty(stem).lower()}", None


def signal_unit(name: str, units: dict | None = None) -> str:
    """The SI unit of a signal: from ``units`` when given, else from its name's suffix."""
    if units and name in units:
        return units[name]
    return split_unit(name.rpartition(".")[2])[1]


def metric_label(key: str) -> tuple[str, str]:
    """(plain label, display unit) of a metric key (``"fuel_economy_raw_kmpl"`` -> ("Fuel economy (raw)",
    "km/l")). Values are shown in the unit of the key (metrics are already in engineering units)."""
    stem, unit = split_unit(key)
    label = METRICS.get(key) or _pretty(stem)
    return label, ("" if unit == "-" else unit)


def fmt(x, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; anything else as text; None as an em dash."""
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, float)):
        if isinstance(x, float) and not math.isfinite(x):
            return str(x)
        if isinstance(x, int):
            return str(x)
        return f"{x:.{digits}g}"
    return str(x)


_TAG = re.compile(r"[^a-z0-9]+")


def slug(text: str) -> str:
    """An HTML id from a text."""
    return _TAG.sub("-", str(text).lower()).strip("-") or "x"
