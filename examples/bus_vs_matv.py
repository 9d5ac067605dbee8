"""A 12 t city bus with a 150 kW engine, defined in a few lines, against the seed's M-ATV on HD-UDDS.

The bus extends the bundled M-ATV scenario and states only what differs: the quantities of the vehicle
as a whole (``[shared]``). Its engine-generator and motor maps, the supervisor's generator limit and fuel
curve, the BMS's pack and the driver's feed-forward all follow from them (shevsim/components/shared.py).

    python examples/bus_vs_matv.py [OUT]
    SHEVSIM_EXAMPLE_QUICK=1 python examples/bus_vs_matv.py     # the first 300 s only
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import shevsim

BUS = """
[scenario]
extends = "hd_udds_mpc"       # the M-ATV's powertrain, MPC supervisor, BMS and wiring
name = "bus_12t"

[shared]                      # only what differs: the vehicle as a whole
mass_kg = 12000.0
frontal_area_m2 = 7.5
drag_coefficient = 0.65
rolling_coefficient = 0.008
wheel_radius_m = 0.48
engine_power_w = 150000.0     # engine-generator maps sized from 261 kW (power-linear, speeds kept)
motor_power_w = 200000.0      # traction maps sized from 380 kW
n_parallel = 14               # 130 s x 14 p A123 cells
aux_power_w = 5000.0
"""


def main(out: Path) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    stop_s = 300.0 if os.environ.get("SHEVSIM_EXAMPLE_QUICK", "") not in ("", "0") else None
    runs = {"bus 12 t, 150 kW": shevsim.simulate(shevsim.load_scenario(text=BUS), stop_s=stop_s),
            "M-ATV 15.6 t, 261 kW": shevsim.simulate("hd_udds_mpc", stop_s=stop_s)}
    (out / "bus_12t.toml").write_text(BUS)
    keys = ["distance_km", "fuel_mass_g", "fuel_economy_dsoc_corrected_kmpl", "fuel_economy_soc_sustained_kmpl",
            "delta_soc_pct"]
    print(shevsim.metrics_table(list(runs.values()), keys, labels=list(runs)).T.to_string(
        float_format=lambda x: f"{x:.4g}"))
    return runs


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="bus_vs_matv_")))
