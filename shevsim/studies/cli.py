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

from ..core.argtypes import positive_int
from ..core.errors import ShevsimError



def _at_least_one(text: str) -> int:
    """argparse type: an integer >= 1 (a usage error, exit 2, otherwise)."""
    return positive_int(text, "to evaluate nothing, do not run the study; a study resumes from its cache")


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


def _evaluation_options(a) -> dict:
    """The options every evaluation study takes, as :func:`~shevsim.studies.result.run_study` keywords."""
    return dict(workers=a.workers, scheduler=a.scheduler, cache=a.cache, supervisor=a.supervisor,
                stop_s=a.stop_s, set=a.set, edges_kw=a.edges_kw, max_evaluations=a.max_evaluations,
                synthetic=a.synthetic, fe_metric=a.fe_metric, soot_metric=a.soot_metric, plots=not a.no_plots,
                progress=not a.quiet, log=print)


def _default_out(a, which: str) -> Path:
    """``--out``, else ``results/study_<which>_<scenario stem>`` (``_synthetic`` for the surrogate)."""
    if a.out:
        return Path(a.out)
    from .result import study_problem
    return study_problem(which, a.scenario, synthetic=a.synthetic, supervisor=a.supervisor, stop_s=a.stop_s,
                         sets=a.set)[1]


def _report(which: str, res, out: Path) -> int:
    """Print a finished study's notes (stderr) and where its files are; return its exit status."""
    for n in res.notes:
        print(f"shevsim study {which}: {n}", file=sys.stderr)
    print(f"outputs in {out}")
    return res.exit_code


def cmd_tradeoff(argv) -> int:
    from .result import STUDY_OPTIONS, run_study
    ap = argparse.ArgumentParser(prog="shevsim study tradeoff",
                                 description="fuel economy and soot vs a constant max engine power rate (seed Fig. A.2)")
    _common(ap)
    ap.add_argument("--rates-kwps", "--rates", type=float, nargs="+",
                    default=list(STUDY_OPTIONS["tradeoff"]["rates_kwps"]),
                    help="constant max power rates to sweep (kW/s)")
    ap.add_argument("--fe-loss-pct", type=float, default=0.5, help="fuel-economy loss accepted (%%, seed 0.5)")
    a = ap.parse_args(argv)
    out = _default_out(a, "tradeoff")
    res = run_study("tradeoff", a.scenario, out=out, rates_kwps=a.rates_kwps, fe_loss_pct=a.fe_loss_pct,
                    **_evaluation_options(a))
    return _report("tradeoff", res, out)


def cmd_powerrate_map(argv) -> int:
    from .result import run_study
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
    out = _default_out(a, "powerrate-map")
    res = run_study("powerrate-map", a.scenario, out=out, levels_kwps=a.levels_kwps, generations=a.generations,
                    population=a.population, crossover=a.crossover, mutation=a.mutation, seed=a.seed,
                    fe_loss_pct=a.fe_loss_pct, top_k=a.top_k, max_cases=a.max_cases,
                    unique_population=a.unique_population, fill_cases=not a.no_fill_cases,
                    **_evaluation_options(a))
    return _report("powerrate-map", res, out)


def cmd_thermal(argv) -> int:
    from .result import run_study
    ap = argparse.ArgumentParser(prog="shevsim study thermal", description="battery thermal-model verification")
    ap.add_argument("out_dir", nargs="?", help="output folder (same as --out)")
    ap.add_argument("-o", "--out", default="results/study_thermal", help="output folder (default results/study_thermal)")
    a = ap.parse_args(argv)
    out = a.out_dir or a.out
    run_study("thermal", out=out)
    print(f"thermal verification written to {out}")
    return 0


def cmd_bms(argv) -> int:
    """``shevsim study bms OUT [--seed S] [--quick] [--only ...]``."""
    from .bms_study import summary_lines
    from .result import run_study
    ap = argparse.ArgumentParser(prog="shevsim study bms",
                                 description="BMS studies: DEKF tracking (Fig. 5.11-5.12), Table 3.3, "
                                             "power capability under the cooling fault (Fig. 5.15)")
    ap.add_argument("out", nargs="?", default="results/study_bms", help="output folder")
    ap.add_argument("--out", dest="out_opt", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help="scenario / noise seed (default 1)")
    ap.add_argument("--quick", action="store_true", help="shortened runs (1800 s DEKF, 1500 s fault, 1200 s stages)")
    ap.add_argument("--only", default="dekf,thermal,power", help="comma list of dekf,thermal,power")
    a = ap.parse_args(argv)
    out = a.out_opt or a.out
    res = run_study("bms", out=out, seed=a.seed, quick=a.quick, only=a.only)
    for line in summary_lines(res.summary):
        print(line)
    print(f"BMS studies written to {out}")
    return 0


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
