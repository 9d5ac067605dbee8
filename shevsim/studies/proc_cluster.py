"""proc_cluster.py - a Dask scheduler and workers started as separate processes on this machine.

What an operator does by hand (``dask scheduler`` and ``dask worker``, see ``docs/cluster.md``), scripted
for the tests and ``benchmarks/cluster_scaling.py``: every process is a child of this one, on the loopback
address, and :meth:`ProcessCluster.close` (or leaving the ``with`` block) stops each one it started, by its
process id.  A worker can be given a view of the filesystem without some folders (``hide``): it then runs
in its own mount namespace (``unshare --mount``, root only) where each of those folders is covered by an
empty tmpfs, as a worker on another machine would not see them.  :func:`can_hide_folders` says whether this
machine allows it.

Workers run with ``--no-nanny`` (killing one is losing it: nothing restarts it), one thread each, their
working directory and Dask local directory in a folder of their own.
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..core.errors import ShevsimError
from .evaluate import THREAD_ENV


def can_hide_folders() -> bool:
    """True when worker processes can be started in a mount namespace with folders hidden (root + unshare)."""
    if shutil.which("unshare") is None or not hasattr(os, "geteuid") or os.geteuid() != 0:
        return False
    d = tempfile.mkdtemp(prefix="shevsim-probe-")
    try:
        r = subprocess.run(["unshare", "--mount", "sh", "-c", f"mount -t tmpfs -o size=64k x {shlex.quote(d)}"],
                           capture_output=True, timeout=30)
        return r.returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False
    finally:
        os.rmdir(d)


class ProcessCluster:
    """A scheduler and workers as child processes on 127.0.0.1.

    Parameters
    ----------
    hide : list of paths
        Folders the workers must not see (mount namespace; requires :func:`can_hide_folders`).
    env : dict
        Extra environment of every process (e.g. ``PYTHONPATH``).
    """

    def __init__(self, hide=(), env: dict | None = None, timeout_s: float = 120.0):
        self.hide = [str(Path(h).resolve()) for h in hide]
        if self.hide and not can_hide_folders():
            raise ShevsimError("hiding folders from workers needs root and unshare --mount")
        self.env = {**os.environ, **THREAD_ENV, **(env or {})}
        self.timeout_s = timeout_s
        self.root = Path(tempfile.mkdtemp(prefix="shevsim-cluster-"))
        self.scheduler_file = self.root / "scheduler.json"
        self.procs: dict[str, subprocess.Popen] = {}
        self.address: str | None = None

    def __enter__(self) -> "ProcessCluster":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _spawn(self, name: str, argv: list[str], cwd: Path, env: dict | None = None) -> subprocess.Popen:
        log = open(self.root / f"{name}.log", "wb")
        try:
            p = subprocess.Popen(argv, cwd=cwd, env={**self.env, **(env or {})}, stdout=log, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, start_new_session=True)
        finally:
            log.close()
        self.procs[name] = p
        return p

    def log(self, name: str) -> str:
        f = self.root / f"{name}.log"
        return f.read_text(errors="replace") if f.is_file() else ""

    def start_scheduler(self) -> str:
        """Start ``dask scheduler`` on 127.0.0.1 (random port); returns its address."""
        argv = [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                "--no-dashboard", "--scheduler-file", str(self.scheduler_file)]
        p = self._spawn("scheduler", argv, self.root)
        t_end = time.monotonic() + self.timeout_s
        while time.monotonic() < t_end:
            if p.poll() is not None:
                raise ShevsimError(f"dask scheduler exited ({p.returncode}): {self.log('scheduler')[-2000:]}")
            try:
                self.address = json.loads(self.scheduler_file.read_text())["address"]
                return self.address
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        raise ShevsimError(f"dask scheduler did not start within {self.timeout_s:g} s")

    def start_worker(self, name: str, env: dict | None = None) -> subprocess.Popen:
        """Start one ``dask worker`` process (one thread, no nanny) in a working directory of its own; ``env``:
        extra environment of this worker only."""
        if self.address is None:
            self.start_scheduler()
        wd = self.root / name
        wd.mkdir()
        argv = [sys.executable, "-m", "dask", "worker", self.address, "--nthreads", "1", "--nworkers", "1",
                "--no-nanny", "--no-dashboard", "--host", "127.0.0.1", "--name", name,
                "--local-directory", str(wd / "dask"), "--memory-limit", "0"]
        if self.hide:
            mounts = " && ".join(f"mount -t tmpfs -o size=64k,mode=0555 shevsim-hidden {shlex.quote(h)}"
                                 for h in self.hide)
            argv = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
                    f"{mounts} && exec {shlex.join(argv)}"]
        return self._spawn(name, argv, wd, env)

    def kill(self, name: str) -> None:
        """SIGKILL one process started here (a worker lost without warning)."""
        p = self.procs[name]
        if p.poll() is None:
            p.send_signal(signal.SIGKILL)
        p.wait(timeout=30)

    def close(self) -> None:
        """Stop every process started here (workers first), then remove the cluster's folder."""
        for name in sorted(self.procs, key=lambda n: n == "scheduler"):
            p = self.procs[name]
            if p.poll() is None:
                p.terminate()
        t_end = time.monotonic() + 10.0
        for name, p in self.procs.items():
            try:
                p.wait(timeout=max(0.1, t_end - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=30)
        self.procs.clear()
        shutil.rmtree(self.root, ignore_errors=True)
