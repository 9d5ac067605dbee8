"""calibration_effects.py - every effect of the three calibration models on synthetic plant data.

For each effect of the cell, vehicle and engine libraries: data from the co-simulation plant (the component
stepped by the master with that one effect switched on, sensor noise), calibrated with the effect
undeclared; prints whether it was named and the affected channel's held-out RMSE before -> after -> replay
(the overlay stepped through the master).  Also the no-effect case of each model.

    python benchmarks/calibration_effects.py
"""
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from shevsim.calibrate.synthetic import (CELL_EFFECTS, CELL_NOMINAL, ENGINE_EFFECTS, VEHICLE_EFFECTS,  # noqa: E402
                                         as_measured, synth_cell, synth_engine, synth_vehicle)
from shevsim.calibrate.workflow import run_workflow  # noqa: E402

CELL_CHANNEL = {"entropic_heat": "t_surface_c", "cooling_change": "t_surface_c"}
# (as tests/unit/test_calibrate_cell.py: hysteresis shows only where rests are reached after charge and after discharge)
CELL_KW = {"arrhenius_resistance": {"ambient": "warmup"}, "low_soc_resistance": {"soc0": 0.5, "discharge_frac": 0.45},
           "ocv_hysteresis": {"charge_rests": True}}


def _row(model, effect, rep, channel, dt):
    b = rep["rmse_before"][channel]["holdout"]
    a = rep["rmse_after"][channel]["holdout"]
    r = rep["replay"][channel]["holdout"] if rep.get("replay") and "error" not in rep["replay"] else float("nan")
    named = ("yes" if effect in rep["selected_effects"] else "NO") if effect != "none" else \
        ("nothing selected" if not rep["selected_effects"] else "FALSE: " + ",".join(rep["selected_effects"]))
    extra = [e for e in rep["selected_effects"] if e != effect]
    print(f"| {model} | {effect} | {named}{' (+' + ', '.join(extra) + ')' if extra and effect != 'none' else ''} | "
          f"{channel} | {b:.4g} -> {a:.4g} -> {r:.4g} | {a / b:.2f} | {dt:.1f} s |", flush=True)


def main():
    print("| model | effect in the data | named? | channel | held-out RMSE before -> after -> replay | after/before | time |")
    print("|---|---|---|---|---|---|---|")
    for effect in ["none"] + list(CELL_EFFECTS):
        kw = CELL_KW.get(effect, {})
        df, _ = synth_cell({} if effect == "none" else {effect: {}}, seed=7, **kw)
        nominal = dict(CELL_NOMINAL, **({"soc0_frac": kw["soc0"]} if "soc0" in kw else {}))
        t0 = time.perf_counter()
        rep = run_workflow("cell", as_measured(df, "cell"), nominal, plots=False)
        _row("cell", effect, rep, CELL_CHANNEL.get(effect, "voltage_v"), time.perf_counter() - t0)
    for effect in ["none"] + list(VEHICLE_EFFECTS):
        df, _ = synth_vehicle({} if effect == "none" else {effect: {}}, duration_s=600.0, seed=7)
        t0 = time.perf_counter()
        rep = run_workflow("vehicle", as_measured(df, "vehicle"), plots=False)
        _row("vehicle", effect, rep, "power_w", time.perf_counter() - t0)
    for effect in ["none"] + list(ENGINE_EFFECTS):
        df, _ = synth_engine({} if effect == "none" else {effect: {}}, seed=11)
        t0 = time.perf_counter()
        rep = run_workflow("engine", as_measured(df, "engine"), plots=False)
        _row("engine", effect, rep, "soot_rate_mgps", time.perf_counter() - t0)


if __name__ == "__main__":
    main()
