"""cycles.py - drive-cycle loading, validation and statistics.

A drive cycle is a plain CSV with the columns ``time_s`` and ``speed_mps``
(other columns are ignored). Lines starting with ``#`` and blank lines are
comments. The loader rejects anything a simulation cannot follow faithfully:
missing columns, unparsable or non-finite values, negative speed, duplicate or
decreasing time, and gaps (a time step that differs from the cycle's step by
more than a tolerance). Every error is a :class:`shevsim.core.errors.DataError`
naming the file, the line and the column.

Statistics (all from the sampled trace, interval ``i`` between samples ``i`` and
``i + 1``, acceleration ``a_i = (v_{i+1} - v_i) / dt``):

* ``distance_m``: trapezoidal integral of speed.
* ``idle_frac``: fraction of intervals whose both end speeds are below
  :data:`IDLE_SPEED_MPS`.
* ``accel_p50_mps2``, ``accel_p95_mps2``: median and 95th percentile of ``a_i``
  over the intervals with ``a_i > ACCEL_THRESHOLD_MPS2``; ``decel_*`` the same
  for ``-a_i`` over ``a_i < -ACCEL_THRESHOLD_MPS2`` (reported positive).
* ``pke_mps2``: positive kinetic energy per unit mass and distance,
  ``sum(max(v_{i+1}^2 - v_i^2, 0)) / (2 * distance)`` (J/kg/m = m/s^2), an
  aggressiveness measure of a cycle. This is the "characteristic acceleration" of
  Sovran & Blaser / O'Keefe et al. (2007); the PKE of Watson et al. (1983) common in
  the drive-cycle literature, ``sum(max(dv^2, 0)) / distance``, is twice this value.
* ``rms_accel_mps2``: root mean square of ``a_i`` over all intervals.
"""
from __future__ import annotations

import csv
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shevsim.core.errors import DataError
from shevsim.core.filecache import memo_file

#: Speed below which the vehicle counts as standing still (m/s).
IDLE_SPEED_MPS = 0.1
#: Accelerations of smaller magnitude count as cruising in the percentile statistics (m/s^2).
ACCEL_THRESHOLD_MPS2 = 0.1
#: Relative tolerance on the time step before a row is called a gap.
DT_REL_TOL = 1e-6
#: Speeds down to this small negative value are rounding noise and clipped to 0 (m/s).
NEG_SPEED_TOL_MPS = 1e-9

REQUIRED_COLUMNS = ("time_s", "speed_mps")
#: Declared units a header may carry instead of SI, converted on load: column -> (canonical, factor to SI).
UNIT_COLUMNS = {
    "time_s": ("time_s", 1.0), "time_ms": ("time_s", 1e-3), "time_min": ("time_s", 60.0),
    "speed_mps": ("speed_mps", 1.0), "speed_kmh": ("speed_mps", 1.0 / 3.6), "speed_kph": ("speed_mps", 1.0 / 3.6),
    "speed_mph": ("speed_mps", 0.44704),
}
#: Highest plausible road-vehicle cycle speed (m/s, 252 km/h): above it the column looks like km/h.
MAX_PLAUSIBLE_SPEED_MPS = 70.0
#: A time column in milliseconds read as seconds: steps of 10 "s" or more over more than 12 hours (a
#: one-minute cycle logged in ms spans 16.7 "hours"). A coarse trace, sampled every 10-60 s over a few
#: hours, is plausible and accepted.
MAX_PLAUSIBLE_STEP_S = 10.0
MAX_PLAUSIBLE_DURATION_S = 43200.0
#: Largest plausible acceleration magnitude of a drive cycle (m/s^2, ~1 g), measured as the speed change
#: over 1 s windows (sensor noise of a 10-100 Hz log does not count); a km/h column read as m/s is 3.6x.
MAX_PLAUSIBLE_ACCEL_MPS2 = 10.0
#: most power per kg of vehicle (v * dv/dt over 1 s windows, W/kg) a drive cycle asks for: the bundled
#: cycles reach 9-21 W/kg, aggressive car cycles (US06) about 50; the same cycles in km/h read as m/s reach
#: 117-277 (x 3.6^2)
MAX_PLAUSIBLE_SPECIFIC_POWER_W_PER_KG = 100.0
ACCEL_WINDOW_S = 1.0


