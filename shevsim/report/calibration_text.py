"""calibration_text.py - what a calibration report says beyond its numbers, shared by ``report.md`` (the
calibration's own renderer), ``report.html`` (:func:`shevsim.report.html.calibration_page`) and the command's
summary (:func:`shevsim.calibrate.cli.report_lines`): the parameter table's baseline column and the advice to
decimate a fast record whose noise floor is its inputs' differentiated noise.  Plain functions of the report
dictionary (``report.json``); no import of the calibration package."""
from __future__ import annotations

import math

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


#: a channel's noise floor is "the inputs'" when their propagated part exceeds its sensor part by this factor ...
DECIMATE_PROPAGATED_RATIO = 3.0
#: ... on a record sampled faster than this [s]: then --decimate is suggested, to this sample interval
DECIMATE_BELOW_S = 1.0


def decimate_advice(rep: dict) -> str | None:
    """The suggestion to decimate a fast record whose noise floor is its measured inputs' noise differentiated
    at the sample rate (a 10 Hz speed record: ~10 kW of power floor, the effects hidden under it), or None.

    When a channel's propagated-input floor exceeds ``DECIMATE_PROPAGATED_RATIO`` x its sensor floor and the
    sample interval is below ``DECIMATE_BELOW_S``: ``--decimate K`` (``K`` = the interval brought to 1 s).  An
    input the model differentiates (speed into acceleration) carries its noise as sigma * sqrt(2) / dt, so a
    K-times longer interval lowers that part of the floor about K times; the sensor part stays."""
    dt = (rep.get("timing") or {}).get("sample_interval_s")
    if not dt or not (0.0 < float(dt) < DECIMATE_BELOW_S):
        return None
    # only an input the model differentiates carries its noise divided by the interval (a cell's current is
    # integrated into heat and charge: the Panasonic -20 degC record at 10 Hz, whose temperature floor is the
    # current's noise through the heat, would not gain by decimation)
    diff = set(rep.get("differentiated_inputs") or ())
    worst = None
    for c, nf in (rep.get("noise_floor") or {}).items():
        if not diff & set(((nf.get("propagated_inputs") or {}).get("inputs") or {})):
            continue
        pr = (nf.get("propagated_inputs") or {}).get("value")
        sn = (nf.get("sensor") or {}).get("value")
        if pr is None or sn is None or not pr > DECIMATE_PROPAGATED_RATIO * max(float(sn), 1e-300):
            continue
        if worst is None or pr / max(sn, 1e-300) > worst[1] / max(worst[2], 1e-300):
            worst = (c, float(pr), float(sn))
    if worst is None:
        return None
    k = max(2, math.ceil(DECIMATE_BELOW_S / float(dt) - 1e-9))
    c, pr, sn = worst
    return (f"The noise floor of `{c}` is the measured inputs' noise propagated through the model ({pr:.4g}, "
            f"{pr / max(sn, 1e-300):.0f}x its sensor part {sn:.4g}) on a record sampled every {float(dt):.3g} s: an "
            f"input the model differentiates (speed into acceleration) carries its noise divided by the sample "
            f"interval, and residuals below that floor cannot name an effect.  Try `--decimate {k}` (keeps every "
            f"{k}th row: sample interval {float(dt):.3g} s -> {k * float(dt):.3g} s; that part of the floor falls "
            f"about {k}x).")
