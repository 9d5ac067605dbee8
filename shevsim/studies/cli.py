"""cli.py - ``shevsim study ...``: a dispatch table of study sub-commands.

    shevsim study tradeoff SCENARIO --rates-kwps 30 25 19.3 15 10 [--workers N | --scheduler ADDR] [--out DIR]
    shevsim study powerrate-map SCENARIO [--generations G --population P --seed S --workers N
                                          --scheduler ADDR --out DIR --cache FILE --max-evaluations K]
    shevsim study thermal [DIR | --out DIR]  # battery thermal-model verification
    shevsim study bms ...                    # (not yet available)

Add a study by adding ``name: (help, handler)`` to :data:`STUDIES`; a handler takes the remaining
argv and returns an exit code. Options shared by the evaluation studies: ``--workers`` (0 = serial;
N = embedded Dask LocalCluster, or a process pool without dask; default auto: serial for a handful), ``--scheduler`` (existing Dask cluster), ``--cache``
(SQLite evaluation cache, default ``OUT/cache.sqlite``: rerunning the same command resumes),
``--stop-s`` (shorter runs), ``--set comp.param=value`` (applied to every run), ``--synthetic``
(analytic surrogate instead of the scenario: a dry run of the machinery).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..core.errors import ShevsimError



def _at_least_one(text: str) -> int:
    """argparse type: an integer >= 1 (a usage error, exit 2, otherwise)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {v} (to evaluate nothing, do not run "
                                         f"the study; a study resumes from its cache)")
    return v


def _workers(text: str):
    if text == "auto":
        return "auto"
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or an integer >= 0, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected 'auto' or an integer >= 0, got {v}")
    return v


