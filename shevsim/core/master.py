"""master.py - the fixed-step, multi-rate co-simulation master.

One communication step of length ``h`` from ``t`` to ``t + h`` (Gauss-Seidel)::

    for comp in order:                     # order from the connection graph
        if step_index % comp.multiple == 0:
            copy its connected inputs        # sources earlier in the order are at t + h already
            comp.do_step(t, multiple * h)  # a multi-rate component covers [t, t + k h]
    t = t + h; record every output; stop on NaN/inf (component, port, time)

Jacobi copies *all* inputs from the outputs at ``t`` first, then steps every
component, so the result does not depend on the order.

The order is a topological order of the component graph in which only
direct-feedthrough edges are mandatory: a component whose output depends
directly on an input must run after that input's source. A cycle made only of
feedthrough edges is an algebraic loop and is reported with every
``component.port`` in it. Other cycles (through a state) are broken where the
declaration order puts them. A cycle of components that is not a cycle of ports
(A's output feeds B's feedthrough input and B's output feeds another of A's
feedthrough inputs) cannot be stepped in one Gauss-Seidel pass either: it is broken
at the component with the fewest unplaced feedthrough predecessors (ties: the
scenario's declaration order) and the connections that then carry the previous
step's value are listed in :attr:`Master.delayed` and by ``shevsim info``.
"""
from __future__ import annotations

import math
import time as _time
from array import array
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any, Iterable, Sequence

import numpy as np

from .errors import AlgebraicLoopError, ConnectionError_, ScenarioError, SimulationError
from .variables import units_compatible
from .units import check_connection, link_source
from .results import Result


@dataclass
class MasterSettings:
    """Settings of a run.

    Parameters
    ----------
    step_s : float
        Communication step (s).
    method : {'gauss-seidel', 'jacobi'}
    progress : bool
        Show a progress bar (tqdm) on long runs.
    """

    step_s: float = 0.1
    method: str = "gauss-seidel"
    progress: bool = False

    def check(self) -> None:
        if not (isinstance(self.step_s, (int, float)) and self.step_s > 0 and math.isfinite(self.step_s)):
            raise ScenarioError(f"master: step_s must be a positive number, got {self.step_s!r}")
        if self.method not in ("gauss-seidel", "jacobi"):
            raise ScenarioError(f"master: method must be 'gauss-seidel' or 'jacobi', got {self.method!r}")


@dataclass(frozen=True)
class Connection:
    """``dst.dst_port`` (an input) takes the value of ``src.src_port`` (an output)."""

    src: str
    src_port: str
    dst: str
    dst_port: str

    @classmethod
    def parse(cls, dst: str, src: str) -> "Connection":
        try:
            d, dp = dst.split(".", 1)
            s, sp = src.split(".", 1)
        except ValueError:
            raise ConnectionError_(f"connection '{dst}' = '{src}': both ends must be 'component.port'") from None
        return cls(s, sp, d, dp)

    def __str__(self) -> str:
        return f"{self.src}.{self.src_port} -> {self.dst}.{self.dst_port}"


@dataclass(frozen=True)
class Fault:
    """From ``at_s`` on, input ``component.port`` is forced to ``value`` (its connection is cut)."""

    at_s: float
    component: str
    port: str
    value: float


@dataclass
class MasterState:
    """A whole-system snapshot (see :meth:`Master.save_state`)."""

    step_index: int
    time_s: float
    components: dict[str, Any]
    n_rows: int
    forced: dict
    faults_done: int
    t0: float = 0.0


