"""data.py - load measured time series into canonical columns, with checks that name file, column and row.

Canonical columns (SI, unit-suffixed; extra columns are kept as candidate explanatory signals):

* ``cell``: ``time_s``, ``current_a`` (positive = discharge), ``voltage_v``, ``t_surface_c``,
  ``t_ambient_c``; optional ``t_core_c``.
* ``vehicle``: ``time_s``, ``speed_mps``, ``power_w`` (total electrical load on the bus, positive = drawn).
* ``engine``: ``time_s``, ``power_w`` (engine brake power), ``soot_rate_mgps`` (soot mass rate).

File format: CSV with one header line; lines starting with ``#`` are comments; ``.csv.gz`` is read
transparently.  ``mapping`` renames file columns to canonical names (``{"current_a": "Current"}``).
Sign conventions: ``current_sign="charge-positive"`` negates the current column (e.g. battery testers
that log charge as positive); ``power_sign="delivered-positive"`` negates the vehicle power.

Checks (all problems of a file are raised together, as one :class:`shevsim.core.errors.DataError` naming the
file and, per problem, the column/row and the option that fixes it; file row numbers count every line of the
file, 1-based, including comments and header):
missing columns (with the closest existing name), non-numeric values, NaN runs in a required column,
non-increasing or duplicate time (identical duplicate rows may be dropped with
``drop_duplicate_rows=True``), implausible units (temperature looking like kelvin, speed looking like
km/h, power looking like kW, cell voltage outside 1-5.5 V), and a current sign that contradicts the
measured voltage response (dV/dI must be negative for discharge-positive current).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from ..core.errors import DataError
from ..core.textfile import decode_text

REQUIRED = {
    "cell": ("time_s", "current_a", "voltage_v", "t_surface_c", "t_ambient_c"),
    "vehicle": ("time_s", "speed_mps", "power_w"),
    "engine": ("time_s", "power_w", "soot_rate_mgps"),
}
OPTIONAL = {"cell": ("t_core_c",), "vehicle": (), "engine": ()}
CURRENT_SIGNS = ("discharge-positive", "charge-positive")
#: ``current_sign="auto"``: the sign is guessed from the data (voltage falls as discharge current rises) and
#: stated in the notes; a record whose voltage response does not tell (|corr(dI, dV)| below this) is refused
SIGN_GUESS_MIN_CORR = 0.3

#: what each canonical column holds, and words that name it in file headers (for the candidates offered
#: when a required column is missing)
COLUMN_INFO = {
    "time_s": ("time [s]", ("time", "t", "timestamp", "test_time", "seconds", "sec", "elapsed")),
    "current_a": ("current [A]", ("current", "i", "amps", "amp", "ampere", "curr", "ibat")),
    "voltage_v": ("cell voltage [V]", ("voltage", "v", "volt", "volts", "u", "vcell", "vbat")),
    "t_surface_c": ("cell surface temperature [degC]", ("surface", "battery", "cell", "case", "skin", "can",
                                                         "thermocouple", "tc", "bat")),
    "t_ambient_c": ("ambient temperature [degC]", ("ambient", "chamber", "room", "environment", "env", "air",
                                                    "amb", "oven")),
    "t_core_c": ("core temperature [degC]", ("core", "internal", "centre", "center")),
    "speed_mps": ("vehicle speed [m/s]", ("speed", "velocity", "vel", "v", "vspd", "spd")),
    "power_w": ("power [W]", ("power", "p", "pwr", "load")),
    "soot_rate_mgps": ("soot mass rate [mg/s]", ("soot", "pm", "particulate", "particulates")),
}
#: unit words per canonical suffix (a header ``Battery_Temp_degC`` names a temperature in degC)
UNIT_WORDS = {"_s": ("s", "sec", "secs", "seconds", "ms", "us", "ns", "min", "h"), "_a": ("a", "amp", "amps", "ma"),
              "_v": ("v", "volt", "volts", "mv"),
              "_c": ("c", "degc", "k", "celsius", "temp", "temperature", "degf"),
              "_mps": ("mps", "kmh", "kph", "mph"), "_w": ("w", "kw", "watt", "watts"),
              "_mgps": ("mgps", "gps", "mgs")}
#: plausible value ranges of a candidate column (a column outside it is not offered)
PLAUSIBLE = {"_v": (0.5, 6.0), "_c": (-60.0, 150.0), "_mps": (-1.0, 120.0)}
POWER_SIGNS = ("drawn-positive", "delivered-positive")
#: the canonical columns with a sign convention, per model: column -> (the option that states the file's
#: convention, the conventions it takes - the first is the canonical one; :func:`load_measured` negates a column
#: given in the other)
SIGNED = {"cell": {"current_a": ("--current-sign", CURRENT_SIGNS)},
          "vehicle": {"power_w": ("--power-sign", POWER_SIGNS)}, "engine": {}}

#: Units a column may be declared in (a header suffix ``time_ms`` or ``--unit time_s=ms``), converted to the
#: canonical SI column on load: unit -> (scale, offset), SI = value * scale + offset; per canonical suffix.
UNITS = {
    "_s": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "ns": (1e-9, 0.0), "min": (60.0, 0.0),
           "h": (3600.0, 0.0)},
    "_a": {"a": (1.0, 0.0), "ma": (1e-3, 0.0)},
    "_v": {"v": (1.0, 0.0), "mv": (1e-3, 0.0)},
    "_w": {"w": (1.0, 0.0), "kw": (1e3, 0.0)},
    "_mps": {"mps": (1.0, 0.0), "kmh": (1.0 / 3.6, 0.0), "kph": (1.0 / 3.6, 0.0), "mph": (0.44704, 0.0)},
    "_c": {"c": (1.0, 0.0), "k": (1.0, -273.15)},
    "_mgps": {"mgps": (1.0, 0.0), "gps": (1e3, 0.0)},
}
#: A value of this magnitude or more (or an infinite one) in a canonical column is no measurement: an instrument's
#: overload code (9.9E+37 of many meters and loggers) or an overflow; refused naming the column and line.
OVERLOAD_VALUE = 1e30
#: Largest plausible sample step of a calibration record (s): 10 or more "seconds" looks like milliseconds (or
#: microseconds, nanoseconds: the unit that brings the step under it is named).
MAX_PLAUSIBLE_STEP_S = 10.0
#: Smallest plausible sample step (s): under 0.1 ms (a logger above 10 kHz) the time column looks like hours or
#: minutes; from there to 1 ms (1-10 kHz: a fast logger, or a 1 Hz record in hours) a note says which unit it would be
MIN_PLAUSIBLE_STEP_S = 1e-4
NOTE_STEP_S = 1e-3
#: A vehicle's median |acceleration| while moving, over windows of `ACCEL_WINDOW_S` (so that a fast logger's speed
#: noise does not count), above this (m/s^2, half a g; a drive's is under 1) means the time column runs slower than
#: seconds (minutes or hours)
MAX_MEDIAN_ACCEL_MPS2 = 5.0
ACCEL_WINDOW_S = 0.2


def _median_moving_accel(t: np.ndarray, v: np.ndarray) -> float:
    """Median |dv/dt| while moving (|v| > 1 m/s), over windows of at least `ACCEL_WINDOW_S` (whole samples), so
    that the speed noise of a fast logger is not read as acceleration; NaN with fewer than 10 such windows."""
    ok = np.isfinite(t) & np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 3:
        return float("nan")
    step = float(np.median(np.diff(t)))
    if not step > 0:
        return float("nan")
    k = max(1, int(math.ceil(ACCEL_WINDOW_S / step - 1e-9)))
    dt = t[k:] - t[:-k]
    acc = np.abs(v[k:] - v[:-k]) / np.where(dt > 0, dt, np.inf)
    moving = np.isfinite(acc) & (np.abs(v[k:]) > 1.0) & (np.abs(v[:-k]) > 1.0)
    return float(np.median(acc[moving])) if moving.sum() >= 10 else float("nan")


def _time_unit_guess(step_s: float, coarse: bool) -> list[str]:
    """The time units that make a median sample step of ``step_s`` "seconds" plausible (a step of 1 ms to 10 s),
    the likeliest first (nearest 0.3 s): ``coarse`` for a step too short (hours, minutes), else too long (ms, us,
    ns)."""
    cands = (("h", 3600.0), ("min", 60.0)) if coarse else (("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))
    ok = sorted((abs(math.log10(step_s * f) + 0.5), u) for u, f in cands
                if NOTE_STEP_S <= step_s * f * (1.0 + 1e-6) and step_s * f < MAX_PLAUSIBLE_STEP_S)
    return [u for _, u in ok]


#: Smallest plausible cell resistance seen through dV/dI (ohm): below it, with large current numbers, the
#: current column looks like milliamps.
MIN_APPARENT_RESISTANCE_OHM = 1e-4


def _unit_of(canon: str) -> tuple[str, str, dict] | None:
    for suf, units in UNITS.items():
        if canon.endswith(suf):
            return canon[: -len(suf)], suf, units
    return None


def _declared_units(columns, canon_all, units: Mapping[str, str], path) -> dict:
    """``{file column: (canonical, scale, offset, unit)}`` for columns declared in a non-SI unit: a header
    ``time_ms`` for canonical ``time_s``, or ``units={"time_s": "ms"}`` (``--unit time_s=ms``)."""
    out = {}
    for canon, unit in (units or {}).items():
        u = _unit_of(canon) if canon in canon_all else None
        if u is None:
            raise DataError(f"--unit {canon}={unit}: '{canon}' is not a canonical column with a unit "
                            f"({', '.join(canon_all)})")
        if str(unit).lower() not in u[2]:
            raise DataError(f"--unit {canon}={unit}: unknown unit '{unit}' for {canon} (known: {', '.join(u[2])})")
        sc, off = u[2][str(unit).lower()]
        out[canon] = (canon, sc, off, str(unit).lower())
    for col in columns:
        for canon in canon_all:
            u = _unit_of(canon)
            if u is None or canon in out or col == canon:
                continue
            base, suf, table = u
            if col.lower().startswith(base + "_"):
                unit = col[len(base) + 1:].lower()
                if unit in table and unit != suf[1:]:
                    if canon in columns:
                        raise DataError(f"{path}: both '{canon}' and '{col}' are in the file: keep one")
                    sc, off = table[unit]
                    out[col] = (canon, sc, off, unit)
    return out


@dataclass
class MeasuredData:
    """Measured data in canonical columns: ``df`` (pandas), ``path``, ``model``, ``notes`` (what was changed)."""
    df: pd.DataFrame
    path: str
    model: str
    notes: list = field(default_factory=list)
    #: what the loader verified: ``current_sign`` ({"file": convention of the file, "how": "stated" | "guessed",
    #: "corr_dI_dV": correlation of the canonical current's and the voltage's steps}), ``mapped`` (the columns
    #: renamed), ``units`` (columns converted)
    checks: dict = field(default_factory=dict)

    @property
    def extra_columns(self) -> list[str]:
        canon = set(REQUIRED[self.model]) | set(OPTIONAL[self.model])
        return [c for c in self.df.columns if c not in canon]


def parse_mapping(items) -> dict:
    """Parse ``["canonical=column", ...]`` into a dict (errors name the bad item)."""
    out = {}
    for it in items or ():
        if "=" not in it:
            raise DataError(f"--map '{it}': expected canonical=column")
        k, v = it.split("=", 1)
        _once("--map", out, k.strip(), v.strip())
    return out


def _once(option: str, out: dict, key: str, value) -> None:
    """``out[key] = value``, refusing a key given twice with different values (which one was meant?)."""
    if key in out and out[key] != value:
        raise DataError(f"{option} {key}={out[key]} and {option} {key}={value}: '{key}' given twice with different "
                        f"values; give it once")
    out[key] = value


def parse_units(items) -> dict:
    """Parse ``["canonical=unit", ...]`` (``--unit time_s=ms``) into a dict (errors name the bad item)."""
    out = {}
    for it in items or ():
        if "=" not in it:
            raise DataError(f"--unit '{it}': expected canonical=unit (e.g. time_s=ms)")
        k, v = it.split("=", 1)
        _once("--unit", out, k.strip(), v.strip())
    return out


def _tokens(name: str) -> list[str]:
    import re
    s = re.sub(r"([a-z])([A-Z])", r"\1_\2", str(name))
    return [t for t in re.split(r"[^0-9a-zA-Z]+", s.lower()) if t]


def _candidate_score(canon: str, col: str, values: np.ndarray) -> tuple[int, str]:
    """How well file column ``col`` fits canonical column ``canon`` by its name, its unit and its values:
    ``(score, why)``; a score of 2 or more is a candidate."""
    toks = _tokens(col)
    words = COLUMN_INFO.get(canon, ("", ()))[1]
    u = _unit_of(canon)
    score, why = 0, []
    hit = [w for w in words if w in toks]
    if hit:
        score += 3 if hit[0] == words[0] else 2
        why.append(f"name '{hit[0]}'")
    if u is not None and any(t in UNIT_WORDS.get(u[1], ()) for t in toks[1:] if len(toks) > 1):
        score += 1
        why.append("unit")
    v = values[np.isfinite(values)]
    if v.size == 0:
        return -10, "no numbers"
    if u is not None and u[1] in PLAUSIBLE:
        lo, hi = PLAUSIBLE[u[1]]
        if v.min() < lo or v.max() > hi:
            return -10, "values out of range"
    if canon == "time_s":
        if v.size > 2 and np.all(np.diff(v) >= 0):
            score += 1
        else:
            return -10, "not increasing"
    why.append(f"values {v.min():.4g}..{v.max():.4g}")
    return score, ", ".join(why)


def _candidates(raw: pd.DataFrame, missing: list[str], taken: set[str]) -> dict[str, tuple[str, str]]:
    """``{canonical: (file column, why)}``: the best unused file column for each missing canonical column,
    chosen by name, unit and plausible values (greedy, best fits first; each column offered once)."""
    num = {c: pd.to_numeric(raw[c], errors="coerce").to_numpy(float) for c in raw.columns if c not in taken}
    scored = []
    for canon in missing:
        for col, vals in num.items():
            sc, why = _candidate_score(canon, col, vals)
            if sc >= 2:
                scored.append((sc, canon, col, why))
    out: dict = {}
    used: set = set()
    for sc, canon, col, why in sorted(scored, key=lambda x: -x[0]):
        if canon not in out and col not in used:
            out[canon] = (col, why)
            used.add(col)
    return out


def _sign_corr(current: np.ndarray, voltage: np.ndarray) -> float | None:
    """corr(dI, dV) over the large current steps (None when there are fewer than 5)."""
    di, dv = np.diff(current), np.diff(voltage)
    ok = np.isfinite(di) & np.isfinite(dv)
    di, dv = di[ok], dv[ok]
    if di.size < 5:
        return None
    big = np.abs(di) > 0.05 * max(np.abs(current[np.isfinite(current)]).max(initial=0.0), 1e-9)
    if big.sum() < 5 or np.std(di[big]) == 0 or np.std(dv[big]) == 0:
        return None
    return float(np.corrcoef(di[big], dv[big])[0, 1])


def guess_current_sign(current: np.ndarray, voltage: np.ndarray) -> tuple[str | None, float | None]:
    """The file's current sign convention from its voltage response: a cell's voltage falls when discharge
    current rises, so corr(dI, dV) < 0 means discharge-positive and > 0 charge-positive.  ``(sign, corr)``;
    sign None when the correlation is weaker than :data:`SIGN_GUESS_MIN_CORR`."""
    c = _sign_corr(np.asarray(current, float), np.asarray(voltage, float))
    if c is None or abs(c) < SIGN_GUESS_MIN_CORR:
        return None, c
    return ("charge-positive" if c > 0 else "discharge-positive"), c


def _precheck(path: Path, raw: pd.DataFrame, model: str, mapping: dict, canon_all, current_sign: str,
              drop_duplicate_rows: bool, line_of: np.ndarray, ambient: tuple | None = None) -> tuple:
    """Every problem the column layout shows at once (bad --map items, missing columns with candidates, repeated
    rows, a current sign that contradicts the data), with the options that fix them.  Returns ``(guessed,
    problems, fixes, cols, note)``: the current sign guessed from the data (``current_sign="auto"``, else None),
    the problems (text), ``{key: option}``, the file column of each required column (the candidate where one
    is missing: what the unit checks read when the layout has problems) and what to add to the message (the
    guessed sign).  ``ambient``: ``(value_degc, where)`` of a constant ambient given instead of a column."""
    problems: list[str] = []
    fixes: dict[str, str] = {}
    cand_units: dict[str, str] = {}
    for canon, col in mapping.items():
        if canon not in canon_all:
            problems.append(f"--map {canon}={col}: '{canon}' is not a canonical column of model '{model}' "
                            f"({', '.join(canon_all)})")
        elif col not in raw.columns:
            best = difflib.get_close_matches(col, list(raw.columns), n=1)
            hint = f" (did you mean '{best[0]}'?)" if best else ""
            problems.append(f"column '{col}' (mapped to {canon}) not found{hint}; columns: {', '.join(raw.columns)}")
    have = {canon: (mapping[canon] if canon in mapping else canon) for canon in canon_all
            if (canon in mapping and mapping[canon] in raw.columns) or (canon not in mapping and canon in raw.columns)}
    if ambient is not None and "t_ambient_c" in have:
        problems.append(f"the file has an ambient column ('{have['t_ambient_c']}') and {ambient[1]} gives a constant "
                        f"{ambient[0]:g} degC: keep one (drop {ambient[1].split(' in ')[0]} to use the column)")
    missing = [c for c in REQUIRED[model] if c not in have and c not in mapping
               and not (c == "t_ambient_c" and ambient is not None)]
    cands = _candidates(raw, missing, set(have.values()) | set(mapping.values()))
    for c in missing:
        what = COLUMN_INFO.get(c, (c, ()))[0]
        # a chamber or a room at one temperature: a constant, not a column
        alt = (f"; for a constant ambient pass {AMBIENT_OPTION} DEGC (or t_ambient_c = DEGC in the --params "
               f"file's [params])" if c == "t_ambient_c" else "")
        if c in cands:
            col, why = cands[c]
            fix = f"--map {c}={col}"
            unit = _name_unit(c, col)
            if unit is not None:                        # its name says its unit: converted with it
                fix += f" --unit {c}={unit}"
                cand_units[c] = unit
            problems.append(f"missing required column '{c}' ({what}) for model '{model}'; candidate '{col}' "
                            f"({why}): use {fix} if that is it{alt}")
            fixes[f"map:{c}"] = fix
        else:
            problems.append(f"missing required column '{c}' ({what}) for model '{model}'; no column looks like it "
                            f"by name, unit and values; columns: {', '.join(raw.columns)}{alt}")
            if alt:
                fixes[f"map:{c}"] = f"{AMBIENT_OPTION} DEGC"
    cols = {c: have.get(c) or (cands[c][0] if c in cands else None) for c in REQUIRED[model]}
    # repeated rows (identical to the previous row in every column): a logger repeat
    if cols.get("time_s"):
        t = pd.to_numeric(raw[cols["time_s"]], errors="coerce").to_numpy(float)
        same_t = np.flatnonzero(np.diff(t) == 0)
        if same_t.size:
            arr = raw.to_numpy()
            ident = np.array([all((a == b) or (a != a and b != b) for a, b in zip(arr[k], arr[k + 1]))
                              for k in same_t[:1000]])
            lines = ", ".join(f"{_row_of(k, line_of)}/{_row_of(k + 1, line_of)}" for k in same_t[:3])
            more = " ..." if same_t.size > 3 else ""
            if ident.all() and same_t.size <= 1000:
                if not drop_duplicate_rows:
                    problems.append(f"identical rows: {same_t.size} row(s) repeat the previous row in every column (a "
                                    f"logger repeat; lines {lines}{more}): pass --drop-duplicate-rows to drop them")
                    fixes["dup"] = "--drop-duplicate-rows"
            else:
                k = int(same_t[~ident][0]) if (~ident).any() else int(same_t[0])
                problems.append(f"column 'time_s': duplicate time {t[k]} s at lines {_row_of(k, line_of)} and "
                                f"{_row_of(k + 1, line_of)} (different values; {same_t.size} duplicate(s) in total)")
    guessed = None
    if model == "cell" and cols.get("current_a") and cols.get("voltage_v"):
        i = pd.to_numeric(raw[cols["current_a"]], errors="coerce").to_numpy(float)
        v = pd.to_numeric(raw[cols["voltage_v"]], errors="coerce").to_numpy(float)
        sign, corr = guess_current_sign(i, v)
        if current_sign == "auto":
            if sign is None:
                problems.append(f"column 'current_a': the current sign cannot be told from the data (corr(dI, dV) = "
                                f"{'n/a' if corr is None else f'{corr:+.2f}'}); pass --current-sign "
                                f"discharge-positive or charge-positive")
            else:
                guessed = sign
        elif current_sign in CURRENT_SIGNS and sign is not None and sign != current_sign:
            problems.append(f"column 'current_a': voltage {'rises' if corr > 0 else 'falls'} when current rises "
                            f"(corr(dI, dV) = {corr:+.2f}) - the current sign looks inverted for '{current_sign}'; "
                            f"pass --current-sign {sign} (or leave --current-sign out: it is then guessed from "
                            f"the data)")
            fixes["sign"] = f"--current-sign {sign}"
    note = (f"\n  (current sign guessed from the data: {guessed}, corr(dI, dV) = {corr:+.2f}; "
            f"stated with --current-sign to override)") if guessed else ""
    return guessed, problems, fixes, {c: (col, cand_units.get(c)) for c, col in cols.items()}, note


def _name_unit(canon: str, col: str) -> str | None:
    """The non-SI unit a file column's name ends with (``HVBatt_Pwr_kW`` -> ``kw`` for ``power_w``), else None."""
    import re
    u = _unit_of(canon)
    last = re.split(r"[^0-9a-zA-Z]+", str(col).strip())[-1]
    if u is None or last == str(col).strip() or last.lower() not in u[2] or last.lower() == u[1][1:]:
        return None
    return last


