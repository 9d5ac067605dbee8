"""Vehicle records for the calibration tests, made by FASTSim 3 (not by shevsim).

Run with a Python that has FASTSim 3 (``benchmarks/.venv-fastsim``, created by ``benchmarks/vs_fastsim.py``):

    benchmarks/.venv-fastsim/bin/python tests/data/independent/make_vehicle_fastsim.py [--vehicle zoe|m3|all]

(default ``all``: both vehicles; the Zoe's files are what they were before the second vehicle came, byte for
byte).  Each vehicle of :data:`VEHICLES` has its own FASTSim resource, cases, file prefix and published
nominal; the Zoe's are described first, the Tesla Model 3's (a vehicle the calibration was not developed on)
after them.

FASTSim's own vehicle model (``2022_Renault_Zoe_ZE50_R135.yaml``, a battery-electric car: its motor
efficiency curve, transmission efficiency, wheel inertia, air density at the cycle's elevation) and its own
time stepping (0.1 s) drive the HD-UDDS speed trace (first 700 s, interpolated linearly to the 0.1 s
steps and smoothed there with a Gaussian of ``SMOOTH_S`` = 1.5 s - a car driver's acceleration rather than
the truck cycle's 1 Hz steps; on the raw cycle the 1 Hz sampling alone leaves a 1.8 kW error in any model
that sees only the 1 Hz speed).  The smoothing is done at the 0.1 s steps, not on the 1 Hz samples
followed by a cubic through them: a cubic through 1 Hz knots (PCHIP, the first version of this script)
has its acceleration tied to the knots - lower at them (their slope is the harmonic mean of the two
secants), higher half-way - and the knots fall on the logger's sample times, so a record read half-way
between them (the power channel of ``shift_half``/``payload_shift``, 0.5 s late) saw systematically higher
inertial power: the same payload trace logged at the knots or half-way gave a mass +1..4 % or +9..11 %
(docs/calibration_independent.md).  A vehicle's speed has no structure locked to the logger's clock.
A logger then samples the speed and the battery's electrical output power
(``res.pwr_out_electrical_watts``: traction + auxiliaries, drawn positive) **at 1 Hz, instantaneously**
(every 10th step), adds white sensor noise (speed 0.02 m/s, power 100 W, seeded) and writes
``vehicle_<case>.csv``.  The effects are set through FASTSim's own inputs:

* ``none``: the published vehicle;
* ``payload``: ``mass_kilograms`` 1600 -> 1950 kg;
* ``aux``: ``pwr_aux_base_watts`` 250 -> 2250 W (HVAC);
* ``grade``: the cycle's ``grade`` 0 -> ``0.03 sin(2 pi d / D)`` along the distance ``d`` (``D`` the trace's
  distance: a hill up, then down; a constant grade is indistinguishable from rolling resistance);
* ``shift_half``: the ``none`` vehicle, the power channel logged 0.5 s late (CAN latency of half a sample);
* ``latency_2``: the ``none`` vehicle, the power channel logged 2 s late;
* ``payload_shift``: the ``payload`` vehicle (1950 kg), the power channel logged 0.5 s late (an effect and a
  timing artefact in one record);
* ``regen_limit``: the electrical regenerative power at most 6 kW (the published vehicle regenerates up to
  17 kW on this trace).  FASTSim 3.1's battery-electric vehicle has no regeneration-only power limit
  (``ReversibleEnergyStorage::set_pwr_charge_max``: the charge limit is the battery's ``pwr_out_max``, the
  number that also limits discharge; ``ElectricMachine::set_curr_pwr_prop_out_max``: the machine's
  ``pwr_out_max`` both ways; the cycle's ``pwr_max_chrg`` is read and never used), but its machine
  efficiency curve may cover the signed power fraction [-1, 1]: the regenerative half is set so that the
  machine's electrical output saturates at the limit (:func:`_limit_regen`; beyond it the braking power is
  lost in the machine where a real drive would hand it to the friction brakes - the logged electrical
  power is the same).  Truth: motor ``regen_power_max_w`` = 6000 W;
* ``none_2``, ``none_3``, ``none_4``: no effect, on HD-UDDS from its first standstill after 300 s, the Orange County bus cycle and the
  WVU interstate cycle (first 700 s), other noise seeds (the false-selection rate).

The user's nominal (``vehicle_nominal.toml``, the calibration's ``--params``) is the published data of
that vehicle in shevsim's terms: mass, frontal area, drag and rolling coefficients, wheel radius, the
wheels' rotating inertia (``wheel_inertia_kg_m2`` = FASTSim's per-wheel
``wheel_inertia_kilogram_square_meters`` x ``num_wheels``, read from the file: 4 x 0.815 kg m2, an equivalent
mass J / r^2 of 33.8 kg, which FASTSim books as ``pwr_whl_inertia``; added to the nominal after the records
were made - the records and the truth's cases are unchanged), base auxiliary load, a single-speed gear of
9.3, and the motor's published efficiency curve (FASTSim's
``eff_interp_achieved`` over output-power fraction, times the transmission's 0.92) written as a
speed x torque map (``zoe_motor_eff_map.csv``) with a 245 N.m / 100 kW torque curve
(``zoe_motor_torque_curves.csv``).

``vehicle_truth.json`` holds, per case, the FASTSim inputs, the seed and the truth in shevsim's names
(``mass_kg``, ``aux_power_w``, ``grade_frac``, ``time_shift_s``), and the user's nominal (``known``: the
published vehicle data a user has; the calibration's ``--params``).

**Second vehicle: the Tesla Model 3 RWD** (``--vehicle m3``; FASTSim's ``2022 Tesla Model 3 RWD thrml.yaml``,
1752 kg, C_d 0.23, 2.22 m2, rolling 0.007, wheel radius 0.334 m, a 239 kW machine and a 0.98 transmission),
driven by cycles the Zoe's records do not use (FASTSim's own ``udds.csv`` and ``hwfet.csv`` resources, the
same linear-to-0.1 s + 1.5 s Gaussian treatment, 700 s from a standstill), logged in the same way (1 Hz
instantaneous, 0.02 m/s and 100 W noise).  Files ``vehicle_m3_<case>.csv``, ``vehicle_m3_truth.json``,
``vehicle_m3_nominal.toml``, ``m3_motor_eff_map.csv``, ``m3_motor_torque_curves.csv``.

* The ``thrml`` variant carries a cabin, an HVAC controller and a battery thermal model, whose HVAC power is
  an auxiliary load that varies with the cabin's and the battery's temperatures.  They are **switched off**
  in FASTSim's inputs (``cabin``, ``hvac`` and the battery's ``thrml`` set to none, as in the Zoe's file):
  the record's auxiliary load is then the vehicle's constant ``pwr_aux_base_watts``, the truth is one
  number, and the records test the vehicle calibration, not a cabin model shevsim does not have.  (Measured:
  with them on, the ``none`` record's power history is the same to the watt - the cycles' 22 degC ambient is
  the cabin's set point, so the HVAC draws nothing here; off, the truth does not rest on that.)
* Cases: ``none`` (UDDS 0-700 s), ``payload`` (1752 -> 2150 kg, +22.7 %), ``aux`` (250 -> 2250 W),
  ``latency_2`` (the ``none`` vehicle, power logged 2 s late), ``none_2`` (HWFET, the highway cycle,
  0-700 s; another seed).
* The nominal: the file's chassis numbers (wheel inertia too: 4 x 0.815 kg m2, 29.2 kg equivalent at its
  0.334 m radius), its 250 W base auxiliary load, the machine's published
  efficiency curve (``eff_interp_achieved`` over output-power fraction, read linearly between its points as
  a user reading a published curve would, times the transmission's 0.98) as a speed x torque map, a single
  gear of 9.036 (Tesla's published reduction ratio of the Model 3's rear drive unit) and a 420 N.m / 239 kW
  torque curve (the machine's power from the file; 420 N.m the commonly cited peak torque of the 2021-22
  RWD, which the file does not give; the trace never asks for more than a third of it).  FASTSim's file
  declares its curve with a ``Step: Lower`` interpolation (the Zoe's: ``Linear``): FASTSim reads the
  efficiency at the grid point below, up to 0.02 lower than the linear reading at light load - a
  difference of form between the user's published curve and the record's physics, kept as such.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import fastsim as fsim

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
VEHICLE = "2022_Renault_Zoe_ZE50_R135.yaml"
DURATION_S = 700.0
H_S = 0.1
SMOOTH_S = 1.5
NOISE = {"speed_mps": 0.02, "power_w": 100.0}
CASES = {
    "none": {"seed": 11},
    "payload": {"seed": 12, "mass_kilograms": 1950.0},
    "aux": {"seed": 13, "pwr_aux_base_watts": 2250.0},
    "grade": {"seed": 14, "grade_amplitude": 0.03},
    "shift_half": {"seed": 15, "lag_s": 0.5},
    "latency_2": {"seed": 16, "lag_s": 2.0},
    # more no-effect records (the false-selection rate): another window, other cycles, other noise
    "none_2": {"seed": 17, "start_s": 300.0},
    "none_3": {"seed": 18, "cycle": "orange_county_bus.csv"},
    "none_4": {"seed": 19, "cycle": "wvu_interstate.csv"},
    # an effect and a timing artefact together (review): the payload vehicle, the power channel 0.5 s late
    "payload_shift": {"seed": 20, "mass_kilograms": 1950.0, "lag_s": 0.5},
    # regenerative power limited to 6 kW electrical through the machine's efficiency curve (module docstring)
    "regen_limit": {"seed": 21, "regen_max_elec_watts": 6000.0},
}
# the second vehicle (module docstring): FASTSim's own UDDS and HWFET resources, from 0 s
CASES_M3 = {
    "none": {"seed": 31, "fastsim_cycle": "udds.csv"},
    "payload": {"seed": 32, "fastsim_cycle": "udds.csv", "mass_kilograms": 2150.0},
    "aux": {"seed": 33, "fastsim_cycle": "udds.csv", "pwr_aux_base_watts": 2250.0},
    "latency_2": {"seed": 34, "fastsim_cycle": "udds.csv", "lag_s": 2.0},
    "none_2": {"seed": 35, "fastsim_cycle": "hwfet.csv"},
}
#: vehicle -> FASTSim resource, cases, file names and the published data FASTSim's file does not hold
VEHICLES = {
    "zoe": {"resource": VEHICLE, "label": "Renault Zoe ZE50 R135", "cases": CASES, "record": "vehicle_",
            "truth": "vehicle_truth.json", "nominal": "vehicle_nominal.toml", "motor": "zoe_motor_",
            "gear": 9.3, "t_peak_nm": 245.0, "w_max_radps": 1150.0, "thermal_off": False,
            "trace": "HD-UDDS 0-700 s"},
    "m3": {"resource": "2022 Tesla Model 3 RWD thrml.yaml", "label": "Tesla Model 3 RWD 2022", "cases": CASES_M3,
           "record": "vehicle_m3_", "truth": "vehicle_m3_truth.json", "nominal": "vehicle_m3_nominal.toml",
           "motor": "m3_motor_", "gear": 9.036, "t_peak_nm": 420.0, "w_max_radps": 1900.0, "thermal_off": True,
           "trace": "FASTSim's UDDS and HWFET 0-700 s"},
}


def _limit_regen(em: dict, p_lim_w: float) -> None:
    """FASTSim's machine efficiency curve over the signed output-power fraction, its regenerative half set so
    that the electrical regenerative power is at most ``p_lim_w`` (module docstring).

    Published curve: ``eff(x)`` on ``x`` = output / rated power in [0, 1]; FASTSim 3 reads it at
    ``max(x, 0)`` when the grid starts at 0 (every regenerative point at ``eff(0)`` = ``e0``) and at the
    signed ``x`` when the grid starts below 0 (``ElectricMachine::get_pwr_in_req``; ``init`` accepts
    [-1, 1]).  Here ``eff(x) = e0`` for ``-x0 <= x < 0`` (as the published vehicle regenerates) and
    ``e0 x0 / |x|`` below ``-x0 = -p_lim_w / (e0 P_rated)``: FASTSim's electrical power
    ``pwr_elec_prop_in = pwr_mech_prop_out * eff`` is then ``-p_lim_w`` for any harder braking.
    """
    data = em["eff_interp_achieved"]["data"]
    g = [float(x) for x in data["grid"][0]["data"]]
    v = [float(x) for x in data["values"]["data"]]
    e0, p_rated = v[0], float(em["pwr_out_max_watts"])
    x0 = p_lim_w / (e0 * p_rated)
    xs = -np.geomspace(1.0, x0, 300)                       # -1 .. -x0, dense where 1/|x| bends
    grid = [float(x) for x in xs] + [-0.5 * x0] + g
    vals = [float(e0 * x0 / abs(x)) for x in xs] + [e0] + v
    data["grid"][0]["data"], data["grid"][0]["dim"] = grid, [len(grid)]
    data["values"]["data"], data["values"]["dim"] = vals, [len(vals)]
    em.pop("eff_interp_at_max_input", None)                 # derived from the curve at init


def _fastsim_cycle(name: str) -> np.ndarray:
    """One of FASTSim's own cycle resources as (time [s], speed [m/s]) rows."""
    c = fsim.Cycle.from_resource(name)
    c = c.to_dict() if hasattr(c, "to_dict") else c.to_pydict()
    return np.column_stack([np.asarray(c["time_seconds"], float), np.asarray(c["speed_meters_per_second"], float)])


