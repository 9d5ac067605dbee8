"""run.py - run a scenario end to end: load -> check -> simulate -> judge -> metrics -> save.

[`run()`][shevsim.run.run] is what ``shevsim.simulate`` and ``shevsim run`` call. A run never loses what it
simulated: a run stopped by a non-finite value, a plant limit, a component or FMU failure, or Ctrl-C
returns (and saves) the trajectory up to the stop with `Result.termination` saying why, where
and when; a metric that cannot be computed is None with a note; the output folder is checked before
the simulation starts.

Engines: ``engine="python"`` steps the components with `Master`;
``"fast"`` uses the compiled fast path (`shevsim.fast`, when installed and when the scenario is
eligible, else an error); ``"auto"`` uses the fast path when it can and the master otherwise.
``res.meta["engine"]`` records which one ran.
"""
from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .core.errors import FastPathError, ScenarioError, ShevsimError, SimulationError
from .core.results import Result, Termination, beside_folder, check_out_dir, git_commit, holds_result, save_result
from .core.scenario import (PROJECT_ROOT, Scenario, build_master, check_metrics_options, load_scenario,
                            shared_metrics, stop_time)

log = logging.getLogger(__name__)

DEFAULT_SCENARIO = PROJECT_ROOT / "scenarios" / "hd_udds_mpc.toml"
#: cumulative counters reported in metrics.json as ``component.port``: final value
COUNTER_SUFFIXES = (".fallback_count", ".clamp_count", ".shed_count", ".shed_time_s")
ENGINES = ("auto", "python", "fast")

#: a run is refused before it starts when its record would need more than this fraction of the
#: memory available now, or when it has more than MAX_STEPS communication steps (override:
#: ``allow_large=True`` / ``--allow-large``)
MEMORY_FRACTION = 0.5
MAX_STEPS = 50_000_000
#: conservative per-step wall time used for the duration estimate in the refusal message (s/step)
STEP_WALL_S = 2e-5

#: speed-trace check defaults (overridable in the scenario's [metrics] table or with
#: ``--set metrics.trace_...``): the run is 'degraded' when it covers less than
#: ``1 - trace_distance_tolerance`` of the cycle's distance, or when the speed error stays above
#: ``trace_speed_tolerance_kmh`` for longer than ``trace_speed_window_s``; ``trace_allow_miss = true``
#: turns both into notes
TRACE_DEFAULTS = {"trace_distance_tolerance": 0.05, "trace_speed_tolerance_kmh": 10.0,
                  "trace_speed_window_s": 30.0, "trace_allow_miss": False}


# --------------------------------------------------------------------------- checks before running
def available_memory_bytes() -> int | None:
    """Memory available to a new allocation now (``MemAvailable``; None when unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def run_size(n_steps: int, n_signals: int, record_every: int = 1) -> dict:
    """Estimate of a run's record (bytes) and wall time (s) from its size."""
    rows = n_steps // max(1, record_every) + 2
    # the record buffer, its copy into the result, and a DataFrame when it is saved
    nbytes = int(rows * (n_signals + 1) * 8 * 3)
    return {"steps": int(n_steps), "rows": int(rows), "signals": int(n_signals), "record_bytes": nbytes,
            "wall_s_estimate": n_steps * STEP_WALL_S}


def check_run_size(n_steps: int, n_signals: int, record_every: int = 1, *, allow_large: bool = False,
                   memory_bytes: int | None = None, where: str = "<scenario>") -> dict:
    """Refuse (ScenarioError) a run far beyond what this machine holds, before it starts."""
    est = run_size(n_steps, n_signals, record_every)
    if allow_large:
        return est
    avail = available_memory_bytes() if memory_bytes is None else memory_bytes
    too_big = avail is not None and est["record_bytes"] > MEMORY_FRACTION * avail
    too_long = n_steps > MAX_STEPS
    if too_big or too_long:
        why = []
        if too_big:
            why.append(f"its record needs ~{est['record_bytes'] / 1e9:.3g} GB ({est['rows']} points x "
                       f"{n_signals} signals) but {avail / 1e9:.3g} GB are available")
        if too_long:
            why.append(f"{n_steps} communication steps (> {MAX_STEPS}; at least "
                       f"~{est['wall_s_estimate'] / 3600:.3g} h)")
        raise ScenarioError(f"{where}: run refused before starting: {'; '.join(why)}. Shorten stop_s, record "
                            f"less ([record] signals, --record-every N), or override with --allow-large "
                            f"(allow_large=True)")
    return est


