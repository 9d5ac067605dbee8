"""Calibrate the battery cell model on the shipped measured data (Panasonic 18650PF, 25 degC US06).

The measured record (Kollmeyer 2018, CC BY 4.0; ``data/measured/panasonic_18650pf/``) is fitted by the
battery component's own cell model, the residual is traced to missing effects, and the held-out error is
reported before and after (``docs/calibration_results.md`` has the full run: 27.3 -> 13.1 mV).

    python examples/calibrate_cell.py [OUT]          # the whole record (a few minutes)
    SHEVSIM_EXAMPLE_QUICK=1 python examples/calibrate_cell.py   # the first 10 minutes, one candidate effect

Run from a checkout (the measured data are not part of the wheel).
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import shevsim

QUICK = os.environ.get("SHEVSIM_EXAMPLE_QUICK", "") not in ("", "0")
HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "data" / "measured" / "panasonic_18650pf"


def main(out: Path) -> dict:
    record = DATA / "25degC_US06_Pan18650PF.csv"
    options = dict(params=DATA / "ocv_25degC_hwfet_lowcurrent.toml",
                   map={"time_s": "Time", "current_a": "Current", "voltage_v": "Voltage",
                        "t_surface_c": "Battery_Temp_degC", "t_ambient_c": "Chamber_Temp_degC"},
                   current_sign="charge-positive", drop_duplicate_rows=True)
    if QUICK:   # a shorter record (the first 600 s: comment lines, header, 0.1 s samples) and one effect
        lines = record.read_text().splitlines(keepends=True)
        head = [ln for ln in lines[:10] if ln.startswith("#")]
        body = lines[len(head):]
        record = out / "us06_first_600s.csv"
        out.mkdir(parents=True, exist_ok=True)
        record.write_text("".join(head + body[:6001]))
        options.update(effects=["second_rc_branch"], plots=False, drop_duplicate_rows=False)
    cal = shevsim.run_calibration("cell", record, out=out / "calibration", **options)
    print(cal)                                    # <CalibrationReport cell: selected ...; held-out RMSE ...>
    print(cal.before_after.to_string(float_format=lambda x: f"{x:.4g}"))   # RMSE per channel, before / after
    rep = cal.report
    print(f"calibrated parameters: {out / 'calibration' / 'params.toml'} (use with shevsim run --params)")
    return rep


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="shevsim_calibration_")))
