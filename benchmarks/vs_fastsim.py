"""Side by side with FASTSim 3 (Rust core) on this machine, in one run.

    python benchmarks/vs_fastsim.py                 # installs FASTSim into benchmarks/.venv-fastsim if needed
    python benchmarks/vs_fastsim.py --repeat 7 --campaign 40
    python benchmarks/vs_fastsim.py --fastsim-python /path/to/python   # an existing FASTSim environment

FASTSim is a benchmark dependency, not a project one: it lives in its own virtual environment
(``benchmarks/.venv-fastsim``, git-ignored), created with ``python -m venv`` and ``pip install
'fastsim>=3,<4'`` on first use, and is driven through a subprocess of that environment's Python.

What is timed (median of ``--repeat`` >= 5 runs each, start-up excluded and reported separately):

* FASTSim: its bundled HEV (``2016_TOYOTA_Prius_Two.yaml``) over our HD-UDDS trace (``cycles/hd_udds.csv``,
  1 s samples; FASTSim does not bundle HD-UDDS); one run = ``SimDrive(vehicle, cycle)`` + ``run()`` (``walk()``
  before 3.1), the vehicle's history saved every step (its ``save_interval = 1``).
  Start-up = import + vehicle/cycle load + first run.
* shevsim: ``scenarios/hd_udds_rule.toml`` and ``scenarios/hd_udds_mpc.toml`` with ``cycle.repeat=1`` (one
  HD-UDDS, 1060 s at the scenario's 0.1 s communication step, BMS in the loop, every output recorded);
  one run = the fast path's ``runner(1060.0)`` (the whole simulation from t0 to the stop, recording
  included), the runner built once (``runner_for``). Start-up = import + scenario load + runner build +
  first run (numba's on-disk cache loaded, or compiled on the very first use). The full
  ``shevsim.run.simulate`` call (scenario build + run + metrics) is reported too.
* Campaign: ``--campaign`` distinct constant power-rate maps on ``scenarios/uac_proxy_mpc.toml`` (UAC
  proxy x2, MPC), evaluated by ``shevsim.studies`` on 2 Dask workers (no cache); the cluster start and
  its warm-up (one evaluation on every worker, one through the client) are excluded; evaluations/s =
  evaluations / wall time.

The load average is printed before and after: on a shared machine the ratios are only as good as the
machine is quiet. The output ends with exactly three lines::

    rule HD-UDDS ratio shevsim/FASTSim: X
    mpc HD-UDDS ratio shevsim/FASTSim: Y
    campaign evaluations/s (2 workers, UAC proxy x2, MPC): Z
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import venv
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
VENV = HERE / ".venv-fastsim"

FASTSIM_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import fastsim as fsim
cyc_file, repeat = sys.argv[1], int(sys.argv[2])
data = np.loadtxt(cyc_file, delimiter=",", skiprows=1)
veh = fsim.Vehicle.from_resource("2016_TOYOTA_Prius_Two.yaml")
cd = {"time_seconds": data[:, 0].tolist(), "speed_meters_per_second": data[:, 1].tolist()}
try:
    cyc = fsim.Cycle.from_dict(cd)
except Exception:
    cyc = fsim.Cycle.from_pydict(cd)
go = "run" if hasattr(fsim.SimDrive, "run") else "walk"
def once():
    sd = fsim.SimDrive(veh, cyc)
    getattr(sd, go)()
    return sd
sd = once()
startup = time.perf_counter() - t0
times = []
for _ in range(repeat):
    t = time.perf_counter()
    once()
    times.append(time.perf_counter() - t)
print(json.dumps({"version": fsim.__version__, "startup_s": startup, "times_s": times,
                  "n_samples": int(data.shape[0])}))
"""


def loadavg() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover
        return "n/a"


def fastsim_python(explicit: str | None) -> str:
    """The Python of an environment with FASTSim 3 (created in benchmarks/.venv-fastsim if needed)."""
    if explicit:
        return explicit
    py = VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    ok = py.exists() and subprocess.run([str(py), "-c", "import fastsim"], capture_output=True).returncode == 0
    if not ok:
        print(f"installing FASTSim 3 into {VENV} (benchmark dependency) ...", flush=True)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
        subprocess.run([str(py), "-m", "pip", "install", "-q", "fastsim>=3,<4"], check=True)
    return str(py)


