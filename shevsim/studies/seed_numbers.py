"""seed_numbers.py - the thesis-comparison numbers quoted in README.md and docs/seed_fidelity.md, made by one script.

Every number of the README's *Results* tables that compares with the thesis, and of ``docs/seed_fidelity.md``, is
computed here into ``docs/figures/seed_numbers.json`` and rendered into the documents' marked blocks
(``<!-- BEGIN seed:NAME -->`` ... ``<!-- END seed:NAME -->``), so a table is never typed by hand. A test
(``tests/unit/test_seed_numbers.py``) fails when a block no longer matches the JSON and when a cheap section,
recomputed from the current code, no longer matches the JSON (the slow variant recomputes every section).

Sections (``python -m shevsim.studies.seed_numbers --only NAME ...``; all by default):

=============  ===================================================================================  ==========
``runs``       whole-vehicle runs of the bundled scenarios (A.1, ΔSOC-corrected fuel economy, soot,      ~30 s
               Ah-processed, SOC, speed miss, closure, max core temperature)
``fig_4_9``    Ch. IV Fig. 4.9 analogue (:mod:`shevsim.studies.ch4_study`)                              ~5 s
``fig_4_10``   Ch. IV Fig. 4.10 analogue: power capability on a pulse train (:func:`ch4_study.fig_4_10`)  ~3 s
``table_3_3``  Table 3.3 at 1 s and 0.1 s with the converted tuning, three seeds                       ~2 min
               (:func:`shevsim.studies.bms_study.table_3_3_rates`)
``a1_gap``     the A.1 fuel-economy gap by factor (:mod:`shevsim.studies.a1_gap`)                       ~20 s
``bms``        DEKF replay (Figs. 5.11-5.12) and the cooling fault (Fig. 5.15),                         ~1 min
               :mod:`shevsim.studies.bms_study`
``tradeoff``   App. A Fig. A.2: constant power-rate limits on the reproduction and transient variant    ~1 min
``app_a``      App. A.3 map optimisation at full size: read from the ``summary.json`` of               (file)
               ``shevsim study powerrate-map uac_proxy_mpc_seed`` (GA 30 x 50 + 648 cases; minutes), given
               by ``--app-a-summary``
=============  ===================================================================================  ==========

Run: ``python -m shevsim.studies.seed_numbers [--only ...] [--app-a-summary PATH] [--write-docs]``.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

from shevsim.core.paths import DATA_ROOT

__all__ = ["SECTIONS", "RUN_SCENARIOS", "compute", "render", "update_docs", "load_numbers", "NUMBERS_PATH",
           "DOC_FILES"]

NUMBERS_PATH = DATA_ROOT / "docs" / "figures" / "seed_numbers.json"
DOC_FILES = (DATA_ROOT / "README.md", DATA_ROOT / "docs" / "seed_fidelity.md", DATA_ROOT / "docs" / "bms_results.md")
RUN_SCENARIOS = ("hd_udds_rule", "hd_udds_mpc", "uac_proxy_rule", "uac_proxy_mpc", "uac_proxy_mpc_cooling_fault",
                 "hd_udds_rule_seed", "hd_udds_mpc_seed")
TRADEOFF_RATES_KWPS = (30, 25, 22.5, 20, 19.3, 17.5, 15, 12.5, 10, 7.5, 5)


def _runs() -> dict:
    import numpy as np

    from shevsim.run import run
    out = {}
    for name in RUN_SCENARIOS:
        res = run(name)
        m = res.metrics
        keep = ("fuel_economy_soc_sustained_kmpl", "soc_sustained_windows_count", "fuel_economy_dsoc_corrected_kmpl",
                "soot_g_per_km", "soot_dsoc_corrected_g_per_km", "soot_per_fuel_g_per_kg", "ah_effective_cell_ah",
                "delta_soc_pct", "soc_min_pct", "soc_max_pct", "speed_miss_rms_kmh", "energy_closure_error_frac",
                "supervisor.fallback_count", "distance_km")
        row = {k: m.get(k) for k in keep}
        row["termination"] = str(res.termination)
        row["t_core_max_c"] = float(np.max(res["battery.t_core_c"]))
        if "bms.soc_pct" in res:
            err = np.abs(np.asarray(res["bms.soc_pct"]) - np.asarray(res["battery.soc_pct"]))
            t = np.asarray(res.time_s)
            row["bms_soc_err_max_after_600s_pct"] = float(err[t >= 600.0].max())
            row["bms_soc_err_end_pct"] = float(res["bms.soc_pct"][-1] - res["battery.soc_pct"][-1])
        out[name] = row
    return out


def _fig_4_9() -> dict:
    from shevsim.studies.ch4_study import fig_4_9
    return fig_4_9(None)


def _fig_4_10() -> dict:
    from shevsim.studies.ch4_study import fig_4_10
    res = fig_4_10(None)
    res.pop("_traces")
    return res


def _table_3_3() -> dict:
    from shevsim.studies.bms_study import table_3_3_rates
    r = table_3_3_rates(None, seeds=(0, 1, 2), duration_s=3600.0, dt_values=(1.0, 0.1), wrong_h0_factors=(2.0, 0.5),
                        tuning_ref_dt_s=1.0)
    return {"dt_s": {str(k): v for k, v in r["dt_s"].items()}, "fit": {str(k): v for k, v in r["fit"].items()},
            "seeds": r["seeds"], "tuning_ref_dt_s": r["tuning_ref_dt_s"], "seed_table": r["seed_table"]}


def _a1_gap() -> dict:
    from shevsim.studies.a1_gap import a1_gap
    return a1_gap(None)


def _bms() -> dict:
    import tempfile

    from shevsim.studies.bms_study import dekf_study, power_capability_study
    with tempfile.TemporaryDirectory() as tmp:
        dk = dekf_study(Path(tmp) / "dekf", seed=1)
        pc = power_capability_study(Path(tmp) / "power", seed=1)
    keep_d = ("soc_time_below_2pct_s", "soc_err_max_after_settle_pct", "soc_err_final_pct", "rs_rel_err_max_loaded",
              "heat_rmse_rel_mean", "heat_floor_rel_mean")
    keep_r = ("t_core_max_c", "time_battery_power_beyond_same_step_limits_s",
              "battery_power_beyond_same_step_limits_max_w", "distance_m", "termination", "end_s")
    return {"dekf": {k: dk.get(k) for k in keep_d},
            "cooling_fault": {run: {k: v.get(k) for k in keep_r} for run, v in pc["runs"].items()}}


def _tradeoff() -> dict:
    from shevsim.studies.parallel import StudyRunner
    from shevsim.studies.problem import ScenarioProblem
    from shevsim.studies.tradeoff import run_tradeoff
    from shevsim.core.paths import bundled_scenario
    out = {}
    for name in ("uac_proxy_mpc_seed", "uac_proxy_mpc_seed_transient"):
        prob = ScenarioProblem(str(bundled_scenario(name)), "supervisor")
        with StudyRunner(None, progress=False) as runner:
            s = run_tradeoff(prob, runner, [1e3 * r for r in TRADEOFF_RATES_KWPS], None, prob.default_edges(),
                             plots=False, log=lambda *_: None)
        out[name] = [{"rate_kwps": r["rate_wps"] / 1e3, "fe_change_pct": r["fe_change_pct"],
                      "soot_change_pct": r["soot_change_pct"]} for r in s["rows"]]
    return out


def _app_a(summary_path: str | Path | None) -> dict | None:
    if summary_path is None:
        return None
    s = json.loads(Path(summary_path).read_text())
    keep = {"config": s["config"], "baseline": s["baseline"], "best_map": s["best_map"],
            "best_constant": s["best_constant"], "ratio": s["soot_reduction_ratio_map_vs_constant"],
            "ga": {k: v for k, v in s["ga"].items() if k != "history"}, "narrowed": s["narrowed"],
            "performance": s["performance"], "constant_limits": s["constant_limits"],
            "top_solutions": s.get("top_solutions", [])}
    return keep


SECTIONS = {"runs": _runs, "fig_4_9": _fig_4_9, "fig_4_10": _fig_4_10, "table_3_3": _table_3_3, "a1_gap": _a1_gap,
            "bms": _bms, "tradeoff": _tradeoff}


def compute(only=None, app_a_summary=None, base: dict | None = None) -> dict:
    """Compute the sections in ``only`` (default all) on top of ``base`` (e.g. the committed JSON)."""
    numbers = dict(base or {})
    for name, fn in SECTIONS.items():
        if only is None or name in only:
            numbers[name] = _jsonable(fn())
    if app_a_summary is not None:
        numbers["app_a"] = _jsonable(_app_a(app_a_summary))
    return numbers


def _jsonable(x):
    return json.loads(json.dumps(x, default=lambda o: float(o) if hasattr(o, "__float__") else str(o)))


def load_numbers(path: Path = NUMBERS_PATH) -> dict:
    return json.loads(Path(path).read_text())


# ------------------------------------------------------------------------------------------------ rendering
def _f(x, d: int = 3, sign: bool = False) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    s = f"{x:+.{d}f}" if sign else f"{x:.{d}f}"
    return s.replace("-", "−") if sign else s


def _block_runs(n: dict) -> str:
    rows = ["| scenario | A.1 [km/L] (windows) | ΔSOC-corrected [km/L] | soot raw / corrected [g/km] | soot per fuel "
            "[g/kg] | Ah_eff per cell [Ah] | ΔSOC [%] | SOC range [%] | max \\|SOC estimate error\\| after 600 s [%] | "
            "speed miss RMS [km/h] | max core [°C] |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in [x for x in RUN_SCENARIOS if x in n["runs"]]:
        r = n["runs"][name]
        a1 = _f(r["fuel_economy_soc_sustained_kmpl"])
        rows.append(f"| `{name}` | {a1} ({r['soc_sustained_windows_count']}) | {_f(r['fuel_economy_dsoc_corrected_kmpl'])} "
                    f"| {_f(r['soot_g_per_km'], 4)} / {_f(r['soot_dsoc_corrected_g_per_km'], 4)} "
                    f"| {_f(r['soot_per_fuel_g_per_kg'], 3)} | {_f(r['ah_effective_cell_ah'], 2)} "
                    f"| {_f(r['delta_soc_pct'], 1, True)} | {_f(r['soc_min_pct'], 1)}–{_f(r['soc_max_pct'], 1)} "
                    f"| {_f(r.get('bms_soc_err_max_after_600s_pct'), 2)} | {_f(r['speed_miss_rms_kmh'], 3)} "
                    f"| {_f(r['t_core_max_c'], 1)} |")
    runs = n["runs"]
    if {"hd_udds_mpc_seed", "hd_udds_rule_seed"} <= set(runs):
        a, b = runs["hd_udds_mpc_seed"]["fuel_economy_soc_sustained_kmpl"], runs["hd_udds_rule_seed"]["fuel_economy_soc_sustained_kmpl"]
        if a and b:
            rows += ["", f"A.1 over four HD-UDDS cycles: MPC {_f(a)} km/L against the rule-based baseline's {_f(b)} km/L "
                         f"({_f(100 * (a / b - 1), 1, True)} %)."]
    return "\n".join(rows)


def _block_fig_4_9(n: dict) -> str:
    f = n["fig_4_9"]
    th = f["thesis"]
    rows = ["| | thesis (Fig. 4.9) | ours (mass 45 g; 40.5 g / 49.5 g) |", "|---|---|---|"]
    r0, r1, r2 = f["runs"]
    rows.append(f"| constant current [A] | not given | {_f(r0['current_a'], 3)} (from 2.3 Ah / 2133 s) |")
    rows.append(f"| R_e inferred from the 87 °C peak [mΩ] | not given | {_f(1e3 * r0['r_e_ohm'], 1)} "
                f"({_f(1e3 * r1['r_e_ohm'], 1)} / {_f(1e3 * r2['r_e_ohm'], 1)}) |")
    rows.append(f"| peak without limit [°C] | {th['t_peak_unlimited_c']:g} | {_f(r0['t_peak_unlimited_c'], 2)} (fitted) |")
    rows.append(f"| completion without limit [s] | {th['completion_unlimited_s']:g} | {_f(r0['completion_unlimited_s'], 0)} (by the current) |")
    rows.append(f"| peak with the limit [°C] | ~45 | {_f(r0['t_peak_limited_c'], 2)} |")
    rows.append(f"| completion with the limit [s] (the prediction) | {th['completion_limited_s']:g} | "
                f"**{_f(r0['completion_limited_s'], 0)}** ({_f(r1['completion_limited_s'], 0)} / "
                f"{_f(r2['completion_limited_s'], 0)}); {_f(f['completion_limited_error_pct'], 1, True)} % |")
    return "\n".join(rows)


def _block_fig_4_10(n: dict) -> str:
    f = n["fig_4_10"]
    th, st, sp = f["thesis"], f["settings"], f["spans"]

    def eps(name):
        e = sp[name]["episodes"]
        return "; ".join(f"{a:.0f}–{b:.0f}" if b > a else f"{a:.0f}" for a, b in e) if e else "never"

    rows = ["| | thesis (Fig. 4.10) | ours (analogue) |", "|---|---|---|",
            f"| cell | e-Moli ICR18650J, OCV-R-RC-RC (tables not published) | the Fig. 4.9 cell as OCV-R: R_e "
            f"{_f(1e3 * st['r_e_ohm'], 1)} mΩ, {st['mass_kg'] * 1e3:g} g, c_p {st['cp_j_kgk']:g} J/kg/K; LCO/graphite OCV "
            f"(PyBaMM Ramadass 2004) |",
            f"| request | robot duty cycles (ref. [93], not published) | {st['pulse_period_s']:g} s period, "
            f"{100 * st['pulse_duty']:g} % on at {_f(st['pulse_w'], 2)} W: mean = 1C power 2.3 A × mean OCV "
            f"{_f(st['ocv_mean_v'], 3)} V = {_f(st['p_1c_w'], 2)} W |",
            f"| ambient, convection, horizon | {th['t_amb_c']:g} °C, 6 W/m²K, 10 s at 10 Hz | {st['t_amb_c']:g} °C, "
            f"{st['h_w_m2k']:g} W/m²K, {st['horizon_steps'] * st['dt_s']:g} s at {1 / st['dt_s']:g} Hz |",
            f"| limits | V_min {th['v_min_v']:g} V, T_max {th['t_max_c']:g} °C, SOC_min not given | V_min "
            f"{st['v_min_v']:g} V, T_max {st['t_max_c']:g} °C, SOC_min {st['soc_min_frac']:g} (assumed) |",
            f"| all constraints inactive until [s] | 4705 | {_f(min(v['first_s'] for v in sp.values() if v['first_s'] is not None), 0)} |",
            f"| voltage limit sets the power [s] | {th['voltage_active_from_s']:g}–{th['voltage_active_to_s']:g} | {eps('voltage')} |",
            f"| temperature limit sets the power [s] | after 5740, until SOC | {eps('temperature')} |",
            f"| SOC limit sets the power [s] | at the end | {eps('soc')} |",
            f"| order in which they first act | {' → '.join(th['order'])} | {' → '.join(f['order'])} |",
            f"| min voltage / max temperature / end SOC | ≥ 3.2 V / ≤ 45 °C / – | {_f(f['v_min_run_v'], 3)} V / "
            f"{_f(f['t_max_run_c'], 2)} °C / {_f(100 * f['soc_end_frac'], 2)} % at {_f(f['end_s'], 0)} s |",
            f"| energy drawn / requested [Wh] | – | {_f(f['energy_drawn_wh'], 2)} / {_f(f['energy_requested_wh'], 2)} |"]
    return "\n".join(rows)


def _block_table_3_3(n: dict) -> str:
    t = n["table_3_3"]
    seed = t["seed_table"]
    lab = {"I": "I", "II": "II", "III": "III, DKF/JEKF from 2 h*", "III_h0_x0.5": "III, DKF/JEKF from h*/2",
           "III_h0_star": "III, DKF/JEKF from θ̂(0) = 56.2 = h* (the thesis's literal setting)"}

    def cell(row):
        return " · ".join(f"{row[k]['core_c']:.3f}±{row[k]['core_sd_c']:.3f}/{row[k]['surface_c']:.3f}±"
                          f"{row[k]['surface_sd_c']:.3f}" for k in ("KF", "DKF", "JEKF"))

    rows = ["| stage | thesis | dt = 1 s | dt = 0.1 s |", "|---|---|---|---|"]
    for key, name in lab.items():
        st = key.split("_")[0]
        th = " · ".join(f"{seed[st][k][0]:.2f}/{seed[st][k][1]:.2f}" for k in ("KF", "DKF", "JEKF")) \
            if key in ("I", "II", "III") else ("as III" if key == "III_h0_star" else "–")
        rows.append(f"| {name} | {th} | {cell(t['dt_s']['1.0'][key])} | {cell(t['dt_s']['0.1'][key])} |")
    fit = {dt: {lit: _fit(t["dt_s"][dt], seed, lit) for lit in (True, False)} for dt in ("1.0", "0.1")}
    rows.append(f"| mean \\|log(ours / thesis)\\| over the 18 cells, stage III's DKF/JEKF from θ̂(0) = h* | | "
                f"{_f(fit['1.0'][True], 2)} | {_f(fit['0.1'][True], 2)} |")
    rows.append(f"| the same, stage III's DKF/JEKF from 2 h* | | {_f(fit['1.0'][False], 2)} | {_f(fit['0.1'][False], 2)} |")
    return "\n".join(rows)


def _fit(rows: dict, seed: dict, literal: bool) -> float:
    """Mean |log(ours / thesis)| over stages I-III x KF, DKF, JEKF x core, surface."""
    errs = []
    for st, theirs in seed.items():
        for k, (tc, ts) in theirs.items():
            row = rows["III_h0_star"] if (st == "III" and k != "KF" and literal) else rows[st]
            errs += [abs(math.log(row[k]["core_c"] / tc)), abs(math.log(row[k]["surface_c"] / ts))]
    return sum(errs) / len(errs)


def _block_a1_gap(n: dict) -> str:
    g = n["a1_gap"]
    label = {"baseline": "reproduction (UAC proxy × 4, MPC)",
             "cycle": "sensitivity to the cycle: HD-UDDS × 4 instead of the UAC proxy (not a share: the real UAC is neither)",
             "drag": "drag coefficient 0.7 → 0.6", "rolling": "rolling coefficient 0.012 → 0.008",
             "fuel_map": f"fuel map × {g['fuel_factor']:g} (10 % better BSFC)", "all": "drag + rolling + fuel map"}
    rows = ["| run | A.1 [km/L] (windows) | ΔSOC-corrected [km/L] | change [km/L] | share of the gap |", "|---|---|---|---|---|"]
    for k in [x for x in label if x in g["runs"]]:
        v = g["runs"][k]
        rows.append(f"| {label[k]} | {_f(v['a1_kmpl'])} ({v['a1_windows']}) | {_f(v['dsoc_corrected_kmpl'])} "
                    f"| {_f(v['change_kmpl'], 3, True)} | {_f(v['share_of_gap_pct'], 0, True)} % |")
    rows.append(f"| thesis (real UAC) | {g['thesis_a1_kmpl']:.3f} | | gap {_f(g['gap_kmpl'], 3)} | |")
    base = g["runs"]["baseline"]
    rows += ["", f"Changes and shares are on the ΔSOC-corrected basis (every run has it); the thesis's 3.278 km/L is an A.1 "
                 f"figure, against which our A.1 ({_f(base['a1_kmpl'])} km/L) leaves a gap of "
                 f"{_f(g['thesis_a1_kmpl'] - base['a1_kmpl'], 3)} km/L."]
    return "\n".join(rows)


def _block_bms(n: dict) -> str:
    b = n["bms"]
    d, cf = b["dekf"], b["cooling_fault"]
    rows = ["| | thesis | ours |", "|---|---|---|",
            f"| Fig. 5.12: heat-generation RMSE / mean | < 0.2 % | {_f(100 * d['heat_rmse_rel_mean'], 2)} % |",
            f"| Fig. 5.11: SOC error below 2 % from | – | {_f(d['soc_time_below_2pct_s'], 0)} s (start 10 % off) |",
            f"| SOC error after the first cycle, max / end | – | {_f(d['soc_err_max_after_settle_pct'], 2)} % / "
            f"{_f(d['soc_err_final_pct'], 2, True)} % |",
            f"| Fig. 5.15: max core, limits within the step | ≤ 45 °C | {_f(cf['limited']['t_core_max_c'], 3)} °C |",
            f"| beyond the same-step limits (> 1 kW) | – | {_f(cf['limited']['time_battery_power_beyond_same_step_limits_s'], 1)} s |",
            f"| max core without a thermal limit | above 45 °C | {_f(cf.get('no_thermal_limit', {}).get('t_core_max_c'), 1)} °C |"]
    return "\n".join(rows)


def _block_tradeoff(n: dict) -> str:
    t = n["tradeoff"]
    q, tr = t["uac_proxy_mpc_seed"], t["uac_proxy_mpc_seed_transient"]
    head = "| constant ΔP_g,max [kW/s] | " + " | ".join(f"{r['rate_kwps']:g}" for r in q) + " |"
    rows = [head, "|" + "---|" * (len(q) + 1),
            "| fuel economy change [%] | " + " | ".join(_f(r["fe_change_pct"], 2, True) for r in q) + " |",
            "| soot change, quasi-static (reproduction) [%] | " + " | ".join(_f(r["soot_change_pct"], 2, True) for r in q) + " |",
            "| soot change, transient variant [%] | " + " | ".join(_f(r["soot_change_pct"], 1, True) for r in tr) + " |"]
    return "\n".join(rows)


def _block_app_a(n: dict) -> str:
    a = n.get("app_a")
    if not a:
        return "(not computed: run `shevsim study powerrate-map uac_proxy_mpc_seed -o OUT` and pass `--app-a-summary OUT/summary.json`)"
    bm, bc, base = a["best_map"], a["best_constant"], a["baseline"]
    edges = ", ".join(f"{e / 1e3:.1f}" for e in a["config"]["edges_w"])
    ga = a["config"]["ga"]
    rows = [f"GA {ga['population']} × {ga['generations']} (crossover {ga['crossover_prob']}, mutation {ga['mutation_prob']}, "
            f"seed {ga['seed']}), {a['narrowed']['cases']} exhaustive cases, partition edges [{edges}] kW; "
            f"{a['performance']['new_evaluations']} new evaluations in {a['performance']['wall_s']:.0f} s.", "",
            "| | rates [kW/s] per partition | fuel economy | soot (ΔSOC-corrected) | Ah_eff per cell [Ah] |",
            "|---|---|---|---|---|",
            f"| baseline (30 kW/s) | | {_f(base['fuel_economy_kmpl'])} km/L | {_f(base['soot_g_per_km'], 5)} g/km | "
            f"{_f(base.get('ah_effective_cell_ah'), 3)} |",
            f"| best {bm.get('kind', 'map')} | {', '.join(f'{r / 1e3:g}' for r in bm['rates_wps'])} | "
            f"{_f(bm['fe_change_pct'], 2, True)} % | **{_f(bm['soot_change_pct'], 2, True)} %** | "
            f"{_f(bm.get('ah_effective_cell_ah'), 3)} ({_f(100 * (bm.get('ah_effective_cell_ah', math.nan) / base.get('ah_effective_cell_ah', math.nan) - 1), 1, True)} %) |"]
    if bc:
        rows.append(f"| best constant at the same constraint | {bc['rate_wps'] / 1e3:g} everywhere | "
                    f"{_f(bc['fe_change_pct'], 2, True)} % | {_f(bc['soot_change_pct'], 2, True)} % | "
                    f"{_f(bc.get('ah_effective_cell_ah'), 3)} |")
    rows.append(f"| thesis (Figs. A.4, A.7c) | | −0.3 % | map −4.0 %, constant −1.9 % (2×) | 3.51 → 3.71 Ah (+5.5 %) |")
    if a.get("ratio") is not None:
        rows += ["", f"Map vs best constant: **{a['ratio']:.2f}×** in soot reduction (thesis 2×)."]
    nar = a["narrowed"]
    rows += ["", f"Narrowed space: the {nar['k_used']} best GA maps ({a['ga']['distinct_evaluations']} distinct maps "
                 f"evaluated by the GA) bound {nar['cases']} cases (cap {a['config']['max_cases']})."]
    same = [t for t in a.get("top_solutions", []) if t["soot_g_per_km"] == bm["soot_g_per_km"]
            and t["fuel_economy_kmpl"] == bm["fuel_economy_kmpl"]]
    if len(same) > 1:
        parts = [i + 1 for i in range(len(bm["rates_wps"])) if len({t["rates_wps"][i] for t in same}) > 1]
        rows.append(f"The {len(same)} best maps give identical runs and differ only in partition(s) "
                    f"{', '.join(f'd{i}' for i in parts)}: the rate there is not identified by this cycle.")
    return "\n".join(rows)


BLOCKS = {"runs": _block_runs, "fig_4_9": _block_fig_4_9, "fig_4_10": _block_fig_4_10, "table_3_3": _block_table_3_3,
          "a1_gap": _block_a1_gap, "bms": _block_bms, "tradeoff": _block_tradeoff, "app_a": _block_app_a}
_BLOCK_RE = re.compile(r"(<!-- BEGIN seed:(?P<name>[a-z0-9_]+) -->\n)(?P<body>.*?)(<!-- END seed:(?P=name) -->)", re.S)


def render(numbers: dict) -> dict:
    """Block name -> markdown, for every block whose section is in ``numbers`` (app_a always)."""
    return {name: fn(numbers) for name, fn in BLOCKS.items() if name in numbers or name == "app_a"}


def marked_blocks(text: str) -> dict:
    return {m.group("name"): m.group("body")[:-1] if m.group("body").endswith("\n") else m.group("body")
            for m in _BLOCK_RE.finditer(text)}


def update_docs(numbers: dict, files=DOC_FILES) -> list[str]:
    """Rewrite every marked block of ``files`` from ``numbers``; returns the blocks rewritten."""
    from shevsim.core.atomic import write_text_atomic
    blocks = render(numbers)
    done = []
    for path in files:
        text = Path(path).read_text()

        def sub(m):
            name = m.group("name")
            if name not in blocks:
                return m.group(0)
            done.append(f"{Path(path).name}:{name}")
            return m.group(1) + blocks[name] + "\n" + m.group(4)
        new = _BLOCK_RE.sub(sub, text)
        if new != text:
            write_text_atomic(path, new)
    return done


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m shevsim.studies.seed_numbers", description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(SECTIONS), help="sections to recompute (default all)")
    ap.add_argument("--app-a-summary", help="summary.json of the full-size powerrate-map study")
    ap.add_argument("--out", default=str(NUMBERS_PATH), help="the numbers JSON (default docs/figures/seed_numbers.json)")
    ap.add_argument("--write-docs", action="store_true", help="rewrite the marked blocks of README.md and docs/seed_fidelity.md")
    a = ap.parse_args(argv)
    out = Path(a.out)
    base = load_numbers(out) if out.is_file() else {}
    numbers = compute(a.only, a.app_a_summary, base)
    from shevsim.core.atomic import write_text_atomic
    write_text_atomic(out, json.dumps(numbers, indent=1, sort_keys=True) + "\n")
    print(f"numbers in {out}")
    if a.write_docs:
        for b in update_docs(numbers):
            print(f"rewrote {b}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
