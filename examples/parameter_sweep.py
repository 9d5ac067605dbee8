"""Sweep a parameter and plot a metric against it: vehicle mass vs fuel economy.

Runs the bundled ``hd_udds_rule`` scenario (one HD-UDDS cycle) for several vehicle masses and plots the
fuel economy corrected for the battery's net energy (``fuel_economy_dsoc_corrected_kmpl``, see
``shevsim/metrics.py``) against mass; also saves each run under OUT/mass_<kg>/.

    python examples/parameter_sweep.py [OUT]
    SHEVSIM_EXAMPLE_QUICK=1 python examples/parameter_sweep.py      # 3 masses, the first 300 s
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import shevsim  # noqa: E402

QUICK = os.environ.get("SHEVSIM_EXAMPLE_QUICK", "") not in ("", "0")


def main(out: Path) -> dict:
    masses_kg = [10000.0, 15554.0, 20000.0] if QUICK else [8000.0, 10000.0, 12500.0, 15554.0, 18000.0, 20000.0]
    stop_s = 300.0 if QUICK else None
    sc = shevsim.load_scenario("hd_udds_rule", {"cycle.repeat": 1})   # load once, change per point
    fe = {}
    for m in masses_kg:
        sc.set("vehicle.mass_kg", m)
        res = shevsim.simulate(sc, stop_s=stop_s, out=out / f"mass_{m:.0f}")
        fe[m] = res.metrics["fuel_economy_dsoc_corrected_kmpl"]
        print(f"mass {m:8.0f} kg: {res.termination}, fuel economy {fe[m]} km/L")
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([m / 1000 for m in fe], [fe[m] for m in fe], "o-")
    ax.set_xlabel("vehicle mass [t]")
    ax.set_ylabel("fuel economy, dSOC corrected [km/L]")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "sweep_mass.png", dpi=100)
    plt.close(fig)
    print(f"figure: {out / 'sweep_mass.png'}")
    return fe


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="shevsim_sweep_")))
