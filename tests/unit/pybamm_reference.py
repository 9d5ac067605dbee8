"""PyBaMM references shared by the independent cell-record tests (not a test module)."""
from __future__ import annotations

import numpy as np
import pytest


def equilibrium_ocv(parameter_set: str, soc_table, q_ah: float, rated_ah: float) -> np.ndarray:
    """PyBaMM's equilibrium OCV of ``parameter_set``, U_p - U_n, at the nominal table's SOC (1 - discharged A.h /
    ``rated_ah``; PyBaMM's SOC is the fraction of its stoichiometry window, whose capacity ``q_ah`` the C/50 run
    measured)."""
    pybamm = pytest.importorskip("pybamm")
    p = pybamm.ParameterValues(parameter_set)
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    u_n, u_p = p["Negative electrode OCP [V]"], p["Positive electrode OCP [V]"]
    s = 1.0 - (1.0 - np.atleast_1d(np.asarray(soc_table, float))) * rated_ah / q_ah
    return np.array([float(u_p(pybamm.Scalar(y0 + a * (y1 - y0))).evaluate())
                     - float(u_n(pybamm.Scalar(x0 + a * (x1 - x0))).evaluate()) for a in s])