def check_faults_in_run(scenario: Scenario, t_stop: float) -> None:
    """A fault before the start of the run, or one that would act only at or after its end (it never
    acts), is an error."""
    h, t0 = scenario.settings.step_s, scenario.t0_s
    for i, f in enumerate(scenario.faults):
        if f.at_s < t0 - 1e-9 * max(1.0, abs(t0)):
            raise ScenarioError(f"{scenario.path or '<scenario>'}: [[faults]] #{i + 1} at_s = {f.at_s} s "
                                f"({f.component}.{f.port}) is before the start of the run (t0_s = {t0:g} s); a "
                                f"fault acts from a time within the run [{t0:g} s, {t_stop:g} s)")
        k = max(0, math.ceil((f.at_s - t0) / h - 1e-9 * max(1.0, abs(f.at_s) / h)))
        if t0 + k * h >= t_stop - 1e-9 * max(1.0, abs(t_stop)):
            raise ScenarioError(f"{scenario.path or '<scenario>'}: [[faults]] #{i + 1} at_s = {f.at_s} s "
                                f"({f.component}.{f.port}) is at or after the end of the run ({t_stop:g} s): "
                                f"it would never act")


#: the reason given when ``engine="auto"`` runs the master because the layout's loop is not built yet
#: (`shevsim.warmup`); such a run starts the background build when it has finished
NOT_BUILT = "the compiled loop for this component layout is not built yet"


def _fast_runner(scenario: Scenario, engine: str, master=None, n_steps: int = 0):
    """(runner, why): the fast path's runner for ``scenario`` or None with the reason.

    ``engine="auto"`` takes the fast path only when its loop is built for this layout or the run is long
    enough to pay for building it (`shevsim.warmup.choose()`)."""
    if engine not in ENGINES:
        raise ScenarioError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "python":
        return None, "engine 'python' requested"
    try:
        from . import fast
        from .fast import runner_for
    except ImportError as exc:
        if engine == "fast":
            raise ScenarioError(f"engine 'fast': the fast path is not available ({exc})") from None
        return None, f"no fast path ({exc})"
    if engine == "auto":
        static = getattr(fast, "_static_reason", None)
        why = static(scenario) if static is not None else ""
        if why:
            return None, why
        from .warmup import choose
        use, why = choose(scenario, n_steps, len(scenario.components))
        if not use:
            return None, why
    runner, why = runner_for(scenario, master)      # reuses the master built by simulate (one build)
    if runner is None and engine == "fast":
        raise ScenarioError(f"engine 'fast': scenario '{scenario.name}' is not eligible for the fast path: {why}")
    return runner, why


def _drop_non_finite_tail(res: Result) -> None:
    """The master records a row before checking it: a run stopped by a non-finite output keeps the
    trajectory up to the last finite row (the value that stopped it is in the termination reason)."""
    if len(res.time_s) and res.signals:
        last = np.array([v[-1] for v in res.signals.values()], dtype=float)
        if not np.all(np.isfinite(last)):
            res.time_s = res.time_s[:-1]
            res.signals = {k: v[:-1] for k, v in res.signals.items()}


def _guess_port(exc: BaseException, master) -> None:
    """A component's own error names the port it is about as ``port=value`` (``soc_pct=100.6``):
    take the first such port of that component when the error does not say it otherwise."""
    import re
    comp = getattr(exc, "component", None)
    if comp is None or getattr(exc, "port", None) is not None or comp not in getattr(master, "_vars", {}):
        return
    text = str(exc)
    hits = [(m.start(), name) for name in master._vars[comp]
            for m in [re.search(rf"(?<![\w.]){re.escape(name)}\s*=", text)] if m]
    if hits:
        exc.port = min(hits)[1]


class Terminated(KeyboardInterrupt):
    """Raised by the command line's SIGTERM handler: the run stops like on Ctrl-C and saves what it has."""

    reason = "interrupted (SIGTERM)"


def _interrupt_reason(exc: BaseException) -> str:
    return getattr(exc, "reason", "interrupted (Ctrl-C)")


