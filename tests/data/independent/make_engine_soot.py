"""Engine-generator soot records for the calibration tests, made by an independent script (not the
``engine_generator`` component, not :mod:`shevsim.powertrain.engine`).

    python tests/data/independent/make_engine_soot.py

Plant (written here from the published maps only, numpy/scipy lookups of its own):

* the generator's electrical power follows the supervisor's command through a first-order response
  (``TAU_P_S`` = 0.8 s) with the 0 .. 236 kW range of the machine;
* the operating point is the optimal operating line at that power (``optimal_operating_line.csv``: speed,
  torque), the quasi-static soot ``soot_map.csv`` (bilinear) at it, times ``SOOT_SCALE`` = 1.3;
* the transient term (case ``transient``) has a form the component does not use: an air-deficit state
  ``z' = max(dP/dt, 0) / P_max - z / TAU_AIR_S`` (``TAU_AIR_S`` = 2 s) adds ``K_T z`` mg/s (``K_T`` =
  40 mg/s per unit of z) - a puff that grows with the rate of power rise, not with the fuel deficit;
* the analyser (cases ``analyzer_lag``: first-order lag 4 s; ``analyzer_offset``: +1.5 mg/s); noise 2 % +
  0.05 mg/s.

Stepped at 0.05 s.  The command is a seeded supervisor-like sequence (levels held 5-40 s) for 900 s.
Logged at 1 Hz in the engine model's documented convention: ``power_w[k]`` is the command in force over
``(t[k-1], t[k]]``, ``soot_rate_mgps[k]`` the analyser's reading at ``t[k]``.  ``engine_truth.json``:
seeds and the truth in the component's names (``soot_scale_frac``, ``soot_analyzer_tau_s``,
``soot_analyzer_offset_mgps``; the transient term has no counterpart parameter: it is judged by name).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator

HERE = Path(__file__).resolve().parent
EG = HERE.parents[2] / "components" / "engine_generator"
DURATION_S = 900.0
H_S = 0.05
TAU_P_S = 0.8
TAU_AIR_S = 2.0
K_T = 40.0
SOOT_SCALE = 1.3
P_MAX_W = 236e3
CASES = {
    "none": {"seed": 31},
    "transient": {"seed": 32, "transient": True},
    "analyzer_lag": {"seed": 33, "tau_s": 4.0},
    "analyzer_offset": {"seed": 34, "offset_mgps": 1.5},
}


def _csv(path):
    lines = [ln for ln in Path(path).read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    head = lines[0].split(",")
    arr = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    return {h: arr[:, j] for j, h in enumerate(head)}


def steady_soot():
    ool = _csv(EG / "optimal_operating_line.csv")
    sm = _csv(EG / "soot_map.csv")
    sp, tq = np.unique(sm["speed_radps"]), np.unique(sm["torque_nm"])
    grid = np.full((sp.size, tq.size), np.nan)
    for a, b, c in zip(sm["speed_radps"], sm["torque_nm"], sm["soot_mgps"]):
        grid[np.searchsorted(sp, a), np.searchsorted(tq, b)] = c
    f = RegularGridInterpolator((sp, tq), grid, bounds_error=False, fill_value=None)
    pw = ool["elec_power_w"]
    soot = f(np.column_stack([ool["speed_radps"], ool["engine_torque_nm"]]))
    return lambda p: np.interp(p, pw, soot)


def command(rng):
    n = int(DURATION_S) + 1
    p = np.zeros(n)
    k = 1
    while k < n:
        seg = max(1, int(rng.uniform(5, 40)))
        p[k:k + seg] = rng.choice([0.0, rng.uniform(20e3, 100e3), rng.uniform(100e3, 230e3)], p=[0.15, 0.45, 0.4])
        k += seg
    return np.arange(n, dtype=float), p


def run(case, rng):
    t, cmd = command(rng)
    ss = steady_soot()
    sub = int(round(1.0 / H_S))
    p, z, y = cmd[0], 0.0, None
    tau_a, off = case.get("tau_s", 0.0), case.get("offset_mgps", 0.0)
    out = np.empty(t.size)
    s0 = SOOT_SCALE * float(ss(p))
    y = s0
    out[0] = y + off
    for k in range(1, t.size):
        for _ in range(sub):         # the command cmd[k] is in force over (t[k-1], t[k]]
            dp = (min(max(cmd[k], 0.0), P_MAX_W) - p) / TAU_P_S
            p += H_S * dp
            z += H_S * (max(dp, 0.0) / P_MAX_W - z / TAU_AIR_S)
            s = SOOT_SCALE * float(ss(p)) + (K_T * z if case.get("transient") else 0.0)
            y = s if tau_a <= 0 else y + H_S * (s - y) / tau_a
        out[k] = y + off
    return t, cmd, out


def main() -> int:
    truth = {"generator": "make_engine_soot.py (independent plant: first-order power response, OOL, soot map "
                          "x 1.3, air-deficit transient puff, analyser)", "cases": {}}
    for name, case in CASES.items():
        rng = np.random.default_rng(case["seed"])
        t, cmd, s = run(case, rng)
        s = s * (1.0 + rng.normal(0.0, 0.02, s.size)) + rng.normal(0.0, 0.05, s.size)
        lines = [f"# independent engine-generator soot record, case '{name}' (make_engine_soot.py)",
                 "time_s,power_w,soot_rate_mgps"] + [f"{a:.1f},{b:.1f},{c:.5f}" for a, b, c in zip(t, cmd, s)]
        (HERE / f"engine_{name}.csv").write_text("\n".join(lines) + "\n")
        truth["cases"][name] = {"inputs": {k: v for k, v in case.items() if k != "seed"}, "seed": case["seed"],
                                "file": f"engine_{name}.csv",
                                "truth": {"soot_scale_frac": SOOT_SCALE, "soot_analyzer_tau_s": case.get("tau_s", 0.0),
                                          "soot_analyzer_offset_mgps": case.get("offset_mgps", 0.0),
                                          "transient": bool(case.get("transient", False))},
                                "soot_mean_mgps": float(np.mean(s))}
        print(name, f"mean soot {np.mean(s):.3f} mg/s")
    (HERE / "engine_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
