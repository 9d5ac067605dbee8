"""profile.py - where the compiled loop's time goes, per component.

``python -m shevsim.fast.profile hd_udds_mpc [--stop 1060] [--set cycle.repeat=1]``

Runs the scenario once on the fast path, reconstructs every component's input sequence from the
recorded outputs (a Gauss-Seidel input is its source's output of this step when the source runs earlier
in the order, of the previous step otherwise; step multiples respected), then replays each component's
compiled step alone over its own inputs from the initial state and times it.  So each figure is that
component's compiled step with realistic inputs (the MPC's DAQP warm starts included); the remainder of
the full run is the loop itself (connections, recording).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit



@njit
def _replay(step, data, sig, io, in_idx, vals, steps, h):
    ib, nin, ob, nout = io[0], io[1], io[2], io[3]
    for s in range(steps.shape[0]):
        for q in range(in_idx.shape[0]):
            sig[in_idx[q]] = vals[s, q]
        st = step(data, sig[ib:ib + nin], sig[ob:ob + nout], steps[s] * h, h)
        if st != 0:
            return st
    return 0


def profile(runner, t_stop_s: float, repeat: int = 3) -> dict:
    """``{"total_s", "steps", "per_component": {name: (seconds, calls)}}`` for a :class:`FastRunner`."""
    t = time.perf_counter()
    res = runner(t_stop_s)
    total = time.perf_counter() - t
    for _ in range(repeat - 1):
        t = time.perf_counter()
        runner(t_stop_s)
        total = min(total, time.perf_counter() - t)
    rec = np.column_stack([res.signals[n] for n in runner._names])
    n = rec.shape[0] - 1
    typ, mult_a, ibase, nin, obase, nout, lptr, ldst, lsrc, inst, _flags = runner._plan
    owner = np.full(runner.nsig, -1)
    for j in range(len(runner._comp_names)):
        owner[obase[j]:obase[j] + nout[j]] = j
    out = {}
    for j, name in enumerate(runner._comp_names):
        mult = int(mult_a[j])
        steps = np.arange(0, n, mult, dtype=np.int64)
        lo, hi = lptr[j], lptr[j + 1]
        in_idx = ldst[lo:hi].copy()
        vals = np.empty((steps.size, hi - lo))
        for q in range(lo, hi):
            src = int(lsrc[q])
            row = steps + (1 if owner[src] < j else 0)
            vals[:, q - lo] = rec[row, src]
        fn = runner._fns[int(typ[j])]
        c, data, mut = runner._by_fn[fn][int(inst[j])]
        io = np.array([ibase[j], nin[j], obase[j], nout[j]], dtype=np.int64)
        best = None
        for rep in range(repeat + 1):             # the first pass compiles the replay: not timed
            d = c.fast_data(tuple(a.copy() if k in mut else a for k, a in enumerate(data)), steps.size)
            sig = runner._sig0.copy()
            t = time.perf_counter()
            st = _replay(fn, d, sig, io, in_idx, vals, steps, runner.h * mult)
            dt = time.perf_counter() - t
            c.fast_release(d)
            if rep > 0:
                best = dt if best is None else min(best, dt)
        out[name] = (best, int(steps.size), int(st))
    return {"total_s": total, "steps": n, "per_component": out}


def main(argv=None) -> int:
    from shevsim.core.scenario import load_scenario
    from . import runner_for
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario")
    ap.add_argument("--stop", type=float, default=None)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    sc = load_scenario(a.scenario, a.set)
    run, why = runner_for(sc)
    if run is None:
        raise SystemExit(f"not eligible for the fast path: {why}")
    from shevsim.core.scenario import stop_time
    stop = a.stop if a.stop is not None else float(stop_time(sc, run.master))
    run(min(stop, 1.0))                      # compile / load off the clock
    p = profile(run, stop, a.repeat)
    tot, n = p["total_s"], p["steps"]
    print(f"{sc.name}: {n} steps, full run {1e3 * tot:.1f} ms ({1e6 * tot / n:.2f} us/step)")
    acc = 0.0
    for name, (s, calls, st) in sorted(p["per_component"].items(), key=lambda kv: -kv[1][0]):
        acc += s
        print(f"  {name:18s} {1e3 * s:8.1f} ms  {100 * s / tot:5.1f} %  {1e6 * s / max(calls, 1):7.2f} us/call"
              f"  ({calls} calls){'  (stopped early)' if st else ''}")
    rest = tot - acc
    print(f"  {'loop+recording':18s} {1e3 * rest:8.1f} ms  {100 * rest / tot:5.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