def _stop_info(exc: BaseException) -> Termination:
    if isinstance(exc, KeyboardInterrupt):
        return Termination("stopped", _interrupt_reason(exc), None, None, getattr(exc, "time_s", None))
    return Termination("stopped", str(exc), getattr(exc, "component", None), getattr(exc, "port", None),
                       getattr(exc, "time_s", None))


# ------------------------------------------------------------------------------------ simulation
def simulate(scenario: Scenario, progress: bool = False, *, engine: str = "auto", partial: bool = False,
             record_every: int = 1, allow_large: bool = False) -> Result:
    """Simulate a loaded scenario and return its result (all signals, or the recorded ones).

    Parameters
    ----------
    scenario : Scenario
    progress : bool
        Progress bar on long runs.
    engine : {'auto', 'python', 'fast'}
        See the module docstring; ``res.meta["engine"]`` says which ran.
    partial : bool
        False (default): a run stopped by a `SimulationError` (or Ctrl-C) raises it, with the
        trajectory up to the stop attached as ``exc.result``. True: return that trajectory with
        ``termination`` set (status 'stopped', reason, component, port, time).
    record_every : int
        Keep every k-th communication point (and the last).
    allow_large : bool
        Run even when the run-size check would refuse it.
    """
    if isinstance(record_every, bool) or not isinstance(record_every, int) or record_every < 1:
        raise ScenarioError(f"record_every must be an integer >= 1, got {record_every!r}")
    where = str(scenario.path or "<scenario>")
    master = build_master(scenario)
    master.settings.progress = progress
    master.record_every = record_every
    try:
        t_stop = stop_time(scenario, master)
        check_faults_in_run(scenario, t_stop)
        x = (t_stop - scenario.t0_s) / scenario.settings.step_s
        if x < 1.0 - 1e-9:
            raise ScenarioError(f"{where}: [scenario] step_s = {scenario.settings.step_s:g} s is longer than the run "
                                f"({t_stop - scenario.t0_s:g} s from t0_s = {scenario.t0_s:g} s to {t_stop:g} s): "
                                f"not one communication step fits; use a step of at most the run's length")
        check_run_size(int(math.ceil(x)), len(master._signal_names), record_every,
                       allow_large=allow_large, where=where)
        runner, why = _fast_runner(scenario, engine, master, int(math.ceil(x)))
    except BaseException:
        master.terminate()
        raise
    wall = time.perf_counter()
    used = "python"
    if runner is not None:
        master.terminate()
        used = "fast"
        try:
            res = runner(t_stop)
        except FastPathError as exc:
            if engine != "auto":
                res = Result(np.zeros(0), {}, {}, {}, _stop_info(exc))
                if not partial:
                    exc.result = res
                    raise
            else:   # an exception inside compiled code names no component or time: rerun on the master
                log.warning("%s: fast path failed (%s); rerunning on the Python master", where, exc)
                why = f"the fast path failed ({exc}); ran on the Python master"
                runner = None
                master = build_master(scenario)
                master.settings.progress = progress
                master.record_every = record_every
                used = "python"
        except (SimulationError, KeyboardInterrupt) as exc:
            res = getattr(exc, "result", None)
            if res is None:
                res = Result(np.zeros(0), {}, {}, {}, _stop_info(exc))
            res.termination = _stop_info(exc)
            if not partial:
                exc.result = res
                raise
        if runner is not None and record_every > 1 and len(res.time_s) > 2:
            keep = np.unique(np.r_[np.arange(0, len(res.time_s), record_every), len(res.time_s) - 1])
            res.time_s = res.time_s[keep]
            res.signals = {k: v[keep] for k, v in res.signals.items()}
    if runner is None:
        try:
            try:
                res = master.run(t_stop, t0=scenario.t0_s)
            except (SimulationError, KeyboardInterrupt) as exc:
                _guess_port(exc, master)
                res = master.result(_stop_info(exc))
                _drop_non_finite_tail(res)
                if isinstance(exc, KeyboardInterrupt):      # the time of the last row kept
                    res.termination = Termination("stopped", _interrupt_reason(exc), None, None,
                                                  float(res.time_s[-1]) if len(res.time_s) else master.time_s)
                if not partial:
                    _finish(res, scenario, master, time.perf_counter() - wall, used, why)
                    exc.result = res
                    raise
        finally:
            master.terminate()
    _finish(res, scenario, master, time.perf_counter() - wall, used, why)
    _after_engine(res, scenario, used, why)
    return res