def _problems_error(path: Path, problems: list, fixes: dict, note: str = "") -> DataError:
    """One DataError listing every problem of the file (one alone: as it is), with the options that fix them."""
    if len(problems) == 1:
        msg = f"{path}: {problems[0]}"
    else:
        msg = f"{path}: {len(problems)} problems (all of them; fix them together):\n" + "\n".join(
            f"  - {p}" for p in problems)
    opts = list(dict.fromkeys(fixes.values()))
    if len(opts) > 1 or (opts and len(problems) > 1):
        msg += "\n  the options that fix the fixable ones: " + " ".join(
            o for o in opts if not any(o != x and o in x for x in opts))
    return DataError(msg + note)


def _row_of(df_index: int, line_of: np.ndarray) -> int:
    return int(line_of[df_index])


#: compressed records, by the file name's last suffix (any case): read decompressed, as pandas would
_COMPRESSED = {".gz": "gzip", ".bz2": "bz2", ".xz": "xz", ".zip": "zip"}


def _record_bytes(path: Path) -> bytes:
    """The record's bytes, decompressed by its suffix (`_COMPRESSED`; a .zip holding exactly one file); a damaged
    archive is a DataError naming the file."""
    import bz2
    import gzip
    import lzma
    import zipfile
    import zlib
    kind = _COMPRESSED.get(path.suffix.lower())
    try:
        if kind is None:
            return path.read_bytes()
        if kind == "zip":
            with zipfile.ZipFile(path) as z:
                names = [n for n in z.namelist() if not n.endswith("/")]
                if len(names) != 1:
                    raise DataError(f"{path}: a .zip record must hold exactly one file (it holds {len(names)}: "
                                    f"{', '.join(names[:4])})")
                return z.read(names[0])
        return {"gzip": gzip, "bz2": bz2, "xz": lzma}[kind].decompress(path.read_bytes())
    except DataError:
        raise
    except OSError as exc:
        raise DataError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    except (EOFError, ValueError, zlib.error, lzma.LZMAError, zipfile.BadZipFile, RuntimeError) as exc:
        raise DataError(f"{path}: a damaged {kind} file: {type(exc).__name__}: {exc}") from None


