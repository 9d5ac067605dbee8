"""result.py - run a study from Python and get an object back: `run_study` and `StudyResult`.

    import shevsim
    st = shevsim.run_study("tradeoff", "uac_proxy_mpc", rates_kwps=[30, 20, 10], workers=2)
    st                      # <StudyResult tradeoff: 3 rates ...>, a table in a notebook
    st.tables["tradeoff"]   # pandas DataFrame (units in the column names)
    st.best_map             # the best map (power-rate map study) or the best constant rate (trade-off)
    fig = st.plot()         # matplotlib Figure
    st.save("out/tradeoff") # the same files ``shevsim study tradeoff --out out/tradeoff`` writes

The command line (`shevsim.studies.cli`) parses its options, calls `run_study` and prints
the result; nothing here reads ``sys.argv`` or prints.
"""
from __future__ import annotations

import difflib
import io
import json
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from ..core.errors import ScenarioError, ShevsimError

#: the studies and their own options with defaults (the options every study of evaluations takes are
#: the keyword arguments of `run_study`)
STUDY_OPTIONS: dict[str, dict[str, Any]] = {
    "tradeoff": {"rates_kwps": (30, 27.5, 25, 22.5, 20, 19.3, 17.5, 15, 12.5, 10, 7.5, 5), "fe_loss_pct": 0.5},
    "powerrate-map": {"levels_kwps": None, "generations": 50, "population": 30, "crossover": 0.8,
                      "mutation": 0.01, "seed": 0, "fe_loss_pct": 0.4, "top_k": 10, "max_cases": 648,
                      "unique_population": False, "fill_cases": True},
    "thermal": {},
    "bms": {"seed": 1, "quick": False, "only": ("dekf", "thermal", "power")},
}
#: studies that evaluate a scenario many times (through the evaluation cache, serial or on Dask)
EVALUATION_STUDIES = ("tradeoff", "powerrate-map")
#: the evaluation cache is the study's working state, not one of its outputs (``save`` leaves it out)
CACHE_NAME = "cache.sqlite"
MARKER = "summary.json"


def _csv_frame(data: bytes):
    """A CSV the studies wrote as a DataFrame; leading ``#`` lines go to ``df.attrs["note"]``."""
    import pandas as pd
    text = data.decode("utf-8")
    lines = text.splitlines(keepends=True)
    k = 0
    while k < len(lines) and lines[k].startswith("#"):
        k += 1
    df = pd.read_csv(io.StringIO("".join(lines[k:])))
    if k:
        df.attrs["note"] = "".join(lines[:k]).strip()
    return df


