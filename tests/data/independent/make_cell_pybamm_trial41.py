"""Out-of-sample cell records (trial 41): PyBaMM DFN cells the project never used, made by a new-user trial.

    python tests/data/independent/make_cell_pybamm_trial41.py Ramadass2004    # PyBaMM 26.x
    python tests/data/independent/make_cell_pybamm_trial41.py OKane2022
    python tests/data/independent/make_cell_pybamm_trial41.py Ramadass2004 none capacity   # only these cases

A helper who had not seen the calibration's development wrote this script (the third out-of-sample trial) to try
``shevsim calibrate cell`` as a new user would, on a generator and parameter sets the project never used:
PyBaMM's **DFN** (the earlier trials used the SPMe) with a lumped thermal model (``{"thermal": "lumped"}``,
IDAKLU solver), on ``Ramadass2004`` (Sony 18650 LCO/graphite, 1.0 A.h) and ``OKane2022`` (LG M50 21700
NMC811/graphite, 5.0 A.h; its degradation submodels off, PyBaMM's default DFN options).

Generator settings: every temperature-dependent parameter function held at 25 degC and the entropic change zero
(the user's nominal has neither, so a no-effect record has no Arrhenius or reversible-heat effect to find).  The
voltage cut-offs widened (+0.2 V, -0.3 V) so the drive runs through.  ``Ramadass2004`` has no lumped-thermal
geometry: it is given the 18650's (radius 9 mm, length 65 mm: volume 1.654e-5 m3, cooling surface 4.185e-3 m2) and
a total heat transfer coefficient of 10 W/(m2.K) (still air; stated assumptions).  ``OKane2022``: PyBaMM's own volume and
surface, and 25 W/(m2.K) (forced air; PyBaMM's 10 lets the 21700 heat > 15 K in this drive).

The current ("commute"; 1 Hz knots, piecewise linear): a first rest of 90 s, then four drives of 600 s separated by
parking rests of 300 s, a last rest of 210 s (3600 s in all).  In a drive the current goes to a new level every
3-25 s: 20 % zero, 20 % regen U(-0.8C, 0), 60 % discharge U(0, IMAX) (Ramadass2004 2.2C, OKane2022 1.8C), so that
the SOC falls by 30-40 % over the hour with rests where a sensor offset shows.  The parking rests (300 s) turned
out shorter than the slow relaxation the calibration fits (its report says so: 370 s), so a second protocol,
"swing" (the earlier trials' rest-stop shape, one hour): a first rest of 60 s, two drives of 1200 s each followed
by a rest of 600 s (3660 s in all), in a drive 15 % zero, 15 % regen, 70 % discharge, from 95 % SOC: a 45-60 %
SOC swing with rests long enough to tell a capacity or a current offset from the slow branch.  Initial SOC (PyBaMM's
``set_initial_state`` in the published 2.8/2.5-4.2 V window): 0.90, except ``none_2`` 0.70 (another part of the OCV).

Logger: a current column discharge-positive (a BMS/CAN-style export: ``t_s``, ``I_pack_A``, ``U_cell_V``,
``T_cell_degC``, ``T_amb_degC``), white noise: voltage 1.0 mV, current 0.2 % of 1C, temperature 0.1 K (quantised
to 0.1 K: a BMS's resolution), ambient a constant 25.0.

Cases (``CASES``; the seeds fix the drive and the noise):

* ``none`` (seed 4111), ``none_2`` (seed 4112, from 70 % SOC): nothing;
* ``capacity``: both electrodes' active material volume fraction x 0.87 (13 % lost capacity; the drive of ``none``);
* ``current_offset``: the logger reads 4 % of 1C *less* discharge current than flows (-0.07 A Ramadass2004,
  -0.2 A OKane2022 added to the logged discharge-positive current; in the calibration's terms ``current_offset_a``
  = logged - true = that value);
* ``contact_resistance``: PyBaMM's contact resistance (25 mOhm Ramadass2004, 6 mOhm OKane2022; the drive of
  ``none``);
* ``cooling_change``: the total heat transfer coefficient x 2.5 from 1990 s (a fan switched on 100 s into the
  third drive; 0.5 s sigmoid);
* ``none_swing``, ``capacity_swing`` (x 0.87, the drive of ``none_swing``), ``current_offset_swing`` (-4 % of 1C
  as ``current_offset``): the swing protocol;
* ``none_standing_charge`` (a reviewer's case, fifteenth session): the drive of ``current_offset`` with a real
  current of -4 % of 1C (a charger's trickle) added all through, rests included, and logged as it flows: no effect
  is missing (the logged current is the cell's), but the rests read the level ``current_offset`` would, so the
  level alone cannot tell a standing current from a sensor offset.

The user's nominal (``cell_trial41_<set>_nominal.toml``): the rated capacity (OKane2022 PyBaMM's nominal 5.0 A.h;
Ramadass2004 1.75 A.h, since PyBaMM's 1.0 A.h is only its current scale: its DFN holds 1.775 A.h at C/25), a
pseudo-OCV from a C/25 discharge from 100 % SOC (4.2 V) to the published lower cut-off with the same DFN (SOC = 1 - discharged A.h / rated A.h, 41
points), the initial SOC from the first rest (``soc0_frac = -1``), two RC branches, the cell's radius and length,
the heat transfer coefficient.  ``cell_trial41_<set>_truth.json``: per case the seed, the inputs and the truth in the
calibration's terms (``capacity_ah``, ``current_offset_a`` discharge-positive logged - true, ``h_change_factor``,
``h_change_time_s``, ``series_resistance_added_ohm``) and the solve's wall time; ``solid_diffusion_time_s``: the
particles' R^2/D (``diffusion_times.py``), the generator's own diffusion a ``solid_diffusion`` fit may name.
"""
import inspect
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import pybamm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from diffusion_times import electrode_diffusion_times_s  # (the particles' R^2/D, as the earlier truths)

