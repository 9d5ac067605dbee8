"""providers.py - register the package's own component types, FMU adapter and metrics with ``core``.

`shevsim.core` imports nothing above it: it asks `shevsim.core.registry` for the class of a
component type, for an FMU component and for a result's metrics. ``import shevsim`` runs
`register` once; each provider imports its layer only when first used, so a scenario pays only
for what it names.
"""
from __future__ import annotations

from .core import registry


def component_class(type_name: str, where: str = "scenario") -> type:
    """The class of a native or plugin component type (`shevsim.components.get_component_class`)."""
    from .components import get_component_class
    return get_component_class(type_name, where)


def fmu_component(spec, scenario, where: str):
    """A scenario's ``type = "fmu"`` component (`shevsim.fmu.adapter.component_from_spec`)."""
    from .fmu.adapter import component_from_spec
    return component_from_spec(spec, scenario, where)


def result_metrics(result) -> dict:
    """A result's metrics (`shevsim.metrics.result_metrics`)."""
    from .metrics import result_metrics as compute
    return compute(result)


def fmu_ports(spec) -> dict | None:
    """The ports of a ``type = "fmu"`` spec from its model description (None when fmpy cannot read it now;
    the FMU's own error comes when it is built)."""
    try:
        from .fmu.adapter import load_model_description
        md = load_model_description(spec.fmu)
    except Exception:  # noqa: BLE001 - unknown here; reported when the component is built
        return None
    kinds: dict[str, set] = {}
    for v in md.modelVariables:
        if v.causality in ("input", "output"):
            kinds.setdefault(spec.mapping.get(v.name, v.name), set()).add(v.causality)
    return {p: "/".join(sorted(k)) for p, k in kinds.items()}


def result_html(result) -> str:
    """A result's notebook view (`shevsim.report.html.result_summary_html`)."""
    from .report.html import result_summary_html
    return result_summary_html(result)


def scenario_html(scenario) -> str:
    """A scenario's notebook view (`shevsim.report.html.scenario_html`)."""
    from .report.html import scenario_html as view
    return view(scenario)


def shared_quantities():
    """The rules of a scenario's ``[shared]`` quantities (`shevsim.components.shared`)."""
    from .components import shared
    return shared
def plot_signals(*args, **kwargs):
    """Signals against time, one axis per display unit (`shevsim.plotting.plot_signals`)."""
    from .plotting import plot_signals as plot
    return plot(*args, **kwargs)


def scenario_plots(*args, **kwargs):
    """The figures (and the HTML report) a saved run gets (`shevsim.plotting.scenario_plots`)."""
    from .plotting import scenario_plots as plots
    return plots(*args, **kwargs)


def register() -> None:
    """Register the package's providers with `shevsim.core.registry` (idempotent)."""
    registry.register_component_lookup(component_class)
    registry.register_fmu_factory(fmu_component)
    registry.register_result_metrics(result_metrics)
    registry.register_fmu_ports(fmu_ports)
    registry.register_html_view("result", result_html)
    registry.register_html_view("scenario", scenario_html)
    registry.register_shared_quantities(shared_quantities)
    registry.register_plot("signals", plot_signals)
    registry.register_plot("scenario", scenario_plots)


register()