@dataclass(repr=False)
class StudyResult:
    """What a study found: its summary, its tables and figures, and the files its command writes.

    Attributes
    ----------
    study : str
        ``tradeoff``, ``powerrate-map``, ``thermal`` or ``bms``.
    summary : dict
        The study's summary (``summary.json`` of the trade-off, the map and the BMS studies;
        ``thermal_verification.json`` of the thermal study).
    files : dict of str to bytes
        The output files by relative path (tables as CSV, figures as PNG, the summary as JSON),
        exactly what ``shevsim study ... --out DIR`` writes, without the evaluation cache.
    out : Path or None
        Where the files were saved (``out=`` of `run_study`, or the last `save`).
    notes : list of str
        Warnings of the run (failed evaluations), also what the command line prints on stderr.
    exit_code : int
        0, or 1 when every evaluation failed (the command's exit status).
    """

    study: str
    summary: dict
    files: dict[str, bytes] = field(default_factory=dict)
    out: Path | None = None
    notes: list[str] = field(default_factory=list)
    exit_code: int = 0

    # ------------------------------------------------------------------ what a user reads
    @property
    def tables(self) -> dict:
        """The study's tables as pandas DataFrames, by file stem (``tradeoff``, ``top_solutions``,
        ``exhaustive``, ``ga_history``, ``constant_limits``, ``table_3_3_dt1``...)."""
        return {Path(n).with_suffix("").as_posix(): _csv_frame(b) for n, b in self.files.items()
                if n.endswith(".csv")}

    @property
    def best_map(self) -> dict | None:
        """The best power-rate map (``edges_w``, ``rates_wps``, fuel-economy and soot changes) of the map
        study; the best constant rate within the fuel-economy loss (a one-segment map) of the trade-off;
        None for the other studies or when no rate met the constraint."""
        if self.study == "powerrate-map":
            return self.summary.get("best_map")
        if self.study == "tradeoff":
            best = self.summary.get("best_within_loss")
            if not best:
                return None
            edges = self.summary.get("edges_w", [])
            return {"edges_w": list(edges), "rates_wps": [best["rate_wps"]] * max(1, len(edges) - 1),
                    **{k: v for k, v in best.items() if k != "rate_wps"}}
        return None

    @property
    def figures(self) -> list[str]:
        """Names of the PNG figures among `files`."""
        return [n for n in self.files if n.endswith(".png")]

    def plot(self, which: str | None = None):
        """A matplotlib ``Figure`` of the study.

        Trade-off: seed Fig. A.2 (fuel economy and soot vs the rate). Power-rate map: ``which="maps"``
        (default, Fig. A.3) or ``"comparison"`` (Fig. A.4). Thermal and BMS studies: the saved figure
        ``which`` (a name from `figures`; default the first) drawn on a new Figure.
        """
        if self.study == "tradeoff":
            from .tradeoff import tradeoff_figure
            return tradeoff_figure(self.summary)
        if self.study == "powerrate-map":
            from .powerrate_map import comparison_figure, rate_maps_figure
            kinds = {"maps": rate_maps_figure, "comparison": comparison_figure}
            if which not in (None, *kinds):
                raise ScenarioError(f"StudyResult.plot: which must be 'maps' or 'comparison', got {which!r}")
            return kinds[which or "maps"](self.summary)
        figs = self.figures
        if not figs:
            raise ShevsimError(f"study {self.study}: no figure was written (plots=False?)")
        name = which or figs[0]
        if name not in self.files:
            best = difflib.get_close_matches(str(name), figs, n=1)
            raise ScenarioError(f"StudyResult.plot: no figure '{name}'" + (f" (did you mean '{best[0]}'?)" if best
                                                                          else f" (figures: {', '.join(figs)})"))
        import matplotlib.image as mpimg
        from matplotlib.figure import Figure
        img = mpimg.imread(io.BytesIO(self.files[name]), format="png")
        h, w = img.shape[:2]
        fig = Figure(figsize=(w / 110, h / 110))
        ax = fig.add_axes((0, 0, 1, 1))
        ax.imshow(img)
        ax.set_axis_off()
        return fig

    def save(self, out_dir: str | Path) -> Path:
        """Write the study's files into ``out_dir`` (the files ``shevsim study ... --out`` writes, without
        the evaluation cache); files of other names there are kept. Returns the folder."""
        from ..core.atomic import write_files
        self.out = write_files(out_dir, self.files, self._marker(), f"study {self.study}")
        return self.out

    def _marker(self) -> str:
        return MARKER if MARKER in self.files else next(iter(sorted(n for n in self.files if n.endswith(".json"))),
                                                        MARKER)

    # ------------------------------------------------------------------ display
    def _headline(self) -> str:
        s = self.summary
        if self.study == "tradeoff":
            rows = s.get("rows", [])
            b = s.get("best_within_loss")
            best = (f"best {b['rate_wps'] / 1e3:g} kW/s (soot {b['soot_change_pct']:+.2f} %, fuel economy "
                    f"{b['fe_change_pct']:+.3f} %)" if b else "no rate within the fuel-economy loss")
            return f"{len(rows)} rates, {best}"
        if self.study == "powerrate-map":
            b = s.get("best_map", {})
            return (f"best map {[round(r / 1e3, 3) for r in b.get('rates_wps', [])]} kW/s (soot "
                    f"{b.get('soot_change_pct', float('nan')):+.2f} %, fuel economy {b.get('fe_change_pct', float('nan')):+.3f} %)")
        if self.study == "bms":
            return "parts: " + ", ".join(k for k in ("dekf", "thermal", "power") if k in s)
        return f"{len(s)} summary entries"

    def __repr__(self) -> str:
        t = [Path(n).stem for n in self.files if n.endswith(".csv")]
        tables = ", ".join(t[:4]) + (f" +{len(t) - 4}" if len(t) > 4 else "")
        return (f"<StudyResult {self.study}: {self._headline()}; tables: {tables or 'none'}; "
                f"{len(self.files)} files{'; saved in ' + str(self.out) if self.out else ''}>")

    def _repr_html_(self) -> str:
        import html

        from ..report.html import study_summary_html
        rows = [("tables", ", ".join(Path(n).stem for n in self.files if n.endswith(".csv")) or "none"),
                ("figures", ", ".join(self.figures) or "none"), ("saved in", str(self.out) if self.out else "not saved")]
        rows += [("note", n) for n in self.notes]
        body = "".join(f"<tr><th style='text-align:left'>{html.escape(k)}</th><td style='text-align:left'>"
                       f"{html.escape(str(v))}</td></tr>" for k, v in rows)
        return (f"<div><b>StudyResult</b> {html.escape(self.study)}: {html.escape(self._headline())}"
                f"{study_summary_html(self.summary)}<table>{body}</table>"
                "<p style='font-size:11px;color:#666'>st.to_html(PATH) writes the interactive report</p></div>")

    def to_html(self, path: str | Path | None = None):
        """The interactive report of the study (trade-off, GA history, chosen map, parameters; the page
        ``report.html`` of its folder): the HTML text, or written to ``path`` (returns the path)."""
        from ..report.html import study_report
        from ..report.write import write_page
        text = study_report(self.summary, self.tables)
        return text if path is None else write_page(path, text)

