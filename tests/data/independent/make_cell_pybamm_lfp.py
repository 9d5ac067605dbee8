"""LFP cell records with a flat OCV for the calibration tests, made by PyBaMM (not by shevsim).

    python tests/data/independent/make_cell_pybamm_lfp.py    # PyBaMM 26.x (a test/benchmark dependency)

PyBaMM's SPMe with a lumped thermal model and the published ``Prada2013`` parameter set (A123 ANR26650m1,
LiFePO4 / graphite 26650, 2.3 A.h; Prada et al., J. Electrochem. Soc. 160 (2013) A616) runs a seeded
drive-like current (1 Hz levels linearly interpolated): a 60 s rest at the initial SOC, then pulses from
-1C to +2C (-2.3 to +4.6 A) held 5-40 s, rests (rest 20 %, charge 30 %, discharge 50 %: about 35 % of SOC
swing) for one hour - the ``drive`` protocol of ``make_cell_pybamm.py`` scaled to this cell's capacity; or
(``stops``) the same pulses in three blocks of 880 s each followed by a 300 s rest stop.
Its open-circuit voltage is flat: between 50 and 70 % SOC it rises by 8 mV (0.4 mV per % of SOC), between
82 and 95 % by 5 mV; it has steps (graphite staging) of 15-20 mV between 70 and 80 % and between 35 and 50 %.
A rest voltage read to 1 mV gives the SOC to about 0.3 % on a step and to no better than 2-7 % on a plateau.

``Prada2013`` has no thermal parameters.  Filled in (a stated assumption each):

* the cell as one homogeneous body with the A123 26650's identified lumped properties of Kim (2014)
  (dissertation, Table 2.2, the project's thesis; the battery component's defaults): every layer's density
  2047 kg/m3 and specific heat 1109.2 J/(kg.K);
* the can: radius 12.93 mm, length 65.15 mm (the same source) - cell volume pi r^2 L, cooling surface the
  lateral and both end faces;
* current collectors: ``Chen2020``'s thicknesses and conductivities (12 um copper, 16 um aluminium); the
  stack (0.18 m2 of electrode) is then 3.0e-5 m3 against the can's 3.4e-5 m3;
* ``Total heat transfer coefficient`` 10 W/(m2.K) (natural convection, as the Chen2020 records; Kim's
  26650 was identified at 58.6 W/(m2.K) under a fan).

The exchange-current densities and the electrolyte conductivity (``Prada2013``'s carry Arrhenius factors)
are held at their 25 degC values, as in ``make_cell_pybamm.py``: the user's nominal has no temperature law,
so a no-effect record has none either.  The upper voltage cut-off is 3.8 V (charge pulses at 90 % SOC).

The logger is ``make_cell_pybamm.log_record`` (1 Hz, instantaneous; noise voltage 1 mV, temperature 0.05 K,
current 5 mA), records ``cell_lfp_<case>.csv``.  Cases (the start SOC ``soc0`` is PyBaMM's: the fraction of
its stoichiometry window between the OCV limits 2.0 and 3.6 V):

* ``none``, ``none_2``: start at 78 and 76 % SOC, on the step between 70 and 80 % (3.6 mV per %): the first
  rest voltage gives the SOC; nothing is missing from the nominal;
* ``plateau``: start at 60 %, mid-plateau: the rest voltage's SOC through the user's table is off (the C/50
  table lies 1.8-3.3 mV below the equilibrium, 2.2 mV on average: 6.6 % of SOC there); the drive then
  crosses the step at 35-50 % (and reaches 15 %), where the voltage shows the SOC;
* ``plateau_2``: start at 90 % (the flattest plateau, 0.3 mV per %), another seed; the drive crosses the step
  at 70-80 %;
* ``ocv_c20``: the ``stops`` protocol from a sloped start (78 %) given with a nominal whose OCV table is a
  C/20 discharge (``cell_lfp_nominal_c20.toml``, a common and realistic mismatch: the table lies below the
  equilibrium by the C/20 overpotential, 4.4-7.9 mV between 30 and 90 % SOC, 2.5x the C/50 one; the
  calibration checks an OCV correction at the rests after current, which the ``drive`` lacks).

The user's nominal (``cell_lfp_nominal.toml``): the rated capacity 2.3 A.h, a pseudo-OCV measured by
PyBaMM at C/50 on the nominal cell, logged every 60 s, as a 101-point table (SOC = 1 - discharged A.h /
2.3 A.h; an LFP curve's staging steps need the finer table: 41 points, 2.5 % apart, interpolate the steps
with errors of 1-2 mV, several % of SOC on this OCV), the initial SOC from the first rest voltage
(``soc0_frac = -1``, as a user would), two RC branches (``rc_pairs = 2``) and the can's size.
``cell_lfp_truth.json``: seeds, PyBaMM inputs, the truth in the calibration's terms (``soc_init_pct``, the
initial SOC as the nominal table's SOC: 1 - (1 - soc0) q / 2.3 A.h with q the C/50 capacity, the mapping
``make_cell_pybamm.cell_dudt`` uses), what the first rest voltage gives through the user's table
(``soc_from_rest_voltage_pct``), the SOC range each record visits (``soc_table_range``), and for ``ocv_c20``
the table's error (equilibrium OCV - table) at five knots over that range (``ocv_delta_knots_*``).
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pybamm

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_cell_pybamm import NOISE, T_REF_K, log_record  # noqa: E402  (the same logger and noise)

OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))     # where to write (default: beside this script)
RATED_AH = 2.3
DURATION_S, FIRST_REST_S = 3600.0, 60
STOP_BLOCKS, STOP_DRIVE_S, STOP_REST_S = 3, 880, 300   # the "stops" protocol: 60 + 3 x (880 + 300) = 3600 s
RADIUS_M, LENGTH_M = 12.93e-3, 65.15e-3                 # A123 26650 (Kim 2014, Table 2.2)
DENSITY_KG_M3, CP_J_KGK, H_W_M2K = 2047.0, 1109.2, 10.0
N_TABLE = 101
N_OCV_KNOTS = 5                                          # the calibration's ocv_correction knots
CASES = {
    "none": {"seed": 41, "soc0": 0.78},
    "none_2": {"seed": 44, "soc0": 0.76},
    "plateau": {"seed": 42, "soc0": 0.60},
    "plateau_2": {"seed": 43, "soc0": 0.90},
    "ocv_c20": {"seed": 45, "soc0": 0.78, "nominal": "c20", "protocol": "stops"},
}
HELD_AT_25C = ("Negative electrode exchange-current density [A.m-2]",
               "Positive electrode exchange-current density [A.m-2]")


def params():
    """Prada2013 with the thermal parameters it lacks (module docstring) and its kinetics and electrolyte
    conductivity held at 25 degC."""
    p = pybamm.ParameterValues("Prada2013")
    c = pybamm.ParameterValues("Chen2020")
    for k in ("Negative current collector thickness [m]", "Positive current collector thickness [m]",
              "Negative current collector conductivity [S.m-1]", "Positive current collector conductivity [S.m-1]"):
        p.update({k: c[k]}, check_already_exists=False)
    extra = {"Cell volume [m3]": math.pi * RADIUS_M ** 2 * LENGTH_M,
             "Cell cooling surface area [m2]": 2.0 * math.pi * RADIUS_M * (LENGTH_M + RADIUS_M),
             "Total heat transfer coefficient [W.m-2.K-1]": H_W_M2K}
    for d in ("Negative electrode", "Positive electrode", "Separator", "Negative current collector",
              "Positive current collector"):
        extra[f"{d} density [kg.m-3]"] = DENSITY_KG_M3
        extra[f"{d} specific heat capacity [J.kg-1.K-1]"] = CP_J_KGK
    p.update(extra, check_already_exists=False)
    p["Ambient temperature [K]"] = T_REF_K
    p["Initial temperature [K]"] = T_REF_K
    p["Upper voltage cut-off [V]"] = 3.8
    for k in HELD_AT_25C:
        f = p[k]
        p[k] = (lambda f: lambda c_e, c_s_surf, c_s_max, T: f(c_e, c_s_surf, c_s_max, T_REF_K))(f)
    g = p["Electrolyte conductivity [S.m-1]"]
    p["Electrolyte conductivity [S.m-1]"] = (lambda g: lambda c_e, T: g(c_e, T_REF_K))(g)
    return p


def current_profile(rng, protocol: str = "drive"):
    """1 Hz current levels [A] (+ discharge): a 60 s rest, then pulses held 5-40 s (rest 20 %, charge
    U(-1C, 0) 30 %, discharge U(0, 2C) 50 %) to 3600 s (``drive``), or in ``STOP_BLOCKS`` blocks of
    ``STOP_DRIVE_S`` each followed by a rest stop of ``STOP_REST_S`` (``stops``)."""
    n = int(DURATION_S) + 1
    i = np.zeros(n)
    blocks = ([(FIRST_REST_S, n)] if protocol == "drive" else
              [(FIRST_REST_S + b * (STOP_DRIVE_S + STOP_REST_S), FIRST_REST_S + b * (STOP_DRIVE_S + STOP_REST_S)
                + STOP_DRIVE_S) for b in range(STOP_BLOCKS)])
    for k, end in blocks:
        while k < end:
            seg = min(int(rng.uniform(5, 40)), end - k)
            i[k:k + seg] = rng.choice([0.0, rng.uniform(-RATED_AH, 0.0), rng.uniform(0.0, 2.0 * RATED_AH)],
                                      p=[0.2, 0.3, 0.5])
            k += seg
    return np.arange(n, dtype=float), i


def simulate(case: dict, t, i_true):
    p = params()
    p["Current function [A]"] = pybamm.Interpolant(t, i_true, pybamm.t)
    sim = pybamm.Simulation(pybamm.lithium_ion.SPMe({"thermal": "lumped"}), parameter_values=p,
                            solver=pybamm.IDAKLUSolver())
    sol = sim.solve(t_eval=[t[0], t[-1]], t_interp=t, initial_soc=case["soc0"])
    if sol.t.size != t.size:
        raise SystemExit(f"PyBaMM stopped at t = {sol.t[-1]:.0f} s: {sol.termination}")
    return sol["Voltage [V]"].entries, sol["Volume-averaged cell temperature [C]"].entries


def pseudo_ocv(c_rate_inv: int = 50):
    """The C/``c_rate_inv`` discharge from full to 2.0 V logged every 60 s, as an ``N_TABLE``-point table
    against the rated SOC (1 - discharged A.h / 2.3 A.h); and the capacity it measured."""
    model = pybamm.lithium_ion.SPMe({"thermal": "lumped"})
    exp = pybamm.Experiment([f"Discharge at C/{c_rate_inv} until 2.0 V (60 second period)"])
    sol = pybamm.Simulation(model, parameter_values=params(), experiment=exp).solve(initial_soc=1.0)
    ah = sol["Discharge capacity [A.h]"].entries
    v = sol["Voltage [V]"].entries
    soc = 1.0 - ah / RATED_AH
    grid = np.linspace(max(soc.min(), 0.0), 1.0, N_TABLE)
    order = np.argsort(soc)
    ocv = np.interp(grid, soc[order], v[order])
    grid[0] = 0.0   # the table's lowest point (the run ends at 2.0 V near SOC 0)
    return grid, ocv, float(ah[-1])


def equilibrium_ocv(soc_table, q_ah: float) -> np.ndarray:
    """The cell's equilibrium OCV [V] at the nominal table's SOC: U_p(y) - U_n(x) at the electrode
    stoichiometries of PyBaMM's SOC s = 1 - (1 - soc_table) 2.3 A.h / ``q_ah`` (``q_ah`` the C/50 capacity)."""
    p = pybamm.ParameterValues("Prada2013")
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    s = 1.0 - (1.0 - np.atleast_1d(np.asarray(soc_table, float))) * RATED_AH / q_ah
    u_n, u_p = p["Negative electrode OCP [V]"], p["Positive electrode OCP [V]"]
    return np.array([float(u_p(pybamm.Scalar(y0 + a * (y1 - y0))).evaluate())
                     - float(u_n(pybamm.Scalar(x0 + a * (x1 - x0))).evaluate()) for a in s])


