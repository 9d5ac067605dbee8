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

Run: ``python -m shevsim.studies.ch4_study OUT`` (writes ``fig_4_9.json`` and ``fig_4_9.png``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from shevsim.bms.lumped import LumpedCell, step_exact, thermal_current_limits

__all__ = ["THESIS_FIG_4_9", "emoli_cell", "constant_current_run", "infer_r_e", "fig_4_9"]

THESIS_FIG_4_9 = {"t_peak_unlimited_c": 87.0, "completion_unlimited_s": 2133.0, "completion_limited_s": 4687.0,
                  "t_max_c": 45.0}
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
    ap.add_argument("out", help="output folder (fig_4_9.json, fig_4_9.png)")
    args = ap.parse_args(argv)
    res = fig_4_9(args.out)
    for r in res["runs"]:
        print(f"mass {r['mass_kg']*1e3:.1f} g: R_e {r['r_e_ohm']*1e3:.1f} mohm, I {r['current_a']:.3f} A; "
              f"no limit: peak {r['t_peak_unlimited_c']:.2f} C, {r['completion_unlimited_s']:.0f} s; "
              f"limit: peak {r['t_peak_limited_c']:.2f} C, mean after 600 s {r['t_limited_after_600s_mean_c']:.2f} C, "
              f"{r['completion_limited_s']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
