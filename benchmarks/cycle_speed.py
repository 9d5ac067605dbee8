"""Benchmark: one whole HD-UDDS co-simulation on one core (issue 4, SPEC section 6).

All components of ``scenarios/hd_udds_mpc.toml`` (cycle, driver, motor, vehicle, bus, engine-generator,
battery pack, BMS with DEKF + thermal DKF + power capability every 0.1 s step, MPC supervisor every
0.2 s), recording every output, one HD-UDDS (``cycle.repeat=1``, 1060 s, 10,600 steps).

Prints

* process start-up costs: imports, and building the master (includes loading the numba-compiled QP
  vector build from its cache, or compiling it on the first run after a code change);
* wall seconds of the run (best of N and median; also the process CPU seconds: on a shared machine
  wall time includes waiting for the core) and simulated seconds per wall second;
* the supervisor call (state -> QP -> first move, timed around ``MPCSupervisor.step`` inside the
  component; kept in the component's ``call_times_us`` attribute, never in the recorded outputs):
  mean, median and p99 [us];
* the same run with the supervisor on the readable cvxpy reference path
  (``--set supervisor.solver="cvxpy"``), measured in the same process, and the wall-time ratio;
* the compiled whole-vehicle loop (``shevsim.fast``) on the same scenario: wall times, the ratio to the
  master and whether every recorded signal equals the master's;
* a cProfile table (top 15 functions by own time) of one master run.

    python benchmarks/cycle_speed.py [--runs 3] [--no-cvxpy] [--no-profile] [--cpu N]

The process is pinned to one CPU (``os.sched_setaffinity``, default: the CPU it is running on) and
BLAS threads are limited to one.
"""
from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import pstats  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "hd_udds_mpc.toml"


def _pin(cpu: int | None) -> str:
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity)"
    if cpu is None:
        try:
            cpu = os.sched_getcpu()
        except AttributeError:
            cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def _run_once(sc, build_master, stop_time, collect=True):
    m = build_master(sc)
    sup = m.components["supervisor"]
    if collect:
        sup.call_times_us = []
    stop = stop_time(sc, m)
    c0, w0 = time.process_time(), time.perf_counter()
    res = m.run(stop, sc.t0_s)          # initialise, 10,600 steps, result arrays
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return m, res, wall, cpu, list(sup.call_times_us or [])


