"""providers.py - register the package's own component types, FMU adapter and metrics with ``core``.

:mod:`shevsim.core` imports nothing above it: it asks :mod:`shevsim.core.registry` for the class of a
component type, for an FMU component and for a result's metrics. ``import shevsim`` runs
:func:`register` once; each provider imports its layer only when first used, so a scenario pays only
for what it names.
"""
from __future__ import annotations

from .core import registry


def component_class(type_name: str, where: str = "scenario") -> type:
    """The class of a native or plugin component type (:func:`shevsim.components.get_component_class`)."""
    from .components import get_component_class
    return get_component_class(type_name, where)


def fmu_component(spec, scenario, where: str):
    """A scenario's ``type = "fmu"`` component (:func:`shevsim.fmu.adapter.component_from_spec`)."""
    from .fmu.adapter import component_from_spec
    return component_from_spec(spec, scenario, where)


def result_metrics(result) -> dict:
    """A result's metrics (:func:`shevsim.metrics.result_metrics`)."""
    from .metrics import result_metrics as compute
    return compute(result)


def register() -> None:
    """Register the package's providers with :mod:`shevsim.core.registry` (idempotent)."""
    registry.register_component_lookup(component_class)
    registry.register_fmu_factory(fmu_component)
    registry.register_result_metrics(result_metrics)


register()
