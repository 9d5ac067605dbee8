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

import math
from bisect import bisect_right
from pathlib import Path

import numpy as np

from shevsim.core.errors import DataError

_MODES = ("clamp", "linear", "error")


def _check_axis(name: str, axis: np.ndarray) -> None:
    if axis.ndim != 1 or axis.size < 2:
        raise DataError(f"{name}: an axis needs at least 2 points, got {axis.size}")
    if not np.all(np.isfinite(axis)):
        raise DataError(f"{name}: axis contains NaN/inf")
    if not np.all(np.diff(axis) > 0):
        raise DataError(f"{name}: axis must be strictly increasing")


def _locate(axis: list[float], x: float, mode: str, name: str) -> tuple[int, float]:
    """Cell index ``i`` and fraction ``f`` (0..1 inside; outside per ``mode``)."""
    n = len(axis)
    if x <= axis[0]:
        if mode == "clamp" or x == axis[0]:
            return 0, 0.0
        if mode == "error":
            raise DataError(f"{name}: {x!r} below the map range [{axis[0]}, {axis[-1]}]")
        return 0, (x - axis[0]) / (axis[1] - axis[0])
    if x >= axis[-1]:
        if mode == "clamp" or x == axis[-1]:
            return n - 2, 1.0
        if mode == "error":
            raise DataError(f"{name}: {x!r} above the map range [{axis[0]}, {axis[-1]}]")
        return n - 2, (x - axis[n - 2]) / (axis[n - 1] - axis[n - 2])
    if x != x:  # NaN
        raise DataError(f"{name}: NaN lookup")
    i = bisect_right(axis, x) - 1
    return i, (x - axis[i]) / (axis[i + 1] - axis[i])


