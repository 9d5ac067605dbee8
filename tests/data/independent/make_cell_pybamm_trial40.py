"""Out-of-sample cell records (trial 40): PyBaMM cells the project never used, made by a new-user trial.

    python tests/data/independent/make_cell_pybamm_trial40.py Marquis2019    # PyBaMM 26.x
    python tests/data/independent/make_cell_pybamm_trial40.py ORegan2022

A helper who had not seen the calibration's development wrote this script to try ``shevsim calibrate cell`` as a
new user would, on parameter sets the project never used: ``Marquis2019`` (Kokam LCO/graphite pouch, 0.68 A.h)
and ``ORegan2022`` (LG M50 21700, NMC811/graphite-SiOx, 5 A.h).

Generator: PyBaMM's SPMe with a lumped thermal model (``{"thermal": "lumped"}``), IDAKLU solver.  Every
temperature-dependent parameter function is held at 25 degC and the entropic change is zero (the user's nominal
has neither; so the no-effect records have no Arrhenius or reversible-heat effect to find).  Voltage cut-offs
widened (+0.2 V, -0.3 V) so the drive runs through.  ``ORegan2022``'s total heat transfer coefficient is set to
30 W/(m2.K) (forced air; at PyBaMM's 10 the 21700 would heat > 20 K), a stated assumption.

The current ("drive-and-park"): a first rest of 120 s, then three drives (15, 15, 10 min) separated by parking
rests of 5 and 8 min, and a final 3 min rest (3540 s).  In a drive the current is piecewise linear between knots
2-20 s apart: 15 % zero, 25 % regen U(-1C, 0), 60 % discharge U(0, IMAX) (Marquis2019 IMAX = 2.5C, ORegan2022
1.5C).  Initial SOC 0.85 (PyBaMM's ``initial_soc``), ambient 25 degC.

Logger: the current column is charge-positive (an Arbin-style export: "Test_Time(s)", "Current(A)", "Voltage(V)",
"Aux_Temperature_1(C)", and for some records "Chamber_Temperature(C)"), white noise: voltage 0.8 mV, current 0.3 %
of 1C (2 mA Marquis2019, 15 mA ORegan2022), temperature 0.05 K; the temperature is also quantised to 0.01 K.
Sampling 1 Hz, except ``none_10hz`` (10 Hz, written gzipped: ``*_none_10hz.csv.gz``) and ``ORegan2022``'s
``none_05hz`` (0.5 Hz).  Records without the ambient column (``ambient_column`` false in the truth) are refused
by ``shevsim calibrate cell`` (a required column); the trial ran them with a constant column appended
(``awk -F, 'NR==1{print;next} NR==2{print $0",Chamber_Temperature(C)";next} {print $0",25.0"}'``).

Cases (``CASES``; seeds fix the drive and the noise):

* ``none``, ``none_2``, ``none_10hz`` (Marquis2019) / ``none``, ``none_2``, ``none_05hz`` (ORegan2022): nothing;
* ``capacity``: both electrodes' active material volume fraction x 0.88 (the drive of ``none``);
* ``current_offset``: + 3 % of 1C added to the *logged* current (in the file's charge-positive sign: the logger
  reads 0.0204 A / 0.15 A too much charge; in discharge-positive terms the offset is -0.0204 A / -0.15 A);
* ``contact_resistance``: PyBaMM's contact resistance (15 mOhm Marquis2019, 8 mOhm ORegan2022);
* ``cooling_change``: the total heat transfer coefficient x 0.4 from 2400 s (a 0.5 s sigmoid).

The user's nominal (``cell_trial40_<set>_nominal.toml``): the rated capacity (PyBaMM's nominal cell capacity), a
pseudo-OCV measured by a C/30 discharge from 100 % (SOC = 1 - discharged A.h / rated A.h, 41 points), the initial
SOC from the first rest (``soc0_frac = -1``), two RC branches, and the geometry: the 21700's real radius and length
(ORegan2022), or for the pouch a cylinder of the cell's volume and cooling surface (Marquis2019), and PyBaMM's
heat transfer coefficient.  ``cell_trial40_<set>_truth.json``: per case the seed, the inputs and the truth in the
calibration's terms (``capacity_ah``, ``current_offset_a`` discharge-positive, ``h_change_factor``,
``h_change_time_s``, ``series_resistance_added_ohm``).
"""
import gzip
import inspect
import json
import os
import sys
from pathlib import Path

import numpy as np
import pybamm

if len(sys.argv) != 2:
    raise SystemExit("usage: make_cell_pybamm_trial40.py SET   (Marquis2019 or ORegan2022)")