def _after_engine(res: Result, scenario: Scenario, used: str, why: str) -> None:
    """Record a layout whose loop a completed fast run built; after a master run that waited for no loop
    (`NOT_BUILT`), start the background build for the next runs (``res.meta["warmup_pid"]``)."""
    from . import warmup
    try:
        if used == "fast" and res.termination.ok and not warmup.is_compiled(scenario):
            warmup.mark_compiled(scenario)
        elif used == "python" and why.startswith(NOT_BUILT):
            pid = warmup.start_background(scenario)
            if pid is not None:
                res.meta["warmup_pid"] = pid
                log.info("%s: building the compiled loop for this layout in the background (pid %d)",
                         scenario.name, pid)
    except Exception as exc:  # noqa: BLE001 - bookkeeping of the compile cache never fails a run
        log.debug("compile bookkeeping: %s", exc)


def _finish(res: Result, scenario: Scenario, master, wall: float, engine: str, why: str) -> None:
    if scenario.record is not None:
        missing = [s for s in scenario.record if s not in res.signals and len(res.signals)]
        if missing:
            raise ShevsimError(f"{scenario.path or '<scenario>'}: [record] unknown signal(s) {missing}")
        keep = set(scenario.record)
        res.signals = {k: v for k, v in res.signals.items() if k in keep}
        res.units = {k: v for k, v in res.units.items() if k in keep}
    res.meta.update({"scenario": scenario.name, "seed": scenario.seed, "wall_s": wall,
                     "step_s": scenario.settings.step_s, "method": scenario.settings.method,
                     "order": master.order, "engine": engine,
                     "metrics_options": dict(scenario.metrics),
                     "resolved_scenario": scenario.resolved()})
    if engine != "fast":
        res.meta["fast_path"] = why


# --------------------------------------------------------------------------------- judging a run
def check_trace_options(options: Mapping[str, Any], where: str = "<scenario>") -> None:
    """Refuse (ScenarioError) trace-check options out of range: ``trace_distance_tolerance`` in [0, 1],
    ``trace_speed_tolerance_kmh`` and ``trace_speed_window_s`` >= 0, ``trace_allow_miss`` true/false."""
    ranges = {"trace_distance_tolerance": (0.0, 1.0), "trace_speed_tolerance_kmh": (0.0, math.inf),
              "trace_speed_window_s": (0.0, math.inf)}
    for key, (lo, hi) in ranges.items():
        if key in options:
            v = options[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi) or math.isnan(v):
                raise ScenarioError(f"{where}: [metrics] {key} = {v!r}: valid range [{lo:g}, {hi:g}]")
    if "trace_allow_miss" in options and not isinstance(options["trace_allow_miss"], bool):
        raise ScenarioError(f"{where}: [metrics] trace_allow_miss = {options['trace_allow_miss']!r}: "
                            f"expected true/false")


def trace_signals(scenario: Scenario) -> tuple[str, str] | None:
    """``(vehicle speed, cycle reference speed)`` signal names of a scenario with one component of type
    ``vehicle`` and one of type ``cycle`` (whatever their names), else None."""
    veh = [c.name for c in scenario.components if c.type == "vehicle"]
    cyc = [c.name for c in scenario.components if c.type == "cycle"]
    if len(veh) == 1 and len(cyc) == 1:
        return f"{veh[0]}.speed_mps", f"{cyc[0]}.speed_ref_mps"
    return None