def _file_lines(text: str) -> np.ndarray:
    """1-based file line number of each data row (skipping comment lines and the header)."""
    lines = []
    header_seen = False
    for ln, line in enumerate(text.split("\n"), start=1):     # as the parser counts lines (not \x0c, \x85 ...)
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if not header_seen:
            header_seen = True
            continue
        lines.append(ln)
    return np.asarray(lines, dtype=np.int64)


def _runs(mask: np.ndarray):
    """Start/end indices (inclusive) of runs of True."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def _sniff_format(text: str) -> dict:
    """pandas options for a CSV as spreadsheets export it: ``;`` separators with decimal commas, tabs."""
    for line in text.splitlines():
        s = line.strip()
        if s and not s.startswith("#"):
            if ";" in s and "," not in s:
                return {"sep": ";", "decimal": ","}
            if "\t" in s and "," not in s:
                return {"sep": "\t"}
            return {}
    return {}


#: the command-line option that gives a cell record's ambient temperature as a constant
AMBIENT_OPTION = "--ambient-c"
#: the plausible range of an ambient temperature [degC] (a column's: the unit checks')
AMBIENT_RANGE_C = (-60.0, 150.0)
#: required columns a record may give as a constant instead, per model: column -> the option that gives it
CONSTANT_COLUMNS = {"cell": {"t_ambient_c": AMBIENT_OPTION}}


def check_ambient(value, where: str = AMBIENT_OPTION, model: str = "cell") -> float:
    """A constant ambient temperature [degC] as a float; a DataError naming ``where`` (the option or the
    ``--params`` key that gave it) when it is not a number in :data:`AMBIENT_RANGE_C` or the model has no
    ambient input."""
    if "t_ambient_c" not in CONSTANT_COLUMNS.get(model, {}):
        raise DataError(f"{where}: a constant ambient temperature is an input of model 'cell' only, not '{model}'")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DataError(f"{where}: ambient temperature {value!r} is not a number (degC)") from None
    lo, hi = AMBIENT_RANGE_C
    if not (lo <= v <= hi):
        raise DataError(f"{where} {value!r}: ambient temperature outside the plausible range [{lo:g}, {hi:g}] degC "
                        f"(degC, not kelvin or degF)")
    return v


def _check_options(model: str, current_sign: str, power_sign: str) -> None:
    """Refuse an unknown model or sign convention before the file is opened."""
    if model not in REQUIRED:
        raise DataError(f"unknown model '{model}'; available: {', '.join(REQUIRED)}")
    if current_sign not in CURRENT_SIGNS + ("auto",):
        raise DataError(f"current sign '{current_sign}': expected one of {CURRENT_SIGNS + ('auto',)}")
    if power_sign not in POWER_SIGNS:
        raise DataError(f"power sign '{power_sign}': expected one of {POWER_SIGNS}")


def _read_table(path: Path) -> tuple[pd.DataFrame, np.ndarray]:
    """Parse the CSV as written (no conversion yet); return it and each data row's file line number."""
    from ..core.errors import file_problem
    why = file_problem(path, "data file")
    if why is not None:
        raise DataError(f"{path}: {why}")
    import io
    import warnings
    text, enc_note = decode_text(_record_bytes(path), path, decompresses=True)
    try:
        with warnings.catch_warnings():
            # a row longer than the header would lose its extra values silently: an error instead
            warnings.simplefilter("error", pd.errors.ParserWarning)
            raw = pd.read_csv(io.StringIO(text), comment="#", skipinitialspace=True, index_col=False,
                              **_sniff_format(text))
    except pd.errors.ParserWarning as exc:
        raise DataError(f"{path}: a data row has more values than the header has columns ({exc}); nothing is "
                        f"dropped silently: fix the header or the row") from exc
    except Exception as exc:  # pandas parser errors carry the line
        raise DataError(f"{path}: cannot parse CSV: {type(exc).__name__}: {exc}") from exc
    raw.columns = [str(c).strip() for c in raw.columns]
    empty = [c for c in raw.columns if (c == "" or c.startswith("Unnamed:")) and raw[c].isna().all()]
    if empty:   # trailing separators of a spreadsheet export
        raw = raw.drop(columns=empty)
    if len(set(raw.columns)) != len(raw.columns) or any(c.endswith(".1") and c[:-2] in raw.columns
                                                        for c in raw.columns):
        raise DataError(f"{path}: duplicate column names in the header ({', '.join(raw.columns)})")
    if raw.shape[0] < 3:
        raise DataError(f"{path}: only {raw.shape[0]} data rows")
    line_of = _file_lines(text)
    if line_of.size != raw.shape[0]:  # blank lines inside etc.: fall back to header offset
        line_of = np.arange(raw.shape[0]) + 2
    raw.attrs["encoding_note"] = enc_note
    return raw, line_of