SET = sys.argv[1]
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))
PRE = "cell_trial40_" + SET.lower()
T_REF = 298.15
SOC0 = 0.85
CFG = {"Marquis2019": {"imax_c": 2.5, "override": {}, "contact_ohm": 0.015,
                       "fast": ("none_10hz", 0.1), "ambient_col": ["none", "capacity", "cooling_change", "none_10hz"]},
       "ORegan2022": {"imax_c": 1.5, "override": {"Total heat transfer coefficient [W.m-2.K-1]": 30.0},
                      "contact_ohm": 0.008, "fast": ("none_05hz", 2.0), "ambient_col": ["none", "cooling_change"]}}[SET]
CAP = float(pybamm.ParameterValues(SET)["Nominal cell capacity [A.h]"])
NOISE = {"voltage_v": 0.8e-3, "t_surface_c": 0.05, "current_a": 0.003 * CAP, "t_quantum_c": 0.01}
CASES = {"none": {"seed": 4001}, "none_2": {"seed": 4002}, CFG["fast"][0]: {"seed": 4003, "dt_s": CFG["fast"][1]},
         "capacity": {"seed": 4001, "am_factor": 0.88},
         "current_offset": {"seed": 4005, "offset_charge_pos_a": 0.03 * CAP},
         "contact_resistance": {"seed": 4006, "contact_ohm": CFG["contact_ohm"]},
         "cooling_change": {"seed": 4007, "h_factor": 0.4, "t_change_s": 2400.0}}


def base_params():
    p = pybamm.ParameterValues(SET)
    for k, v in CFG["override"].items():
        p[k] = v
    p["Upper voltage cut-off [V]"] = p["Upper voltage cut-off [V]"] + 0.2
    p["Lower voltage cut-off [V]"] = p["Lower voltage cut-off [V]"] - 0.3
    for k, v in list(p.items()):        # every T-dependent function held at 25 degC
        if callable(v):
            try:
                names = list(inspect.signature(v).parameters)
            except (TypeError, ValueError):
                continue
            if "T" in names:
                idx = names.index("T")
                p[k] = (lambda f, idx: lambda *a: f(*a[:idx], T_REF, *a[idx + 1:]))(v, idx)
    for e in ("Negative", "Positive"):
        p[f"{e} electrode OCP entropic change [V.K-1]"] = 0.0
    return p


def current_knots(rng):
    """1 s knots of the discharge-positive current (A): drive-and-park."""
    n = 3541
    i = np.zeros(n)
    drives = [(120, 1020), (1320, 2220), (2700, 3300)]       # rests 0-120, 1020-1320 (5 min), 2220-2700 (8 min), 3300-3540
    for a, b in drives:
        k = a
        prev = 0.0
        while k < b:
            seg = min(int(rng.uniform(2, 20)), b - k)
            nxt = rng.choice([0.0, rng.uniform(-1.0, 0.0) * CAP, rng.uniform(0.0, CFG["imax_c"]) * CAP], p=[0.15, 0.25, 0.6])
            i[k:k + seg + 1] = np.linspace(prev, nxt, seg + 1)
            prev = nxt
            k += seg
        i[b] = 0.0
        i[b - 1] = 0.5 * i[b - 2]
    return np.arange(n, dtype=float), i


def simulate(case, tk, ik, t):
    p = base_params()
    if "am_factor" in case:
        for e in ("Negative", "Positive"):
            kk = f"{e} electrode active material volume fraction"
            p[kk] = p[kk] * case["am_factor"]
    if "h_factor" in case:
        h0 = p["Total heat transfer coefficient [W.m-2.K-1]"]
        p["Total heat transfer coefficient [W.m-2.K-1]"] = h0 + (h0 * case["h_factor"] - h0) * pybamm.sigmoid(case["t_change_s"], pybamm.t, 0.5)
    opts = {"thermal": "lumped"}
    if "contact_ohm" in case:
        opts["contact resistance"] = "true"
        p["Contact resistance [Ohm]"] = case["contact_ohm"]
    p["Current function [A]"] = pybamm.Interpolant(tk, ik, pybamm.t)
    sim = pybamm.Simulation(pybamm.lithium_ion.SPMe(opts), parameter_values=p, solver=pybamm.IDAKLUSolver())
    sol = sim.solve(t_eval=[t[0], t[-1]], t_interp=t, initial_soc=SOC0)
    if sol.t.size != t.size:
        raise SystemExit(f"{SET}: PyBaMM stopped at {sol.t[-1]:.0f} s: {sol.termination}")
    return sol["Voltage [V]"].entries, sol["Volume-averaged cell temperature [C]"].entries


def pseudo_ocv():
    p = base_params()
    lo = p["Lower voltage cut-off [V]"] + 0.3
    exp = pybamm.Experiment([f"Discharge at C/30 until {lo} V (60 second period)"])
    sol = pybamm.Simulation(pybamm.lithium_ion.SPMe({"thermal": "lumped"}), parameter_values=p, experiment=exp).solve(initial_soc=1.0)
    ah = sol["Discharge capacity [A.h]"].entries
    v = sol["Voltage [V]"].entries
    soc = 1.0 - ah / CAP
    grid = np.linspace(max(soc.min(), 0.0), 1.0, 41)
    o = np.argsort(soc)
    return grid, np.interp(grid, soc[o], v[o]), float(ah[-1])


