"""Co-simulation core: variables, the component contract, the master, results and scenarios."""
from .component import Component, ComponentProtocol
from .errors import (AlgebraicLoopError, ConnectionError_, DataError, ScenarioError, ShevsimError,
                     SimulationError)
from .master import Connection, Fault, Master, MasterSettings
from .results import Result, load_result, save_result
from .variables import Variable, inp, out

__all__ = ["Component", "ComponentProtocol", "Variable", "inp", "out", "Master", "MasterSettings",
           "Connection", "Fault", "Result", "save_result", "load_result", "ShevsimError", "ScenarioError",
           "ConnectionError_", "AlgebraicLoopError", "SimulationError", "DataError"]
