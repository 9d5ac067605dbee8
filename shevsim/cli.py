"""cli.py - the ``shevsim`` command.

Sub-commands:

    shevsim run [SCENARIO] [--vehicle NAME] [--cycle CYCLE] [--out DIR] [--set comp.param=value ...] [--params [COMP=]FILE ...] [--engine E]
                [--record SIG ...] [--record-every N] [--allow-large] [--no-plots] [--format parquet|csv|mat] [-q]

Every command also takes ``-v``/``-vv`` and ``--log-level LEVEL`` (log lines on stderr).
    shevsim scenarios
    shevsim vehicles
    shevsim components [TYPE] [--sets]
    shevsim info SCENARIO|FMU
    shevsim cycles [FOLDER]
    shevsim study {thermal,bms,tradeoff,powerrate-map} ...
    shevsim calibrate MODEL DATA.csv --out DIR [...]
    shevsim fmu export TYPE --params FILE -o OUT.fmu
    shevsim report DIR [DIR ...] [-o FILE.html]

Exit codes ([`EXIT_CODES`][shevsim.cli.EXIT_CODES]): 0 ok; 1 the run stopped early or is degraded (results saved);
2 bad input (scenario, parameters, options, output folder); 3 internal error; 130 interrupted (Ctrl-C;
what was simulated is saved).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import sys
from pathlib import Path

from .core.argtypes import positive_int as _positive_int
from .core.errors import ShevsimError, SimulationError

EXIT_OK, EXIT_STOPPED, EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
EXIT_CODES = {EXIT_OK: "ok", EXIT_STOPPED: "the run stopped early or is degraded (its results are saved)",
              EXIT_BAD_INPUT: "bad input: scenario, parameters, options or output folder (nothing was run); also "
                              "an output the machine refuses (full disk, file-size limit, full stdout)",
              EXIT_INTERNAL: "internal error (a bug: please report it with the message)",
              EXIT_INTERRUPTED: "interrupted with Ctrl-C or SIGTERM (what was simulated is saved; beside an "
                                "earlier result, in DIR-interrupted-<UTC time>)"}

RUN_EPILOG = """\
SCENARIO is a bundled scenario's name (see `shevsim scenarios`, e.g. hd_udds_rule) or the path of a
scenario TOML file; default: the bundled hd_udds_mpc. A scenario file may name bundled parameter files and
cycles by their path in the data folder (params = "components/vehicle/matv.toml").

--set KEY=VALUE changes one value, typed as TOML (numbers, true/false, "strings", [lists]):
  shared.QUANTITY   a quantity of the vehicle as a whole, reaching every component that uses it
                    e.g. --set shared.mass_kg=18000 --set shared.n_parallel=6 (shevsim/components/shared.py)
  component.param   e.g. --set cycle.repeat=1 (a component's value of a shared quantity, such as
                    vehicle.mass_kg, changes the shared quantity: declared twice differently is an error)
  scenario.FIELD    step_s, stop_s, t0_s, method, seed, name   e.g. --set scenario.stop_s=120
  metrics.OPTION    e.g. --set metrics.trace_allow_miss=true (a run that misses its speed trace is
                    'degraded' unless allowed; see trace_* options in docs/getting_started.md)

Results go to --out (default results/<scenario name>/): timeseries.parquet (units in the Parquet
schema metadata), run.json (termination, parameters, version), metrics.json, scenario.toml (as run),
overview.png and report.html (interactive, opens offline; `shevsim report DIR` rewrites it). Re-running into a result folder replaces only the files shevsim wrote there: each is listed in run.json with
the SHA-256 of its content, checked before it is replaced; a file changed or added since is never
touched (the run is refused before it starts, saying which file).

Ctrl-C or SIGTERM stops a run within a fraction of a second (either engine) and saves what was simulated
(termination 'stopped: interrupted ...', no figures). Into a folder that holds an earlier result, the
partial result goes to a new folder beside it, DIR-interrupted-<UTC time>; the earlier result is kept.

