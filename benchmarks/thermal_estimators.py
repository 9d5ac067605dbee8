"""Benchmark: cost per step of the cell thermal models and the thermal estimators (KF, DKF, JEKF).

Run: ``python benchmarks/thermal_estimators.py``.  Prints microseconds per call (best of 5 repeats).
"""
from __future__ import annotations

import time

import numpy as np

from shevsim.battery.thermal import FDThermal, ThermalParams, TwoStateThermal
from shevsim.bms.thermal_estimators import ThermalDKF, ThermalJEKF, ThermalKF


def _best_us(fn, n: int, repeats: int = 5) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(n)
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def main(n: int = 20000) -> dict:
    p = ThermalParams()
    rng = np.random.default_rng(0)
    ys = (30.0 + 0.05 * rng.standard_normal(n)).tolist()
    qs = (1.0 + rng.random(n)).tolist()
    out = {}

    m2 = TwoStateThermal(p)

    def run_two_state(k):
        x = m2.initial_state(25.0)
        for i in range(k):
            x = m2.step(x, qs[i], 25.0, 20.0, 0.1)
            m2.outputs(x, qs[i], 25.0, 20.0)
    out["TwoStateThermal step+outputs"] = _best_us(run_two_state, n)

    mf = FDThermal(p, 30)

    def run_fd(k):
        x = mf.initial_state(25.0)
        for i in range(k):
            x = mf.step(x, qs[i], 25.0, 20.0, 0.1)
            mf.outputs(x, qs[i], 25.0, 20.0)
    out["FDThermal(30) step+outputs"] = _best_us(run_fd, n // 4)

    for cls in (ThermalKF, ThermalDKF, ThermalJEKF):
        def run_f(k, cls=cls):
            f = cls(p)
            for i in range(k):
                f.update(ys[i], 27.0, qs[i])
        out[f"{cls.__name__}.update"] = _best_us(run_f, n)
    for k, v in out.items():
        print(f"{k:32s} {v:8.2f} us/step")
    return out


if __name__ == "__main__":
    main()