#: timestamps a time column may hold instead of seconds: ISO 8601 date and time (``2026-11-27 10:00:01.5``,
#: ``...T10:00:01Z``, ``...+01:00``), and a time of day or an elapsed time (``10:00:01.5``, ``0 days 00:00:01``)
_ISO_STAMP = r"^\d{4}-\d{2}-\d{2}[T ]\d{1,2}:\d{2}(:\d{2}([.,]\d+)?)?(Z|[+-]\d{2}:?\d{2})?$"
_CLOCK_STAMP = r"^(\d+ days? )?\d{1,7}:\d{2}:\d{2}([.,]\d+)?$"


def _timestamps_to_seconds(raw: pd.DataFrame, mapping: dict, declared: dict, path: Path,
                           line_of: np.ndarray) -> str | None:
    """A time column of timestamps (`_ISO_STAMP`, `_CLOCK_STAMP`; every value in one of the two forms) replaced in
    ``raw`` by the seconds from its first value; the note saying so, else None.  A time of day that passes
    midnight goes on into the next day.  A unit declared for such a column is refused (a timestamp has its own);
    any other text is left to the numeric checks (named with its line), with a hint when it looks like a date."""
    col = mapping.get("time_s", "time_s")
    if col not in raw.columns or pd.api.types.is_numeric_dtype(raw[col]):
        return None
    txt = raw[col].astype(str).str.strip().str.replace(",", ".", regex=False)   # ISO 8601's decimal comma
    forms = (("ISO 8601 date and time", _ISO_STAMP), ("hh:mm:ss", _CLOCK_STAMP))
    form = next((f for f, rx in forms if txt.str.fullmatch(rx).all()), None)
    for f, rx in forms:       # most values a timestamp of one form: the first that is not, named
        m = txt.str.fullmatch(rx).to_numpy()
        if form is None and m.mean() > 0.5:
            k = int(np.flatnonzero(~m)[0])
            raise DataError(f"{path}: column '{col}', line {_row_of(k, line_of)}: {raw[col].iloc[k]!r} is not a "
                            f"timestamp ({f}) like the other values of the column")
    if form is None:
        if txt.str.contains(r"\d[:/.]\d+[:/.]\d", regex=True).mean() > 0.5 \
                and pd.to_numeric(txt, errors="coerce").isna().mean() > 0.5:
            k = int(np.flatnonzero(pd.to_numeric(txt, errors="coerce").isna().to_numpy())[0])
            raise DataError(f"{path}: column '{col}', line {_row_of(k, line_of)} and on: {txt.iloc[k]!r} looks like a timestamp "
                            f"in a form other than ISO 8601 (2026-11-27 10:00:01.5) or hh:mm:ss (a day-first or "
                            f"month-first date is ambiguous): write the time so, or as seconds")
        return None
    unit = next((d[3] for c, d in declared.items() if d[0] == "time_s" and c in (col, "time_s")), None)
    if unit not in (None, "s"):
        raise DataError(f"{path}: column '{col}' holds timestamps ({form}), which carry their own unit; a unit "
                        f"'{unit}' was declared for it: drop it (--unit / the header's suffix)")
    if form.startswith("ISO"):
        try:
            stamps = pd.to_datetime(txt, format="ISO8601", utc=True)
        except (ValueError, OverflowError) as exc:
            raise DataError(f"{path}: column '{col}': a timestamp that is no date ({exc})") from None
        sec = (stamps - stamps.iloc[0]).dt.total_seconds().to_numpy(float)
    else:
        sec = pd.to_timedelta(txt).dt.total_seconds().to_numpy(float)
        back = np.diff(sec) < -43200.0            # a time of day past midnight
        sec = sec + 86400.0 * np.concatenate([[0], np.cumsum(back)])
        sec = sec - sec[0]
    raw[col] = sec
    return f"time column '{col}' read as timestamps ({form}): seconds from the first, {txt.iloc[0]}"


