"""make_lco_ocv.py - generate lco_ocv_ramadass2004.csv (an LCO/graphite OCV(SOC) curve) once, with PyBaMM.

Run from the repository root: ``python components/cell/make_lco_ocv.py``. PyBaMM is a test/benchmark dependency
only; shevsim's run-time code reads the CSV and never imports PyBaMM for it.

Source: PyBaMM's ``Ramadass2004`` parameter set (LiCoO2 positive, graphite negative; P. Ramadass, B. Haran,
P. M. Gomadam, R. White, B. N. Popov, "Development of first principles capacity fade model for Li-ion cells",
J. Electrochem. Soc. 151 (2004) A196). PyBaMM is BSD-3-Clause licensed (copyright the PyBaMM team).

OCV(SOC) = U_pos(y(SOC)) - U_neg(x(SOC)) at 298.15 K, with the stoichiometries linear in SOC between those at
0 % and 100 % SOC that PyBaMM's electrode-SOH solver gives for the set's voltage window
(``get_min_max_stoichiometries``).
"""
from __future__ import annotations

import csv
import inspect
from pathlib import Path

import numpy as np
import pybamm

OUT = Path(__file__).with_name("lco_ocv_ramadass2004.csv")


def _ocp(fn, sto: float, t_ref) -> float:
    """Evaluate a parameter set's OCP function (some take (sto), some (sto, T))."""
    n_args = len(inspect.signature(fn).parameters)
    args = (pybamm.Scalar(sto), t_ref)[:n_args]
    return float((pybamm.Scalar(0.0) + fn(*args)).evaluate())


def main() -> None:
    pv = pybamm.ParameterValues("Ramadass2004")
    x0, x100, y100, y0 = pybamm.lithium_ion.get_min_max_stoichiometries(pv)
    t_ref = pybamm.Scalar(298.15)
    u_p, u_n = pv["Positive electrode OCP [V]"], pv["Negative electrode OCP [V]"]
    socs = np.linspace(0.0, 1.0, 101)
    rows = []
    for soc in socs:
        x = x0 + soc * (x100 - x0)        # negative (graphite) stoichiometry
        y = y0 + soc * (y100 - y0)        # positive (LiCoO2) stoichiometry
        rows.append((soc, _ocp(u_p, y, t_ref) - _ocp(u_n, x, t_ref)))
    with OUT.open("w", newline="") as fh:
        fh.write(f"# LCO/graphite OCV from PyBaMM {pybamm.__version__} ParameterValues('Ramadass2004') at 298.15 K; "
                 f"x(0%)={x0:.6f} x(100%)={x100:.6f} y(0%)={y0:.6f} y(100%)={y100:.6f}; "
                 f"made by components/cell/make_lco_ocv.py; PyBaMM BSD-3-Clause, Ramadass et al. 2004 JES 151 A196\n")
        w = csv.writer(fh)
        w.writerow(["soc_frac", "ocv_v"])
        for soc, v in rows:
            w.writerow([f"{soc:.2f}", f"{v:.6f}"])
    print(f"wrote {OUT} ({len(rows)} rows, {rows[0][1]:.4f} V .. {rows[-1][1]:.4f} V)")


if __name__ == "__main__":
    main()
