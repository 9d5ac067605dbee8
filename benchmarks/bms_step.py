"""bms_step.py - cost of one BMS step (DEKF -> thermal DKF -> power capability) and of one plant step.

Runs the battery pack plant and the BMS in closed loop (the BMS's limits clamp a drive-cycle-like
pack-power demand, cooling fault h 20 -> 3 W/m2K at 300 s) at 0.1 s for ``n`` steps and reports
microseconds per step of each, timed separately (min of 3 repeats of the whole run).

Run: ``python benchmarks/bms_step.py [n_steps]``.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from shevsim.components.battery import BatteryPack, BatteryPackParams
from shevsim.components.bms import BMS, BMSParams

PORTS = ("cell_current_meas_a", "cell_voltage_meas_v", "t_surface_meas_c", "t_ambient_meas_c")


def profile(n: int, dt: float, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = np.zeros(n)
    k = 0
    while k < n:
        m = int(rng.uniform(2.0, 15.0) / dt)
        p[k:k + m] = rng.uniform(-60e3, 80e3) if rng.random() > 0.2 else 0.0
        k += m
    return 2.0 * (p - 0.9 * p.mean())


def run(n: int, dt: float = 0.1, estimator: str = "dkf"):
    prof = profile(n, dt).tolist()
    b = BatteryPack("battery", BatteryPackParams(soc_init_pct=55.0))
    m = BMS("bms", BMSParams.retuned(thermal_estimator=estimator))
    bu, by, mu, my = b.u, b.y, m.u, m.y
    tp = tm = 0.0
    clock = time.perf_counter
    t_core_max = 0.0
    for k in range(n):
        t = k * dt
        bu["h_conv_w_m2k"] = 20.0 if t < 300.0 else 3.0
        p = prof[k]
        lo, hi = my["power_min_w"], my["power_max_w"]
        bu["power_w"] = lo if p < lo else (hi if p > hi else p)
        t0 = clock()
        b.do_step(t, dt)
        t1 = clock()
        for name in PORTS:
            mu[name] = by[name]
        t2 = clock()
        m.do_step(t, dt)
        t3 = clock()
        tp += t1 - t0
        tm += t3 - t2
        if by["t_core_c"] > t_core_max:
            t_core_max = by["t_core_c"]
    return tp / n * 1e6, tm / n * 1e6, t_core_max


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    for est in ("dkf", "jekf", "kf"):
        best = min((run(n, estimator=est) for _ in range(3)), key=lambda r: r[1])
        print(f"thermal estimator {est:4s}: BMS step {best[1]:6.1f} us, plant step {best[0]:5.1f} us "
              f"(n = {n}, max true core temperature {best[2]:.2f} degC)")
