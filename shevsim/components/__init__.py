"""Native co-simulation components, found by their scenario ``type`` name.

The registry maps a type name to ``"module:Class"`` and imports lazily, so a
scenario only pays for the components it uses.  Plugins add types through the entry-point group
``shevsim.components``; a scenario names a type, never a module path.
"""
from __future__ import annotations

import difflib
import importlib

from ..core.errors import ScenarioError

REGISTRY: dict[str, str] = {
    "cycle": "shevsim.components.cycle:CycleSource",
    "profile": "shevsim.components.profile:ProfileSource",
    "driver": "shevsim.components.driver:Driver",
    "vehicle": "shevsim.components.vehicle:Vehicle",
    "motor": "shevsim.components.motor:Motor",
    "bus": "shevsim.components.bus:PowerBus",
    "power_limits": "shevsim.components.bus:PowerLimits",
    "engine_generator": "shevsim.components.engine_generator:EngineGenerator",
    "battery": "shevsim.components.battery:BatteryPack",
    "bms": "shevsim.components.bms:BMS",
    "rule_supervisor": "shevsim.components.supervisors:RuleSupervisor",
    "mpc_supervisor": "shevsim.components.supervisors:MPCSupervisor",
    # test/verification components
    "mass_spring": "shevsim.components.verification:MassSpring",
    "spring_damper": "shevsim.components.verification:SpringDamper",
    "trivial": "shevsim.components.verification:Trivial",
    "gain": "shevsim.components.verification:Gain",
}


ENTRY_POINT_GROUP = "shevsim.components"


def _plugins() -> dict:
    """Component types declared by installed packages as entry points (group ``shevsim.components``,
    ``name = "package.module:Class"``); loaded only when a scenario names one."""
    from importlib.metadata import entry_points
    try:
        return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    except Exception:  # pragma: no cover - a broken installation must not break the built-in types
        return {}


def is_registered(type_name: str) -> bool:
    """True when ``type_name`` is a component type: the package's own registry first, the installed plugins
    (entry points, ~10 ms to list) only for a name the registry does not have."""
    return type_name in REGISTRY or type_name in _plugins()


def registered_types() -> list[str]:
    """Names of every component type: the package's own and the installed plugins'."""
    return sorted(set(REGISTRY) | set(_plugins()))


def get_component_class(type_name: str, where: str = "scenario"):
    """Return the component class registered as ``type_name``.

    Only registered names are accepted: the package's own registry and installed plugins declared as
    entry points.  A scenario can never name a module path (``module:Class``), so no file a user hands
    us makes us import code.
    """
    if not isinstance(type_name, str):
        raise ScenarioError(f"{where}: component type must be a registered name, got {type_name!r}")
    target = REGISTRY.get(type_name)
    plugin = None if target is not None else _plugins().get(type_name)
    if target is None and plugin is None:
        names = registered_types()
        if ":" in type_name or "." in type_name:
            raise ScenarioError(f"{where}: component type '{type_name}' looks like a module path; a scenario names "
                                f"a registered type ({', '.join(names)}); other components are installed as "
                                f"plugins (entry point group '{ENTRY_POINT_GROUP}')")
        best = difflib.get_close_matches(type_name, names, n=1)
        hint = f" (did you mean '{best[0]}'?)" if best else f" (known: {', '.join(names)})"
        raise ScenarioError(f"{where}: unknown component type '{type_name}'{hint}")
    try:
        if plugin is not None:
            return plugin.load()
        mod, cls = target.split(":")
        return getattr(importlib.import_module(mod), cls)
    except Exception as exc:
        raise ScenarioError(f"{where}: component type '{type_name}' cannot be loaded: "
                            f"{type(exc).__name__}: {exc}") from exc