def run_fastsim(py: str, repeat: int) -> dict:
    cyc = ROOT / "cycles" / "hd_udds.csv"
    out = subprocess.run([py, "-c", FASTSIM_SCRIPT, str(cyc), str(repeat)], capture_output=True, text=True,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    if out.returncode != 0:
        raise SystemExit(f"FASTSim run failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_shevsim(name: str, repeat: int) -> dict:
    t0 = time.perf_counter()
    from shevsim.core.scenario import load_scenario
    from shevsim.fast import runner_for
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml", ["cycle.repeat=1"])
    run, why = runner_for(sc)
    if run is None:
        raise SystemExit(f"{name}: not eligible for the fast path: {why}")
    stop = 1060.0
    res = run(stop)
    startup = time.perf_counter() - t0
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        res = run(stop)
        times.append(time.perf_counter() - t)
    # the whole user-level call (scenario build + run + metrics), for reference
    from shevsim.run import simulate
    sim = []
    for _ in range(max(3, repeat // 2)):
        t = time.perf_counter()
        simulate(load_scenario(ROOT / "scenarios" / f"{name}.toml", ["cycle.repeat=1"]), engine="fast")
        sim.append(time.perf_counter() - t)
    return {"startup_s": startup, "times_s": times, "simulate_s": sim, "steps": len(res.time_s) - 1,
            "signals": len(res.signals), "fuel_g": float(res["engine_generator.fuel_mass_g"][-1])}


def run_campaign(n: int, workers: int = 2) -> dict:
    from shevsim.studies.parallel import StudyRunner
    from shevsim.studies.problem import DEFAULT_EDGES_W, ScenarioProblem
    problem = ScenarioProblem(str(ROOT / "scenarios" / "uac_proxy_mpc.toml"))
    rates = [5e3 + 25e3 * i / max(n - 1, 1) for i in range(n)]
    items = [problem.item(DEFAULT_EDGES_W, [r] * (len(DEFAULT_EDGES_W) - 1)) for r in rates]
    t0 = time.perf_counter()
    with StudyRunner(None, workers=workers, progress=False) as r:
        warm = problem.item(DEFAULT_EDGES_W, [31e3] * (len(DEFAULT_EDGES_W) - 1))
        r.client.run(warm.run)      # warm-up on every worker (compiled loop, data files), untimed
        r.evaluate([warm])          # and the client's submit / gather path, untimed
        startup = time.perf_counter() - t0
        t = time.perf_counter()
        out = r.evaluate(items)
        wall = time.perf_counter() - t
    bad = [o.get("error") or o.get("termination") for o in out
           if "error" in o or o.get("termination") != "completed"]
    return {"n": n, "wall_s": wall, "startup_s": startup, "evals_per_s": n / wall, "failed": bad}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=7, help="timed runs per model (>= 5)")
    ap.add_argument("--campaign", type=int, default=40, help="evaluations in the campaign")
    ap.add_argument("--fastsim-python", default=None, help="Python of an existing FASTSim 3 environment")
    a = ap.parse_args(argv)
    if a.repeat < 5:
        ap.error("--repeat must be >= 5")
    print(f"load average at start: {loadavg()}  (cpus: {os.cpu_count()})", flush=True)
    py = fastsim_python(a.fastsim_python)
    fs = run_fastsim(py, a.repeat)
    rule = run_shevsim("hd_udds_rule", a.repeat)
    mpc = run_shevsim("hd_udds_mpc", a.repeat)
    fs2 = run_fastsim(py, a.repeat)            # FASTSim again after ours: the load may have changed
    fs_all = fs["times_s"] + fs2["times_s"]
    med = statistics.median
    f_med = med(fs_all)
    print(f"FASTSim {fs['version']} HEV (Prius, bundled) over HD-UDDS ({fs['n_samples']} samples at 1 s): "
          f"median {1e3 * f_med:.1f} ms (min {1e3 * min(fs_all):.1f}, max {1e3 * max(fs_all):.1f}, n={len(fs_all)}); "
          f"start-up {fs['startup_s']:.2f} s")
    for name, r in (("rule", rule), ("mpc", mpc)):
        print(f"shevsim {name:4s} HD-UDDS fast path ({r['steps']} steps of 0.1 s, {r['signals']} signals recorded, "
              f"fuel {r['fuel_g']:.1f} g): median {1e3 * med(r['times_s']):.1f} ms "
              f"(min {1e3 * min(r['times_s']):.1f}, max {1e3 * max(r['times_s']):.1f}, n={len(r['times_s'])}); "
              f"{1e6 * med(r['times_s']) / r['steps']:.2f} us/step; start-up {r['startup_s']:.2f} s; "
              f"whole simulate() call median {1e3 * med(r['simulate_s']):.0f} ms")
    camp = run_campaign(a.campaign)
    print(f"campaign: {camp['n']} evaluations of UAC proxy x2 + MPC on 2 Dask workers in {camp['wall_s']:.2f} s "
          f"(cluster start + warm-up {camp['startup_s']:.1f} s, excluded); failed: {len(camp['failed'])}")
    print(f"load average at end: {loadavg()}")
    print(f"rule HD-UDDS ratio shevsim/FASTSim: {med(rule['times_s']) / f_med:.2f}")
    print(f"mpc HD-UDDS ratio shevsim/FASTSim: {med(mpc['times_s']) / f_med:.2f}")
    print(f"campaign evaluations/s (2 workers, UAC proxy x2, MPC): {camp['evals_per_s']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
