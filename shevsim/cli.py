"""cli.py - the ``shevsim`` command.

Sub-commands::

    shevsim run [SCENARIO] [--out DIR] [--set comp.param=value ...] [--params [COMP=]FILE ...] [--no-plots] [--quiet]
    shevsim info SCENARIO|FMU
    shevsim cycles [FOLDER]
    shevsim study {thermal,bms,tradeoff,powerrate-map} ...
    shevsim calibrate MODEL DATA.csv --out DIR [...]
    shevsim fmu export TYPE --params FILE -o OUT.fmu
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from .core.errors import ShevsimError


def _cmd_run(a) -> int:
    from .run import DEFAULT_SCENARIO, run_scenario
    res, metrics, out = run_scenario(a.scenario or DEFAULT_SCENARIO, a.out, a.set or (), progress=not a.quiet,
                                     plots=not a.no_plots, overlays=a.params or ())
    if not a.quiet:
        print(f"scenario {res.meta['scenario']}: {res.termination}, {len(res.time_s)} points, "
              f"wall {res.meta['wall_s']:.2f} s")
        for k, v in metrics.items():
            if isinstance(v, (int, float)):
                print(f"  {k:40s} {v:.6g}")
        print(f"results in {out}")
    return 0


def _cmd_info(a) -> int:
    p = Path(a.target)
    if p.suffix.lower() == ".fmu":
        from .fmu.info import fmu_info
        print(fmu_info(p))
        return 0
    from .core.scenario import build_master, load_scenario, stop_time
    sc = load_scenario(p)
    m = build_master(sc)
    print(f"scenario {sc.name}: step {sc.settings.step_s} s, method {sc.settings.method}, "
          f"start {sc.t0_s} s, stop {stop_time(sc, m)} s, seed {sc.seed}")
    if sc.description:
        print(f"  {sc.description}")
    print(m.describe())
    if sc.faults:
        print("faults:")
        for f in sc.faults:
            # a fault acts from the first communication point at or after its time (as the master applies it)
            h, t0 = sc.settings.step_s, sc.t0_s
            k = max(0, math.ceil((f.at_s - t0) / h - 1e-9 * max(1.0, abs(f.at_s) / h)))
            acts = "" if abs(t0 + k * h - f.at_s) <= 1e-9 * max(1.0, abs(f.at_s)) else \
                f" (acts from the communication point {t0 + k * h:.6g} s)"
            print(f"  at {f.at_s} s: {f.component}.{f.port} = {f.value}{acts}")
    m.terminate()
    return 0


def _cmd_cycles(a) -> int:
    from .cycles import cycles_command
    from .core.scenario import PROJECT_ROOT
    print(cycles_command(Path(a.folder) if a.folder else PROJECT_ROOT / "cycles"))
    return 0


def _cmd_study(a, rest) -> int:
    from .studies.cli import main_study
    return main_study([a.which] + [r for r in rest if r != a.which])


def _cmd_calibrate(rest) -> int:
    from .calibrate.cli import main_calibrate
    return main_calibrate(rest)


def _cmd_fmu(a) -> int:
    from .fmu.export import export_component
    out = export_component(a.type, a.params, a.output, fmi_version=a.fmi_version)
    print(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(prog="shevsim", description="Series-hybrid vehicle co-simulation")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a scenario (default: scenarios/hd_udds_mpc.toml)")
    r.add_argument("scenario", nargs="?")
    r.add_argument("--out", help="output folder (default results/<scenario name>)")
    r.add_argument("--set", action="append", metavar="COMP.PARAM=VALUE", help="parameter override")
    r.add_argument("--params", action="append", metavar="[COMPONENT=]FILE",
                   help="parameter overlay (e.g. a calibration's DIR/params.toml) merged over the component's "
                        "parameters; without COMPONENT= every table applies to the component of that name")
    r.add_argument("--no-plots", action="store_true")
    r.add_argument("--quiet", action="store_true")
    i = sub.add_parser("info", help="describe a scenario or an FMU")
    i.add_argument("target")
    c = sub.add_parser("cycles", help="list drive cycles with statistics")
    c.add_argument("folder", nargs="?")
    s = sub.add_parser("study", help="studies: thermal, bms, tradeoff, powerrate-map", add_help=False)
    s.add_argument("which", nargs="?", default="--help")
    sub.add_parser("calibrate", help="closed-loop calibration against measured data", add_help=False)
    f = sub.add_parser("fmu", help="FMU tools")
    fsub = f.add_subparsers(dest="fmu_cmd", required=True)
    fe = fsub.add_parser("export", help="export a native component as a co-simulation FMU")
    fe.add_argument("type", help="registered component type name (e.g. vehicle)")
    fe.add_argument("--params", help="parameter file")
    fe.add_argument("-o", "--output", required=True)
    fe.add_argument("--fmi-version", default="2", choices=["2", "3"])
    try:
        if argv and argv[0] == "calibrate":
            return _cmd_calibrate(argv[1:])
        if argv and argv[0] == "study":
            a, rest = ap.parse_known_args(argv)
            return _cmd_study(a, rest)
        a = ap.parse_args(argv)
        return {"run": _cmd_run, "info": _cmd_info, "cycles": _cmd_cycles, "fmu": _cmd_fmu}[a.cmd](a)
    except ShevsimError as exc:
        print(f"shevsim: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:             # output piped into `head` & co.: stop quietly
        import os
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())   # the interpreter's final flush must not fail again
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
