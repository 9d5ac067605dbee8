"""daqp_nb.py - DAQP's C library called from numba-compiled code (no return to Python per solve).

The installed ``daqp`` wheel (a Cython extension) exports the C API of DAQP (``setup_daqp_main``,
``daqp_update_ldp``, ``daqp_solve``, ...).  The functions here replay, call for call, what the
Python class ``daqp.Model`` does in ``__cinit__`` / ``setup`` / ``update`` / ``solve`` /
``__dealloc__`` (read from the daqp 0.11.0 source, ``daqp.pyx``), so a compiled caller gets the very
iterates, warm start and exit flags of :class:`shevsim.supervisor.mpc._DaqpSolver` - bit for bit
(``tests/unit/test_fast_path.py``).

The C structs are held in numpy buffers laid out as in DAQP's ``types.h`` / ``api.h`` (x86-64 /
aarch64 LP64: int 4 bytes, pointers 8 bytes, natural alignment)::

    DAQPProblem  {int n, m, ms; double *H, *f, *A, *bupper, *blower; int *sense, *break_points;
                  int nh, problem_type}                                   80 bytes
    DAQPResult   {double *x, *lam; double fval, soft_slack; int exitflag, iter, nodes;
                  double solve_time, setup_time}                          64 bytes
    DAQPWorkspace {DAQPProblem *qp; int n, m, ms; double *M, *dupper, *dlower, *Rinv, *v;
                  int *sense; ...}                                         sense at byte 64

Pointers are passed to the C functions as 64-bit integers (the same register in the LP64 calling
convention).  :func:`available` says whether this binding can be used (a daqp wheel of the checked
version exporting the symbols, a 64-bit platform); otherwise the fast path declines MPC scenarios.
"""
from __future__ import annotations

import ctypes
import struct

import numpy as np
from numba import njit, types

CHECKED_VERSIONS = ("0.11.0",)
UPDATE_MASK = 1 | 4 | 8 | 16        # DAQP_UPDATE_Rinv | _v | _d | _sense (daqp.Model.update(H, f, bu, bl))
WS_BYTES = 8192                     # >= sizeof(DAQPWorkspace) (about 330 bytes in 0.11.0)
WS_SENSE_OFFSET = 64                # offsetof(DAQPWorkspace, sense)

_WHY = None


def _load() -> str | None:
    """Load DAQP's symbols for LLVM; return None or why it cannot be used."""
    global _WHY
    if _WHY is not None:
        return _WHY or None
    try:
        import daqp
        from importlib.metadata import version
        ver = version("daqp")
    except Exception as exc:  # pragma: no cover - daqp is a dependency
        _WHY = f"daqp is not importable ({exc})"
        return _WHY
    from numba.core import config as _nb_config
    if _nb_config.DISABLE_JIT:
        _WHY = "NUMBA_DISABLE_JIT is set (DAQP's C library is called from compiled code only)"
        return _WHY
    if struct.calcsize("P") != 8:
        _WHY = "DAQP binding needs a 64-bit platform"
        return _WHY
    if ver not in CHECKED_VERSIONS:
        _WHY = f"daqp {ver}: its C structs are checked only for daqp {', '.join(CHECKED_VERSIONS)}"
        return _WHY
    try:
        lib = ctypes.CDLL(daqp.__file__)
        for sym in ("setup_daqp_main", "daqp_update_ldp", "daqp_solve", "allocate_daqp_settings",
                    "free_daqp_workspace", "free_daqp_ldp"):
            getattr(lib, sym)
        import llvmlite.binding as ll
        ll.load_library_permanently(daqp.__file__)
    except Exception as exc:  # pragma: no cover
        _WHY = f"daqp's C library does not export the API ({exc})"
        return _WHY
    _WHY = ""
    return None


def available() -> tuple[bool, str]:
    why = _load()
    return (why is None), (why or "")


