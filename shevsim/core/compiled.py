"""compiled.py - a native component whose ``do_step`` is ONE compiled step, shared by both engines.

A component written this way declares

* ``STEP``: a numba-compiled function ``step(data, u, y, t, h) -> int`` that advances the component
  from ``t`` to ``t + h``.  ``u`` holds the inputs and ``y`` receives the outputs, both float arrays in
  the component's declared order (index them with :func:`port_index` constants); ``data`` is the
  component's own tuple of arrays (state, parameters, tables), updated in place.  The step holds the
  whole of the component's bookkeeping - input checks, physics, limits, noise, output publishing - and
  returns 0, or a nonzero status the class turns into its error message (:meth:`CompiledStep.step_error`).
* ``data``: the instance's tuple of arrays (built in ``initialize``), and ``DATA_MUTABLE``: which of
  them a run changes (the fast path copies those per run, shares the rest).

The Python master calls :meth:`CompiledStep.do_step` (inputs from ``self.u`` into the component's
input array, the step on the component's own arrays, outputs into ``self.y``); the compiled
whole-vehicle loop (:mod:`shevsim.fast`) calls the very same ``STEP`` on slices of its signal array.
Nothing in :mod:`shevsim.fast` is specific to a component type: a new type written this way runs on
both paths.

Index constants are generated from the declared names (never restated by hand)::

    U = port_index(VARIABLES, "input")       # U.power_w == 0, U.h_conv_w_m2k == 1, ...
    Y = port_index(VARIABLES, "output")
    P = field_index(("n_parallel", "n_series"))
    p = pack_fields(params, P)               # float array in P's order

numba freezes a module-level named tuple of ints into constants, so ``y[Y.soc_pct]`` compiles to
``y[2]``.
"""
from __future__ import annotations

from collections import namedtuple
from typing import Any, ClassVar, Iterable

import numpy as np

from .errors import SimulationError

__all__ = ["port_index", "field_index", "pack_fields", "CompiledStep", "njit_step", "ERR_NAN_INPUT",
           "ERR_SAMPLE_TIME"]

#: status codes shared by several steps (a component adds its own from 16 on)
ERR_NAN_INPUT = 1
ERR_SAMPLE_TIME = 2


def njit_step(fn=None, **options):
    """``numba.njit(cache=True)`` without numba's reference counting, for a compiled step, the hot physics it
    calls and the compiled loop (``@njit_step`` or ``@njit_step(inline="always")``).

    numba counts references to every array it binds to a name (an argument, an item unpacked from the
    ``data`` tuple, a slice, an argument of an inlined helper): an atomic increment and decrement through a
    call each.  A step binds a dozen or more arrays per call, so on the fast path these were 15-30 % of a
    step's time (measured per step: engine-generator 421 -> 302 ns, motor 124 -> 100 ns, BMS 709 -> 624 ns).
    A step allocates nothing and keeps no array beyond the call (every array it touches is owned by its
    caller: the component or the fast runner), so the counts are pure overhead; ``_nrt=False`` (numba's
    option to compile without its runtime) leaves them out.  numba refuses to compile a function so marked
    that allocates (``np.empty``, a copying slice assignment, an exception with a run-time message), so the
    contract is checked when the step compiles.  numba compiles the functions a step calls without the runtime
    too, so a helper compiled with plain ``njit`` cannot allocate either: scratch arrays belong in the
    component's ``data`` tuple, allocated once in ``initialize`` (numba's message then reads "No implementation
    of function ... empty" or "Only accept returning of array passed into the function as argument").
    """
    from numba import njit
    opts = {"cache": True, "_nrt": False, **options}
    if fn is None:
        return lambda f: njit(**opts)(f)
    return njit(**opts)(fn)


def field_index(names: Iterable[str], typename: str = "Index"):
    """A named tuple whose field ``n`` holds the position of ``n`` in ``names`` (numba-constant)."""
    names = tuple(names)
    return namedtuple(typename, names)(*range(len(names)))


def port_index(variables, causality: str, typename: str | None = None):
    """Index constants of the declared ``variables`` of one causality (``"input"`` or ``"output"``)."""
    names = [v.name for v in variables if v.causality == causality]
    return field_index(names, typename or ("U" if causality == "input" else "Y"))


