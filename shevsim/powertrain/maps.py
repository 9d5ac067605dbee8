"""maps.py - 1-D curves and 2-D regular-grid maps with an explicit extrapolation rule.

Every map shevsim uses is measured on a finite grid; what happens outside it is a modelling
choice, so it is a named, explicit argument here, never an accident of ``np.interp``:

``"clamp"`` (default)
    Hold the value at the nearest grid edge (per axis). Safe for efficiencies and emission
    ratios: an efficiency never leaves [min, max] of the measured data.
``"linear"``
    Continue the edge cell's linear slope. Used where physics says the relation is linear
    beyond the data (the Willans line of a diesel: fuel rate is affine in torque), never for
    efficiencies.
``"error"``
    Raise :class:`~shevsim.core.errors.DataError` naming the map and the offending value.

Scalar calls (``m(x, y)``) use :mod:`bisect` on Python lists (hot path, ~1 µs); array calls use
:meth:`Grid2D.eval_array` / :meth:`Curve.eval_array` (NumPy, vectorised).

CSV files are long format with ``#`` comment lines (the provenance header) followed by a header
row, e.g. ``speed_radps,torque_nm,fuel_gps``; see :func:`load_grid_csv`.
"""
from __future__ import annotations

import difflib
import math
from pathlib import Path

import numpy as np

from shevsim.core.errors import DataError
from shevsim.core.params import name_rule
from shevsim.core.lookup import EXTRAPOLATION_CODES, curve_ex, grid_ex, curve_eval_array, grid_eval_array
from shevsim.core.filecache import memo_file

_MODES = ("clamp", "linear", "error")


def _check_axis(name: str, axis: np.ndarray) -> None:
    if axis.ndim != 1 or axis.size < 2:
        raise DataError(f"{name}: an axis needs at least 2 points, got {axis.size}")
    if not np.all(np.isfinite(axis)):
        raise DataError(f"{name}: axis contains NaN/inf")
    if not np.all(np.diff(axis) > 0):
        raise DataError(f"{name}: axis must be strictly increasing")


def _lookup_error(axis, x: float, mode: str, name: str) -> DataError:
    """The error of a lookup the compiled function refused (NaN ``x``, or outside an 'error' map)."""
    if x != x:
        return DataError(f"{name}: NaN lookup")
    side = "below" if x < axis[0] else "above"
    return DataError(f"{name}: {x!r} {side} the map range [{axis[0]}, {axis[-1]}]")


class Curve:
    """Piecewise-linear curve ``y(x)``, evaluated by the one compiled lookup module
    (:func:`shevsim.core.lookup.curve_ex`) on the packed array ``[x, y]``.

    Parameters
    ----------
    x, y : array_like
        Breakpoints (strictly increasing ``x``) and values.
    extrapolation : {'clamp', 'linear', 'error'}
    name : str
        Used in error messages.
    """

    def __init__(self, x, y, extrapolation: str = "clamp", name: str = "curve"):
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        _check_axis(name, x)
        if y.shape != x.shape or not np.all(np.isfinite(y)):
            raise DataError(f"{name}: values must be finite and match the axis ({y.shape} vs {x.shape})")
        if extrapolation not in _MODES:
            raise ValueError(f"{name}: extrapolation must be one of {_MODES}")
        self.x, self.y, self.mode, self.name = x, y, extrapolation, name
        self._d = np.concatenate([x, y])
        self._n = int(x.size)
        self._m = EXTRAPOLATION_CODES[extrapolation]
        self.fn = self.__call__

    def __call__(self, x: float) -> float:
        v = curve_ex(self._d, 0, self._n, self._m, float(x))
        if v != v:
            raise _lookup_error(self.x, float(x), self.mode, self.name)
        return v

    def eval_array(self, x) -> np.ndarray:
        x = np.asarray(x, float)
        out = curve_eval_array(self._d, self._n, self._m, np.ascontiguousarray(x.reshape(-1))).reshape(x.shape)
        if np.isnan(out).any():
            bad = x.reshape(-1)[np.isnan(out.reshape(-1))][0]
            raise _lookup_error(self.x, float(bad), self.mode, self.name)
        return out