# ---------------------------------------------------------------------- running a study
def _check_options(which: str, options: Mapping[str, Any]) -> dict:
    if which not in STUDY_OPTIONS:
        best = difflib.get_close_matches(str(which), list(STUDY_OPTIONS), n=1)
        raise ScenarioError(f"unknown study '{which}'" + (f" (did you mean '{best[0]}'?)" if best else
                                                          f" (known: {', '.join(STUDY_OPTIONS)})"))
    known = STUDY_OPTIONS[which]
    for k in options:
        if k not in known:
            best = difflib.get_close_matches(k, list(known), n=1)
            raise ScenarioError(f"study {which}: unknown option '{k}'" + (f" (did you mean '{best[0]}'?)" if best else
                                f" (its options: {', '.join(known) or 'none besides out'})"))
    return {**known, **options}


def _overrides(sets: Mapping[str, Any] | Sequence[str] | None) -> dict:
    """``set`` as ``{"comp.param": value}``: a mapping of typed values or ``"comp.param=value"`` strings."""
    from ..core.scenario import parse_value
    if not sets:
        return {}
    if isinstance(sets, Mapping):
        items = list(sets.items())
    else:
        items = []
        for s in ([sets] if isinstance(sets, str) else sets):
            if "=" not in str(s) or "." not in str(s).split("=", 1)[0]:
                raise ShevsimError(f"--set '{s}': expected component.param=value")
            k, v = str(s).split("=", 1)
            items.append((k.strip(), parse_value(v.strip())))
    for k, _ in items:
        if "." not in str(k):
            raise ShevsimError(f"set '{k}': expected component.param")
    return dict(items)


def study_problem(which: str, scenario, *, synthetic: bool = False, supervisor: str = "supervisor",
                  stop_s: float | None = None, sets=None, edges_w=None):
    """The evaluation problem of a study (checked before any run) and its default output folder."""
    from .evaluate import freeze
    from .problem import ScenarioProblem, SyntheticProblem
    name = which.replace("-", "_")
    if synthetic:
        return SyntheticProblem(), Path(f"results/study_{name}_synthetic")
    if not scenario:
        raise ShevsimError(f"study {which}: a SCENARIO file is needed (or synthetic=True / --synthetic)")
    p = Path(scenario)
    if not p.is_file():
        from ..core.paths import bundled_scenario, bundled_scenarios
        b = bundled_scenario(str(scenario))
        if b is None:
            raise ShevsimError(f"{p}: scenario file not found (bundled scenarios by name: "
                               f"{', '.join(bundled_scenarios())})")
        p = b
    extra = _overrides(sets)
    prob = ScenarioProblem(str(p.resolve()), supervisor, stop_s, tuple(sorted((k, freeze(v)) for k, v in extra.items())))
    prob.item((0.0, 1.0), None).key()          # fail early on a malformed scenario
    prob.check(study_edges(prob, edges_w))     # ... on an unknown supervisor, a bad override: before any run
    return prob, Path(f"results/study_{name}_{p.stem}")


