"""shevsim - co-simulation of series-hybrid electric vehicles (FMI-style components, fixed-step master).

The Python API (see :mod:`shevsim.api`)::

    import shevsim
    res = shevsim.simulate("hd_udds_rule", overrides={"vehicle.mass_kg": 18000.0, "cycle.repeat": 1})
    res.to_pandas(); res.metrics; res.termination; res.plot(["vehicle.speed_mps"]); res.save("out")
"""
from .version import __version__  # noqa: E402
from .core import jitcache as _jitcache  # noqa: E402
_jitcache.install_when_numba_loads()   # numba's cache for shevsim, before any function is compiled (core/jitcache.py)
from . import providers  # noqa: E402,F401  (registers component types, the FMU adapter and metrics with core)

from .api import (Result, Scenario, compare, load_result, load_scenario, metrics_table,  # noqa: E402
                  new_scenario, run_calibration, run_study, scenarios, simulate, vehicles)
from .core.errors import ScenarioError, ShevsimError, SimulationError  # noqa: E402
from .core.results import Termination  # noqa: E402

__all__ = ["__version__", "simulate", "load_scenario", "new_scenario", "scenarios", "vehicles", "compare", "metrics_table",
           "load_result", "run_study", "run_calibration", "Scenario", "Result", "Termination", "ShevsimError",
           "ScenarioError", "SimulationError"]