class Grid2D:
    """Bilinear map ``z(x, y)`` on a regular (rectilinear) grid, ``z.shape == (len(x), len(y))``, evaluated
    by the one compiled lookup module (:func:`shevsim.core.lookup.grid_ex`) on ``[x, y, z row-major]``.

    Parameters
    ----------
    x, y : array_like
        Strictly increasing axes.
    z : array_like
        Values, shape ``(len(x), len(y))``.
    extrapolation : {'clamp', 'linear', 'error'} or (mode_x, mode_y)
        Rule outside the grid, per axis.
    name : str
        Used in error messages.
    """

    def __init__(self, x, y, z, extrapolation="clamp", name: str = "map"):
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        z = np.asarray(z, float)
        _check_axis(f"{name} (first axis)", x)
        _check_axis(f"{name} (second axis)", y)
        if z.shape != (x.size, y.size):
            raise DataError(f"{name}: value table shape {z.shape} != ({x.size}, {y.size})")
        if not np.all(np.isfinite(z)):
            raise DataError(f"{name}: value table contains NaN/inf")
        mx, my = (extrapolation, extrapolation) if isinstance(extrapolation, str) else extrapolation
        for m in (mx, my):
            if m not in _MODES:
                raise ValueError(f"{name}: extrapolation must be one of {_MODES}, got {m!r}")
        self.x, self.y, self.z, self.name = x, y, z, name
        self.mode_x, self.mode_y = mx, my
        self._d = np.concatenate([x, y, z.reshape(-1)])
        self._nx, self._ny = int(x.size), int(y.size)
        self._mx, self._my = EXTRAPOLATION_CODES[mx], EXTRAPOLATION_CODES[my]
        self.fn = self.__call__

    def _error(self, x: float, y: float) -> DataError:
        if x != x or y != y:
            return DataError(f"{self.name}: NaN lookup")
        if self.mode_x == "error" and not (self.x[0] <= x <= self.x[-1]):
            return _lookup_error(self.x, x, "error", self.name)
        return _lookup_error(self.y, y, "error", self.name)

    def __call__(self, x: float, y: float) -> float:
        v = grid_ex(self._d, 0, self._nx, self._ny, self._mx, self._my, float(x), float(y))
        if v != v:
            raise self._error(float(x), float(y))
        return v

    def eval_array(self, x, y) -> np.ndarray:
        """Vectorised evaluation (broadcasting ``x`` and ``y``)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        xf, yf = np.ascontiguousarray(x.reshape(-1)), np.ascontiguousarray(y.reshape(-1))
        out = grid_eval_array(self._d, self._nx, self._ny, self._mx, self._my, xf, yf)
        if np.isnan(out).any():
            k = int(np.flatnonzero(np.isnan(out))[0])
            raise self._error(float(xf[k]), float(yf[k]))
        return out.reshape(x.shape)


def _split(line: str, sep: str) -> list[str]:
    return [v.strip() for v in line.split(sep)]


@memo_file
def _read_table(path: Path) -> tuple[list[str], np.ndarray, list[str], list[int]]:
    """Header, data, comment lines and the file line of each data row.  Spreadsheet quirks are accepted:
    a UTF-8 byte-order mark, CRLF line ends, ``;`` separators (with decimal commas), trailing empty columns."""
    comments, rows, lines, header = [], [], [], None
    sep = ","
    from shevsim.core.textfile import read_text_file, text_lines
    text = read_text_file(path, "map file")[0]      # UTF-8, UTF-16 or Windows-1252; a binary file named
    for lineno, line in enumerate(text_lines(text), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            comments.append(s)
            continue
        if header is None:
            if ";" in s and "," not in s:
                sep = ";"
            elif "\t" in s and "," not in s:
                sep = "\t"
            header = _split(s, sep)
            while header and header[-1] == "":       # trailing empty columns of a spreadsheet export
                header.pop()
            if not header or any(h == "" for h in header):
                raise DataError(f"{path}:{lineno}: empty column name in the header {header!r}")
            continue
        cells = _split(s, sep)
        while len(cells) > len(header) and cells[-1] == "":
            cells.pop()
        try:
            vals = [float(v.replace(",", ".") if sep == ";" else v) for v in cells]
        except ValueError as exc:
            raise DataError(f"{path}:{lineno}: not a number: {exc}") from exc
        if len(vals) != len(header):
            raise DataError(f"{path}:{lineno}: {len(vals)} values for {len(header)} columns")
        rows.append(vals)
        lines.append(lineno)
    if header is None or not rows:
        raise DataError(f"{path}: no data rows")
    return header, np.asarray(rows), comments, lines


def read_columns(path, columns: tuple[str, ...], checked: bool = False) -> dict[str, np.ndarray]:
    """Read named columns of a long-format CSV with ``#`` provenance comments.

    With ``checked=True`` every value must be finite (a NaN cell is reported with its file line and column)
    and within the physical range the column's unit-suffixed name declares
    (:func:`shevsim.core.params.name_rule`: ``efficiency_frac`` in (0, 1], ``fuel_gps`` >= 0, ...)."""
    path = Path(path)
    from shevsim.core.errors import file_problem
    why = file_problem(path, "map file")        # not found, a folder, a device: said as such
    if why is not None:
        raise DataError(f"{path}: {why}")
    header, data, _, lines = _read_table(path)
    out = {}
    for c in columns:
        if c not in header:
            best = difflib.get_close_matches(c, header, n=1)
            hint = f"; did you mean '{best[0]}'?" if best else ""
            raise DataError(f"{path}: missing column '{c}' (has {', '.join(header)}){hint}")
        out[c] = data[:, header.index(c)]
        if checked:
            check_column(path, c, out[c], lines)
    return out


def check_column(path, name: str, values: np.ndarray, lines: list[int] | None = None) -> None:
    """Raise :class:`DataError` at the first NaN/inf or out-of-range value of column ``name`` (file line
    named when ``lines`` is given); the range is the unit-suffix rule of the name."""
    values = np.asarray(values, float)
    r = name_rule(name)
    bad = np.flatnonzero(~np.isfinite(values))
    why = "not a finite number (NaN/inf)"
    if not bad.size:
        bad = np.flatnonzero(~r.ok_array(values))
        why = f"outside the physical range {r.describe()}"
    if bad.size:
        k = int(bad[0])
        at = f"line {lines[k]}" if lines is not None else f"row {k}"
        raise DataError(f"{path}: {at}, column '{name}': value {float(values[k])!r} is {why}"
                        + (f" ({bad.size} such values)" if bad.size > 1 else ""))


def load_curve_csv(path, xcol: str, ycol: str, extrapolation: str = "clamp") -> Curve:
    """Curve from two columns of a CSV (rows sorted by ``xcol``); values checked (:func:`read_columns`)."""
    d = read_columns(path, (xcol, ycol), checked=True)
    order = np.argsort(d[xcol], kind="stable")
    xs = d[xcol][order]
    dup = np.flatnonzero(np.diff(xs) == 0)
    if dup.size:
        raise DataError(f"{path}: column '{xcol}': the value {xs[dup[0]]!r} appears twice (a curve needs "
                        f"one row per {xcol})")
    return Curve(xs, d[ycol][order], extrapolation, name=f"{path}:{ycol}")


def load_grid_csv(path, xcol: str, ycol: str, zcol: str, extrapolation="clamp") -> Grid2D:
    """Grid2D from a long-format CSV: one row per (x, y) node; the grid must be complete.  Values are
    checked (:func:`read_columns`): a NaN cell is named by its line and column, not as a missing node."""
    d = read_columns(path, (xcol, ycol, zcol), checked=True)
    xs, ys = np.unique(d[xcol]), np.unique(d[ycol])
    z = np.full((xs.size, ys.size), np.nan)
    ix = np.searchsorted(xs, d[xcol])
    iy = np.searchsorted(ys, d[ycol])
    seen = np.zeros(z.shape, bool)
    for a, b in zip(ix, iy):
        if seen[a, b]:
            raise DataError(f"{path}: two rows for {xcol}={xs[a]}, {ycol}={ys[b]} (one row per grid node)")
        seen[a, b] = True
    z[ix, iy] = d[zcol]
    if not seen.all():
        k = np.argwhere(~seen)[0]
        raise DataError(f"{path}: incomplete grid, no row for {xcol}={xs[k[0]]}, {ycol}={ys[k[1]]}")
    return Grid2D(xs, ys, z, extrapolation, name=f"{path}:{zcol}")


def scaled_curve(c: Curve, kx: float = 1.0, ky: float = 1.0) -> Curve:
    """``c`` with its axis times ``kx`` and its values times ``ky`` (same extrapolation); exact at 1."""
    return Curve(c.x * float(kx), c.y * float(ky), c.mode, name=c.name)


def scaled_grid(g: Grid2D, ky: float = 1.0, kz: float = 1.0) -> Grid2D:
    """``g`` with its second axis times ``ky`` and its values times ``kz`` (first axis, extrapolation kept);
    exact at 1.  The rating rule of :mod:`shevsim.powertrain.engine` / :mod:`shevsim.components.motor`:
    a machine ``k`` times as powerful has, at the same speed, ``k`` times the torque (and fuel, soot)."""
    return Grid2D(g.x, g.y * float(ky), g.z * float(kz), (g.mode_x, g.mode_y), name=g.name)


def write_long_csv(path, header_lines: list[str], columns: dict[str, np.ndarray], fmt: str = "%.8g") -> None:
    """Write a long-format CSV with a ``#`` provenance header."""
    path = Path(path)
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], float).ravel() for n in names])
    with path.open("w") as f:
        for h in header_lines:
            f.write("# " + h + "\n")
        f.write(",".join(names) + "\n")
        for row in data:
            f.write(",".join(fmt % v for v in row) + "\n")


def grid_to_long(x, y, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten a grid to long format (x varies slowest)."""
    X, Y = np.meshgrid(np.asarray(x, float), np.asarray(y, float), indexing="ij")
    return X.ravel(), Y.ravel(), np.asarray(z, float).ravel()


RPM = 2.0 * math.pi / 60.0
"""rad/s per rpm."""