if len(sys.argv) < 2:
    raise SystemExit("usage: make_cell_pybamm_trial41.py SET [CASE ...]  (SET Ramadass2004 or OKane2022)")
SET = sys.argv[1]
ONLY = sys.argv[2:]
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))
PRE = "cell_trial41_" + SET.lower()
T_REF = 298.15
CFG = {"Ramadass2004": {"imax_c": 2.2, "h": 10.0, "geom": (0.009, 0.065), "contact_ohm": 0.025,
                        "override": {"Cell volume [m3]": np.pi * 0.009 ** 2 * 0.065,
                                     "Cell cooling surface area [m2]": 2 * np.pi * 0.009 * 0.065 + 2 * np.pi * 0.009 ** 2}},
       "OKane2022": {"imax_c": 1.8, "h": 25.0, "geom": (0.0105, 0.0704), "contact_ohm": 0.006, "override": {}}}[SET]
# the user's rated capacity: PyBaMM's nominal for OKane2022 (5.0 A.h; the DFN gives 5.10 at C/25); Ramadass2004's
# 1.0 A.h is only a current scale (its DFN gives 1.775 A.h at C/25 from 4.2 to 2.8 V), so a datasheet's 1.75 A.h
CAP = {"Ramadass2004": 1.75}.get(SET, float(pybamm.ParameterValues(SET)["Nominal cell capacity [A.h]"]))
NOISE = {"voltage_v": 1.0e-3, "t_surface_c": 0.1, "current_a": 0.002 * CAP, "t_quantum_c": 0.1}
CASES = {"none": {"seed": 4111, "soc0": 0.90},
         "none_2": {"seed": 4112, "soc0": 0.70},
         "capacity": {"seed": 4111, "soc0": 0.90, "am_factor": 0.87},
         "current_offset": {"seed": 4114, "soc0": 0.90, "offset_logged_a": -0.04 * CAP},
         "contact_resistance": {"seed": 4111, "soc0": 0.90, "contact_ohm": CFG["contact_ohm"]},
         "cooling_change": {"seed": 4116, "soc0": 0.90, "h_factor": 2.5, "t_change_s": 1990.0},
         "none_swing": {"seed": 4117, "soc0": 0.95, "protocol": "swing"},
         "capacity_swing": {"seed": 4117, "soc0": 0.95, "protocol": "swing", "am_factor": 0.87},
         "current_offset_swing": {"seed": 4119, "soc0": 0.95, "protocol": "swing", "offset_logged_a": -0.04 * CAP},
         # a reviewer's case (fifteenth session): a real standing current, logged as it flows (no offset)
         "none_standing_charge": {"seed": 4114, "soc0": 0.90, "standing_current_a": -0.04 * CAP}}


