"""component.py - the one component contract shared by native components and FMUs.

Life cycle (FMI co-simulation shaped)::

    comp = SomeComponent("battery", params)      # instantiate with parameters
    comp.initialize(t0)                           # outputs valid at t0
    loop:
        comp.u["current_a"] = 12.0               # set inputs (master copies connections)
        comp.do_step(t, h)                        # advance the state from t to t + h
        value = comp.y["voltage_v"]              # get outputs, valid at t + h
    comp.terminate()

Inputs live in the dict ``comp.u`` and outputs in the dict ``comp.y``, keyed by
port name. The master writes ``u`` and reads ``y`` directly (a dict read and a
write per connection, the cheapest exchange Python has); an FMU adapter fills
the same dicts from ``fmi2GetReal``/``fmi3GetFloat64``. So the master cannot tell
a native component from an FMU.

Semantics the master relies on
------------------------------
* ``initialize(t0)`` sets ``y`` consistent with the initial state and the start
  values of ``u``.
* ``do_step(t, h)`` integrates from ``t`` to ``t + h`` with inputs held at the
  values in ``u`` (zero-order hold) and leaves ``y`` at ``t + h``. Outputs that
  declare ``depends_on`` inputs are direct feedthrough: they are evaluated with
  the held inputs.
* ``get_state()`` returns an opaque snapshot from which ``set_state`` restores
  the component exactly (the snapshot does not alias live data).
* Units are SI inside; every port name carries its unit suffix and declares its unit.
"""
from __future__ import annotations

import dataclasses

import copy
from typing import Any, ClassVar, Protocol, runtime_checkable

from .variables import Variable


@runtime_checkable
class ComponentProtocol(Protocol):
    """What the master needs from any component (native or FMU)."""

    name: str
    u: dict[str, float]
    y: dict[str, float]

    def variables(self) -> tuple[Variable, ...]: ...
    def initialize(self, t0: float) -> None: ...
    def do_step(self, t: float, h: float) -> None: ...
    def get_state(self) -> Any: ...
    def set_state(self, state: Any) -> None: ...
    def terminate(self) -> None: ...


class Component:
    """Base class of native components.

    Subclasses declare ``TYPE`` (the registry name used in scenarios),
    ``Params`` (a frozen dataclass of unit-suffixed parameters, or ``None``)
    and ``VARIABLES`` (inputs and outputs), and implement ``initialize`` and
    ``do_step``. Attributes listed in ``_static`` are not part of the saved
    state (parameters, maps, compiled tables).
    """

    TYPE: ClassVar[str] = ""
    Params: ClassVar[type | None] = None
    VARIABLES: ClassVar[tuple[Variable, ...]] = ()
    _static: ClassVar[tuple[str, ...]] = ("name", "params")
    #: inputs that may be left unconnected: their start value is then a declared default ("no limit", a
    #: flat road, no auxiliary load); any other input left unconnected is refused when the scenario is
    #: built.  ``None`` (components that declare nothing): every input has its start value as default.
    INPUT_DEFAULTS: ClassVar[tuple[str, ...] | None] = None

    def __init__(self, name: str, params: Any = None):
        self.name = name
        if params is None and self.Params is not None:
            params = self.Params()
        if params is not None and dataclasses.is_dataclass(params) and not isinstance(params, type):
            from .params import validate_params   # every number checked, also when built through the Python API
            validate_params(params, f"component '{name}' parameters")
        self.params = params
        self.u: dict[str, float] = {v.name: v.start for v in self.variables() if v.causality == "input"}
        self.y: dict[str, float] = {v.name: v.start for v in self.variables() if v.causality == "output"}

    def defaulted_inputs(self) -> set[str]:
        """Inputs that may be left unconnected (:attr:`INPUT_DEFAULTS`; all of them when it is None)."""
        names = {v.name for v in self.variables() if v.causality == "input"}
        return names if self.INPUT_DEFAULTS is None else names & set(self.INPUT_DEFAULTS)

    # -- interface -------------------------------------------------------------
    def variables(self) -> tuple[Variable, ...]:
        """The declared variables (class-level by default; FMUs build theirs at load)."""
        return self.VARIABLES

    def initialize(self, t0: float) -> None:
        """Set the initial state and the outputs at ``t0``."""

    def do_step(self, t: float, h: float) -> None:  # pragma: no cover - abstract
        """Advance from ``t`` to ``t + h`` with ``self.u`` held; update ``self.y``."""
        raise NotImplementedError

    def terminate(self) -> None:
        """Release resources. Native components hold none by default."""

    def get_state(self) -> Any:
        """Deep copy of everything but the static attributes."""
        skip = set(self._static)
        return copy.deepcopy({k: v for k, v in self.__dict__.items() if k not in skip})

    def set_state(self, state: Any) -> None:
        """Restore a snapshot made by :meth:`get_state`."""
        for k, v in copy.deepcopy(state).items():
            setattr(self, k, v)

    # -- helpers ---------------------------------------------------------------
    @classmethod
    def inputs(cls) -> tuple[Variable, ...]:
        return tuple(v for v in cls.VARIABLES if v.causality == "input")

    @classmethod
    def outputs(cls) -> tuple[Variable, ...]:
        return tuple(v for v in cls.VARIABLES if v.causality == "output")

    def natural_stop_time(self) -> float | None:
        """A component that defines the run length (a drive cycle) returns it here."""
        return None

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"