def _column_mapping(raw: pd.DataFrame, model: str, mapping, units, path: Path) -> tuple[dict, dict]:
    """The file column of each canonical name (``--map`` plus unit-suffixed headers) and the declared units."""
    mapping = dict(mapping or {})
    canon_all = REQUIRED[model] + OPTIONAL[model]
    declared = _declared_units(list(raw.columns), canon_all, dict(units or {}), path)
    for col, (canon, _, _, _) in list(declared.items()):
        if col != canon and col in raw.columns and canon not in mapping:
            mapping[canon] = col
    for canon, col in mapping.items():
        if canon not in canon_all:
            raise DataError(f"--map {canon}={col}: '{canon}' is not a canonical column of model '{model}' "
                            f"({', '.join(canon_all)})")
    return mapping, declared


def _rename_to_canonical(raw: pd.DataFrame, model: str, mapping: dict, path: Path, supplied=()) -> pd.DataFrame:
    """Rename mapped columns to their canonical names; refuse a missing required column (not in ``supplied``: given
    otherwise) with a best match."""
    rename = {col: canon for canon, col in mapping.items()}
    # a canonical name already present in the file and also mapped from another column: the mapped wins
    df = raw.drop(columns=[c for c in raw.columns if c in mapping and c not in rename]).rename(columns=rename)
    for col in REQUIRED[model]:
        if col not in df.columns and col not in supplied:
            best = difflib.get_close_matches(col, list(df.columns), n=1, cutoff=0.3)
            hint = f"; use --map {col}={best[0]} if that is it" if best else ""
            raise DataError(f"{path}: missing required column '{col}' for model '{model}'{hint}; "
                            f"columns: {', '.join(df.columns)}")
    return df


def _numeric_columns(df: pd.DataFrame, canon_all, path: Path, line_of: np.ndarray, notes: list,
                     problems: list | None = None) -> pd.DataFrame:
    """Every column as float: a non-numeric or NaN canonical value is an error naming the line (appended to
    ``problems`` when given, the value read as NaN; else raised); an extra column with either is dropped (said
    in ``notes``)."""
    def fail(msg):
        if problems is None:
            raise DataError(f"{path}: {msg}")
        problems.append(msg)

    for col in list(df.columns):
        conv = pd.to_numeric(df[col], errors="coerce")
        bad = conv.isna() & df[col].notna() & (df[col].astype(str).str.strip().str.lower() != "nan")
        if bad.any():
            k = int(np.flatnonzero(bad.to_numpy())[0])
            if col in canon_all:
                fail(f"column '{col}', line {_row_of(k, line_of)}: non-numeric value {df[col].iloc[k]!r}"
                     + (f" ({int(bad.sum())} in all)" if bad.sum() > 1 else ""))
                df[col] = conv.astype(float)
                continue
            notes.append(f"extra column '{col}' is not numeric and was dropped")
            df = df.drop(columns=[col])
            continue
        df[col] = conv.astype(float)
        # NaN runs in required/optional canonical columns
        nan = df[col].isna().to_numpy()
        if col in canon_all and nan.any():
            runs = _runs(nan)
            a, b = runs[0]
            fail(f"column '{col}' has {int(nan.sum())} NaN value(s) in {len(runs)} run(s); first run lines "
                 f"{_row_of(a, line_of)}-{_row_of(b, line_of)} ({b - a + 1} samples)")
        # an infinite value, or an instrument's overload code (9.9E+37): no measurement, and it would carry
        # through every fit and RMSE as inf/NaN
        x = df[col].to_numpy(float)
        over = ~nan & ~(np.abs(x) < OVERLOAD_VALUE)
        if col in canon_all and over.any():
            k = np.flatnonzero(over)
            fail(f"column '{col}', line {_row_of(int(k[0]), line_of)}: value {x[k[0]]:.4g} is "
                 f"{'infinite' if not np.isfinite(x[k[0]]) else 'no measurement (an overload or error code)'}"
                 + (f" ({k.size} in all)" if k.size > 1 else "") + "; fix or remove those rows")
            df[col] = np.where(over, np.nan, x)
    for col in list(df.columns):
        if col not in canon_all and not np.isfinite(df[col].to_numpy(float)).all():
            notes.append(f"extra column '{col}' has NaN or infinite values and was dropped from the candidate signals")
            df = df.drop(columns=[col])
    return df