def _thermal_off(d: dict) -> None:
    """No cabin, no HVAC, no battery thermal model (the ``thrml`` files' varying HVAC load; module docstring)."""
    d["cabin"] = "None"          # FASTSim's own variant name, as the Zoe's file reads back
    d["hvac"] = "None"
    d["pt_type"]["BEV"]["res"]["thrml"] = "None"


def regen_ratios(d: dict, vh: dict) -> tuple[float, float]:
    """The drive's generating / motoring efficiency ratio on a run, from FASTSim's machine history: the machine
    regenerates at ``P_elec / P_mech`` (0.84 on both vehicles: its curve's zero-power point) where the published
    curve ``c(x)`` (the user's map) gives ``c`` at the output fraction ``x``.  Returns the energy-weighted ratio
    ``0.84 / (sum(c |P_mech|) / sum(|P_mech|))`` and the least-squares one ``sum(c P_elec P_mech) / sum((c
    P_mech)^2)`` (what a fit of one constant ratio to the power record estimates) over the regenerative steps."""
    em = d["pt_type"]["BEV"]["em"]
    data = em["eff_interp_achieved"]["data"]
    grid, vals = np.asarray(data["grid"][0]["data"], float), np.asarray(data["values"]["data"], float)
    h = vh["pt_type"]["BEV"]["em"]["history"]
    pm, pe = np.asarray(h["pwr_mech_prop_out_watts"], float), np.asarray(h["pwr_elec_prop_in_watts"], float)
    r = pm < -1.0
    if not r.any():
        return float("nan"), float("nan")
    c = np.interp(np.abs(pm[r]) / float(em["pwr_out_max_watts"]), grid, vals)
    e0 = float(np.median(pe[r] / pm[r]))
    return (e0 / float(np.sum(c * -pm[r]) / np.sum(-pm[r])),
            float(np.sum(c * pe[r] * pm[r]) / np.sum((c * pm[r]) ** 2)))


