"""first_run.py - a new user's first contact: the wall time of the first and second ``shevsim run`` after
installing the wheel, and of the first run of a scenario with a new component layout (issue 26).

What it does, as a user would:

1. builds the wheel of the repository (``pip wheel --no-deps``, as a release would: the build hook
   ``hatch_build.py`` precompiles shevsim's numba code into the wheel when this interpreter has numba;
   ``--repo`` picks another checkout, e.g. main before a change) and installs it into a fresh venv
   (``--system-site-packages``: the dependencies come from this interpreter; the wheel itself with
   ``--no-deps``) with an empty user cache folder, so nothing compiled on this machine before is used;
2. in an empty folder, times ``shevsim run`` (the bundled hd_udds_mpc, with its plots) twice, one after the
   other, and then a 5 s scenario with a layout no run used before (cycle, driver, vehicle only);
3. prints each command's wall and CPU time (CPU = user + sys of the child and its children: the host is
   shared, so the wall time also shows the other loads) and ends with
   ``first run: X s, second run: Y s, new layout: Z s`` (wall).

Usage: ``python benchmarks/first_run.py [--repo PATH] [--keep DIR] [--cpu NAME]`` (takes 2-6 minutes, the
wheel's build included; a background build started by a run is waited for before the folder is removed, and
its time is reported too).  ``--cpu generic`` runs the three commands with ``NUMBA_CPU_NAME=generic``: numba
then targets another CPU than the one the wheel was built on, as on a user's machine of another model (the
precompiled code does not fit, and what the runs need compiles on first use).
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

NEW_LAYOUT = """\
# a layout no bundled scenario has: the vehicle with its driver on the cycle (issue 26's "vehicle-only" run)
[scenario]
name = "vehicle_only"
step_s = 0.1
stop_s = 5.0
order = ["cycle", "driver", "vehicle"]

[components.cycle]
type = "cycle"
params = "cycle/hd_udds"

[components.driver]
type = "driver"
params = "driver/default"

[components.vehicle]
type = "vehicle"
params = "vehicle/matv"

[connections]
"driver.speed_ref_mps" = "cycle.speed_ref_mps"
"driver.accel_ref_mps2" = "cycle.accel_ref_mps2"
"driver.speed_mps" = "vehicle.speed_mps"
"vehicle.traction_force_n" = "driver.force_req_n"
"""


def _timed(cmd, cwd, env, log) -> tuple[float, float, int, str]:
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    log.write(f"$ {' '.join(map(str, cmd))}\n{p.stdout}\n")
    return wall, cpu, p.returncode, p.stdout


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]), help="checkout to build the wheel of")
    ap.add_argument("--keep", help="keep the venv and the work folder here (default: a temporary folder)")
    ap.add_argument("--wheel", help="install this wheel instead of building one")
    ap.add_argument("--cpu", help="NUMBA_CPU_NAME for the runs (e.g. generic: another CPU than the build's)")
    a = ap.parse_args(argv)
    root = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="shevsim_first_run_"))
    root.mkdir(parents=True, exist_ok=True)
    log = open(root / "first_run.log", "w")
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "SHEVSIM_BACKGROUND_COMPILE", "SHEVSIM_CACHE_DIR",
                        "VIRTUAL_ENV")}
    env["SHEVSIM_CACHE_DIR"] = str(root / "user_cache")      # a new user's empty cache folder (.../shevsim)
    env["MPLBACKEND"] = "Agg"
    try:
        dist = root / "dist"
        t0 = time.perf_counter()
        r0 = r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if a.wheel:
            wheel = Path(a.wheel).resolve()
        else:
            print(f"building the wheel of {a.repo} ...", flush=True)
            # the venv below takes numba & co. from this interpreter: the build compiles with it too (in pip's
            # isolated build environment the newest numba/numpy would be used, which this one may not hold)
            subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), a.repo],
                           check=True, env={**env, "SHEVSIM_BUILD_PYTHON": sys.executable})
            r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            wheel = sorted(dist.glob("shevsim-*.whl"))[-1]
        import json
        import zipfile
        with zipfile.ZipFile(wheel) as z:
            names = z.namelist()
            man = json.loads(z.read("shevsim/_jitcache/manifest.json")) if "shevsim/_jitcache/manifest.json" \
                in names else None
        head = f"wheel {wheel.name}; " if a.wheel else \
            (f"wheel built in {time.perf_counter() - t0:.0f} s wall, "
             f"{(r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime):.0f} s CPU; ")
        print(head + (f"precompiled code: {man['indexes']} function caches for numba {man['numba']}, CPU "
                      f"{man['cpu'][1]}, {len(man['layouts'])} fast loop(s)" if man else "no precompiled code"),
              flush=True)
        venv = root / "venv"
        subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
        py = venv / "bin" / "python"
        subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)],
                       check=True, env=env)
        where = subprocess.run([str(py), "-c", "import shevsim; print(shevsim.__file__)"], env=env, text=True,
                               stdout=subprocess.PIPE, check=True, cwd=root).stdout.strip()
        if not where.startswith(str(venv)):
            raise SystemExit(f"the venv imports shevsim from {where}, not from the wheel: aborted")
        print(f"installed {wheel.name} -> {where}", flush=True)
        env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
        if a.cpu:
            env["NUMBA_CPU_NAME"] = a.cpu
            print(f"runs with NUMBA_CPU_NAME={a.cpu}", flush=True)
        work = root / "work"
        work.mkdir()
        (work / "vehicle_only.toml").write_text(NEW_LAYOUT)
        exe = str(venv / "bin" / "shevsim")
        rows = []
        for label, cmd in (("first run", [exe, "run"]), ("second run", [exe, "run"]),
                           ("new layout", [exe, "run", "vehicle_only.toml"])):
            wall, cpu, rc, out = _timed(cmd, work, env, log)
            engine = next((ln.split("engine ")[1].split(",")[0] for ln in out.splitlines()
                           if ln.startswith("scenario ") and "engine " in ln), "?")
            rows.append((label, wall, cpu, rc, engine))
            print(f"{label:11s} wall {wall:6.1f} s  cpu {cpu:6.1f} s  exit {rc}  engine {engine}", flush=True)
            if rc != 0:
                print(out[-2000:], file=sys.stderr)
        # a background build started by a run (shevsim.warmup): wait for it and report how long it took
        t0 = time.perf_counter()
        state = root / "user_cache" / "shevsim" / "warmup"
        locks = lambda: list(state.glob("warmup-*.lock"))  # noqa: E731
        while locks() and time.perf_counter() - t0 < 900:
            time.sleep(2)
        logs = list(state.glob("warmup.log"))
        if logs:
            text = logs[0].read_text().strip()
            print("background builds:\n  " + text.replace("\n", "\n  "), flush=True)
            wall, cpu, rc, out = _timed([exe, "run"], work, env, log)
            engine = next((ln.split("engine ")[1].split(",")[0] for ln in out.splitlines()
                           if ln.startswith("scenario ") and "engine " in ln), "?")
            print(f"{'after build':11s} wall {wall:6.1f} s  cpu {cpu:6.1f} s  exit {rc}  engine {engine}", flush=True)
        print(f"log: {root / 'first_run.log'}")
        first, second, new = (r[1] for r in rows)
        print(f"first run: {first:.1f} s, second run: {second:.1f} s, new layout: {new:.1f} s")
        return 0 if all(r[3] == 0 for r in rows) else 1
    finally:
        log.close()
        if not a.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
