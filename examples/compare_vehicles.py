"""Run a bundled scenario for two vehicles and compare them.

The M-ATV of the seed (15.5 t, 5.72 m^2, Cd 0.7) against a lighter, more streamlined variant of the same
series-hybrid powertrain, both on HD-UDDS with the rule-based supervisor. Prints a metrics table and
writes ``compare_vehicles.png`` (speed, powers and SOC overlaid, one axis per unit).

    python examples/compare_vehicles.py [OUT]
    SHEVSIM_EXAMPLE_QUICK=1 python examples/compare_vehicles.py     # the first 300 s only
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")            # write files; no display needed
import matplotlib.pyplot as plt  # noqa: E402

import shevsim  # noqa: E402

QUICK = os.environ.get("SHEVSIM_EXAMPLE_QUICK", "") not in ("", "0")

VEHICLES = {
    "M-ATV (15.5 t)": {},
    "light variant (10 t, Cd 0.5)": {"vehicle.mass_kg": 10000.0, "vehicle.drag_coefficient": 0.5,
                                     "vehicle.frontal_area_m2": 5.0},
}


def main(out: Path) -> list:
    out.mkdir(parents=True, exist_ok=True)
    stop_s = 300.0 if QUICK else None          # None: the cycle's length
    runs = []
    for label, overrides in VEHICLES.items():
        res = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, **overrides}, stop_s=stop_s)
        print(f"{label}: {res.termination}")
        runs.append(res)
    keys = ["distance_km", "fuel_mass_g", "fuel_economy_raw_kmpl", "fuel_economy_dsoc_corrected_kmpl",
            "delta_soc_pct", "speed_miss_rms_kmh"]
    table = shevsim.metrics_table(runs, keys, labels=list(VEHICLES))
    print(table.T.to_string(float_format=lambda x: f"{x:.4g}"))
    fig = shevsim.compare(runs, ["vehicle.speed_mps", "motor.elec_power_w", "engine_generator.elec_power_w",
                                  "battery.soc_pct"], labels=list(VEHICLES))
    fig.set_size_inches(10, 8)
    fig.tight_layout()
    fig.savefig(out / "compare_vehicles.png", dpi=100)
    plt.close(fig)
    print(f"figure: {out / 'compare_vehicles.png'}")
    return runs


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="shevsim_compare_")))
