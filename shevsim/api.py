"""api.py - the Python API of shevsim (exported from ``shevsim``).

Run a bundled scenario, change parameters with typed values, read the results:

    import shevsim
    res = shevsim.simulate("hd_udds_rule", overrides={"vehicle.mass_kg": 18000.0, "cycle.repeat": 1})
    df = res.to_pandas()                 # time_s + one column per component.port (units in the names)
    res.metrics["fuel_economy_raw_kmpl"]
    res.termination                      # 'completed', or 'stopped: ...' / 'degraded: ...' with details
    res.plot(["vehicle.speed_mps", "cycle.speed_ref_mps", "battery.soc_pct"])   # one axis per unit

Inspect and change a scenario before running, or build one in code:

    sc = shevsim.load_scenario("hd_udds_rule")
    sc.component("vehicle").overrides["mass_kg"] = 20000.0
    sc.set("scenario.step_s", 0.2)
    res = shevsim.simulate(sc, stop_s=120.0)

Studies and calibration return objects ([`run_study()`][shevsim.api.run_study]: a
[`StudyResult`][shevsim.studies.result.StudyResult]; [`run_calibration()`][shevsim.api.run_calibration]: a
[`CalibrationReport`][shevsim.calibrate.report.CalibrationReport]); the command line calls them and prints.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .core.errors import ScenarioError, ShevsimError
from .core.results import Result, load_result, run_labels
from .core.scenario import Scenario, new_scenario
from .core.scenario import load_scenario as _load_scenario

__all__ = ["simulate", "load_scenario", "new_scenario", "compare", "metrics_table", "run_labels", "load_result",
           "scenarios", "vehicles", "run_study", "run_calibration", "Scenario", "Result"]


def simulate(scenario: str | Path | Scenario, overrides: Mapping[str, Any] | None = None, *,
             stop_s: float | None = None, out: str | Path | None = None, engine: str = "auto",
             record: Sequence[str] | None = None, record_every: int = 1, plots: bool = False,
             progress: bool = False, allow_large: bool = False, vehicle: str | None = None,
             cycle: str | None = None) -> Result:
    """Simulate a scenario and return its [`Result`][shevsim.core.results.Result].

    Parameters
    ----------
    scenario : str, Path or Scenario
        A bundled scenario's name (``"hd_udds_rule"``, see [`scenarios()`][shevsim.api.scenarios]), a scenario file, or a
        [`Scenario`][shevsim.core.scenario.Scenario] (from [`load_scenario()`][shevsim.api.load_scenario] or [`new_scenario()`][shevsim.api.new_scenario];
        it is copied, not changed).
    overrides : mapping, optional
        Typed values by ``"component.param"`` (``{"vehicle.mass_kg": 18000.0, "cycle.repeat": 1}``),
        ``"scenario.FIELD"`` (``step_s``, ``stop_s``, ``t0_s``, ``method``, ``seed``, ``name``),
        ``"record.signals"`` or ``"metrics.OPTION"``. Checked like the scenario file's values; an
        error names the override.
    stop_s : float, optional
        Stop time (s); default the scenario's, else the cycle's length.
    out : str or Path, optional
        Save the run there (timeseries.parquet with units, run.json, metrics.json, scenario.toml).
        Checked before the simulation starts.
    engine : {'auto', 'python', 'fast'}
        ``'python'``: the co-simulation master; ``'fast'``: the compiled fast path (error when
        unavailable or not eligible); ``'auto'``: fast when possible. ``res.meta["engine"]`` says which.
    record : sequence of str, optional
        Keep only these signals (``component.port``).
    record_every : int
        Keep every k-th communication point (and the last).
    plots : bool
        Write ``overview.png`` with the saved run.
    progress : bool
        Progress bar on long runs.
    allow_large : bool
        Run even when the record or duration estimate exceeds what this machine holds.
    vehicle, cycle : str, optional
        Run the scenario's powertrain and supervisors on a bundled vehicle (`shevsim.vehicles()`, e.g.
        ``"city_bus"``) or a vehicle file, and/or on a bundled cycle (``"orange_county_bus"``) or a
        cycle CSV.

    Returns
    -------
    Result
        Also when the run stopped early (non-finite value, plant limit, FMU failure, Ctrl-C): the
        trajectory up to the stop with ``res.termination.status == "stopped"`` and its ``reason``,
        ``component``, ``port`` and ``time_s``. A run that reached its stop time but missed its speed
        trace is ``"degraded"``.

    Raises
    ------
    ScenarioError
        Bad input (unknown scenario, component, parameter or value; unusable ``out``), before running.
    """
    from .run import run
    return run(scenario, overrides, stop_s=stop_s, out=out, engine=engine, record=([record] if isinstance(record, str) else list(record)) if record else None,
               record_every=record_every, plots=plots, progress=progress, allow_large=allow_large,
               vehicle=vehicle, cycle=cycle)


def load_scenario(scenario: str | Path | None = None, overrides: Mapping[str, Any] | None = None, *,
                  params: Iterable[str] = (), text: str | None = None) -> Scenario:
    """Load a scenario (bundled name or file) into an object to inspect and change.

    Parameters
    ----------
    scenario : str or Path
        Bundled name or path.
    overrides : mapping, optional
        Typed overrides as in [`simulate()`][shevsim.api.simulate].
    params : iterable of str
        Parameter overlays ``[COMPONENT=]FILE`` (the CLI's ``--params``, e.g. a calibration's params.toml).
    text : str, optional
        The scenario as TOML text instead of a file (``scenario`` may then be omitted), e.g. a few lines
        that ``extends = "hd_udds_mpc"`` and change the ``[shared]`` quantities.

    Returns
    -------
    Scenario
        ``.components`` (specs with ``.type``, ``.params_file``, ``.overrides``), ``.connections``,
        ``.faults``, ``.settings.step_s``, ``.stop_s``; change with ``.set(key, value)``,
        ``.add_component``, ``.connect``, ``.add_fault``; ``.to_toml()`` writes it out.
    """
    if isinstance(scenario, Scenario):
        sc = scenario.copy()
    elif text is not None:
        sc = _load_scenario(scenario, text=text, overlays=list(params))
    else:
        sc = _load_scenario(scenario, overlays=list(params))
    for k, v in dict(overrides or {}).items():
        sc.set(k, v, f"overrides['{k}']")
    return sc


def vehicles() -> dict[str, dict[str, Any]]:
    """The bundled vehicles: ``{name: {"description", "source", "shared": {quantity: value}}}``
    (``shevsim vehicles`` prints them; run one with ``simulate(SCENARIO, vehicle=NAME)``)."""
    from .components.shared import bundled_vehicles, load_vehicle
    out = {}
    for n in bundled_vehicles():
        v = load_vehicle(n)
        out[n] = {"description": v.description, "source": v.source, "shared": dict(v.shared), "path": str(v.path)}
    return out


def scenarios() -> list[str]:
    """Names of the bundled scenarios (``shevsim scenarios`` lists them with their descriptions)."""
    from .core.paths import bundled_scenarios
    return bundled_scenarios()


def compare(results: Sequence[Result], signals: Sequence[str] | str, *, labels: Sequence[str] | None = None,
            ax=None):
    """Overlay ``signals`` of several runs, one axis per display unit (kW, km/h, degC...); returns the
    matplotlib Figure (its axes: ``fig.axes``).

    Parameters
    ----------
    results : sequence of Result
    signals : sequence of str or str
        ``component.port`` names present in every result.
    labels : sequence of str, optional
        One per result (default: `run_labels()`).
    ax : Axes or sequence of Axes, optional
    """
    from .plotting import plot_signals
    if isinstance(signals, str):
        signals = [signals]
    if not results:
        raise ShevsimError("compare: no results given")
    return plot_signals(list(results), list(signals), ax=ax, labels=labels)


def metrics_table(results: Sequence[Result] | Mapping[str, Result], keys: Sequence[str] | None = None, *,
                  labels: Sequence[str] | None = None):
    """A pandas DataFrame of scalar metrics, one row per run, plus a ``termination`` column.

    Rows are labelled by ``labels``, by the keys of a ``{label: result}`` mapping, or by
    `run_labels()` (``res.meta["label"]`` or the scenario name; same-named runs by the parameters
    in which they differ), so no two rows share a label. Column units are in ``df.attrs["units"]``."""
    import pandas as pd

    from .report.labels import metric_label
    if isinstance(results, Mapping):
        if labels is not None:
            raise ShevsimError("metrics_table: give labels either as the mapping's keys or as labels=, not both")
        labels = [str(k) for k in results]
        results = list(results.values())
    results = list(results)
    if labels is not None:
        labels = [str(x) for x in labels]
        if len(labels) != len(results):
            raise ShevsimError(f"metrics_table: {len(labels)} labels for {len(results)} results")
        if len(set(labels)) != len(labels):
            dup = sorted({x for x in labels if labels.count(x) > 1})
            raise ShevsimError(f"metrics_table: labels must be distinct; repeated: {dup}")
    rows = []
    for r in results:
        m = r.metrics
        ks = keys if keys is not None else [k for k, v in m.items()
                                            if isinstance(v, (int, float)) and not isinstance(v, bool) or v is None]
        row = {k: m.get(k) for k in ks}
        row["termination"] = str(r.termination)
        rows.append(row)
    idx = labels if labels is not None else run_labels(results)
    df = pd.DataFrame(rows, index=pd.Index(idx, name="run"))
    df.attrs["units"] = {c: metric_label(c)[1] for c in df.columns if c != "termination"}
    return df


# --------------------------------------------------------------------- studies and calibration
def run_study(which: str, scenario: str | Path | None = None, *, out: str | Path | None = None, **options):
    """Run a study (``tradeoff``, ``powerrate-map``, ``thermal``, ``bms``) and return its
    `StudyResult` (tables as DataFrames, ``best_map``, ``plot()``, ``save()``).

    ``scenario`` is a scenario file or a bundled scenario's name; ``out`` saves the files the command
    ``shevsim study WHICH --out DIR`` writes. Options: `shevsim.studies.result.run_study`
    (``workers=0``, ``stop_s=120.0``, ``set={"cycle.repeat": 1}``, ``synthetic=True``, ``plots=False``
    and the study's own, e.g. ``rates_kwps=[30, 20]``):

    Examples
    --------
    ```python
    st = shevsim.run_study("tradeoff", "uac_proxy_mpc", rates_kwps=[30, 20, 10], workers=2)
    st.tables["tradeoff"]; st.best_map; st.plot(); st.save("out/tradeoff")
    ```
    """
    from .studies.result import run_study as _run
    return _run(which, scenario, out=out, **options)


def run_calibration(model: str, data: str | Path, *, out: str | Path | None = None, **options):
    """Calibrate a model (battery cell, vehicle, engine) on a measured CSV and return its
    `CalibrationReport` (selected effects, ``before_after``, ``overlay``,
    ``replay``, ``plot()``, ``save()``).

    ``out`` saves the files ``shevsim calibrate ... --out DIR`` writes (params.toml, report.json,
    report.md, figures). Options: `shevsim.calibrate.report.run_calibration`
    (``params="ocv.toml"``, ``map={"time_s": "Time", "current_a": "I"}``, ``current_sign=...``,
    ``effects=[...]``, ``holdout=0.3``):

    Examples
    --------
    ```python
    cal = shevsim.run_calibration("cell", "record.csv", map={"time_s": "Time", "current_a": "I"})
    cal.selected_effects; cal.before_after; cal.overlay; cal.plot(); cal.save("out/cal")
    ```
    """
    from .calibrate.report import run_calibration as _run
    return _run(model, data, out=out, **options)
