"""Issue 26, first contact and conventions: which engine runs before a layout's compiled loop exists (and the
background build that makes later runs fast), compile messages on screen, `shevsim components`,
`--format csv|parquet|mat`, `-v`/`--log-level`, bundled names for `fmu export --params`, and the worker count
of a study chosen from its size (serial for a handful, a process pool without dask)."""
from __future__ import annotations

import io
import json
import logging
import time

import numpy as np
import pytest

import shevsim
from shevsim import warmup
from shevsim.cli import main
from shevsim.core.results import load_result
from shevsim.core.scenario import load_scenario
from shevsim.run import NOT_BUILT


@pytest.fixture
def fresh_state(tmp_path, monkeypatch):
    """An empty marker folder and no precompiled code shipped (as after a fresh install without it; an editable
    install puts one into the checkout's shevsim/_jitcache, which would count its loop as built; the compiled
    code itself stays where it is)."""
    from shevsim.core import jitcache
    monkeypatch.setenv("SHEVSIM_WARMUP_DIR", str(tmp_path / "warmup"))
    monkeypatch.setattr(jitcache, "SHIPPED", tmp_path / "no_shipped_cache")
    jitcache.shipped_status.cache_clear()
    assert warmup.state_dir() == tmp_path / "warmup"
    yield tmp_path
    jitcache.shipped_status.cache_clear()


def _short(name="hd_udds_rule", stop=20.0):
    sc = load_scenario(name)
    sc.set("scenario.stop_s", stop)
    return sc


# ------------------------------------------------------------------------------ engine choice
def test_auto_runs_the_master_until_the_layout_is_built(fresh_state):
    sc = _short()
    use, why = warmup.choose(sc, 200, 11)
    assert not use and why.startswith(NOT_BUILT)
    res = shevsim.simulate(sc, engine="auto")
    assert res.meta["engine"] == "python" and res.meta["fast_path"].startswith(NOT_BUILT)
    assert "warmup_pid" not in res.meta          # SHEVSIM_BACKGROUND_COMPILE=0 in the test session
    # a long run pays for the build: compiled in the foreground
    assert warmup.choose(sc, 10_000_000, 11) == (True, "")
    # a fast run marks its layout; the next auto run takes the fast path, with the master's numbers
    fast = shevsim.simulate(sc, engine="fast")
    assert warmup.is_compiled(sc)
    again = shevsim.simulate(sc, engine="auto")
    assert again.meta["engine"] == "fast"
    for k in res.signals:
        np.testing.assert_array_equal(again[k], res[k], err_msg=k)
        np.testing.assert_array_equal(fast[k], res[k], err_msg=k)
    # another layout is not marked by it
    other = _short("hd_udds_mpc")
    assert warmup.layout_of(other) != warmup.layout_of(sc) and not warmup.is_compiled(other)


def test_markers_follow_the_sources(fresh_state, monkeypatch):
    sc = _short()
    warmup.mark_compiled(sc)
    assert warmup.is_compiled(sc)
    monkeypatch.setattr(warmup, "_sources_stamp", lambda: "edited")      # a source file changed
    assert not warmup.is_compiled(sc)
    warmup.mark_compiled(sc, ok=False)          # a failed build is not retried, and not taken as built
    assert not warmup.is_compiled(sc)
    monkeypatch.setenv("SHEVSIM_BACKGROUND_COMPILE", "1")
    assert warmup.start_background(sc) is None


@pytest.mark.slow
def test_background_build_makes_the_next_run_fast(fresh_state, monkeypatch):
    monkeypatch.setenv("SHEVSIM_BACKGROUND_COMPILE", "1")
    sc = _short("hd_udds_mpc", 10.0)
    res = shevsim.simulate(sc, engine="auto")
    assert res.meta["engine"] == "python" and res.meta["warmup_pid"] > 0
    assert warmup.warmup_running(sc)
    t0 = time.monotonic()
    while warmup.warmup_running(sc) and time.monotonic() - t0 < 600:
        time.sleep(1)
    assert warmup.is_compiled(sc), (warmup.state_dir() / "warmup.log").read_text()
    fast = shevsim.simulate(sc, engine="auto")
    assert fast.meta["engine"] == "fast"
    for k in res.signals:
        np.testing.assert_array_equal(fast[k], res[k], err_msg=k)


