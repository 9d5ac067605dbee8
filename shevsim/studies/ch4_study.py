"""ch4_study.py - seed Ch. IV, Fig. 4.9: current limiting for temperature control (lumped cell, eq. 4.13).

The thesis discharges an e-Moli ICR18650J (2.3 Ah, LiCoO2) at a constant current at 25 degC and natural
convection (6 W/m2K), with the thermal current limit of eq. 4.13 at 10 Hz and a 100-sample horizon:
without the limit the cell reaches 87 degC and completes in 2133 s; with it the temperature stays around
45 degC and completion takes 4687 s.

What is and is not published, and what this study therefore does:

- c_p = 1248 J/kg/K (Sec. 4.2.2), h = 6 W/m2K, 2.3 Ah, 25 degC, T_max = 45 degC, 10 Hz, N = 100:
  from the thesis.
- The cell's mass and surface are not given: 45 g and the full surface of an 18 x 65 mm cylinder
  (4.18 cm2 ends included), typical of an 18650; varied by +-10 % in the sensitivity rows.
- The constant current is not given: it follows from the unlimited completion time, 2.3 Ah x 3600 / 2133 s
  = 3.88 A (1.69 C), for a discharge from SOC 1 to 0.
- R_e (lumped ohmic + polarisation resistance) is not given for the e-Moli cell: it is **inferred from one
  thesis number**, the unlimited run's 87 degC peak (a root find); the entropy change is set to zero (the
  thesis's Fig. 4.2 is a plot; its heat is folded into R_e by the inference).
- The limited run's completion time and temperature are then a **prediction** compared with the thesis's
  4687 s and ~45 degC: nothing is fitted to them.

Fig. 4.10 (power capability during repeated discharge duty cycles, 30 degC, 6 W/m2K, 10 s horizon at 10 Hz):
the thesis's robot duty cycle (its ref. [93]) and the e-Moli cell's OCV and ECM tables are not published, so
:func:`fig_4_10` is an analogue. The cell is the Fig. 4.9 cell above (R_e inferred from the 87 degC peak) used as
an OCV-R cell (eq. 4.6 without its RC branches), with an LCO/graphite OCV made once by PyBaMM from the
Ramadass 2004 set (``components/cell/lco_ocv_ramadass2004.csv``); the limits are 4.16a (SOC_min 0.1, assumed),
4.16b (V_min 3.2 V, the thesis's, OCV linearised at the present SOC) and 4.13a (45 degC); the capability is
4.18a/4.19a without RC terms. The request is an invented square pulse train whose level is set by one rule (the
cell's 1C power on average, see :func:`duty_cycle_request_w`); the times at which each constraint takes over
therefore depend on that invented cycle and are not comparable with the thesis's 4705 s and 5740 s; the order is.

Run: ``python -m shevsim.studies.ch4_study OUT`` (writes ``fig_4_9.json/.png`` and ``fig_4_10.json/.png``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from shevsim.bms.lumped import (LumpedCell, OcvTable, predicted_voltage, soc_current_limit, step_exact,
                                thermal_current_limits, voltage_current_limit)
from shevsim.core.paths import data_path

__all__ = ["THESIS_FIG_4_9", "THESIS_FIG_4_10", "emoli_cell", "constant_current_run", "infer_r_e", "fig_4_9",
           "duty_cycle_request_w", "power_capability_run", "fig_4_10", "LCO_OCV_CSV"]

THESIS_FIG_4_9 = {"t_peak_unlimited_c": 87.0, "completion_unlimited_s": 2133.0, "completion_limited_s": 4687.0,
                  "t_max_c": 45.0}
THESIS_FIG_4_10 = {"t_amb_c": 30.0, "v_min_v": 3.2, "t_max_c": 45.0, "voltage_active_from_s": 4705.0,
                   "voltage_active_to_s": 5740.0, "order": ["voltage", "temperature", "soc"]}
LCO_OCV_CSV = data_path("components", "cell", "lco_ocv_ramadass2004.csv")
CAPACITY_AH = 2.3
DT_S = 0.1
HORIZON_STEPS = 100
H_W_M2K = 6.0
T_AMB_C = 25.0


def emoli_cell(r_e_ohm: float, mass_kg: float = 0.045, area_m2: float | None = None) -> LumpedCell:
    """The Ch. IV cell: c_p from the thesis, an 18650's size (assumed), R_e given."""
    if area_m2 is None:
        r, length = 0.009, 0.065
        area_m2 = 2.0 * math.pi * r * length + 2.0 * math.pi * r * r
    return LumpedCell(mass_kg=mass_kg, cp_j_kgk=1248.0, area_m2=area_m2, r_e_ohm=r_e_ohm, capacity_ah=CAPACITY_AH)


