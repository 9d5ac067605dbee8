"""make_records.py - the Nissan Leaf cell's calibration records and the nominal a user can derive for it.

Source: ORNL, "Battery cell data from a 2013 Nissan Leaf" (Wiggins, Allu, Wang; doi:10.5281/zenodo.2580327,
github.com/batterysim/nissan-leaf-data at commit b2222ed, MIT licence, ``LICENSE.txt``).  The raw files
beside this script are the repository's ``data/`` files, unchanged.

Records (``leaf_<rate>.csv``, columns ``time_s, current_a`` (charge positive, as the Bitrode logs it),
``voltage_v, t_surface_c, t_ambient_c``): one cycle of the constant-current tests, cut from the Bitrode
log (``*-Discharge-Bitrode-data.csv``: 1 s while a step starts, then 60 s; column 2 time, 9 current,
10 voltage) and merged with the LabVIEW thermocouple log of the same test (``Temperature-*-discharge.lvm``:
3 s per row from the same start, as the repository's ``datalib.TemperatureData`` reads it; TC2 = middle of
the cell face as the surface temperature, TC4 = the chamber air as the ambient), linearly interpolated to
the Bitrode times:

* ``leaf_1C``: from the rest after the first full charge: rest 600 s, 1C (30.6 A) discharge to 3.0 V,
  rest 1800 s, C/2 charge (15.3 A, CC-CV to 4.2 V) up to where the charge returned equals the charge
  taken (the model has no coulombic inefficiency: the charge's last ~0.02 Ah would take it above 100 % SOC);
* ``leaf_2C``: the same cycle at 2C (61.2 A).

The 3C test is not shipped: its temperature log covers only the first discharge, which starts under load
at the log's first sample, so the record cannot give its initial SOC (no rest before it).

Nominal (``ocv_25degC_hppc.toml``, the calibration's ``--params``): what a user can derive from the same
project's low-current HPPC test at 25 degC (``NissanLeaf-cell-Low-Current-HPPC-25C-2.csv``), a test
independent of the records: after a full charge and 1 h rest, ten steps of (30 s 30 A pulse, 40 s rest,
10 s charge pulse, 3 Ah at 10 A, 1 h rest) to 3.0 V.  Capacity = the Ah discharged from full to 3.0 V
(the cycler's own ``Capacity(Ah)`` counter, per step, summed with its sign); OCV points = the voltage at
the end of each 1 h rest against SOC = 1 - discharged Ah / capacity; below the lowest rest (SOC ~0.06) the
end of the 30 min rest after the 2C test's first discharge to 3.0 V (SOC ~0.017; still rising: a lower
bound) and SOC 0 extrapolated linearly through those two points (the HPPC test ends under load).  Geometry: the pouch cell (290 x 216 x
7.1 mm, 799 g; ``README_ORNL.md``) as the thermal model's cylinder of the same volume and cooled surface
(R = 2V/A, L = A / (2 pi R): equal heat capacity and convective area; the internal conduction path differs
and ``kt_w_mk`` is fitted); voltage limits 3.0 / 4.2 V (the tests' own).

Run from the project root:  python data/measured/nissan_leaf_cell/make_records.py
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
WINDOWS = {  # rate: (Bitrode file, lvm file, start s, end s) - cut at the Bitrode's step boundaries
    "1C": ("1C-Discharge-Bitrode-data.csv", "Temperature-1C-discharge.lvm", 9486.3, 23846.2),
    "2C": ("2C-Discharge-Bitrode-data.csv", "Temperature-2C-discharge.lvm", 11247.9, 23714.9),
}
LVM_DT_S = 3.0
POUCH_M = (0.290, 0.216, 0.0071)
MASS_KG = 0.799


def bitrode(name: str) -> pd.DataFrame:
    df = pd.read_csv(HERE / name, header=None)
    return pd.DataFrame({"t": df[1].astype(float), "i": df[8].astype(float), "v": df[9].astype(float),
                         "mode": df[13].astype(str)})


def temperatures(name: str) -> pd.DataFrame:
    df = pd.read_csv(HERE / name, header=None, sep="\t", usecols=[1, 2, 3, 4])
    return pd.DataFrame({"t": np.arange(len(df)) * LVM_DT_S, "tc2": df[2].astype(float), "tc4": df[4].astype(float)})


def make_record(rate: str) -> Path:
    bfile, tfile, t0, t1 = WINDOWS[rate]
    b, tc = bitrode(bfile), temperatures(tfile)
    t_end = min(t1 if t1 is not None else math.inf, float(tc["t"].iloc[-1]))
    w = b[(b["t"] >= t0) & (b["t"] <= t_end)]
    if (w["mode"] == "CHRG").any():
        # the model has no coulombic inefficiency: end where the charge returned equals the charge taken
        # (the CC-CV charge returns ~0.02 Ah more; its last minutes would take the model above 100 % SOC)
        tt, ii = w["t"].to_numpy(), w["i"].to_numpy()
        net = np.concatenate([[0.0], np.cumsum(0.5 * (ii[1:] + ii[:-1]) * np.diff(tt))])
        dis_end = int(np.flatnonzero(w["mode"].to_numpy() == "DCHG")[-1])
        back = np.flatnonzero((net >= 0.0) & (np.arange(len(w)) > dis_end))
        if back.size:
            w = w.iloc[: int(back[0])]
    ts = w["t"].to_numpy() - t0
    out = pd.DataFrame({"time_s": np.round(ts, 1), "current_a": w["i"].to_numpy(), "voltage_v": w["v"].to_numpy(),
                        "t_surface_c": np.round(np.interp(w["t"], tc["t"], tc["tc2"]), 4),
                        "t_ambient_c": np.round(np.interp(w["t"], tc["t"], tc["tc4"]), 4)})
    path = HERE / f"leaf_{rate}.csv"
    head = (f"# 2013 Nissan Leaf cell, {rate} constant-current cycle (ORNL, doi:10.5281/zenodo.2580327, MIT licence); "
            f"{bfile} from t = {t0} s (Bitrode) + {tfile} (TC2 surface, TC4 chamber air); make_records.py\n"
            "# current positive = charge (the Bitrode's sign)\n")
    path.write_text(head + out.to_csv(index=False, float_format="%.6g"))
    return path


def make_nominal() -> Path:
    df = pd.read_csv(HERE / "NissanLeaf-cell-Low-Current-HPPC-25C-2.csv")
    t, v, ah = (df[c].to_numpy(float) for c in ("Time(s)", "Voltage(V)", "Capacity(Ah)"))
    mode = df["Mode"].astype(str).to_numpy()
    edges = np.flatnonzero(mode[1:] != mode[:-1]) + 1
    seg = list(zip(np.r_[0, edges], np.r_[edges, len(df)]))
    # charge passed: the cycler's own Ah counter (reset at each charge/discharge step, held during rests;
    # integrating the logged current instead would miss the 60 s gaps at the step ends), from the rest
    # after the full charge on
    dis = np.zeros(len(df))
    done = 0.0
    for s, e in seg[1:]:
        if mode[s] in ("CHRG", "DCHG"):
            dis[s:e] = done - ah[s:e]
            done -= ah[e - 1]
        else:
            dis[s:e] = done
    rests = [(s, e) for s, e in seg if mode[s] == "REST" and t[e - 1] - t[s] > 3000.0]
    cap = float(dis[-1])
    pts = [(1.0 - dis[e - 1] / cap, v[e - 1]) for s, e in rests]
    # below the lowest HPPC rest (SOC ~0.06): the end of the 30 min rest after the 2C test's first
    # discharge to 3.0 V (29.95 Ah of this capacity taken: SOC ~0.017; still rising, so a lower bound), and
    # SOC 0 by linear extrapolation through those two points
    b2 = bitrode(WINDOWS["2C"][0])
    d0 = int(np.flatnonzero(b2["mode"].to_numpy() == "REST")[0])
    dr = b2["mode"].to_numpy()[d0:] == "REST"
    d1 = d0 + int(np.argmin(dr)) - 1                          # last sample of that rest
    ah2 = pd.read_csv(HERE / WINDOWS["2C"][0], header=None)[11].to_numpy(float)
    s2 = 1.0 - abs(float(ah2[d0 - 1])) / cap
    pts.append((s2, float(b2["v"].iloc[d1])))
    pts = sorted((min(a, 1.0), b) for a, b in pts)
    (sa, va), (sb, vb) = pts[0], pts[1]
    pts.insert(0, (0.0, va - sa * (vb - va) / (sb - sa)))
    soc = [round(a, 4) for a, _ in pts]
    ocv = [round(b, 4) for _, b in pts]
    lx, wy, tz = POUCH_M
    vol = lx * wy * tz
    area = 2.0 * (lx * wy + lx * tz + wy * tz)
    r = 2.0 * vol / area
    length = area / (2.0 * math.pi * r)
    lines = ["[meta]",
             'source = "2013 Nissan Leaf cell (ORNL, doi:10.5281/zenodo.2580327, MIT): OCV = end of the 1 h rests of '
             'the 25 degC low-current HPPC test vs Ah-counted SOC, capacity = Ah to 3.0 V at 10 A; SOC 0 a pseudo-OCV '
             '(cut-off + ohmic drop); pouch as the cylinder of equal volume and surface; make_records.py"',
             "", "[params]", f"capacity_ah = {cap:.4f}",
             f"radius_m = {r:.6g}      # 2 V / A of the 290 x 216 x 7.1 mm pouch",
             f"length_m = {length:.6g}      # A / (2 pi R): the pouch's cooled surface",
             f"density_kg_m3 = {MASS_KG / vol:.6g}  # 799 g / pouch volume",
             "v_min_v = 3.0", "v_max_v = 4.2", "", "[ocv]",
             "soc_frac = [" + ", ".join(f"{x:.4f}" for x in soc) + "]",
             "ocv_v = [" + ", ".join(f"{x:.4f}" for x in ocv) + "]", ""]
    path = HERE / "ocv_25degC_hppc.toml"
    path.write_text("\n".join(lines))
    print(f"capacity {cap:.3f} Ah, {len(rests)} rests, OCV {ocv[0]:.3f}-{ocv[-1]:.3f} V")
    return path


def main() -> int:
    make_nominal()
    for rate in WINDOWS:
        print(make_record(rate))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
