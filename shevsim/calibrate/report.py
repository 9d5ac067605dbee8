"""report.py - calibrate from Python and get an object back: `run_calibration` and `CalibrationReport`.

    import shevsim
    cal = shevsim.run_calibration("cell", "record.csv", map={"time_s": "Time", "current_a": "I"},
                                  params="ocv.toml", current_sign="charge-positive")
    cal                     # <CalibrationReport cell: selected ...>, a table in a notebook
    cal.selected_effects    # ['second_rc_branch', ...]
    cal.before_after        # pandas DataFrame: RMSE per channel, train / held-out, before / after / replay
    cal.overlay             # {"battery": {...}}: the parameters that carry the fit into a scenario
    fig = cal.plot()        # matplotlib Figure
    cal.save("out/cal")     # the files ``shevsim calibrate ... --out out/cal`` writes (params.toml, report.*)

The command line (`shevsim.calibrate.cli`) parses its options, calls `run_calibration` and
prints the report; the loop itself is `shevsim.calibrate.workflow.run_workflow`.
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

from ..core.errors import DataError
from ..report.calibration_text import (BASELINE_COLUMN, baseline_values, decimate_advice,  # noqa: F401
                                       md_parameters)

MARKER = "report.json"
#: a record longer than this (rows, after --decimate) is refused unless --allow-large: a calibration
#: simulates the model over the whole record some hundreds to thousands of times
MAX_RECORD_ROWS = 200_000
#: simulations a calibration typically takes (baseline fit, one fit per candidate effect and round): for
#: the time estimate printed before a long calibration starts
TYPICAL_SIMULATIONS = (300, 3000)


@dataclass(repr=False)
class CalibrationReport:
    """What a calibration found.

    Attributes
    ----------
    model : str
        The calibration model (``cell``, ``vehicle``, ``engine``...).
    report : dict
        The whole report (``report.json``): data, split, candidates and rounds, parameters before and
        after, diagnostics, identifiability, overlay, replay.
    files : dict of str to bytes
        The output files by name (``params.toml``, ``report.json``, ``report.md``, the PNG figures and any
        file the overlay refers to), exactly what ``shevsim calibrate ... --out DIR`` writes.
    out : Path or None
        Where the files were saved (``out=`` of `run_calibration`, or the last `save`).
    notes : list of str
        What reading the record noticed (units converted, rows dropped...).
    """

    model: str
    report: dict
    files: dict[str, bytes] = field(default_factory=dict)
    out: Path | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def selected_effects(self) -> list[str]:
        """The effects the held-out evidence selected (empty: nothing found)."""
        return list(self.report.get("selected_effects", []))

    @property
    def parameters(self) -> dict:
        """The fitted parameters after the selection (name -> value, in the units of the model)."""
        return dict(self.report.get("final_parameters", {}))

    @property
    def before_after(self):
        """RMSE per measured channel (rows; the unit is the channel's): ``train_before``,
        ``holdout_before``, ``train_after``, ``holdout_after`` and, when the fit was replayed through the
        simulator with the overlay, ``replay_train`` and ``replay_holdout`` (a pandas DataFrame)."""
        import pandas as pd
        rep = self.report
        rows = {}
        replay = rep.get("replay") if isinstance(rep.get("replay"), dict) and "error" not in rep["replay"] else {}
        for c, b in rep.get("rmse_before", {}).items():
            a = rep.get("rmse_after", {}).get(c, {})
            row = {"train_before": b.get("train"), "holdout_before": b.get("holdout"),
                   "train_after": a.get("train"), "holdout_after": a.get("holdout")}
            if c in replay:
                row.update(replay_train=replay[c]["train"], replay_holdout=replay[c]["holdout"])
            rows[c] = row
        df = pd.DataFrame.from_dict(rows, orient="index")
        df.index.name = "channel"
        return df

    @property
    def candidates(self):
        """The first round's candidate effects with their held-out scores (a pandas DataFrame)."""
        import pandas as pd
        return pd.DataFrame([{k: v for k, v in c.items() if not isinstance(v, (dict, list))}
                             for c in self.report.get("candidates", [])])

    @property
    def overlay(self) -> dict:
        """The parameter overlay, ``{component: {parameter: value}}`` (``params.toml``)."""
        return dict((self.report.get("overlay") or {}).get("tables") or {})

    @property
    def overlay_toml(self) -> str | None:
        """The text of ``params.toml`` (use it with ``shevsim run SCENARIO --params params.toml``)."""
        b = self.files.get("params.toml")
        return None if b is None else b.decode("utf-8")

    @property
    def replay(self) -> dict | None:
        """RMSE per channel of the overlay replayed through the simulator, ``{"error": ...}`` when the
        replay stopped, None when the model has no replay."""
        return self.report.get("replay")

    @property
    def figures(self) -> list[str]:
        """Names of the PNG figures among `files`."""
        return [n for n in self.files if n.endswith(".png")]

    def plot(self, which: str | None = None):
        """A matplotlib ``Figure``: by default the held-out RMSE per channel before, after and replayed
        (from the report); ``which`` = a saved figure's name (``fit_before_after.png``,
        ``residuals_before_after.png``, ``evidence.png``; see `figures`) draws that one."""
        from matplotlib.figure import Figure
        if which is None:
            df = self.before_after
            cols = [c for c in ("holdout_before", "holdout_after", "replay_holdout") if c in df]
            fig = Figure(figsize=(3.2 + 2.2 * max(1, len(df)), 3.6))
            axes = fig.subplots(1, max(1, len(df)), squeeze=False)[0]
            for ax, (chan, row) in zip(axes, df.iterrows()):
                ax.bar([c.replace("_", "\n") for c in cols], [row[c] for c in cols], color=["C0", "C3", "C2"][:len(cols)])
                ax.set_title(chan)
                ax.set_ylabel("held-out RMSE")
                ax.grid(alpha=0.3, axis="y")
            fig.suptitle(f"{self.model}: selected {', '.join(self.selected_effects) or 'nothing'}", fontsize=9)
            fig.tight_layout()
            return fig
        if which not in self.files or not which.endswith(".png"):
            best = difflib.get_close_matches(str(which), self.figures, n=1)
            raise DataError(f"CalibrationReport.plot: no figure '{which}'" + (
                f" (did you mean '{best[0]}'?)" if best else f" (figures: {', '.join(self.figures) or 'none'})"))
        import matplotlib.image as mpimg
        img = mpimg.imread(io.BytesIO(self.files[which]), format="png")
        h, w = img.shape[:2]
        fig = Figure(figsize=(w / 90, h / 90))
        ax = fig.add_axes((0, 0, 1, 1))
        ax.imshow(img)
        ax.set_axis_off()
        return fig

    def save(self, out_dir: str | Path) -> Path:
        """Write the calibration's files into ``out_dir`` (those ``shevsim calibrate ... --out`` writes);
        files of other names there are kept. Returns the folder."""
        from ..core.atomic import write_files
        self.out = write_files(out_dir, self.files, MARKER, f"calibrate {self.model}")
        return self.out

    def _headline(self) -> str:
        sel = ", ".join(self.selected_effects) or "nothing found"
        parts = [f"{c} held-out RMSE {r['holdout_before']:.4g} -> {r['holdout_after']:.4g}"
                 for c, r in self.before_after.iterrows()]
        return f"selected {sel}; " + "; ".join(parts[:3]) + ("; ..." if len(parts) > 3 else "")

    def __repr__(self) -> str:
        return (f"<CalibrationReport {self.model}: {self._headline()}; {len(self.files)} files"
                f"{'; saved in ' + str(self.out) if self.out else ''}>")

    def _repr_html_(self) -> str:
        import html

        from ..report.html import calibration_summary_html
        saved = f"saved in {self.out}" if self.out else "not saved"
        notes = "".join(f"<li>{html.escape(n)}</li>" for n in self.notes)
        return (calibration_summary_html(self.report)
                + (f"<ul style='font-size:12px'>{notes}</ul>" if notes else "")
                + f"<p style='font-size:11px;color:#666'>{html.escape(saved)}; cal.to_html(PATH) writes the "
                  "interactive report (fit before and after, residuals, evidence)</p>")

    def to_html(self, path: str | Path | None = None):
        """The interactive report of the calibration (fit before and after, residuals, evidence table,
        parameters; the page ``report.html`` of its folder): the HTML text, or written to ``path`` (returns
        the path)."""
        import pandas as pd

        from ..report.html import calibration_report
        from ..report.write import write_page
        traces = self.files.get("fit_traces.csv")
        text = calibration_report(self.report, pd.read_csv(io.BytesIO(traces)) if traces else None)
        return text if path is None else write_page(path, text)


def _pairs(x: Mapping[str, Any] | Sequence[str] | None) -> list[str]:
    """``{"a": "b"}`` or ``["a=b"]`` as the command line's ``CANONICAL=VALUE`` strings."""
    if not x:
        return []
    if isinstance(x, Mapping):
        return [f"{k}={v}" for k, v in x.items()]
    return [str(x)] if isinstance(x, str) else [str(s) for s in x]


def check_record_size(data, model_name: str, known: dict, allow_large: bool, log) -> None:
    """Time one simulation of the model over the record, say the estimate, and refuse (DataError) a record
    of more than `MAX_RECORD_ROWS` rows unless ``allow_large``."""
    import time as _time
    from .models import get_model
    n = len(data.df)
    grid_too_large(data, allow_large)
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


def grid_too_large(data, allow_large: bool) -> None:
    """Refuse (DataError) a record whose sampling grid - its span at the median sample step, what every model
    simulates (`sampling_grid` of `shevsim.calibrate.models`) - has more than `MAX_RECORD_ROWS` points while its
    rows do not: time gaps (a logger stopped for days) would make a few hundred rows a simulation of millions of
    steps per fit.  ``allow_large`` calibrates it as it is."""
    import numpy as np
    from .data import time_gaps
    t = data.df["time_s"].to_numpy(float)
    if allow_large or t.size < 3 or t.size > MAX_RECORD_ROWS:
        return
    k, h = time_gaps(t)
    if not h > 0 or not k.size:
        return
    n_grid = int(round((t[-1] - t[0]) / h)) + 1
    if n_grid <= MAX_RECORD_ROWS:
        return
    j = int(k[np.argmax(t[k + 1] - t[k])])
    raise DataError(f"{data.path}: the record's {t.size:,} rows span {t[-1] - t[0]:g} s, which at its median sample "
                    f"step {h:g} s is a grid of {n_grid:,} points to simulate, more than the {MAX_RECORD_ROWS:,} a "
                    f"calibration takes without --allow-large: {k.size} time gap(s), the longest {t[j + 1] - t[j]:g} s "
                    f"({t[j]:g} -> {t[j + 1]:g} s). Cut the record at its gaps and calibrate the parts, or give "
                    f"--allow-large to calibrate it as it is (the inputs interpolated across the gaps)")


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


def run_calibration(model: str, data: str | Path, *, out: str | Path | None = None,
                    params: str | Path | None = None, map: Mapping[str, str] | Sequence[str] | None = None,
                    holdout: float = 0.3, split: str = "blocks", current_sign: str | None = None,
                    power_sign: str = "drawn-positive", drop_duplicate_rows: bool = False,
                    units: Mapping[str, str] | Sequence[str] | None = None, effects: Sequence[str] | None = None,
                    plots: bool = True, decimate: int = 1, allow_large: bool = False,
                    log: Callable[[str], None] | None = None, progress_every_s: float | None = None,
                    sample_convention: str | None = None, sensor_noise: Mapping[str, float] | None = None,
                    ambient_c: float | None = None) -> CalibrationReport:
    """Calibrate ``model`` on the measured CSV ``data`` and return a `CalibrationReport`.

    Parameters
    ----------
    model : str
        ``cell``, ``vehicle``, ``engine``... (`shevsim.calibrate.models.MODELS`).
    data : str or Path
        The measured CSV (or .csv.gz; ``#`` lines are comments), or a shipped record by name
        (``shevsim calibrate --records``): its declared columns, current sign, repeated rows and
        parameters apply under what is given here.
    out : str or Path, optional
        Save the files there (as ``shevsim calibrate --out``); default: nothing written, the files stay
        in the report (`CalibrationReport.save` writes them later).
    params : str or Path, optional
        TOML with known parameters, starting values, an OCV curve or a calibration's own overlay.
    map : mapping or list of str, optional
        File columns for the canonical ones: ``{"time_s": "Time", "current_a": "I"}`` or ``["time_s=Time"]``.
    holdout, split, current_sign, power_sign, drop_duplicate_rows, units, effects, plots
        As the command's options (``shevsim calibrate --help``): held-out fraction, ``blocks``/``tail``,
        the file's sign conventions, dropping logger repeats, column units (``{"current_a": "mA"}``), the
        candidate effects to try, the PNG figures.
    decimate : int
        Keep every k-th row of the record (a long record sampled faster than the model needs).
    allow_large : bool
        Calibrate on a record of more than `MAX_RECORD_ROWS` rows (after ``decimate``) as it is.
    log : callable, optional
        Called with each progress line (default: silent).
    progress_every_s : float, optional
        Also report the time elapsed this often while the fit runs (the command line: 15 s).
    sample_convention : str or mapping, optional
        What a logged value stands for: ``instantaneous`` (default), ``mean-ending`` or ``mean-starting``
        (`shevsim.calibrate.timing`), for every channel (inputs included), or per channel
        (``"power_w=mean-ending"`` or ``{"power_w": "mean-ending"}``: the others instantaneous); stated in the
        report.
    sensor_noise : mapping, optional
        Declared sensor noise per channel (``{"power_w": 300.0}``), used as its noise floor.
    ambient_c : float, optional
        A cell record without an ambient-temperature column: the ambient as a constant [degC] (a chamber or a
        room at one temperature; ``--ambient-c``), stated in the report.  ``t_ambient_c`` in the ``params``
        file's ``[params]`` does the same; this option overrides it.

    Raises
    ------
    DataError
        Bad input: the message names the file and column, row or field.
    """
    from ..core.atomic import read_files
    from .known import load_params_toml
    from .data import load_measured, parse_mapping, parse_units
    from .workflow import run_workflow
    _check_calibration_options(model, split, current_sign, power_sign, decimate)
    if out is not None:      # before the record is read and fitted (minutes): not after, when the fit would be lost
        check_calibration_out(out, model)
    say = log or (lambda m: None)
    mapping = parse_mapping(_pairs(map))
    data_path, mapping, current_sign, drop_duplicate_rows, params = _shipped_record_options(
        data, model, mapping, current_sign, drop_duplicate_rows, params, say)
    known = load_params_toml(params) if params else {}
    ambient_from = "--ambient-c"
    if model == "cell" and "t_ambient_c" in known:   # a constant ambient in --params: the record's input, not a parameter
        v = known.pop("t_ambient_c")
        if ambient_c is None:
            ambient_c, ambient_from = v, f"t_ambient_c in {params}"
        else:
            say(f"note: --ambient-c {ambient_c} overrides t_ambient_c = {v} in {params}")
    measured = load_measured(data_path, model, mapping, current_sign=current_sign or "auto",
                             power_sign=power_sign, drop_duplicate_rows=drop_duplicate_rows,
                             units=parse_units(_pairs(units)), ambient_c=ambient_c, ambient_from=ambient_from)
    if decimate > 1:
        before = len(measured.df)
        measured.df = measured.df.iloc[::decimate].reset_index(drop=True)
        measured.notes.append(f"--decimate {decimate}: {before:,} rows -> {len(measured.df):,}")
    check_record_size(measured, model, known, allow_large, say)
    for n in measured.notes:
        say(f"note: {n}")
    say(f"calibrating {model} on {len(measured.df)} samples: nominal fit, then the candidate effects one "
        f"round at a time (minutes for an hour of 10 Hz data)")
    work = Path(tempfile.mkdtemp(prefix=f"shevsim_calibrate_{model}_"))
    try:
        import contextlib
        with (_Ticker(say, progress_every_s) if progress_every_s else contextlib.nullcontext()) as tick:
            rep = run_workflow(model, measured, known, holdout=holdout, split=split, out_dir=work,
                               effects=list(effects) if effects else None, plots=plots,
                               params_where=str(params) if params else "<params>",
                               log=tick.say if tick is not None else say,
                               sample_convention=sample_convention, sensor_noise=sensor_noise)
        files = read_files(work)
    finally:
        shutil.rmtree(work, ignore_errors=True)       # our own temporary folder
    res = CalibrationReport(model, json.loads(json.dumps(rep, default=float)), files, None, list(measured.notes))
    if out is not None:
        res.save(out)
    return res


#: the files a calibration writes into its folder (`CalibrationReport.save`; the cell's ``ocv.csv``): checked
#: before the run against a folder of the user's own (the save checks the files it actually has again)
OUTPUT_FILES = ("params.toml", "report.json", "report.md", "fit_traces.csv", "ocv.csv", "fit_before_after.png",
                "residuals_before_after.png", "evidence.png")


def check_calibration_out(out, model: str) -> None:
    """Refuse, before anything runs, an output folder the save would refuse after the fit (the rules of
    `shevsim.core.atomic.write_files`): a path that exists and is not a folder, a folder of the user's own
    (no ``report.json``) holding a file of a name the calibration writes (`OUTPUT_FILES`), an earlier calibration's
    file changed since it was written (`shevsim.core.atomic.edited_outputs`: a hand-edited ``params.toml``), a place
    that cannot be created or written.  Nothing is created here."""
    import os
    from ..core.atomic import check_output_folder
    from ..core.errors import ShevsimError
    what = f"calibrate {model}"
    p = Path(out)
    check_output_folder(p, OUTPUT_FILES, MARKER, what)   # an earlier calibration's changed file is kept
    probe = p.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ShevsimError(f"{what}: output folder '{p}': '{probe}' is a file, so the folder cannot be created")
    try:        # a real write test in the nearest folder that exists (permission bits lie for root)
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=".shevsim-calibrate-probe-")
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise ShevsimError(f"{what}: output folder '{p}' is not writable: {exc.strerror or exc}") from None


