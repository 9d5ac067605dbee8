"""calibration_text.py - what a calibration report says beyond its numbers, shared by ``report.md`` (the
calibration's own renderer), ``report.html`` (:func:`shevsim.report.html.calibration_page`) and the command's
summary (:func:`shevsim.calibrate.cli.report_lines`): the parameter table's baseline column.  Plain functions of the report
dictionary (``report.json``); no import of the calibration package."""
from __future__ import annotations

#: what the parameter table's baseline column holds (the header of report.md's and report.html's table)
BASELINE_COLUMN = ("the nominal model's value - fitted for a declared parameter, the nominal's own value "
                   "(from --params or the model's default: the neutral value the effect starts from) for an effect's")


def baseline_values(rep: dict) -> dict[str, tuple[float | None, str]]:
    """The parameter table's baseline column: for each final parameter of the report ``rep``, ``(value, source)``
    - ``"fitted"`` (a declared parameter of the nominal fit), ``"nominal"`` (an effect's parameter: the neutral
    value the effect starts from, ``rep["effect_neutral"]``, else the nominal's own value in
    ``rep["known_parameters"]``, an element ``name[j]`` of a list there included) or ``"-"`` (not known, None)."""
    base = rep.get("baseline_parameters") or {}
    neutral = rep.get("effect_neutral") or {}
    known = rep.get("known_parameters") or {}
    out: dict = {}
    for k in (rep.get("final_parameters") or {}):
        if k in base:
            out[k] = (float(base[k]), "fitted")
            continue
        v = neutral.get(k, known.get(k))
        if v is None and k.endswith("]") and "[" in k:
            name, j = k[:-1].split("[", 1)
            lst = known.get(name)
            if isinstance(lst, (list, tuple)) and j.isdigit() and int(j) < len(lst):
                v = lst[int(j)]
        try:
            out[k] = (float(v), "nominal") if v is not None and not isinstance(v, bool) else (None, "-")
        except (TypeError, ValueError):
            out[k] = (None, "-")
    return out


def md_parameters(rep: dict, fmt=None) -> list[str]:
    """The report's parameter table (markdown lines): parameter, baseline (:data:`BASELINE_COLUMN`), final."""
    fmt = fmt or (lambda x: f"{x:.4g}")
    bv = baseline_values(rep)
    lines = ["## Parameters", "", f"Baseline column: {BASELINE_COLUMN}.", "",
             "| parameter | baseline | final |", "|---|---|---|"]
    for k, v in (rep.get("final_parameters") or {}).items():
        b, src = bv.get(k, (None, "-"))
        lines.append(f"| {k} | {'-' if b is None else fmt(b)}{' (nominal)' if src == 'nominal' else ''} | {fmt(v)} |")
    return lines
