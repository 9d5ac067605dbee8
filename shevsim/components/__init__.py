"""Native co-simulation components, found by their scenario ``type`` name.

The registry maps a type name to ``"module:Class"`` and imports lazily, so a
scenario only pays for the components it uses.
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


def get_component_class(type_name: str, where: str = "scenario"):
    """Return the component class registered as ``type_name`` (or a ``module:Class`` string)."""
    target = REGISTRY.get(type_name)
    if target is None and ":" in type_name:
        target = type_name
    if target is None:
        best = difflib.get_close_matches(type_name, list(REGISTRY), n=1)
        hint = f" (did you mean '{best[0]}'?)" if best else f" (known: {', '.join(sorted(REGISTRY))})"
        raise ScenarioError(f"{where}: unknown component type '{type_name}'{hint}")
    mod, cls = target.split(":")
    try:
        return getattr(importlib.import_module(mod), cls)
    except (ImportError, AttributeError) as exc:
        raise ScenarioError(f"{where}: component type '{type_name}' cannot be loaded ({target}): {exc}") from exc
