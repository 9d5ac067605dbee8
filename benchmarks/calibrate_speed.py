"""calibrate_speed.py - the whole calibration workflow on a 1-hour, 10 Hz record (36,001 samples).

Prints the wall time of `run_workflow` (fit, candidate tests, selection, refit, overlay, replay through the master, report with plots) for the
cell model (synthetic record with a cooling change), the vehicle model (synthetic record with a
regeneration limit) and the engine soot model (transient soot).  Target: under a minute each on this machine.

    python benchmarks/calibrate_speed.py
"""
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from shevsim.calibrate.synthetic import CELL_NOMINAL, as_measured, synth_cell, synth_engine, synth_vehicle  # noqa: E402
from shevsim.calibrate.workflow import run_workflow  # noqa: E402


def main():
    # warm-up (numba compile / cache load) on a tiny record
    df, _ = synth_cell({}, duration_s=300.0)
    run_workflow("cell", as_measured(df, "cell"), dict(CELL_NOMINAL), effects=["current_offset"])
    cases = [("cell", *synth_cell({"cooling_change": {}}, duration_s=3600.0, dt_s=0.1)),
             ("vehicle", *synth_vehicle({"regen_limit": {}}, duration_s=3600.0, dt_s=0.1)),
             ("engine", *synth_engine({"transient_soot": {}}, duration_s=3600.0, dt_s=0.1))]
    for model, df, _ in cases:
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            rep = run_workflow(model, as_measured(df, model), dict(CELL_NOMINAL) if model == "cell" else None,
                               out_dir=out)
            dt = time.perf_counter() - t0
        print(f"{model:8s} {len(df)} samples (1 h at 10 Hz): workflow {dt:6.1f} s "
              f"({rep['n_simulations']} simulations, selected {rep['selected_effects']})")


if __name__ == "__main__":
    main()
