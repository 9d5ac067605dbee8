"""Out-of-sample vehicle records (trial 40): FASTSim 3.1's 2016 Nissan Leaf 30 kWh, made by a new-user trial.

    /work/wt24/benchmarks/.venv-fastsim/bin/python tests/data/independent/make_vehicle_fastsim_trial40.py
    (any Python with fastsim==3.1.0 and numpy)

A helper who had not seen the calibration's development wrote this script to try ``shevsim calibrate vehicle`` as a
new user would, on a vehicle the project never used, with a nominal from its spec sheet.

Generator: FASTSim's own vehicle model (``2016 Nissan Leaf 30 kWh thrml.yaml``; cabin and HVAC models off, so the
auxiliary load is the constant ``pwr_aux_base_watts``) and its own time stepping (0.1 s) on FASTSim's UDDS (1369 s),
HWFET (765 s) or both back to back (UDDS, 10 s stop, HWFET).  The trace is interpolated linearly to the 0.1 s steps
and smoothed with a Gaussian of 1.0 s.  The logged power is the battery's electrical output power
(``pwr_out_electrical_watts``: traction + auxiliaries, drawn positive).

Logger ("a CAN logger export"): columns ``Time``, ``VehSpd_kph`` (km/h, 2 decimals), ``HVBatt_Pwr_kW`` (kW, 3
decimals = 1 W), sampled instantaneously at 1 Hz (``none_10hz``: 10 Hz, written gzipped), white noise: speed 0.1 km/h, power 250 W
(seeded).  Cases set through FASTSim's own inputs:

* ``none`` (UDDS), ``none_2`` (HWFET), ``none_10hz`` (UDDS + HWFET at 10 Hz): the published vehicle;
* ``payload`` (UDDS): ``mass_kilograms`` + 250 kg (two passengers and luggage);
* ``aux`` (UDDS + HWFET): ``pwr_aux_base_watts`` + 1200 W (cabin heating);
* ``latency_2`` (UDDS): the power channel two samples (2 s) late against the speed;
* ``grade`` (UDDS): a constant +2 % road grade (FASTSim's cycle ``grade`` = 0.02, a long climb);
* ``payload_2`` (UDDS + HWFET): ``mass_kilograms`` + 250 kg;
* ``grade_hill`` (UDDS): a hill: +3 % over the first third of the trace's distance, flat, -3 % over the last third
  (the grade set per 0.1 s step from the trace's distance; ``grade_distance_m`` in the truth: where each part
  starts).

The user's nominals, from the vehicle's data (FASTSim's mass, frontal area, drag and rolling coefficients, wheel
radius and inertia; 8.19 gear, 80 kW / 254 N.m; 250 W accessories):

* ``vehicle_trial40_leaf_nominal.toml``: the published motor efficiency curve (FASTSim's ``eff_interp_achieved``
  against the fraction of rated power, read as a linear curve) x 0.98 transmission, as a speed-torque map
  ``vehicle_trial40_leaf_eff_curve.csv``;
* ``vehicle_trial40_leaf_nominal_const.toml``: a constant drive efficiency of 0.88 (a spec-sheet guess),
  ``vehicle_trial40_leaf_eff_const88.csv``.

``vehicle_trial40_leaf_truth.json``: per case the seed, cycle, FASTSim's mass, auxiliary power, grade and latency,
in the calibration's terms (``mass_kg``, ``aux_power_w``, ``time_shift_s`` (power late, s), ``grade_frac``,
``grade_distance_m``).
"""
from __future__ import annotations

import gzip
import json
import os
from pathlib import Path

import fastsim as fsim
import numpy as np

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))
PRE = "vehicle_trial40_leaf"
RES = "2016 Nissan Leaf 30 kWh thrml.yaml"
H, SMOOTH = 0.1, 1.0
GEAR, TPK = 8.19, 254.0
NOISE = {"speed_kmh": 0.1, "power_w": 250.0}
CASES = {"none": {"seed": 4101, "cyc": ["udds.csv"]},
         "none_2": {"seed": 4102, "cyc": ["hwfet.csv"]},
         "none_10hz": {"seed": 4103, "cyc": ["udds.csv", "hwfet.csv"], "dt_s": 0.1},
         "payload": {"seed": 4104, "cyc": ["udds.csv"], "dmass": 250.0},
         "aux": {"seed": 4105, "cyc": ["udds.csv", "hwfet.csv"], "daux": 1200.0},
         "latency_2": {"seed": 4106, "cyc": ["udds.csv"], "lag_s": 2.0},
         "grade": {"seed": 4107, "cyc": ["udds.csv"], "grade": 0.02},
         "payload_2": {"seed": 4108, "cyc": ["udds.csv", "hwfet.csv"], "dmass": 250.0},
         "grade_hill": {"seed": 4109, "cyc": ["udds.csv"], "hill": [0.03, 0.0, -0.03]}}