def _check_time(df: pd.DataFrame, path: Path, line_of: np.ndarray, drop_duplicate_rows: bool,
                notes: list, problems: list | None = None) -> tuple[pd.DataFrame, np.ndarray]:
    """Time must increase strictly; identical duplicate rows are dropped only when asked.  A problem is appended
    to ``problems`` when given (else raised)."""
    if problems is not None:
        try:
            return _check_time(df, path, line_of, drop_duplicate_rows, notes)
        except DataError as exc:
            problems.append(str(exc).removeprefix(f"{path}: "))
            return df, line_of
    t = df["time_s"].to_numpy()
    dt = np.diff(t)
    dup = np.flatnonzero(dt == 0)
    if dup.size:
        same = np.array([np.array_equal(df.iloc[k].to_numpy(), df.iloc[k + 1].to_numpy(), equal_nan=True)
                         for k in dup[:1000]])
        if drop_duplicate_rows and same.all() and dup.size <= 1000:
            keep = np.ones(len(df), bool)
            keep[dup + 1] = False
            df = df[keep].reset_index(drop=True)
            line_of = line_of[keep]
            notes.append(f"dropped {dup.size} duplicate row(s) (identical in every column)")
            t = df["time_s"].to_numpy()
            dt = np.diff(t)
        else:
            k = int(dup[0])
            kind = "identical rows" if same[0] else "different values"
            hint = "; pass --drop-duplicate-rows to drop identical duplicates" if same[0] else ""
            raise DataError(f"{path}: column 'time_s': duplicate time {t[k]} s at lines "
                            f"{_row_of(k, line_of)} and {_row_of(k + 1, line_of)} ({kind}; {dup.size} "
                            f"duplicate(s) in total){hint}")
    back = np.flatnonzero(dt < 0)
    if back.size:
        k = int(back[0])
        raise DataError(f"{path}: column 'time_s': time goes backwards at line {_row_of(k + 1, line_of)} "
                        f"({t[k]} -> {t[k + 1]} s); time must increase strictly")
    return df, line_of


#: more long sample steps than this in a record: variable-rate sampling (a logger that samples on change, slowly at
#: rest: the shipped Nissan Leaf records have 224), said as such rather than as dropouts
GAP_NOTE_MANY = 10


def time_gaps(t: np.ndarray) -> tuple[np.ndarray, float]:
    """The sample steps of ``t`` longer than ``GAP_STEPS`` x its median step (a logger dropout; the same rule as
    :func:`shevsim.calibrate.timing.band_limited_read`): ``(indices k of the steps t[k] -> t[k+1], median step)``."""
    from .timing import GAP_STEPS
    dt = np.diff(np.asarray(t, float))
    if dt.size < 2:
        return np.array([], dtype=int), float(dt[0]) if dt.size else 0.0
    h = float(np.median(dt))
    return np.flatnonzero(dt > GAP_STEPS * h), h


def gap_note(t: np.ndarray, line_of: np.ndarray | None = None) -> str | None:
    """What the report says of a record's time gaps (None: none): how many, the longest and where, and that the
    model's inputs are interpolated linearly across a gap (the record is simulated on its median-step grid)."""
    k, h = time_gaps(t)
    if not k.size:
        return None
    t = np.asarray(t, float)
    j = int(k[np.argmax(t[k + 1] - t[k])])
    where = (f"lines {_row_of(j, line_of)}-{_row_of(j + 1, line_of)}" if line_of is not None
             else f"t = {t[j]:g} s")
    if k.size > GAP_NOTE_MANY:     # a logger that samples on change (slowly at rest): not dropouts
        return (f"variable sampling: {k.size} sample steps longer than 10x the median step {h:g} s, the longest "
                f"{t[j + 1] - t[j]:g} s ({where}); the model's inputs are interpolated linearly between samples - "
                f"right for a logger that samples on change, not across a stop of the logger")
    return (f"time gaps: {k.size} sample step(s) longer than 10x the median step {h:g} s, the longest "
            f"{t[j + 1] - t[j]:g} s ({where}, {t[j]:g} -> {t[j + 1]:g} s); the model's inputs are interpolated "
            f"linearly across a gap - if the logger was off there, cut the record at the gap and calibrate the "
            f"parts")


def _check_current_sign(df: pd.DataFrame, path: Path, current_sign: str) -> None:
    """After conversion, the voltage of a cell must fall as the (discharge-positive) current rises."""
    di = np.diff(df["current_a"].to_numpy())
    dv = np.diff(df["voltage_v"].to_numpy())
    big = np.abs(di) > 0.05 * max(np.abs(df["current_a"]).max(), 1e-9)
    if big.sum() >= 5:
        c = np.corrcoef(di[big], dv[big])[0, 1]
        if c > 0.3:
            other = [s for s in CURRENT_SIGNS if s != current_sign][0]
            raise DataError(f"{path}: column 'current_a': voltage rises when current rises (corr(dI, dV) = "
                            f"{c:+.2f}) - the current sign looks inverted for '{current_sign}'; "
                            f"pass --current-sign {other}")


