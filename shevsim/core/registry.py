"""registry.py - the factories ``core`` uses but does not own, registered by the layers above it.

``core`` reads scenarios and runs the master; it knows no component type, no FMU and no metric. The
layers that do register what they provide here (as FMPy's and PyBaMM's registries do), and ``core``
asks the registry:

* `component_class` - the class of a scenario's component ``type`` (registered by
  `shevsim.components`, which also finds installed plugins);
* `fmu_component` - a component for ``type = "fmu"`` (registered by `shevsim.fmu`);
* `result_metrics` - the metrics of a `Result` (registered by
  `shevsim.metrics`);
* `fmu_ports` - the inputs and outputs of an FMU spec before it is built (registered by
  `shevsim.fmu`), so a connection's direction is checked when it is made;
* `html_view` - the HTML a notebook shows for a result or a scenario (registered by
  `shevsim.report`);
* `shared_quantities` - the rules of a scenario's ``[shared]`` quantities (which component parameter
  each one is; registered by `shevsim.components`: `shevsim.components.shared`).

``import shevsim`` registers the package's own providers (`shevsim.providers`); a program that
uses ``shevsim.core`` alone registers its own with the ``register_*`` functions.
"""
from __future__ import annotations

from typing import Any, Callable

from .errors import ScenarioError, ShevsimError

_providers: dict[str, Callable[..., Any]] = {}


def register_component_lookup(lookup: Callable[[str, str], type]) -> None:
    """Register ``lookup(type_name, where) -> class``: the class of a scenario's component type
    (raising `ScenarioError` naming ``where`` for an unknown name)."""
    _providers["component"] = lookup


def register_fmu_factory(factory: Callable[[Any, Any, str], Any]) -> None:
    """Register ``factory(spec, scenario, where) -> component`` for components of type ``"fmu"``."""
    _providers["fmu"] = factory


def register_result_metrics(metrics: Callable[[Any], dict]) -> None:
    """Register ``metrics(result) -> dict``: what `Result.metrics` computes on first access."""
    _providers["metrics"] = metrics


def register_shared_quantities(provider: Callable[[], Any]) -> None:
    """Register ``provider() -> module`` with ``check_value(name, value, where)``, ``resolve(scenario,
    file_params)`` and ``same(a, b)``: the rules of the scenario's ``[shared]`` quantities."""
    _providers["shared"] = provider
def register_plot(kind: str, plot: Callable[..., Any]) -> None:
    """Register a figure maker: ``"signals"`` (``plot(results, signals, ax=None, labels=None) -> Figure``,
    what `Result.plot` draws) or ``"scenario"`` (``plot(result, folder) -> [paths]``, the figures
    `Result.save` writes with ``plots=True``)."""
    _providers[f"plot:{kind}"] = plot


def plot_function(kind: str) -> Callable[..., Any]:
    """The figure maker registered as ``kind`` (see `register_plot`)."""
    if f"plot:{kind}" not in _providers:
        raise ShevsimError(f"no '{kind}' plot is registered (import shevsim, or register one with "
                           f"shevsim.core.registry.register_plot)")
    return _providers[f"plot:{kind}"]


def _provider(kind: str, what: str) -> Callable[..., Any]:
    try:
        return _providers[kind]
    except KeyError:
        raise ShevsimError(f"no {what} is registered (import shevsim, or register one with "
                           f"shevsim.core.registry.register_{'component_lookup' if kind == 'component' else kind})"
                           ) from None


def component_class(type_name: str, where: str = "scenario") -> type:
    """The component class registered for the scenario type ``type_name``."""
    return _provider("component", "component type lookup")(type_name, where)


def fmu_component(spec, scenario, where: str):
    """A component for the ``type = "fmu"`` spec ``spec`` of ``scenario``."""
    if "fmu" not in _providers:
        raise ScenarioError(f"{where}: FMU components are not available (the FMU layer, shevsim.fmu, is not "
                            f"registered)")
    return _providers["fmu"](spec, scenario, where)


def result_metrics(result) -> dict:
    """The metrics of ``result`` (see `register_result_metrics`)."""
    return _provider("metrics", "metrics function")(result)


def register_fmu_ports(ports: Callable[[Any], dict | None]) -> None:
    """Register ``ports(spec) -> {port: "input" | "output"}`` (None when unknown) for ``type = "fmu"`` specs."""
    _providers["fmu_ports"] = ports


def fmu_ports(spec) -> dict | None:
    """The ports of an FMU spec from its model description, or None when no provider can tell."""
    fn = _providers.get("fmu_ports")
    return fn(spec) if fn is not None else None


def register_html_view(kind: str, view: Callable[[Any], str]) -> None:
    """Register ``view(obj) -> HTML`` shown by a notebook for objects of ``kind`` (``"result"``,
    ``"scenario"``)."""
    _providers[f"html:{kind}"] = view


def html_view(kind: str, obj) -> str | None:
    """The registered HTML view of ``obj``, or None (a notebook then shows its ``repr``)."""
    fn = _providers.get(f"html:{kind}")
    return fn(obj) if fn is not None else None


def shared_quantities():
    """The rules of the ``[shared]`` quantities (see `register_shared_quantities`)."""
    return _provider("shared", "shared-quantity rules")()
