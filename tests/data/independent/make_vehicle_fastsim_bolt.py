"""Out-of-sample vehicle records (eighth session): FASTSim 3.1's 2020 Chevrolet Bolt EV, made by a new-user trial.

    benchmarks/.venv-fastsim/bin/python tests/data/independent/make_vehicle_fastsim_bolt.py

A helper who had not seen the calibration's development wrote this script to try ``shevsim calibrate vehicle`` as a
new user would: a vehicle the project never used, with a nominal from its spec sheet.  The calibration rules
changed by what it found (a missing motor map filling in the project's truck motor; see
``docs/calibration_independent.md``, "Out of sample") are tested on these records, so they are no longer out of
sample for those rules.  They stay in the suite and the benchmark as regression cases.

FASTSim's own vehicle model (``2020 Chevrolet Bolt EV thrml.yaml``; cabin, HVAC and battery thermal models off, the
battery's efficiency a constant 0.985 - the logged power is the terminal power, which that efficiency does not
change) and its own time stepping (0.1 s) drive FASTSim's UDDS (whole, 1369 s) or HWFET cycle.  The trace is
interpolated linearly to the 0.1 s steps and smoothed there with a Gaussian of ``SMOOTH`` = 1.0 s.  A logger
samples the speed and the battery's electrical output power (``pwr_out_electrical_watts``: traction + auxiliaries,
drawn positive) at 1 Hz, instantaneously, and adds white noise (speed 0.02 m/s, power 300 W, seeded).  Cases set
through FASTSim's own inputs:

* ``none`` / ``none_3`` (UDDS, two seeds), ``none_2`` (HWFET): the published vehicle;
* ``payload`` (UDDS), ``payload_hwfet``: ``mass_kilograms`` + 300 kg;
* ``aux`` (UDDS), ``aux_hwfet``: ``pwr_aux_base_watts`` + 1500 W;
* ``latency_1``: the power channel read 1 s late (a logger latency).

The user's nominals, from the vehicle's data (mass, frontal area, drag and rolling coefficients, wheel radius and
inertia, 7.05 gear, 150 kW / 360 N.m):

* ``vehicle_bolt_nominal.toml``: the published efficiency curve (FASTSim's ``eff_interp_achieved`` x 0.98
  transmission) as a map, ``vehicle_bolt_eff_curve.csv``;
* ``vehicle_bolt_nominal_spec.toml``: a constant drive efficiency of 0.90 (a spec-sheet guess),
  ``vehicle_bolt_eff_const90.csv``;
* ``vehicle_bolt_nominal_nomap.toml``: no map at all (the calibration then takes the project's defaults and must
  say so).

``vehicle_bolt_truth.json``: per case the seed, cycle, FASTSim's mass and auxiliary power, the latency, and the truth in
the calibration's terms (``mass_kg``, ``aux_power_w``, ``time_shift_s``).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import fastsim as fsim
import numpy as np

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))
PRE = "vehicle_bolt"
RES = "2020 Chevrolet Bolt EV thrml.yaml"
H, SMOOTH = 0.1, 1.0
NOISE = {"speed_mps": 0.02, "power_w": 300.0}
CASES = {"none": {"seed": 201, "cyc": "udds.csv"},
         "payload": {"seed": 202, "cyc": "udds.csv", "dmass": 300.0},
         "aux": {"seed": 203, "cyc": "udds.csv", "daux": 1500.0},
         "latency_1": {"seed": 204, "cyc": "udds.csv", "lag_s": 1.0},
         "none_2": {"seed": 205, "cyc": "hwfet.csv"},
         "none_3": {"seed": 206, "cyc": "udds.csv"},
         "payload_hwfet": {"seed": 207, "cyc": "hwfet.csv", "dmass": 300.0},
         "aux_hwfet": {"seed": 208, "cyc": "hwfet.csv", "daux": 1500.0}}


def cycle(name):
    c = fsim.Cycle.from_resource(name).to_dict()
    tt, vv = np.asarray(c["time_seconds"], float), np.asarray(c["speed_meters_per_second"], float)
    t = np.round(np.arange(0.0, tt[-1] + 1e-9, H), 10)
    sig = SMOOTH / H
    k = np.arange(-int(4 * sig), int(4 * sig) + 1) * 1.0
    w = np.exp(-0.5 * (k / sig) ** 2)
    v = np.maximum(np.convolve(np.pad(np.interp(t, tt, vv), k.size // 2, mode="edge"), w / w.sum(), mode="valid"), 0.0)
    return t, v


def run(case):
    t, v = cycle(case["cyc"])
    cyc = fsim.Cycle.from_dict({"time_seconds": t.tolist(), "speed_meters_per_second": v.tolist(), "grade": [0.0] * t.size})
    d = fsim.Vehicle.from_resource(RES).to_dict()
    d["cabin"] = "None"
    d["hvac"] = "None"
    d["pt_type"]["BEV"]["res"]["thrml"] = "None"
    d["pt_type"]["BEV"]["res"]["eff_interp"] = {"Constant": 0.985}
    d["mass_kilograms"] = d["mass_kilograms"] + case.get("dmass", 0.0)
    d["pwr_aux_base_watts"] = d["pwr_aux_base_watts"] + case.get("daux", 0.0)
    sd = fsim.SimDrive(fsim.Vehicle.from_dict(d), cyc)
    sd.walk()
    o = sd.to_dict()["veh"]
    p = np.asarray(o["pt_type"]["BEV"]["res"]["history"]["pwr_out_electrical_watts"], float)
    va = np.asarray(o["history"]["speed_ach_meters_per_second"], float)
    return t, va, p, bool(all(o["history"]["cyc_met"])), d


def nominal(d):
    ch = d["chassis"]
    em = d["pt_type"]["BEV"]["em"]
    pmax = float(em["pwr_out_max_watts"])
    tpk = 360.0
    ws, tq = np.linspace(0, 1000.0, 21), np.linspace(-tpk, tpk, 25)
    rows = ["# 2020 Chevrolet Bolt EV: constant drive efficiency 0.90 (a spec-sheet guess)",
            "speed_radps,torque_nm,efficiency_frac"]
    rows += [f"{a:.3f},{b:.3f},0.90" for a in ws for b in tq]
    (OUT / f"{PRE}_eff_const90.csv").write_text("\n".join(rows) + "\n")
    rows = ["# Bolt EV 360 N.m up to 150 kW", "speed_radps,peak_torque_nm,cont_torque_nm"]
    rows += [f"{a:.3f},{min(tpk, pmax / a) if a > 0 else tpk:.3f},{min(tpk, pmax / a) if a > 0 else tpk:.3f}" for a in ws]
    (OUT / f"{PRE}_torque.csv").write_text("\n".join(rows) + "\n")
    g = np.asarray(em["eff_interp_achieved"]["data"]["grid"][0]["data"])
    vals = np.asarray(em["eff_interp_achieved"]["data"]["values"]["data"])
    rows = ["# Bolt EV published curve x 0.98", "speed_radps,torque_nm,efficiency_frac"]
    rows += [f"{a:.3f},{b:.3f},{float(np.interp(min(abs(a * b) / pmax, 1.0), g, vals)) * 0.98:.5f}" for a in ws for b in tq]
    (OUT / f"{PRE}_eff_curve.csv").write_text("\n".join(rows) + "\n")
    base = ["[params]", f"mass_kg = {float(d['mass_kilograms']):.1f}",
            f"frontal_area_m2 = {ch['frontal_area_square_meters']:.4f}", f"drag_coefficient = {ch['drag_coef']}",
            f"rolling_coefficient = {ch['wheel_rr_coef']:.5f}", f"wheel_radius_m = {ch['wheel_radius_meters']}",
            f"wheel_inertia_kg_m2 = {ch['wheel_inertia_kilogram_square_meters'] * ch['num_wheels']:.3f}",
            "aux_power_w = 250.0", "air_density_kg_m3 = 1.2", "gear_ratio = 7.05",
            f"rated_power_w = {pmax:.0f}", f"maps_rated_power_w = {pmax:.0f}", f'torque_curves_file = "{PRE}_torque.csv"']
    (OUT / f"{PRE}_nominal_spec.toml").write_text("\n".join(
        ["[meta]", 'source = "2020 Chevrolet Bolt EV spec sheet; constant 0.90 drive efficiency"'] + base
        + [f'efficiency_map_file = "{PRE}_eff_const90.csv"']) + "\n")
    (OUT / f"{PRE}_nominal.toml").write_text("\n".join(
        ["[meta]", 'source = "2020 Chevrolet Bolt EV; FASTSim published curve x 0.98"'] + base
        + [f'efficiency_map_file = "{PRE}_eff_curve.csv"']) + "\n")
    (OUT / f"{PRE}_nominal_nomap.toml").write_text("\n".join(
        ["[meta]", 'source = "2020 Chevrolet Bolt EV spec sheet without a motor map"'] + base[:10]) + "\n")


def main():
    truth = {"generator": f"FASTSim {fsim.__version__} {RES}, 1 Hz instantaneous", "noise": NOISE, "cases": {}}
    for name, case in CASES.items():
        t, va, p, met, d = run(case)
        if name == "none":
            nominal(d)
        rng = np.random.default_rng(case["seed"])
        ts = t[::10]
        lag = case.get("lag_s", 0.0)
        pl = np.interp(ts - lag, t, p, left=p[0])
        sp = np.maximum(va[::10] + rng.normal(0, NOISE["speed_mps"], ts.size), 0.0)
        pw = pl + rng.normal(0, NOISE["power_w"], ts.size)
        lines = [f"# FASTSim {fsim.__version__} {RES} case {name} (tests/data/independent/make_vehicle_fastsim_bolt.py)",
                 "time_s,speed_mps,power_w"]
        lines += [f"{a:.1f},{b:.4f},{c:.1f}" for a, b, c in zip(ts, sp, pw)]
        (OUT / f"{PRE}_{name}.csv").write_text("\n".join(lines) + "\n")
        truth["cases"][name] = {**case, "file": f"{PRE}_{name}.csv", "cycle_met": met,
                                "truth": {"mass_kg": float(d["mass_kilograms"]),
                                          "aux_power_w": float(d["pwr_aux_base_watts"]), "time_shift_s": lag},
                                "power_rms_w": float(np.sqrt(np.mean(p * p))), "p_min_w": float(p.min()),
                                "p_max_w": float(p.max())}
        print(name, met, f"rms {np.sqrt(np.mean(p * p)):.0f} W  min {p.min():.0f} max {p.max():.0f}", flush=True)
    # the no-effect UDDS record given with the nominal that has no motor map (the same file)
    truth["cases"]["none_nomap"] = dict(truth["cases"]["none"], nominal=f"{PRE}_nominal_nomap.toml")
    (OUT / f"{PRE}_truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
