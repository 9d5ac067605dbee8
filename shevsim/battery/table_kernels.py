"""table_kernels.py - compiled (numba) lookups on the cell tables packed by :meth:`CellTables.packed`.

Each function repeats the arithmetic of the corresponding Python method of
:mod:`shevsim.battery.cell` (``_Table1.__call__``, ``slope``, ``integral``, ``_Grid2._locate``) in the
same order, so compiled callers reproduce the Python results bit for bit.
"""
from __future__ import annotations

try:  # numba is a dependency; without it the Python path runs
    from numba import njit as _njit
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def _njit(*args, **kwargs):
        return lambda f: f


@_njit(cache=True)
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


@_njit(cache=True)
def _t1_value(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        return d[o + n]
    if x >= d[o + n - 1]:
        return d[o + 2 * n - 1]
    k = _bisect_right(d, o, n, x) - 1
    return d[o + n + k] + d[o + 2 * n + k] * (x - d[o + k])


@_njit(cache=True)
def _t1_slope(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        k = 0
    elif x >= d[o + n - 1]:
        k = n - 2
    else:
        k = _bisect_right(d, o, n, x) - 1
    return d[o + 2 * n + k]


@_njit(cache=True)
def _t1_integral(d, o, n, x):  # pragma: no cover - compiled
    oc = o + 3 * n - 1
    if x <= d[o]:
        return d[o + n] * (x - d[o])
    if x >= d[o + n - 1]:
        return d[oc + n - 1] + d[o + 2 * n - 1] * (x - d[o + n - 1])
    k = _bisect_right(d, o, n, x) - 1
    dx = x - d[o + k]
    return d[oc + k] + d[o + n + k] * dx + 0.5 * d[o + 2 * n + k] * dx * dx


@_njit(cache=True)
def _g2_locate(d, o, n, x):  # pragma: no cover - compiled
    if x <= d[o]:
        return 0, 0.0
    if x >= d[o + n - 1]:
        return n - 2, 1.0
    j = _bisect_right(d, o, n, x) - 1
    return j, (x - d[o + j]) / (d[o + j + 1] - d[o + j])