def load_measured(path, model: str, mapping: Mapping[str, str] | None = None,
                  current_sign: str = "discharge-positive", power_sign: str = "drawn-positive",
                  drop_duplicate_rows: bool = False, check_sign: bool = True,
                  units: Mapping[str, str] | None = None, check_units: bool = True,
                  ambient_c: float | None = None, ambient_from: str = "--ambient-c") -> MeasuredData:
    """Load and check a measured CSV for calibration model ``model`` (``cell`` or ``vehicle``).

    Columns in other units are converted when the unit is declared: by the header (``time_ms``,
    ``current_ma``, ``speed_kmh``, ``power_kw``, ``t_surface_k`` ...) or by ``units`` (``{"time_s": "ms"}``,
    CLI ``--unit time_s=ms``).  Undeclared units that look wrong (time in ms, current in mA, speed in km/h,
    power in kW, temperature in K, voltage in mV) are refused with what was detected and how to declare
    it.  Spreadsheet quirks are read as they come: UTF-8 byte-order mark, CRLF, ``;`` with decimal commas,
    tabs, trailing empty columns.

    ``ambient_c`` (a cell record without an ambient column: a chamber or a room at one temperature) gives
    ``t_ambient_c`` as that constant [degC], stated in ``notes`` with ``ambient_from`` (what gave it: the
    option ``--ambient-c`` or ``t_ambient_c`` in a ``--params`` file); a value outside [-60, 150] degC, a model
    other than ``cell`` or a file that has an ambient column too is refused naming it.

    Returns
    -------
    MeasuredData
        canonical columns (SI, signs as documented in the module docstring) plus all extra numeric columns.
    """
    path = Path(path)
    _check_options(model, current_sign, power_sign)
    ambient = None if ambient_c is None else (check_ambient(ambient_c, ambient_from, model), ambient_from)
    raw, line_of = _read_table(path)
    mapping, declared = _column_mapping(raw, model, mapping, units, path)
    stamp_note = _timestamps_to_seconds(raw, mapping, declared, path, line_of)
    canon_all = REQUIRED[model] + OPTIONAL[model]
    guessed, problems, fixes, cols, note = _precheck(
        path, raw, model, mapping, canon_all, current_sign if check_sign or current_sign == "auto" else "auto-skip",
        drop_duplicate_rows, line_of, ambient)
    if problems:
        # the columns' units too, read from the columns there are (a missing one's candidate), so that every
        # problem of the file is listed at once
        if check_units:
            _unit_problems_into(_provisional_frame(raw, cols, declared), model, line_of,
                                {d[0] for d in declared.values()}, problems, fixes)
        raise _problems_error(path, problems, fixes, note)
    notes = [n for n in (raw.attrs.get("encoding_note"), stamp_note) if n]
    sign_how = "guessed" if current_sign == "auto" else "stated"
    if current_sign == "auto":
        if guessed is None:         # no current/voltage (not a cell): the canonical convention
            current_sign = "discharge-positive"
        else:
            current_sign = guessed
            notes.append(f"current sign guessed from the data: {guessed} (the voltage "
                         f"{'rises' if guessed == 'charge-positive' else 'falls'} as the file's current rises); "
                         f"pass --current-sign to state it")
    df = _rename_to_canonical(raw, model, mapping, path, ("t_ambient_c",) if ambient else ())
    if ambient:
        df["t_ambient_c"] = ambient[0]
        notes.append(f"ambient: constant {ambient[0]:g} degC, given by {ambient[1]}")
    # the values (numbers, no NaN runs), the time (increasing) and every column's unit: all problems at once
    problems, fixes = [], {}
    df = _numeric_columns(df, canon_all, path, line_of, notes, problems)
    # declared units: converted to SI before any check
    for col, (canon, sc, off, unit) in declared.items():
        if canon in df.columns and (sc != 1.0 or off != 0.0):
            df[canon] = df[canon] * sc + off
            notes.append(f"column '{canon}' converted from {unit} (declared by "
                         f"{'the header' if col != canon else '--unit'})")
    df, line_of = _check_time(df, path, line_of, drop_duplicate_rows, notes, problems)
    if not problems:
        gap = gap_note(df["time_s"].to_numpy(float), line_of)
        if gap:
            notes.append(gap)
    if check_units:
        _unit_problems_into(df, model, line_of, {d[0] for d in declared.values()}, problems, fixes, notes)
    if problems:
        raise _problems_error(path, problems, fixes)
    if "current_a" in SIGNED[model] and current_sign == CURRENT_SIGNS[1]:
        df["current_a"] = -df["current_a"]
        notes.append("current negated (file: charge positive -> canonical: discharge positive)")
    if "power_w" in SIGNED[model] and power_sign == POWER_SIGNS[1]:
        df["power_w"] = -df["power_w"]
        notes.append("power negated (file: delivered positive -> canonical: drawn positive)")
    checks: dict = {"mapped": dict(mapping), "units": {c: u for c, (_, _, _, u) in declared.items()}}
    if model == "cell":
        checks["current_sign"] = {"file": current_sign, "how": sign_how,
                                  "corr_dI_dV": _sign_corr(df["current_a"].to_numpy(), df["voltage_v"].to_numpy())}
    if model == "cell" and check_sign:
        _check_current_sign(df, path, current_sign)
    return MeasuredData(df=df, path=str(path), model=model, notes=notes, checks=checks)


def _provisional_frame(raw: pd.DataFrame, cols: dict, declared: dict) -> pd.DataFrame:
    """The required columns found (or their candidates, in the unit their name says) as numbers in SI (declared
    units converted): what the unit checks read when the column layout has problems of its own - the file as the
    options the message offers would read it.  ``cols``: ``{canonical: (file column or None, unit or None)}``."""
    out = {}
    for canon, (col, unit) in cols.items():
        if col is None or col not in raw.columns:
            continue
        x = pd.to_numeric(raw[col], errors="coerce").to_numpy(float)
        if not np.isfinite(x).any():
            continue
        d = declared.get(col)
        if d is not None and d[0] == canon:
            x = x * d[1] + d[2]
        elif unit is not None:
            sc, off = _unit_of(canon)[2][unit.lower()]
            x = x * sc + off
        out[canon] = x
    return pd.DataFrame(out)


def _check_units(df, model, path, line_of, declared=frozenset()):
    """Every unit problem of the record's columns at once (:func:`_unit_problems_into`): one DataError."""
    problems: list = []
    fixes: dict = {}
    _unit_problems_into(df, model, line_of, declared, problems, fixes)
    if problems:
        raise _problems_error(path, problems, fixes)


