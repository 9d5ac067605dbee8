"""write.py - write a report beside saved outputs, or from a result folder (``shevsim report DIR``).

A folder is recognised by what shevsim wrote there: ``run.json`` (a run), ``summary.json`` with a
``study`` key (a study), ``report.json`` with ``selected_effects`` (a calibration). The report goes to
``DIR/report.html``; a file of that name that shevsim did not write is never replaced.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

from ..core.atomic import write_text_atomic
from ..core.errors import ShevsimError

REPORT_NAME = "report.html"
_MARK = '<meta name="generator" content="shevsim'


def folder_kind(folder: str | Path) -> str:
    """``"run"``, ``"study"`` or ``"calibration"``: what the folder holds; `ShevsimError` otherwise."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ShevsimError(f"report: '{folder}' is not a folder (give a result folder of shevsim run, study "
                           f"or calibrate)")
    if (folder / "run.json").is_file():
        return "run"
    for name, key, kind in (("summary.json", "study", "study"), ("report.json", "selected_effects", "calibration")):
        p = folder / name
        if p.is_file():
            try:
                doc = json.loads(p.read_text())
            except (OSError, ValueError) as exc:
                raise ShevsimError(f"report: {p}: not readable JSON ({exc})") from None
            if isinstance(doc, dict) and key in doc:
                return kind
    raise ShevsimError(f"report: '{folder}' holds no shevsim outputs (expected run.json of a run, summary.json "
                       f"of a study or report.json of a calibration)")


def _check_target(path: Path) -> None:
    """A report may replace only an earlier shevsim report."""
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise ShevsimError(f"report: '{path}' exists and is not a regular file: not replaced")
    if path.exists():
        try:
            head = path.read_text(errors="replace")[:4000]
        except OSError as exc:
            raise ShevsimError(f"report: '{path}' cannot be read ({exc.strerror or exc}): not replaced") from None
        if _MARK not in head:
            raise ShevsimError(f"report: '{path}' exists and was not written by shevsim: not replaced "
                               f"(choose another file with -o)")


def _write(path: Path, text: str) -> Path:
    _check_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)
    return path


def write_page(path: str | Path, text: str) -> Path:
    """Write an HTML page a builder made to ``path`` (atomically); a file there that shevsim did not
    write is never replaced. Returns the path."""
    return _write(Path(path), text)


def write_run_html(result, folder: str | Path) -> Path:
    """Write ``report.html`` of a run into ``folder`` (the hook of a saved run)."""
    from .html import run_report
    return _write(Path(folder) / REPORT_NAME, run_report(result))


def load_study_tables(folder: str | Path) -> dict:
    """The CSV tables a study left in ``folder`` (``constant_limits``, ``exhaustive``, ``top_solutions``,
    ``ga_history``, ``tradeoff``) as DataFrames."""
    import pandas as pd
    out = {}
    for name in ("constant_limits", "exhaustive", "top_solutions", "ga_history", "tradeoff"):
        p = Path(folder) / f"{name}.csv"
        if p.is_file():
            try:
                out[name] = pd.read_csv(p)
            except (OSError, ValueError) as exc:
                raise ShevsimError(f"report: {p}: not a readable CSV ({exc})") from None
    return out


def write_study_html(folder: str | Path, summary: dict | None = None) -> Path:
    """Write ``report.html`` of a study from the outputs in ``folder``."""
    from .html import study_report
    folder = Path(folder)
    if summary is None:
        summary = json.loads((folder / "summary.json").read_text())
    return _write(folder / REPORT_NAME, study_report(summary, load_study_tables(folder)))


TRACES_NAME = "fit_traces.csv"


def write_calibration_html(folder: str | Path, rep: dict | None = None, traces=None) -> Path:
    """Write ``report.html`` of a calibration (``report.json`` and ``fit_traces.csv`` in ``folder``)."""
    import pandas as pd

    from .html import calibration_report
    folder = Path(folder)
    if rep is None:
        rep = json.loads((folder / "report.json").read_text())
    if traces is None and (folder / TRACES_NAME).is_file():
        try:
            traces = pd.read_csv(folder / TRACES_NAME)
        except (OSError, ValueError) as exc:
            raise ShevsimError(f"report: {folder / TRACES_NAME}: not a readable CSV ({exc})") from None
    return _write(folder / REPORT_NAME, calibration_report(rep, traces))


def write_report(target: str | Path | Sequence[str | Path], out: str | Path | None = None) -> Path:
    """Write the HTML report of a result folder (run, study, calibration), or the comparison of several
    run folders; return its path.

    Parameters
    ----------
    target : folder or sequence of folders
        One folder: its report goes to ``FOLDER/report.html`` (or ``out``). Several run folders: a
        comparison, to ``out`` (default ``comparison.html`` in the working directory).
    out : str or Path, optional
        The HTML file to write. A file there that shevsim did not write is never replaced.
    """
    from ..core.results import load_result
    targets = [target] if isinstance(target, (str, Path)) else list(target)
    if not targets:
        raise ShevsimError("report: no folder given")
    if len(targets) == 1:
        folder = Path(targets[0])
        kind = folder_kind(folder)
        dest = Path(out) if out is not None else folder / REPORT_NAME
        if kind == "run":
            from .html import run_report
            return _write(dest, run_report(_load_run(folder, load_result)))
        if kind == "study":
            from .html import study_report
            summary = json.loads((folder / "summary.json").read_text())
            return _write(dest, study_report(summary, load_study_tables(folder)))
        import pandas as pd

        from .html import calibration_report
        rep = json.loads((folder / "report.json").read_text())
        traces = pd.read_csv(folder / TRACES_NAME) if (folder / TRACES_NAME).is_file() else None
        return _write(dest, calibration_report(rep, traces))
    kinds = [(Path(t), folder_kind(t)) for t in targets]
    bad = [str(p) for p, k in kinds if k != "run"]
    if bad:
        raise ShevsimError(f"report: a comparison takes run folders only; not runs: {', '.join(bad)}")
    results = [_load_run(p, load_result) for p, _ in kinds]
    from ..core.results import run_labels
    from .html import compare_report
    labels = run_labels(results, fallback=[p.name for p, _ in kinds])
    return _write(Path(out) if out is not None else Path("comparison.html"), compare_report(results, labels))


def write_html(results, path: str | Path, *, labels: Sequence[str] | None = None, title: str | None = None) -> Path:
    """Write the report of one [`Result`][shevsim.core.results.Result] (a run page) or of several (a
    comparison) to ``path``, from a notebook or a script; returns the path. A file there that shevsim did
    not write is never replaced."""
    from ..core.results import Result
    from .html import compare_report, run_report
    if isinstance(results, Result):
        return _write(Path(path), run_report(results, title))
    results = list(results)
    if not results or not all(isinstance(r, Result) for r in results):
        raise ShevsimError("write_html: give a Result or a sequence of Results")
    if len(results) == 1 and labels is None:
        return _write(Path(path), run_report(results[0], title))
    return _write(Path(path), compare_report(results, labels, title))


def _load_run(folder: Path, load_result):
    try:
        return load_result(folder)
    except (OSError, ValueError, KeyError) as exc:
        raise ShevsimError(f"report: '{folder}' is not a readable run folder ({type(exc).__name__}: {exc})") from None