def _p99(xs):
    s = sorted(xs)
    return s[min(len(s) - 1, int(round(0.99 * (len(s) - 1))))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="timed runs of the fast path (default 3)")
    ap.add_argument("--no-cvxpy", action="store_true", help="skip the cvxpy-path run")
    ap.add_argument("--no-profile", action="store_true", help="skip the cProfile table")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: the current one)")
    args = ap.parse_args(argv)

    pin = _pin(args.cpu)
    t0 = time.perf_counter()
    sys.path.insert(0, str(ROOT))
    import shevsim
    from shevsim.core.scenario import build_master, load_scenario, stop_time
    t_import = time.perf_counter() - t0
    sc = load_scenario(SCENARIO, ["cycle.repeat=1"])
    t0 = time.perf_counter()
    build_master(sc)                     # first build: loads (or compiles) the numba QP build
    t_first_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_master(sc)
    t_build = time.perf_counter() - t0

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"# cycle_speed: {SCENARIO.relative_to(ROOT)} with cycle.repeat=1, {pin}, "
          f"load average {load[0]:.2f} on {os.cpu_count()} CPUs; shevsim from {Path(shevsim.__file__).parent}")
    print(f"start-up: import shevsim {t_import:.3f} s; first build_master {t_first_build:.3f} s "
          f"(numba QP build from cache or compiled); later build_master {t_build:.3f} s")

    walls, cpus, calls = [], [], []
    res = None
    for _ in range(args.runs):
        m, res, wall, cpu, ct = _run_once(sc, build_master, stop_time)
        walls.append(wall)
        cpus.append(cpu)
        calls.extend(ct)
    sim_s = float(res.time_s[-1] - res.time_s[0])
    n_steps = len(res.time_s) - 1
    fb = float(res["supervisor.fallback_count"][-1])
    best, med = min(walls), statistics.median(walls)
    print(f"simulated {sim_s:.0f} s in {n_steps} steps; {len(res.signals)} signals recorded; "
          f"MPC fallbacks {fb:.0f}")
    print(f"Python master (MPC daqp): wall best {best:.3f} s, median {med:.3f} s over {args.runs} runs "
          f"(CPU best {min(cpus):.3f} s); {sim_s / best:.0f} simulated s per wall s; "
          f"{best / n_steps * 1e6:.1f} us per step")
    print(f"supervisor call (state -> QP -> first move), {len(calls)} calls: mean {statistics.fmean(calls):.1f} us, "
          f"median {statistics.median(calls):.1f} us, p99 {_p99(calls):.1f} us")

    # the compiled whole-vehicle loop (shevsim.fast) on the same scenario, same process
    from shevsim.fast import runner_for
    run, why = runner_for(sc)
    if run is None:
        print(f"compiled whole-vehicle loop: not eligible ({why})")
    else:
        stop = stop_time(sc, run.master)
        t0 = time.perf_counter()
        run(stop)                        # loads (or compiles) the loop
        t_first = time.perf_counter() - t0
        fw = []
        for _ in range(max(args.runs, 5)):
            t0 = time.perf_counter()
            rf = run(stop)
            fw.append(time.perf_counter() - t0)
        same = all(bool((rf[k] == res[k]).all()) for k in res.signals)
        print(f"compiled whole-vehicle loop (shevsim.fast): wall best {min(fw):.3f} s, median {statistics.median(fw):.3f} s "
              f"over {len(fw)} runs ({min(fw) / n_steps * 1e6:.1f} us per step; first run {t_first:.2f} s); "
              f"master / loop {best / min(fw):.1f}x; every signal equal to the master's: {same}")

    # the same call in CPU time (thread_time: not inflated by waiting for the core on a shared machine),
    # one extra run with MPCSupervisor.step wrapped
    m = build_master(sc)
    mpc = m.components["supervisor"].mpc
    inner, cpu_calls, tt = mpc.step, [], time.thread_time

    def timed_step(*a):
        c0 = tt()
        r = inner(*a)
        cpu_calls.append((tt() - c0) * 1e6)
        return r
    mpc.step = timed_step
    m.run(stop_time(sc, m), sc.t0_s)
    print(f"supervisor call in CPU time (thread_time), {len(cpu_calls)} calls: mean {statistics.fmean(cpu_calls):.1f} us, "
          f"median {statistics.median(cpu_calls):.1f} us, p99 {_p99(cpu_calls):.1f} us")

    if not args.no_cvxpy:
        scx = load_scenario(SCENARIO, ["cycle.repeat=1", 'supervisor.solver="cvxpy"'])
        _, resx, wall_x, cpu_x, ctx = _run_once(scx, build_master, stop_time)
        d_fuel = float(resx["engine_generator.fuel_mass_g"][-1] - res["engine_generator.fuel_mass_g"][-1])
        print(f"cvxpy path: wall {wall_x:.3f} s (CPU {cpu_x:.3f} s); supervisor call mean "
              f"{statistics.fmean(ctx):.0f} us, p99 {_p99(ctx):.0f} us; ratio cvxpy / daqp wall "
              f"{wall_x / best:.1f}x (call mean ratio {statistics.fmean(ctx) / statistics.fmean(calls):.0f}x); "
              f"final fuel differs by {d_fuel:+.3g} g")

    if not args.no_profile:
        m = build_master(sc)
        stop = stop_time(sc, m)
        pr = cProfile.Profile()
        pr.enable()
        m.run(stop, sc.t0_s)
        pr.disable()
        buf = io.StringIO()
        st = pstats.Stats(pr, stream=buf).sort_stats("tottime")
        st.print_stats(15)
        text = buf.getvalue().replace(str(ROOT) + "/", "")
        lines = text.splitlines()
        start = next((i for i, ln in enumerate(lines) if "ncalls" in ln), 0)
        print("cProfile, one fast-path run (profiling inflates times ~2-3x; look at the shares), top 15 by own time:")
        print("\n".join(lines[start:]).rstrip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