def trace_check(res: Result, options: Mapping[str, Any] | None = None, speed: str = "vehicle.speed_mps",
                ref_speed: str = "cycle.speed_ref_mps") -> Termination | None:
    """A 'degraded' termination when a completed run missed its speed trace beyond tolerance
    (distance shortfall or a sustained speed error), else None. ``speed`` and ``ref_speed`` name the
    vehicle's and the cycle's speed signals (`trace_signals()`); see [`TRACE_DEFAULTS`][shevsim.run.TRACE_DEFAULTS] for the
    options."""
    opts = {**TRACE_DEFAULTS, **{k: v for k, v in dict(options or {}).items() if k in TRACE_DEFAULTS}}
    if opts["trace_allow_miss"] is True or speed not in res.signals \
            or ref_speed not in res.signals or len(res.time_s) < 2:
        return None
    t = np.asarray(res.time_s, float)
    v = np.asarray(res[speed], float)
    ref = np.asarray(res[ref_speed], float)
    comp, port = speed.split(".", 1)
    dt = np.diff(t)
    d_ref = float(np.sum(0.5 * (ref[1:] + ref[:-1]) * dt))
    d_veh = float(np.sum(0.5 * (v[1:] + v[:-1]) * dt))
    tol = float(opts["trace_distance_tolerance"])
    if d_ref > 0 and d_veh < (1.0 - tol) * d_ref:
        return Termination("degraded", f"trace miss: the vehicle covered {d_veh / 1000:.4g} km of the cycle's "
                           f"{d_ref / 1000:.4g} km (shortfall {100 * (1 - d_veh / d_ref):.3g} % > "
                           f"{100 * tol:.3g} % tolerance; [metrics] trace_distance_tolerance / trace_allow_miss)",
                           comp, port, None)
    err = np.abs(v - ref) * 3.6 > float(opts["trace_speed_tolerance_kmh"])
    window = float(opts["trace_speed_window_s"])
    if np.any(err):
        # longest run of consecutive samples with the error above tolerance
        edges = np.diff(np.r_[0, err.astype(np.int8), 0])
        starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
        lengths = t[np.minimum(ends, len(t) - 1)] - t[starts]
        i = int(np.argmax(lengths))
        if lengths[i] > window:
            return Termination("degraded", f"trace miss: speed error above {opts['trace_speed_tolerance_kmh']:g} "
                               f"km/h for {lengths[i]:.4g} s from t={t[starts[i]]:.6g} s (> {window:g} s; "
                               f"[metrics] trace_speed_tolerance_kmh / trace_speed_window_s / trace_allow_miss)",
                               comp, port, float(t[starts[i]]))
    return None


def compute_run_metrics(res: Result, scenario: Scenario | None = None) -> dict:
    """Scenario metrics (SHEV metrics when the SHEV signals are present). Never raises: a metric
    that cannot be computed is None and ``notes`` says why."""
    from .metrics import result_metrics
    opts = None
    if scenario is not None:
        try:
            opts = {**shared_metrics(scenario), **scenario.metrics}   # the fuel's density from [shared]
        except ShevsimError:
            opts = dict(scenario.metrics)        # refused before the run (check_run); never raises here
    out = result_metrics(res, opts)
    for name, values in res.signals.items():
        if name.endswith((".fallback_count", ".clamp_count")) and len(values) and values[-1] > 0:
            log.warning("%s: %s = %g at the end of the run", res.meta.get("scenario", ""), name, values[-1])
    return out


# ----------------------------------------------------------------------------- the one pipeline
def _as_scenario(scenario, sets=(), overlays=()) -> Scenario:
    if isinstance(scenario, Scenario):
        if sets or overlays:
            raise ScenarioError("sets/overlays apply when loading a scenario; use overrides= for a Scenario object")
        return scenario.copy()
    if scenario is None:
        scenario = DEFAULT_SCENARIO
    if not isinstance(scenario, (str, Path)):
        raise ScenarioError(f"scenario must be a bundled name, a path or a Scenario, got {type(scenario).__name__}")
    return load_scenario(scenario, list(sets), overlays=list(overlays))