@dataclass(frozen=True, eq=False)
class Cycle:
    """A validated, uniformly sampled drive cycle.

    Parameters
    ----------
    name : str
        Cycle name (file stem for loaded cycles).
    time_s : ndarray
        Sample times (s), starting at 0, uniform step ``dt_s``.
    speed_mps : ndarray
        Speed at each sample (m/s, >= 0).
    source : str
        Where the cycle came from (path), for messages and provenance.
    time_offset_s : float
        Time of the first row in the file (subtracted so that ``time_s[0] == 0``).
    """

    name: str
    time_s: np.ndarray
    speed_mps: np.ndarray
    source: str = ""
    time_offset_s: float = 0.0
    _stats: dict = field(default_factory=dict, repr=False, compare=False)

    # -- basic quantities ----------------------------------------------------
    @property
    def dt_s(self) -> float:
        """Sample step (s)."""
        return float(self.time_s[1] - self.time_s[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample (s)."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def accel_mps2(self) -> np.ndarray:
        """Interval accelerations ``(v[i+1] - v[i]) / dt`` (m/s^2), length n - 1."""
        return np.diff(self.speed_mps) / self.dt_s

    @property
    def distance_m(self) -> float:
        """Trapezoidal distance (m)."""
        v = self.speed_mps
        return float(np.sum(0.5 * (v[1:] + v[:-1])) * self.dt_s)

    def stats(self) -> dict[str, float]:
        """All statistics as a dict with unit-suffixed keys (see module docstring)."""
        if self._stats:
            return dict(self._stats)
        v = self.speed_mps
        a = self.accel_mps2
        dist = self.distance_m
        dur = self.duration_s
        idle = (v[1:] < IDLE_SPEED_MPS) & (v[:-1] < IDLE_SPEED_MPS)
        pos = a[a > ACCEL_THRESHOLD_MPS2]
        neg = -a[a < -ACCEL_THRESHOLD_MPS2]
        dke = np.diff(v * v)
        # number of stops: transitions from moving to standing
        moving = v >= IDLE_SPEED_MPS
        n_stops = int(np.sum(moving[:-1] & ~moving[1:]))

        def pct(x, q):
            return float(np.percentile(x, q)) if x.size else 0.0

        s = {
            "duration_s": dur,
            "distance_m": dist,
            "max_speed_mps": float(v.max()),
            "mean_speed_mps": dist / dur if dur > 0 else 0.0,
            "idle_frac": float(np.mean(idle)) if idle.size else 0.0,
            "n_stops": n_stops,
            "accel_p50_mps2": pct(pos, 50),
            "accel_p95_mps2": pct(pos, 95),
            "accel_max_mps2": float(max(a.max(), 0.0)),
            "decel_p50_mps2": pct(neg, 50),
            "decel_p95_mps2": pct(neg, 95),
            "decel_max_mps2": float(max(-a.min(), 0.0)),
            "pke_mps2": float(np.sum(dke[dke > 0]) / (2.0 * dist)) if dist > 0 else 0.0,
            "rms_accel_mps2": float(math.sqrt(np.mean(a * a))),
        }
        self._stats.update(s)
        return dict(s)


def _fail(path, line: int | None, column: str | None, msg: str) -> DataError:
    where = f"{path}"
    if line is not None:
        where += f", line {line}"
    if column is not None:
        where += f", column '{column}'"
    return DataError(f"{where}: {msg}")


def _split_row(line: str, sep: str) -> list[str]:
    return next(csv.reader([line], delimiter=sep))


def check_plausible(path, t: np.ndarray, v: np.ndarray, lines=None, declared=None) -> None:
    """Unit sniffing on a cycle in SI: a speed above :data:`MAX_PLAUSIBLE_SPEED_MPS` looks like km/h;
    steps of :data:`MAX_PLAUSIBLE_STEP_S` or more over more than :data:`MAX_PLAUSIBLE_DURATION_S` look like
    milliseconds; a speed change faster than :data:`MAX_PLAUSIBLE_ACCEL_MPS2` over 1 s windows is no road
    vehicle's, nor one that takes more than :data:`MAX_PLAUSIBLE_SPECIFIC_POWER_W_PER_KG` (km/h below 50 km/h).  A unit declared in the header other than the default (``time_min``, ``speed_kmh`` ...)
    skips its column's check.  The error says what was detected, how to declare the unit, and how to
    turn the check off (``check_units = false`` in the cycle's parameters) for a legitimate trace."""
    declared = declared or {}
    off = " (or set check_units = false in the cycle's parameters if the trace is right as it is)"

    def line(k):
        return int(lines[k]) if lines is not None else None
    speed_declared = declared.get("speed_mps", "speed_mps") != "speed_mps"
    time_declared = declared.get("time_s", "time_s") != "time_s"
    k = int(np.argmax(v))
    if not speed_declared and v[k] > MAX_PLAUSIBLE_SPEED_MPS:
        raise _fail(path, line(k), "speed_mps",
                    f"speed {v[k]:g} m/s (= {v[k] * 3.6:.0f} km/h) is beyond any road vehicle (> "
                    f"{MAX_PLAUSIBLE_SPEED_MPS:g} m/s); the column looks like km/h (or mph): name it 'speed_kmh' "
                    f"(or 'speed_mph') in the header and it is converted, or convert it to m/s{off}")
    dt = np.diff(t)
    if (not time_declared and dt.size and float(np.median(dt)) >= MAX_PLAUSIBLE_STEP_S
            and t[-1] - t[0] > MAX_PLAUSIBLE_DURATION_S):
        raise _fail(path, line(1), "time_s",
                    f"sample step {float(np.median(dt)):g} s over {(t[-1] - t[0]) / 3600.0:.3g} hours: the time "
                    f"column looks like milliseconds; name it 'time_ms' in the header and it is converted{off}")
    if dt.size and not (speed_declared and time_declared):
        # speed change over windows of at least ACCEL_WINDOW_S (one sample when coarser)
        step = float(np.median(dt))
        w = max(1, int(round(ACCEL_WINDOW_S / step))) if step > 0 else 1
        if v.size > w:
            a = np.abs(v[w:] - v[:-w]) / (t[w:] - t[:-w])
            k = int(np.argmax(a))
            if a[k] > MAX_PLAUSIBLE_ACCEL_MPS2:
                raise _fail(path, line(k + w), "speed_mps",
                            f"acceleration {a[k]:.3g} m/s^2 between {t[k]:g} s and {t[k + w]:g} s is beyond any "
                            f"road vehicle (> {MAX_PLAUSIBLE_ACCEL_MPS2:g} m/s^2): are speed (m/s) and time (s) "
                            f"in the declared units?{off}")
            # the power per kg to accelerate, v * dv/dt: a speed column in km/h read as m/s multiplies it by
            # 3.6^2 = 13, which gives away even a slow city cycle (top speed under 50 km/h) in km/h
            pw = 0.5 * (v[w:] + v[:-w]) * (v[w:] - v[:-w]) / (t[w:] - t[:-w])
            k = int(np.argmax(pw))
            if not speed_declared and pw[k] > MAX_PLAUSIBLE_SPECIFIC_POWER_W_PER_KG:
                raise _fail(path, line(k + w), "speed_mps",
                            f"accelerating from {v[k]:.3g} to {v[k + w]:.3g} m/s between {t[k]:g} s and "
                            f"{t[k + w]:g} s takes {pw[k]:.0f} W per kg of vehicle (v dv/dt), beyond any road "
                            f"vehicle on a drive cycle (> {MAX_PLAUSIBLE_SPECIFIC_POWER_W_PER_KG:g} W/kg; km/h "
                            f"read as m/s multiplies it by 13): the speed column looks like km/h (or mph): name it "
                            f"'speed_kmh' (or 'speed_mph') in the header and it is converted{off}")


#: largest cycle CSV read (bytes): a 2-million-row trace is ~40 MB
MAX_CYCLE_BYTES = 1 * 2**30


@memo_file
def load_cycle(path: str | Path, name: str | None = None, check_units: bool = True) -> Cycle:
    """Load and validate a ``time_s,speed_mps`` drive-cycle CSV.

    Parameters
    ----------
    path : str or Path
        CSV file. ``#`` lines and blank lines are comments; the first other line is
        the header and must contain a time and a speed column: ``time_s`` (or ``time_ms``, ``time_min``)
        and ``speed_mps`` (or ``speed_kmh``, ``speed_mph``), converted to SI on load.  Spreadsheet
        exports are read as they come: UTF-8 (with or without a byte-order mark), UTF-16 ("Unicode text"),
        Windows-1252, CRLF line ends, ``;`` separators with decimal commas, trailing empty columns.
    name : str, optional
        Cycle name; defaults to the file stem.
    check_units : bool
        Unit sniffing (:func:`check_plausible`): refuse speeds that look like km/h and times that look
        like milliseconds.  Turn off only for a trace that really is that fast or that coarse.

    Returns
    -------
    Cycle

    Raises
    ------
    DataError
        Missing file or columns, unparsable/NaN/infinite values, negative speed,
        duplicate or decreasing time, non-uniform step (gap), fewer than 2 rows, implausible units.
        The message names the file, the line (1-based, as in an editor) and the column.
    """
    path = Path(path)
    text = _read_text(path)
    rows: list[tuple[int, str]] = []
    from .core.textfile import text_lines
    for lineno, line in enumerate(text_lines(text), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        rows.append((lineno, s))
    if not rows:
        raise _fail(path, None, None, "no header and no data (file empty or only comments)")
    header_line, hs = rows[0]
    sep = ";" if (";" in hs and "," not in hs) else ("\t" if ("\t" in hs and "," not in hs) else ",")
    header = [h.strip() for h in _split_row(hs, sep)]
    idx, factor, declared = _cycle_columns(path, header_line, header)
    data = rows[1:]
    if len(data) < 2:
        raise _fail(path, None, None, f"needs at least 2 data rows, found {len(data)}")
    t, v, lines = _parse_rows(path, data, sep, idx, factor, declared)
    step = _check_time_grid(path, t, lines, declared["time_s"])
    if check_units:
        check_plausible(path, t, v, lines, declared)
    offset = float(t[0])
    # rebuild a clean uniform grid (removes accumulated rounding of the file's times)
    tt = np.arange(len(t)) * step
    return Cycle(name=name or path.stem, time_s=tt, speed_mps=v, source=str(path), time_offset_s=offset)


def _read_text(path: Path) -> str:
    """The cycle file as text (:func:`shevsim.core.textfile.read_text_file`: UTF-8, UTF-16 or Windows-1252, a
    byte-order mark dropped); unreadable, binary or too large: an error naming the file."""
    from .core.textfile import read_text_file
    return read_text_file(path, "cycle file", MAX_CYCLE_BYTES)[0]


def _cycle_columns(path: Path, header_line: int, header: list[str]):
    """Where time and speed stand in the header and the factor to SI of the unit each declares:
    ``(index, factor, declared column name)`` by canonical name."""
    idx: dict[str, int] = {}
    factor: dict[str, float] = {}
    declared: dict[str, str] = {}
    for j, h in enumerate(header):
        if h in UNIT_COLUMNS:
            canon, f = UNIT_COLUMNS[h]
            if canon in idx:
                raise _fail(path, header_line, h, f"two columns give '{canon}' ('{declared[canon]}' and '{h}')")
            idx[canon], factor[canon], declared[canon] = j, f, h
    for col in REQUIRED_COLUMNS:
        if col not in idx:
            alts = [c for c, (k, _) in UNIT_COLUMNS.items() if k == col]
            best = difflib.get_close_matches(col, [h for h in header if h], n=1, cutoff=0.5)
            hint = f"; did you mean '{best[0]}'?" if best else ""
            raise _fail(path, header_line, col,
                        f"missing column (header is {header}; required: {', '.join(REQUIRED_COLUMNS)}, a unit "
                        f"may be declared instead: {', '.join(alts)}){hint}")
    return idx, factor, declared


def _parse_rows(path: Path, data, sep: str, idx: dict, factor: dict, declared: dict):
    """Time [s] and speed [m/s] of each data row (``(line number, text)``) and the file line numbers;
    a missing, non-numeric or non-finite value or a negative speed is an error naming line and column."""
    decimal_comma = sep == ";"
    t = np.empty(len(data))
    v = np.empty(len(data))
    lines = np.empty(len(data), dtype=int)
    for k, (lineno, s) in enumerate(data):
        lines[k] = lineno
        fields = _split_row(s, sep)
        for col, arr in (("time_s", t), ("speed_mps", v)):
            j = idx[col]
            if j >= len(fields) or fields[j].strip() == "":
                raise _fail(path, lineno, declared[col], "missing value")
            raw_v = fields[j].strip()
            try:
                val = float(raw_v.replace(",", ".") if decimal_comma else raw_v)
            except ValueError:
                hint = (" (a decimal comma? separate columns with ';' then)" if "," in raw_v else "")
                raise _fail(path, lineno, declared[col], f"not a number: {raw_v!r}{hint}") from None
            if not math.isfinite(val):
                raise _fail(path, lineno, declared[col], f"non-finite value {raw_v!r}")
            arr[k] = val * factor[col]
        if v[k] < 0.0:
            if v[k] < -NEG_SPEED_TOL_MPS:
                raise _fail(path, lineno, declared["speed_mps"], f"negative speed {float(v[k])!r} m/s")
            v[k] = 0.0
    return t, v, lines


def _check_time_grid(path: Path, t: np.ndarray, lines: np.ndarray, time_col: str) -> float:
    """Time must increase strictly with a uniform step; returns the step [s]."""
    dt = np.diff(t)
    bad = np.nonzero(dt <= 0)[0]
    if bad.size:
        k = int(bad[0]) + 1
        kind = "duplicate time" if dt[k - 1] == 0 else "time decreases (non-monotonic)"
        raise _fail(path, int(lines[k]), time_col,
                    f"{kind}: {float(t[k])!r} s after {float(t[k - 1])!r} s on line {int(lines[k - 1])}")
    step = float(dt[0])
    tol = DT_REL_TOL * step + 1e-9
    bad = np.nonzero(np.abs(dt - step) > tol)[0]
    if bad.size:
        k = int(bad[0]) + 1
        raise _fail(path, int(lines[k]), time_col,
                    f"non-uniform time step (gap?): {dt[k - 1]:.6g} s from {float(t[k - 1])!r} s, "
                    f"the cycle's step is {step:.6g} s")
    return step


def cycle_from_arrays(name: str, time_s, speed_mps, source: str = "<arrays>", check_units: bool = True) -> Cycle:
    """Build a :class:`Cycle` from arrays with the same checks as :func:`load_cycle`."""
    try:
        t = np.asarray(time_s, dtype=float)
        v = np.asarray(speed_mps, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{source}: time_s and speed_mps must be numbers: {exc}") from None
    if t.shape != v.shape or t.ndim != 1 or t.size < 2:
        raise DataError(f"{source}: time_s and speed_mps must be 1-D of equal length >= 2")
    for col, arr in (("time_s", t), ("speed_mps", v)):
        badv = np.nonzero(~np.isfinite(arr))[0]
        if badv.size:
            raise DataError(f"{source}, row {int(badv[0])}, column '{col}': non-finite value")
    neg = np.nonzero(v < -NEG_SPEED_TOL_MPS)[0]
    if neg.size:
        raise DataError(f"{source}, row {int(neg[0])}, column 'speed_mps': negative speed {float(v[neg[0]])!r} m/s")
    dt = np.diff(t)
    if np.any(dt <= 0) or np.any(np.abs(dt - dt[0]) > DT_REL_TOL * dt[0] + 1e-9):
        k = int(np.nonzero((dt <= 0) | (np.abs(dt - dt[0]) > DT_REL_TOL * dt[0] + 1e-9))[0][0]) + 1
        raise DataError(f"{source}, row {k}, column 'time_s': time not strictly increasing with a uniform step")
    if check_units:
        check_plausible(source, t, np.maximum(v, 0.0))
    return Cycle(name=name, time_s=np.arange(t.size) * float(dt[0]), speed_mps=np.maximum(v, 0.0),
                 source=source, time_offset_s=float(t[0]))


def write_cycle_csv(cycle: Cycle, path: str | Path, header_comment: str = "") -> None:
    """Write a cycle as ``time_s,speed_mps`` CSV (5 decimals), with optional ``#`` comment lines."""
    lines = []
    for c in header_comment.splitlines():
        lines.append("# " + c if c else "#")
    lines.append("time_s,speed_mps")
    dt = cycle.dt_s
    int_time = abs(dt - round(dt)) < 1e-12
    for t, v in zip(cycle.time_s, cycle.speed_mps):
        ts = f"{int(round(t))}" if int_time else f"{t:.6f}"
        lines.append(f"{ts},{v:.5f}")
    Path(path).write_text("\n".join(lines) + "\n")


def list_cycles(folder: str | Path) -> list[Cycle]:
    """Load every ``*.csv`` in ``folder`` (sorted by name). Raises on the first bad file."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: cycle folder not found")
    return [load_cycle(p) for p in sorted(folder.glob("*.csv"))]


def cycles_command(folder: str | Path) -> str:
    """The text table printed by ``shevsim cycles``: one row per cycle with its statistics.

    A file that fails validation is listed with its error instead of statistics.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: cycle folder not found")
    head = (f"{'cycle':<20} {'dur s':>6} {'dist km':>8} {'vmax km/h':>9} {'vmean km/h':>10} "
            f"{'idle %':>6} {'stops':>5} {'a95 m/s2':>8} {'d95 m/s2':>8} {'amax':>5} {'dmax':>5} "
            f"{'PKE m/s2':>8} {'RMSa m/s2':>9}")
    out = [head, "-" * len(head)]
    for p in sorted(folder.glob("*.csv")):
        try:
            s = load_cycle(p).stats()
        except DataError as exc:
            out.append(f"{p.stem:<20} INVALID: {exc}")
            continue
        out.append(
            f"{p.stem:<20} {s['duration_s']:>6.0f} {s['distance_m'] / 1000:>8.3f} "
            f"{s['max_speed_mps'] * 3.6:>9.1f} {s['mean_speed_mps'] * 3.6:>10.1f} "
            f"{100 * s['idle_frac']:>6.1f} {s['n_stops']:>5d} {s['accel_p95_mps2']:>8.2f} "
            f"{s['decel_p95_mps2']:>8.2f} {s['accel_max_mps2']:>5.2f} {s['decel_max_mps2']:>5.2f} "
            f"{s['pke_mps2']:>8.3f} {s['rms_accel_mps2']:>9.3f}")
    if len(out) == 2:
        out.append(f"(no *.csv cycles in {folder})")
    return "\n".join(out)