class Master:
    """Fixed-step multi-rate co-simulation master.

    Parameters
    ----------
    components : sequence of components (native or FMU adapters)
    connections : sequence of :class:`Connection`
    settings : MasterSettings
    step_multiples : dict, optional
        ``{name: k}``: the component steps every ``k`` communication steps.
    faults : sequence of :class:`Fault`, optional
    order : sequence of str, optional
        Explicit Gauss-Seidel order (every component once). Connections into
        feedthrough inputs that then run against the order are reported in
        :attr:`delayed` (they carry the previous step's value).
    """

    def __init__(self, components: Sequence, connections: Iterable[Connection],
                 settings: MasterSettings | None = None,
                 step_multiples: dict[str, int] | None = None,
                 faults: Iterable[Fault] = (), order: Sequence[str] | None = None):
        self.settings = settings or MasterSettings()
        self.settings.check()
        self.components = {}
        for c in components:
            if c.name in self.components:
                raise ScenarioError(f"duplicate component name '{c.name}'")
            self.components[c.name] = c
        self.connections = list(connections)
        self.step_multiples = {n: 1 for n in self.components}
        for n, k in (step_multiples or {}).items():
            if n not in self.components:
                raise ScenarioError(f"step multiple given for unknown component '{n}'")
            if isinstance(k, bool) or not isinstance(k, int) or k < 1:
                raise ScenarioError(f"component '{n}': step_multiple must be an integer >= 1, got {k!r}")
            self.step_multiples[n] = k
        self.faults = sorted(faults, key=lambda f: f.at_s)
        self._vars = {n: {v.name: v for v in c.variables()} for n, c in self.components.items()}
        self._check_depends_on()
        self._check_connections()
        for f in self.faults:
            self._port(f.component, f.port, "input", f"fault at {f.at_s} s")
        self.order = self._execution_order(order)
        self._build_links()
        self.step_index = 0
        self.time_s = 0.0
        self.t0 = 0.0
        self._buf = array("d")           # recorded rows, flat (row-major, len(_signal_names) per row)
        self._times: list[float] = []
        self._forced: dict[tuple[str, str], float] = {}
        self._faults_done = 0
        self._initialized = False
        #: keep every k-th communication point in the record (the last one always); 1 keeps all
        self.record_every = 1

    # ------------------------------------------------------------------ checks
    def _port(self, comp: str, port: str, want: str, ctx: str):
        if comp not in self.components:
            import difflib
            best = difflib.get_close_matches(comp, list(self.components), n=1)
            hint = f" (did you mean '{best[0]}'?)" if best else ""
            raise ConnectionError_(f"{ctx}: unknown component '{comp}'{hint}")
        vs = self._vars[comp]
        if port not in vs or vs[port].causality != want:
            why = getattr(self.components[comp], "not_connectable", None)
            why = why(port) if callable(why) else None
            if why:                     # an FMU's String/Binary/Clock variable: a value, never a port
                raise ConnectionError_(f"{ctx}: {why}")
            import difflib
            cands = [n for n, v in vs.items() if v.causality == want]
            best = difflib.get_close_matches(port, cands, n=1)
            hint = f" (did you mean '{best[0]}'?)" if best else f" ({want}s: {', '.join(cands) or 'none'})"
            raise ConnectionError_(f"{ctx}: component '{comp}' has no {want} '{port}'{hint}")
        return vs[port]

    def _check_depends_on(self) -> None:
        # a misspelt feedthrough dependency would silently drop an ordering constraint
        for n, vs in self._vars.items():
            for v in vs.values():
                for i in (v.depends_on if v.causality == "output" else ()):
                    if i not in vs or vs[i].causality != "input":
                        raise ScenarioError(f"component '{n}' output '{v.name}' depends_on '{i}', but the component "
                                            f"has no such input{_port_hint(i, vs)}")

    def _check_connections(self) -> None:
        seen = {}
        for c in self.connections:
            ctx = f"connection {c}"
            so = self._port(c.src, c.src_port, "output", ctx)
            di = self._port(c.dst, c.dst_port, "input", ctx)
            key = (c.dst, c.dst_port)
            if key in seen:
                raise ConnectionError_(f"{ctx}: input {c.dst}.{c.dst_port} is already connected to "
                                       f"{seen[key].src}.{seen[key].src_port}")
            seen[key] = c
            if not units_compatible(so.unit, di.unit):   # another scale of one dimension converts (core/units.py)
                check_connection(self.components[c.src], so.unit, self.components[c.dst], di.unit,
                                 f"{ctx}: output {c.src}.{c.src_port} in '{so.unit}', input {c.dst}.{c.dst_port}")

    def _execution_order(self, given: Sequence[str] | None = None) -> list[str]:
        names = list(self.components)
        # port-level feedthrough graph: output node -> input node (connection), input -> output (depends_on)
        succ: dict[tuple, list[tuple]] = {}
        for c in self.connections:
            succ.setdefault((c.src, "out", c.src_port), []).append((c.dst, "in", c.dst_port))
        for n, vs in self._vars.items():
            for v in vs.values():
                if v.causality == "output":
                    for i in v.depends_on:
                        succ.setdefault((n, "in", i), []).append((n, "out", v.name))
        cycle = _find_cycle(succ)
        if cycle:
            ports = " -> ".join(f"{c}.{p}" for c, _, p in cycle)
            comps = sorted({c for c, _, _ in cycle})
            raise AlgebraicLoopError(f"algebraic loop (a cycle of direct feedthrough) through components "
                                     f"{', '.join(comps)}: {ports}")
        # mandatory component edges: src -> dst when dst's input feeds an output directly
        ft_inputs = {n: {i for v in vs.values() if v.causality == "output" for i in v.depends_on}
                     for n, vs in self._vars.items()}
        hard: dict[str, set[str]] = {n: set() for n in names}
        soft: dict[str, set[str]] = {n: set() for n in names}
        for c in self.connections:
            if c.src == c.dst:
                continue
            (hard if c.dst_port in ft_inputs[c.dst] else soft)[c.dst].add(c.src)
        order: list[str] = []
        placed: set[str] = set()
        remaining = list(names)
        if given is not None:
            given = list(given)
            unknown = [n for n in given if n not in self.components]
            if unknown:
                raise ScenarioError(f"execution order names unknown component(s) {unknown}")
            if sorted(given) != sorted(names):
                missing = [n for n in names if n not in given]
                raise ScenarioError(f"execution order must list every component exactly once (missing: {missing})")
            order, remaining = given, []
        while remaining:
            # prefer a component whose predecessors are all placed; else one whose feedthrough
            # predecessors are; else (a cycle of components without a cycle of ports) the one with
            # the fewest unplaced feedthrough predecessors, ties in declaration order
            pick = next((n for n in remaining if (hard[n] | soft[n]) <= placed), None)
            if pick is None:
                pick = next((n for n in remaining if hard[n] <= placed), None)
            if pick is None:
                pick = min(remaining, key=lambda n: (len(hard[n] - placed), names.index(n)))
            order.append(pick)
            placed.add(pick)
            remaining.remove(pick)
        # connections into a feedthrough input whose source runs later: they carry the value of the
        # previous communication step (reported by describe())
        pos = {n: i for i, n in enumerate(order)}
        self._order_given = given is not None
        jacobi = self.settings.method == "jacobi"     # Jacobi: every input holds the previous step's value
        self.delayed = [c for c in self.connections
                        if c.dst_port in ft_inputs[c.dst] and c.src != c.dst and (jacobi or pos[c.src] > pos[c.dst])]
        return order

    def _build_links(self) -> None:
        self._links: dict[str, list[tuple[dict, str, dict, str]]] = {n: [] for n in self.components}
        for c in self.connections:
            src = self.components[c.src]
            su, du = self._vars[c.src][c.src_port].unit, self._vars[c.dst][c.dst_port].unit
            # y itself, or a view converting the unit (kW -> W, degC -> K): resolved here, once
            sy = src.y if units_compatible(su, du) else link_source(src, su, self.components[c.dst], du, str(c))
            self._links[c.dst].append((self.components[c.dst].u, c.dst_port, sy, c.src_port))
        self._signal_names: list[str] = []
        self._signal_units: list[str] = []
        self._signal_src: list[tuple[dict, str]] = []
        # recording: one C-level getter per component returning its outputs as a tuple
        self._rec: list[tuple[dict, Any]] = []
        for n in self.order:
            comp = self.components[n]
            keys = []
            for v in self._vars[n].values():
                if v.causality == "output":
                    self._signal_names.append(f"{n}.{v.name}")
                    self._signal_units.append(v.unit)
                    self._signal_src.append((comp.y, v.name))
                    keys.append(v.name)
            if len(keys) > 1:
                self._rec.append((comp.y, itemgetter(*keys)))
            elif keys:
                self._rec.append((comp.y, lambda y, _k=keys[0]: (y[_k],)))
        self._sched = [(self.components[n], self._links[n], self.step_multiples[n]) for n in self.order]

    # ----------------------------------------------------------------- running
    def initialize(self, t0: float = 0.0) -> None:
        """Initialise every component at ``t0`` in execution order (sources first)."""
        self.t0 = self.time_s = float(t0)
        self.step_index = 0
        if not math.isfinite(self.t0):
            raise ScenarioError(f"master: start time t0 must be a finite number, got {t0!r}")
        # a re-initialisation starts over: no fault is active before its time
        self._forced = {}
        self._faults_done = 0
        self._build_links()
        self._apply_faults()
        for comp, links, _ in self._sched:
            for du, dk, sy, sk in links:
                du[dk] = sy[sk]
            self._apply_forced(comp)
            try:
                comp.initialize(self.t0)
            except SimulationError as exc:
                raise _where(exc, comp.name, None, self.t0)
            except Exception as exc:
                raise _where(SimulationError(f"component '{comp.name}' failed to initialise at t={self.t0:.6g} s: "
                                             f"{type(exc).__name__}: {exc}"), comp.name, None, self.t0) from exc
        self._buf = array("d")
        self._times = []
        self._record()
        self._initialized = True

    def _apply_forced(self, comp) -> None:
        for (cn, port), val in self._forced.items():
            if cn == comp.name:
                comp.u[port] = val

    def _apply_faults(self) -> None:
        eps = 1e-9 * max(1.0, abs(self.time_s))
        while self._faults_done < len(self.faults) and self.faults[self._faults_done].at_s <= self.time_s + eps:
            f = self.faults[self._faults_done]
            self._forced[(f.component, f.port)] = float(f.value)
            comp = self.components[f.component]
            comp.u[f.port] = float(f.value)
            self._links[f.component] = [l for l in self._links[f.component] if l[1] != f.port]
            self._sched = [(self.components[n], self._links[n], self.step_multiples[n]) for n in self.order]
            self._faults_done += 1

    def _record(self) -> None:
        buf = self._buf
        n0 = len(buf)
        s = 0.0
        try:
            for y, get in self._rec:
                vals = get(y)
                buf.extend(vals)
                s += sum(vals)
        except (TypeError, OverflowError):
            del buf[n0:]
            self._record_checked()
            return
        self._times.append(self.time_s)
        if not math.isfinite(s):
            self._check_row([y[k] for y, k in self._signal_src])

    def _record_checked(self) -> None:
        """Slow path of :meth:`_record` for rows with values that are not plain numbers."""
        row = [y[k] for y, k in self._signal_src]
        self._check_row(row)
        self._buf.extend([float(v) for v in row])
        self._times.append(self.time_s)

    def _check_row(self, row) -> None:
        """Raise :class:`SimulationError` naming the first non-finite (or non-numeric) output."""
        for (name, val) in zip(self._signal_names, row):
            try:
                ok = math.isfinite(val)
            except TypeError:
                ok = False
            if not ok:
                comp, port = name.split(".", 1)
                raise _where(SimulationError(f"component '{comp}' output '{port}' is {val!r} at "
                                             f"t={self.time_s:.6g} s (step {self.step_index})"),
                             comp, port, self.time_s)

    def step(self) -> None:
        """Advance the whole system by one communication step."""
        h = self.settings.step_s
        t = self.time_s
        k = self.step_index
        if self._faults_done < len(self.faults):
            self._apply_faults()
        if self.settings.method == "jacobi":
            for comp, links, m in self._sched:
                if k % m == 0:
                    for du, dk, sy, sk in links:
                        du[dk] = sy[sk]
            # snapshot semantics: every component above read outputs at t; now step them all
            for comp, links, m in self._sched:
                if k % m == 0:
                    self._do_step(comp, t, m * h)
        else:
            comp = None
            try:
                for comp, links, m in self._sched:
                    if m == 1 or k % m == 0:
                        for du, dk, sy, sk in links:
                            du[dk] = sy[sk]
                        comp.do_step(t, m * h)
            except SimulationError as exc:
                raise _where(exc, comp.name, None, t)
            except Exception as exc:
                raise _step_failure(comp, t, self.step_index, exc) from exc
        self.step_index = k + 1
        self.time_s = self.t0 + self.step_index * h
        if self.record_every == 1 or self.step_index % self.record_every == 0:
            self._record()
        else:                             # decimated: not kept, still checked for non-finite outputs
            self._check_only()

    def _check_only(self) -> None:
        """Check a step that decimated recording does not keep (non-finite outputs stop the run)."""
        s = 0.0
        try:
            for y, get in self._rec:
                s += sum(get(y))
        except (TypeError, OverflowError):
            s = math.nan
        if not math.isfinite(s):
            self._check_row([y[k] for y, k in self._signal_src])

    def _do_step(self, comp, t: float, h: float) -> None:
        try:
            comp.do_step(t, h)
        except SimulationError as exc:
            raise _where(exc, comp.name, None, t)
        except Exception as exc:
            raise _step_failure(comp, t, self.step_index, exc) from exc

    def run(self, stop_s: float, t0: float = 0.0) -> Result:
        """Initialise (if needed) and step until ``stop_s``; return the result."""
        if not (isinstance(stop_s, (int, float)) and math.isfinite(stop_s)):
            raise ScenarioError(f"master: stop time must be a finite number, got {stop_s!r}")
        if not self._initialized:
            self.initialize(t0)
        # end at the first communication point at or after stop_s (a stop time that is a multiple
        # of the step, up to rounding, is hit exactly)
        x = (stop_s - self.t0) / self.settings.step_s
        n_total = round(x) if abs(x - round(x)) <= 1e-9 * max(1.0, abs(x)) else math.ceil(x)
        n = int(n_total) - self.step_index
        termination = "completed"
        bar = None
        if self.settings.progress and n > 1000:
            try:
                from tqdm import tqdm
                bar = tqdm(total=n, unit="step", desc="simulating", mininterval=0.5)
            except ImportError:  # pragma: no cover
                bar = None
        wall = _time.perf_counter()
        try:
            if bar is None:
                step = self.step
                for _ in range(n):
                    step()
            else:
                for i in range(n):
                    self.step()
                    if i % 500 == 499:
                        bar.update(500)
                bar.update(n - bar.n)
        finally:
            if bar is not None:
                bar.close()
            self.wall_s = _time.perf_counter() - wall
        if self.record_every > 1 and (not self._times or self._times[-1] != self.time_s):
            self._record()                # a decimated record still ends at the stop time
        return self.result(termination)

    def result(self, termination: str = "completed") -> Result:
        nsig = len(self._signal_names)
        # whole rows only: a run interrupted (Ctrl-C, SIGTERM) in the middle of recording a row keeps the
        # rows before it
        rows = min(len(self._buf) // nsig, len(self._times)) if nsig else len(self._times)
        data = np.frombuffer(self._buf, dtype=np.float64)[:rows * nsig].copy().reshape(-1, nsig) if nsig else \
            np.zeros((rows, 0))
        signals = {name: data[:, j] for j, name in enumerate(self._signal_names)}
        times = np.array(self._times[:rows])
        units = dict(zip(self._signal_names, self._signal_units))
        params = {}
        for n, c in self.components.items():
            p = getattr(c, "params", None)
            from .params import params_to_dict
            try:
                params[n] = params_to_dict(p)
            except TypeError:
                params[n] = {}
        return Result(times, signals, units, params, termination)

    def terminate(self) -> None:
        for comp in self.components.values():
            comp.terminate()

    # ------------------------------------------------------------ save/restore
    def save_state(self) -> MasterState:
        """Snapshot of the whole system (components, time, recorded length, faults)."""
        return MasterState(self.step_index, self.time_s,
                           {n: c.get_state() for n, c in self.components.items()},
                           len(self._times), dict(self._forced), self._faults_done, self.t0)

    def restore_state(self, s: MasterState) -> None:
        """Return to a snapshot made by :meth:`save_state`; later records are dropped.

        When the recorded history does not reach the snapshot (restoring into a fresh master, or a
        later snapshot after an earlier one was restored), the record restarts at the snapshot, so
        the result's time vector never has a gap.
        """
        for n, c in self.components.items():
            c.set_state(s.components[n])
        self.step_index = s.step_index
        self.time_s = s.time_s
        self.t0 = s.t0
        self._initialized = True     # run() continues from the snapshot (also in a fresh master)
        fresh_record = len(self._times) < s.n_rows
        if fresh_record:
            # the recorded history does not reach the snapshot (a fresh master, or a snapshot taken
            # after an earlier one that was restored since): start a new, contiguous record at the
            # snapshot instead of leaving a gap in time
            del self._buf[:]
            del self._times[:]
        else:
            del self._buf[s.n_rows * len(self._signal_names):]
            del self._times[s.n_rows:]
        self._forced = dict(s.forced)
        self._faults_done = s.faults_done
        # components' u/y dicts may be new objects after set_state: rebuild the links
        self._build_links()
        for (cn, port) in self._forced:
            self._links[cn] = [l for l in self._links[cn] if l[1] != port]
        self._sched = [(self.components[n], self._links[n], self.step_multiples[n]) for n in self.order]
        if fresh_record:
            self._record()

    def describe(self) -> str:
        """Human-readable summary: components, ports with units, connections, order."""
        lines = ["components (execution order):"]
        for n in self.order:
            c = self.components[n]
            lines.append(f"  {n}  [{type(c).__name__}]  step x{self.step_multiples[n]}")
            for v in self._vars[n].values():
                if v.causality in ("input", "output"):
                    dep = f"  (feedthrough from {', '.join(v.depends_on)})" if v.depends_on else ""
                    lines.append(f"      {v.causality:6s} {v.name:28s} [{v.unit}]  {v.description}{dep}")
        lines.append("connections:")
        delayed = set(self.delayed)
        why = ("Jacobi" if self.settings.method == "jacobi" else
               "source runs later in the given order" if self._order_given else "component cycle broken here")
        for c in self.connections:
            note = f"   (one-step delay: {why})" if c in delayed else ""
            lines.append(f"  {c}{note}")
        unconnected = [f"{n}.{v.name}" for n, vs in self._vars.items() for v in vs.values()
                       if v.causality == "input" and not any(c.dst == n and c.dst_port == v.name for c in self.connections)]
        if unconnected:
            lines.append("unconnected inputs (held at start value): " + ", ".join(unconnected))
        return "\n".join(lines)


def _step_failure(comp, t: float, step_index: int, exc: BaseException) -> Exception:
    """The error for a component whose ``do_step`` raised something that is not a :class:`SimulationError`.
    A compiled step that numba cannot compile (a user's component: numba's typing or lowering error) is the
    component's code, not the run: a :class:`ScenarioError` naming the component, numba's first line and the
    rule of :func:`shevsim.core.compiled.njit_step` (steps and their callees allocate nothing)."""
    if type(exc).__module__.startswith("numba.") and type(exc).__name__ in ("TypingError", "LoweringError",
                                                                           "UnsupportedError", "NumbaError"):
        import re
        text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))            # numba colours its messages
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        what = next((ln for ln in lines if ln.startswith(("No implementation", "Cannot", "Unknown attribute",
                                                          "Use of unsupported"))), lines[0] if lines else "")
        where = next((ln.rstrip(":") for ln in reversed(lines) if ln.startswith("File ")), "")
        return ScenarioError(
            f"component '{comp.name}' (type {getattr(comp, 'TYPE', type(comp).__name__)}): its compiled step does "
            f"not compile: {what}{' (' + where + ')' if where else ''}. A step compiled with "
            f"shevsim.core.compiled.njit_step runs without numba's runtime, and so do the functions it calls: they "
            f"may not allocate (np.empty, a copying slice, an exception with a run-time message); scratch arrays "
            f"belong in the component's data tuple, allocated in initialize. numba's message: "
            f"{type(exc).__name__}: {text}")
    return _where(SimulationError(f"component '{comp.name}' failed in do_step at t={t:.6g} s (step {step_index}): "
                                  f"{type(exc).__name__}: {exc}"), comp.name, None, t)



