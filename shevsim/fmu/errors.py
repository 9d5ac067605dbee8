"""errors.py - FMU-specific exceptions.

They subclass the shared exceptions of :mod:`shevsim.core.errors`, so a caller
catching ``ScenarioError`` (bad input files) or ``SimulationError`` (a failed
run) also catches the FMU cases; the subclasses let tests and tools tell the
cases apart. Every message names the FMU file or the component, and for step
failures the simulation time and the FMI status.
"""
from __future__ import annotations

from ..core.errors import ConnectionError_, ScenarioError, ShevsimError, SimulationError

FMI_STATUS_NAMES = ("ok", "warning", "discard", "error", "fatal", "pending")


def status_name(status: int) -> str:
    """Human label of an FMI status code (``3 -> 'error'``)."""
    return FMI_STATUS_NAMES[status] if 0 <= status < len(FMI_STATUS_NAMES) else f"illegal status {status}"


class FMUError(ShevsimError):
    """Base class of every FMU error."""


class FMULoadError(FMUError, ScenarioError):
    """The FMU file is missing, not a ZIP/FMU, has an invalid model description, or cannot be loaded."""


class FMUUnsupportedError(FMULoadError):
    """The FMU is valid but not usable here: model exchange only, or an FMI version other than 2.0/3.0."""


class FMUMappingError(FMUError, ScenarioError):
    """A variable mapping, parameter or start value names a variable the FMU does not have."""


class FMUUnitError(FMUError, ConnectionError_):
    """An FMU variable's unit differs from the unit the replaced component's port declares."""


class FMUStepError(FMUError, SimulationError):
    """An FMI call failed during the run (``doStep`` and friends).

    Attributes
    ----------
    component : str
        Name of the FMU component instance.
    time : float
        Communication point at which the call failed (s).
    status : int
        FMI status code returned (3 = error, 4 = fatal, 2 = discard).
    function : str
        Name of the FMI function that failed.
    """

    def __init__(self, component: str, time: float, status: int, function: str = "doStep",
                 detail: str = "", step: float | None = None):
        self.component = component
        self.time = time
        self.status = status
        self.function = function
        self.step = step
        where = f"t = {time:.6g} s" + (f" (step to {time + step:.6g} s)" if step is not None else "")
        msg = (f"FMU component '{component}': {function} failed at {where} "
               f"with FMI status {status} ({status_name(status)})")
        if detail:
            msg += f": {detail}"
        super().__init__(msg)


class FMUStateError(FMUError, SimulationError):
    """Save/restore requested on an FMU whose model description says it cannot get/set its state."""


class FMUTimeoutError(FMUStepError):
    """One communication step of an FMU did not return within its wall-time bound (``step_timeout_s``)."""

    def __init__(self, component: str, time: float, step: float, timeout_s: float, function: str = "doStep",
                 fmu_file: str = ""):
        self.timeout_s = timeout_s
        super().__init__(component, time, 3, function, "", step)
        where = f"t = {time:.6g} s (step to {time + step:.6g} s)"
        self.args = (f"FMU component '{component}'{f' ({fmu_file})' if fmu_file else ''}: {function} did not "
                     f"return within {timeout_s:.6g} s of wall time at {where}; the FMU appears to hang and its "
                     f"instance is abandoned (raise the bound with step_timeout_s, or 0 for none)",)