def run_case(case: dict, veh_spec: dict | None = None):
    veh_spec = veh_spec or VEHICLES["zoe"]
    if "fastsim_cycle" in case:
        cyc_raw = _fastsim_cycle(case["fastsim_cycle"])
    else:
        cyc_raw = np.loadtxt(ROOT / "cycles" / case.get("cycle", "hd_udds.csv"), delimiter=",", skiprows=1, comments="#")
    t0 = float(case.get("start_s", 0.0))
    t0 = float(cyc_raw[(cyc_raw[:, 0] >= t0) & (cyc_raw[:, 1] <= 0.0), 0][0])     # from a standstill
    t1 = cyc_raw[(cyc_raw[:, 0] >= t0) & (cyc_raw[:, 0] <= t0 + DURATION_S)].copy()
    t1[:, 0] -= t0
    t = np.round(np.arange(0.0, DURATION_S + 1e-9, H_S), 10)
    # the cycle's 1 Hz trace to the 0.1 s steps (linear), then the Gaussian at the 0.1 s steps: no structure
    # of the trace is tied to the 1 Hz knots (module docstring)
    sig = SMOOTH_S / H_S
    k = np.arange(-int(4 * sig), int(4 * sig) + 1) * 1.0
    w = np.exp(-0.5 * (k / sig) ** 2)
    v_lin = np.interp(t, t1[:, 0], t1[:, 1])
    v = np.maximum(np.convolve(np.pad(v_lin, k.size // 2, mode="edge"), w / w.sum(), mode="valid"), 0.0)
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * H_S)])
    grade = float(case.get("grade_amplitude", 0.0)) * np.sin(2.0 * np.pi * dist / dist[-1])
    cd = {"time_seconds": t.tolist(), "speed_meters_per_second": v.tolist(), "grade": grade.tolist()}
    cyc = fsim.Cycle.from_dict(cd) if hasattr(fsim.Cycle, "from_dict") else fsim.Cycle.from_pydict(cd)
    veh = fsim.Vehicle.from_resource(veh_spec["resource"])
    d = veh.to_dict() if hasattr(veh, "to_dict") else veh.to_pydict()
    if veh_spec["thermal_off"]:
        _thermal_off(d)
    for k in ("mass_kilograms", "pwr_aux_base_watts"):
        if k in case:
            d[k] = case[k]
    if "regen_max_elec_watts" in case:
        _limit_regen(d["pt_type"]["BEV"]["em"], float(case["regen_max_elec_watts"]))
    veh = fsim.Vehicle.from_dict(d) if hasattr(fsim.Vehicle, "from_dict") else fsim.Vehicle.from_pydict(d)
    sd = fsim.SimDrive(veh, cyc)
    sd.walk()
    out = sd.to_dict() if hasattr(sd, "to_dict") else sd.to_pydict()
    vh = out["veh"]
    p = np.asarray(vh["pt_type"]["BEV"]["res"]["history"]["pwr_out_electrical_watts"], float)
    va = np.asarray(vh["history"]["speed_ach_meters_per_second"], float)
    met = bool(all(vh["history"]["cyc_met"]))
    run_case.regen_ratios = regen_ratios(d, vh)       # printed by make(); not in the records
    return t, va, p, met, d, dist