def _where(exc: SimulationError, component: str | None, port: str | None, time_s: float | None):
    """Attach where a run stopped (``component``, ``port``, ``time_s``) to ``exc`` unless it already says."""
    if getattr(exc, "component", None) is None:
        exc.component = component
    if getattr(exc, "port", None) is None:
        exc.port = port
    if getattr(exc, "time_s", None) is None:
        exc.time_s = None if time_s is None else float(time_s)
    return exc


def _port_hint(name: str, vs: dict) -> str:
    import difflib
    cands = [k for k, v in vs.items() if v.causality == "input"]
    best = difflib.get_close_matches(name, cands, n=1)
    return f" (did you mean '{best[0]}'?)" if best else f" (inputs: {', '.join(cands) or 'none'})"


def _find_cycle(succ: dict[tuple, list[tuple]]) -> list[tuple] | None:
    """Return one cycle of the directed graph ``succ`` as a node list, or None."""
    WHITE, GREY, BLACK = 0, 1, 2
    color: dict[tuple, int] = {}
    for root in list(succ):
        if color.get(root, WHITE) != WHITE:
            continue
        stack = [(root, iter(succ.get(root, ())))]
        path = [root]
        color[root] = GREY
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                color[node] = BLACK
                stack.pop()
                path.pop()
                continue
            c = color.get(nxt, WHITE)
            if c == GREY:
                return path[path.index(nxt):] + [nxt]
            if c == WHITE:
                color[nxt] = GREY
                stack.append((nxt, iter(succ.get(nxt, ()))))
                path.append(nxt)
    return None
