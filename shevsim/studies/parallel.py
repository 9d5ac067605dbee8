"""parallel.py - evaluate batches of study items on Dask distributed (or serially), through the cache.

:class:`StudyRunner` owns the compute resources of one study:

* ``workers=0`` and no scheduler: serial, in this process (tests, debugging);
* ``workers=N``: an embedded ``distributed.LocalCluster(n_workers=N, threads_per_worker=1,
  processes=True)`` whose worker processes get ``OPENBLAS_NUM_THREADS=1`` and friends
  (``evaluate.THREAD_ENV``) before NumPy loads, and malloc settings that keep evaluation-sized arrays off
  mmap (:data:`MALLOC_ENV`);
* ``scheduler="tcp://host:8786"``: a ``distributed.Client`` on an existing cluster (the runner
  does not start or stop that cluster; its workers must have been started with the single-thread settings
  in their environment, docs/cluster.md: set later, in a running worker, they would not reach NumPy's BLAS).

Before the first evaluation every worker is asked for its shevsim version and the hash of its package
sources (:meth:`StudyRunner.check_workers`): a worker that differs from the client is refused with both
named; a cluster without any worker is refused after ``worker_wait_s``.  Each evaluation task carries the
client's version and sources hash too: a worker that joins later with other ones refuses it, and the study
stops with the same message.

Workers share no files with the client: a scenario evaluation is sent as its captured run
(:mod:`.bundle`: values and file hashes) plus one Dask task per distinct set of files holding their bytes,
keyed by their hashes - fetched once by each worker that needs it, kept there for the next evaluation, and
recomputed by the scheduler (which holds the bytes in the task) should every worker holding it be lost.

:meth:`StudyRunner.evaluate` takes a list of evaluation items (``evaluate.py``), drops duplicate
keys, answers the cached ones from the SQLite cache, submits the rest as Dask futures, and, as each
future completes (``distributed.as_completed``), writes its row to the cache (one committed row per
finished evaluation - the client process is the single writer) and advances a tqdm bar showing done /
total, elapsed and the ETA. Results are returned in input order, so a run on any number of workers
returns exactly what the serial run returns (each evaluation is a deterministic function of its
inputs). ``max_new_evaluations`` stops a study cleanly after that many new evaluations
(:class:`StudyInterrupted`); a Ctrl-C does the same - finished rows stay committed and a rerun
resumes from them. Each worker reports the hash of the shevsim sources it runs; a result from a
worker whose sources differ from the key's (files edited while the study runs) is stored under the
key recomputed with the current sources when they match the worker's, otherwise used but not
cached - with a warning either way - so the cache never holds a result under a key it does not match.
"""
from __future__ import annotations

import hashlib
import logging
import os
import time
from dataclasses import dataclass, field

from ..core.errors import ShevsimError
from .evaluate import (THREAD_ENV, WorkerVersionError, code_version, run_item, shevsim_version,
                       warm_up_fast_path, worker_identity)

log = logging.getLogger(__name__)

#: glibc malloc settings of the embedded cluster's worker processes.  Dask starts workers with
#: ``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.pre-spawn-environ``), which also turns off glibc's
#: adaptive mmap threshold: every array above 128 KiB is then mmap-ed and unmapped again, and each
#: evaluation's temporaries (the recorded run, the metrics' arrays) page-fault afresh - measured: the metrics of
#: a UAC proxy x2 evaluation 11 ms in a worker vs 3 ms in a plain process, the run 174 vs 161 ms.  Arrays up to
#: 64 MiB come from the heap instead and up to 256 MiB of freed memory stays with the process for the next
#: evaluation.
MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(64 * 2**20), "MALLOC_TRIM_THRESHOLD_": str(256 * 2**20)}


class StudyInterrupted(ShevsimError):
    """The study stopped before finishing (evaluation budget reached or interrupted); rerun to resume."""


@dataclass
class RunnerStats:
    """Counters of a runner (cumulative over its batches)."""

    requested: int = 0        # items asked for
    unique: int = 0           # distinct keys among them (per batch, summed)
    cached: int = 0           # answered from the cache
    new: int = 0              # evaluated now
    wall_s: float = 0.0       # wall time spent running new evaluations
    busy_s: float = 0.0       # sum of the new evaluations' own wall times (in their workers)
    slots: int = 1            # parallel slots (workers x threads), 1 when serial
    not_cached: int = 0       # results not cached: the worker's code version differed from the key's
    code_versions: set = field(default_factory=set)   # code versions seen when the sources changed mid-study

    @property
    def evals_per_s(self) -> float:
        return self.new / self.wall_s if self.wall_s > 0 else float("nan")

    @property
    def efficiency(self) -> float:
        """Busy time / (slots x wall time): 1.0 = every slot always evaluating."""
        return self.busy_s / (self.slots * self.wall_s) if self.wall_s > 0 else float("nan")

    def as_dict(self) -> dict:
        return {"requested": self.requested, "unique": self.unique, "cached": self.cached, "new": self.new,
                "wall_s": self.wall_s, "busy_s": self.busy_s, "slots": self.slots,
                "evals_per_s": self.evals_per_s, "parallel_efficiency": self.efficiency,
                "not_cached_code_mismatch": self.not_cached,
                "code_changed_mid_study": bool(self.code_versions)}