def write_nominal(d: dict, veh_spec: dict | None = None) -> dict:
    """The user's nominal: the published vehicle in shevsim's parameter names, its motor maps as CSV."""
    vs = veh_spec or VEHICLES["zoe"]
    label, t_peak, gear, mot = vs["label"], vs["t_peak_nm"], vs["gear"], vs["motor"]
    ch, bev = d["chassis"], d["pt_type"]["BEV"]
    em = bev["em"]["eff_interp_achieved"]["data"]
    grid, vals = np.asarray(em["grid"][0]["data"]), np.asarray(em["values"]["data"])
    eta_tr = float(bev["transmission"]["eff_interp"])
    p_max = float(bev["em"]["pwr_out_max_watts"])
    w_max = vs["w_max_radps"]
    ws = np.linspace(0.0, w_max, 24)
    tq = np.linspace(-t_peak, t_peak, 41)
    rows = [f"# {label} drive (motor + transmission) efficiency from FASTSim's published curve",
            f"# eff(|P|/P_max) x transmission {eta_tr} (P_max {p_max:.0f} W); make_vehicle_fastsim.py",
            "speed_radps,torque_nm,efficiency_frac"]
    for w in ws:
        for q in tq:
            frac = min(abs(q * w) / p_max, 1.0)
            rows.append(f"{w:.4f},{q:.4f},{float(np.interp(frac, grid, vals)) * eta_tr:.5f}")
    (HERE / f"{mot}eff_map.csv").write_text("\n".join(rows) + "\n")
    rows = [f"# {label}: {t_peak:.0f} N.m up to {p_max / 1000.0:.0f} kW (published); continuous = peak",
            "speed_radps,peak_torque_nm,cont_torque_nm"]
    for w in ws:
        t = t_peak if w <= 0 else min(t_peak, p_max / w)
        rows.append(f"{w:.4f},{t:.4f},{t:.4f}")
    (HERE / f"{mot}torque_curves.csv").write_text("\n".join(rows) + "\n")
    known = {"mass_kg": float(d["mass_kilograms"]), "frontal_area_m2": float(ch["frontal_area_square_meters"]),
             "drag_coefficient": float(ch["drag_coef"]), "rolling_coefficient": float(ch["wheel_rr_coef"]),
             "wheel_radius_m": float(ch["wheel_radius_meters"]),
             # all wheels' rotating inertia: FASTSim's per-wheel value x its wheel count (module docstring)
             "wheel_inertia_kg_m2": float(ch["wheel_inertia_kilogram_square_meters"]) * int(ch["num_wheels"]),
             "aux_power_w": float(d["pwr_aux_base_watts"]), "air_density_kg_m3": 1.2, "gear_ratio": gear}
    note = {"wheel_inertia_kg_m2": f"  # all wheels: FASTSim's chassis {int(ch['num_wheels'])} x "
                                   f"{float(ch['wheel_inertia_kilogram_square_meters'])!r} kg m2 "
                                   "(wheel_inertia_kilogram_square_meters x num_wheels)"}
    lines = ["[meta]", f'source = "published {label} data (FASTSim resource); make_vehicle_fastsim.py"',
             "[params]"] + [f"{k} = {v!r}{note.get(k, '')}" for k, v in known.items()]
    lines += [f'efficiency_map_file = "{mot}eff_map.csv"', f'torque_curves_file = "{mot}torque_curves.csv"']
    (HERE / vs["nominal"]).write_text("\n".join(lines) + "\n")
    return known


