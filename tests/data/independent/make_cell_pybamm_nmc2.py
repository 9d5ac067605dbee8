"""A second NMC cell the calibration was never developed on, made by PyBaMM (not by shevsim).

    python tests/data/independent/make_cell_pybamm_nmc2.py   # PyBaMM 26.x (a test/benchmark dependency)

PyBaMM's SPMe with a lumped thermal model and the published ``Ecker2015`` parameter set (Kokam SLPB 75106100,
NMC / graphite pouch, 7.5 A.h; Ecker et al., J. Electrochem. Soc. 162 (2015) A1836 and A1849; electrode and
electrolyte fits of Richardson et al. 2020; thermal material properties of a Kokam pouch cell from Zhao et al.
2018) runs the protocols of ``make_cell_pybamm.py`` (``current_profile``: the same seeded pulse statistics),
their current scaled by 7.5 / 5 to this cell's rating (the same C-rates):

* ``swing`` (the ``*_swing`` cases): a 60 s rest, then three blocks of 30 min of pulses from -0.7C to +1.6C
  (-5.25 to +12 A), each followed by a 10 min rest stop (the last 9 min), from 95 % SOC, 7200 s;
* ``drive`` (``none``): a 60 s rest, then pulses from -1C to +2C (-7.5 to +15 A) for one hour from 80 % SOC.

``Ecker2015`` describes ONE electrode pair of the cell (0.156 A.h; ``Cell volume`` 1.52e-6 m3, the layer's;
``Cell cooling surface area`` 0.0172 m2, its two faces).  Filled in to make it the whole cell (each a stated
assumption):

* 48 electrode pairs in parallel (``Number of electrodes connected in parallel``: 7.5 A.h rated / 0.15625 A.h,
  PyBaMM's ``Nominal cell capacity`` of the pair); the stack is then 48 x 1.52e-6 = 7.3e-5 m3;
* the pouch: 7.5 x 106 x 100 mm (Kokam's type designation SLPB 75106100: thickness 7.5 mm, width 106 mm,
  length 100 mm; the set's electrodes, 101 x 85 mm, fit inside): ``Cell volume`` 7.95e-5 m3 and ``Cell
  cooling surface area`` 0.0243 m2 (both faces and the four edges);
* ``Total heat transfer coefficient`` 10 W/(m2.K) (the set's own value; natural convection, as the Chen2020
  and Prada2013 records).  The set's layer densities and specific heats (Zhao 2018) are kept.

The exchange-current densities, the particle diffusivities and the electrolyte conductivity and diffusivity
(``Ecker2015``'s all carry Arrhenius factors, around its 23 degC reference) are held at their 25 degC values,
as in ``make_cell_pybamm.py``: the user's nominal has no temperature law, so a no-effect record has none
either.  The upper voltage cut-off is 4.4 V (regeneration pulses at 95 % SOC pass 4.2 V briefly), as there.

The logger is ``make_cell_pybamm.log_record`` (1 Hz, instantaneous; noise voltage 1 mV, temperature 0.05 K,
current 5 mA), records ``cell_nmc2_<case>.csv``.  Cases:

* ``none_swing`` and ``none``: the published cell (no effect);
* ``capacity_swing``: both electrodes' active-material volume fractions x 0.85 (lost active material, as the
  Chen2020 ``capacity`` records); truth in the table's terms as there: 0.85 x 7.5 A.h;
* ``current_offset_swing``: the logged current is the true one + 0.15 A (the Chen2020 records' +0.1 A on
  5 A.h scaled to 7.5 A.h: 0.02C).

The user's nominal (``cell_nmc2_nominal.toml``): the rated capacity 7.5 A.h; a pseudo-OCV measured by PyBaMM at
C/50 on the nominal cell, logged every 60 s (SOC = 1 - discharged A.h / 7.5 A.h, 41 points; the C/50 run
discharges about 8.1 A.h between 4.2 and 2.5 V, so the table ends at SOC 0 with 7.5 A.h discharged, well
below what the records visit); the initial SOC from the first rest voltage (``soc0_frac = -1``); two RC
branches (``rc_pairs = 2``); and the pouch as the cylinder the battery model takes, with the pouch's volume
and cooling surface (radius 6.62 mm, length 0.577 m: the root of pi r^2 L = V, 2 pi r (L + r) = A whose
conduction distance, 6.6 mm, is that of the pouch's half-thickness, 3.75 mm, rather than the flat disk's
62 mm).  ``cell_nmc2_truth.json``: seeds, PyBaMM inputs, the truth in shevsim's names (``capacity_ah``,
``current_offset_a``), the initial SOC in the table's terms (``soc_init_pct``) and the SOC range each record
visits (``soc_table_range``).
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
# the same protocols, logger and noise
from make_cell_pybamm import (
    FIRST_REST_S,
    NOISE,
    SOC0,
    T_REF_K,
    current_profile,
    log_record,
)

OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))     # where to write (default: beside this script)
RATED_AH = 7.5
SCALE = RATED_AH / 5.0                                  # the Chen2020 protocols' currents -> this cell's C-rates
N_PARALLEL = 48                                         # 7.5 A.h / 0.15625 A.h (the set's one electrode pair)
THICK_M, WIDTH_M, LENGTH_POUCH_M = 7.5e-3, 0.106, 0.100  # Kokam SLPB 75106100
POUCH_VOLUME_M3 = THICK_M * WIDTH_M * LENGTH_POUCH_M
POUCH_AREA_M2 = 2.0 * (WIDTH_M * LENGTH_POUCH_M + THICK_M * (WIDTH_M + LENGTH_POUCH_M))
H_W_M2K = 10.0
OFFSET_A = 0.02 * RATED_AH                              # 0.15 A
CASES = {
    "none_swing": {"seed": 51, "protocol": "swing"},
    "capacity_swing": {"seed": 52, "protocol": "swing", "am_factor": 0.85},
    "current_offset_swing": {"seed": 53, "protocol": "swing", "offset_a": OFFSET_A},
    "none": {"seed": 54, "protocol": "drive"},
}
HELD_AT_25C = {   # parameter -> its arguments (the temperature last)
    "Negative electrode exchange-current density [A.m-2]": 4,
    "Positive electrode exchange-current density [A.m-2]": 4,
    "Negative particle diffusivity [m2.s-1]": 2,
    "Positive particle diffusivity [m2.s-1]": 2,
    "Electrolyte conductivity [S.m-1]": 2,
    "Electrolyte diffusivity [m2.s-1]": 2,
}


def equivalent_cylinder(volume_m3: float = POUCH_VOLUME_M3, area_m2: float = POUCH_AREA_M2):
    """The cylinder (radius, length) [m] with the pouch's volume and cooling surface: the thin root of
    pi r^2 L = V, 2 pi r L + 2 pi r^2 = A (bisection on r in (0, 2 V / A])."""
    def f(r):
        return 2.0 * volume_m3 / r + 2.0 * math.pi * r * r - area_m2
    lo, hi = 1e-4, 2.0 * volume_m3 / area_m2 * 1.5
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0.0 else (lo, mid)
    r = 0.5 * (lo + hi)
    return r, volume_m3 / (math.pi * r * r)


def _at_25c(f, n_args: int):
    """The function ``f`` (the temperature its last of ``n_args`` arguments) evaluated at 25 degC whatever T."""
    if n_args == 4:
        return lambda a, b, c, T: f(a, b, c, T_REF_K)
    return lambda a, T: f(a, T_REF_K)


def params():
    """Ecker2015 made the whole cell (module docstring), its temperature laws held at 25 degC."""
    p = pybamm.ParameterValues("Ecker2015")
    p.update({"Number of electrodes connected in parallel to make a cell": float(N_PARALLEL),
              "Nominal cell capacity [A.h]": RATED_AH,
              "Cell volume [m3]": POUCH_VOLUME_M3, "Cell cooling surface area [m2]": POUCH_AREA_M2,
              "Total heat transfer coefficient [W.m-2.K-1]": H_W_M2K,
              "Ambient temperature [K]": T_REF_K, "Initial temperature [K]": T_REF_K,
              "Upper voltage cut-off [V]": 4.4})
    for k, n in HELD_AT_25C.items():
        p[k] = _at_25c(p[k], n)
    return p


def simulate(case: dict, t, i_true):
    p = params()
    if "am_factor" in case:
        for e in ("Negative", "Positive"):
            k = f"{e} electrode active material volume fraction"
            p[k] = p[k] * case["am_factor"]
    p["Current function [A]"] = pybamm.Interpolant(t, i_true, pybamm.t)
    sim = pybamm.Simulation(pybamm.lithium_ion.SPMe({"thermal": "lumped"}), parameter_values=p,
                            solver=pybamm.IDAKLUSolver())
    sol = sim.solve(t_eval=[t[0], t[-1]], t_interp=t, initial_soc=SOC0[case["protocol"]])
    if sol.t.size != t.size:
        raise SystemExit(f"PyBaMM stopped at t = {sol.t[-1]:.0f} s: {sol.termination}")
    return sol["Voltage [V]"].entries, sol["Volume-averaged cell temperature [C]"].entries


def pseudo_ocv():
    """The C/50 discharge from full to 2.5 V logged every 60 s, as a 41-point table against the rated SOC
    (1 - discharged A.h / 7.5 A.h, from 0); and the capacity it measured."""
    model = pybamm.lithium_ion.SPMe({"thermal": "lumped"})
    exp = pybamm.Experiment(["Discharge at C/50 until 2.5 V (60 second period)"])
    sol = pybamm.Simulation(model, parameter_values=params(), experiment=exp).solve(initial_soc=1.0)
    ah = sol["Discharge capacity [A.h]"].entries
    v = sol["Voltage [V]"].entries
    soc = 1.0 - ah / RATED_AH
    grid = np.linspace(max(soc.min(), 0.0), 1.0, 41)
    order = np.argsort(soc)
    ocv = np.interp(grid, soc[order], v[order])
    grid[0] = 0.0
    return grid, ocv, float(ah[-1])


def main() -> int:
    grid, ocv, cap = pseudo_ocv()
    r_m, l_m = equivalent_cylinder()
    nom = ["[meta]", (f'source = "PyBaMM {pybamm.__version__} Ecker2015 (Kokam SLPB 75106100, NMC/graphite): rated '
                      f'{RATED_AH} A.h; pseudo-OCV at C/50 (measured {cap:.3f} A.h); the pouch 7.5 x 106 x 100 mm as a '
                      f'cylinder of its volume and cooling surface; make_cell_pybamm_nmc2.py"'),
           "[params]", f"capacity_ah = {RATED_AH}", "soc0_frac = -1.0", "rc_pairs = 2",
           f"radius_m = {r_m:.6f}", f"length_m = {l_m:.5f}", f"h_conv_w_m2k = {H_W_M2K}",
           "[ocv]", "soc_frac = [" + ", ".join(f"{x:.4f}" for x in grid) + "]",
           "ocv_v = [" + ", ".join(f"{x:.5f}" for x in ocv) + "]"]
    (OUT / "cell_nmc2_nominal.toml").write_text("\n".join(nom) + "\n")
    truth = {"generator": f"PyBaMM {pybamm.__version__} SPMe + lumped thermal, Ecker2015 (Kokam SLPB 75106100 "
                          f"NMC, 48 pairs, 7.5 A.h), 1 Hz instantaneous", "noise": NOISE,
             "rated_capacity_ah": RATED_AH, "pseudo_ocv_capacity_ah": cap,
             "pouch_volume_m3": POUCH_VOLUME_M3, "pouch_cooling_area_m2": POUCH_AREA_M2,
             "equivalent_cylinder_m": [r_m, l_m], "cases": {}}
    for name, case in CASES.items():
        rng = np.random.default_rng(case["seed"])
        proto = case["protocol"]
        t, i5 = current_profile(rng, proto)
        i_true = SCALE * i5
        v, temp = simulate(case, t, i_true)
        log_record(OUT / f"cell_nmc2_{name}.csv", f"# PyBaMM {pybamm.__version__} SPMe/Ecker2015 (Kokam 7.5 A.h NMC) "
                   f"record, case '{name}' (make_cell_pybamm_nmc2.py)", rng, t, i_true, v, temp,
                   case.get("offset_a", 0.0))
        q = RATED_AH * case.get("am_factor", 1.0)
        # the initial SOC and the SOC visited in the nominal table's terms (true current, true capacity)
        soc_init = 1.0 - (1.0 - SOC0[proto]) * cap / RATED_AH
        soc_tab = soc_init - np.cumsum(i_true) / 3600.0 / q
        tr = {"capacity_ah": q, "current_offset_a": case.get("offset_a", 0.0), "soc_init_pct": 100.0 * soc_init}
        truth["cases"][name] = {"pybamm_inputs": {k: x for k, x in case.items() if k not in ("seed", "protocol")},
                                "seed": case["seed"], "truth": tr, "file": f"cell_nmc2_{name}.csv",
                                "v_min": float(v.min()), "v_max": float(v.max()), "t_max_c": float(temp.max()),
                                "protocol": proto, "first_rest_s": FIRST_REST_S,
                                "soc_table_range": [float(soc_tab.min()), float(soc_tab.max())]}
        print(name, f"V {v.min():.3f}-{v.max():.3f}  T max {temp.max():.2f} C  SOC {soc_tab.min():.3f}-"
              f"{soc_tab.max():.3f}", flush=True)
    # the particles' own solid diffusion (in every record): the truth of the solid_diffusion effect
    from diffusion_times import electrode_diffusion_times_s
    truth["solid_diffusion_time_s"] = electrode_diffusion_times_s('Ecker2015')
    (OUT / "cell_nmc2_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
