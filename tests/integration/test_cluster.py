"""Studies on a real Dask cluster whose workers share no files with the user (issue 28).

``dask scheduler`` and ``dask worker`` run as separate processes on 127.0.0.1 (``shevsim.studies.proc_cluster``),
each worker in a working directory of its own and - where this machine allows it (root + ``unshare``) - in a
mount namespace where the user's folder is covered by an empty tmpfs; elsewhere the user's folder is a copy
removed once the study has captured it.  The user's scenario names its own cycle, its own motor parameter
set with its own efficiency map beside it, and an overlay: all of it must reach the workers by content.

Each evaluation is one short run (a 300 s cycle of the user's own), a handful per study; every process
started here is stopped by the fixtures.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from shevsim.core.paths import DATA_ROOT  # noqa: E402
from shevsim.studies.bundle import capture  # noqa: E402
from shevsim.studies.cache import EvaluationCache  # noqa: E402
from shevsim.studies.evaluate import Evaluation  # noqa: E402
from shevsim.studies.parallel import StudyRunner  # noqa: E402
from shevsim.studies.problem import DEFAULT_EDGES_W, ScenarioProblem, map_overrides  # noqa: E402
from shevsim.studies.proc_cluster import ProcessCluster, can_hide_folders  # noqa: E402

WORKTREE = Path(__file__).resolve().parents[2]
# SHEVSIM_TEST_NO_UNSHARE=1 exercises the fallback (a copy of the user's folder removed before the study)
HIDE = can_hide_folders() and not os.environ.get("SHEVSIM_TEST_NO_UNSHARE")
CYCLE_S = 300
RATES_WPS = (30e3, 15e3, 7.5e3, 5e3, 20e3, 10e3)


def make_user_folder(d: Path) -> Path:
    """A user's scenario folder: the bundled MPC scenario with the user's own cycle (the first 300 s of the
    HD-UDDS), the user's own motor parameter set and efficiency map (the bundled map 2 % less efficient) and a
    vehicle overlay (1 t heavier); returns the scenario file."""
    d.mkdir(parents=True)
    lines = (DATA_ROOT / "cycles" / "hd_udds.csv").read_text().splitlines()
    (d / "mycycle.csv").write_text("\n".join(lines[:CYCLE_S + 2]) + "\n")
    (d / "mycycle.toml").write_text('[params]\ncycle_file = "mycycle.csv"\nrepeat = 1\n')
    (d / "motor").mkdir()
    src = (DATA_ROOT / "components" / "motor" / "motor_eff_map.csv").read_text().splitlines()
    out = [src[0]]
    for ln in src[1:]:
        if ln.strip() and not ln.startswith("#") and not ln.startswith("speed"):
            *head, eff = ln.split(",")
            ln = ",".join(head + [repr(float(eff) * 0.98)])
        out.append(ln)
    (d / "motor" / "mymap.csv").write_text("\n".join(out) + "\n")
    motor = (DATA_ROOT / "components" / "motor" / "default.toml").read_text()
    motor = motor.replace('"motor_eff_map.csv"', '"mymap.csv"').replace(
        '"motor_torque_curves.csv"', json.dumps(str(DATA_ROOT / "components" / "motor" / "motor_torque_curves.csv")))
    (d / "motor" / "mymotor.toml").write_text(motor)
    (d / "heavier.toml").write_text("[vehicle]\nmass_kg = 16554.0\n")
    text = (DATA_ROOT / "scenarios" / "hd_udds_mpc.toml").read_text()
    text = text.replace('params = "components/cycle/hd_udds.toml"', 'params = "mycycle.toml"')
    text = text.replace('params = "components/motor/default.toml"', 'params = "motor/mymotor.toml"')
    text = text.replace('params = "components/vehicle/matv.toml"',
                        'params = "components/vehicle/matv.toml"\noverlay = "heavier.toml"')
    text = text.replace('name = "hd_udds_mpc"', 'name = "my_study"')
    (d / "my.toml").write_text(text)
    return d / "my.toml"


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    """(scenario file, the study's problem captured on the client)."""
    scen = make_user_folder(tmp_path_factory.mktemp("user") / "project")
    prob = ScenarioProblem(str(scen), stop_s=None)
    prob.bundle()
    return scen, prob


@pytest.fixture(scope="module")
def cluster(user):
    scen, _ = user
    hide = [scen.parent] if HIDE else []
    with ProcessCluster(hide=hide, env={"PYTHONPATH": str(WORKTREE)}) as c:
        c.start_scheduler()
        c.start_worker("a")
        c.start_worker("b")
        yield c


def _items(prob, rates, engine="auto"):
    items = [prob.item(DEFAULT_EDGES_W, None)]
    items += [prob.item(DEFAULT_EDGES_W, [r] * (len(DEFAULT_EDGES_W) - 1)) for r in rates]
    if engine != "auto":
        items = [Evaluation.make(it.scenario, it.overrides_dict(), it.stop_s, engine=engine, bundle=prob.bundle())
                 for it in items]
    return items


@pytest.fixture(scope="module")
def serial(user):
    """Serial results of the fault tests' evaluations (the Python master: ~1 s each, so a study lasts long
    enough for things to happen to it)."""
    _, prob = user
    items = _items(prob, RATES_WPS, engine="python")
    return items, StudyRunner(None, progress=False).evaluate(items)


def _wait(pred, timeout_s=120.0, what="condition"):
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if pred():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def test_bundle_is_content_addressed_and_location_free(user, tmp_path):
    scen, prob = user
    b = prob.bundle()
    # every file the scenario references is captured by content, the user's and the bundled ones alike
    names = {t.split("/", 1)[1] for spec in b.scenario.components
             for t in list((spec.params_table or {}).values()) + list(spec.overrides.values())
             if isinstance(t, str) and t.startswith("shevsim-blob:")}
    # the pack's cell tables are shared quantities (issue 25): captured in the scenario's shared tables
    names |= {t.split("/", 1)[1] for t in list(b.scenario.shared_base.values()) + list(b.scenario.shared.values())
              if isinstance(t, str) and t.startswith("shevsim-blob:")}
    assert {"mycycle.csv", "mymap.csv", "motor_torque_curves.csv", "a123_26650_ocv.csv"} <= names
    assert b.scenario.component("vehicle").overrides["mass_kg"] == 16554.0          # the overlay's value
    # the same folder elsewhere gives the same keys; a changed byte in a referenced file changes them
    moved = tmp_path / "elsewhere"
    shutil.copytree(scen.parent, moved)
    it = _items(prob, (10e3,))
    it2 = _items(ScenarioProblem(str(moved / "my.toml")), (10e3,))
    assert [i.key() for i in it] == [i.key() for i in it2]
    (moved / "motor" / "mymap.csv").write_text((moved / "motor" / "mymap.csv").read_text().replace("0.", "0.0", 1))
    assert _items(ScenarioProblem(str(moved / "my.toml")), (10e3,))[1].key() != it[1].key()
    # what is shipped to a worker holds data only: the pickled run names no folder of the user's (the scenario
    # and parameter files by name, the origins of values without their folders, no scenario text)
    import pickle
    run, blobs = it[1].payload()
    shipped = pickle.dumps(run)
    assert str(scen.parent.parent).encode() not in shipped and str(moved).encode() not in shipped
    assert str(run.scenario.path) == "my.toml" and run.scenario.text == ""
    assert str(run.scenario.component("motor").params_file) == "mymotor.toml"
    assert run.scenario.component("vehicle").sources["mass_kg"].startswith("my.toml: ")
    assert capture(scen).scenario.component("cycle").params_table["cycle_file"].endswith("/mycycle.csv")


def test_study_on_separate_processes_identical_to_serial(user, cluster, tmp_path):
    scen, prob = user
    rates = (30e3, 10e3, 5e3)
    if not HIDE:
        # no mount namespace here: the study runs from a copy of the user's folder, captured and then removed
        # before the study starts (so neither the workers nor the client can open it)
        copy = Path(tempfile.mkdtemp(prefix="shevsim-user-")) / "project"
        shutil.copytree(scen.parent, copy)
        scen, prob = copy / "my.toml", ScenarioProblem(str(copy / "my.toml"))
        items = _items(prob, rates)
        for it in items:
            it.payload()
        shutil.rmtree(copy.parent)
    else:
        items = _items(prob, rates)
    from distributed import Client
    with Client(cluster.address, timeout="60s") as c:
        c.wait_for_workers(2, timeout=120)
        assert set(c.run(os.path.exists, str(scen)).values()) == {False}    # the workers cannot see it
        cwd = c.run(os.getcwd)
        assert all(not w.startswith(str(scen.parent)) for w in cwd.values())
    ref = StudyRunner(None, progress=False).evaluate(items)
    assert all("error" not in r for r in ref), ref
    with EvaluationCache(tmp_path / "c.sqlite") as cache, \
            StudyRunner(cache, scheduler=cluster.address, progress=False) as runner:
        assert runner.stats.slots == 2
        assert runner.evaluate(items) == ref
        assert runner.stats.new == len(items) and len(cache) == len(items)
        # the files went to each worker at most once (a Dask transfer of their one task), into its own store
        fetched = runner.client.run(lambda dask_worker: [str(k) for e in dask_worker.transfer_incoming_log
                                                         for k in e["keys"] if "shevsim-files" in str(k)])
        assert all(len(v) <= 1 for v in fetched.values()), fetched
        stored = runner.client.run(lambda dask_worker: sorted(
            p.parent.name + "/" + p.name
            for p in __import__("pathlib").Path(dask_worker.local_directory, "shevsim-files").glob("*/*")))
        wanted = {t.split(":", 1)[1] for it in items for t in it.payload()[0].tokens()}
        assert set().union(*map(set, stored.values())) == wanted and "mycycle.csv" in str(wanted)
    # the study command on the same cluster: same rows as the serial command
    if HIDE:
        from shevsim.studies.cli import main_study
        common = ["tradeoff", str(scen), "--rates-kwps", "30", "10", "5", "--no-plots", "--quiet"]
        assert main_study(common + ["--workers", "0", "-o", str(tmp_path / "ser")]) == 0
        assert main_study(common + ["--scheduler", cluster.address, "-o", str(tmp_path / "clu")]) == 0
        rows = [json.loads((tmp_path / o / "summary.json").read_text())["rows"] for o in ("ser", "clu")]
        assert rows[0] == rows[1] and len(rows[0]) == 3


def test_version_mismatch_refused_up_front(tmp_path):
    """A worker with another shevsim version: the client refuses before any evaluation, naming both."""
    pkg = tmp_path / "other"
    shutil.copytree(WORKTREE / "shevsim", pkg / "shevsim", ignore=shutil.ignore_patterns("__pycache__", "_data"))
    init = pkg / "shevsim" / "version.py"
    text = init.read_text()
    init.write_text(re.sub(r'__version__ = "[^"]+"', '__version__ = "0.0.9"', text))
    assert init.read_text() != text
    from shevsim import __version__
    from shevsim.core.errors import ShevsimError
    with ProcessCluster(env={"PYTHONPATH": str(pkg)}) as c:
        c.start_scheduler()
        c.start_worker("old")
        from distributed import Client
        with Client(c.address, timeout="60s") as cl:
            cl.wait_for_workers(1, timeout=120)
        with pytest.raises(ShevsimError) as ei:
            StudyRunner(None, scheduler=c.address, progress=False).start()
        msg = str(ei.value)
        assert "shevsim 0.0.9" in msg and f"shevsim {__version__}" in msg and c.address in msg


def test_faults_killed_worker_joining_worker_interrupted_client(user, cluster, serial, tmp_path):
    """Worker a killed mid-study (b carries on), then b killed too (the study waits, every replica of its files
    gone), worker c joins and finishes it; then a client interrupted by SIGINT and the study resumed against
    the same cluster.  Nothing lost, nothing run twice, results identical to the serial run."""
    from distributed import get_task_stream
    items, ref = serial
    n = len(items)
    with EvaluationCache(tmp_path / "f.sqlite") as cache, \
            StudyRunner(cache, scheduler=cluster.address, progress=False) as runner, \
            get_task_stream(runner.client) as ts:
        got, err = {}, []

        def study():
            try:
                got["out"] = runner.evaluate(items)
            except BaseException as exc:  # noqa: BLE001
                err.append(exc)

        th = threading.Thread(target=study, daemon=True)
        th.start()
        left = 0
        try:
            _wait(lambda: len(cache) >= 1 or err, what="a first result")
            cluster.kill("a")
            done_a = len(cache)
            _wait(lambda: len(cache) > done_a or err, what="a result of worker b alone")
            cluster.kill("b")
            left = n - len(cache)
        finally:
            cluster.start_worker("c")          # (also when a wait failed: the study thread can then end)
            th.join(timeout=300)
        assert left >= 1, "the study ended before the second kill: evaluations too short for this test"
        assert not th.is_alive() and not err, err
        assert got["out"] == ref and len(cache) == n and runner.stats.new == n
        c_addr = [a for a, w in runner.client.scheduler_info()["workers"].items() if w["name"] == "c"]
    workers = {t["worker"] for t in ts.data if "shevsim-eval" in str(t.get("key", ""))}
    assert len(c_addr) == 1 and c_addr[0] in workers          # the joining worker evaluated some

    # the client interrupted (SIGINT, as Ctrl-C), then the study resumed against the same cluster
    db = tmp_path / "i.sqlite"
    script = textwrap.dedent(f"""
        import sys
        from shevsim.studies.cache import EvaluationCache
        from shevsim.studies.evaluate import Evaluation
        from shevsim.studies.parallel import StudyRunner
        from shevsim.studies.problem import ScenarioProblem, DEFAULT_EDGES_W
        prob = ScenarioProblem({str(user[0])!r})
        items = [prob.item(DEFAULT_EDGES_W, None)] + [prob.item(DEFAULT_EDGES_W, [r] * 8) for r in {RATES_WPS!r}]
        items = [Evaluation.make(i.scenario, i.overrides_dict(), engine="python", bundle=prob.bundle()) for i in items]
        with EvaluationCache({str(db)!r}) as cache, StudyRunner(cache, scheduler={cluster.address!r},
                                                                progress=False) as r:
            print("started", flush=True)
            try:
                r.evaluate(items)
            except KeyboardInterrupt:
                sys.exit(130)
    """)
    env = {**os.environ, "PYTHONPATH": str(WORKTREE)}
    p = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        with EvaluationCache(db) as watch:
            _wait(lambda: p.poll() is not None or len(watch) >= 1, what="the client's first result")
            p.send_signal(signal.SIGINT)
            _, errtxt = p.communicate(timeout=120)
            assert p.returncode == 130, errtxt.decode()[-2000:]
            kept = len(watch)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert 1 <= kept < n
    with EvaluationCache(db) as cache, StudyRunner(cache, scheduler=cluster.address, progress=False) as runner:
        assert runner.evaluate(items) == ref
        assert runner.stats.cached == kept and runner.stats.new == n - kept and len(cache) == n


def test_no_worker_and_a_joining_worker_with_other_sources_refused(tmp_path, monkeypatch):
    """A scheduler without workers is refused (naming it; exit 2 from the study command) after a bounded wait;
    a worker with the same version but other package sources that joins after the client's check refuses the
    evaluations it receives, and the study stops naming both sources hashes (no result of it is used)."""
    import functools

    from shevsim.core.errors import ShevsimError
    from shevsim.studies import cli, parallel
    from shevsim.studies.evaluate import code_version
    from shevsim.studies.problem import SyntheticProblem
    other = tmp_path / "other"            # the same shevsim with one comment added: same version, other sources
    shutil.copytree(WORKTREE / "shevsim", other / "shevsim", ignore=shutil.ignore_patterns("__pycache__", "_data"))
    for f in ("components", "cycles", "scenarios", "fmus", "vehicles", "data/measured"):
        shutil.copytree(DATA_ROOT / f, other / f, ignore=shutil.ignore_patterns("__pycache__", "*.fmu"))
    with (other / "shevsim" / "metrics.py").open("a") as fh:
        fh.write("# edited on this worker only\n")
    with ProcessCluster() as c:
        c.start_scheduler()
        with pytest.raises(ShevsimError) as ei:
            StudyRunner(None, scheduler=c.address, progress=False, worker_wait_s=1.0).start()
        assert "no Dask worker" in str(ei.value) and c.address in str(ei.value)
        monkeypatch.setattr(parallel, "StudyRunner", functools.partial(StudyRunner, worker_wait_s=1.0))
        assert cli.main_study(["tradeoff", "--synthetic", "--rates-kwps", "30", "--no-plots", "--quiet",
                               "--scheduler", c.address, "-o", str(tmp_path / "out")]) == 2

        c.start_worker("edited", env={"PYTHONPATH": str(other)})
        from distributed import Client
        with Client(c.address, timeout="60s") as cl:
            cl.wait_for_workers(1, timeout=120)
            theirs = next(iter(cl.run(lambda: __import__("shevsim.studies.evaluate").studies.evaluate
                                      .code_version()).values()))
        assert theirs != code_version()
        runner = StudyRunner(None, scheduler=c.address, progress=False)
        monkeypatch.setattr(runner, "check_workers", lambda: None)     # as if the worker joined after the check
        monkeypatch.setattr(parallel, "warm_up_fast_path", lambda: "")
        with runner, pytest.raises(ShevsimError) as ei:
            runner.evaluate([SyntheticProblem().item(DEFAULT_EDGES_W, [10e3] * 8)])
        msg = str(ei.value)
        assert "joined the study was refused" in msg and "other package sources" in msg
        assert theirs[:12] in msg and code_version()[:12] in msg and runner.stats.new == 0