def make(vehicle: str) -> None:
    vs = VEHICLES[vehicle]
    gen = (f"FASTSim {fsim.__version__}, vehicle {vs['resource']}, {vs['trace']} (linear to {H_S} s, Gaussian {SMOOTH_S} s), "
           f"step {H_S} s, logged at 1 Hz instantaneous")
    if vehicle == "zoe":      # the Zoe's words as they were (its records byte-identical)
        gen = (f"FASTSim {fsim.__version__}, vehicle {VEHICLE}, HD-UDDS 0-{DURATION_S:.0f} s (linear to {H_S} s, Gaussian {SMOOTH_S} s), "
               f"step {H_S} s, logged at 1 Hz instantaneous")
    if vs["thermal_off"]:
        gen += "; cabin, HVAC and battery thermal models switched off (constant auxiliary load)"
    truth = {"generator": gen, "noise": NOISE, "cases": {}}
    known = None
    for name, case in vs["cases"].items():
        t, va, p, met, d, dist = run_case(case, vs)
        if known is None:
            known = write_nominal(d, vs)
        rng = np.random.default_rng(case["seed"])
        step = int(round(1.0 / H_S))
        ts = t[::step]
        lag = float(case.get("lag_s", 0.0))
        p_log = np.interp(ts - lag, t, p, left=p[0])          # the power channel read lag_s late
        speed = np.maximum(va[::step] + rng.normal(0.0, NOISE["speed_mps"], ts.size), 0.0)
        power = p_log + rng.normal(0.0, NOISE["power_w"], ts.size)
        lines = [f"# FASTSim {fsim.__version__} record, case '{name}' (make_vehicle_fastsim.py; truth in {vs['truth']})",
                 "time_s,speed_mps,power_w"]
        lines += [f"{a:.1f},{b:.4f},{c:.1f}" for a, b, c in zip(ts, speed, power)]
        if vehicle != "zoe":
            lines[0] = lines[0].replace(f"case '{name}'", f"{vs['label']}, case '{name}'")
        (HERE / f"{vs['record']}{name}.csv").write_text("\n".join(lines) + "\n")
        tr = {"mass_kg": float(case.get("mass_kilograms", known["mass_kg"])),
              "aux_power_w": float(case.get("pwr_aux_base_watts", known["aux_power_w"])),
              "grade_amplitude_frac": float(case.get("grade_amplitude", 0.0)), "distance_m": float(dist[-1]),
              "time_shift_s": lag}
        if "regen_max_elec_watts" in case:       # the drive's electrical regenerative limit (motor regen_power_max_w)
            tr["regen_power_max_w"] = float(case["regen_max_elec_watts"])
        truth["cases"][name] = {"fastsim_inputs": {k: v for k, v in case.items() if k != "seed"}, "seed": case["seed"],
                                "truth": tr, "cycle_met": met, "file": f"{vs['record']}{name}.csv",
                                "power_rms_w": float(np.sqrt(np.mean(p * p)))}
        ew, ls = run_case.regen_ratios
        print(vehicle, name, "cycle met" if met else "CYCLE NOT MET", f"power rms {np.sqrt(np.mean(p * p)):.0f} W",
              f"generating/motoring ratio {ew:.4f} (energy-weighted), {ls:.4f} (least squares)")
    truth["known"] = known
    (HERE / vs["truth"]).write_text(json.dumps(truth, indent=2) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="FASTSim 3 vehicle records (module docstring)")
    ap.add_argument("--vehicle", choices=sorted(VEHICLES) + ["all"], default="all")
    a = ap.parse_args(argv)
    for v in (sorted(VEHICLES, reverse=True) if a.vehicle == "all" else [a.vehicle]):
        make(v)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
