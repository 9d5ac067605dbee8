"""cycle.py - drive-cycle source component (TYPE ``cycle``).

Plays a drive cycle (a ``time_s,speed_mps`` CSV, see :mod:`shevsim.cycles`)
``repeat`` times back to back. No inputs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shevsim.core.compiled import CompiledStep, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.lookup import njit
from shevsim.core.variables import out
from shevsim.cycles import load_cycle
from shevsim.core.paths import data_path

_DEFAULT_CYCLE = str(data_path("cycles", "hd_udds.csv"))


@dataclass(frozen=True, slots=True)
class CycleParams:
    """Parameters of :class:`CycleSource`.

    Attributes
    ----------
    cycle_file : str
        Path of the cycle CSV (relative paths in a parameter file resolve against that file).
    repeat : int
        Number of consecutive repetitions of the cycle (1 to 1e6). The seed's fuel
        economy (A.1) is evaluated over two consecutive cycles.
    check_units : bool
        Unit sniffing on the cycle file (speeds that look like km/h, times like ms, impossible
        accelerations; :func:`shevsim.cycles.check_plausible`). ``false`` for a legitimate trace the
        checks refuse (a synthetic step, a race car).
    """

    cycle_file: str = _DEFAULT_CYCLE
    repeat: int = 1
    check_units: bool = True

    def __post_init__(self):
        if not 1 <= self.repeat <= 1_000_000:
            raise ValueError(f"parameter 'repeat' must be in [1, 1000000], got {self.repeat}")


@njit(cache=True)
def cycle_sample(v, slope, dt: float, dur: float, repeat: int, t0: float, t: float):
    """``(speed_ref_mps, accel_ref_mps2, time_in_cycle_s)`` of the trace ``v`` (samples every ``dt``,
    segment slopes ``slope``) played ``repeat`` times from ``t0``, at time ``t`` (see :class:`CycleSource`).

    Compiled once; the component and the compiled whole-vehicle loop (:mod:`shevsim.fast`) both call it.
    """
    n = v.shape[0]
    rel = t - t0
    # repetition index, robust to floating-point round-off at the boundaries
    k = math.floor(rel / dur + 1e-9)
    if rel < 0.0:
        k = 0
        rel = 0.0
    if k >= repeat:
        return v[n - 1], 0.0, dur
    tc = rel - k * dur
    if tc < 0.0:
        tc = 0.0
    x = tc / dt
    i = int(math.floor(x + 1e-9))
    if i >= n - 1:
        i = n - 2
    frac = x - i
    if frac < 0.0:
        frac = 0.0
    return v[i] + (v[i + 1] - v[i]) * frac, slope[i], tc


class CycleSource(CompiledStep, Component):
    """Drive-cycle speed reference.

    Outputs
    -------
    speed_ref_mps : m/s
        Reference speed at the current time, linear interpolation of the trace (>= 0).
    accel_ref_mps2 : m/s^2
        Reference acceleration for driver feed-forward: the slope of the trace
        segment that is driven in the next interval, i.e. the segment
        ``[t_i, t_i + dt)`` containing the current time (right-continuous). Positive
        = speeding up. 0 after the last repetition.
    time_in_cycle_s : s
        Time since the start of the current repetition, in ``[0, duration)``;
        equals the duration after the end of the last repetition.

    Notes
    -----
    The run is ``duration x repeat`` long (:meth:`natural_stop_time`). Beyond it the
    source holds the last speed of the trace with zero acceleration. The cycle
    starts at the ``t0`` given to :meth:`initialize`.
    """

    TYPE = "cycle"
    Params = CycleParams
    VARIABLES = (
        out("speed_ref_mps", "m/s", 0.0, "reference speed (>= 0)"),
        out("accel_ref_mps2", "m/s2", 0.0, "reference acceleration: slope of the segment driven next (+ speeding up)"),
        out("time_in_cycle_s", "s", 0.0, "time since the start of the current repetition"),
    )
    _static = ("name", "params", "cycle", "_v", "_slope", "_dt", "_n", "_dur", "_repeat", "_va", "_sa", "_fn",
               "_u_names", "_y_names")

    def __init__(self, name: str, params: CycleParams | None = None):
        super().__init__(name, params)
        self.cycle = load_cycle(self.params.cycle_file, check_units=self.params.check_units)
        self._v = [float(x) for x in self.cycle.speed_mps]
        self._dt = self.cycle.dt_s
        self._slope = [(self._v[i + 1] - self._v[i]) / self._dt for i in range(len(self._v) - 1)] + [0.0]
        self._n = len(self._v)
        self._va = np.array(self._v, dtype=np.float64)     # the trace and slopes for cycle_sample
        self._sa = np.array(self._slope, dtype=np.float64)
        self._dur = self.cycle.duration_s
        self._repeat = int(self.params.repeat)
        self.t0 = 0.0

    def natural_stop_time(self) -> float:
        """Cycle duration x repeat (s), counted from the start time."""
        return self.t0 + self._dur * self._repeat

    def initialize(self, t0: float) -> None:
        """``data`` = ``(speeds, slopes, [dt, n, duration, repeat, t0])``; the outputs at ``t0``."""
        self.t0 = float(t0)
        self.data = (self._va, self._sa, np.array([self._dt, self._n, self._dur, self._repeat, self.t0],
                                                  dtype=np.float64))
        self._io()
        y = self.y
        y["speed_ref_mps"], y["accel_ref_mps2"], y["time_in_cycle_s"] = cycle_sample(
            self._va, self._sa, self._dt, self._dur, self._repeat, self.t0, self.t0)


Y = port_index(CycleSource.VARIABLES, "output")


@njit_step
def cycle_step(data, u, y, t, h):
    """:class:`CycleSource`'s step: the trace sampled at ``t + h`` (:func:`cycle_sample`)."""
    v, slope, p = data
    y[Y.speed_ref_mps], y[Y.accel_ref_mps2], y[Y.time_in_cycle_s] = cycle_sample(v, slope, p[0], p[2], int(p[3]),
                                                                               p[4], t + h)
    return 0


CycleSource.STEP = cycle_step
