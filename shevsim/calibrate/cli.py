"""cli.py - ``shevsim calibrate MODEL DATA.csv --out DIR [--params PARAMS.toml] [--map canonical=column ...]
[--holdout FRACTION]``.

``--params`` TOML::

    [meta]                      # free text, ignored
    source = "..."
    [params]                    # the component's own parameters (e.g. capacity_ah, mass_kg) - known
    capacity_ah = 2.9           # values or starting values; unknown names fail with a suggestion
    soc0_frac = 1.0             # cell short form: initial SOC (< 0: from the first rest voltage)
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
import tomllib
from pathlib import Path

from ..core.errors import DataError, ShevsimError
from .data import CURRENT_SIGNS, POWER_SIGNS, load_measured, parse_mapping, parse_units
from .models import MODELS


def load_params_toml(path) -> dict:
    """Read a ``--params`` file into a dict of known / initial parameters for the calibration model.

    Accepted: the short form (``[params]`` and, for a cell, ``[ocv]``), a component parameter file
    (``[meta]`` + ``[params]``), or an overlay with one table per component (``[battery]``, ``[vehicle]``,
    ``[motor]``, ``[bus]``, ``[engine_generator]`` - a calibration's own ``params.toml``), returned under the
    key ``"__tables__"``.  ``"__base_dir__"`` is the file's folder (relative ``*_file`` paths resolve
    against it).
    """
    path = Path(path)
    if not path.is_file():
        from ..core.paths import bundled_params
        found = bundled_params(str(path))          # a bundled set by name (battery/default)
        if found is None:
            raise DataError(f"{path}: parameter file not found (a file, or a bundled parameter set such as "
                            f"battery/default: shevsim components --sets)")
        path = found
    from ..core.errors import toml_loads
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise DataError(f"{path}: cannot read as UTF-8 text: {exc}") from None
    doc = toml_loads(text, str(path), DataError, "invalid TOML")
    out: dict = {"__base_dir__": str(path.resolve().parent)}
    tables: dict = {}
    for sec, body in doc.items():
        if sec == "meta":
            continue
        if not isinstance(body, dict):
            raise DataError(f"{path}: '{sec}' must be a table [{sec}] of name = value")
        if sec == "params":
            out.update(body)
        elif sec == "ocv":
            for k in body:
                if k not in ("soc_frac", "ocv_v"):
                    raise DataError(f"{path}: [ocv] unknown key '{k}' (expected soc_frac, ocv_v)")
            if "soc_frac" not in body or "ocv_v" not in body:
                raise DataError(f"{path}: [ocv] needs both soc_frac and ocv_v")
            try:
                out["ocv_soc_frac"] = tuple(float(x) for x in body["soc_frac"])
                out["ocv_v"] = tuple(float(x) for x in body["ocv_v"])
            except (TypeError, ValueError) as exc:
                raise DataError(f"{path}: [ocv] soc_frac and ocv_v must be lists of numbers ({exc})") from exc
        elif sec in COMPONENT_TABLES:
            tables[sec] = dict(body)
        else:
            raise DataError(f"{path}: unknown table [{sec}] (expected [meta], [params], [ocv] or a component "
                            f"table: {', '.join(COMPONENT_TABLES)})")
    if tables:
        out["__tables__"] = tables
    return out


COMPONENT_TABLES = ("battery", "vehicle", "motor", "bus", "engine_generator")
#: a record longer than this (rows, after --decimate) is refused unless --allow-large: a calibration
#: simulates the model over the whole record some hundreds to thousands of times
MAX_RECORD_ROWS = 200_000
#: simulations a calibration typically takes (baseline fit, one fit per candidate effect and round): for
#: the time estimate printed before a long calibration starts
TYPICAL_SIMULATIONS = (300, 3000)


def _at_least_one(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {v}")
    return v


def check_record_size(data, model_name: str, known: dict, allow_large: bool, log) -> None:
    """Time one simulation of the model over the record, say the estimate, and refuse (DataError) a record
    of more than :data:`MAX_RECORD_ROWS` rows unless ``allow_large``."""
    import time as _time
    from .models import get_model
    n = len(data.df)
    if n <= 20_000 and not allow_large:
        return
    try:
        model = get_model(model_name, known, "<params>")
        ctx = model.prepare(data)
        t0 = _time.perf_counter()
        model.simulate(ctx, model.defaults())
        one = _time.perf_counter() - t0
    except Exception:  # noqa: BLE001 - the estimate is advisory; the calibration itself reports a failure
        one = None
    est = ("" if one is None else f"; one simulation of the model over it takes {one:.2g} s, so the calibration "
           f"needs about {one * TYPICAL_SIMULATIONS[0] / 60:.2g}-{one * TYPICAL_SIMULATIONS[1] / 60:.2g} min")
    if n > MAX_RECORD_ROWS and not allow_large:
        dt = data.df["time_s"].diff().median()
        k = -(-n // MAX_RECORD_ROWS)
        raise DataError(f"{data.path}: the record has {n:,} rows, more than the {MAX_RECORD_ROWS:,} a calibration "
                        f"takes without --allow-large{est}. Decimate it (--decimate {k}: keeps 1 row in {k}, sample "
                        f"step {dt:g} s -> {dt * k:g} s) or give --allow-large to calibrate on all of it")
    log(f"record: {n:,} rows{est} (progress is reported as it goes)")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="shevsim calibrate",
                                 description="Fit a model to measured data, trace the residual to a missing "
                                             "effect, add it and report the error before and after.",
                                 epilog="shevsim calibrate --records lists the shipped measured records, each with "
                                        "the command that calibrates it (DATA may be a record's name).")
    ap.add_argument("model", choices=sorted(MODELS), help="calibration model")
    ap.add_argument("data", help="measured CSV (or .csv.gz; '#' lines are comments), or a shipped record's name "
                                 "(shevsim calibrate --records)")
    ap.add_argument("-o", "--out", required=True, help="output directory (report.json, report.md, plots)")
    ap.add_argument("-p", "--params", help="TOML with known parameters / starting values / OCV curve")
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


class _Ticker:
    """Progress while the fit runs: a line every ``every_s`` seconds with the time elapsed and the last step
    reported (the workflow's own messages arrive between them)."""

    def __init__(self, log, every_s: float = 15.0):
        import threading
        self.log, self.every_s = log, every_s
        self.last = "fitting the nominal model"
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def say(self, msg: str) -> None:
        self.last = msg if len(msg) <= 70 else msg[:67] + "..."
        self.log(msg)

    def _run(self):
        import time
        t0 = time.perf_counter()
        while not self._stop.wait(self.every_s):
            self.log(f"... {time.perf_counter() - t0:.0f} s elapsed (last: {self.last})")

    def __enter__(self):
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        return False


def main_calibrate(argv=None) -> int:
    """Entry point of ``shevsim calibrate``; returns the exit status."""
    from .data import resolve_record
    from .workflow import run_workflow
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--records" in argv or argv[:1] == ["records"]:
        print(list_records())
        return 0
    args = build_parser().parse_args(argv)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    try:
        mapping = parse_mapping(args.map)
        current_sign, drop_dups, params = args.current_sign, args.drop_duplicate_rows, args.params
        data_path = args.data
        rec = None if Path(args.data).is_file() else resolve_record(args.data)
        if rec is not None:         # a shipped record: its declared options, under what the user gave
            o = rec["options"]
            if rec["model"] != args.model:
                raise DataError(f"record '{rec['name']}' is a {rec['model']} record, not {args.model}")
            data_path = rec["path"]
            mapping = {**dict(o.get("map", {})), **mapping}
            current_sign = current_sign or o.get("current_sign")
            drop_dups = drop_dups or bool(o.get("drop_duplicate_rows", False))
            if params is None and o.get("params"):
                params = str(Path(rec["folder"]) / o["params"])
            log(f"record {rec['name']}: {rec['description']}")
            log(f"  as declared by its records.toml: columns {', '.join(f'{k}={v}' for k, v in mapping.items())}; "
                f"current sign {current_sign}; repeated rows {'dropped' if drop_dups else 'refused'}; "
                f"parameters {params}")
        elif not Path(args.data).is_file():
            from .data import measured_records
            names = [r["name"] for r in measured_records()]
            raise DataError(f"{args.data}: file not found" + (f" (shipped records: {', '.join(names)}; "
                                                              f"shevsim calibrate --records)" if names else ""))
        known = load_params_toml(params) if params else {}
        data = load_measured(data_path, args.model, mapping, current_sign=current_sign or "auto",
                             power_sign=args.power_sign, drop_duplicate_rows=drop_dups,
                             units=parse_units(args.unit))
        if args.decimate > 1:
            before = len(data.df)
            data.df = data.df.iloc[::args.decimate].reset_index(drop=True)
            data.notes.append(f"--decimate {args.decimate}: {before:,} rows -> {len(data.df):,}")
        check_record_size(data, args.model, known, args.allow_large, log)
        for n in data.notes:
            log(f"note: {n}")
        log(f"calibrating {args.model} on {len(data.df)} samples: nominal fit, then the candidate effects one "
            f"round at a time (minutes for an hour of 10 Hz data; a line every 15 s)")
        with _Ticker(log) as tick:
            rep = run_workflow(args.model, data, known, holdout=args.holdout, split=args.split, out_dir=args.out,
                               effects=args.effects, plots=not args.no_plots,
                               params_where=params or "<params>", log=tick.say)
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
    sel = ", ".join(rep["selected_effects"]) or "nothing found"
    print(f"selected effects: {sel}")
    for c, b in rep["rmse_before"].items():
        a = rep["rmse_after"][c]
        print(f"  {c}: held-out RMSE {b['holdout']:.4g} -> {a['holdout']:.4g} (train {b['train']:.4g} -> {a['train']:.4g})")
    if rep.get("not_identifiable"):
        print(f"not identifiable from this record (values are not measurements): {', '.join(rep['not_identifiable'])}")
    print(f"report: {Path(args.out) / 'report.md'} ({rep['elapsed_s']:.1f} s)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main_calibrate())