def run(scenario: str | Path | Scenario | None = None, overrides: Mapping[str, Any] | None = None, *,
        stop_s: float | None = None, out: str | Path | None = None, engine: str = "auto",
        sets=(), overlays=(), record: list[str] | None = None, record_every: int = 1,
        plots: bool = False, progress: bool = False, allow_large: bool = False, save: bool | None = None,
        scenario_text: str | None = None, fmt: str = "parquet", vehicle: str | None = None,
        cycle: str | None = None) -> Result:
    """Load, check, simulate, judge, compute metrics and (when ``out``) save one run.

    ``vehicle`` (a bundled vehicle's name or a vehicle file) and ``cycle`` (a bundled cycle's name or a
    CSV) run the scenario's powertrain and supervisors on another vehicle / drive cycle
    (`Scenario.use`).

    Stopped runs are returned (and saved) with their termination; they do not raise.
    ``res.meta["out"]`` is the folder written (when saved); ``fmt`` is the trajectory's format there
    (``"parquet"``, ``"csv"`` or ``"mat"``).
    """
    from .core.results import TIMESERIES_FORMATS
    if fmt not in TIMESERIES_FORMATS:
        raise ScenarioError(f"format must be one of {', '.join(TIMESERIES_FORMATS)}, got {fmt!r}")
    sc = _as_scenario(scenario, sets, overlays)
    sc.use(vehicle, cycle)
    for k, v in dict(overrides or {}).items():
        sc.set(k, v, f"overrides['{k}']")
    if stop_s is not None:
        sc.set("scenario.stop_s", stop_s, "stop_s=")
    if record is not None:
        sc.set("record.signals", list(record), "record=")
    check_trace_options(sc.metrics, str(sc.path or "<scenario>"))
    shared_metrics(sc)       # a [metrics] value contradicting a shared quantity: refused before running
    check_metrics_options(sc.metrics, f"{sc.path or '<scenario>'}: [metrics]")   # also when changed by attribute
    trace = trace_signals(sc)
    if trace and sc.record is not None and sc.metrics.get("trace_allow_miss") is not True:
        missing = [x for x in trace if x not in sc.record]
        if missing:          # the trace check needs them: recorded too (a partial record must not hide a miss)
            log.info("%s: %s recorded too (the speed-trace check needs them)", sc.name, ", ".join(missing))
            sc.record = list(sc.record) + missing
    out_dir = None
    if save is None:
        save = out is not None
    if save:
        out_dir = check_out_dir(Path(out) if out else Path("results") / sc.name)   # before running
    res = simulate(sc, progress=progress, engine=engine, partial=True, record_every=record_every,
                   allow_large=allow_large)
    if res.termination.ok:
        degraded = trace_check(res, sc.metrics, *trace) if trace else None
        if degraded is not None:
            res.termination = degraded
    res.metrics = compute_run_metrics(res, sc)
    res.metrics["wall_s"] = res.meta["wall_s"]
    if scenario_text is None:
        scenario_text = sc.text or sc.to_toml()
        if sc.overlays:
            scenario_text = "".join(f"# run with --params {o}\n" for o in sc.overlays) + scenario_text
        if sc.sets:   # the scenario as run: the command-line overrides on top of the file
            scenario_text = "".join(f"# run with --set {s}\n" for s in sc.sets) + scenario_text
        if overrides:
            scenario_text = "".join(f"# run with overrides[{k!r}] = {v!r}\n"
                                    for k, v in dict(overrides).items()) + scenario_text
        if vehicle is not None or cycle is not None:
            scenario_text = sc.to_toml()      # the scenario as run, on that vehicle and cycle
    res.meta["scenario_text"] = scenario_text
    res.meta["sets"] = list(sc.sets)
    res.meta["overlays"] = list(sc.overlays)
    if save:
        res.meta["git_commit"] = git_commit()
        plot_fn = None
        interrupted = is_interrupted(res.termination)
        if plots and not interrupted:          # an interrupted run is saved at once, without figures
            from .plotting import scenario_plots
            plot_fn = scenario_plots
        if interrupted and holds_result(out_dir):
            # a stopped run never replaces an earlier result: its partial result goes to a new folder beside
            # it (NAME-interrupted-<UTC time>) and the earlier one stays as it was
            res.meta["earlier_result_kept"] = str(out_dir)
            out_dir = beside_folder(out_dir, "interrupted")
        save_result(res, out_dir, scenario_text=scenario_text, metrics=res.metrics, plots=plot_fn, fmt=fmt)
        res.meta["out"] = str(out_dir)
    return res


def is_interrupted(term) -> bool:
    """True for the termination of a run stopped by Ctrl-C / SIGINT / SIGTERM."""
    term = Termination.coerce(term)
    return term.status == "stopped" and term.reason.startswith("interrupted")


def run_scenario(path: str | Path | None = None, out: str | Path | None = None, sets=(), progress: bool = False,
                 plots: bool = True, save: bool = True, overlays=(), **kw) -> tuple[Result, dict, Path | None]:
    """Run a scenario file; save under ``out`` (default ``results/<name>/``); ``overlays`` are
    ``COMPONENT=FILE`` parameter overlays (``--params``). Returns ``(result, metrics, folder)``;
    keyword arguments go to [`run()`][shevsim.run.run] (``engine``, ``record_every``, ``allow_large``...)."""
    res = run(path, out=out, sets=sets, overlays=overlays, progress=progress, plots=plots, save=save, **kw)
    out_dir = Path(res.meta["out"]) if "out" in res.meta else None
    return res, res.metrics, out_dir
