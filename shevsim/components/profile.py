"""profile.py - sampled-signal source component (TYPE ``profile``): replays measured or prescribed inputs.

Holds each sample until the next one (sample-and-hold): the output at time ``t`` is the value of the last
sample with ``time_s[k] <= t`` (a tolerance of 1e-9 of the step absorbs round-off in ``t``).  Under the
Gauss-Seidel master a component that follows the source therefore steps ``[t, t + h]`` with the sample at
``t + h`` - the convention of :func:`shevsim.battery.model.run_profile`, so a replay through the master and
the calibration's compiled loop are the same computation on a regular grid.

Ports
-----
Outputs (no inputs)
    ``current_a`` [A] (+ discharge), ``power_w`` [W] (+ drawn / discharge), ``speed_mps`` [m/s],
    ``t_ambient_c`` [degC], ``h_conv_w_m2k`` [W/(m2.K)].  A port whose column is empty holds its start
    value (0; 25 degC; 20 W/(m2.K)).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from shevsim.core.compiled import CompiledStep, njit_step
from shevsim.core.component import Component
from shevsim.core.errors import ScenarioError
from shevsim.core.lookup import py_max
from shevsim.core.variables import out
from shevsim.supervisor.rule_based import bisect_right

_PORTS = ("current_a", "power_w", "speed_mps", "t_ambient_c", "h_conv_w_m2k")


@dataclass(frozen=True)
class ProfileParams:
    """Samples of :class:`ProfileSource`: ``time_s`` [s] (strictly increasing) and one column per port
    (empty = the port's start value).  Parameter files may give the columns as TOML arrays."""

    time_s: tuple[float, ...] = (0.0,)
    current_a: tuple[float, ...] = ()
    power_w: tuple[float, ...] = ()
    speed_mps: tuple[float, ...] = ()
    t_ambient_c: tuple[float, ...] = ()
    h_conv_w_m2k: tuple[float, ...] = ()

    def __post_init__(self):
        n = len(self.time_s)
        if n < 1:
            raise ScenarioError("profile parameters: time_s needs at least one sample")
        ts = list(self.time_s)
        if any(not math.isfinite(v) for v in ts) or any(not (b > a) for a, b in zip(ts, ts[1:])):
            raise ScenarioError("profile parameters: time_s must be finite and strictly increasing")
        for p in _PORTS:
            col = getattr(self, p)
            if col and len(col) != n:
                raise ScenarioError(f"profile parameters: column '{p}' has {len(col)} samples, time_s has {n}")
            if any(not math.isfinite(v) for v in col):
                raise ScenarioError(f"profile parameters: column '{p}' holds a non-finite value")


class ProfileSource(CompiledStep, Component):
    """Sample-and-hold source of measured / prescribed signals (see the module docstring)."""

    TYPE = "profile"
    Params = ProfileParams
    VARIABLES = (
        out("current_a", "A", 0.0, "current, + discharge"),
        out("power_w", "W", 0.0, "power, + drawn (discharge)"),
        out("speed_mps", "m/s", 0.0, "speed"),
        out("t_ambient_c", "degC", 25.0, "ambient temperature"),
        out("h_conv_w_m2k", "W/(m2.K)", 20.0, "convection coefficient"),
    )
    _static = ("name", "params", "_t", "_cols", "_fn", "_u_names", "_y_names")

    def __init__(self, name: str = "profile", params: ProfileParams | None = None):
        super().__init__(name, params)
        self._t = list(self.params.time_s)
        self._cols = {p: list(getattr(self.params, p)) for p in _PORTS if getattr(self.params, p)}
        self.initialize(0.0)

    def _evaluate(self, t: float) -> None:
        ts = self._t
        tol = 1e-9 * max(1.0, abs(t))
        k = max(0, bisect.bisect_right(ts, t + tol) - 1)
        for p, col in self._cols.items():
            self.y[p] = col[k]

    def initialize(self, t0: float) -> None:
        """``data`` = ``(time_s, columns (ports x samples), has (1 for a port with a column))``."""
        ts = np.array(self._t, dtype=np.float64)
        cols = np.zeros((len(_PORTS), ts.size))
        has = np.zeros(len(_PORTS))
        for q, name in enumerate(_PORTS):
            if name in self._cols:
                cols[q] = self._cols[name]
                has[q] = 1.0
        self.data = (ts, cols, has)
        self._evaluate(t0)
        self._io()

    def natural_stop_time(self) -> float | None:
        return self._t[-1]


@njit_step
def profile_step(data, u, y, t, h):
    """:class:`ProfileSource`'s step: the last sample at or before ``t + h`` (tolerance 1e-9 of the time) for
    every port with a column; the others hold."""
    ts, cols, has = data
    te = t + h
    tol = 1e-9 * py_max(1.0, abs(te))
    k = bisect_right(ts, te + tol) - 1
    if k < 0:
        k = 0
    for q in range(has.shape[0]):
        if has[q] > 0.5:
            y[q] = cols[q, k]
    return 0


ProfileSource.STEP = profile_step