exit codes: 0 ok; 1 stopped early or degraded (results saved); 2 bad input (or an output the machine
refuses: full disk, file-size limit, full stdout); 3 internal error; 130 interrupted (results saved)."""


def _say(a, *args, **kw):
    if not getattr(a, "quiet", False):
        print(*args, **kw)


def _on_sigterm(signum, frame):
    from .run import Terminated
    raise Terminated()


def _cmd_run(a) -> int:
    import signal

    from .run import DEFAULT_SCENARIO, run
    # `kill PID` (SIGTERM) stops a run like Ctrl-C: what was simulated is saved
    try:
        old = signal.signal(signal.SIGTERM, _on_sigterm)
    except (ValueError, AttributeError):      # not the main thread, or no SIGTERM on this platform
        old = None
    from .warmup import CompileNotice
    try:
        with CompileNotice(enabled=not a.quiet):
            res = run(a.scenario or DEFAULT_SCENARIO, out=a.out, sets=a.set or (), overlays=a.params or (),
                      vehicle=a.vehicle, cycle=a.cycle,
                      engine=a.engine, record=a.record, record_every=a.record_every, plots=not a.no_plots,
                      progress=not a.quiet, allow_large=a.allow_large, save=True, fmt=a.format)
    finally:
        if old is not None:
            signal.signal(signal.SIGTERM, old)
    term = res.termination
    interrupted = term.status == "stopped" and term.reason.startswith("interrupted")
    _say(a, f"scenario {res.meta['scenario']}: {term}, {len(res.time_s)} points, engine {res.meta['engine']}, "
            f"wall {res.meta['wall_s']:.2f} s")
    if not a.quiet:
        for k, v in res.metrics.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                print(f"  {k:40s} {v:.6g}")
        for n in res.metrics.get("notes", []):
            print(f"  note: {n}")
    _say(a, f"results in {res.meta.get('out')}")
    if res.meta.get("earlier_result_kept"):
        print(f"shevsim: the earlier result in {res.meta['earlier_result_kept']} is kept as it was; this "
              f"interrupted run's partial result is in {res.meta.get('out')}", file=sys.stderr)
    if res.meta.get("warmup_pid") and not a.quiet:
        print(f"engine: the Python master ran (no compiled loop for this component layout yet); the loop is "
              f"being compiled in the background (pid {res.meta['warmup_pid']}, niced) and later runs of this "
              f"layout use it (SHEVSIM_BACKGROUND_COMPILE=0 turns this off)", file=sys.stderr)
    if not term.ok:
        where = ", ".join(x for x in (f"component {term.component}" if term.component else "",
                                      f"port {term.port}" if term.port else "",
                                      f"t={term.time_s:g} s" if term.time_s is not None else "") if x)
        print(f"shevsim: run {term.status}{' (' + where + ')' if where else ''}: {term.reason}; "
              f"results saved in {res.meta.get('out')}", file=sys.stderr)
        return EXIT_INTERRUPTED if interrupted else EXIT_STOPPED
    return EXIT_OK


def _cmd_scenarios(a) -> int:
    import tomllib

    from .core.paths import bundled_scenario, bundled_scenarios
    for n in bundled_scenarios():
        desc = ""
        try:
            desc = tomllib.loads(bundled_scenario(n).read_text()).get("scenario", {}).get("description", "")
        except (OSError, ValueError):
            pass
        print(n if a.quiet or not desc else f"{n:32s} {desc}")
    return EXIT_OK


def _cmd_vehicles(a) -> int:
    from .api import vehicles
    for n, v in vehicles().items():
        if a.quiet:
            print(n)
            continue
        q = v["shared"]
        facts = ", ".join(x for x in (
            f"{q['mass_kg'] / 1e3:.1f} t" if "mass_kg" in q else "",
            f"engine {q['engine_power_w'] / 1e3:.0f} kW" if "engine_power_w" in q else "",
            f"motor {q['motor_power_w'] / 1e3:.0f} kW" if "motor_power_w" in q else "",
            f"pack {q.get('cell', '?')} {q['n_series']}s x {q['n_parallel']}p" if "n_series" in q and "n_parallel" in q
            else "") if x)
        print(f"{n:16s} {facts}\n{'':16s} {v['description']}")
    print("run one: shevsim run [SCENARIO] --vehicle NAME [--cycle CYCLE] (cycles: shevsim cycles)")
    return EXIT_OK


def _cmd_info(a) -> int:
    p = Path(a.target)
    if p.suffix.lower() == ".fmu":
        from .fmu.info import fmu_info
        text = fmu_info(p)
        print(text.splitlines()[0] if a.quiet and text else text)
        return EXIT_OK
    from .core.scenario import build_master, load_scenario, stop_time
    sc = load_scenario(p)
    m = build_master(sc)
    try:
        print(f"scenario {sc.name}: step {sc.settings.step_s} s, method {sc.settings.method}, "
              f"start {sc.t0_s} s, stop {stop_time(sc, m)} s, seed {sc.seed}")
        if a.quiet:
            return EXIT_OK
        if sc.description:
            print(f"  {sc.description}")
        print(m.describe())
        if m.delayed:                   # a connection that carries the previous step's value
            print(f"delayed connections ({len(m.delayed)}, previous step's value): "
                  + ", ".join(str(c) for c in m.delayed))
        if sc.faults:
            print("faults:")
            for f in sc.faults:
                # a fault acts from the first communication point at or after its time (as the master applies it)
                h, t0 = sc.settings.step_s, sc.t0_s
                k = max(0, math.ceil((f.at_s - t0) / h - 1e-9 * max(1.0, abs(f.at_s) / h)))
                acts = "" if abs(t0 + k * h - f.at_s) <= 1e-9 * max(1.0, abs(f.at_s)) else \
                    f" (acts from the communication point {t0 + k * h:.6g} s)"
                print(f"  at {f.at_s} s: {f.component}.{f.port} = {f.value}{acts}")
    finally:
        m.terminate()
    return EXIT_OK


def _cmd_components(a) -> int:
    from . import catalog
    if a.sets:
        rows = catalog.parameter_sets(a.type)
        if a.json:
            print(json.dumps(rows, indent=1))
        else:
            print(catalog.format_sets(rows))
        return EXIT_OK
    if a.type:
        d = catalog.describe_type(a.type)
        print(json.dumps(d, indent=1, default=str) if a.json else catalog.format_type(d))
        return EXIT_OK
    rows = catalog.component_types(include_test_types=a.all)
    print(json.dumps(rows, indent=1) if a.json else catalog.format_types(rows))
    return EXIT_OK


def _cmd_cycles(a) -> int:
    from .cycles import cycles_command
    from .core.scenario import PROJECT_ROOT
    text = cycles_command(Path(a.folder) if a.folder else PROJECT_ROOT / "cycles")
    print(text)
    return EXIT_OK


def _quiet_stdout(quiet: bool):
    return contextlib.redirect_stdout(io.StringIO()) if quiet else contextlib.nullcontext()


def _cmd_study(a, rest) -> int:
    from .studies.cli import main_study
    args = [r for r in rest if r != a.which]
    quiet = a.quiet or "-q" in args
    args = [r for r in args if r != "-q"]
    if quiet and a.which in ("tradeoff", "powerrate-map") and "--quiet" not in args:
        args.append("--quiet")
    with _quiet_stdout(quiet):
        return main_study([a.which] + args)


def _cmd_calibrate(rest, quiet: bool) -> int:
    from .calibrate.cli import main_calibrate
    if quiet and "-q" not in rest and "--quiet" not in rest:
        rest = rest + ["--quiet"]
    with _quiet_stdout(quiet or "-q" in rest or "--quiet" in rest):
        return main_calibrate(rest)


def _cmd_fmu(a) -> int:
    if a.fmu_cmd == "export-ssp":       # shevsim.fmu.ssp (issue 16)
        from .fmu.ssp import export_ssp
        _say(a, f"wrote {export_ssp(a.scenario, a.output, stop_s=a.stop_s, sets=tuple(a.set or ()), force=a.force)}")
        return EXIT_OK
    if a.fmu_cmd == "import-ssp":
        from .fmu.ssp import import_ssp
        _say(a, f"wrote {import_ssp(a.ssp, a.output, step_s=a.step_s)}")
        return EXIT_OK
    from .fmu.export import export_component
    params = a.params
    if params and not Path(params).is_file():       # a bundled parameter set by name, as scenarios accept
        from .components import get_component_class
        from .core.paths import bundled_params
        typ = getattr(get_component_class(a.type, "fmu export"), "TYPE", a.type)
        found = bundled_params(params, str(typ), a.type)
        if found is None:
            from .catalog import parameter_sets
            names = [r["name"] for r in parameter_sets(str(typ))]
            raise ShevsimError(f"fmu export --params {params}: no such file and no bundled parameter set of that "
                               f"name{' (bundled for ' + str(typ) + ': ' + ', '.join(names) + ')' if names else ''}")
        params = found
    out = export_component(a.type, params, a.output, fmi_version=a.fmi_version, force=a.force)
    _say(a, f"wrote {out}")
    return EXIT_OK


def _cmd_report(a) -> int:
    from .report import write_report
    path = write_report(a.folders, out=a.out)
    _say(a, f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB; open it in a browser, it works offline)")
    return EXIT_OK


def _cmd_warmup(a) -> int:
    from .core.paths import user_cache_dir
    from .core.scenario import load_scenario
    from .warmup import precompile
    for name in a.scenarios:
        load_scenario(name)                 # a name that is no scenario: exit 2, before anything compiles
    out = precompile(scenarios=a.scenarios or None, stream=sys.stderr if not a.quiet else io.StringIO())
    _say(a, f"compiled code for {len(out['scenarios'])} scenario(s) and {len(out['layouts'])} fast loop(s) is "
            f"cached in {user_cache_dir() / 'numba'} ({out['wall_s']:.0f} s)")
    return EXIT_OK if out["scenarios"] or out["layouts"] else EXIT_STOPPED


def build_parser() -> argparse.ArgumentParser:
    """The ``shevsim`` argument parser (sub-commands run, scenarios, info, cycles, study, calibrate, fmu)."""
    from .version import __version__
    codes = "; ".join(f"{k} {v}" for k, v in EXIT_CODES.items())
    ap = argparse.ArgumentParser(prog="shevsim", description="Series-hybrid electric vehicle co-simulation",
                                 epilog=f"exit codes: {codes}")
    ap.add_argument("--version", action="version", version=f"shevsim {__version__}")
    ap.add_argument("-q", "--quiet", action="store_true", help="print only results and errors (every command)")
    ap.add_argument("-v", "--verbose", action="count", default=0,
                    help="more log messages: -v info, -vv debug (every command; log lines go to stderr)")
    ap.add_argument("--log-level", choices=LOG_LEVELS, type=str.upper, metavar="LEVEL",
                    help=f"log level ({', '.join(LOG_LEVELS)}; default WARNING, ERROR with -q)")
    q = argparse.ArgumentParser(add_help=False)
    q.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="no progress bar or summary; errors only")
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    r = sub.add_parser("run", parents=[q], help="run a scenario and save its results",
                       description="Run a scenario and save its results.", epilog=RUN_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("scenario", nargs="?", metavar="SCENARIO",
                   help="bundled scenario name (shevsim scenarios) or scenario TOML path (default hd_udds_mpc)")
    r.add_argument("-o", "--out", metavar="DIR", help="output folder (default results/<scenario name>); checked "
                                                      "before the run: not a file, not a folder of other files")
    r.add_argument("-s", "--set", action="append", metavar="KEY=VALUE",
                   help="override component.param, scenario.FIELD or metrics.OPTION (repeatable; see below)")
    r.add_argument("-p", "--params", action="append", metavar="[COMPONENT=]FILE",
                   help="parameter overlay (e.g. a calibration's DIR/params.toml) merged over the component's "
                        "parameters; without COMPONENT= every table applies to the component of that name")
    r.add_argument("--engine", choices=("auto", "python", "fast"), default="auto",
                   help="python: the co-simulation master; fast: the compiled fast path (error if the scenario "
                        "is not eligible); auto (default): fast when possible")
    r.add_argument("--record", nargs="+", metavar="COMP.PORT", help="record only these signals")
    r.add_argument("--record-every", type=_positive_int, default=1, metavar="N",
                   help="keep every N-th communication point (and the last); default 1")
    r.add_argument("--allow-large", action="store_true",
                   help="run even when the record/duration estimate exceeds what this machine holds")
    r.add_argument("--no-plots", action="store_true", help="do not write overview.png and report.html")
    r.add_argument("--format", choices=("parquet", "csv", "mat"), default="parquet",
                   help="format of the trajectory file timeseries.* (default parquet; mat: one struct per "
                        "component, MATLAB/Octave/scipy.io.loadmat)")
    r.add_argument("--vehicle", metavar="NAME", help="run on a bundled vehicle (shevsim vehicles) or a vehicle file: "
                   "sets the scenario's shared quantities (mass, pack, ratings, fuel)")
    r.add_argument("--cycle", metavar="CYCLE", help="run on a bundled drive cycle (shevsim cycles) or a cycle CSV")
    sub.add_parser("scenarios", parents=[q], help="list the bundled scenarios (names for `shevsim run NAME`)")
    sub.add_parser("vehicles", parents=[q], help="list the bundled vehicles (names for `shevsim run --vehicle NAME`)")
    i = sub.add_parser("info", parents=[q], help="describe a scenario (components, ports, units) or an FMU")
    i.add_argument("target", metavar="SCENARIO|FMU", help="bundled scenario name, scenario TOML or .fmu file")
    co = sub.add_parser("components", parents=[q], help="component types (ports with units, parameters with "
                                                         "ranges) and the bundled parameter sets")
    co.add_argument("type", nargs="?", metavar="TYPE", help="one type in detail (e.g. battery)")
    co.add_argument("--sets", action="store_true", help="list the bundled parameter sets (of TYPE, or all)")
    co.add_argument("--all", action="store_true", help="include the verification-test types")
    co.add_argument("--json", action="store_true", help="machine-readable output")
    c = sub.add_parser("cycles", parents=[q], help="list drive cycles with statistics")
    c.add_argument("folder", nargs="?", help="folder of cycle CSVs (default: the bundled cycles)")
    s = sub.add_parser("study", help="studies: thermal, bms, tradeoff, powerrate-map (shevsim study NAME --help)",
                       add_help=False)
    s.add_argument("which", nargs="?", default="--help")
    sub.add_parser("calibrate", help="closed-loop calibration against measured data (shevsim calibrate --help)",
                   add_help=False)
    f = sub.add_parser("fmu", parents=[q], help="FMU tools")
    fsub = f.add_subparsers(dest="fmu_cmd", required=True)
    fe = fsub.add_parser("export", parents=[q], help="export a native component as a co-simulation FMU")
    fe.add_argument("type", help="registered component type name (e.g. vehicle)")
    fe.add_argument("--params", help="parameter file, or a bundled set by name (shevsim components --sets), "
                                     "e.g. battery/default")
    fe.add_argument("-o", "--output", required=True, help="the .fmu file to write")
    fe.add_argument("--fmi-version", default="2", choices=["2", "3"], help="FMI version (default 2)")
    fe.add_argument("--force", action="store_true", help="replace the output file when it exists")
    fs = fsub.add_parser("export-ssp", parents=[q], help="export a scenario as an SSP package (FMUs + .ssd)")
    fs.add_argument("scenario", help="bundled scenario name or scenario TOML")
    fs.add_argument("-o", "--output", required=True, help="the .ssp file to write")
    fs.add_argument("--stop-s", type=float, help="stop time of the default experiment (default: the scenario's)")
    fs.add_argument("--set", action="append", metavar="COMP.PARAM=VALUE", help="parameter override")
    fs.add_argument("--force", action="store_true", help="replace the output file when it exists")
    fi = fsub.add_parser("import-ssp", parents=[q], help="extract an SSP package into a folder with a scenario")
    fi.add_argument("ssp", help="the .ssp file")
    fi.add_argument("-o", "--output", required=True, help="folder to write the FMUs and the scenario TOML into")
    fi.add_argument("--step-s", type=float, help="communication step (default: from the package)")
    w = sub.add_parser("warmup", parents=[q], help="compile ahead of time what runs use (the component steps of "
                                                  "the bundled scenarios, the default scenario's fast loop)",
                       description="Compile now, with progress, the numba code that runs would otherwise compile on "
                                   "first use: every component step of the bundled scenarios (or those named) and "
                                   "the fast loop of hd_udds_mpc's layout; cached in the user's cache folder. An "
                                   "installation (wheel or editable) carries this code already, for the numba, "
                                   "numpy, Python and CPU it was built with; useful after editing the sources, "
                                   "or on another CPU or versions.")
    w.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="bundled scenario names (default: all)")
    rp = sub.add_parser("report", parents=[q], help="write the HTML report of a result folder (run, study, "
                                                   "calibration) or compare run folders",
                        description="Write a self-contained HTML report (interactive plots, metrics, termination, "
                                    "parameters) from the saved outputs of a result folder: DIR/report.html. "
                                    "Several run folders: one comparison page (default ./comparison.html).")
    rp.add_argument("folders", nargs="+", metavar="DIR", help="result folder of shevsim run, study or calibrate")
    rp.add_argument("-o", "--out", metavar="FILE", help="the HTML file to write (a file shevsim did not write is "
                                                       "never replaced)")
    return ap


def _output_errors(exc: UnicodeEncodeError):
    """Error handler of the output streams under a locale that cannot encode a character (an ASCII-only
    locale): a surrogate-escaped byte of a path given on the command line is written back as that byte,
    any other character as a backslash escape (``b\\xfas``) - never an error."""
    bad = exc.object[exc.start:exc.end]
    if all(0xDC80 <= ord(c) <= 0xDCFF for c in bad):
        return bytes(ord(c) - 0xDC00 for c in bad), exc.end
    return "".join(f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}" if ord(c) < 0x10000
                   else f"\\U{ord(c):08x}" for c in bad), exc.end


def _robust_streams() -> None:
    """Make stdout/stderr unable to fail on a character the locale cannot encode (see `_output_errors()`)."""
    import codecs
    try:
        codecs.lookup_error("shevsim-output")
    except LookupError:
        codecs.register_error("shevsim-output", _output_errors)
    for stream in (sys.stdout, sys.stderr):
        enc = (getattr(stream, "encoding", None) or "").lower().replace("-", "").replace("_", "")
        if stream is not None and enc not in ("utf8", "utf8sig") and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="shevsim-output")
            except (ValueError, OSError):       # a closed or detached stream
                pass


class StdoutError(OSError):
    """Standard output refused a write (full device, I/O error)."""


class _GuardedStdout:
    """sys.stdout while a command runs: an OSError from writing or flushing it becomes `StdoutError`
    (so a full stdout is told apart from a file shevsim writes)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise StdoutError(exc.errno, exc.strerror) from None

    def flush(self):
        try:
            return self._stream.flush()
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise StdoutError(exc.errno, exc.strerror) from None

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _silence_stdout() -> None:
    """Point fd 1 at /dev/null so the interpreter's final flush does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
    except OSError:
        pass


LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")


def _log_options(argv: list[str]) -> tuple[list[str], int, str | None]:
    """Take ``-v``/``-vv``/``--verbose`` and ``--log-level LEVEL`` out of ``argv`` wherever they are (every
    sub-command accepts them); return the rest, the verbosity and the level."""
    rest, verbose, level = [], 0, None
    i = 0
    while i < len(argv):
        x = argv[i]
        if x == "--":
            rest.extend(argv[i:])
            break
        if x in ("-v", "--verbose") or (x.startswith("-v") and set(x[1:]) == {"v"}):
            verbose += 1 if x == "--verbose" else len(x) - 1
        elif x == "--log-level" and i + 1 < len(argv):
            level = argv[i + 1].upper()
            i += 1
        elif x.startswith("--log-level="):
            level = x.split("=", 1)[1].upper()
        else:
            rest.append(x)
        i += 1
    return rest, verbose, level


def _setup_logging(verbose: int, level: str | None, quiet: bool):
    """Send shevsim's log records at the chosen level to stderr for this command; returns a function that
    restores the logger as it was (``main`` is also called in-process, by the API and by tests)."""
    import logging
    root = logging.getLogger("shevsim")
    saved = (root.level, list(root.handlers))

    def restore():
        root.setLevel(saved[0])
        root.handlers[:] = saved[1]

    if level is None:
        level = "DEBUG" if verbose >= 2 else "INFO" if verbose == 1 else "ERROR" if quiet else "WARNING"
    if level not in LOG_LEVELS:
        raise ShevsimError(f"--log-level {level}: expected one of {', '.join(LOG_LEVELS)}")
    for h in list(root.handlers):
        if getattr(h, "_shevsim_cli", False):
            root.removeHandler(h)
    h = logging.StreamHandler(sys.stderr)
    h.setFormatter(logging.Formatter("shevsim: %(levelname)s: %(message)s (%(name)s)"))
    h.setLevel(getattr(logging, level))
    h._shevsim_cli = True
    root.addHandler(h)
    root.setLevel(getattr(logging, level))
    return restore


def main(argv=None) -> int:
    """Entry point of ``shevsim``; returns the exit code (see [`EXIT_CODES`][shevsim.cli.EXIT_CODES])."""
    argv = list(sys.argv[1:] if argv is None else argv)
    _robust_streams()
    if sys.stdout is None and not {"-q", "--quiet", "--help", "-h", "--version"} & set(argv):
        # started with stdout closed (`>&-`): what the command prints would vanish without a word
        print("shevsim: error: standard output is closed, so nothing shevsim prints can be seen; redirect it "
              "(> FILE, or > /dev/null) or give -q", file=sys.stderr)
        return EXIT_BAD_INPUT
    real = sys.stdout
    if real is not None and not isinstance(real, _GuardedStdout):
        sys.stdout = _GuardedStdout(real)
    try:
        return _main(argv)
    finally:
        if isinstance(sys.stdout, _GuardedStdout):
            sys.stdout = real


def _main(argv: list) -> int:
    ap = build_parser()
    argv, verbose, level = _log_options(argv)
    quiet = False
    while argv and argv[0] in ("-q", "--quiet"):
        quiet = True
        argv = argv[1:]
    try:
        restore = _setup_logging(verbose, level, quiet or "-q" in argv or "--quiet" in argv)
    except ShevsimError as exc:
        print(f"shevsim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        return _dispatch(ap, argv, quiet)
    finally:
        restore()


def _dispatch(ap, argv, quiet) -> int:
    try:
        if argv and argv[0] == "calibrate":
            rc = _cmd_calibrate(argv[1:], quiet)
            if sys.stdout is not None:
                sys.stdout.flush()
            return rc
        if argv and argv[0] == "study":
            a, rest = ap.parse_known_args(argv)
            a.quiet = quiet or getattr(a, "quiet", False)
            rc = _cmd_study(a, rest)
            if sys.stdout is not None:
                sys.stdout.flush()
            return rc
        try:
            a = ap.parse_args(argv)
        except SystemExit as exc:          # argparse: --help/--version (0) or a usage error (2)
            return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
        a.quiet = quiet or getattr(a, "quiet", False)
        rc = {"run": _cmd_run, "scenarios": _cmd_scenarios, "vehicles": _cmd_vehicles,
              "info": _cmd_info, "cycles": _cmd_cycles,
              "components": _cmd_components, "fmu": _cmd_fmu, "report": _cmd_report,
              "warmup": _cmd_warmup}[a.cmd](a)
        if sys.stdout is not None:
            sys.stdout.flush()          # a full or failing output stream is said here, not at exit
        return rc
    except SimulationError as exc:      # a simulation that failed outside `run` (info, fmu export)
        print(f"shevsim: stopped: {exc}", file=sys.stderr)
        return EXIT_STOPPED
    except ShevsimError as exc:
        print(f"shevsim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("shevsim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:             # output piped into `head` & co.: stop quietly
        _silence_stdout()               # the interpreter's final flush must not fail again
        return EXIT_STOPPED
    except OSError as exc:
        import errno
        if isinstance(exc, StdoutError):     # stdout on a full device, or failing: said on stderr
            _silence_stdout()
            from .core.errors import os_error_text
            print(f"shevsim: error: cannot write to standard output: {os_error_text(exc)}; redirect the output "
                  f"to a place that takes it (or use -q); any result folder was written before", file=sys.stderr)
            return EXIT_BAD_INPUT
        if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM):
            from .core.errors import os_error_text
            print(f"shevsim: error: cannot write '{exc.filename or '?'}': {os_error_text(exc)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        return _internal(exc)
    except Exception as exc:  # noqa: BLE001 - an internal error: one clear message and its own exit code
        return _internal(exc)


def _internal(exc: BaseException) -> int:
    """Report an internal error (a bug) in one clear message; EXIT_INTERNAL."""
    import traceback
    if os.environ.get("SHEVSIM_TRACEBACK"):
        traceback.print_exception(exc)
    notes = "".join(f"\n  {n}" for n in getattr(exc, "__notes__", []))
    print(f"shevsim: internal error: {type(exc).__name__}: {exc}{notes}\n  (set SHEVSIM_TRACEBACK=1 for the "
          f"traceback; please report it)", file=sys.stderr)
    return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