def constant_current_run(cell: LumpedCell, i_req_a: float, limit: bool, t_max_c: float = 45.0,
                         dt_s: float = DT_S, horizon_steps: int = HORIZON_STEPS, h_w_m2k: float = H_W_M2K,
                         t_amb_c: float = T_AMB_C, soc0: float = 1.0, max_time_s: float = 20000.0) -> dict:
    """Discharge at ``i_req_a`` (or less, under the thermal limit 4.13a) until SOC reaches 0.

    Returns the traces (time_s, current_a, soc_frac, temperature_c) and ``completion_s`` (interpolated
    within the last step), ``t_peak_c``.
    """
    n_max = int(math.ceil(max_time_s / dt_s))
    t_c, soc = t_amb_c, soc0
    ts, cur, socs, temps = [0.0], [0.0], [soc], [t_c]
    completion = math.nan
    for k in range(n_max):
        i_a = i_req_a
        if limit:
            i_dch, _ = thermal_current_limits(cell, t_c, t_max_c, horizon_steps, dt_s, h_w_m2k, t_amb_c)
            i_a = min(i_req_a, max(i_dch, 0.0))
        d_soc = i_a * dt_s / (3600.0 * cell.capacity_ah)
        if d_soc >= soc and i_a > 0.0:        # completes within this step
            frac = soc / d_soc
            t_c = step_exact(cell, t_c, i_a, frac * dt_s, h_w_m2k, t_amb_c)
            completion = k * dt_s + frac * dt_s
            ts.append(completion); cur.append(i_a); socs.append(0.0); temps.append(t_c)
            break
        t_c = step_exact(cell, t_c, i_a, dt_s, h_w_m2k, t_amb_c)
        soc -= d_soc
        ts.append((k + 1) * dt_s); cur.append(i_a); socs.append(soc); temps.append(t_c)
    if len(cur) > 1:
        cur[0] = cur[1]                        # the current held over the first step, not a placeholder 0
    temps_a = np.asarray(temps)
    return {"time_s": np.asarray(ts), "current_a": np.asarray(cur), "soc_frac": np.asarray(socs),
            "temperature_c": temps_a, "completion_s": completion, "t_peak_c": float(temps_a.max())}


def infer_r_e(t_peak_c: float, i_req_a: float, mass_kg: float = 0.045) -> float:
    """R_e [ohm] for which the unlimited constant-current discharge peaks at ``t_peak_c``."""
    def miss(r_e):
        return constant_current_run(emoli_cell(r_e, mass_kg), i_req_a, limit=False)["t_peak_c"] - t_peak_c
    return float(brentq(miss, 1e-3, 2.0, xtol=1e-6))


def fig_4_9(out_dir: str | Path | None = None) -> dict:
    """The Fig. 4.9 analogue and its sensitivity to the assumed mass; writes JSON (+ PNG) into ``out_dir``."""
    th = THESIS_FIG_4_9
    i_req = CAPACITY_AH * 3600.0 / th["completion_unlimited_s"]
    rows = []
    for mass in (0.045, 0.0405, 0.0495):
        r_e = infer_r_e(th["t_peak_unlimited_c"], i_req, mass)
        cell = emoli_cell(r_e, mass)
        free = constant_current_run(cell, i_req, limit=False)
        lim = constant_current_run(cell, i_req, limit=True, t_max_c=th["t_max_c"])
        after = lim["time_s"] > 600.0
        rows.append({"mass_kg": mass, "r_e_ohm": r_e, "current_a": i_req,
                     "t_peak_unlimited_c": free["t_peak_c"], "completion_unlimited_s": free["completion_s"],
                     "t_peak_limited_c": lim["t_peak_c"], "completion_limited_s": lim["completion_s"],
                     "t_limited_after_600s_mean_c": float(lim["temperature_c"][after].mean()),
                     "_traces": (free, lim)})
    main = rows[0]
    result = {"thesis": th, "runs": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
              "completion_limited_error_pct": 100.0 * (main["completion_limited_s"] / th["completion_limited_s"] - 1.0)}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        from shevsim.core.atomic import write_text_atomic
        write_text_atomic(out / "fig_4_9.json", json.dumps(result, indent=2) + "\n")
        _plot(main["_traces"], out / "fig_4_9.png")
    return result