def study_edges(problem, edges_w=None) -> tuple:
    """The power partition edges (W): ``edges_w`` when given, else the seed's layout over the power the
    scenario's generator can reach (``problem.default_edges()``), else `DEFAULT_EDGES_W`."""
    from .problem import DEFAULT_EDGES_W
    if edges_w:
        return tuple(float(x) for x in edges_w)
    return problem.default_edges() if hasattr(problem, "default_edges") else DEFAULT_EDGES_W


def failed_rows(which: str, rows) -> tuple[int, list[str]]:
    """Exit status and notes from a study's rows: 1 when every evaluation failed, 0 otherwise."""
    failed = [r for r in rows if r.get("error")]
    if rows and len(failed) == len(rows):
        return 1, [f"error: all {len(rows)} evaluations failed; first: {failed[0]['error']}"]
    if failed:
        return 0, [f"warning: {len(failed)} of {len(rows)} evaluations failed; first: {failed[0]['error']}"]
    return 0, []


def check_study_out(out: str | Path, which: str) -> None:
    """Refuse, before a study runs, an output folder whose earlier output has a file changed since shevsim wrote
    it (`shevsim.core.atomic.edited_outputs` over every file its manifest lists: the names a study writes again),
    or a path that exists and is not a folder; the save's own checks follow after the run."""
    from ..core.atomic import MANIFEST, _read_manifest, edited_message, edited_outputs
    from ..core.errors import ShevsimError
    p = Path(out)
    what = f"study {which}"
    if (p.exists() or p.is_symlink()) and not p.is_dir():
        raise ShevsimError(f"{what}: '{p}' exists and is not a folder: not replaced; choose another folder")
    man = _read_manifest(p) if p.is_dir() else None
    if not man:
        return
    marker = next((n for n in sorted(man) if n.endswith(".json") and (p / n).is_file()), MARKER)
    bad = edited_outputs(p, [n for n in sorted(man) if n != MANIFEST and (p / n).exists()], marker)
    if bad:
        raise ShevsimError(edited_message(what, p, bad))


def run_study(which: str, scenario: str | Path | None = None, *, out: str | Path | None = None,
              workers: int = 2, scheduler: str | None = None, cache: str | Path | None = None,
              supervisor: str = "supervisor", stop_s: float | None = None,
              set: Mapping[str, Any] | Sequence[str] | None = None, edges_kw: Sequence[float] | None = None,
              max_evaluations: int | None = None, synthetic: bool = False, fe_metric: str | None = None,
              soot_metric: str | None = None, plots: bool = True, progress: bool = False,
              log: Callable[[str], None] | None = None, **options) -> StudyResult:
    """Run a study and return a `StudyResult`.

    Parameters
    ----------
    which : {'tradeoff', 'powerrate-map', 'thermal', 'bms'}
    scenario : str or Path, optional
        Scenario file or a bundled scenario's name (the trade-off and the map study; not with ``synthetic``).
    out : str or Path, optional
        Save the study's files there (as ``shevsim study ... --out``); default: nothing written, the files
        stay in the result (`StudyResult.save` writes them later). The evaluation cache goes to
        ``cache``, else ``out/cache.sqlite`` (rerunning resumes), else a temporary folder.
    workers, scheduler, cache, supervisor, stop_s, set, edges_kw, max_evaluations, synthetic, fe_metric, soot_metric
        The evaluation studies' options (``shevsim study tradeoff --help``): Dask worker processes
        (0 = serial), an existing Dask scheduler, the SQLite cache, the supervisor component's name, the
        stop time (s), overrides (``{"cycle.repeat": 1}`` or ``["cycle.repeat=1"]``), the power partition
        edges (kW), a budget of new evaluations, the analytic surrogate, the metric keys.
    plots : bool
        Write the PNG figures (default True).
    progress : bool
        Progress bars (default off).
    log : callable, optional
        Called with each progress line the study reports (default: silent).
    **options
        The study's own options, `STUDY_OPTIONS` (``rates_kwps=[30, 20]``, ``fe_loss_pct=0.5``,
        ``generations=50``, ``seed=0``...; ``bms``: ``seed``, ``quick``, ``only``).

    Raises
    ------
    ScenarioError
        An unknown study or option (with the closest name).
    ShevsimError
        Bad input (scenario, supervisor, overrides) or a study that cannot run; ``StudyInterrupted``
        when the evaluations stop (finished ones are in the cache).
    """
    opts = _check_options(which, options)
    if out is not None:       # before the study runs (minutes): a file changed in an earlier output is kept
        check_study_out(out, which)
    say = log or (lambda m: None)
    work = Path(tempfile.mkdtemp(prefix=f"shevsim_study_{which}_"))
    try:
        if which in EVALUATION_STUDIES:
            summary, code, notes = _run_evaluations(
                which, scenario, work, opts, say, workers=workers, scheduler=scheduler,
                cache=cache if cache is not None else (Path(out) / CACHE_NAME if out is not None else None),
                supervisor=supervisor, stop_s=stop_s, sets=set, edges_kw=edges_kw, max_evaluations=max_evaluations,
                synthetic=synthetic, fe_metric=fe_metric, soot_metric=soot_metric, plots=plots, progress=progress)
        elif which == "thermal":
            from ..battery.verification import run_thermal_verification
            summary, code, notes = run_thermal_verification(work), 0, []
        else:
            summary, code, notes = _run_bms(work, opts), 0, []
        from ..core.atomic import read_files
        res = StudyResult(which, json.loads(json.dumps(summary, default=_jsonable)), read_files(work, (CACHE_NAME,)),
                          None, notes, code)
    finally:
        shutil.rmtree(work, ignore_errors=True)       # our own temporary folder
    if out is not None:
        res.save(out)
    return res