#: up to this many new evaluations a study with ``workers="auto"`` runs serially: starting a cluster (a few
#: seconds, plus every worker loading the compiled code) costs more than it saves (4 evaluations: 12.5 s on a
#: 2-worker cluster against 2.3 s serially, issue 26)
SERIAL_MAX = 8
#: with ``workers="auto"``, at least this many new evaluations per worker
EVALS_PER_WORKER = 4


def _has_distributed() -> bool:
    import importlib.util
    return importlib.util.find_spec("distributed") is not None


def auto_workers(n_new: int, cpus: int | None = None) -> int:
    """The worker count ``workers="auto"`` takes for ``n_new`` new evaluations: 0 (serial, in this process)
    up to :data:`SERIAL_MAX` or on one core, else one per core but at least :data:`EVALS_PER_WORKER`
    evaluations each."""
    cpus = cpus if cpus is not None else (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                                          else (os.cpu_count() or 1))
    if n_new <= SERIAL_MAX or cpus < 2:
        return 0
    return max(2, min(cpus, n_new // EVALS_PER_WORKER))


class StudyRunner:
    """Evaluate items serially or on Dask, through an optional :class:`~.cache.EvaluationCache`.

    Parameters
    ----------
    cache : EvaluationCache or None
        Finished evaluations are read from and written to it (None: no caching).
    workers : int or "auto"
        0 = serial in this process; N > 0 = embedded LocalCluster with N single-thread processes (or, without
        dask distributed installed, a pool of N processes); ``"auto"``: from the number of new evaluations
        (:func:`auto_workers`: serial for a handful).
    scheduler : str or None
        Address of an existing Dask scheduler (overrides ``workers``).
    progress : bool
        Show tqdm progress bars.
    max_new_evaluations : int or None
        Stop (raise :class:`StudyInterrupted`) once this many new evaluations have finished.
    worker_wait_s : float
        With ``scheduler``: how long to wait for a first worker on a cluster that has none before refusing it.

    Use as a context manager so the embedded cluster is shut down::

        with StudyRunner(cache, workers=2) as runner:
            outputs = runner.evaluate(items)
    """

    def __init__(self, cache=None, workers: int | str = 0, scheduler: str | None = None, progress: bool = True,
                 max_new_evaluations: int | None = None, worker_wait_s: float = 60.0):
        self.auto = workers == "auto"
        if self.auto:
            workers = 0
        elif isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
            raise ValueError(f"workers must be an integer >= 0 or 'auto', got {workers!r}")
        self.cache = cache
        self.workers = int(workers)
        self.scheduler = scheduler
        self.progress = progress
        self.max_new = max_new_evaluations
        self.worker_wait_s = float(worker_wait_s)
        self.stats = RunnerStats()
        self._client = None
        self._cluster = None
        self._files: dict = {}          # bundle key -> future of {sha256: bytes} (the files of an evaluation)

    # -- lifecycle ---------------------------------------------------------------------------------
    @property
    def parallel(self) -> bool:
        return self.scheduler is not None or self.workers > 0

    def start(self) -> "StudyRunner":
        if not self.parallel or self._client is not None:
            return self
        if self.scheduler is None and not _has_distributed():
            self.stats.slots = self.workers     # the plain install: a process pool per evaluate()
            return self
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover
            raise ShevsimError("parallel studies need dask distributed: pip install 'shevsim[studies]' "
                               "(or use --workers 0)") from exc
        if self.scheduler is not None:
            try:
                self._client = Client(self.scheduler, timeout="30s")
            except OSError as exc:
                raise ShevsimError(f"--scheduler {self.scheduler}: cannot connect to the Dask scheduler: {exc}") from exc
            # (the BLAS thread variables cannot be set from here: a running worker has loaded NumPy already;
            # they must be in its environment when it starts - docs/cluster.md)
        else:
            import dask
            pre = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default=None) or {})
            pre.update(MALLOC_ENV)
            # the workers' statistical profiler samples their stacks every 10 ms for the dashboard: off (an
            # evaluation is compiled code and NumPy; the profile would show nothing it could act on)
            with dask.config.set({"distributed.nanny.pre-spawn-environ": pre,
                                  "distributed.worker.profile.enabled": False}):
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             dashboard_address=":0", env=dict(THREAD_ENV),
                                             silence_logs=logging.WARNING)
            self._client = Client(self._cluster)
        try:
            self.check_workers()
        except BaseException:
            self.close()
            raise
        nthreads = self._client.nthreads()
        self.stats.slots = max(1, sum(nthreads.values()))
        # every worker loads the compiled whole-vehicle loop now (start-up), not in its first evaluation
        try:
            self._client.run(warm_up_fast_path)
        except Exception:  # noqa: BLE001 - a warm-up failure only costs time later
            pass
        return self

    def _where(self) -> str:
        return f"--scheduler {self.scheduler}" if self.scheduler else "Dask cluster"

    def _mismatch(self, addr: str, info: dict, mine: dict, joined: bool = False) -> ShevsimError:
        """The error refusing worker ``addr`` whose :func:`worker_identity` ``info`` differs from ``mine``."""
        same = info.get("shevsim") == mine["shevsim"]
        return ShevsimError(
            f"{self._where()}: " + ("a worker that joined the study was refused: " if joined else "") +
            f"worker {addr} runs shevsim {info.get('shevsim')} (sources "
            f"{str(info.get('code_sha256'))[:12]}), this client shevsim {mine['shevsim']} (sources "
            f"{mine['code_sha256'][:12]}): " + ("the same version with other package sources; " if same
                                                else "") +
            f"install the client's shevsim on every worker (pip install 'shevsim[studies]=="
            f"{mine['shevsim']}') or run the client with the workers' version")

    def check_workers(self) -> None:
        """Refuse, before any evaluation, a cluster whose workers run another shevsim than this client (version
        or package sources), or none at all after waiting ``worker_wait_s`` for one to connect:
        :class:`~shevsim.core.errors.ShevsimError` naming both versions, or the scheduler."""
        where = self._where()
        mine = worker_identity()
        if not self._client.scheduler_info().get("workers"):
            try:
                self._client.wait_for_workers(1, timeout=self.worker_wait_s)
            except (TimeoutError, OSError):
                raise ShevsimError(f"{where}: no Dask worker connected to the scheduler within "
                                   f"{self.worker_wait_s:g} s; start workers with: dask worker "
                                   f"{self.scheduler or '<scheduler address>'} --nthreads 1") from None
        try:
            theirs = self._client.run(worker_identity)
        except (ImportError, AttributeError) as exc:     # the worker cannot even unpickle a shevsim function
            raise ShevsimError(f"{where}: a worker cannot run shevsim ({type(exc).__name__}: {exc}); install "
                               f"the client's version on every worker: pip install 'shevsim[studies]=="
                               f"{mine['shevsim']}'") from None
        for addr, info in sorted(theirs.items()):
            if (info.get("shevsim"), info.get("code_sha256")) != (mine["shevsim"], mine["code_sha256"]):
                raise self._mismatch(addr, info, mine)

    def close(self) -> None:
        self._files.clear()
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self) -> "StudyRunner":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def client(self):
        return self._client

    # -- evaluation --------------------------------------------------------------------------------
    def evaluate(self, items: list, desc: str = "evaluations") -> list[dict]:
        """Outputs of every item, in input order (duplicates evaluated once; cached ones not rerun)."""
        items = list(items)
        keys = [it.key() for it in items]
        first: dict[str, object] = {}
        for k, it in zip(keys, items):
            first.setdefault(k, it)
        self.stats.requested += len(items)
        self.stats.unique += len(first)
        results: dict[str, dict] = self.cache.get_many(first) if self.cache is not None else {}
        self.stats.cached += len(results)
        pending = [(k, it) for k, it in first.items() if k not in results]
        if pending:
            self._run_pending(pending, results, desc, n_cached=len(first) - len(pending))
        return [results[k] for k in keys]

    def _budget_left(self) -> int | None:
        return None if self.max_new is None else self.max_new - self.stats.new

    def _finish(self, key, item, out, wall, results, bar, worker_code=None) -> None:
        results[key] = out
        if worker_code is not None and worker_code != code_version():
            code_version.cache_clear()          # the sources changed since the key was made: rehash them
            if worker_code == code_version():
                log.warning("shevsim sources changed during the study: results from now on are keyed with the "
                            "new code version (earlier results of this study came from the old sources)")
                self.stats.code_versions.add(worker_code)
                key = item.key()
            else:
                self.stats.not_cached += 1
                if self.stats.not_cached == 1:
                    log.warning("a worker runs different shevsim sources than this process: its results are used "
                                "but not cached; restart the study for consistent results")
                key = None
        if key is not None and self.cache is not None:
            self.cache.put(key, item.inputs(), out, wall)
        self.stats.new += 1
        self.stats.busy_s += wall
        if bar is not None:
            bar.set_postfix_str(f"{bar.total - bar.n - 1} left, {self._n_cached} cached", refresh=False)
            bar.update(1)

    def _run_pending(self, pending, results, desc, n_cached) -> None:
        budget = self._budget_left()
        if budget is not None and budget <= 0:
            raise StudyInterrupted(f"evaluation budget of {self.max_new} new evaluations reached; "
                                   f"{len(pending)} left in '{desc}' - rerun to resume from the cache")
        bar = None
        self._n_cached = n_cached
        if self.progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=len(pending), desc=desc, unit="eval", dynamic_ncols=True,
                       bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} done{postfix} "
                                  "[{elapsed}<{remaining} ETA, {rate_fmt}]")
            bar.set_postfix_str(f"{len(pending)} left, {n_cached} cached", refresh=False)
        if self.auto and self._client is None and self.scheduler is None:
            self.workers = auto_workers(len(pending))
            if self.workers:
                log.info("%d new evaluations: %d worker processes", len(pending), self.workers)
        t0 = time.perf_counter()
        try:
            if self.parallel and self.scheduler is None and self._client is None and not _has_distributed():
                self._run_processes(pending, results, bar)
            elif not self.parallel:
                for k, it in pending:
                    if budget is not None and self.stats.new >= self.max_new:
                        break
                    payload, blobs = _payload(it)
                    out, wall, _ = run_item(payload, blobs)
                    self._finish(k, it, out, wall, results, bar)
            else:
                self._run_dask(pending, results, bar, n_cached)
        finally:
            self.stats.wall_s += time.perf_counter() - t0
            if bar is not None:
                bar.close()
        missing = [k for k, _ in pending if k not in results]
        if missing:
            raise StudyInterrupted(f"stopped after the budget of {self.max_new} new evaluations; {len(missing)} "
                                   f"left in '{desc}' - rerun to resume from the cache")

    def _files_future(self, client, blobs: dict):
        """The future of ``{sha256: bytes}`` for one evaluation's files: one task per distinct set of files,
        keyed by their hashes and holding the bytes itself, so each worker fetches it once (Dask keeps the
        replica for the next evaluation) and the scheduler can recompute it if every holder is lost."""
        if not blobs:
            return None
        key = hashlib.sha256("".join(sorted(blobs)).encode()).hexdigest()
        fut = self._files.get(key)
        if fut is None:
            fut = client.submit(_files, blobs, key=f"shevsim-files-{key}", pure=False)
            self._files[key] = fut
        return fut

    def _run_processes(self, pending, results, bar) -> None:
        """Without dask distributed (the plain install): a pool of ``workers`` processes from the standard
        library; results are the same (each evaluation is a pure function of its item)."""
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed
        self.stats.slots = self.workers
        ctx = mp.get_context("spawn")       # no fork of a process holding threads (tqdm, BLAS)
        with ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx) as pool:
            futures = {pool.submit(run_item, *_payload(it)): (k, it) for k, it in pending}   # the captured run
            try:
                for fut in as_completed(futures):
                    k, it = futures[fut]
                    out, wall, wcode = fut.result()
                    self._finish(k, it, out, wall, results, bar, wcode)
                    if self.max_new is not None and self.stats.new >= self.max_new:
                        break
            finally:
                for f in futures:
                    f.cancel()

    def _run_dask(self, pending, results, bar, n_cached) -> None:
        from distributed import as_completed
        self.start()
        client = self._client
        futures = {}
        version, code = shevsim_version(), code_version()
        for k, it in pending:
            payload, blobs = _payload(it)
            files = self._files_future(client, blobs)
            # every task carries the client's version and sources hash: a worker that joined after
            # check_workers with other ones refuses it (WorkerVersionError) instead of computing a result
            fut = client.submit(run_item, payload, files, version, code, pure=False,
                                key=f"shevsim-eval-{k[:24]}-{time.monotonic_ns()}")
            futures[fut] = (k, it)
        try:
            for fut in as_completed(list(futures)):
                k, it = futures[fut]
                try:
                    out, wall, wcode = fut.result()
                except WorkerVersionError as exc:
                    info = exc.args[0] if exc.args and isinstance(exc.args[0], dict) else {}
                    raise self._mismatch(info.get("address", "?"), info, worker_identity(), joined=True) from None
                self._finish(k, it, out, wall, results, bar, wcode)
                if self.max_new is not None and self.stats.new >= self.max_new:
                    break
        finally:
            left = [f for f in futures if not f.done()]
            if left:
                client.cancel(left)


def _payload(item) -> tuple:
    """``(what a worker runs, {sha256: bytes} of its files)``: a scenario evaluation's captured run, or the
    item itself (items without files, e.g. the synthetic problem's)."""
    pay = getattr(item, "payload", None)
    return pay() if pay is not None else (item, {})


def _files(blobs: dict) -> dict:
    """The task holding an evaluation's files (its result is its argument)."""
    return blobs