_load()
_i64 = types.int64
_c_setup = types.ExternalFunction("setup_daqp_main", types.int32(_i64, _i64, _i64, types.int32))
_c_update = types.ExternalFunction("daqp_update_ldp", types.int32(types.int32, _i64, _i64))
_c_solve = types.ExternalFunction("daqp_solve", types.void(_i64, _i64))
_c_alloc_settings = types.ExternalFunction("allocate_daqp_settings", types.void(_i64))
_c_free_ws = types.ExternalFunction("free_daqp_workspace", types.void(_i64))
_c_free_ldp = types.ExternalFunction("free_daqp_ldp", types.void(_i64))


def new_state(n: int, m_total: int):
    """Buffers of one ``daqp.Model`` replica for a QP with ``n`` variables and ``m_total`` bounds+rows.

    Returns ``(ws, qp, res, sense, x, lam, flags)``; ``flags[0]`` = has a model (set up).
    """
    ws = np.zeros(WS_BYTES // 8, dtype=np.int64)
    qp = np.zeros(10, dtype=np.int64)
    res = np.zeros(8, dtype=np.int64)
    sense = np.zeros(max(m_total, 1), dtype=np.int32)
    x = np.zeros(n)
    lam = np.zeros(max(m_total, 1))
    flags = np.zeros(2, dtype=np.int64)
    return ws, qp, res, sense, x, lam, flags


@njit(cache=True)
def drop_model(ws, flags):
    """``model = None`` (``__dealloc__``): free the workspace's allocations."""
    if flags[0] != 0:
        w = ws.ctypes.data
        _c_free_ws(w)
        _c_free_ldp(w)
        flags[0] = 0


@njit(cache=True)
def solve(ws, qp, res, sense, x, lam, flags, H, f, A, bu, bl):
    """One ``_DaqpSolver.solve``: set up a fresh model (first call / after a failure) or update the
    existing one with ``H, f, bu, bl``, then solve.  Returns DAQP's exit flag (< 1: no solution, the
    model is dropped as the Python solver does), or -1000 when the setup failed; ``x`` holds the
    solution."""
    w = ws.ctypes.data
    qp32 = qp.view(np.int32)
    if flags[0] == 0:
        # daqp.Model(): calloc + allocate_daqp_settings; setup(): fresh default settings
        ws[:] = 0
        _c_alloc_settings(w)
        n = H.shape[0]
        m = bu.shape[0]
        ms = m - A.shape[0]
        sense[:] = 0
        qp32[0] = n
        qp32[1] = m
        qp32[2] = ms
        qp[2] = H.ctypes.data
        qp[3] = f.ctypes.data
        qp[4] = A.ctypes.data
        qp[5] = bu.ctypes.data
        qp[6] = bl.ctypes.data
        qp[7] = sense.ctypes.data
        qp[8] = 0
        qp32[18] = 0
        qp32[19] = 0
        # the setup time (a double DAQP writes) goes into res's setup_time slot (byte 56), zeroed before the solve:
        # no allocation here, so this compiles inside a step built without numba's runtime (core.compiled.njit_step)
        flag = _c_setup(qp.ctypes.data, w, res.ctypes.data + 56, 0)
        if flag < 0:
            _c_alloc_settings(w)
            _c_free_ws(w)
            _c_free_ldp(w)
            return -1000
        flags[0] = 1
    else:
        qp[2] = H.ctypes.data
        qp[3] = f.ctypes.data
        qp[5] = bu.ctypes.data
        qp[6] = bl.ctypes.data
        qp[7] = ws[WS_SENSE_OFFSET // 8]          # qp.sense = work.sense (model has solved)
        _c_update(UPDATE_MASK, w, qp.ctypes.data)
    res[:] = 0
    res[0] = x.ctypes.data
    res[1] = lam.ctypes.data
    _c_solve(res.ctypes.data, w)
    flag = res.view(np.int32)[8]
    if flag < 1:
        drop_model(ws, flags)
    return flag