def _jsonable(o):
    import numpy as np
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _run_evaluations(which, scenario, work: Path, opts: dict, say, *, workers, scheduler, cache, supervisor,
                     stop_s, sets, edges_kw, max_evaluations, synthetic, fe_metric, soot_metric, plots, progress):
    from .cache import EvaluationCache
    from .parallel import StudyRunner
    given = tuple(1e3 * float(x) for x in edges_kw) if edges_kw else None
    problem, _ = study_problem(which, scenario, synthetic=synthetic, supervisor=supervisor, stop_s=stop_s,
                               sets=sets, edges_w=given)
    edges = study_edges(problem, given)
    keys = {k: v for k, v in (("fe_key", fe_metric), ("soot_key", soot_metric)) if v}
    ev_cache = EvaluationCache(cache if cache is not None else work / CACHE_NAME)
    runner = StudyRunner(ev_cache, workers=workers, scheduler=scheduler, progress=progress,
                         max_new_evaluations=max_evaluations)
    with ev_cache, runner:
        if which == "tradeoff":
            from .tradeoff import run_tradeoff
            summary = run_tradeoff(problem, runner, [1e3 * float(r) for r in opts["rates_kwps"]], work, edges,
                                   fe_loss_max_frac=opts["fe_loss_pct"] / 100, plots=plots, log=say, **keys)
            code, notes = failed_rows(which, summary.get("rows", []))
            return summary, code, notes
        from .ga import GAConfig
        from .powerrate_map import MapStudyConfig, run_powerrate_map
        from .problem import DEFAULT_LEVELS_WPS
        levels = DEFAULT_LEVELS_WPS if not opts["levels_kwps"] else tuple(1e3 * float(x) for x in opts["levels_kwps"])
        cfg = MapStudyConfig(edges_w=edges, levels_wps=levels, fe_loss_max_frac=opts["fe_loss_pct"] / 100,
                             ga=GAConfig(population=opts["population"], generations=opts["generations"],
                                         crossover_prob=opts["crossover"], mutation_prob=opts["mutation"],
                                         seed=opts["seed"], unique_population=opts["unique_population"]),
                             top_k=opts["top_k"], max_cases=opts["max_cases"], fill_cases=bool(opts["fill_cases"]),
                             **keys)
        return run_powerrate_map(problem, runner, cfg, work, plots=plots, log=say), 0, []


def _run_bms(work: Path, opts: dict) -> dict:
    from .bms_study import run_all
    only = opts["only"]
    only = tuple(s.strip() for s in (only.split(",") if isinstance(only, str) else only) if str(s).strip())
    unknown = set(only) - {"dekf", "thermal", "power"}
    if unknown or not only:
        raise ShevsimError(f"study bms: only: unknown {sorted(unknown) or 'empty'} (known: dekf, thermal, power)")
    return run_all(work, seed=int(opts["seed"]), quick=bool(opts["quick"]), only=only)
