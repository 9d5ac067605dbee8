"""Cell records for the calibration tests, made by PyBaMM (not by shevsim).

    python tests/data/independent/make_cell_pybamm.py        # PyBaMM 26.x (a test/benchmark dependency)

PyBaMM's SPMe with a lumped thermal model and the published ``Chen2020`` parameter set (LG M50, NMC811 /
graphite-SiOx 21700, 5 A.h) runs a seeded drive-like current (1 Hz levels linearly interpolated) in one of
two protocols (``current_profile``):

* ``drive`` (the cases without a suffix): a 60 s rest, then pulses from -1C to +2C held 5-40 s, rests, from
  80 % initial SOC for one hour - about 25 % of SOC swing;
* ``swing`` (the ``*_swing`` cases): as a lab runs a drive cycle down through the SOC range with rest stops
  between the repeats (the Panasonic 18650PF protocol's shape): a 60 s rest, then three blocks of 30 min of
  pulses from -0.7C to +1.6C, each followed by a 10 min rest stop (the last 9 min), from 95 % SOC, 7200 s in
  all, 50-70 % of SOC swing.  A capacity is identifiable only over a wide swing (over a narrow one the OCV
  is nearly linear in the charge passed, so a capacity error is the voltage of a series capacitor - what a
  slow RC branch whose time constant the record cannot resolve also is), and a current-sensor offset shows
  in the rests, where the logged current is not zero.

A logger samples current, voltage and the cell temperature (the lumped model's volume-averaged temperature
as the surface reading) at 1 Hz, instantaneously, with white noise (voltage 1 mV, temperature 0.05 K,
current 5 mA) and writes ``cell_<case>.csv``.  Effects in PyBaMM's own parameters:

* ``none`` (and ``none_2``, ``none_3``: other seeds of the drive): the published cell, its
  exchange-current densities held at their 25 degC values (the user's nominal has no temperature
  dependence; Chen2020's own Arrhenius kinetics made the former "no-effect" record an Arrhenius record,
  25 -> 33 degC, and the calibration rightly found it there);
* ``capacity``: both electrodes' active-material volume fractions x 0.85 (lost active material: the same
  OCV-vs-SOC shape at 85 % capacity);
* ``current_offset``: the logged current is the true one + 0.1 A (a current-sensor offset);
* ``cooling_change``: ``Total heat transfer coefficient`` 10 -> 2.5 W/(m2.K) from t = 1200 s (a smooth
  step of 10 s);
* ``arrhenius``: Chen2020's own Arrhenius exchange-current densities (35 kJ/mol graphite, 17.8 kJ/mol
  NMC811).  Truth in shevsim's terms (``arrhenius_ea_r_k`` scales all resistances): the apparent Ea/R of
  the cell's 10 s, 1C pulse resistance at 60 % SOC between 25 and 35 degC, isothermal PyBaMM runs
  (``apparent_activation_k``; the kinetic part only, so below the kinetic 4210 K);
* ``contact_resistance``: PyBaMM's contact resistance (model option ``"contact resistance": "true"``,
  ``Contact resistance [Ohm]`` = 10 mOhm) on the drive of ``none`` (same seed: the pair a lab has when it
  retests a cell after a connector change).  Truth: the series resistance added,
  ``series_resistance_added_ohm`` (the battery model has no separate contact resistance: it is a higher
  ohmic resistance, the declared ``rs_scale``);
* ``entropic``: the published entropic change of this very cell switched into Chen2020's zero ``Negative /
  Positive electrode OCP entropic change [V.K-1]`` (O'Regan et al. 2022, PyBaMM's ``ORegan2022`` functions;
  PyBaMM then has the reversible heat and the OCV's temperature dependence).  Truth in shevsim's terms
  (battery ``dudt_v_k`` against the nominal table's SOC): dU/dT = dU_p/dT - dU_n/dT at the stoichiometries
  of each SOC (``cell_dudt``), as a 41-point table, at the calibration's four knots over the SOC range the
  record visits, and its mean over the record (``dudt_*``);
* ``none_swing``, ``none_swing_2``, ``capacity_swing`` (x 0.85 as ``capacity``), ``current_offset_swing``
  (+0.1 A as ``current_offset``): the ``swing`` protocol;
* ``none_mixing``, ``none_2_mixing``: the drives of ``none`` and ``none_2`` with PyBaMM's heat of mixing
  (model option ``"heat of mixing": "true"``).  Without it PyBaMM's lumped heat leaves out the energy of the
  concentration gradients: over the drive of the entropic record its irreversible heat is 0.60 W while the
  electrical loss ``i (U - V)`` is 0.78 W; with it, 0.79 W.  The cell then warms more (to 36 and 44 degC)
  while its SOC falls, and its resistance, which has no temperature law here (the exchange-current densities
  held at 25 degC; apparent Ea/R of the 10 s pulse resistance -212 K, from the thermal voltage), falls 6 %
  from 80 to 60 % SOC: a record on which the two trends can be taken for a temperature law;
* ``entropic_mixing``: ``entropic`` with the heat of mixing (the same drive and cell; the same truth);
  ``none_swing_mixing``: ``none_swing`` with it;
* ``capacity_swing_420`` (a reviewer's counter-record, sixth session): the ``swing`` protocol with rest stops of
  420 s (the last 360 s; 7020 s in all), 8 % lost capacity (x 0.92) and the heat of mixing.  Its rests are
  barely longer than the cell's own slow relaxation, so a true capacity is fitted with the slow RC branch at
  the time-constant limit the rests set: the record a capacity rule must not refuse.

The user's nominal (``cell_nominal.toml``, the calibration's ``--params``): the rated capacity 5 A.h, a
pseudo-OCV measured by PyBaMM at C/50 on the nominal cell, logged every 60 s as a cycler would (SOC = 1 -
discharged A.h / 5 A.h, 41 points; without the 60 s period PyBaMM returns only its adaptive solver steps,
a few dozen over the 50 h discharge, and the table interpolated linearly between them was off by up to
11 mV over the SOC range the records visit and 130 mV near empty - an error of the generator, not of the
cell),
the initial SOC from the first rest voltage (``soc0_frac = -1``) and a two-RC equivalent circuit
(``rc_pairs = 2``: solid diffusion in an NMC cell has a slow time constant that one RC branch misses).  ``cell_truth.json``: seeds, PyBaMM
inputs and the truth in shevsim's names (``capacity_ah``, ``current_offset_a``, ``h_change_factor``,
``h_change_time_s``, ``arrhenius_ea_r_k``, ``series_resistance_added_ohm``, ``dudt_*``) and the SOC range
each record visits (``soc_table_range``).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pybamm

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("SHEVSIM_GEN_OUT", HERE))     # where to write (default: beside this script)
# the protocols (module docstring): "drive" - one hour of the drive from 80 % SOC; "swing" - a 60 s rest,
# then SWING_BLOCKS x (SWING_DRIVE_S of the drive, SWING_REST_S of rest) from 95 % SOC, the last rest 540 s
DURATION_S = {"drive": 3600.0, "swing": 7200.0}
SOC0 = {"drive": 0.8, "swing": 0.95}
SWING_BLOCKS, SWING_DRIVE_S, SWING_REST_S, FIRST_REST_S = 3, 1800, 600, 60
CONTACT_OHM = 0.010
NOISE = {"voltage_v": 1e-3, "t_surface_c": 0.05, "current_a": 5e-3}
CASES = {
    "none": {"seed": 21},
    "capacity": {"seed": 22, "am_factor": 0.85},
    "current_offset": {"seed": 23, "offset_a": 0.1},
    "cooling_change": {"seed": 24, "h_after": 2.5, "t_change_s": 1200.0},
    "arrhenius": {"seed": 25, "arrhenius": True},
    "none_2": {"seed": 26},          # two more no-effect records (other drives): the false-selection rate
    "none_3": {"seed": 27},
    # PyBaMM's own contact resistance; the same drive as ``none`` (seed 21): the pair a lab has when it
    # retests a cell after a connector change
    "contact_resistance": {"seed": 21, "contact_ohm": CONTACT_OHM},
    # the published entropic change of this very cell (LG M50, O'Regan et al. 2022, PyBaMM's ORegan2022 set)
    "entropic": {"seed": 28, "entropic": True},
    # the "swing" protocol (a wide SOC swing with rest stops): the records a capacity or a current-sensor
    # offset is identifiable from, and two no-effect records of it
    "none_swing": {"seed": 31, "protocol": "swing"},
    "capacity_swing": {"seed": 32, "protocol": "swing", "am_factor": 0.85},
    "current_offset_swing": {"seed": 33, "protocol": "swing", "offset_a": 0.1},
    "none_swing_2": {"seed": 34, "protocol": "swing"},
    # no effect, with PyBaMM's heat of mixing (the drives of none and none_2): a cell whose heat is its whole
    # electrical loss, so that it warms more (to 36 and 44 degC) while its SOC falls
    "none_mixing": {"seed": 21, "mixing": True},
    "none_2_mixing": {"seed": 26, "mixing": True},
    # the entropic record's drive and cell with the heat of mixing (its dU/dT measured beside the whole loss)
    "entropic_mixing": {"seed": 28, "entropic": True, "mixing": True},
    "none_swing_mixing": {"seed": 31, "protocol": "swing", "mixing": True},
    # a reviewer's record (sixth session): 8 % lost capacity, the heat of mixing, rest stops of 420 s - barely
    # longer than the cell's own slow relaxation (Chen2020's positive particle: R^2/(pi^2 D) = 690 s), so that a
    # true capacity is fitted with the slow RC branch at the record's time-constant limit
    "capacity_swing_420": {"seed": 50, "protocol": "swing", "am_factor": 0.92, "mixing": True, "rest_s": 420},
}
T_REF_K = 298.15
EXCHANGE = ("Negative electrode exchange-current density [A.m-2]",
            "Positive electrode exchange-current density [A.m-2]")


ENTROPIC = ("Negative electrode OCP entropic change [V.K-1]", "Positive electrode OCP entropic change [V.K-1]")


def params(arrhenius: bool = False, entropic: bool = False):
    """Chen2020; the exchange-current densities at 25 degC whatever the temperature unless ``arrhenius``
    (then Chen2020's own Arrhenius factors: 35 kJ/mol graphite, 17.8 kJ/mol NMC811).  Chen2020's electrode
    OCPs have no entropic change (zero); ``entropic`` switches in the published LG M50 ones (O'Regan et al.,
    Electrochim. Acta 425 (2022) 140700: PyBaMM's ``ORegan2022`` set, the same cell)."""
    p = pybamm.ParameterValues("Chen2020")
    if entropic:
        o = pybamm.ParameterValues("ORegan2022")
        for k in ENTROPIC:
            p[k] = o[k]
    p["Upper voltage cut-off [V]"] = 4.4      # regen pulses near full charge pass 4.2 V briefly
    if not arrhenius:
        for k in EXCHANGE:
            f = p[k]
            p[k] = (lambda f: lambda c_e, c_s_surf, c_s_max, T: f(c_e, c_s_surf, c_s_max, T_REF_K))(f)
    return p


def apparent_activation_k() -> float:
    """The Arrhenius cell's apparent Ea/R of its 10 s pulse resistance (the quantity shevsim's
    ``arrhenius_ea_r_k`` scales all resistances with): 1C discharge pulse from rest at 60 % SOC,
    isothermal at 25 and 35 degC; Ea/R = ln(R25 / R35) / (1/T25 - 1/T35)."""
    r = {}
    for tc in (25.0, 35.0):
        p = params(arrhenius=True)
        p["Ambient temperature [K]"] = 273.15 + tc
        p["Initial temperature [K]"] = 273.15 + tc
        p["Current function [A]"] = 5.0
        sim = pybamm.Simulation(pybamm.lithium_ion.SPMe(), parameter_values=p)
        sol = sim.solve([0.0, 10.0], initial_soc=0.6)
        ocv0 = float(sol["Battery open-circuit voltage [V]"].entries[0])     # at rest, before the pulse
        r[tc] = (ocv0 - float(sol["Voltage [V]"].entries[-1])) / 5.0
    return float(np.log(r[25.0] / r[35.0]) / (1.0 / 298.15 - 1.0 / 308.15))


def current_profile(rng, protocol: str = "drive", rest_s: int = SWING_REST_S):
    """1 Hz current levels [A] of a protocol (+ discharge).  ``drive``: a 60 s rest, then pulses held 5-40 s
    (rest 20 %, charge U(-1C, 0) 30 %, discharge U(0, 2C) 50 %) to 3600 s.  ``swing``: a 60 s rest, then
    ``SWING_BLOCKS`` blocks of ``SWING_DRIVE_S`` of pulses (rest 15 %, charge U(-0.7C, 0) 25 %, discharge
    U(0, 1.6C) 60 %: mean about 0.39C; regeneration at 95 % SOC up to 0.7C keeps the cell below 4.4 V) each
    followed by a rest stop of ``rest_s`` (default ``SWING_REST_S``; the last one 60 s shorter)."""
    n = (int(DURATION_S[protocol]) if protocol == "drive"
         else FIRST_REST_S + SWING_BLOCKS * (SWING_DRIVE_S + rest_s) - 60) + 1
    i = np.zeros(n)
    if protocol == "drive":
        k = FIRST_REST_S
        while k < n:
            seg = int(rng.uniform(5, 40))
            i[k:k + seg] = rng.choice([0.0, rng.uniform(-5.0, 0.0), rng.uniform(0.0, 10.0)], p=[0.2, 0.3, 0.5])
            k += seg
        return np.arange(n, dtype=float), i
    for blk in range(SWING_BLOCKS):
        k = FIRST_REST_S + blk * (SWING_DRIVE_S + rest_s)
        end = k + SWING_DRIVE_S
        while k < end:
            seg = min(int(rng.uniform(5, 40)), end - k)
            i[k:k + seg] = rng.choice([0.0, rng.uniform(-3.5, 0.0), rng.uniform(0.0, 8.0)], p=[0.15, 0.25, 0.6])
            k += seg
    return np.arange(n, dtype=float), i


def cell_dudt(soc_table, q_ah: float) -> np.ndarray:
    """The entropic cell's dU/dT [V/K] at the nominal table's SOC (``soc_table`` = 1 - discharged A.h / 5 A.h,
    the SOC the calibration works in): dU_p/dT(y) - dU_n/dT(x), the ORegan2022 functions at the electrode
    stoichiometries of that SOC (PyBaMM's SOC of its stoichiometry window between the OCV limits:
    s = 1 - (1 - soc_table) 5 A.h / ``q_ah``, ``q_ah`` the C/50 capacity; the mapping that
    ``test_calibrate_independent_cell.py`` checks the pseudo-OCV with)."""
    p = pybamm.ParameterValues("Chen2020")
    o = pybamm.ParameterValues("ORegan2022")
    x0, y0 = pybamm.lithium_ion.get_initial_stoichiometries(0.0, p)
    x1, y1 = pybamm.lithium_ion.get_initial_stoichiometries(1.0, p)
    s = 1.0 - (1.0 - np.asarray(soc_table, float)) * 5.0 / q_ah
    x, y = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
    return np.asarray(o[ENTROPIC[1]](y), float) - np.asarray(o[ENTROPIC[0]](x), float)


def simulate(case: dict, t, i_true):
    p = params(case.get("arrhenius", False), case.get("entropic", False))
    if "am_factor" in case:
        for e in ("Negative", "Positive"):
            k = f"{e} electrode active material volume fraction"
            p[k] = p[k] * case["am_factor"]
    if "h_after" in case:
        h0 = p["Total heat transfer coefficient [W.m-2.K-1]"]
        p["Total heat transfer coefficient [W.m-2.K-1]"] = (
            h0 + (case["h_after"] - h0) * pybamm.sigmoid(case["t_change_s"], pybamm.t, 0.5))
    opts = {"thermal": "lumped"}
    if case.get("mixing"):
        opts["heat of mixing"] = "true"
    if "contact_ohm" in case:
        opts["contact resistance"] = "true"
        p["Contact resistance [Ohm]"] = case["contact_ohm"]
    p["Current function [A]"] = pybamm.Interpolant(t, i_true, pybamm.t)
    model = pybamm.lithium_ion.SPMe(opts)
    sim = pybamm.Simulation(model, parameter_values=p, solver=pybamm.IDAKLUSolver())
    sol = sim.solve(t_eval=[t[0], t[-1]], t_interp=t, initial_soc=SOC0[case.get("protocol", "drive")])
    if sol.t.size != t.size:
        raise SystemExit(f"PyBaMM stopped at t = {sol.t[-1]:.0f} s: {sol.termination}")
    return sol["Voltage [V]"].entries, sol["Volume-averaged cell temperature [C]"].entries


def pseudo_ocv():
    p = params()
    model = pybamm.lithium_ion.SPMe({"thermal": "lumped"})
    exp = pybamm.Experiment(["Discharge at C/50 until 2.5 V (60 second period)"])
    sol = pybamm.Simulation(model, parameter_values=p, experiment=exp).solve(initial_soc=1.0)
    ah = sol["Discharge capacity [A.h]"].entries
    v = sol["Voltage [V]"].entries
    soc = 1.0 - ah / 5.0
    grid = np.linspace(max(soc.min(), 0.0), 1.0, 41)
    order = np.argsort(soc)
    return grid, np.interp(grid, soc[order], v[order]), float(ah[-1])


def log_record(path: Path, comment: str, rng, t, i_true, v, temp, offset_a: float = 0.0) -> None:
    """The logger: current (+ ``offset_a``), voltage and temperature with white noise ``NOISE`` (drawn from
    ``rng`` in that order), written as the record's CSV at 1 Hz under the ``comment`` line."""
    i_log = i_true + offset_a + rng.normal(0.0, NOISE["current_a"], t.size)
    v_log = v + rng.normal(0.0, NOISE["voltage_v"], t.size)
    ts_log = temp + rng.normal(0.0, NOISE["t_surface_c"], t.size)
    lines = [comment, "time_s,current_a,voltage_v,t_surface_c,t_ambient_c"]
    lines += [f"{a:.1f},{b:.4f},{c:.5f},{d:.3f},25.0" for a, b, c, d in zip(t, i_log, v_log, ts_log)]
    path.write_text("\n".join(lines) + "\n")


def main() -> int:
    grid, ocv, cap = pseudo_ocv()
    grid[0] = 0.0   # the table's lowest point (the C/50 run ends at 2.5 V near SOC 0)
    nom = ["[meta]", f'source = "PyBaMM {pybamm.__version__} Chen2020 (LG M50): rated 5 A.h; pseudo-OCV at C/50 '
           f'(measured {cap:.3f} A.h); make_cell_pybamm.py"', "[params]", "capacity_ah = 5.0", "soc0_frac = -1.0", "rc_pairs = 2",
           "radius_m = 0.0105", "length_m = 0.07", "h_conv_w_m2k = 10.0",
           "[ocv]", "soc_frac = [" + ", ".join(f"{x:.4f}" for x in grid) + "]",
           "ocv_v = [" + ", ".join(f"{x:.5f}" for x in ocv) + "]"]
    (OUT / "cell_nominal.toml").write_text("\n".join(nom) + "\n")
    ea_r = apparent_activation_k()
    truth = {"generator": f"PyBaMM {pybamm.__version__} SPMe + lumped thermal, Chen2020, 1 Hz instantaneous",
             "noise": NOISE, "pseudo_ocv_capacity_ah": cap, "arrhenius_apparent_ea_r_k": ea_r, "cases": {}}
    for name, case in CASES.items():
        rng = np.random.default_rng(case["seed"])
        proto = case.get("protocol", "drive")
        t, i_true = current_profile(rng, proto, case.get("rest_s", SWING_REST_S))
        v, temp = simulate(case, t, i_true)
        log_record(OUT / f"cell_{name}.csv", f"# PyBaMM {pybamm.__version__} SPMe/Chen2020 record, case '{name}' "
                   "(make_cell_pybamm.py)", rng, t, i_true, v, temp, case.get("offset_a", 0.0))
        tr = {"capacity_ah": 5.0 * case.get("am_factor", 1.0), "current_offset_a": case.get("offset_a", 0.0),
              "h_change_factor": case.get("h_after", 10.0) / 10.0, "h_change_time_s": case.get("t_change_s"),
              "arrhenius_ea_r_k": ea_r if case.get("arrhenius") else 0.0,
              # the series resistance added to the cell's (PyBaMM's contact resistance) [Ohm]
              "series_resistance_added_ohm": case.get("contact_ohm", 0.0)}
        # the SOC the record visits, in the nominal table's terms (true current, true capacity)
        soc_tab = (1.0 - (1.0 - SOC0[proto]) * cap / 5.0) - np.cumsum(i_true) / 3600.0 / tr["capacity_ah"]
        if case.get("entropic"):
            grid = np.linspace(0.0, 1.0, 41)
            lo, hi = float(soc_tab.min()), float(soc_tab.max())
            knots = np.linspace(lo, hi, 4)      # the calibration's dudt knots: 4 over the SOC range visited
            tr.update(dudt_soc_frac=[round(float(x), 4) for x in grid],
                      dudt_v_k=[float(x) for x in cell_dudt(grid, cap)],
                      dudt_knots_soc_frac=[float(x) for x in knots], dudt_knots_v_k=[float(x) for x in cell_dudt(knots, cap)],
                      dudt_mean_visited_v_k=float(np.mean(cell_dudt(soc_tab, cap))))
        else:
            tr.update(dudt_mean_visited_v_k=0.0)
        truth["cases"][name] = {"pybamm_inputs": {k: x for k, x in case.items() if k not in ("seed", "protocol")}, "seed": case["seed"],
                                "truth": tr, "file": f"cell_{name}.csv", "v_min": float(v.min()), "v_max": float(v.max()),
                                "t_max_c": float(temp.max()),
                                "protocol": proto, "soc_table_range": [float(soc_tab.min()), float(soc_tab.max())]}
        print(name, f"V {v.min():.3f}-{v.max():.3f}  T max {temp.max():.2f} C  SOC {soc_tab.min():.3f}-{soc_tab.max():.3f}",
              flush=True)
    # the particles' own solid diffusion (in every record): the truth of the solid_diffusion effect
    from diffusion_times import electrode_diffusion_times_s
    truth["solid_diffusion_time_s"] = electrode_diffusion_times_s('Chen2020')
    (OUT / "cell_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