def write_nominal(path: Path, grid, ocv, cap: float, what: str) -> None:
    nom = ["[meta]", f'source = "PyBaMM {pybamm.__version__} Prada2013 (A123 ANR26650m1): rated {RATED_AH} A.h; '
           f'pseudo-OCV at {what} (measured {cap:.3f} A.h); make_cell_pybamm_lfp.py"',
           "[params]", f"capacity_ah = {RATED_AH}", "soc0_frac = -1.0", "rc_pairs = 2",
           f"radius_m = {RADIUS_M}", f"length_m = {LENGTH_M}", f"h_conv_w_m2k = {H_W_M2K}",
           "[ocv]", "soc_frac = [" + ", ".join(f"{x:.4f}" for x in grid) + "]",
           "ocv_v = [" + ", ".join(f"{x:.5f}" for x in ocv) + "]"]
    path.write_text("\n".join(nom) + "\n")


def main() -> int:
    tables = {"c50": pseudo_ocv(50), "c20": pseudo_ocv(20)}
    cap = tables["c50"][2]
    write_nominal(OUT / "cell_lfp_nominal.toml", *tables["c50"], "C/50")
    write_nominal(OUT / "cell_lfp_nominal_c20.toml", *tables["c20"], "C/20")
    truth = {"generator": f"PyBaMM {pybamm.__version__} SPMe + lumped thermal, Prada2013 (A123 26650 LFP), "
                          "1 Hz instantaneous", "noise": NOISE, "pseudo_ocv_capacity_ah": cap,
             "pseudo_ocv_c20_capacity_ah": tables["c20"][2], "cases": {}}
    for name, case in CASES.items():
        rng = np.random.default_rng(case["seed"])
        t, i_true = current_profile(rng, case.get("protocol", "drive"))
        v, temp = simulate(case, t, i_true)
        log_record(OUT / f"cell_lfp_{name}.csv", f"# PyBaMM {pybamm.__version__} SPMe/Prada2013 (A123 26650 LFP) "
                   f"record, case '{name}' (make_cell_pybamm_lfp.py)", rng, t, i_true, v, temp)
        nominal = case.get("nominal", "c50")
        grid, ocv, _ = tables[nominal]
        # the initial SOC in the nominal table's terms, and the SOC the record visits (true current)
        soc_init = 1.0 - (1.0 - case["soc0"]) * cap / RATED_AH
        soc_tab = soc_init - np.cumsum(i_true) / 3600.0 / RATED_AH
        # what a user reads from the first rest (noise-free): the rest voltage through the user's table
        soc_rest = float(np.interp(np.mean(v[:FIRST_REST_S]), ocv, grid))
        tr = {"soc_init_pct": 100.0 * soc_init, "soc_from_rest_voltage_pct": 100.0 * soc_rest,
              "capacity_ah": RATED_AH}
        lo, hi = float(soc_tab.min()), float(soc_tab.max())
        if nominal != "c50":
            knots = np.linspace(lo, hi, N_OCV_KNOTS)
            tr.update(ocv_delta_knots_soc_frac=[float(x) for x in knots],
                      ocv_delta_knots_v=[float(x) for x in equilibrium_ocv(knots, cap) - np.interp(knots, grid, ocv)])
        truth["cases"][name] = {"pybamm_inputs": {"initial_soc": case["soc0"]}, "seed": case["seed"],
                                "nominal": "cell_lfp_nominal.toml" if nominal == "c50" else f"cell_lfp_nominal_{nominal}.toml",
                                "truth": tr, "file": f"cell_lfp_{name}.csv", "v_min": float(v.min()),
                                "v_max": float(v.max()), "t_max_c": float(temp.max()), "protocol": case.get("protocol", "drive"),
                                "soc_table_range": [lo, hi]}
        print(name, f"V {v.min():.3f}-{v.max():.3f}  T max {temp.max():.2f} C  SOC {lo:.3f}-{hi:.3f}  "
              f"start {soc_init:.3f}, from the rest voltage {soc_rest:.3f}", flush=True)
    # the particles' own solid diffusion (in every record): the truth of the solid_diffusion effect
    from diffusion_times import electrode_diffusion_times_s
    truth["solid_diffusion_time_s"] = electrode_diffusion_times_s('Prada2013')
    (OUT / "cell_lfp_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
