"""loop.py - the compiled fixed-step, multi-rate Gauss-Seidel loop over a scenario's schedule.

The loop is the one of :meth:`shevsim.core.master.Master.step`, with the components' ports in one
float array ``sig`` (outputs first, in the master's recording order, then inputs) and the
connections as index pairs::

    for k in range(n):                              # communication steps, t = t0 + k h
        force the inputs of faults due at t
        for j in execution order:
            if k % multiple[j] == 0:
                sig[dst] = sig[src] for the connections into component j   (Jacobi: all before any step)
                step component j over multiple[j] * h      (kernels.py, by type code)
        record sig[:n_signals] as column k + 1 of rec (signals x samples); stop at the first non-finite value

Component data are passed as one tuple per kind holding one tuple per instance
(:mod:`shevsim.fast.kernels`); ``inst[j]`` is the position of the j-th component (execution order) in its
type's list.  Faults (``f_t``, ``f_idx``, ``f_val``, sorted by time) force
an input from their time on and cut its connection, as :meth:`Master._apply_faults` does.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

from numba import njit

from . import kernels as K

#: the modules whose compiled functions the loop calls (inlined into its machine code). numba's on-disk
#: cache checks only the defining file of a function, so a change in one of these would leave a stale
#: compiled loop: :func:`_drop_stale_cache` removes the loop's cache entries when their sources change.
_DEPENDS = ("fast/loop.py", "fast/kernels.py", "supervisor/daqp_nb.py", "battery/model.py", "battery/thermal.py",
            "bms/electrical.py", "bms/thermal_estimators.py", "bms/power_capability.py", "core/lookup.py",
            "powertrain/engine.py", "powertrain/motor.py", "powertrain/vehicle.py", "powertrain/driver.py",
            "supervisor/mpc.py", "supervisor/rule_based.py", "components/cycle.py")


@njit(cache=True)
def run_loop(n, k0, h, t0, typ, mult, ibase, obase, lptr, ldst, lsrc, sig, rec, nsig, out, inst,
             f_t, f_idx, f_val, forced, fstate, jacobi, cyc, drv, veh, mot, bus, eng, bat, bms, rule, mpc, lim,
             vsp, prof):
    """Step ``n`` communication steps from step index ``k0``; columns ``k0 + 1 .. k0 + n`` of ``rec`` (one row per
    signal: each signal's samples contiguous) are recorded.

    ``out`` receives ``[status, step index, position in the order]``; status 0 = completed, otherwise
    the kernel's error code (or :data:`~shevsim.fast.kernels.ERR_NONFINITE_OUTPUT`).
    """
    ncomp = typ.shape[0]
    nf = f_t.shape[0]
    # the first instance of each kind held in locals (taking an item out of the tuple of instances by a
    # run-time index copies its arrays' descriptors: done once here rather than at every call)
    cyc0 = cyc[0]
    drv0 = drv[0]
    veh0 = veh[0]
    mot0 = mot[0]
    bus0 = bus[0]
    eng0 = eng[0]
    bat0 = bat[0]
    bms0 = bms[0]
    rule0 = rule[0]
    mpc0 = mpc[0]
    lim0 = lim[0]
    vsp0 = vsp[0]
    prof0 = prof[0]
    for s in range(n):
        k = k0 + s
        t = t0 + k * h
        # faults due at this communication point (Master._apply_faults): force the input, cut its connection
        fd = fstate[0]
        while fd < nf and f_t[fd] <= t + 1e-9 * max(1.0, abs(t)):
            sig[f_idx[fd]] = f_val[fd]
            forced[f_idx[fd]] = 1
            fd += 1
        fstate[0] = fd
        if jacobi:
            # Jacobi: every due component reads the outputs at t before any of them steps
            for j in range(ncomp):
                if k % mult[j] == 0:
                    for q in range(lptr[j], lptr[j + 1]):
                        if forced[ldst[q]] == 0:
                            sig[ldst[q]] = sig[lsrc[q]]
        for j in range(ncomp):
            m = mult[j]
            if m == 1 or k % m == 0:
                if not jacobi:
                    for q in range(lptr[j], lptr[j + 1]):
                        if forced[ldst[q]] == 0:
                            sig[ldst[q]] = sig[lsrc[q]]
                hk = m * h
                ty = typ[j]
                ib = ibase[j]
                ob = obase[j]
                if ty == K.T_CYCLE:
                    if inst[j] == 0:
                        st = K.cycle_step(cyc0, sig, ib, ob, t, hk)
                    else:
                        st = K.cycle_step(cyc[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_DRIVER:
                    if inst[j] == 0:
                        st = K.driver_kernel(drv0, sig, ib, ob, t, hk)
                    else:
                        st = K.driver_kernel(drv[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_VEHICLE:
                    if inst[j] == 0:
                        st = K.vehicle_kernel(veh0, sig, ib, ob, t, hk)
                    else:
                        st = K.vehicle_kernel(veh[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_MOTOR:
                    if inst[j] == 0:
                        st = K.motor_kernel(mot0, sig, ib, ob, t, hk)
                    else:
                        st = K.motor_kernel(mot[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_BUS:
                    if inst[j] == 0:
                        st = K.bus_kernel(bus0, sig, ib, ob, t, hk)
                    else:
                        st = K.bus_kernel(bus[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_ENGINE:
                    if inst[j] == 0:
                        st = K.engine_kernel(eng0, sig, ib, ob, t, hk)
                    else:
                        st = K.engine_kernel(eng[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_BATTERY:
                    if inst[j] == 0:
                        st = K.battery_kernel(bat0, sig, ib, ob, t, hk)
                    else:
                        st = K.battery_kernel(bat[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_BMS:
                    if inst[j] == 0:
                        st = K.bms_kernel(bms0, sig, ib, ob, t, hk)
                    else:
                        st = K.bms_kernel(bms[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_RULE:
                    if inst[j] == 0:
                        st = K.rule_kernel(rule0, sig, ib, ob, t, hk)
                    else:
                        st = K.rule_kernel(rule[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_LIMITS:
                    if inst[j] == 0:
                        st = K.power_limits_kernel(lim0, sig, ib, ob, t, hk)
                    else:
                        st = K.power_limits_kernel(lim[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_VEHICLE_SPEED:
                    if inst[j] == 0:
                        st = K.vehicle_speed_kernel(vsp0, sig, ib, ob, t, hk)
                    else:
                        st = K.vehicle_speed_kernel(vsp[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_PROFILE:
                    if inst[j] == 0:
                        st = K.profile_kernel(prof0, sig, ib, ob, t, hk)
                    else:
                        st = K.profile_kernel(prof[inst[j]], sig, ib, ob, t, hk)
                elif ty == K.T_MPC:
                    if inst[j] == 0:
                        st = K.mpc_kernel(mpc0, sig, ib, ob, t, hk)
                    else:
                        st = K.mpc_kernel(mpc[inst[j]], sig, ib, ob, t, hk)
                else:
                    st = K.ERR_NAN_INPUT
                if st != 0:
                    out[0] = st
                    out[1] = k
                    out[2] = j
                    return
        acc = 0.0
        row = k + 1
        for i in range(nsig):
            x = sig[i]
            rec[i, row] = x
            acc += x
        if not math.isfinite(acc):
            out[0] = K.ERR_NONFINITE_OUTPUT
            out[1] = k + 1
            out[2] = -1
            return
    out[0] = 0
    out[1] = k0 + n
    out[2] = -1


def _sources_digest() -> str:
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for rel in _DEPENDS:
        try:
            h.update(rel.encode() + b"\0" + (root / rel).read_bytes())
        except OSError:
            h.update(rel.encode() + b"\0missing")
    return h.hexdigest()


def _drop_stale_cache() -> None:
    """Remove the cached compiled loop and kernels when the sources they inline have changed (best effort:
    a cache folder that cannot be written is left alone)."""
    try:
        cache_dir = Path(run_loop._cache._cache_path)
        stamp = cache_dir / "shevsim_fast_sources.sha256"
        digest = _sources_digest()
        if stamp.exists() and stamp.read_text().strip() == digest:
            return
        for f in list(cache_dir.glob("loop.*.nb[ic]")) + list(cache_dir.glob("kernels.*.nb[ic]")):
            f.unlink(missing_ok=True)
        cache_dir.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest + "\n")
    except Exception:  # noqa: BLE001 - never stop a run over the cache
        pass


_drop_stale_cache()
