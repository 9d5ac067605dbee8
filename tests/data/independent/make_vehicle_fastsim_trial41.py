"""Out-of-sample vehicle records (trial 41): an electric minivan in FASTSim 3.1, made by a new-user trial.

    /work/wt24/benchmarks/.venv-fastsim/bin/python tests/data/independent/make_vehicle_fastsim_trial41.py
    (any Python with fastsim==3.1.0 and numpy)

A helper who had not seen the calibration's development wrote this script (the third out-of-sample trial) to try
``shevsim calibrate vehicle`` as a new user would.  FASTSim 3.1 ships four BEVs (Renault Zoe, Tesla Model 3,
Chevrolet Bolt, Nissan Leaf), all used by the earlier trials; its other vehicles are a conventional Ford Fusion,
two HEVs and a conventional ``2026_Chrysler_Pacifica_Select``.  The vehicle here is therefore a BEV built from
FASTSim's own parts on a body the project never used: **the Pacifica's chassis** (its drag coefficient 0.330,
frontal area 3.05 m2, rolling coefficient 0.00648, wheel radius 0.369 m, wheel inertia; a 2.4 t minivan), its
700 W base auxiliary load, a mass of the Pacifica's 2398 kg + 300 kg (battery heavier than the engine and tank it
replaces: 2698 kg), and the Bolt's BEV powertrain (its 150 kW motor and efficiency curve, 0.98 transmission,
battery with a constant 0.985 efficiency - the logged power is the battery's terminal power, which that does not
change).  Cabin, HVAC and battery thermal models off, so the auxiliary load is the constant ``pwr_aux_base_watts``.

FASTSim's own time stepping (0.1 s) on its HWFET and UDDS cycles: ``hu`` = HWFET, a 10 s stop, UDDS (2144 s);
``u`` = UDDS (1369 s).  The trace is interpolated linearly to the 0.1 s steps and smoothed with a Gaussian of
0.8 s.  The logged power is the battery's electrical output power (``pwr_out_electrical_watts``: traction +
auxiliaries, drawn positive).

Loggers ("a data-logger export": columns ``time_s``, ``speed_kmh`` (km/h, 2 decimals), ``batt_power_kw`` (kW,
3 decimals); white noise: speed 0.05 km/h, power 200 W, seeded):

* ``instantaneous`` (the default): the 0.1 s signal at the sample time;
* ``mean-ending``: both channels the mean of the 0.1 s signal over the period ending at the sample (the ten
  steps in (t - 1 s, t]; the first sample the value at 0);
* ``mean-ending-power``: the power the mean over the period ending at the sample (an energy counter read each
  second: the ten steps in (t - 1 s, t]), the speed instantaneous (a CAN snapshot);
* 2 Hz (``none_2hz``): instantaneous at 0.5 s.

Cases set through FASTSim's own inputs:

* ``none`` (hu), ``none_2`` (u): the vehicle as built;
* ``payload`` (hu): ``mass_kilograms`` + 350 kg (+13 %: five passengers and luggage);
* ``aux`` (u): ``pwr_aux_base_watts`` + 1800 W (cabin heating and a seat/rear-HVAC load);
* ``latency_2`` (hu): the power channel two samples (2 s) late against the speed;
* ``grade`` (u): a constant road grade of +1.5 % (FASTSim's cycle ``grade``);
* ``none_mean`` (hu, mean-ending), ``payload_mean`` (hu, +350 kg, mean-ending);
* ``none_2hz`` (u, 2 Hz instantaneous);
* ``none_pmean`` (hu, mean-ending-power), ``payload_pmean`` (hu, +350 kg, mean-ending-power).

The user's nominal ``vehicle_trial41_emv_nominal.toml`` from the vehicle's data: mass 2698 kg, the chassis
values above, 700 W auxiliaries, air 1.2 kg/m3, a 9.0 gear (rated 150 kW, 360 N.m: torque curves
``vehicle_trial41_emv_torque.csv``), and the published motor efficiency curve (FASTSim's ``eff_interp_achieved``
against the fraction of rated power, read as a linear curve) x 0.98 transmission as a speed-torque map
``vehicle_trial41_emv_eff_curve.csv``.  FASTSim's gear is not a parameter of its BEV (its motor works on power
alone), so the gear only sets where on the map a power lands; the map's efficiency depends on power alone.

``vehicle_trial41_emv_truth.json``: per case the seed, cycle, logger, FASTSim's mass, auxiliary power, grade and
latency in the calibration's terms (``mass_kg``, ``aux_power_w``, ``time_shift_s`` (power late, s),
``grade_frac``).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import fastsim as fsim
import numpy as np

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))
PRE = "vehicle_trial41_emv"
BODY, POWERTRAIN = "2026_Chrysler_Pacifica_Select.yaml", "2020 Chevrolet Bolt EV thrml.yaml"
DMASS_BEV = 300.0
H, SMOOTH = 0.1, 0.8
GEAR, TPK = 9.0, 360.0
NOISE = {"speed_kmh": 0.05, "power_w": 200.0}
HU, U = ["hwfet.csv", "udds.csv"], ["udds.csv"]
CASES = {"none": {"seed": 4121, "cyc": HU},
         "none_2": {"seed": 4122, "cyc": U},
         "payload": {"seed": 4123, "cyc": HU, "dmass": 350.0},
         "aux": {"seed": 4124, "cyc": U, "daux": 1800.0},
         "latency_2": {"seed": 4125, "cyc": HU, "lag_s": 2.0},
         "grade": {"seed": 4126, "cyc": U, "grade": 0.015},
         "none_mean": {"seed": 4127, "cyc": HU, "logger": "mean-ending"},
         "payload_mean": {"seed": 4128, "cyc": HU, "dmass": 350.0, "logger": "mean-ending"},
         "none_2hz": {"seed": 4129, "cyc": U, "dt_s": 0.5},
         "none_pmean": {"seed": 4130, "cyc": HU, "logger": "mean-ending-power"},
         "payload_pmean": {"seed": 4131, "cyc": HU, "dmass": 350.0, "logger": "mean-ending-power"}}


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
    d = fsim.Vehicle.from_resource(BODY).to_dict()
    b = fsim.Vehicle.from_resource(POWERTRAIN).to_dict()
    d["name"] = "electric minivan (Pacifica chassis, Bolt powertrain)"
    d["pt_type"] = b["pt_type"]
    d["pt_type"]["BEV"]["res"]["thrml"] = "None"
    d["pt_type"]["BEV"]["res"]["eff_interp"] = {"Constant": 0.985}
    d["cabin"] = "None"
    d["hvac"] = "None"
    d["mass_kilograms"] = d["mass_kilograms"] + DMASS_BEV + case.get("dmass", 0.0)
    d["pwr_aux_base_watts"] = d["pwr_aux_base_watts"] + case.get("daux", 0.0)
    return d


def run(case):
    t, v = cycle(case["cyc"])
    cyc = fsim.Cycle.from_dict({"time_seconds": t.tolist(), "speed_meters_per_second": v.tolist(),
                                "grade": np.full(t.size, case.get("grade", 0.0)).tolist()})
    d = vehicle_dict(case)
    sd = fsim.SimDrive(fsim.Vehicle.from_dict(d), cyc)
    sd.walk()
    o = sd.to_dict()["veh"]
    p = np.asarray(o["pt_type"]["BEV"]["res"]["history"]["pwr_out_electrical_watts"], float)
    va = np.asarray(o["history"]["speed_ach_meters_per_second"], float)
    return t, va, p, bool(all(o["history"]["cyc_met"])), d


def log(t, x, ts, logger, lag=0.0, power=False):
    """The logged value of the 0.1 s signal ``x`` at the sample times ``ts`` (``lag``: the channel late by it)."""
    if logger == "instantaneous" or (logger == "mean-ending-power" and not power):
        return np.interp(ts - lag, t, x, left=x[0])
    n = round(1.0 / H)                         # mean over (ts - 1 s, ts]: the n steps ending at ts
    idx = np.round(ts / H).astype(int)
    c = np.concatenate([[0.0], np.cumsum(x)])
    lo = np.maximum(idx + 1 - n, 0)
    return (c[idx + 1] - c[lo]) / (idx + 1 - lo)


def nominal(d):
    ch = d["chassis"]
    em = d["pt_type"]["BEV"]["em"]
    pmax = float(em["pwr_out_max_watts"])
    teff = float(d["pt_type"]["BEV"]["transmission"]["eff_interp"])
    ws, tq = np.linspace(0, 1100.0, 23), np.linspace(-TPK, TPK, 25)
    rows = ["# electric minivan: the Bolt's 150 kW motor, 360 N.m", "speed_radps,peak_torque_nm,cont_torque_nm"]
    rows += [f"{a:.3f},{min(TPK, pmax / a) if a > 0 else TPK:.3f},{min(TPK, pmax / a) if a > 0 else TPK:.3f}" for a in ws]
    (OUT / f"{PRE}_torque.csv").write_text("\n".join(rows) + "\n")
    g = np.asarray(em["eff_interp_achieved"]["data"]["grid"][0]["data"])
    vals = np.asarray(em["eff_interp_achieved"]["data"]["values"]["data"])
    rows = [f"# the Bolt's published motor curve (vs fraction of rated power, linear) x {teff} transmission",
            "speed_radps,torque_nm,efficiency_frac"]
    rows += [f"{a:.3f},{b:.3f},{float(np.interp(min(abs(a * b) / pmax, 1.0), g, vals)) * teff:.5f}" for a in ws for b in tq]
    (OUT / f"{PRE}_eff_curve.csv").write_text("\n".join(rows) + "\n")
    base = ["[params]", f"mass_kg = {float(d['mass_kilograms']):.1f}",
            f"frontal_area_m2 = {ch['frontal_area_square_meters']:.4f}", f"drag_coefficient = {ch['drag_coef']:.4f}",
            f"rolling_coefficient = {ch['wheel_rr_coef']:.5f}", f"wheel_radius_m = {ch['wheel_radius_meters']}",
            f"wheel_inertia_kg_m2 = {ch['wheel_inertia_kilogram_square_meters'] * ch['num_wheels']:.3f}",
            f"aux_power_w = {float(d['pwr_aux_base_watts']):.1f}", "air_density_kg_m3 = 1.2", f"gear_ratio = {GEAR}",
            f"rated_power_w = {pmax:.0f}", f"maps_rated_power_w = {pmax:.0f}", f'torque_curves_file = "{PRE}_torque.csv"',
            f'efficiency_map_file = "{PRE}_eff_curve.csv"']
    (OUT / f"{PRE}_nominal.toml").write_text("\n".join(
        ["[meta]", 'source = "electric minivan: Pacifica chassis + Bolt powertrain (FASTSim 3.1 resources); published motor curve x 0.98 transmission"']
        + base) + "\n")


def main():
    truth = {"generator": f"FASTSim {fsim.__version__} {BODY} chassis + {POWERTRAIN} BEV powertrain", "noise": NOISE,
             "columns": {"time_s": "time_s", "speed_mps": "speed_kmh (km/h)", "power_w": "batt_power_kw (kW, drawn positive)"},
             "cases": {}}
    nominal(vehicle_dict({}))
    for name, case in CASES.items():
        t, va, p, met, d = run(case)
        rng = np.random.default_rng(case["seed"])
        dt = case.get("dt_s", 1.0)
        logger = case.get("logger", "instantaneous")
        ts = np.round(np.arange(0.0, t[-1] + 1e-9, dt), 6)
        lag = case.get("lag_s", 0.0)
        pl = log(t, p, ts, logger, lag, power=True)
        sp = np.maximum(log(t, va, ts, logger) * 3.6 + rng.normal(0, NOISE["speed_kmh"], ts.size), 0.0)
        pw = (pl + rng.normal(0, NOISE["power_w"], ts.size)) / 1000.0
        lines = [(f"# FASTSim {fsim.__version__} electric minivan case {name}, logger {logger} {dt:g} s "
                  "(tests/data/independent/make_vehicle_fastsim_trial41.py)"), "time_s,speed_kmh,batt_power_kw"]
        lines += [f"{a:.1f},{b:.2f},{c:.3f}" for a, b, c in zip(ts, sp, pw)]
        fname = f"{PRE}_{name}.csv"
        (OUT / fname).write_text("\n".join(lines) + "\n")
        truth["cases"][name] = {**case, "file": fname, "cycle_met": met, "dt_s": dt, "logger": logger,
                                "truth": {"mass_kg": float(d["mass_kilograms"]),
                                          "aux_power_w": float(d["pwr_aux_base_watts"]), "time_shift_s": lag,
                                          "grade_frac": case.get("grade", 0.0)},
                                "power_rms_w": float(np.sqrt(np.mean(p * p))), "p_min_w": float(p.min()),
                                "p_max_w": float(p.max()), "distance_m": float(np.sum(va) * H)}
        print(name, met, f"rms {np.sqrt(np.mean(p * p)):.0f} W  min {p.min():.0f} max {p.max():.0f}", flush=True)
    (OUT / f"{PRE}_truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