def _check_calibration_options(model: str, split: str, current_sign, power_sign: str, decimate) -> None:
    """Refuse an unknown model, split or sign convention and a bad ``decimate`` before any file is read."""
    from .models import MODELS
    if model not in MODELS:
        best = difflib.get_close_matches(str(model), sorted(MODELS), n=1)
        raise DataError(f"calibrate: unknown model '{model}'" + (f" (did you mean '{best[0]}'?)" if best else
                                                                 f" (models: {', '.join(sorted(MODELS))})"))
    from .data import CURRENT_SIGNS, POWER_SIGNS
    for name, val, allowed in (("split", split, ("blocks", "tail")),
                               ("current_sign", current_sign, (None, "auto") + tuple(CURRENT_SIGNS)),
                               ("power_sign", power_sign, POWER_SIGNS)):
        if val not in allowed:
            raise DataError(f"calibrate: {name} must be one of {', '.join(allowed)}, got {val!r}")
    if isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1:
        raise DataError(f"calibrate: decimate must be an integer >= 1, got {decimate!r}")


def _shipped_record_options(data, model: str, mapping: dict, current_sign, drop_duplicate_rows: bool, params, say):
    """Where ``data`` names a shipped record rather than a file: its path and its declared options under what
    the caller gave; returns ``(data_path, mapping, current_sign, drop_duplicate_rows, params)``."""
    data_path = str(data)
    if not Path(data_path).is_file():
        from .data import measured_records, resolve_record
        rec = resolve_record(data_path)
        if rec is None:
            names = [r["name"] for r in measured_records()]
            raise DataError(f"{data}: file not found" + (f" (shipped records: {', '.join(names)}; "
                                                         f"shevsim calibrate --records)" if names else ""))
        o = rec["options"]         # a shipped record: its declared options, under what the user gave
        if rec["model"] != model:
            raise DataError(f"record '{rec['name']}' is a {rec['model']} record, not {model}")
        data_path = rec["path"]
        mapping = {**dict(o.get("map", {})), **mapping}
        current_sign = current_sign or o.get("current_sign")
        drop_duplicate_rows = drop_duplicate_rows or bool(o.get("drop_duplicate_rows", False))
        if params is None and o.get("params"):
            params = str(Path(rec["folder"]) / o["params"])
        say(f"record {rec['name']}: {rec['description']}")
        say(f"  as declared by its records.toml: columns {', '.join(f'{k}={v}' for k, v in mapping.items())}; "
            f"current sign {current_sign}; repeated rows {'dropped' if drop_duplicate_rows else 'refused'}; "
            f"parameters {params}")
    return data_path, mapping, current_sign, drop_duplicate_rows, params