def _unit_problems_into(df, model, line_of, declared, problems: list, fixes: dict, notes: list | None = None) -> None:
    """The unit checks of each canonical column there is (time in ms, current in mA, speed in km/h, power in kW,
    temperature in K, voltage in mV, implausible values): each problem appended to ``problems`` as
    ``column 'X', line N: what was detected; the option that fixes it``, the option into ``fixes``; what is only
    likely (a 1-10 kHz time step: hours or minutes?) into ``notes`` when given."""
    def bad(col, msg, k, fix=None):
        problems.append(f"column '{col}', line {_row_of(k, line_of)}: {msg}")
        if fix:
            fixes[f"unit:{col}"] = fix

    def arr(col):
        return df[col].to_numpy(float) if col in df else None

    t = arr("time_s")
    dt = np.diff(t) if t is not None else np.array([])
    dt = dt[np.isfinite(dt)]
    step = float(np.median(dt)) if dt.size else float("nan")
    words = {"ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds", "min": "minutes", "h": "hours"}

    def units_text(us):
        return " or ".join(words[u] for u in us)

    def fix_text(col_, us):
        return (f"name the column '{col_[:-2]}_{us[0]}' or pass " + " / ".join(f"--unit {col_}={u}" for u in us))

    tol = 1.0 + 1e-6            # a step read back from text lands a rounding error either side of its value
    if "time_s" not in declared and dt.size and (step >= MAX_PLAUSIBLE_STEP_S or 0.0 < step * tol < MIN_PLAUSIBLE_STEP_S):
        coarse = step < MIN_PLAUSIBLE_STEP_S
        us = _time_unit_guess(step, coarse)
        what = (f"looks like {units_text(us)}" if us else
                f"is not in seconds (no time unit brings it to {NOTE_STEP_S:g}-{MAX_PLAUSIBLE_STEP_S:g} s)")
        bad("time_s", f"median sample step {step:g} s {what} (calibration records are sampled every 0.001-1 s)"
                      + (f"; {fix_text('time_s', us)} to convert" if us else "")
                      + f" (--unit time_s=s if the step really is that {'short' if coarse else 'long'})", 1,
            f"--unit time_s={us[0]}" if us else None)
        return_early = True
    else:
        return_early = False
    if not return_early and "time_s" not in declared and dt.size and step < 0.9 * NOTE_STEP_S and notes is not None:
        us = _time_unit_guess(step, True)
        if us:
            notes.append(f"column 'time_s': median sample step {step:g} s ({1.0 / step:.3g} Hz); if the time is in "
                         f"{units_text(us)} rather than seconds, pass " + " / ".join(f"--unit time_s={u}" for u in us))
    if not return_early and model == "vehicle" and "time_s" not in declared and dt.size and "speed_mps" in df:
        s = arr("speed_mps")
        tt = np.diff(t)
        acc = np.abs(np.diff(s)) / np.where(tt > 0, tt, np.inf)
        med = _median_moving_accel(t, s)
        if np.nanmax(s) - np.nanmin(s) > 2.0 and np.nanmax(acc) < 0.02:
            bad("time_s", f"speed varies by {np.nanmax(s) - np.nanmin(s):.3g} m/s but never faster than "
                          f"{np.nanmax(acc):.2g} m/s^2: the time column looks like milliseconds; name it 'time_ms' or "
                          f"pass --unit time_s=ms", 1, "--unit time_s=ms")
        elif med > MAX_MEDIAN_ACCEL_MPS2:
            bad("time_s", f"the speed changes by a median {med:.3g} m/s^2 while moving ({med / 9.81:.2g} g, over "
                          f"{ACCEL_WINDOW_S:g} s or a sample; a drive's is under 1 m/s^2): the time column looks like "
                          f"minutes or hours; {fix_text('time_s', ['min', 'h'])} (--unit time_s=s if it really is in "
                          f"seconds)", 1, "--unit time_s=min")
    if model == "cell" and "current_a" not in declared and "current_a" in df and "voltage_v" in df:
        i = arr("current_a")
        di, dv = np.diff(i), np.diff(arr("voltage_v"))
        ok = np.isfinite(di) & np.isfinite(dv)
        big = ok & (np.abs(np.nan_to_num(di)) > 0.05 * max(np.nanmax(np.abs(i)), 1e-12))
        if big.sum() >= 5 and np.nanmax(np.abs(i)) > 50.0:
            r_app = float(np.median(np.abs(dv[big] / di[big])))
            if r_app < MIN_APPARENT_RESISTANCE_OHM:
                bad("current_a", f"the voltage moves {r_app:.2g} V per unit of current, i.e. a cell resistance "
                                 f"of {r_app * 1e3:.3g} mOhm if the column is in A - implausibly small, while the "
                                 f"largest current is {np.nanmax(np.abs(i)):.4g}: the column looks like milliamps; "
                                 f"name it 'current_ma' or pass --unit current_a=mA", int(np.nanargmax(np.abs(i))),
                    "--unit current_a=mA")

    if model == "cell":
        for col in ("t_surface_c", "t_ambient_c", "t_core_c"):
            if col not in df:
                continue
            x = arr(col)
            if not np.isfinite(x).any():        # no value (NaN or refused as infinite): said by the value checks
                continue
            if np.nanmedian(x) > 150.0:
                bad(col, f"median {np.nanmedian(x):.1f} looks like kelvin, expected degC (name the column "
                         f"'{col[:-2]}_k' or pass --unit {col}=K to convert)", int(np.argmax(x > 150)),
                    f"--unit {col}=K")
                continue
            k = np.flatnonzero((x < -60.0) | (x > 150.0))
            if k.size:
                bad(col, f"temperature {x[k[0]]} degC outside the plausible range [-60, 150]", int(k[0]))
        v = arr("voltage_v")
        if v is not None:
            if np.nanmedian(v) > 100:
                bad("voltage_v", f"median {np.nanmedian(v):.0f} looks like millivolts, expected V (name the column "
                                 f"'voltage_mv' or pass --unit voltage_v=mV to convert)", 0, "--unit voltage_v=mV")
            else:
                k = np.flatnonzero((v < 1.0) | (v > 5.5))
                if k.size:
                    bad("voltage_v", f"cell voltage {v[k[0]]} V outside the plausible range [1, 5.5] V", int(k[0]))
        i = arr("current_a")
        if i is not None and "unit:current_a" not in fixes:
            k = np.flatnonzero(np.abs(i) > 1000.0)
            if k.size:
                bad("current_a", f"cell current {i[k[0]]} A implausible (> 1000 A): the column looks like milliamps; "
                                 f"name it 'current_ma' or pass --unit current_a=mA to convert", int(k[0]),
                    "--unit current_a=mA")
    elif model == "engine":
        p = arr("power_w")
        if p is not None and np.nanmax(np.abs(p)) < 2000.0:
            bad("power_w", f"largest engine power {np.nanmax(np.abs(p)):.3g} - looks like kW, expected W (name the "
                           f"column 'power_kw' or pass --unit power_w=kW to convert)",
                int(np.nanargmax(np.abs(p))), "--unit power_w=kW")
        sr = arr("soot_rate_mgps")
        if sr is not None:
            k = np.flatnonzero(sr < -1.0)
            if k.size:
                bad("soot_rate_mgps", f"negative soot rate {sr[k[0]]} mg/s", int(k[0]))
    else:
        s = arr("speed_mps")
        kmh = False
        if s is not None:
            k = np.flatnonzero(s < -0.5)
            if k.size:
                bad("speed_mps", f"negative speed {s[k[0]]} m/s", int(k[0]))
            if np.nanmax(s) > 70.0:
                kmh = True
                bad("speed_mps", f"speed {np.nanmax(s):.4g} m/s (> 70 m/s = 252 km/h) looks like km/h; name the "
                                 f"column 'speed_kmh' or pass --unit speed_mps=kmh to convert", int(np.nanargmax(s)),
                    "--unit speed_mps=kmh")
        p = arr("power_w")
        if s is not None and p is not None:
            # moving: faster than 5 m/s (18 km/h; in the file's km/h when the speed looks like km/h)
            moving = np.nan_to_num(s / (3.6 if kmh else 1.0)) > 5.0
            if moving.sum() >= 5 and np.nanmedian(np.abs(p[moving])) < 500.0:
                # any road vehicle above 5 m/s draws (or regenerates) well over 500 W
                bad("power_w", f"median |power| while moving faster than 5 m/s is "
                               f"{np.nanmedian(np.abs(p[moving])):.3g} - looks like kW, expected W (name the column "
                               f"'power_kw' or pass --unit power_w=kW to convert)", int(np.argmax(moving)),
                    "--unit power_w=kW")


# ------------------------------------------------------------------------------ shipped measured records
RECORDS_FILE = "records.toml"


def measured_root() -> Path:
    """The folder of the shipped measured records (``data/measured`` in a checkout, inside the wheel too)."""
    from ..core.paths import DATA_ROOT
    return DATA_ROOT / "data" / "measured"


def _record_folder_info(folder: Path) -> dict:
    import tomllib
    f = folder / RECORDS_FILE
    if not f.is_file():
        return {}
    try:
        return tomllib.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{f}: cannot read: {exc}") from exc


def measured_records() -> list[dict]:
    """The shipped measured records: ``{"name", "path", "model", "description", "options"}`` where ``options``
    are the calibration options the record's ``records.toml`` declares (columns, sign, duplicates, parameters)
    and ``name`` is what ``shevsim calibrate MODEL NAME`` accepts in place of a path."""
    root = measured_root()
    out = []
    if not root.is_dir():
        return out
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        info = _record_folder_info(folder)
        defaults = dict(info.get("defaults", {}))
        for name, rec in sorted(info.get("records", {}).items()):
            p = folder / name
            if not p.is_file():
                continue
            opts = {**defaults, **{k: v for k, v in rec.items() if k != "description"}}
            out.append({"name": f"{folder.name}/{Path(name).name.split('.')[0]}", "path": str(p),
                        "model": opts.pop("model", "cell"), "description": rec.get("description", ""),
                        "options": opts, "folder": str(folder)})
    return out


def resolve_record(name: str) -> dict | None:
    """A shipped record by name (``panasonic_18650pf/25degC_US06_Pan18650PF``, with or without ``.csv``), else
    None."""
    stem = str(name)
    for suf in (".csv.gz", ".csv"):
        if stem.endswith(suf):
            stem = stem[: -len(suf)]
    for r in measured_records():
        if r["name"] == stem or r["name"].split("/", 1)[1] == stem:
            return r
    return None


def record_command(rec: dict, out: str = "DIR") -> str:
    """The ``shevsim calibrate`` command line that calibrates a shipped record (its declared options applied)."""
    return f"shevsim calibrate {rec['model']} {rec['name']} --out {out}"
