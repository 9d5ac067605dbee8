"""profile.py - where the compiled loop's time goes, per component.

``python -m shevsim.fast.profile hd_udds_mpc [--stop 1060] [--set cycle.repeat=1]``

Runs the scenario once on the fast path, reconstructs every component's input sequence from the
recorded outputs (a Gauss-Seidel input is its source's output of this step when the source runs earlier
in the order, of the previous step otherwise; step multiples respected), then replays each component's
kernel alone over its own inputs from the initial state and times it.  So each figure is that
component's compiled step with realistic inputs (the MPC's DAQP warm starts included); the remainder of
the full run is the loop itself (connections, recording).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from . import kernels as K


@njit
def _replay(kern, data, sig, ib, ob, in_idx, vals, steps, h):
    nin = in_idx.shape[0]
    for s in range(steps.shape[0]):
        for q in range(nin):
            sig[in_idx[q]] = vals[s, q]
        st = kern(data, sig, ib, ob, steps[s] * h, h)
        if st != 0:
            return st
    return 0


_KERN = {K.T_CYCLE: K.cycle_step, K.T_DRIVER: K.driver_kernel, K.T_VEHICLE: K.vehicle_kernel,
         K.T_MOTOR: K.motor_kernel, K.T_BUS: K.bus_kernel, K.T_ENGINE: K.engine_kernel,
         K.T_BATTERY: K.battery_kernel, K.T_BMS: K.bms_kernel, K.T_RULE: K.rule_kernel, K.T_MPC: K.mpc_kernel}


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
    m = runner.master
    pos = {name: j for j, name in enumerate(runner._comp_names)}
    out = {}
    types = {runner._comp_names[j]: m.components[runner._comp_names[j]].TYPE for j in range(len(pos))}
    for j, name in enumerate(runner._comp_names):
        mult = int(runner._mult[j])
        steps = np.arange(0, n, mult, dtype=np.int64)
        lo, hi = runner._lptr[j], runner._lptr[j + 1]
        in_idx = runner._ldst[lo:hi].copy()
        vals = np.empty((steps.size, hi - lo))
        for q in range(lo, hi):
            src = int(runner._lsrc[q])
            src_comp = next(c for c in runner._comp_names
                            if runner._obase[pos[c]] <= src < runner._obase[pos[c]] + len(_out_ports(types[c])))
            row = steps + (1 if pos[src_comp] < j else 0)
            vals[:, q - lo] = rec[row, src]
        best = None
        for rep in range(repeat + 1):             # the first pass compiles the replay: not timed
            typ = types[name]
            i = int(runner._inst[j])
            d = runner._fresh(typ, i)
            if typ == "battery":
                b = next(b for b in runner._batteries if b[0] == i)
                d = d[:6] + (runner._noise_for(b, 4 * steps.size),) + d[7:]
            sig = runner._sig0.copy()
            t = time.perf_counter()
            if int(runner._typ[j]) == K.T_LIMITS:
                st = _replay(K.power_limits_kernel, d, sig, runner._ibase[j], runner._obase[j], in_idx, vals, steps,
                             runner.h * mult)
            else:
                st = _replay(_KERN[int(runner._typ[j])], d, sig, runner._ibase[j], runner._obase[j],
                             in_idx, vals, steps, runner.h * mult)
            dt = time.perf_counter() - t
            if typ == "mpc_supervisor":
                from shevsim.supervisor import daqp_nb
                if d[30][0] != 0:
                    daqp_nb.drop_model(d[24], d[30])
            if rep > 0:
                best = dt if best is None else min(best, dt)
        out[name] = (best, int(steps.size), int(st))
    return {"total_s": total, "steps": n, "per_component": out}


def _out_ports(typ):
    from . import _PORTS
    return _PORTS[typ][1]


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
