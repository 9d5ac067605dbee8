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

Studies and calibration take the command line's options as keyword arguments
([`run_study()`][shevsim.api.run_study], [`run_calibration()`][shevsim.api.run_calibration]).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .core.errors import ScenarioError, ShevsimError
from .core.results import Result, load_result
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


def _flat_params(params: Mapping[str, Any]) -> dict[str, str]:
    import json
    out = {}
    for comp, p in (params or {}).items():
        if isinstance(p, Mapping):
            for k, v in p.items():
                out[f"{comp}.{k}"] = json.dumps(v, sort_keys=True, default=str)
        else:
            out[str(comp)] = json.dumps(p, sort_keys=True, default=str)
    return out


def run_labels(results: Sequence[Result], fallback: Sequence[str] | None = None) -> list[str]:
    """One distinct label per result: ``res.meta["label"]`` when set, else the scenario name; runs of the same
    name are told apart by the parameters in which they differ (``hd_udds_mpc (vehicle.mass_kg=18000)``),
    else by ``fallback`` (e.g. their folder names), else numbered (``#2``)."""
    import json
    results = list(results)
    base = []
    for i, r in enumerate(results):
        lab = r.meta.get("label") or r.meta.get("scenario") or (fallback[i] if fallback else None) or f"run {i + 1}"
        base.append(str(lab))
    out = list(base)
    for name in set(base):
        group = [i for i, b in enumerate(base) if b == name]
        if len(group) < 2:
            continue
        flat = [_flat_params(results[i].parameters) for i in group]
        keys = sorted(set().union(*flat))
        differ = [k for k in keys if len({f.get(k) for f in flat}) > 1]
        for j, i in enumerate(group):
            parts = []
            for k in differ[:2]:
                v = flat[j].get(k)
                v = "unset" if v is None else json.loads(v)
                parts.append(f"{k}={v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{k}={v}")
            if parts:
                out[i] = f"{name} ({', '.join(parts)}{', ...' if len(differ) > 2 else ''})"
            elif fallback and len({fallback[g] for g in group}) == len(group):
                out[i] = f"{name} ({fallback[i]})"
            else:
                out[i] = f"{name} #{j + 1}"
    counts = {lab: out.count(lab) for lab in out}
    seen: dict[str, int] = {}
    for i, lab in enumerate(out):            # still equal (the same differences shown): number them
        if counts[lab] > 1:
            seen[lab] = seen.get(lab, 0) + 1
            out[i] = f"{lab} #{seen[lab]}"
    return out


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
_APPEND = {"set", "map", "params"}      # options given once per value on the command line


def _argv(positional: Sequence[Any], options: Mapping[str, Any]) -> list[str]:
    argv = [str(p) for p in positional if p is not None]
    for key, val in options.items():
        flag = "--" + key.replace("_", "-")
        if val is None or val is False:
            continue
        if val is True:
            argv.append(flag)
        elif isinstance(val, (list, tuple)):
            if key in _APPEND:
                for v in val:
                    argv += [flag, str(v)]
            else:
                argv += [flag, *[str(v) for v in val]]
        elif isinstance(val, Mapping) and key in _APPEND:
            for k, v in val.items():
                argv += [flag, f"{k}={v}"]
        else:
            argv += [flag, str(val)]
    return argv


def _call_cli(fn, argv: list[str], what: str) -> int:
    import contextlib
    import io
    quiet = "--quiet" in argv or "-q" in argv
    try:
        with contextlib.redirect_stdout(io.StringIO()) if quiet else contextlib.nullcontext():
            return int(fn(argv))
    except SystemExit as exc:          # argparse: a bad option
        code = exc.code if isinstance(exc.code, int) else 2
        if code:
            raise ScenarioError(f"{what}: bad arguments {argv} (see the message above)") from None
        return 0


def run_study(which: str, scenario: str | Path | None = None, *, out: str | Path | None = None, **options) -> dict:
    """Run a study (``tradeoff``, ``powerrate-map``, ``thermal``, ``bms``) with the CLI's options.

    ``scenario`` is a scenario file or a bundled scenario's name.

    Keyword arguments are the options of ``shevsim study WHICH --help`` with ``_`` for ``-``
    (``workers=0``, ``stop_s=120.0``, ``rates_kwps=[10, 20]``, ``set=["cycle.repeat=1"]``,
    ``synthetic=True``); the study writes its tables and figures to ``out``.

    Returns
    -------
    dict
        ``exit_code`` (0 ok; see ``shevsim --help``) and ``out`` (the folder, when given).

    Raises
    ------
    ShevsimError
        When the study exits non-zero (its message is printed on stderr).
    """
    from .core.paths import bundled_scenario
    from .studies.cli import main_study
    if scenario is not None and not Path(scenario).is_file() and bundled_scenario(str(scenario)) is not None:
        scenario = bundled_scenario(str(scenario))          # a bundled scenario by name
    argv = [which] + _argv([scenario], {"out": out, **options})
    code = _call_cli(main_study, argv, f"study {which}")
    if code != 0:
        raise ShevsimError(f"study {which} failed with exit code {code} (arguments {argv[1:]})")
    return {"exit_code": code, "out": Path(out) if out is not None else None}


def run_calibration(model: str, data: str | Path, *, out: str | Path, **options) -> dict:
    """Calibrate a model (``shevsim calibrate --help``: battery cell, vehicle, engine) on a measured
    CSV with the CLI's options (``_`` for ``-``: ``map={"current_a": "I"}``, ``effects=[...]``,
    ``params="FILE"``). Writes ``out`` (params.toml, report.json, report.md, figures).

    Returns
    -------
    dict
        ``exit_code``, ``out`` and ``report`` (the parsed ``report.json`` when written).
    """
    import json

    from .calibrate.cli import main_calibrate
    argv = _argv([model, data], {"out": out, **options})
    code = _call_cli(main_calibrate, argv, "calibrate")
    if code != 0:
        raise ShevsimError(f"calibrate {model} failed with exit code {code} (arguments {argv})")
    rep = Path(out) / "report.json"
    return {"exit_code": code, "out": Path(out),
            "report": json.loads(rep.read_text()) if rep.is_file() else None}
