"""errors.py - the exceptions shevsim raises; every message names where the problem is."""
from __future__ import annotations


class ShevsimError(Exception):
    """Base class of all shevsim errors."""


class ScenarioError(ShevsimError):
    """A scenario or parameter file is malformed or inconsistent (message names file and field)."""


class ConnectionError_(ShevsimError):
    """A connection refers to an unknown port or joins incompatible units."""


class AlgebraicLoopError(ShevsimError):
    """A cycle of direct-feedthrough connections (message lists every component.port in it)."""


class SimulationError(ShevsimError):
    """A run failed: message names component, variable and time."""



class FastPathError(SimulationError):
    """The compiled whole-system loop (:mod:`shevsim.fast`) raised inside compiled code: no component,
    port or time is known (``engine='auto'`` then reruns on the Python master, which names them)."""

class DataError(ShevsimError):
    """Input data (cycle, measurement) is malformed: message names the file and column/row."""