def base_params(soc0=None):
    """The generator's parameters; ``soc0``: the initial stoichiometries set for this SOC in PyBaMM's own terms
    (in the cell's published voltage window, before the cut-offs are widened)."""
    p = pybamm.ParameterValues(SET)
    p["Nominal cell capacity [A.h]"] = CAP
    for k, v in CFG["override"].items():
        p.update({k: v}, check_already_exists=False)
    p.update({"Total heat transfer coefficient [W.m-2.K-1]": CFG["h"]}, check_already_exists=False)
    if soc0 is not None:
        p.set_initial_state(soc0)
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
        p.update({f"{e} electrode OCP entropic change [V.K-1]": 0.0}, check_already_exists=False)
    return p


def current_knots(rng, protocol="commute"):
    """1 s knots of the discharge-positive current (A): the commute or the swing (module docstring)."""
    if protocol == "swing":
        n, drives, probs = 3661, [(60, 1260), (1860, 3060)], [0.15, 0.15, 0.7]
    else:
        n, drives, probs = 3601, [(90, 690), (990, 1590), (1890, 2490), (2790, 3390)], [0.2, 0.2, 0.6]
    i = np.zeros(n)
    for a, b in drives:
        k, prev = a, 0.0
        while k < b:
            seg = min(int(rng.uniform(3, 25)), b - k)
            nxt = rng.choice([0.0, rng.uniform(-0.8, 0.0) * CAP, rng.uniform(0.0, CFG["imax_c"]) * CAP], p=probs)
            i[k:k + seg + 1] = np.linspace(prev, nxt, seg + 1)
            prev, k = nxt, k + seg
        i[b] = 0.0
        i[b - 1] = 0.5 * i[b - 2]
    return np.arange(n, dtype=float), i


def simulate(case, tk, ik, t):
    p = base_params(case["soc0"])
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
    sim = pybamm.Simulation(pybamm.lithium_ion.DFN(opts), parameter_values=p, solver=pybamm.IDAKLUSolver())
    sol = sim.solve(t_eval=[t[0], t[-1]], t_interp=t)
    if sol.t.size != t.size:
        raise SystemExit(f"{SET}: PyBaMM stopped at {sol.t[-1]:.0f} s: {sol.termination}")
    return sol["Voltage [V]"].entries, sol["Volume-averaged cell temperature [C]"].entries


def pseudo_ocv():
    p = base_params(1.0)
    lo = p["Lower voltage cut-off [V]"] + 0.3
    exp = pybamm.Experiment([f"Discharge at C/25 until {lo} V (60 second period)"])
    sol = pybamm.Simulation(pybamm.lithium_ion.DFN({"thermal": "lumped"}), parameter_values=p, experiment=exp).solve()
    ah = sol["Discharge capacity [A.h]"].entries
    v = sol["Voltage [V]"].entries
    soc = 1.0 - ah / CAP
    grid = np.linspace(max(soc.min(), 0.0), 1.0, 41)
    o = np.argsort(soc)
    return grid, np.interp(grid, soc[o], v[o]), float(ah[-1])


