"""shevsim.fmu - FMU import (fmpy, FMI 2.0/3.0 co-simulation and model exchange), info, building and export.

* :class:`~shevsim.fmu.adapter.FMUComponent` - an FMU as a shevsim component.
* :func:`~shevsim.fmu.info.fmu_info` - what ``shevsim info some.fmu`` prints.
* :func:`~shevsim.fmu.export.export_component` - a native component as an FMU (pythonfmu/pythonfmu3).
* :mod:`~shevsim.fmu.build` - build FMUs from C (fmpy + cmake) or Python sources.
"""
from .adapter import FMUComponent, expected_units_of, load_model_description, read_fmi_version
from .errors import (FMUError, FMULoadError, FMUMappingError, FMUStateError, FMUStepError, FMUTimeoutError,
                     FMUUnitError, FMUUnsupportedError)

__all__ = ["FMUComponent", "expected_units_of", "load_model_description", "read_fmi_version",
           "FMUError", "FMULoadError", "FMUMappingError", "FMUStateError", "FMUStepError", "FMUTimeoutError", "FMUUnitError",
           "FMUUnsupportedError"]