PULSE_PERIOD_S = 60.0
PULSE_DUTY = 0.5
SOC_MIN_FRAC = 0.1


def duty_cycle_request_w(time_s, p_1c_w: float, period_s: float = PULSE_PERIOD_S, duty: float = PULSE_DUTY):
    """The repeated discharge request [W]: a square pulse train (on for ``duty`` of each ``period_s``, then rest)
    whose pulses are ``p_1c_w / duty``, so that its mean is the cell's 1C power ``p_1c_w``."""
    phase = np.mod(np.asarray(time_s, dtype=float), period_s)
    return np.where(phase < duty * period_s, p_1c_w / duty, 0.0)


def power_capability_run(cell: LumpedCell, ocv: OcvTable, p_1c_w: float, *, t_amb_c: float = 30.0,
                         v_min_v: float = 3.2, t_max_c: float = 45.0, soc_min_frac: float = SOC_MIN_FRAC,
                         dt_s: float = DT_S, horizon_steps: int = HORIZON_STEPS, h_w_m2k: float = H_W_M2K,
                         soc0: float = 1.0, max_time_s: float = 20000.0, stop_power_frac: float = 0.05) -> dict:
    """Power capability (4.17a, 4.18a, 4.19a without RC terms) each step and the power drawn = min(request, it).

    Per step k: the three discharge limits (4.16a SOC, 4.16b voltage, 4.13a temperature), I_max = their minimum
    (not below 0), P_cap = I_max V_{k+N|k}; the cell then delivers min(P_req, P_cap) with the current that gives
    that power at the present OCV and R_e (``I (V_oc - R_e I) = P``), held over the step (SOC by coulomb counting,
    T by :func:`step_exact`). The run ends when a pulse's capability is below ``stop_power_frac`` of the request
    (the SOC constraint has taken the cell to SOC_min) or at ``max_time_s``.

    Returns the traces (time_s, power_request_w, power_capability_w, power_drawn_w, current_a, voltage_v,
    temperature_c, soc_frac, limit: 0 none / 1 SOC / 2 voltage / 3 temperature for the binding limit when the
    capability is below the request, else 0) and the limits' currents.
    """
    cap_as = 3600.0 * cell.capacity_ah
    r = cell.r_e_ohm
    n_max = int(math.ceil(max_time_s / dt_s))
    soc, t_c = soc0, t_amb_c
    cols = {k: np.full(n_max, np.nan) for k in ("time_s", "power_request_w", "power_capability_w", "power_drawn_w",
                                                   "current_a", "voltage_v", "temperature_c", "soc_frac",
                                                   "i_soc_a", "i_v_a", "i_t_a", "v_pred_v")}
    limit = np.zeros(n_max, dtype=np.int8)
    n = 0
    for k in range(n_max):
        t = k * dt_s
        p_req = float(duty_cycle_request_w(t, p_1c_w))
        i_soc = soc_current_limit(soc, soc_min_frac, cell.capacity_ah, horizon_steps, dt_s)
        i_v = voltage_current_limit(ocv, soc, r, v_min_v, cell.capacity_ah, horizon_steps, dt_s)
        i_t, _ = thermal_current_limits(cell, t_c, t_max_c, horizon_steps, dt_s, h_w_m2k, t_amb_c)
        i_max = max(min(i_soc, i_v, i_t), 0.0)                                        # 4.17a
        v_pred = predicted_voltage(ocv, soc, i_max, r, cell.capacity_ah, horizon_steps, dt_s)   # 4.19a
        p_cap = i_max * v_pred                                                        # 4.18a
        p = min(p_req, p_cap)
        if p_req > 0.0 and p_cap < stop_power_frac * p_req and i_soc <= min(i_v, i_t):
            break                                                                     # emptied to SOC_min
        v_oc = ocv(soc)
        i_a = (v_oc - math.sqrt(max(v_oc * v_oc - 4.0 * r * p, 0.0))) / (2.0 * r)
        for key, val in (("time_s", t), ("power_request_w", p_req), ("power_capability_w", p_cap),
                         ("power_drawn_w", p), ("current_a", i_a), ("voltage_v", v_oc - r * i_a),
                         ("temperature_c", t_c), ("soc_frac", soc), ("i_soc_a", i_soc), ("i_v_a", i_v),
                         ("i_t_a", i_t), ("v_pred_v", v_pred)):
            cols[key][k] = val
        if p_cap < p_req:
            limit[k] = 1 + int(np.argmin((i_soc, i_v, i_t)))
        t_c = step_exact(cell, t_c, i_a, dt_s, h_w_m2k, t_amb_c)
        soc -= i_a * dt_s / cap_as
        n = k + 1
    out = {k: v[:n] for k, v in cols.items()}
    out["limit"] = limit[:n]
    return out


