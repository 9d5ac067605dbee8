"""Cluster scaling: evaluations/s of the same campaign on 1 and 2 Dask workers started as separate processes.

    python benchmarks/cluster_scaling.py                       # UAC proxy + MPC, 24 maps, best of 2
    python benchmarks/cluster_scaling.py --batch 48 --repeat 3
    python benchmarks/cluster_scaling.py --scenario my.toml --stop-s 600

A ``dask scheduler`` and ``dask worker`` processes (one thread each, no nanny, each in a working directory of
its own) are started on 127.0.0.1 by :class:`shevsim.studies.proc_cluster.ProcessCluster`, as an operator
would start them by hand (docs/cluster.md).  The client connects with ``--scheduler`` semantics
(``StudyRunner(scheduler=...)``: version check, warm-up of the compiled loop on every worker, off the clock)
and evaluates the same batch of ``--batch`` distinct constant-rate power-rate maps without a cache, first
with worker ``w1`` alone, then with ``w2`` added; ``w2`` is stopped again and the pair repeated ``--repeat``
times (best of each: the machine is shared).  Each evaluation's scenario travels to the workers as a bundle
(``shevsim.studies.bundle``), so the figure includes shipping the files.

Efficiency = (evaluations/s with 2 workers) / (2 x evaluations/s with 1).  On a machine whose cores are
shared with other jobs it is only as good as the machine is quiet: the load average is printed with it.
The last line reads ``cluster: 1 worker X eval/s, 2 workers Y eval/s, efficiency Z``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from shevsim.core.scenario import PROJECT_ROOT
from shevsim.studies.parallel import StudyRunner
from shevsim.studies.problem import DEFAULT_EDGES_W, ScenarioProblem
from shevsim.studies.proc_cluster import ProcessCluster

DEFAULT_SCENARIO = PROJECT_ROOT / "scenarios" / "uac_proxy_mpc.toml"


def _timed(address: str, n_workers: int, items) -> tuple[float, list]:
    with StudyRunner(None, scheduler=address, progress=False) as r:
        if r.stats.slots != n_workers:
            raise RuntimeError(f"expected {n_workers} worker(s), the scheduler has {r.stats.slots}")
        t0 = time.perf_counter()
        out = r.evaluate(items)
        return time.perf_counter() - t0, out


def _wait_workers(address: str, n: int) -> None:
    from distributed import Client
    with Client(address, timeout="60s") as c:
        c.wait_for_workers(n, timeout=180)
        t_end = time.monotonic() + 60
        while len(c.scheduler_info()["workers"]) != n and time.monotonic() < t_end:
            time.sleep(0.1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default=str(DEFAULT_SCENARIO))
    ap.add_argument("--stop-s", type=float, default=None, help="shorter runs (s)")
    ap.add_argument("--batch", type=int, default=24, help="evaluations in the timed batch")
    ap.add_argument("--repeat", type=int, default=2, help="alternating repetitions of the 1- vs 2-worker timing")
    a = ap.parse_args(argv)

    problem = ScenarioProblem(str(Path(a.scenario).resolve()), "supervisor", a.stop_s)
    rates = [5e3 + i * 25e3 / max(1, a.batch - 1) for i in range(a.batch)]
    items = [problem.item(DEFAULT_EDGES_W, [r] * (len(DEFAULT_EDGES_W) - 1)) for r in rates]
    print(f"problem: {problem.describe()}, {a.batch} evaluations per timing, {os.cpu_count()} CPUs, "
          f"load average before {os.getloadavg()[0]:.2f}")
    env = {"PYTHONPATH": os.pathsep.join(p for p in (str(PROJECT_ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    t1s, t2s, ref = [], [], None
    with ProcessCluster(env=env) as cluster:
        address = cluster.start_scheduler()
        cluster.start_worker("w1")
        for k in range(a.repeat):
            _wait_workers(address, 1)
            t, o1 = _timed(address, 1, items)
            t1s.append(t)
            cluster.start_worker(f"w2-{k}")
            _wait_workers(address, 2)
            t, o2 = _timed(address, 2, items)
            t2s.append(t)
            cluster.kill(f"w2-{k}")
            ref = ref or o1
            if o1 != ref or o2 != ref:
                print("results differ between runs: were the shevsim sources edited meanwhile?", file=sys.stderr)
                return 1
    t1, t2 = min(t1s), min(t2s)
    r1, r2 = a.batch / t1, a.batch / t2
    eff = r2 / (2 * r1)
    print(f"  1-worker times {[round(x, 2) for x in t1s]} s, 2-worker times {[round(x, 2) for x in t2s]} s; "
          f"results identical across all runs; load average after {os.getloadavg()[0]:.2f}")
    print(f"cluster: 1 worker {r1:.3g} eval/s, 2 workers {r2:.3g} eval/s, efficiency {eff:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