def geometry(p0):
    if SET == "ORegan2022":
        return 0.0105, 0.0704                              # the 21700: 21 mm x 70 mm
    V, A = float(p0["Cell volume [m3]"]), float(p0["Cell cooling surface area [m2]"])
    r = 2 * V / A
    return r, V / (np.pi * r * r)                          # a cylinder of the pouch's volume and cooling surface


def main():
    p0 = base_params()
    r, L = geometry(p0)
    grid, ocv, cap = pseudo_ocv()
    grid[0] = 0.0
    h = float(p0["Total heat transfer coefficient [W.m-2.K-1]"])
    nom = ["[meta]", f'source = "PyBaMM {pybamm.__version__} {SET}: rated {CAP} A.h; pseudo-OCV at C/30 (measured {cap:.4f} A.h); tests/data/independent/make_cell_pybamm_trial40.py"',
           "[params]", f"capacity_ah = {CAP}", "soc0_frac = -1.0", "rc_pairs = 2", f"radius_m = {r:.6g}", f"length_m = {L:.6g}",
           f"h_conv_w_m2k = {h}",
           "[ocv]", "soc_frac = [" + ", ".join(f"{x:.4f}" for x in grid) + "]", "ocv_v = [" + ", ".join(f"{x:.5f}" for x in ocv) + "]"]
    (OUT / f"{PRE}_nominal.toml").write_text("\n".join(nom) + "\n")
    truth = {"set": SET, "generator": f"PyBaMM {pybamm.__version__} SPMe lumped thermal", "rated_ah": CAP, "c30_ah": cap,
             "noise": NOISE, "radius_m": r, "length_m": L, "h": h, "soc0": SOC0, "current_sign_in_file": "charge-positive",
             "columns": {"time_s": "Test_Time(s)", "current_a": "Current(A)", "voltage_v": "Voltage(V)",
                         "t_surface_c": "Aux_Temperature_1(C)", "t_ambient_c": "Chamber_Temperature(C)"}, "cases": {}}
    for name, case in CASES.items():
        rng = np.random.default_rng(case["seed"])
        tk, ik = current_knots(rng)
        dt = case.get("dt_s", 1.0)
        t = np.round(np.arange(0.0, tk[-1] + 1e-9, dt), 6)
        v, temp = simulate(case, tk, ik, t)
        i_true = np.interp(t, tk, ik)
        i_log = -i_true + case.get("offset_charge_pos_a", 0.0) + rng.normal(0, NOISE["current_a"], t.size)
        v_log = v + rng.normal(0, NOISE["voltage_v"], t.size)
        ts = np.round((temp + rng.normal(0, NOISE["t_surface_c"], t.size)) / NOISE["t_quantum_c"]) * NOISE["t_quantum_c"]
        amb = name in CFG["ambient_col"]
        head = "Test_Time(s),Current(A),Voltage(V),Aux_Temperature_1(C)" + (",Chamber_Temperature(C)" if amb else "")
        lines = [f"# PyBaMM {pybamm.__version__} SPMe/{SET} case {name} (tests/data/independent/make_cell_pybamm_trial40.py)", head]
        lines += [f"{a:.1f},{b:.4f},{c:.5f},{d:.2f}" + (",25.0" if amb else "") for a, b, c, d in zip(t, i_log, v_log, ts)]
        fname = f"{PRE}_{name}.csv" + (".gz" if dt < 1.0 else "")      # the 10 Hz record gzipped (mtime 0: reproducible)
        text = ("\n".join(lines) + "\n").encode()
        (OUT / fname).write_bytes(gzip.compress(text, mtime=0) if dt < 1.0 else text)
        q = np.concatenate([[0.0], np.cumsum(0.5 * (i_true[1:] + i_true[:-1]) * np.diff(t))]) / 3600.0
        truth["cases"][name] = {**case, "file": fname, "ambient_column": amb, "dt_s": dt,
                                "truth": {"capacity_ah": CAP * case.get("am_factor", 1.0),
                                          "current_offset_a": -case.get("offset_charge_pos_a", 0.0),
                                          "h_change_factor": case.get("h_factor", 1.0),
                                          "h_change_time_s": case.get("t_change_s"),
                                          "series_resistance_added_ohm": case.get("contact_ohm", 0.0)},
                                "v": [float(v.min()), float(v.max())], "t_max_c": float(temp.max()),
                                "discharged_ah": [float(q.min()), float(q.max())], "i_rms_a": float(np.sqrt(np.mean(i_true ** 2)))}
        print(SET, name, f"V {v.min():.3f}-{v.max():.3f} Tmax {temp.max():.2f} Ah {q.max():.3f}", flush=True)
    (OUT / f"{PRE}_truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