def cycle(names):
    tt, vv = [], []
    t0 = 0.0
    for n in names:
        c = fsim.Cycle.from_resource(n).to_dict()
        a, b = np.asarray(c["time_seconds"], float), np.asarray(c["speed_meters_per_second"], float)
        tt.append(a + t0)
        vv.append(b)
        t0 = tt[-1][-1] + 10.0
    tt, vv = np.concatenate(tt), np.concatenate(vv)
    t = np.round(np.arange(0.0, tt[-1] + 1e-9, H), 10)
    sig = SMOOTH / H
    k = np.arange(-int(4 * sig), int(4 * sig) + 1) * 1.0
    w = np.exp(-0.5 * (k / sig) ** 2)
    v = np.maximum(np.convolve(np.pad(np.interp(t, tt, vv), k.size // 2, mode="edge"), w / w.sum(), mode="valid"), 0.0)
    return t, v


def vehicle_dict(case):
    d = fsim.Vehicle.from_resource(RES).to_dict()
    d["cabin"] = "None"
    d["hvac"] = "None"
    d["pt_type"]["BEV"]["res"]["thrml"] = "None"
    d["mass_kilograms"] = d["mass_kilograms"] + case.get("dmass", 0.0)
    d["pwr_aux_base_watts"] = d["pwr_aux_base_watts"] + case.get("daux", 0.0)
    return d


def grade_of(case, t, v):
    """The road grade at each step: constant, or a hill by thirds of the trace's distance."""
    if "hill" not in case:
        return np.full(t.size, case.get("grade", 0.0)), None
    x = np.concatenate([[0.0], np.cumsum(v[:-1] * H)])
    edges = x[-1] * np.array([1 / 3, 2 / 3])
    return np.asarray(case["hill"])[np.searchsorted(edges, x, side="right")], [0.0, float(edges[0]), float(edges[1])]


def run(case):
    t, v = cycle(case["cyc"])
    gr, _ = grade_of(case, t, v)
    cyc = fsim.Cycle.from_dict({"time_seconds": t.tolist(), "speed_meters_per_second": v.tolist(),
                                "grade": gr.tolist()})
    d = vehicle_dict(case)
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
    teff = float(d["pt_type"]["BEV"]["transmission"]["eff_interp"])
    ws, tq = np.linspace(0, 1100.0, 23), np.linspace(-TPK, TPK, 25)
    rows = ["# 2016 Nissan Leaf 30 kWh: 80 kW, 254 N.m", "speed_radps,peak_torque_nm,cont_torque_nm"]
    rows += [f"{a:.3f},{min(TPK, pmax / a) if a > 0 else TPK:.3f},{min(TPK, pmax / a) if a > 0 else TPK:.3f}" for a in ws]
    (OUT / f"{PRE}_torque.csv").write_text("\n".join(rows) + "\n")
    g = np.asarray(em["eff_interp_achieved"]["data"]["grid"][0]["data"])
    vals = np.asarray(em["eff_interp_achieved"]["data"]["values"]["data"])
    rows = [f"# 2016 Nissan Leaf: published motor curve (vs fraction of rated power, linear) x {teff} transmission",
            "speed_radps,torque_nm,efficiency_frac"]
    rows += [f"{a:.3f},{b:.3f},{float(np.interp(min(abs(a * b) / pmax, 1.0), g, vals)) * teff:.5f}" for a in ws for b in tq]
    (OUT / f"{PRE}_eff_curve.csv").write_text("\n".join(rows) + "\n")
    rows = ["# 2016 Nissan Leaf: constant drive efficiency 0.88 (a spec-sheet guess)", "speed_radps,torque_nm,efficiency_frac"]
    rows += [f"{a:.3f},{b:.3f},0.88" for a in ws for b in tq]
    (OUT / f"{PRE}_eff_const88.csv").write_text("\n".join(rows) + "\n")
    base = ["[params]", f"mass_kg = {float(d['mass_kilograms']):.1f}",
            f"frontal_area_m2 = {ch['frontal_area_square_meters']:.4f}", f"drag_coefficient = {ch['drag_coef']}",
            f"rolling_coefficient = {ch['wheel_rr_coef']:.5f}", f"wheel_radius_m = {ch['wheel_radius_meters']}",
            f"wheel_inertia_kg_m2 = {ch['wheel_inertia_kilogram_square_meters'] * ch['num_wheels']:.3f}",
            "aux_power_w = 250.0", "air_density_kg_m3 = 1.2", f"gear_ratio = {GEAR}",
            f"rated_power_w = {pmax:.0f}", f"maps_rated_power_w = {pmax:.0f}", f'torque_curves_file = "{PRE}_torque.csv"']
    (OUT / f"{PRE}_nominal.toml").write_text("\n".join(
        ["[meta]", 'source = "2016 Nissan Leaf 30 kWh; FASTSim published motor curve x 0.98 transmission"'] + base
        + [f'efficiency_map_file = "{PRE}_eff_curve.csv"']) + "\n")
    (OUT / f"{PRE}_nominal_const.toml").write_text("\n".join(
        ["[meta]", 'source = "2016 Nissan Leaf 30 kWh spec sheet; constant 0.88 drive efficiency"'] + base
        + [f'efficiency_map_file = "{PRE}_eff_const88.csv"']) + "\n")


def main():
    truth = {"generator": f"FASTSim {fsim.__version__} {RES}", "noise": NOISE,
             "columns": {"time_s": "Time", "speed_mps": "VehSpd_kph (km/h)", "power_w": "HVBatt_Pwr_kW (kW, drawn positive)"},
             "cases": {}}
    nominal(vehicle_dict({}))
    for name, case in CASES.items():
        t, va, p, met, d = run(case)
        rng = np.random.default_rng(case["seed"])
        dt = case.get("dt_s", 1.0)
        step = int(round(dt / H))
        ts = t[::step]
        lag = case.get("lag_s", 0.0)
        pl = np.interp(ts - lag, t, p, left=p[0])
        sp = np.maximum(va[::step] * 3.6 + rng.normal(0, NOISE["speed_kmh"], ts.size), 0.0)
        pw = (pl + rng.normal(0, NOISE["power_w"], ts.size)) / 1000.0
        lines = [f"# FASTSim {fsim.__version__} {RES} case {name} (tests/data/independent/make_vehicle_fastsim_trial40.py)",
                 "Time,VehSpd_kph,HVBatt_Pwr_kW"]
        lines += [f"{a:.1f},{b:.2f},{c:.3f}" for a, b, c in zip(ts, sp, pw)]
        fname = f"{PRE}_{name}.csv" + (".gz" if dt < 1.0 else "")      # the 10 Hz record gzipped (mtime 0: reproducible)
        text = ("\n".join(lines) + "\n").encode()
        (OUT / fname).write_bytes(gzip.compress(text, mtime=0) if dt < 1.0 else text)
        truth["cases"][name] = {**case, "file": fname, "cycle_met": met, "dt_s": dt,
                                "truth": {"mass_kg": float(d["mass_kilograms"]),
                                          "aux_power_w": float(d["pwr_aux_base_watts"]), "time_shift_s": lag,
                                          "grade_frac": case.get("hill", case.get("grade", 0.0)),
                                          "grade_distance_m": grade_of(case, *cycle(case["cyc"]))[1]},
                                "power_rms_w": float(np.sqrt(np.mean(p * p))), "p_min_w": float(p.min()),
                                "p_max_w": float(p.max()), "distance_m": float(np.sum(va) * H)}
        print(name, met, f"rms {np.sqrt(np.mean(p * p)):.0f} W  min {p.min():.0f} max {p.max():.0f}", flush=True)
    truth["cases"]["none_const"] = dict(truth["cases"]["none"], nominal=f"{PRE}_nominal_const.toml")
    (OUT / f"{PRE}_truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
