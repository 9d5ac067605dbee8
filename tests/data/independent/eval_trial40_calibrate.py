"""Run ``shevsim calibrate`` on the trial-40 records and compare with their truth (a new-user trial's runner).

    python tests/data/independent/eval_trial40_calibrate.py OUT_DIR [CASE_PREFIX ...]

Every record is run as the trial ran it: the whole effect library, defaults, ``--params`` the user's nominal, the
file's own column names given with ``--map`` (and ``--unit`` for the vehicle's km/h and kW).  A cell record without
an ambient column (``ambient_column`` false in its truth) is refused by ``shevsim calibrate`` (a required column,
no option gives a constant); it is run on a copy with a constant ``Chamber_Temperature(C)`` of 25.0 appended, as the
trial did.  Prints one markdown row per run: what was named, the fitted parameters against the truth, the held-out
RMSE before -> after and the wall time.  Expected names: a no-effect record nothing; ``contact_resistance`` nothing
(the nominal fits the series resistance; its change is read from ``rs_scale`` x the 10.0 mOhm of the default
table's mid-SOC R_s); the others their effect.
"""
from __future__ import annotations

import gzip
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CELL_MAP = ["--map", "time_s=Test_Time(s)", "--map", "current_a=Current(A)", "--map", "voltage_v=Voltage(V)",
            "--map", "t_surface_c=Aux_Temperature_1(C)", "--map", "t_ambient_c=Chamber_Temperature(C)"]
VEH_MAP = ["--map", "time_s=Time", "--map", "speed_mps=VehSpd_kph", "--map", "power_w=HVBatt_Pwr_kW",
           "--unit", "speed_mps=kmh", "--unit", "power_w=kW"]
EXPECT = {"capacity": "capacity", "current_offset": "current_offset", "cooling_change": "cooling_change",
          "payload": "mass_error", "payload_2": "mass_error", "aux": "aux_load", "latency_2": "timing",
          "grade": "road_grade", "grade_hill": "road_grade"}
RS_TABLE_OHM = 0.010      # the default (A123 26650) table's R_s at 25 degC, SOC 0.3-0.8
RUNS = [("leaf", HERE / "vehicle_trial40_leaf_truth.json", "vehicle_trial40_leaf_nominal.toml", None),
        ("leaf_const", HERE / "vehicle_trial40_leaf_truth.json", "vehicle_trial40_leaf_nominal_const.toml",
         ("payload", "grade")),
        ("mq", HERE / "cell_trial40_marquis2019_truth.json", "cell_trial40_marquis2019_nominal.toml", None),
        ("or", HERE / "cell_trial40_oregan2022_truth.json", "cell_trial40_oregan2022_nominal.toml", None)]


def with_ambient(src: Path, dst: Path) -> Path:
    """A copy of the cell record with a constant 25.0 degC ambient column appended (the trial's workaround)."""
    text = (gzip.decompress(src.read_bytes()) if src.suffix == ".gz" else src.read_bytes()).decode().splitlines()
    out = [text[0], text[1] + ",Chamber_Temperature(C)"] + [ln + ",25.0" for ln in text[2:]]
    dst.write_text("\n".join(out) + "\n")
    return dst