def main():
    r, L = CFG["geom"]
    truth_path = OUT / f"{PRE}_truth.json"
    if ONLY and truth_path.exists():
        truth = json.loads(truth_path.read_text())
    else:
        t0 = time.perf_counter()
        grid, ocv, cap = pseudo_ocv()
        w_ocv = time.perf_counter() - t0
        grid[0] = 0.0
        nom = ["[meta]", f'source = "PyBaMM {pybamm.__version__} DFN {SET}: rated {CAP} A.h; pseudo-OCV at C/25 (measured {cap:.4f} A.h); tests/data/independent/make_cell_pybamm_trial41.py"',
               "[params]", f"capacity_ah = {CAP}", "soc0_frac = -1.0", "rc_pairs = 2", f"radius_m = {r:.6g}", f"length_m = {L:.6g}",
               f"h_conv_w_m2k = {CFG['h']}",
               "[ocv]", "soc_frac = [" + ", ".join(f"{x:.4f}" for x in grid) + "]", "ocv_v = [" + ", ".join(f"{x:.5f}" for x in ocv) + "]"]
        (OUT / f"{PRE}_nominal.toml").write_text("\n".join(nom) + "\n")
        print(SET, f"pseudo-OCV {cap:.4f} A.h in {w_ocv:.0f} s", flush=True)
        truth = {"set": SET, "generator": f"PyBaMM {pybamm.__version__} DFN lumped thermal", "rated_ah": CAP, "c25_ah": cap,
                 "noise": NOISE, "radius_m": r, "length_m": L, "h": CFG["h"], "current_sign_in_file": "discharge-positive",
                 "solid_diffusion_time_s": electrode_diffusion_times_s(SET),
                 "columns": {"time_s": "t_s", "current_a": "I_pack_A", "voltage_v": "U_cell_V",
                             "t_surface_c": "T_cell_degC", "t_ambient_c": "T_amb_degC"}, "cases": {}}
    for name, case in CASES.items():
        if ONLY and name not in ONLY:
            continue
        rng = np.random.default_rng(case["seed"])
        tk, ik = current_knots(rng, case.get("protocol", "commute"))
        ik = ik + case.get("standing_current_a", 0.0)      # flows all through, rests included, and is logged
        t = np.arange(0.0, tk[-1] + 1e-9, 1.0)
        t0 = time.perf_counter()
        v, temp = simulate(case, tk, ik, t)
        wall = time.perf_counter() - t0
        i_true = np.interp(t, tk, ik)
        i_log = i_true + case.get("offset_logged_a", 0.0) + rng.normal(0, NOISE["current_a"], t.size)
        v_log = v + rng.normal(0, NOISE["voltage_v"], t.size)
        ts = np.round((temp + rng.normal(0, NOISE["t_surface_c"], t.size)) / NOISE["t_quantum_c"]) * NOISE["t_quantum_c"]
        lines = [f"# PyBaMM {pybamm.__version__} DFN/{SET} case {name} (tests/data/independent/make_cell_pybamm_trial41.py)",
                 "t_s,I_pack_A,U_cell_V,T_cell_degC,T_amb_degC"]
        lines += [f"{a:.0f},{b:.4f},{c:.4f},{d:.1f},25.0" for a, b, c, d in zip(t, i_log, v_log, ts)]
        fname = f"{PRE}_{name}.csv"
        (OUT / fname).write_text("\n".join(lines) + "\n")
        q = np.concatenate([[0.0], np.cumsum(0.5 * (i_true[1:] + i_true[:-1]) * np.diff(t))]) / 3600.0
        truth["cases"][name] = {**case, "file": fname, "solve_wall_s": round(wall, 1),
                                "truth": {"capacity_ah": CAP * case.get("am_factor", 1.0),
                                          "current_offset_a": case.get("offset_logged_a", 0.0),
                                          "h_change_factor": case.get("h_factor", 1.0),
                                          "h_change_time_s": case.get("t_change_s"),
                                          "series_resistance_added_ohm": case.get("contact_ohm", 0.0)},
                                "v": [float(v.min()), float(v.max())], "t_max_c": float(temp.max()),
                                "discharged_ah": [float(q.min()), float(q.max())], "i_rms_a": float(np.sqrt(np.mean(i_true ** 2)))}
        print(SET, name, f"V {v.min():.3f}-{v.max():.3f} Tmax {temp.max():.2f} Ah {q.max():.3f} solve {wall:.0f} s", flush=True)
        truth_path.write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
