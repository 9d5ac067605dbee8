"""shevsim.fast - the compiled whole-vehicle path (issue 15).

:func:`runner_for` turns a scenario whose components all have a compiled step
(:class:`shevsim.core.compiled.CompiledStep`) into a ``runner(t_stop_s) -> Result`` that steps the whole
system in one numba-compiled loop (:func:`shevsim.fast.loop.compiled_loop`): the scenario's own execution
order, step multiples and connections (as index arrays), each component's own compiled step - the very
function its ``do_step`` calls, on slices of one signal array - and the outputs recorded into a
preallocated array.  The result equals :meth:`Master.run <shevsim.core.master.Master.run>` of the same
scenario bit for bit (``tests/unit/test_fast_path.py``); the Python master stays the reference and the path
for FMUs and debugging.  Nothing here is specific to a component type: a new type with a compiled step runs
here as it is.

How a run goes: the scenario is built and initialised by the Python master once (component
construction, initial state, initial outputs: the reference code itself); the components' arrays are the
template, and each call of the runner copies the entries a run changes and runs the compiled loop from
``t0``.  So one runner serves many runs (a study's evaluations) at the cost of the loop alone.

A scenario the path cannot take is declined with the reason: FMUs or component types without a compiled
step, or an instance that says why it cannot (:meth:`~shevsim.core.compiled.CompiledStep.fast_reason`: the
30-node battery thermal model, an MPC solver other than DAQP, ``compiled=False``).

Example::

    from shevsim.core.scenario import load_scenario
    from shevsim.fast import runner_for
    run, why = runner_for(load_scenario("hd_udds_mpc"))
    res = run(1060.0) if run is not None else None
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from shevsim.core.errors import FastPathError

__all__ = ["runner_for", "FastRunner", "FastPathError"]


class Declined(Exception):
    """The scenario cannot take the fast path (the message says why)."""


def _compiled(c) -> bool:
    from shevsim.core.compiled import CompiledStep
    return isinstance(c, CompiledStep)


def _step_of(c, h: float):
    """``(step function, template data, mutated entries)`` of component ``c`` (its own compiled step),
    stepped by ``h``."""
    why = c.fast_reason()
    if why:
        raise Declined(why)
    c.fast_prepare(h)
    return c.step_function(), c.data, tuple(c.DATA_MUTABLE)


_EXAMPLES: dict = {}


def _examples() -> dict:
    """``{step function: data}`` of a default component per compiled step of every registered native type
    (the loop's argument for a step a scenario lacks: never called, but one compiled loop serves all)."""
    if not _EXAMPLES:
        from shevsim.components import REGISTRY, get_component_class
        from shevsim.core.compiled import CompiledStep
        for typ in REGISTRY:
            cls = get_component_class(typ, "fast path")
            if issubclass(cls, CompiledStep):
                for fn, c in cls.fast_examples().items():
                    if fn is not None:
                        _EXAMPLES[fn] = c.data
    return _EXAMPLES


def _key(fn) -> str:
    f = getattr(fn, "py_func", fn)
    return f"{f.__module__}.{f.__qualname__}"


class FastRunner:
    """``runner(t_stop_s) -> Result``: one scenario on the compiled loop (see the module docstring).

    Attributes
    ----------
    scenario : Scenario
    master : Master
        The initialised Python master the template was taken from (not stepped).
    last_wall_s : float
        Wall time of the last run's compiled loop [s].

    Notes
    -----
    A runner reuses its arrays from run to run: call it from one thread at a time (Dask workers run one
    task per process here); build one runner per thread otherwise.
    """

    def __init__(self, scenario, master):
        self.scenario = scenario
        self.master = m = master
        self.h = float(m.settings.step_s)
        self.t0 = float(scenario.t0_s)
        m.initialize(self.t0)
        order = list(m.order)
        comps = [m.components[n] for n in order]
        steps = [_step_of(c, m.step_multiples[c.name] * self.h) for c in comps]
        ins = [[v.name for v in c.variables() if v.causality == "input"] for c in comps]
        outs = [[v.name for v in c.variables() if v.causality == "output"] for c in comps]
        self._names = [f"{n}.{p}" for n, o in zip(order, outs) for p in o]
        if self._names != list(m._signal_names):
            raise Declined("the recorded signals differ from the fast path's layout")
        self.nsig = len(self._names)
        # port layout: outputs in the master's recording order, then inputs
        idx, obase, ibase = {}, [], []
        k = 0
        for n, c, o in zip(order, comps, outs):
            obase.append(k)
            idx.update({(n, p): k + q for q, p in enumerate(o)})
            k += len(o)
        for n, c, i in zip(order, comps, ins):
            ibase.append(k)
            idx.update({(n, p): k + q for q, p in enumerate(i)})
            k += len(i)
        sig = np.zeros(k)
        for n, c, i, o in zip(order, comps, ins, outs):
            sig[[idx[(n, p)] for p in o]] = [float(c.y[p]) for p in o]
            sig[[idx[(n, p)] for p in i]] = [float(c.u[p]) for p in i]
        self._sig0 = sig
        lptr, ldst, lsrc = [0], [], []
        for n in order:
            for cn in m.connections:
                if cn.dst == n:
                    ldst.append(idx[(cn.dst, cn.dst_port)])
                    lsrc.append(idx[(cn.src, cn.src_port)])
            lptr.append(len(ldst))
        # the step functions: every registered type's (one compiled loop for all scenarios) and this one's
        ex = dict(_examples())
        for fn, data, _ in steps:
            ex.setdefault(fn, data)
        self._fns = sorted(ex, key=_key)
        code = {fn: q for q, fn in enumerate(self._fns)}
        by_fn: dict = {fn: [] for fn in self._fns}
        inst = []
        for c, (fn, data, mut) in zip(comps, steps):
            inst.append(len(by_fn[fn]))
            by_fn[fn].append((c, data, mut))
        self._by_fn, self._ex = by_fn, ex
        pending = m.faults[m._faults_done:]
        forced = np.zeros(k, dtype=np.int8)
        for (cn, port) in m._forced:
            forced[idx[(cn, port)]] = 1
        i64 = lambda v: np.array(v, dtype=np.int64)  # noqa: E731
        self._plan = (i64([code[s[0]] for s in steps]), i64([m.step_multiples[n] for n in order]), i64(ibase),
                      i64([len(i) for i in ins]), i64(obase), i64([len(o) for o in outs]), i64(lptr), i64(ldst),
                      i64(lsrc), i64(inst), i64([1 if m.settings.method == "jacobi" else 0]))
        self._faults0 = (np.array([f.at_s for f in pending], dtype=np.float64),
                         i64([idx[(f.component, f.port)] for f in pending]),
                         np.array([f.value for f in pending], dtype=np.float64), forced)
        self._row0 = sig[:self.nsig].copy()
        self._comp_names = order
        self._comps = comps
        self._units = dict(zip(m._signal_names, m._signal_units))
        from shevsim.core.params import params_to_dict
        self._params = {}
        for n, c in m.components.items():
            try:
                self._params[n] = params_to_dict(getattr(c, "params", None))
            except TypeError:
                self._params[n] = {}
        self.last_wall_s = 0.0

    # ------------------------------------------------------------------------------------------
    def n_steps(self, t_stop_s: float) -> int:
        """Communication steps to ``t_stop_s`` (the rule of :meth:`Master.run`)."""
        x = (t_stop_s - self.t0) / self.h
        n_total = round(x) if abs(x - round(x)) <= 1e-9 * max(1.0, abs(x)) else math.ceil(x)
        return max(int(n_total), 0)

    def _kinds(self, n: int) -> tuple:
        """Each step function's tuple of instance data for a run of ``n`` steps (the entries a run mutates
        copied from the template; a component adds what the run length needs, :meth:`fast_data`)."""
        kinds = []
        mult = dict(zip(self._comp_names, self._plan[1].tolist()))
        for fn in self._fns:
            live = []
            for c, data, mut in self._by_fn[fn]:
                d = tuple(a.copy() if j in mut else a for j, a in enumerate(data))
                live.append(c.fast_data(d, -(-n // mult[c.name])))
            kinds.append(tuple(live) if live else (self._ex[fn],))
        return tuple(kinds)

    def __call__(self, t_stop_s: float):
        import time
        from shevsim.core.errors import ScenarioError, SimulationError
        from .loop import ERR_NONFINITE_OUTPUT, compiled_loop
        if not (isinstance(t_stop_s, (int, float)) and math.isfinite(t_stop_s)):
            raise ScenarioError(f"fast path: stop time must be a finite number, got {t_stop_s!r}")
        run_loop = compiled_loop(self._fns)
        n = self.n_steps(float(t_stop_s))
        nsig = self.nsig
        rec = np.empty((nsig, n + 1))          # one row per signal: each signal's samples contiguous
        rec[:, 0] = self._row0
        sig = self._sig0.copy()
        kinds = self._kinds(n)
        faults = self._faults0[:3] + (self._faults0[3].copy(), np.zeros(1, dtype=np.int64))
        out = np.zeros(3, dtype=np.int64)
        wall = time.perf_counter()
        k0 = 0
        # the loop runs in chunks of about CHUNK_WALL_S of wall time: between two chunks Python handles a
        # pending signal (Ctrl-C, SIGTERM), so a stop request is honoured within a chunk, and the rows done so
        # far are returned as the partial result
        chunk = 256
        bar = None
        if getattr(self.master.settings, "progress", False) and n > 1000:
            try:
                from tqdm import tqdm
                bar = tqdm(total=n, unit="step", desc="simulating (compiled)", mininterval=0.5)
            except ImportError:  # pragma: no cover
                bar = None
        try:
            while True:
                todo = min(chunk, n - k0)
                tc = time.perf_counter()
                try:
                    run_loop(todo, k0, self.h, self.t0, self._plan, sig, rec, out, faults, kinds)
                except (ArithmeticError, ValueError, IndexError) as exc:
                    # an exception raised inside compiled code carries no component or time: the caller
                    # (shevsim.run.simulate, engine 'auto') reruns on the Python master, which names them
                    raise FastPathError(f"the compiled loop raised {type(exc).__name__}: {exc} (between t="
                                        f"{self._time(k0):.6g} s and the stop; run with engine 'python' to name "
                                        f"the component and time)") from exc
                if out[0] == ERR_NONFINITE_OUTPUT:
                    row = int(out[1])
                    bad = [j for j in range(nsig) if not math.isfinite(rec[j, row])]
                    if bad:
                        comp, port = self._names[bad[0]].split(".", 1)
                        err = SimulationError(f"component '{comp}' output '{port}' is {float(rec[bad[0], row])!r} "
                                              f"at t={self._time(row):.6g} s (step {row})")
                        raise self._stopped(err, rec, row, comp, port, self._time(row))
                    k0 = row                # a row whose sum overflowed, every value finite: go on
                    if k0 >= n:
                        break
                    continue
                if out[0] != 0:
                    k = int(out[1])
                    j = int(out[2])
                    comp = self._comp_names[j]
                    err = SimulationError(f"component '{comp}' failed in do_step at t={self._time(k):.6g} s "
                                          f"(step {k}): {self._error_text(self._comps[j], int(out[0]))}")
                    raise self._stopped(err, rec, k + 1, comp, None, self._time(k))
                k0 = int(out[1])
                if bar is not None:
                    bar.update(k0 - bar.n)
                if k0 >= n:
                    break
                dt = time.perf_counter() - tc
                chunk = int(min(max(chunk * CHUNK_WALL_S / max(dt, 1e-6), 16), 4 * chunk, 1_000_000))
        except KeyboardInterrupt as exc:    # Ctrl-C / SIGTERM between two chunks: the rows done so far
            from shevsim.core.results import Termination
            reason = getattr(exc, "reason", "interrupted (Ctrl-C)")
            exc.time_s = self._time(k0)
            exc.result = self._result(rec, k0 + 1, Termination("stopped", reason, None, None, exc.time_s))
            raise
        finally:
            if bar is not None:
                bar.close()
            for fn, kd in zip(self._fns, kinds):
                for (c, _, _), d in zip(self._by_fn[fn], kd):
                    c.fast_release(d)
            self.last_wall_s = time.perf_counter() - wall
        return self._result(rec, n + 1, "completed")

    @staticmethod
    def _error_text(c, status: int) -> str:
        return c.STEP_ERRORS.get(status, f"status {status}")

    def _stopped(self, err, rec, nrows, comp, port, t):
        """Attach where/when and the trajectory up to the stop (as the master's errors carry them)."""
        from shevsim.core.results import Termination
        err.component, err.port, err.time_s = comp, port, t
        err.result = self._result(rec, nrows, Termination("stopped", str(err), comp, port, t))
        return err

    def _time(self, k: int) -> float:
        return self.t0 + k * self.h

    def _result(self, rec, nrows, termination):
        from shevsim.core.results import Result
        times = np.empty(nrows)
        if nrows:
            times[0] = self.t0
            times[1:] = self.t0 + np.arange(1, nrows, dtype=np.int64) * self.h
        signals = {name: rec[j, :nrows] for j, name in enumerate(self._names)}
        return Result(times, signals, dict(self._units), {k: dict(v) for k, v in self._params.items()}, termination)


#: wall time of one chunk of the compiled loop (s): the longest wait for a stop request
CHUNK_WALL_S = 0.2


def runner_for(scenario, master=None) -> tuple[Callable | None, str]:
    """``(runner, why)``: a :class:`FastRunner` for ``scenario`` and ``""``, or ``None`` and the reason the
    scenario cannot take the fast path.

    ``runner(t_stop_s)`` returns a :class:`~shevsim.core.results.Result` equal to ``Master.run(t_stop_s,
    t0=scenario.t0_s)`` of the same scenario.  ``master``: a master already built from ``scenario``
    (``build_master``, not yet run) to take the components from instead of building them again; the
    runner initialises it (it must not be stepped by anyone else afterwards).
    """
    from shevsim.core.errors import ShevsimError
    why = _static_reason(scenario)
    if why:
        return None, why
    from shevsim.core.scenario import build_master
    if master is None:
        try:
            master = build_master(scenario)
        except ShevsimError as exc:
            return None, f"the scenario does not build: {exc}"
    why = _component_reason(master)
    if why:
        return None, why
    from shevsim.core.variables import units_compatible
    for c in master.connections:            # the loop copies values: a unit-converting link stays on the master
        su = master._vars[c.src][c.src_port].unit
        du = master._vars[c.dst][c.dst_port].unit
        if not units_compatible(su, du):
            return None, f"connection {c} converts '{su}' to '{du}' (unit conversion runs on the Python master)"
    try:
        return FastRunner(scenario, master), ""
    except Declined as exc:
        return None, str(exc)


def _static_reason(scenario) -> str:
    from numba.core import config as _nb_config
    if _nb_config.DISABLE_JIT:
        return "NUMBA_DISABLE_JIT is set (the fast path is compiled code)"
    from shevsim.components import get_component_class
    from shevsim.core.compiled import CompiledStep
    from shevsim.core.errors import ShevsimError
    for spec in scenario.components:
        if spec.type == "fmu":
            return f"component '{spec.name}' is an FMU"
        try:
            cls = get_component_class(spec.type, "fast path")
        except ShevsimError as exc:
            return str(exc)
        if not issubclass(cls, CompiledStep):
            return f"component '{spec.name}' has type '{spec.type}', which has no compiled step"
    return ""


def _component_reason(master) -> str:
    from shevsim.components import get_component_class
    for n, c in master.components.items():
        typ = getattr(c, "TYPE", None)
        if not _compiled(c):
            return f"component '{n}' has type '{typ}', which has no compiled step"
        if type(c) is not get_component_class(typ, "fast path"):
            return f"component '{n}' ({type(c).__name__}) is not the native '{typ}' class"
    return ""
