"""cli.py - ``shevsim calibrate MODEL DATA.csv --out DIR [--params PARAMS.toml] [--map canonical=column ...]
[--holdout FRACTION] [--sample-convention CONVENTION|CHANNEL=CONVENTION,...] [--sensor-noise CHANNEL=VALUE]
[--ambient-c DEGC]``.

``--ambient-c`` gives a cell record without an ambient-temperature column a constant ambient (a chamber or a room
at one temperature; ``t_ambient_c = 25.0`` in ``--params`` ``[params]`` does the same), stated in the report.

``--sample-convention`` says what a logged value stands for (default ``instantaneous``: the value at the
sample time); a time shift between inputs and outputs is fitted as the ``timing`` effect of every model.
``--sensor-noise`` declares a channel's sensor noise (1 sigma, SI) as its sensor floor, or a measured
input's (e.g. ``speed_mps=0.02``), which the model carries into the floor of its outputs; otherwise it is
estimated (quiet segments, a local smoother; :mod:`shevsim.calibrate.timing`) and the method is reported.

``--params`` TOML::

    [meta]                      # free text, ignored
    source = "..."
    [params]                    # the component's own parameters (e.g. capacity_ah, mass_kg) - known
    capacity_ah = 2.9           # values or starting values; unknown names fail with a suggestion
    soc0_frac = 1.0             # cell short form: initial SOC (< 0: from the first rest voltage)
    discharge_file = "ecm.csv"  # cell: R/C tables, CSV soc_frac,t_c,rs_ohm,r1_ohm,c1_f,r2_ohm,c2_f (a full SOC x
    charge_file = "ecm.csv"     # temperature grid; relative to this file); docs/getting_started.md has an example
    [ocv]                       # cell short form: open-circuit voltage curve
    soc_frac = [0.0, 0.1, ...]
    ocv_v = [3.0, 3.4, ...]

or a component parameter file (``components/battery/default.toml``...), or a calibration's own overlay
``params.toml`` (tables ``[battery]``, ``[vehicle]``/``[motor]``/``[bus]``, ``[engine_generator]``).
Every run writes ``DIR/params.toml``: use it with ``shevsim run SCENARIO --params DIR/params.toml``.

Exit status 0 on success, 2 on bad input (message names the file and column/row/field).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..core.argtypes import positive_int as _at_least_one
from ..core.errors import DataError, ShevsimError
from .data import CURRENT_SIGNS, POWER_SIGNS
from .known import load_params_toml  # noqa: F401  (re-exported: tests and scripts import it from here)
from .models import MODELS
from .report import MAX_RECORD_ROWS


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="shevsim calibrate",
                                 description="Fit a model to measured data, trace the residual to a missing "
                                             "effect, add it and report the error before and after.",
                                 epilog="shevsim calibrate --records lists the shipped measured records, each with "
                                        "the command that calibrates it (DATA may be a record's name). "
                                        "shevsim calibrate MODEL --help shows a model's columns, parameters and "
                                        "candidate effects.")
    ap.add_argument("model", choices=sorted(MODELS), help="calibration model")
    ap.add_argument("data", help="measured CSV (or .csv.gz; '#' lines are comments), or a shipped record's name "
                                 "(shevsim calibrate --records)")
    ap.add_argument("-o", "--out", required=True, help="output directory (report.json, report.md, plots)")
    ap.add_argument("-p", "--params", help="TOML with the nominal: known parameters / starting values ([params]), an "
                                           "OCV curve ([ocv]), a cell's R/C tables (discharge_file, charge_file: CSV "
                                           "soc_frac,t_c,rs_ohm,r1_ohm,c1_f,r2_ohm,c2_f); format and examples: "
                                           "docs/getting_started.md, 'Calibrating your own record'")
    ap.add_argument("--map", action="append", default=[], metavar="CANONICAL=COLUMN",
                    help="use file column COLUMN as canonical column CANONICAL (repeatable)")
    ap.add_argument("--holdout", type=float, default=0.3, help="held-out fraction (default 0.3)")
    ap.add_argument("--split", choices=("blocks", "tail"), default="blocks",
                    help="held-out blocks spread over the record (default) or the final part")
    ap.add_argument("--current-sign", choices=CURRENT_SIGNS + ("auto",), default=None,
                    help="sign convention of the current column in the file (default: guessed from the data - "
                         "voltage falls as discharge current rises - and stated; a shipped record's own)")
    ap.add_argument("--power-sign", choices=POWER_SIGNS, default="drawn-positive",
                    help="sign convention of the power column in the file")
    ap.add_argument("--drop-duplicate-rows", action="store_true",
                    help="drop rows identical to the previous one (logger repeats) instead of failing")
    ap.add_argument("--unit", action="append", default=[], metavar="CANONICAL=UNIT",
                    help="unit of a column in the file, converted to SI (time_s=ms, current_a=mA, speed_mps=kmh, "
                         "power_w=kW, t_surface_c=K, voltage_v=mV; CANONICAL=its SI unit skips the unit sniffing)")
    ap.add_argument("--sample-convention", default=None, metavar="CONVENTION | CHANNEL=CONVENTION[,...]",
                    help="what a logged value stands for: instantaneous (the value at the sample time; the "
                         "default), mean-ending (the mean over the period ending at it) or mean-starting (over the "
                         "period starting at it); one for every channel, inputs included, or per channel, the "
                         "others instantaneous (a logger averaging only the power: power_w=mean-ending); stated "
                         "in the report")
    ap.add_argument("--sensor-noise", action="append", default=[], metavar="CHANNEL=VALUE[,CHANNEL=VALUE]",
                    help="declared sensor noise (1 sigma, SI) of an output channel (its sensor floor) or of a "
                         "measured input (propagated through the model into the outputs' floor); otherwise "
                         "estimated from quiet segments and a local smoother; the method is stated.  Repeatable, "
                         "or several separated by commas: --sensor-noise power_w=300,speed_mps=0.02")
    ap.add_argument("--ambient-c", type=float, default=None, metavar="DEGC",
                    help="cell: the ambient temperature as a constant [degC], for a record without an ambient column "
                         "(a chamber or a room at one temperature; also t_ambient_c = DEGC in --params [params]); "
                         "stated in the report")
    ap.add_argument("--effects", nargs="+", help="restrict the candidate effects to these names")
    ap.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    ap.add_argument("--decimate", type=_at_least_one, default=1, metavar="K",
                    help="keep every K-th row of the record (a long record sampled faster than the model needs)")
    ap.add_argument("--allow-large", action="store_true",
                    help=f"calibrate on a record of more than {MAX_RECORD_ROWS:,} rows (after --decimate) as it is")
    ap.add_argument("-q", "--quiet", action="store_true", help="errors only (no progress or summary logging)")
    return ap


def list_records() -> str:
    """The shipped measured records, each with the command that calibrates it."""
    from .data import measured_records, record_command
    recs = measured_records()
    if not recs:
        return "no measured records are shipped with this installation"
    lines = []
    for r in recs:
        lines.append(f"{r['name']}  ({r['model']}) {r['description']}")
        lines.append(f"    {record_command(r)}")
    lines.append("(a record's declared columns, current sign, repeated rows and parameters are applied; any "
                 "option given on the command line overrides them)")
    return "\n".join(lines)


def _help_model(argv) -> str | None:
    """The model named among the positional arguments of a ``--help`` command line (None: none)."""
    return next((a for a in argv if not a.startswith("-") and a in MODELS), None)


def _param_names(params) -> str:
    """Parameter names with units, the elements of a list parameter as one (``dudt_v_k[0..3] [V/K]``)."""
    groups: dict = {}
    for p in params:
        base, sep, _ = p.name.partition("[")
        groups.setdefault((base if sep else p.name, bool(sep), p.unit), []).append(p.name)
    return ", ".join(f"{base}[0..{len(names) - 1}] [{unit}]" if is_list else f"{base} [{unit}]"
                     for (base, is_list, unit), names in groups.items())


def model_help(name: str, width: int | None = None) -> str:
    """What ``shevsim calibrate MODEL --help`` adds to the generic help, all of it read from the code: the
    columns (:data:`~shevsim.calibrate.data.REQUIRED`, ``OPTIONAL``, ``COLUMN_INFO``, ``UNITS``, ``SIGNED``,
    ``CONSTANT_COLUMNS``; inputs and fitted channels from the model), the declared parameters and the candidate
    effects of the model built as the command builds it without ``--params``
    (:func:`~shevsim.calibrate.models.get_model`), the ``timing`` effect every calibration adds
    (:func:`~shevsim.calibrate.timing.timing_effect`) and an example command (a shipped record of the model, if
    any).  Reads no data file and writes nothing."""
    import importlib
    import re
    import shutil
    import textwrap
    from .data import (COLUMN_INFO, CONSTANT_COLUMNS, OPTIONAL, REQUIRED, SIGNED, UNITS, measured_records,
                       record_command)
    from .models import get_model
    from .timing import timing_effect
    width = width or max(60, shutil.get_terminal_size().columns - 2)
    model = get_model(name, {}, "<params>")

    def block(rows, indent=2):
        """Rows ``(key, text)`` as a table: the keys aligned, the texts wrapped beside them."""
        w = indent + max(len(k) for k, _ in rows) + 2
        return [textwrap.fill(text, width, initial_indent=(" " * indent + k).ljust(w), subsequent_indent=" " * w,
                              break_on_hyphens=False, break_long_words=False) for k, text in rows]

    def para(text, indent=0):
        return textwrap.fill(text, width, initial_indent=" " * indent, subsequent_indent=" " * (indent + 2),
                             break_on_hyphens=False, break_long_words=False)

    summary = (importlib.import_module(type(model).__module__).__doc__ or "").strip().splitlines()[0]
    summary = summary.split(" - ", 1)[-1].rstrip(".")
    lines = ["", para(f"model {name}: {summary}"), ""]

    # -- columns
    lines.append(para("columns (canonical name; a file's own names: --map CANONICAL=COLUMN; other units: "
                      "--unit CANONICAL=UNIT or a header suffix such as time_ms):"))
    rows = []
    for c in REQUIRED[name] + OPTIONAL[name]:
        what, unit = COLUMN_INFO.get(c, (c, ()))[0], ""
        m = re.match(r"(.*) \[(.*)\]$", what)
        if m:
            what, unit = m.groups()
        role = ("time base" if c == "time_s" else "input" if c in model.inputs
                else "fitted output" if c in model.channels + model.optional_channels else "used")
        text = f"{'required' if c in REQUIRED[name] else 'optional'}, {role}: {what} [{unit}]"
        if c in SIGNED.get(name, {}):
            option, signs = SIGNED[name][c]
            text += f"; sign: {signs[0]} (a file's other: {option} {'|'.join(signs[1:])})"
        suffix = next((s for s in UNITS if c.endswith(s)), None)
        if suffix:
            other = [u for u in UNITS[suffix] if u != suffix[1:]]
            if other:
                text += f"; other units: {', '.join(other)}"
        if c in CONSTANT_COLUMNS.get(name, {}):
            text += f"; or a constant: {CONSTANT_COLUMNS[name][c]} VALUE"
        rows.append((c, text))
    lines += block(rows) + [""]

    # -- parameters
    lines.append(para("fitted parameters (declared; default: the nominal's value without --params, the fit's "
                      "start - --params [params] NAME = VALUE sets it; bounds of the fit):"))
    rows = []
    for p in model.declared:
        text = f"{p.doc or p.name} [{p.unit}]: default {p.default:g}, bounds {p.lo:g}..{p.hi:g}"
        if p.limits:
            text += f" (may be profiled to {p.limits[0]:g}..{p.limits[1]:g})"
        rows.append((p.name, text))
    lines += block(rows)
    used = model.defaults_used()
    if used:
        by: dict = {}
        for d in used:
            by.setdefault(d["default"], []).append(f"{d['parameter']} = {d['value']}")
        lines.append(para("without --params the nominal takes (give your own in --params): "
                          + "; ".join(f"from {src}: {', '.join(ps)}" for src, ps in by.items()), 2))
    else:
        lines.append(para(f"without --params the nominal is the {model.component} component's default parameters", 2))
    lines.append("")

    # -- effects
    lines.append(para("candidate effects (--effects NAME ... restricts them; each adds its parameters to the fit):"))
    effects = list(model.effects.values()) + [timing_effect(model.channels + model.optional_channels, 1.0)]
    lines += block([(e.name, f"{e.description}; adds {_param_names(e.params)}") for e in effects])
    off = [f.__name__ for f in model.effect_functions if f(model) is None]
    if off:
        lines.append(para(f"in the library but not a candidate for this nominal (a --params nominal may make "
                          f"{'it one' if len(off) == 1 else 'them ones'}): {', '.join(off)}", 2))
    lines.append("")

    # -- example
    recs = [r for r in measured_records() if r["model"] == name]
    own = f"shevsim calibrate {name} DATA.csv --out DIR --params NOMINAL.toml"
    if recs:
        lines.append(f"example: {record_command(recs[0])}   (a shipped record: shevsim calibrate --records)")
    lines.append(f"{'your own record' if recs else 'example'}: {own}")
    return "\n".join(lines)


def _sensor_noise(items) -> dict:
    out = {}
    for it in [x for item in items for x in str(item).split(",") if x.strip()]:
        name, sep, val = it.partition("=")
        try:
            v = float(val)
        except ValueError:
            v = float("nan")
        if not sep or not name or not (v > 0 and v < float("inf")):
            raise DataError(f"--sensor-noise {it!r}: expected CHANNEL=VALUE with a positive number (e.g. power_w=300)")
        if name.strip() in out and out[name.strip()] != v:
            raise DataError(f"--sensor-noise {name.strip()}={out[name.strip()]:g} and {name.strip()}={v:g}: "
                            f"'{name.strip()}' given twice with different values; give it once")
        out[name.strip()] = v
    return out


def main_calibrate(argv=None) -> int:
    """Entry point of ``shevsim calibrate``: parse, call `shevsim.calibrate.report.run_calibration`, print the
    report; returns the exit status."""
    from .report import run_calibration
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--records" in argv or argv[:1] == ["records"]:
        print(list_records())
        return 0
    name = _help_model(argv) if {"-h", "--help"} & set(argv) else None
    if name is not None:                # shevsim calibrate MODEL --help: the generic help, then the model's own
        build_parser().print_help()
        print(model_help(name))
        return 0
    args = build_parser().parse_args(argv)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    try:
        cal = run_calibration(args.model, args.data, out=args.out, params=args.params, map=args.map,
                              holdout=args.holdout, split=args.split, current_sign=args.current_sign,
                              power_sign=args.power_sign, drop_duplicate_rows=args.drop_duplicate_rows,
                              units=args.unit, effects=args.effects, plots=not args.no_plots,
                              decimate=args.decimate, allow_large=args.allow_large, log=log, progress_every_s=15.0,
                              sample_convention=args.sample_convention,
                              sensor_noise=_sensor_noise(args.sensor_noise), ambient_c=args.ambient_c)
    except ShevsimError as exc:
        hint = ""
        if isinstance(exc, DataError) and Path(args.data).is_file():
            from .data import measured_records
            same = [r for r in measured_records() if Path(r["path"]).resolve() == Path(args.data).resolve()]
            if same:
                hint = (f"\n  this is the shipped record '{same[0]['name']}': `shevsim calibrate {same[0]['model']} "
                        f"{same[0]['name']} --out DIR` applies its declared columns, sign and parameters")
        print(f"shevsim calibrate: error: {exc}{hint}", file=sys.stderr)
        return 2
    for line in report_lines(cal.report):
        print(line)
    print(f"report: {Path(args.out) / 'report.md'} ({cal.report['elapsed_s']:.1f} s)")
    return 0


def report_lines(rep: dict) -> list[str]:
    """What ``shevsim calibrate`` prints of a report: the selected effects, RMSE before -> after per
    channel, the parameters the record cannot identify."""
    lines = [f"selected effects: {', '.join(rep['selected_effects']) or 'nothing found'}"
             + (f" (sample convention: {rep['timing']['sample_convention']})" if rep.get("timing") else "")]
    lines += [f"model-form discrepancy: {d['statement']}" for d in rep.get("model_form_discrepancy", [])]
    for c, b in rep["rmse_before"].items():
        a = rep["rmse_after"][c]
        lines.append(f"  {c}: held-out RMSE {b['holdout']:.4g} -> {a['holdout']:.4g} "
                     f"(train {b['train']:.4g} -> {a['train']:.4g})")
    if rep.get("not_identifiable"):
        lines.append("not identifiable from this record (values are not measurements): "
                     + ", ".join(rep["not_identifiable"]))
    from ..report.calibration_text import decimate_advice
    adv = decimate_advice(rep)
    if adv:
        lines.append("advice: " + adv.replace("`", ""))
    return lines


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main_calibrate())