def test_compile_notice_names_what_compiles():
    import numba

    @numba.njit(cache=False)
    def _square_plus(x):
        return x * x + 1.0

    buf = io.StringIO()
    with warmup.CompileNotice(stream=buf, prefix=__name__) as n:
        assert _square_plus(3.0) == 10.0
        _square_plus(4.0)                                # compiled once
    text = buf.getvalue()
    assert n.count == 1 and "compiling" in text and "_square_plus" in text and text.rstrip().endswith(" s")


# ------------------------------------------------------------------------------ conventions
def test_components_lists_types_ports_ranges_and_sets(capsys):
    assert main(["components"]) == 0
    out = capsys.readouterr().out
    assert "battery" in out and "mpc_supervisor" in out and "mass_spring" not in out
    assert main(["components", "battery", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    ports = {p["name"]: p for p in d["ports"]}
    assert ports["power_w"]["unit"] == "W" and ports["power_w"]["causality"] == "input"
    assert ports["current_a"]["unit"] == "A" and ports["current_a"]["causality"] == "output"
    params = {p["name"]: p for p in d["parameters"]}
    assert params["soc_init_pct"]["range"].startswith("[0, 100]")
    assert "battery/default" in d["parameter_sets"]
    assert main(["components", "--sets"]) == 0
    sets = capsys.readouterr().out
    assert "vehicle/matv" in sets and "engine_generator/seed_app_a" in sets
    assert main(["components", "nosuch"]) == 2


@pytest.mark.parametrize("fmt", ["csv", "mat"])
def test_run_format_round_trip(tmp_path, fmt):
    out = tmp_path / fmt
    assert main(["-q", "run", "hd_udds_rule", "--set", "scenario.stop_s=30", "--no-plots", "--out", str(out),
                 "--format", fmt]) == 0
    assert (out / f"timeseries.{fmt}").is_file() and not (out / "timeseries.parquet").exists()
    back = load_result(out)
    ref = shevsim.simulate("hd_udds_rule", stop_s=30.0)
    assert set(back.signals) == set(ref.signals)
    for k in ("battery.soc_pct", "vehicle.speed_mps", "engine_generator.fuel_rate_gps"):
        np.testing.assert_allclose(back[k], ref[k], rtol=1e-8 if fmt == "csv" else 0)
    if fmt == "mat":
        from scipy.io import loadmat
        m = loadmat(str(out / "timeseries.mat"), squeeze_me=True, struct_as_record=False)
        np.testing.assert_array_equal(m["vehicle"].speed_mps, ref["vehicle.speed_mps"])
        assert m["units"].vehicle.speed_mps == "m/s"


def test_log_levels(capsys, tmp_path):
    before = logging.getLogger("shevsim").level
    args = ["run", "hd_udds_rule", "--set", "scenario.stop_s=5", "--record", "battery.soc_pct", "--no-plots", "-q"]
    assert main(["-v"] + args + ["--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert "shevsim: INFO: " in err and "recorded too" in err           # run.py's info line, shown with -v
    assert main(args + ["--out", str(tmp_path / "b")]) == 0
    assert "INFO" not in capsys.readouterr().err
    assert main(["--log-level", "debug"] + args + ["--out", str(tmp_path / "c"), "-vv"]) == 0
    assert "shevsim: INFO: " in capsys.readouterr().err
    assert main(["--log-level", "loud", "scenarios"]) == 2
    assert "--log-level LOUD" in capsys.readouterr().err
    assert logging.getLogger("shevsim").level == before                 # the command's level is undone


@pytest.mark.fmu
def test_fmu_export_takes_a_bundled_parameter_set(tmp_path, capsys):
    pytest.importorskip("pythonfmu")
    out = tmp_path / "vehicle.fmu"
    assert main(["fmu", "export", "vehicle", "--params", "vehicle/matv", "-o", str(out)]) == 0
    assert out.is_file()
    assert main(["fmu", "export", "vehicle", "--params", "nosuch", "-o", str(tmp_path / "x.fmu")]) == 2
    assert "vehicle/matv" in capsys.readouterr().err


def test_study_workers_from_the_study_size(monkeypatch):
    from shevsim.studies import parallel
    from shevsim.studies.parallel import StudyRunner, auto_workers
    from shevsim.studies.problem import DEFAULT_EDGES_W, SyntheticProblem
    assert auto_workers(4, cpus=8) == 0 and auto_workers(8, cpus=8) == 0      # a handful: serial
    assert auto_workers(100, cpus=1) == 0
    assert auto_workers(12, cpus=8) == 3 and auto_workers(400, cpus=8) == 8
    items = [SyntheticProblem().item(DEFAULT_EDGES_W, [r] * 8) for r in (5e3, 9e3, 30e3, 12e3)]
    with StudyRunner(None, workers="auto", progress=False) as r:
        out = r.evaluate(items)
        assert r.workers == 0 and r.client is None        # 4 evaluations: no cluster
    serial = StudyRunner(None, progress=False).evaluate(items)
    assert out == serial
    # the plain install (no dask distributed): a process pool gives the same outputs
    monkeypatch.setattr(parallel, "_has_distributed", lambda: False)
    with StudyRunner(None, workers=2, progress=False) as r:
        assert r.evaluate(items) == serial and r.stats.slots == 2
    with pytest.raises(ValueError, match="auto"):
        StudyRunner(None, workers="many")


def test_run_params_take_a_bundled_set_by_name():
    from shevsim.core.paths import DATA_ROOT
    from shevsim.run import run
    by_name = run("hd_udds_rule", stop_s=60.0, overlays=["engine_generator=engine_generator/seed_app_a_transient"])
    by_path = run("hd_udds_rule", stop_s=60.0, overlays=[
        f"engine_generator={DATA_ROOT / 'components' / 'engine_generator' / 'seed_app_a_transient.toml'}"])
    plain = run("hd_udds_rule", stop_s=60.0)
    np.testing.assert_array_equal(by_name["engine_generator.soot_rate_mgps"], by_path["engine_generator.soot_rate_mgps"])
    assert not np.array_equal(by_name["engine_generator.soot_rate_mgps"], plain["engine_generator.soot_rate_mgps"])


@pytest.mark.fmu
def test_a_bundled_scenarios_fmu_is_built_in_the_user_cache(tmp_path, monkeypatch):
    """hd_udds_fmu_battery from an installed wheel: its FMU is not shipped; it is exported once into the user
    cache (never into the package) and the run equals the native scenario's."""
    pytest.importorskip("pythonfmu")
    from shevsim.core.paths import DATA_ROOT
    monkeypatch.setenv("SHEVSIM_CACHE_DIR", str(tmp_path / "cache"))
    sc = load_scenario("hd_udds_fmu_battery")
    sc.set("scenario.stop_s", 10.0)
    missing = DATA_ROOT / "fmus" / "issue26_not_shipped_battery.fmu"
    spec = next(c for c in sc.components if c.type == "fmu")
    spec.fmu = missing
    res = shevsim.simulate(sc, engine="python")
    assert not missing.exists()
    built = list((tmp_path / "cache" / "shevsim" / "fmus").glob("issue26_not_shipped_battery-*.fmu"))
    assert len(built) == 1
    native = shevsim.simulate("hd_udds_mpc", stop_s=10.0, engine="python")
    for k in ("battery.soc_pct", "battery.voltage_v", "vehicle.speed_mps"):
        np.testing.assert_allclose(res[k], native[k], rtol=1e-12, atol=1e-12, err_msg=k)