LIMIT_NAMES = {1: "soc", 2: "voltage", 3: "temperature"}


def fig_4_10(out_dir: str | Path | None = None) -> dict:
    """The Fig. 4.10 analogue on the Fig. 4.9 cell; writes ``fig_4_10.json`` (+ PNG) into ``out_dir``."""
    th, th9 = THESIS_FIG_4_10, THESIS_FIG_4_9
    i_9 = CAPACITY_AH * 3600.0 / th9["completion_unlimited_s"]
    r_e = infer_r_e(th9["t_peak_unlimited_c"], i_9)
    cell = emoli_cell(r_e)
    ocv = OcvTable(LCO_OCV_CSV)
    p_1c = CAPACITY_AH * ocv.mean_v()            # 1C current x the mean OCV
    tr = power_capability_run(cell, ocv, p_1c, t_amb_c=th["t_amb_c"], v_min_v=th["v_min_v"], t_max_c=th["t_max_c"])
    t, lim = tr["time_s"], tr["limit"]
    spans = {}
    for code, name in LIMIT_NAMES.items():
        hit = t[lim == code]
        spans[name] = {"first_s": round(float(hit[0]), 1) if hit.size else None,
                       "last_s": round(float(hit[-1]), 1) if hit.size else None,
                       "time_s": round(hit.size * DT_S, 1), "episodes": _episodes(hit, PULSE_PERIOD_S)}
    firsts = sorted((v["first_s"], k) for k, v in spans.items() if v["first_s"] is not None)
    v_on = lim == 2
    result = {
        "thesis": th,
        "settings": {"r_e_ohm": r_e, "mass_kg": cell.mass_kg, "cp_j_kgk": cell.cp_j_kgk, "area_m2": cell.area_m2,
                     "capacity_ah": CAPACITY_AH, "ocv_csv": "components/cell/lco_ocv_ramadass2004.csv",
                     "ocv_mean_v": ocv.mean_v(), "p_1c_w": p_1c, "pulse_w": p_1c / PULSE_DUTY,
                     "pulse_period_s": PULSE_PERIOD_S, "pulse_duty": PULSE_DUTY, "soc_min_frac": SOC_MIN_FRAC,
                     "t_amb_c": th["t_amb_c"], "h_w_m2k": H_W_M2K, "v_min_v": th["v_min_v"], "t_max_c": th["t_max_c"],
                     "dt_s": DT_S, "horizon_steps": HORIZON_STEPS},
        "spans": spans,
        "order": [k for _, k in firsts],
        "end_s": float(t[-1] + DT_S),
        "soc_end_frac": float(tr["soc_frac"][-1]),
        "t_max_run_c": float(np.max(tr["temperature_c"])),
        "v_min_run_v": float(np.min(tr["voltage_v"])),
        "v_min_run_while_voltage_limit_v": float(np.min(tr["voltage_v"][v_on])) if v_on.any() else None,
        "energy_drawn_wh": float(np.sum(tr["power_drawn_w"]) * DT_S / 3600.0),
        "energy_requested_wh": float(np.sum(tr["power_request_w"]) * DT_S / 3600.0),
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        from shevsim.core.atomic import write_text_atomic
        write_text_atomic(out / "fig_4_10.json", json.dumps(result, indent=2) + "\n")
        _plot_4_10(tr, result, out / "fig_4_10.png")
    result["_traces"] = tr
    return result


def _episodes(hit_s: np.ndarray, gap_s: float) -> list[list[float]]:
    """[first, last] times of the runs of ``hit_s`` whose gaps are shorter than ``gap_s`` (one pulse period: the
    rests between pulses do not split an episode)."""
    if hit_s.size == 0:
        return []
    cut = np.where(np.diff(hit_s) >= gap_s)[0]
    starts = np.concatenate(([0], cut + 1))
    ends = np.concatenate((cut, [hit_s.size - 1]))
    return [[round(float(hit_s[a]), 1), round(float(hit_s[b]), 1)] for a, b in zip(starts, ends)]


def _plot_4_10(tr: dict, res: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    s = res["settings"]
    t = tr["time_s"]
    fig, axes = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    axes[0].plot(t, tr["power_request_w"], lw=0.4, color="0.7", label="requested")
    axes[0].plot(t, tr["power_capability_w"], lw=0.8, label="capability (4.18a)")
    axes[0].plot(t, tr["power_drawn_w"], lw=0.5, label="drawn")
    axes[0].set_ylim(0.0, 1.5 * s["pulse_w"])
    axes[0].set_ylabel("Power (W)")
    axes[1].plot(t, tr["voltage_v"], lw=0.5)
    axes[1].axhline(s["v_min_v"], color="k", lw=0.8, ls="--")
    axes[1].set_ylabel("Voltage (V)")
    axes[2].plot(t, tr["temperature_c"])
    axes[2].axhline(s["t_max_c"], color="k", lw=0.8, ls="--")
    axes[2].set_ylabel("Temperature (°C)")
    axes[3].plot(t, 100.0 * tr["soc_frac"])
    axes[3].axhline(100.0 * s["soc_min_frac"], color="k", lw=0.8, ls="--")
    axes[3].set_ylabel("SOC (%)")
    axes[3].set_xlabel("Time (s)")
    colors = {"soc": "tab:green", "voltage": "tab:red", "temperature": "tab:orange"}
    for name, sp in res["spans"].items():
        for j, (a, b) in enumerate(sp["episodes"]):
            for ax in axes:
                ax.axvspan(a, b + DT_S, color=colors[name], alpha=0.15, lw=0,
                           label=f"{name} limit sets it" if (ax is axes[0] and j == 0) else None)
    axes[0].legend(loc="upper right", fontsize=7, ncol=2)
    fig.suptitle("Fig. 4.10 analogue: power capability, pulse train at 1C mean power, 30 °C, 6 W/m²K\n"
                 "(shaded: where each limit sets the capability below the request)", fontsize=10)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def _plot(traces, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    free, lim = traces
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for tr, label in ((free, "no limit"), (lim, "thermal limit (eq. 4.13)")):
        axes[0].plot(tr["time_s"], tr["current_a"], label=label)
        axes[1].plot(tr["time_s"], 100.0 * tr["soc_frac"], label=label)
        axes[2].plot(tr["time_s"], tr["temperature_c"], label=label)
    axes[0].set_ylabel("Current (A)")
    axes[1].set_ylabel("SOC (%)")
    axes[2].set_ylabel("Temperature (°C)")
    axes[2].axhline(45.0, color="k", lw=0.8, ls="--")
    axes[2].set_xlabel("Time (s)")
    axes[0].legend()
    fig.suptitle("Fig. 4.9 analogue: constant-current discharge, 25 °C, natural convection 6 W/m²K")
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m shevsim.studies.ch4_study", description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output folder (fig_4_9.json/.png, fig_4_10.json/.png)")
    args = ap.parse_args(argv)
    res = fig_4_9(args.out)
    for r in res["runs"]:
        print(f"mass {r['mass_kg']*1e3:.1f} g: R_e {r['r_e_ohm']*1e3:.1f} mohm, I {r['current_a']:.3f} A; "
              f"no limit: peak {r['t_peak_unlimited_c']:.2f} C, {r['completion_unlimited_s']:.0f} s; "
              f"limit: peak {r['t_peak_limited_c']:.2f} C, mean after 600 s {r['t_limited_after_600s_mean_c']:.2f} C, "
              f"{r['completion_limited_s']:.0f} s")
    f10 = fig_4_10(args.out)
    for name, sp in f10["spans"].items():
        eps = ", ".join(f"{a:.0f}-{b:.0f} s" for a, b in sp["episodes"]) or "never"
        print(f"Fig. 4.10 analogue: {name} limit sets the capability {eps}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
