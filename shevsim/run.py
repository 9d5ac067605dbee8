"""run.py - run a scenario end to end: load -> build -> simulate -> metrics -> save."""
from __future__ import annotations

import logging
import time
from pathlib import Path

from .core.errors import ShevsimError, SimulationError
from .core.results import Result, git_commit, save_result
from .core.scenario import PROJECT_ROOT, Scenario, build_master, load_scenario, stop_time

log = logging.getLogger(__name__)

DEFAULT_SCENARIO = PROJECT_ROOT / "scenarios" / "hd_udds_mpc.toml"
#: cumulative counters reported in metrics.json as ``component.port``: final value
COUNTER_SUFFIXES = (".fallback_count", ".clamp_count", ".shed_count", ".shed_time_s")


def simulate(scenario: Scenario, progress: bool = False) -> Result:
    """Simulate a loaded scenario and return its result (all signals, or the recorded ones)."""
    master = build_master(scenario)
    master.settings.progress = progress
    t_stop = stop_time(scenario, master)
    wall = time.perf_counter()
    try:
        res = master.run(t_stop, t0=scenario.t0_s)
    finally:
        master.terminate()
    wall = time.perf_counter() - wall
    if scenario.record is not None:
        missing = [s for s in scenario.record if s not in res.signals]
        if missing:
            raise ShevsimError(f"{scenario.path or '<scenario>'}: [record] unknown signal(s) {missing}")
        keep = set(scenario.record)
        res.signals = {k: v for k, v in res.signals.items() if k in keep}
        res.units = {k: v for k, v in res.units.items() if k in keep}
    res.meta.update({"scenario": scenario.name, "seed": scenario.seed, "wall_s": wall,
                     "step_s": scenario.settings.step_s, "method": scenario.settings.method,
                     "order": master.order, "resolved_scenario": scenario.resolved()})
    return res


def compute_run_metrics(res: Result, scenario: Scenario) -> dict:
    """Scenario metrics (SHEV metrics when the SHEV signals are present)."""
    try:
        from .metrics import compute_metrics
    except ImportError:  # pragma: no cover
        return {}
    out = {}
    # robustness counters every run reports (QP fallbacks, power demands clamped by the battery,
    # generator load shedding): final value of every recorded counter; fallbacks and clamping logged
    for name, values in res.signals.items():
        if name.endswith(COUNTER_SUFFIXES) and len(values):
            out[name] = float(values[-1])
            if values[-1] > 0 and name.endswith((".fallback_count", ".clamp_count")):   # anomalies, not operation
                log.warning("%s: %s = %g at the end of the run", scenario.name, name, values[-1])
    if "vehicle.speed_mps" not in res.signals:
        return out
    out.update(compute_metrics(res.to_pandas(), {"scenario": scenario.metrics, "parameters": res.parameters}))
    return out


def run_scenario(path: str | Path | None = None, out: str | Path | None = None, sets=(), progress: bool = False,
                 plots: bool = True, save: bool = True, overlays=()) -> tuple[Result, dict, Path | None]:
    """Run a scenario file; save under ``out`` (default ``results/<name>/``); ``overlays`` are
    ``COMPONENT=FILE`` parameter overlays (``--params``)."""
    scenario = load_scenario(path or DEFAULT_SCENARIO, sets, overlays=overlays)
    res = simulate(scenario, progress=progress)
    metrics = compute_run_metrics(res, scenario)
    metrics["wall_s"] = res.meta["wall_s"]
    out_dir = None
    if save:
        out_dir = Path(out) if out else Path("results") / scenario.name
        plot_fn = None
        if plots:
            from .plotting import scenario_plots
            plot_fn = scenario_plots
        res.meta["git_commit"] = git_commit()
        res.meta["sets"] = list(scenario.sets)
        res.meta["overlays"] = list(scenario.overlays)
        text = scenario.text
        if scenario.overlays:
            text = "".join(f"# run with --params {o}\n" for o in scenario.overlays) + text
        if scenario.sets:   # the scenario as run: the command-line overrides on top of the file
            text = "".join(f"# run with --set {s}\n" for s in scenario.sets) + text
        save_result(res, out_dir, scenario_text=text, metrics=metrics, plots=plot_fn)
    return res, metrics, out_dir
