"""make_ocv.py - estimate the Panasonic 18650PF open-circuit voltage curve from the low-current parts
of the 25 degC HWFET run (a run independent of the US06 runs the calibration is tested on).

Method: the cell starts fully charged (README_Kollmeyer: charged at 1C to 4.2 V / 50 mA before each
test), so SOC = 1 - (discharged Ah) / 2.9 Ah (rated capacity).  Every stretch where |I| < 0.1 A for
at least 5 s gives one point: the voltage at the END of the stretch (most relaxed) against that SOC.
The points are binned on SOC (0.05 wide), made monotone (isotonic, pool-adjacent-violators) and written
to ``ocv_25degC_hwfet_lowcurrent.toml`` for ``shevsim calibrate cell ... --params``.

Known bias: rests inside a drive cycle are short, so after a discharge pulse the voltage has not fully
relaxed; the curve lies some mV below the true OCV (the calibration's RC branch and - if needed - the
hysteresis effect take up the rest).  Below the lowest rest point (SOC ~0.07) the curve is extrapolated.

Run from the project root:  python data/measured/panasonic_18650pf/make_ocv.py
"""
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
CAP_AH = 2.9


def main():
    df = pd.read_csv(HERE / "25degC_HWFTa_Pan18650PF.csv", comment="#")
    t, i, v, ah = (df[c].to_numpy(float) for c in ("Time", "Current", "Voltage", "Ah"))
    low = np.abs(i) < 0.1
    pts = []
    k = 0
    n = len(t)
    while k < n:
        if not low[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and low[j + 1]:
            j += 1
        if t[j] - t[k] >= 5.0:
            pts.append((1.0 + ah[j] / CAP_AH, v[j]))   # Ah is negative when discharged
        k = j + 1
    pts = np.array(pts)
    edges = np.arange(0.0, 1.0001, 0.05)
    soc, ocv = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (pts[:, 0] >= a) & (pts[:, 0] < b)
        if m.any():
            soc.append(float(pts[m, 0].mean()))
            ocv.append(float(np.median(pts[m, 1])))
    soc.append(1.0)
    ocv.append(float(v[0]))          # rested, fully charged start
    soc, ocv = np.array(soc), np.array(ocv)
    # isotonic regression (pool adjacent violators) so the OCV rises with SOC
    vals, wts = list(ocv), [1.0] * len(ocv)
    blocks = [[x] for x in range(len(ocv))]
    k = 0
    while k < len(vals) - 1:
        if vals[k] > vals[k + 1]:
            w = wts[k] + wts[k + 1]
            vals[k] = (vals[k] * wts[k] + vals[k + 1] * wts[k + 1]) / w
            wts[k] = w
            blocks[k] += blocks[k + 1]
            del vals[k + 1], wts[k + 1], blocks[k + 1]
            k = max(k - 1, 0)
        else:
            k += 1
    iso = np.empty(len(ocv))
    for val, bl in zip(vals, blocks):
        iso[bl] = val
    keep = np.concatenate([[True], np.diff(iso) > 1e-4])
    soc, iso = soc[keep], iso[keep]
    lines = ["[meta]",
             'source = "Panasonic 18650PF (Kollmeyer 2018, CC BY 4.0), 25 degC HWFET run: end-of-rest voltages '
             f'(|I| < 0.1 A for >= 5 s, {len(pts)} rests), SOC by Ah counting from full charge, '
             'binned and made monotone by make_ocv.py; lies a few mV below the true OCV (short rests)"',
             "", "[params]", f"capacity_ah = {CAP_AH}", "soc0_frac = 1.0", "", "[ocv]",
             "soc_frac = [" + ", ".join(f"{x:.4f}" for x in soc) + "]",
             "ocv_v = [" + ", ".join(f"{x:.4f}" for x in iso) + "]", ""]
    (HERE / "ocv_25degC_hwfet_lowcurrent.toml").write_text("\n".join(lines))
    print(f"{len(pts)} rest points -> {len(soc)} OCV points, SOC {soc.min():.3f}-{soc.max():.3f}, "
          f"V {iso.min():.3f}-{iso.max():.3f}")


if __name__ == "__main__":
    main()