class Curve:
    """Piecewise-linear curve ``y(x)``.

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
        self._xl, self._yl = x.tolist(), y.tolist()
        self.fn = self._scalar_fn()

    def _scalar_fn(self):
        """A plain function ``fn(x)`` equal to ``self(x)`` (a closure: cheaper to call on hot paths)."""
        xl, yl, slow = self._xl, self._yl, self._slow
        x_lo, x_hi = xl[0], xl[-1]

        def fn(x: float) -> float:
            if x_lo < x < x_hi:
                i = bisect_right(xl, x) - 1
                x0 = xl[i]
                y0 = yl[i]
                return y0 + (x - x0) / (xl[i + 1] - x0) * (yl[i + 1] - y0)
            return slow(x)
        return fn

    def _slow(self, x: float) -> float:
        i, f = _locate(self._xl, x, self.mode, self.name)
        return self._yl[i] + f * (self._yl[i + 1] - self._yl[i])

    def __getstate__(self):
        d = self.__dict__.copy()
        d.pop("fn", None)
        return d

    def __setstate__(self, d):
        self.__dict__.update(d)
        self.fn = self._scalar_fn()

    def __call__(self, x: float) -> float:
        xl = self._xl
        if xl[0] < x < xl[-1]:          # interior (hot path): same arithmetic as _locate
            i = bisect_right(xl, x) - 1
            x0 = xl[i]
            yl = self._yl
            y0 = yl[i]
            return y0 + (x - x0) / (xl[i + 1] - x0) * (yl[i + 1] - y0)
        i, f = _locate(xl, x, self.mode, self.name)
        return self._yl[i] + f * (self._yl[i + 1] - self._yl[i])

    def eval_array(self, x) -> np.ndarray:
        x = np.asarray(x, float)
        out = np.interp(x, self.x, self.y)
        if self.mode == "linear":
            lo, hi = x < self.x[0], x > self.x[-1]
            s0 = (self.y[1] - self.y[0]) / (self.x[1] - self.x[0])
            s1 = (self.y[-1] - self.y[-2]) / (self.x[-1] - self.x[-2])
            out = np.where(lo, self.y[0] + s0 * (x - self.x[0]), out)
            out = np.where(hi, self.y[-1] + s1 * (x - self.x[-1]), out)
        elif self.mode == "error" and (np.any(x < self.x[0]) or np.any(x > self.x[-1])):
            raise DataError(f"{self.name}: lookup outside [{self.x[0]}, {self.x[-1]}]")
        return out


class Grid2D:
    """Bilinear map ``z(x, y)`` on a regular (rectilinear) grid, ``z.shape == (len(x), len(y))``.

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
        self._xl, self._yl, self._zl = x.tolist(), y.tolist(), z.tolist()
        self.fn = self._scalar_fn()

    def _scalar_fn(self):
        """A plain function ``fn(x, y)`` equal to ``self(x, y)`` (a closure: cheaper on hot paths)."""
        xl, yl, zl, slow = self._xl, self._yl, self._zl, self.__call__
        x_lo, x_hi, y_lo, y_hi = xl[0], xl[-1], yl[0], yl[-1]

        def fn(x: float, y: float) -> float:
            if x_lo < x < x_hi and y_lo < y < y_hi:
                i = bisect_right(xl, x) - 1
                x0 = xl[i]
                fx = (x - x0) / (xl[i + 1] - x0)
                j = bisect_right(yl, y) - 1
                y0 = yl[j]
                fy = (y - y0) / (yl[j + 1] - y0)
                r0 = zl[i]
                r1 = zl[i + 1]
                a = r0[j] + fy * (r0[j + 1] - r0[j])
                b = r1[j] + fy * (r1[j + 1] - r1[j])
                return a + fx * (b - a)
            return slow(x, y)
        return fn

    def __getstate__(self):
        d = self.__dict__.copy()
        d.pop("fn", None)
        return d

    def __setstate__(self, d):
        self.__dict__.update(d)
        self.fn = self._scalar_fn()

    def __call__(self, x: float, y: float) -> float:
        xl, yl = self._xl, self._yl
        if xl[0] < x < xl[-1]:          # interior (hot path): same arithmetic as _locate
            i = bisect_right(xl, x) - 1
            x0 = xl[i]
            fx = (x - x0) / (xl[i + 1] - x0)
        else:
            i, fx = _locate(xl, x, self.mode_x, self.name)
        if yl[0] < y < yl[-1]:
            j = bisect_right(yl, y) - 1
            y0 = yl[j]
            fy = (y - y0) / (yl[j + 1] - y0)
        else:
            j, fy = _locate(yl, y, self.mode_y, self.name)
        r0 = self._zl[i]
        r1 = self._zl[i + 1]
        a = r0[j] + fy * (r0[j + 1] - r0[j])
        b = r1[j] + fy * (r1[j + 1] - r1[j])
        return a + fx * (b - a)

    def eval_array(self, x, y) -> np.ndarray:
        """Vectorised evaluation (broadcasting ``x`` and ``y``)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        out = np.empty(x.shape)
        flat = out.reshape(-1)
        for k, (a, b) in enumerate(zip(x.reshape(-1), y.reshape(-1))):
            flat[k] = self(float(a), float(b))
        return out


def _read_table(path: Path) -> tuple[list[str], np.ndarray, list[str]]:
    comments, rows, header = [], [], None
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            comments.append(s)
            continue
        if header is None:
            header = [h.strip() for h in s.split(",")]
            continue
        try:
            vals = [float(v) for v in s.split(",")]
        except ValueError as exc:
            raise DataError(f"{path}:{lineno}: not a number: {exc}") from exc
        if len(vals) != len(header):
            raise DataError(f"{path}:{lineno}: {len(vals)} values for {len(header)} columns")
        rows.append(vals)
    if header is None or not rows:
        raise DataError(f"{path}: no data rows")
    return header, np.asarray(rows), comments


def read_columns(path, columns: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Read named columns of a long-format CSV with ``#`` provenance comments."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: map file not found")
    header, data, _ = _read_table(path)
    out = {}
    for c in columns:
        if c not in header:
            raise DataError(f"{path}: missing column '{c}' (has {', '.join(header)})")
        out[c] = data[:, header.index(c)]
    return out


def load_curve_csv(path, xcol: str, ycol: str, extrapolation: str = "clamp") -> Curve:
    """Curve from two columns of a CSV (rows sorted by ``xcol``)."""
    d = read_columns(path, (xcol, ycol))
    order = np.argsort(d[xcol], kind="stable")
    return Curve(d[xcol][order], d[ycol][order], extrapolation, name=f"{path}:{ycol}")


def load_grid_csv(path, xcol: str, ycol: str, zcol: str, extrapolation="clamp") -> Grid2D:
    """Grid2D from a long-format CSV: one row per (x, y) node; the grid must be complete."""
    d = read_columns(path, (xcol, ycol, zcol))
    xs, ys = np.unique(d[xcol]), np.unique(d[ycol])
    z = np.full((xs.size, ys.size), np.nan)
    ix = np.searchsorted(xs, d[xcol])
    iy = np.searchsorted(ys, d[ycol])
    z[ix, iy] = d[zcol]
    if np.isnan(z).any():
        k = np.argwhere(np.isnan(z))[0]
        raise DataError(f"{path}: incomplete grid, no row for {xcol}={xs[k[0]]}, {ycol}={ys[k[1]]}")
    return Grid2D(xs, ys, z, extrapolation, name=f"{path}:{zcol}")


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
