"""lookup.py - the one table-lookup module: compiled (numba) lookups on tables packed into float arrays.

Used by the cell tables (:meth:`shevsim.battery.cell.CellTables.packed`), the engine-generator maps
(:mod:`shevsim.powertrain.engine`), the BMS and the calibration.

The cell tables' Python methods (:class:`shevsim.battery.cell.CellTables` ``ocv``, ``params``...) call these
functions too: there is no second copy of the lookup arithmetic.
"""
from __future__ import annotations

import numpy as np

from numba import njit   # a hard dependency: the physics is compiled from its one source

HAVE_NUMBA = True    # kept for callers that still ask


@njit(cache=True, error_model="numpy")
def _bisect_right(d, o, n, x):  # pragma: no cover - compiled
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < d[o + mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(cache=True, error_model="numpy")
def t1_value(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        return d[o + n]
    if x >= d[o + n - 1]:
        return d[o + 2 * n - 1]
    k = _bisect_right(d, o, n, x) - 1
    return d[o + n + k] + d[o + 2 * n + k] * (x - d[o + k])


@njit(cache=True, error_model="numpy")
def t1_slope(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        k = 0
    elif x >= d[o + n - 1]:
        k = n - 2
    else:
        k = _bisect_right(d, o, n, x) - 1
    return d[o + 2 * n + k]


@njit(cache=True, error_model="numpy")
def t1_integral(d, o, n, x):  # pragma: no cover - compiled
    oc = o + 3 * n - 1
    if x <= d[o]:
        return d[o + n] * (x - d[o])
    if x >= d[o + n - 1]:
        return d[oc + n - 1] + d[o + 2 * n - 1] * (x - d[o + n - 1])
    k = _bisect_right(d, o, n, x) - 1
    dx = x - d[o + k]
    return d[oc + k] + d[o + n + k] * dx + 0.5 * d[o + 2 * n + k] * dx * dx


@njit(cache=True, error_model="numpy")
def _g2_locate(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        return 0, 0.0
    if x >= d[o + n - 1]:
        return n - 2, 1.0
    j = _bisect_right(d, o, n, x) - 1
    return j, (x - d[o + j]) / (d[o + j + 1] - d[o + j])


@njit(cache=True, error_model="numpy")
def curve_nb(d, o, n, x):  # pragma: no cover - compiled
    """Clamped curve at ``d[o:o+n]`` (x) / ``d[o+n:o+2n]`` (y), as ``Curve.__call__``; NaN for NaN x."""
    if x != x:
        return x
    if x <= d[o]:
        i = 0
        f = 0.0
    elif x >= d[o + n - 1]:
        i = n - 2
        f = 1.0
    else:
        i = _bisect_right(d, o, n, x) - 1
        x0 = d[o + i]
        f = (x - x0) / (d[o + i + 1] - x0)
    y0 = d[o + n + i]
    return y0 + f * (d[o + n + i + 1] - y0)


@njit(cache=True, error_model="numpy")
def grid_nb(d, o, nx, ny, x, y):  # pragma: no cover - compiled
    """Clamped bilinear map: axes ``d[o:o+nx]``, ``d[o+nx:o+nx+ny]``, values row-major after them."""
    if x != x or y != y:
        return x + y
    if x <= d[o]:
        i = 0
        fx = 0.0
    elif x >= d[o + nx - 1]:
        i = nx - 2
        fx = 1.0
    else:
        i = _bisect_right(d, o, nx, x) - 1
        x0 = d[o + i]
        fx = (x - x0) / (d[o + i + 1] - x0)
    oy = o + nx
    if y <= d[oy]:
        j = 0
        fy = 0.0
    elif y >= d[oy + ny - 1]:
        j = ny - 2
        fy = 1.0
    else:
        j = _bisect_right(d, oy, ny, y) - 1
        y0 = d[oy + j]
        fy = (y - y0) / (d[oy + j + 1] - y0)
    oz = oy + ny
    r0 = oz + i * ny
    r1 = r0 + ny
    a = d[r0 + j] + fy * (d[r0 + j + 1] - d[r0 + j])
    b = d[r1 + j] + fy * (d[r1 + j + 1] - d[r1 + j])
    return a + fx * (b - a)


# -- extrapolation modes (maps.Curve / maps.Grid2D ``mode``): 0 "clamp", 1 "linear", 2 "error" -------------
import math  # noqa: E402

EXTRAPOLATION_CODES = {"clamp": 0, "linear": 1, "error": 2}


@njit(cache=True, error_model="numpy")
def _axis_ex(d, o, n, mode, x):  # pragma: no cover - compiled
    """Cell index and fraction of ``x`` on the axis ``d[o:o+n]`` with extrapolation ``mode`` (0 clamp,
    1 linear, 2 error), as ``maps._locate``; a NaN fraction where ``_locate`` raises (NaN ``x``, or
    outside the axis in mode 2)."""
    if x != x:
        return 0, x
    if x <= d[o]:
        if mode == 0 or x == d[o]:
            return 0, 0.0
        if mode == 2:
            return 0, math.nan
        return 0, (x - d[o]) / (d[o + 1] - d[o])
    if x >= d[o + n - 1]:
        if mode == 0 or x == d[o + n - 1]:
            return n - 2, 1.0
        if mode == 2:
            return n - 2, math.nan
        return n - 2, (x - d[o + n - 2]) / (d[o + n - 1] - d[o + n - 2])
    j = _bisect_right(d, o, n, x) - 1
    return j, (x - d[o + j]) / (d[o + j + 1] - d[o + j])


@njit(cache=True, error_model="numpy")
def _curve_out(d, o, n, mode, x):  # pragma: no cover - compiled
    """Value of the curve outside its axis (or NaN ``x``) with extrapolation ``mode`` (cold path of
    :func:`curve_ex`)."""
    i, f = _axis_ex(d, o, n, mode, x)
    y0 = d[o + n + i]
    return y0 + f * (d[o + n + i + 1] - y0)


@njit(cache=True, inline="always")   # inlined at numba IR level: keeps the clamp path as fast as curve_nb
def curve_ex(d, o, n, mode, x):  # pragma: no cover - compiled
    """:func:`curve_nb` with the extrapolation ``mode`` of ``Curve`` (0 clamp, 1 linear, 2 error -> NaN
    outside the axis); inside the axis, or in mode 0, it *is* ``curve_nb``, so clamped maps keep their bits."""
    if mode != 0 and not (d[o] <= x <= d[o + n - 1]):
        return _curve_out(d, o, n, mode, x)
    return curve_nb(d, o, n, x)


@njit(cache=True, error_model="numpy")
def _grid_out(d, o, nx, ny, mx, my, x, y):  # pragma: no cover - compiled
    """Bilinear value with per-axis extrapolation modes (cold path of :func:`grid_ex`)."""
    i, fx = _axis_ex(d, o, nx, mx, x)
    j, fy = _axis_ex(d, o + nx, ny, my, y)
    r0 = o + nx + ny + i * ny
    r1 = r0 + ny
    a = d[r0 + j] + fy * (d[r0 + j + 1] - d[r0 + j])
    b = d[r1 + j] + fy * (d[r1 + j + 1] - d[r1 + j])
    return a + fx * (b - a)


@njit(cache=True, inline="always")
def grid_ex(d, o, nx, ny, mx, my, x, y):  # pragma: no cover - compiled
    """:func:`grid_nb` with per-axis extrapolation modes of ``Grid2D`` (0 clamp, 1 linear, 2 error -> NaN
    outside the axis); inside the grid, or in modes (0, 0), it *is* ``grid_nb``."""
    if (mx != 0 and not (d[o] <= x <= d[o + nx - 1])) or (my != 0 and not (d[o + nx] <= y <= d[o + nx + ny - 1])):
        return _grid_out(d, o, nx, ny, mx, my, x, y)
    return grid_nb(d, o, nx, ny, x, y)


@njit(cache=True, error_model="numpy")
def ecm_lookup(d, ix, soc, t_c, sign):
    """``(rs, r1, c1, r2, c2)`` of the cell ECM tables packed by ``CellTables.packed()`` at SOC [1] and
    temperature [degC]: bilinear, clamped at the edges; discharge table for ``sign >= 0``, charge below."""
    if sign >= 0.0:
        og, ns, nt = ix[4], ix[5], ix[6]
    else:
        og, ns, nt = ix[7], ix[8], ix[9]
    nq = ix[10]
    i_s, ws = _g2_locate(d, og, ns, soc)
    j_t, wt = _g2_locate(d, og + ns, nt, t_c)
    ov = og + ns + nt
    pa = ov + (j_t * ns + i_s) * nq
    pb = pa + nq
    pc = ov + ((j_t + 1) * ns + i_s) * nq
    pd = pc + nq
    w00 = (1.0 - ws) * (1.0 - wt)
    w01 = ws * (1.0 - wt)
    w10 = (1.0 - ws) * wt
    w11 = ws * wt
    rs = w00 * d[pa] + w01 * d[pb] + w10 * d[pc] + w11 * d[pd]
    r1 = w00 * d[pa + 1] + w01 * d[pb + 1] + w10 * d[pc + 1] + w11 * d[pd + 1]
    c1 = w00 * d[pa + 2] + w01 * d[pb + 2] + w10 * d[pc + 2] + w11 * d[pd + 2]
    r2 = w00 * d[pa + 3] + w01 * d[pb + 3] + w10 * d[pc + 3] + w11 * d[pd + 3]
    c2 = w00 * d[pa + 4] + w01 * d[pb + 4] + w10 * d[pc + 4] + w11 * d[pd + 4]
    return rs, r1, c1, r2, c2


@njit(cache=True, error_model="numpy")
def curve_eval_array(d, n, mode, xs):  # pragma: no cover - compiled
    """:func:`curve_ex` over an array of ``x`` (a curve packed alone: axis ``d[:n]``, values ``d[n:2n]``)."""
    out = np.empty(xs.size)
    for k in range(xs.size):
        out[k] = curve_ex(d, 0, n, mode, xs[k])
    return out


@njit(cache=True, error_model="numpy")
def grid_eval_array(d, nx, ny, mx, my, xs, ys):  # pragma: no cover - compiled
    """:func:`grid_ex` over arrays of ``(x, y)`` (a map packed alone: axes then row-major values)."""
    out = np.empty(xs.size)
    for k in range(xs.size):
        out[k] = grid_ex(d, 0, nx, ny, mx, my, xs[k], ys[k])
    return out


@njit(cache=True, error_model="numpy")
def interp_held(xa, ox, ya, oy, n, x):  # pragma: no cover - compiled
    """Piecewise-linear ``y(x)`` through ``n >= 1`` knots ``xa[ox:ox+n]`` (increasing) / ``ya[oy:oy+n]``,
    held beyond the end knots (knot lists of parameters: dU/dT(SOC), road grade along distance)."""
    if n == 1 or x <= xa[ox]:
        return ya[oy]
    if x >= xa[ox + n - 1]:
        return ya[oy + n - 1]
    j = _bisect_right(xa, ox, n, x) - 1
    f = (x - xa[ox + j]) / (xa[ox + j + 1] - xa[ox + j])
    return ya[oy + j] + f * (ya[oy + j + 1] - ya[oy + j])


@njit(cache=True)
def py_min(a, b):
    """Python's ``min(a, b)`` in compiled code: the first argument unless the second is strictly smaller
    (numba's ``min`` may pick the other one of two equal values, e.g. signed zeros)."""
    return b if b < a else a


@njit(cache=True)
def py_max(a, b):
    """Python's ``max(a, b)`` in compiled code (see :func:`py_min`)."""
    return b if b > a else a


def py_func(f):
    """The uncompiled (reference) form of a compiled function: the same source, run by Python
    (``f.py_func``; ``f`` itself when it is not compiled)."""
    return getattr(f, "py_func", f)