def fitted(gen, t, fp, rs_none):
    f = []
    if gen.startswith("leaf"):
        if "mass_kg" in fp:
            f.append(f"mass {fp['mass_kg']:.0f} vs {t['mass_kg']:.0f} kg ({fp['mass_kg'] / t['mass_kg'] - 1:+.1%})")
        if "aux_power_w" in fp:
            f.append(f"aux {fp['aux_power_w']:.0f} vs {t['aux_power_w']:.0f} W ({fp['aux_power_w'] / t['aux_power_w'] - 1:+.1%})")
        if "time_shift_s" in fp:
            f.append(f"shift {fp['time_shift_s']:.2f} vs {t['time_shift_s']} s")
        if "rolling_coefficient" in fp:
            f.append(f"f_r {fp['rolling_coefficient']:.4f} (nominal 0.008)")
        if "drag_coefficient" in fp:
            f.append(f"C_d {fp['drag_coefficient']:.3f} (nominal 0.315)")
        if "grade_frac[0]" in fp:
            f.append("grade " + ", ".join(f"{fp[f'grade_frac[{i}]']:.4f}" for i in range(6)) + f" vs {t['grade_frac']}")
        f.append(f"eff scales {fp['efficiency_scale_frac']:.3f}/{fp['regen_efficiency_scale_frac']:.3f}")
    else:
        if "capacity_ah" in fp:
            f.append(f"capacity {fp['capacity_ah']:.4f} vs {t['capacity_ah']:.4f} A.h ({fp['capacity_ah'] / t['capacity_ah'] - 1:+.1%})")
        if "current_offset_a" in fp:
            f.append(f"offset {fp['current_offset_a']:.4f} vs {t['current_offset_a']:.4f} A")
        if "h_change_factor" in fp:
            f.append(f"h x{fp['h_change_factor']:.3f} at {fp['h_change_time_s']:.0f} s vs x{t['h_change_factor']} at {t['h_change_time_s']} s")
        if t.get("series_resistance_added_ohm") and rs_none:
            d = (fp["rs_scale"] - rs_none) * RS_TABLE_OHM
            f.append(f"R_s +{1e3 * d:.1f} mOhm over the no-effect drives vs {1e3 * t['series_resistance_added_ohm']:.0f} mOhm")
        f.append(f"rs_scale {fp['rs_scale']:.3f}")
    return "; ".join(f)


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    out = Path(sys.argv[1]).resolve()
    only = sys.argv[2:]
    out.mkdir(parents=True, exist_ok=True)
    print("| generator | case | named | expected | fitted vs truth | held-out before -> after | wall s |")
    print("|---|---|---|---|---|---|---|")
    for gen, truth_file, nominal, cases in RUNS:
        truth = json.loads(truth_file.read_text())
        rs_none = []
        for case, c in truth["cases"].items():
            if (cases and case not in cases) or (only and not any(f"{gen}_{case}".startswith(p) for p in only)):
                continue
            data = HERE / c["file"]
            model = "vehicle" if gen.startswith("leaf") else "cell"
            nom = c.get("nominal", nominal)
            if model == "cell" and not c.get("ambient_column", True):
                data = with_ambient(data, out / f"amb_{Path(c['file']).name.removesuffix('.gz')}")
            opts = VEH_MAP if model == "vehicle" else CELL_MAP
            if model == "cell" and c.get("dt_s", 1.0) < 1.0:
                opts = opts + ["--current-sign", "charge-positive"]   # the sign cannot be guessed at 10 Hz
            d = out / f"{gen}_{case}"
            t0 = time.perf_counter()
            p = subprocess.run(["shevsim", "calibrate", model, str(data), "--out", str(d), "--params", str(HERE / nom),
                                "-q", *opts], capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if p.returncode != 0:
                print(f"| {gen} | {case} | exit {p.returncode}: {p.stderr.strip()[:200]} | | | | {wall:.0f} |")
                continue
            r = json.loads((d / "report.json").read_text())
            fp = r["final_parameters"]
            if model == "cell" and case.startswith("none"):
                rs_none.append(fp["rs_scale"])
            rb, ra = r["rmse_before"], r["rmse_after"]
            ho = "; ".join(f"{ch} {rb[ch]['holdout']:.4g} -> {ra[ch]['holdout']:.4g}" for ch in rb)
            rsn = sum(rs_none) / len(rs_none) if rs_none else None
            print(f"| {gen} | {case} | {', '.join(r['selected_effects']) or 'nothing'} | {EXPECT.get(case, 'nothing')} | "
                  f"{fitted(gen, c['truth'], fp, rsn)} | {ho} | {wall:.0f} |", flush=True)


if __name__ == "__main__":
    main()