def _common(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("scenario", nargs="?", help="scenario TOML or a bundled scenario's name (its MPC supervisor component: --supervisor)")
    ap.add_argument("--workers", type=_workers, default="auto",
                    help="worker processes: 0 = serial; N = a Dask cluster of N (a process pool without dask); "
                         "auto (default): serial for up to 8 new evaluations, else one per core")
    ap.add_argument("--scheduler", help="address of an existing Dask scheduler (e.g. tcp://host:8786)")
    ap.add_argument("-o", "--out", help="output folder")
    ap.add_argument("--cache", help="SQLite evaluation cache (default OUT/cache.sqlite)")
    ap.add_argument("--supervisor", default="supervisor", help="name of the supervisor component in the scenario")
    ap.add_argument("--stop-s", type=float, help="override the scenario stop time (s)")
    ap.add_argument("-s", "--set", action="append", default=[], metavar="COMP.PARAM=VALUE",
                    help="override applied to every run")
    ap.add_argument("--edges-kw", type=float, nargs="+", help="power partition edges (kW), first 0, last P_max")
    ap.add_argument("--max-evaluations", type=_at_least_one, metavar="K",
                    help="stop after this many new evaluations, K >= 1 (resume later)")
    ap.add_argument("--synthetic", action="store_true", help="use the analytic surrogate (no simulation)")
    ap.add_argument("--fe-metric", default=None,
                    help="fuel-economy metric key (default fuel_economy_dsoc_corrected_kmpl; the seed's A.1 "
                         "definition is fuel_economy_soc_sustained_kmpl, which needs SOC-sustained windows)")
    ap.add_argument("--soot-metric", default=None, help="soot metric key (default soot_dsoc_corrected_g_per_km, the fuel economy's basis)")
    ap.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")


def _problem(a, name: str):
    from .problem import ScenarioProblem, SyntheticProblem
    if a.synthetic:
        return SyntheticProblem(), Path(a.out or f"results/study_{name}_synthetic")
    if not a.scenario:
        raise ShevsimError(f"study {name}: a SCENARIO file is needed (or --synthetic)")
    p = Path(a.scenario)
    if not p.is_file():
        from ..core.paths import bundled_scenario, bundled_scenarios
        b = bundled_scenario(a.scenario)
        if b is None:
            raise ShevsimError(f"{p}: scenario file not found (bundled scenarios by name: "
                               f"{', '.join(bundled_scenarios())})")
        p = b
    from ..core.scenario import parse_value
    extra = {}
    for s in a.set:
        if "=" not in s or "." not in s.split("=", 1)[0]:
            raise ShevsimError(f"--set '{s}': expected component.param=value")
        k, v = s.split("=", 1)
        extra[k.strip()] = parse_value(v.strip())
    from .evaluate import freeze
    prob = ScenarioProblem(str(p.resolve()), a.supervisor, a.stop_s, tuple(sorted((k, freeze(v)) for k, v in extra.items())))
    prob.item((0.0, 1.0), None).key()          # fail early on a malformed scenario
    prob.check(_edges(a, prob))                      # ... on an unknown --supervisor, a bad --set: before any run
    return prob, Path(a.out or f"results/study_{name}_{p.stem}")


def _runner(a, out: Path):
    from .cache import EvaluationCache
    from .parallel import StudyRunner
    cache = EvaluationCache(a.cache or out / "cache.sqlite")
    return cache, StudyRunner(cache, workers=a.workers, scheduler=a.scheduler, progress=not a.quiet,
                              max_new_evaluations=a.max_evaluations)


def _metric_keys(a) -> dict:
    d = {}
    if a.fe_metric:
        d["fe_key"] = a.fe_metric
    if a.soot_metric:
        d["soot_key"] = a.soot_metric
    return d


def _edges(a, problem=None):
    """--edges-kw, else the seed's layout over the power the scenario's generator can reach."""
    from .problem import DEFAULT_EDGES_W
    if a.edges_kw:
        return tuple(1e3 * x for x in a.edges_kw)
    return problem.default_edges() if hasattr(problem, "default_edges") else DEFAULT_EDGES_W


def cmd_tradeoff(argv) -> int:
    from .tradeoff import run_tradeoff
    ap = argparse.ArgumentParser(prog="shevsim study tradeoff",
                                 description="fuel economy and soot vs a constant max engine power rate (seed Fig. A.2)")
    _common(ap)
    ap.add_argument("--rates-kwps", "--rates", type=float, nargs="+",
                    default=[30, 27.5, 25, 22.5, 20, 19.3, 17.5, 15, 12.5, 10, 7.5, 5],
                    help="constant max power rates to sweep (kW/s)")
    ap.add_argument("--fe-loss-pct", type=float, default=0.5, help="fuel-economy loss accepted (%%, seed 0.5)")
    a = ap.parse_args(argv)
    problem, out = _problem(a, "tradeoff")
    cache, runner = _runner(a, out)
    with cache, runner:
        summary = run_tradeoff(problem, runner, [1e3 * r for r in a.rates_kwps], out, _edges(a, problem),
                               fe_loss_max_frac=a.fe_loss_pct / 100, plots=not a.no_plots, **_metric_keys(a))
    return _failed_rows_status("tradeoff", summary.get("rows", []))


def _failed_rows_status(name: str, rows) -> int:
    """Exit status of a study from its rows: 1 when every evaluation failed (said on stderr with the first
    reason), 0 otherwise (failures, if any, counted on stderr)."""
    failed = [r for r in rows if r.get("error")]
    if rows and len(failed) == len(rows):
        print(f"shevsim study {name}: error: all {len(rows)} evaluations failed; first: {failed[0]['error']}",
              file=sys.stderr)
        return 1
    if failed:
        print(f"shevsim study {name}: warning: {len(failed)} of {len(rows)} evaluations failed; first: "
              f"{failed[0]['error']}", file=sys.stderr)
    return 0


def cmd_powerrate_map(argv) -> int:
    from .ga import GAConfig
    from .powerrate_map import MapStudyConfig, run_powerrate_map
    from .problem import DEFAULT_LEVELS_WPS
    ap = argparse.ArgumentParser(prog="shevsim study powerrate-map",
                                 description="power-rate constraint map: GA + narrowed exhaustive search (seed A.3)")
    _common(ap)
    ap.add_argument("--levels-kwps", type=float, nargs="+", help="discrete rate levels (kW/s)")
    ap.add_argument("--generations", type=int, default=50, help="GA generations (seed 50)")
    ap.add_argument("--population", type=int, default=30, help="GA population size (seed 30)")
    ap.add_argument("--crossover", type=float, default=0.8, help="crossover probability")
    ap.add_argument("--mutation", type=float, default=0.01, help="mutation probability per gene")
    ap.add_argument("--seed", type=int, default=0, help="GA random seed (same seed, same maps)")
    ap.add_argument("--fe-loss-pct", type=float, default=0.4, help="fuel-economy loss allowed (%%, seed 0.4)")
    ap.add_argument("--top-k", type=int, default=10, help="best GA maps that set the narrowed bounds")
    ap.add_argument("--max-cases", type=int, default=648, help="cap on the exhaustive-search cases (seed 648)")
    ap.add_argument("--no-fill-cases", action="store_true",
                    help="exhaustive search over the box of the --top-k best maps only (default: grown to --max-cases)")
    ap.add_argument("--unique-population", action="store_true",
                    help="GA with duplicate elimination: better optimum, ~2.5x the evaluations (see ga.py)")
    a = ap.parse_args(argv)
    problem, out = _problem(a, "powerrate_map")
    levels = DEFAULT_LEVELS_WPS if not a.levels_kwps else tuple(1e3 * x for x in a.levels_kwps)
    cfg = MapStudyConfig(edges_w=_edges(a, problem), levels_wps=levels, fe_loss_max_frac=a.fe_loss_pct / 100,
                         ga=GAConfig(population=a.population, generations=a.generations,
                                     crossover_prob=a.crossover, mutation_prob=a.mutation, seed=a.seed,
                                     unique_population=a.unique_population),
                         top_k=a.top_k, max_cases=a.max_cases, fill_cases=not a.no_fill_cases, **_metric_keys(a))
    cache, runner = _runner(a, out)
    with cache, runner:
        run_powerrate_map(problem, runner, cfg, out, plots=not a.no_plots)
    return 0


def cmd_thermal(argv) -> int:
    ap = argparse.ArgumentParser(prog="shevsim study thermal", description="battery thermal-model verification")
    ap.add_argument("out_dir", nargs="?", help="output folder (same as --out)")
    ap.add_argument("-o", "--out", default="results/study_thermal", help="output folder (default results/study_thermal)")
    a = ap.parse_args(argv)
    from ..battery.verification import run_thermal_verification
    out = a.out_dir or a.out
    run_thermal_verification(Path(out))
    print(f"thermal verification written to {out}")
    return 0


def cmd_bms(argv) -> int:
    from .bms_study import main as bms_main    # shevsim study bms OUT [--seed S] [--quick] [--only ...]
    return bms_main(argv)


#: study name -> (one-line help, handler(argv) -> exit code). Extend here.
STUDIES = {
    "tradeoff": ("fuel/soot vs constant max engine power rate (Fig. A.2)", cmd_tradeoff),
    "powerrate-map": ("power-rate constraint map optimisation, GA + exhaustive search (A.3)", cmd_powerrate_map),
    "thermal": ("battery thermal-model verification (Ch. II)", cmd_thermal),
    "bms": ("BMS estimation and power-capability studies (Ch. III-V)", cmd_bms),
}


def main_study(argv=None) -> int:
    """Entry point of ``shevsim study NAME ...``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: shevsim study {" + ",".join(STUDIES) + "} ...\n")
        for k, (h, _) in STUDIES.items():
            print(f"  {k:15s} {h}")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in STUDIES:
        import difflib
        best = difflib.get_close_matches(name, list(STUDIES), n=1)
        print(f"shevsim study: unknown study '{name}'" + (f" (did you mean '{best[0]}'?)" if best else
                                                          f" (known: {', '.join(STUDIES)})"), file=sys.stderr)
        return 2
    from .parallel import StudyInterrupted
    try:
        return STUDIES[name][1](rest)
    except StudyInterrupted as exc:
        print(f"shevsim study {name}: stopped: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print(f"shevsim study {name}: interrupted; finished evaluations are in the cache - rerun to resume",
              file=sys.stderr)
        return 130
    except (ShevsimError, ValueError) as exc:
        print(f"shevsim study {name}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main_study())