def pack_fields(obj: Any, index) -> np.ndarray:
    """The attributes of ``obj`` named by ``index``'s fields, as floats in that order (booleans 1/0)."""
    return np.array([float(getattr(obj, f)) for f in index._fields], dtype=np.float64)


class CompiledStep:
    """Mixin for a :class:`~shevsim.core.component.Component` whose step is one compiled function.

    The subclass sets ``STEP`` (the compiled step), ``STEP_ERRORS`` (status -> text), builds
    ``self.data`` in ``initialize`` and lists the mutated entries in ``DATA_MUTABLE``.  A subclass whose
    instances use another step (a mode with other ports) overrides :meth:`step_function`.

    Hooks of the compiled loop (all optional): :meth:`fast_reason` (why an instance cannot run
    compiled), :meth:`fast_prepare` (the step it will be called with), :meth:`fast_data` (its data for a run
    of ``n`` calls), :meth:`fast_release`.
    """

    STEP: ClassVar[Any] = None
    STEP_ERRORS: ClassVar[dict] = {ERR_NAN_INPUT: "NaN input",
                                   ERR_SAMPLE_TIME: "called with a step that is not its sample_time_s"}
    DATA_MUTABLE: ClassVar[tuple[int, ...]] = ()

    # ------------------------------------------------------------------ the step on own arrays
    def step_function(self):
        """The compiled step of this instance (``STEP``; a mode with other ports may pick another)."""
        return type(self).STEP           # from the class: a compiled function is a descriptor (it would bind)

    def _io(self):
        ins = tuple(v.name for v in self.variables() if v.causality == "input")
        outs = tuple(v.name for v in self.variables() if v.causality == "output")
        self._u_names, self._y_names = ins, outs
        self._u_arr = np.array([float(self.u[k]) for k in ins], dtype=np.float64)
        self._y_arr = np.array([float(self.y[k]) for k in outs], dtype=np.float64)
        self._fn = self.step_function()

    def do_step(self, t: float, h: float) -> None:
        """Inputs from ``self.u`` -> the compiled step on the component's arrays -> ``self.y``."""
        ua = self._u_arr
        u = self.u
        for i, k in enumerate(self._u_names):
            ua[i] = u[k]
        status = self._fn(self.data, ua, self._y_arr, float(t), float(h))
        if status:
            raise SimulationError(self.step_error(int(status), float(t), float(h)))
        self.y.update(zip(self._y_names, self._y_arr.tolist()))

    def step_error(self, status: int, t: float, h: float) -> str:
        """The error message of a nonzero step status (names the component, time and the inputs)."""
        what = self.STEP_ERRORS.get(status, f"status {status}")
        ins = ", ".join(f"{k}={v!r}" for k, v in self.u.items())
        return f"{self.name}: {what} at t={t:.6g} s ({ins})"

    # ------------------------------------------------------------------ the compiled loop's hooks
    def fast_reason(self) -> str:
        """Why this instance cannot run in the compiled loop ("" when it can)."""
        return "" if self.step_function() is not None else f"component '{self.name}' has no compiled step"

    def fast_prepare(self, step_s: float) -> None:
        """Get ready to be stepped by ``step_s`` (before the loop takes :attr:`data` as its template; a
        component whose arrays depend on its step, as the BMS's estimators, builds them here)."""

    def fast_data(self, data: tuple, n_calls: int) -> tuple:
        """The data of a run that calls the step ``n_calls`` times, given ``data`` (a copy of the template's
        :attr:`data` whose :attr:`DATA_MUTABLE` entries the run may change).  A component whose data depend
        on the run length (the battery's noise draws) returns them extended."""
        return data

    def fast_release(self, data: tuple) -> None:
        """Free what a run's data hold outside Python (nothing by default)."""

    @classmethod
    def fast_examples(cls) -> dict:
        """``{step function: default instance}``: one instance per compiled step the class has (the loop's
        placeholder for a type a scenario lacks, so one compiled loop serves every scenario)."""
        c = cls(cls.TYPE)
        c.initialize(0.0)
        return {c.step_function(): c}
